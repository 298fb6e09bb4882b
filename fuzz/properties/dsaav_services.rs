//! Properties of the DSAAV services' readers (configuration files, health rules) that every input
//! must keep. Each function panics when an input breaks a property and tells whether the input was
//! a valid one.

use seabus_dsaav::config::{Address, Database, Sections};

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
    use seabus_dsaav::health::{ComponentState, Event, Instant, Mode, Monitor, Rules};
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
            seabus_dsaav::health::Severity::None,
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
        let entered = now == seabus_dsaav::health::Severity::Emergency && before != now;
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
