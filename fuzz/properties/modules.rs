//! Properties of the seabus-modules readers that every input must keep. Each function panics when
//! an input breaks a property and tells whether the input was a valid one.

use seabus_medium::xml;
use seabus_modules::dsaav::config::{Address, Database, Sections};
use seabus_modules::system::SystemSpec;

/// The readers of the files users write: the positioned XML tree and system files. Any text is read
/// or refused with a placed error, never a panic. True when `data` is UTF-8 text that reads as a
/// system.
pub fn system_file(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let _ = xml::parse("fuzz.xml", text);
    SystemSpec::parse("fuzz.xml", text).is_ok()
}

/// The sections, settings and values of `sections`, without their places.
fn config_data(sections: &Sections) -> Vec<(String, Vec<(String, String)>)> {
    sections
        .iter()
        .map(|s| {
            let settings = s.settings().iter();
            let settings = settings.map(|s| (s.key.clone(), s.value.clone()));
            (s.name().to_owned(), settings.collect())
        })
        .collect()
}

/// The DSAAV configuration-file reader: any bytes are read or refused without a panic, and a
/// refusal names a place inside the text. Sections that read hold no section or key twice, write
/// back (as the application data is written) to text that reads to the same sections, settings
/// and values and writes again to the same text; through a database every value is found, reads as
/// an integer, a float and an address without a panic (a float read is finite, an address writes
/// back to itself), and every override `Service.Key` is the setting its component sees. True when
/// `data` reads.
pub fn dsaav_config(data: &[u8]) -> bool {
    let sections = match Sections::parse_bytes("fuzz.ini", data) {
        Ok(sections) => sections,
        Err(e) => {
            assert_eq!(&*e.pos.file, "fuzz.ini", "{e}");
            let line = usize::try_from(e.pos.line).unwrap_or(usize::MAX);
            let text = data.split(|&b| b == b'\n').nth(line.wrapping_sub(1));
            let Some(text) = text else {
                panic!(
                    "{e} is outside a text of {} lines",
                    data.split(|&b| b == b'\n').count()
                );
            };
            assert!(
                e.pos.col >= 1 && e.pos.col as usize <= text.len() + 1,
                "{e} is outside its line of {} bytes",
                text.len()
            );
            return false;
        }
    };
    let read = config_data(&sections);
    for (i, (name, settings)) in read.iter().enumerate() {
        assert!(
            read[..i].iter().all(|(earlier, _)| earlier != name),
            "section `{name}` read twice"
        );
        for (j, (key, _)) in settings.iter().enumerate() {
            assert!(
                settings[..j].iter().all(|(earlier, _)| earlier != key),
                "key `{key}` read twice in `{name}`"
            );
        }
    }
    let text = sections.to_text();
    let back = Sections::parse("fuzz.ini", &text)
        .unwrap_or_else(|e| panic!("the written text does not read: {e}\n{text}"));
    assert_eq!(
        config_data(&back),
        read,
        "the written text reads differently:\n{text}"
    );
    assert_eq!(back.to_text(), text, "writing again changes the text");
    let db = Database::new(sections);
    for (name, settings) in &read {
        for (key, value) in settings {
            let found = db.get(name, key).expect("every value is found");
            assert_eq!(found.text, value, "[{name}] {key}");
            let _ = found.int();
            if let Ok(f) = found.float() {
                assert!(f.is_finite(), "[{name}] {key} = {value} reads as {f}");
            }
            if let Ok(a) = found.address() {
                assert_eq!(a.to_string().parse::<Address>(), Ok(a), "{value}");
            }
            if let Some((service, setting)) = key.split_once('.') {
                let seen = db.setting(name, service, setting).map(|v| v.text);
                assert_eq!(seen, Ok(value.as_str()), "[{name}] {key}");
                let _ = db.server_of(name, service);
            }
        }
    }
    true
}
