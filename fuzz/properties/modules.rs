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

/// The health rules reader and the monitor built from its rules: any text is read or refused with
/// a place inside it, never a panic. Rules that read name at least one component, each once, give
/// HEALTHY the severity NONE and a passive component a timeout longer than its poll; a monitor
/// following them keeps the severity at the highest severity of the components' states through
/// every update, fires the emergency action exactly on each entry into EMERGENCY, takes every
/// timed component OFFLINE after its timeout and snapshots every component. True when `data`
/// reads as rules.
pub fn health_rules(data: &[u8]) -> bool {
    use seabus_modules::dsaav::health::{ComponentState, Event, Instant, Mode, Monitor, Rules};
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let rules = match Rules::parse("fuzz.xml", text) {
        Ok(rules) => rules,
        Err(e) => {
            assert_eq!(&*e.pos.file, "fuzz.xml", "{e}");
            let lines: Vec<&str> = text.split('\n').collect();
            let line = usize::try_from(e.pos.line).unwrap_or(usize::MAX);
            let Some(at) = lines.get(line.wrapping_sub(1)) else {
                panic!("{e} is outside a text of {} lines", lines.len());
            };
            let chars = at.chars().count();
            assert!(
                e.pos.col >= 1 && e.pos.col as usize <= chars + 1,
                "{e} is outside its line of {chars} characters"
            );
            return false;
        }
    };
    assert!(!rules.components.is_empty(), "rules without components");
    for (i, c) in rules.components.iter().enumerate() {
        assert!(
            rules.components[..i].iter().all(|d| d.name != c.name),
            "component `{}` read twice",
            c.name
        );
        assert_eq!(
            c.levels.get(ComponentState::Healthy),
            seabus_modules::dsaav::health::Severity::None,
            "{}",
            c.name
        );
        if let Mode::Passive { poll, timeout } = c.mode {
            assert!(
                timeout > poll,
                "{}: timeout {timeout:?} <= poll {poll:?}",
                c.name
            );
        }
    }
    let t0 = Instant::now();
    let mut monitor = Monitor::new(rules.clone(), t0);
    let expected = |m: &Monitor| {
        m.components()
            .map(|(name, state)| {
                let rule = m.rules().component(name).expect("a component of the rules");
                rule.levels.get(state)
            })
            .max()
            .unwrap_or_default()
    };
    let check = |m: &Monitor, before, events: &[Event]| {
        let now = m.severity();
        assert_eq!(
            now,
            expected(m),
            "the severity is the highest of the states"
        );
        let fired = events
            .iter()
            .filter(|e| matches!(e, Event::Emergency { .. }))
            .count();
        let entered = now == seabus_modules::dsaav::health::Severity::Emergency && before != now;
        assert_eq!(fired, usize::from(entered), "emergency events: {events:?}");
    };
    let names: Vec<String> = rules
        .components
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for (k, state) in ComponentState::ALL.into_iter().enumerate() {
        for (i, name) in names.iter().enumerate() {
            let before = monitor.severity();
            let at = t0 + std::time::Duration::from_millis((k * names.len() + i) as u64);
            let events = monitor.report(name, state, at);
            check(&monitor, before, &events);
        }
    }
    let before = monitor.severity();
    let far = t0 + std::time::Duration::from_secs(2_000_000_000);
    let events = monitor.tick(far);
    check(&monitor, before, &events);
    for (c, (_, state)) in rules.components.iter().zip(monitor.components()) {
        if c.mode.timeout().is_some() {
            assert_eq!(
                state,
                ComponentState::Offline,
                "{} after its timeout",
                c.name
            );
        }
    }
    let snapshot = monitor.snapshot();
    let listed = snapshot
        .get("components")
        .and_then(seabus_medium::Value::as_map)
        .map(seabus_medium::DataMap::len);
    assert_eq!(listed, Some(rules.components.len()));
    true
}

/// The `convert` module's declared conversions: any line is read or refused with a reason, never a
/// panic; a transform that reads gives one value per output, rotations keep a 3-vector's length and
/// the axis swap undoes itself. True when some line reads.
pub fn conversions(data: &[u8]) -> bool {
    use seabus_modules::frames::{Fields, Kind, Transform};
    use seabus_modules::support::convert::Conversion;
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    /// Every field is the same number.
    struct All(f64);
    impl Fields for All {
        fn number(&self, _: &str) -> Option<f64> {
            Some(self.0)
        }
    }
    let mut read = false;
    for line in text.lines() {
        if let Ok(c) = Conversion::parse(line) {
            read = true;
            let _ = c.apply(1.5);
        }
        let Ok(t) = Transform::parse(line) else {
            continue;
        };
        read = true;
        assert_eq!(t.inputs.len(), t.outputs.len(), "{line}");
        for x in [0.0, 12.5, -33.3] {
            let out = t.apply(&All(x)).expect("every field is there");
            assert_eq!(out.len(), t.outputs.len(), "{line}");
            match &t.kind {
                // in three dimensions (with two, z is taken as 0 and dropped after)
                Kind::Rotate(..) if out.len() == 3 => {
                    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
                    let before = norm(&vec![x; out.len()]);
                    assert!(
                        (norm(&out) - before).abs() <= 1e-9 * before.max(1.0),
                        "{line}: rotating {x} gave {out:?}"
                    );
                }
                Kind::SwapEnuNed => {
                    let back = t.apply(&Named(&t.inputs, &out)).expect("all there");
                    assert!(back.iter().all(|v| *v == x), "{line}: {out:?} → {back:?}");
                }
                _ => {}
            }
        }
    }
    read
}

/// Fields `names` holding `values`.
struct Named<'a>(&'a [String], &'a [f64]);

impl seabus_modules::frames::Fields for Named<'_> {
    fn number(&self, name: &str) -> Option<f64> {
        self.0.iter().position(|n| n == name).map(|i| self.1[i])
    }
}
