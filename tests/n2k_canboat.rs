//! The `nmea2000` driver against canboat's own JavaScript implementation: `tests/peers/n2k_canboat.js`
//! has canboatjs encode every built-in PGN with known values (its field encoder, fast-packet
//! framing and identifiers) and sends the frames over an slcan pseudo-terminal to `seabus run`.
//! seabus publishes each PGN on `n2k.SOURCE.ID` with those values, in seabus's units, and the
//! standard datasets of the navigation PGNs; a second driver reading canboat's database file
//! (`database=`) publishes the same values; a fast packet with a lost frame is dropped and counted
//! on the CAN medium.
//!
//! Needs Node with `@canboat/canboatjs` and `@canboat/pgns`, which `scripts/test` installs and
//! names in `SEABUS_CANBOATJS` (their `node_modules`) and `SEABUS_CANBOAT_JSON`.

mod common;
use common::*;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Where canboat's packages are: `SEABUS_CANBOATJS` (which must then hold them), else where
/// `scripts/test` installs them; `None` when neither holds them.
fn canboat() -> Option<(PathBuf, PathBuf)> {
    let modules = match std::env::var_os("SEABUS_CANBOATJS") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-canboat/node_modules"),
    };
    let json = std::env::var_os("SEABUS_CANBOAT_JSON")
        .map(PathBuf::from)
        .unwrap_or_else(|| modules.join("@canboat/pgns/canboat.json"));
    let found = modules.join("@canboat/canboatjs/package.json").is_file() && json.is_file();
    if std::env::var_os("SEABUS_CANBOATJS").is_some() {
        assert!(
            found,
            "SEABUS_CANBOATJS={} holds no canboatjs, or no canboat.json at {}",
            modules.display(),
            json.display()
        );
    }
    found.then_some((modules, json))
}

/// The messages canboatjs sends: each PGN with its fields in canboat's units, and the values
/// seabus gives that differ from them otherwise than by units.
fn messages() -> Vec<(Value, Value)> {
    let m = |pgn: u32, prio: u8, src: u8, fields: Value| json!({"pgn": pgn, "prio": prio, "src": src, "dst": 255, "fields": fields});
    vec![
        (
            m(
                127250,
                2,
                35,
                json!({"sid": 7, "heading": 1.2345, "deviation": -0.0123,
                "variation": 0.0456, "reference": "Magnetic"}),
            ),
            json!({}),
        ),
        (
            m(127251, 2, 35, json!({"sid": 1, "rate": 0.0123})),
            json!({}),
        ),
        (
            m(
                127257,
                3,
                35,
                json!({"sid": 2, "yaw": 0.5, "pitch": 0.05, "roll": -0.1}),
            ),
            json!({}),
        ),
        (
            m(
                127488,
                2,
                20,
                json!({"instance": "Dual Engine Starboard", "speed": 1500,
                "boostPressure": 120000, "tiltTrim": -5}),
            ),
            json!({}),
        ),
        (
            m(
                127489,
                2,
                20,
                json!({"instance": "Single Engine or Dual Engine Port",
                "oilPressure": 350000, "oilTemperature": 363.2, "temperature": 353.15,
                "alternatorPotential": 14.2, "fuelRate": 12.5, "totalEngineHours": 3600000,
                "coolantPressure": 150000, "fuelPressure": 300000,
                "discreteStatus1": ["Check Engine", "Over Temperature"],
                "discreteStatus2": ["Maintenance Needed"], "engineLoad": 50, "engineTorque": 40}),
            ),
            json!({}),
        ),
        (
            m(
                127506,
                6,
                40,
                json!({"sid": 3, "instance": 0, "dcType": "Battery",
                "stateOfCharge": 87, "stateOfHealth": 95, "timeRemaining": 7200,
                "rippleVoltage": 0.025, "remainingCapacity": 360000}),
            ),
            json!({}),
        ),
        (
            m(
                127508,
                6,
                40,
                json!({"instance": 0, "voltage": 12.8, "current": -3.5,
                "temperature": 298.15, "sid": 4}),
            ),
            json!({}),
        ),
        (
            m(
                128267,
                3,
                45,
                json!({"sid": 5, "depth": 12.34, "offset": 0.5, "range": 100}),
            ),
            json!({}),
        ),
        (
            m(
                129025,
                2,
                7,
                json!({"latitude": 43.5123456, "longitude": 16.44}),
            ),
            json!({}),
        ),
        (
            m(
                129026,
                2,
                7,
                json!({"sid": 6, "cogReference": "True", "cog": 1.0, "sog": 5.14}),
            ),
            json!({}),
        ),
        (
            m(
                129029,
                3,
                7,
                json!({"sid": 9, "date": 19000, "time": 36000.5, "latitude": 43.5,
                "longitude": -16.25, "altitude": 12.5, "gnssType": "GPS+GLONASS",
                "method": "RTK Fixed Integer", "integrity": "Safe", "numberOfSvs": 12,
                "hdop": 0.8, "pdop": 1.5, "geoidalSeparation": 40.0, "referenceStations": 1,
                "list": [{"referenceStationType": "GPS", "referenceStationId": 100,
                          "ageOfDgnssCorrections": 2.5}]}),
            ),
            json!({}),
        ),
        (
            m(
                130306,
                2,
                50,
                json!({"sid": 8, "windSpeed": 7.5, "windAngle": 0.7,
                "reference": "Apparent"}),
            ),
            json!({}),
        ),
        (
            m(
                130312,
                5,
                45,
                json!({"sid": 1, "instance": 2, "source": "Sea Temperature",
                "actualTemperature": 288.15, "setTemperature": 290.0}),
            ),
            json!({}),
        ),
        (
            m(
                130316,
                5,
                45,
                json!({"sid": 1, "instance": 0, "source": "Outside Temperature",
                "temperature": 283.15, "setTemperature": 293.1}),
            ),
            json!({}),
        ),
        (
            m(
                126992,
                3,
                7,
                json!({"sid": 0, "source": "GPS", "date": 19000, "time": 43200.5}),
            ),
            json!({}),
        ),
        (
            // canboatjs writes an indirect lookup only as a number
            m(
                60928,
                6,
                35,
                json!({"uniqueNumber": 123456, "manufacturerCode": "Airmar",
                "deviceInstanceLower": 1, "deviceInstanceUpper": 2, "deviceFunction": 130,
                "deviceClass": "Navigation", "systemInstance": 3, "industryGroup": "Marine",
                "arbitraryAddressCapable": "Yes"}),
            ),
            json!({"deviceFunction": "Bottom Depth"}),
        ),
    ]
}

/// `value` (canboat's units) in seabus's units, and the tolerance of one raw step, for field
/// `id` of `pgn` in the built-in set.
fn expected(pgn: u32, id: &str, value: f64) -> (f64, f64) {
    let db = seabus_drivers::n2k::builtin::database();
    let def = &db.definitions(pgn)[0];
    let f = def
        .fields
        .iter()
        .find(|f| f.id == id)
        .unwrap_or_else(|| panic!("PGN {pgn} has no field {id}"));
    let step = (f.to_seabus(f.resolution) - f.to_seabus(0.0)).abs();
    (f.to_seabus(value), step * 1.01 + 1e-9)
}

/// Checks that `got` (a PGN topic's payload) holds `fields` as sent, in seabus's units.
fn check_fields(what: &str, pgn: u32, fields: &Value, overrides: &Value, got: &Value) {
    for (id, sent) in fields.as_object().unwrap() {
        let have = &got[id];
        if let Some(want) = overrides.get(id) {
            assert_eq!(have, want, "{what}.{id}: {got}");
            continue;
        }
        match sent {
            Value::Number(n) => {
                let (want, tol) = expected(pgn, id, n.as_f64().unwrap());
                let have = have
                    .as_f64()
                    .unwrap_or_else(|| panic!("{what}.{id}: no number in {got}"));
                assert!(
                    (have - want).abs() <= tol,
                    "{what}.{id}: {have}, not {want} (±{tol}): {got}"
                );
            }
            Value::Array(items) if id == "list" => {
                let have = have
                    .as_array()
                    .unwrap_or_else(|| panic!("{what}: no list in {got}"));
                assert_eq!(have.len(), items.len(), "{what}.list: {got}");
                for (i, (sent, got)) in items.iter().zip(have).enumerate() {
                    check_fields(&format!("{what}.list[{i}]"), pgn, sent, &json!({}), got);
                }
            }
            other => assert_eq!(have, other, "{what}.{id}: {got}"),
        }
    }
}

#[test]
fn canboatjs_frames_become_the_same_values_and_the_standard_datasets() {
    let Some((modules, canboat_json)) = canboat() else {
        eprintln!(
            "SKIPPED canboatjs_frames_become_the_same_values_and_the_standard_datasets: canboat's \
             packages are not installed (scripts/test installs them and sets SEABUS_CANBOATJS)"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="n2k-test">
  <medium name="bus" url="{bus}"/>
  <medium name="n2k" url="slcan+pty://{}"/>
  <module name="nmea2000" type="nmea2000" media="n2k bus"/>
  <module name="from-database" type="nmea2000" media="n2k bus" database="{}" prefix="db"
          sources="200"/>
</seabus>"#,
        pty.display(),
        canboat_json.display()
    );
    let path = dir.path().join("system.xml");
    std::fs::write(&path, system).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let (_spy, rx) = spy_json(&bus, 60);
    let _run = spawn_run(&path, &[]);
    assert!(
        wait_for_path(&pty, Duration::from_secs(10)),
        "the pseudo-terminal {} appeared",
        pty.display()
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/n2k_canboat.js");
    let mut node = Running(
        Command::new("node")
            .arg(script)
            .arg(&pty)
            .arg("40")
            .env("NODE_PATH", &modules)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node runs"),
    );
    let list: Vec<Value> = messages().into_iter().map(|(m, _)| m).collect();
    let mut stdin = node.0.stdin.take().unwrap();
    writeln!(stdin, "{}", Value::Array(list)).unwrap();
    stdin.flush().unwrap();
    let out = node.0.stdout.take().unwrap();
    let (ntx, nrx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if ntx.send(line).is_err() {
                return;
            }
        }
    });

    // what the spy sees, the latest of each topic, until every topic looked for is there
    let topic_of = |prefix: &str, m: &Value| {
        let db = seabus_drivers::n2k::builtin::database();
        let pgn = m["pgn"].as_u64().unwrap() as u32;
        format!("{prefix}.{}.{}", m["src"], db.definitions(pgn)[0].id)
    };
    let mut wanted: Vec<String> = messages()
        .iter()
        .flat_map(|(m, _)| [topic_of("n2k", m), topic_of("db", m)])
        .collect();
    wanted.extend(
        [
            "nav.heading",
            "nav.attitude",
            "nav.rate",
            "nav.altitude",
            "nav.position",
            "nav.velocity",
            "env.wind",
            "power.battery",
            "nav.time",
        ]
        .map(String::from),
    );
    let mut latest: HashMap<String, Value> = HashMap::new();
    let mut gnss_position = None;
    let mut lost_counted = None;
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        let Ok(v) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let topic = v["topic"].as_str().unwrap_or_default().to_string();
        if topic == "nav.position" && v["payload"]["fix"] == 4 {
            gnss_position = Some(v["payload"].clone());
        }
        if topic == "seabus.media"
            && let Some(n) =
                v["payload"]["media"]["n2k"]["rejected"]["n2k-fast-packet-lost-frame"].as_u64()
        {
            lost_counted = Some((n, v["payload"]["media"]["n2k"]["rejected"].clone()));
        }
        latest.insert(topic, v["payload"].clone());
        if wanted.iter().all(|t| latest.contains_key(t))
            && gnss_position.is_some()
            && lost_counted.is_some()
        {
            break;
        }
    }
    let _ = writeln!(stdin, "stop");
    drop(stdin);
    let encoded: Vec<String> = nrx.try_iter().filter(|l| l.contains("encoded")).collect();
    let missing: Vec<&String> = wanted.iter().filter(|t| !latest.contains_key(*t)).collect();
    assert!(
        missing.is_empty(),
        "nothing on {missing:?} within 30 s; canboatjs sent {encoded:#?}"
    );

    // every PGN, from the built-in set and from canboat's database, with canboatjs's values
    for (m, overrides) in messages() {
        let pgn = m["pgn"].as_u64().unwrap() as u32;
        for prefix in ["n2k", "db"] {
            let topic = topic_of(prefix, &m);
            let got = &latest[&topic];
            assert_eq!(got["header"]["pgn"], m["pgn"], "{topic}: {got}");
            assert_eq!(got["header"]["src"], m["src"], "{topic}: {got}");
            assert_eq!(got["header"]["prio"], m["prio"], "{topic}: {got}");
            check_fields(&topic, pgn, &m["fields"], &overrides, got);
        }
    }

    // the standard datasets
    let near = |topic: &str, key: &str, want: f64, tol: f64| {
        let got = &latest[topic];
        let have = got[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{topic}: no {key} in {got}"));
        assert!(
            (have - want).abs() <= tol,
            "{topic}.{key}: {have}, not {want}: {got}"
        );
    };
    let deg = f64::to_degrees;
    near(
        "nav.heading",
        "heading",
        deg(1.2345 - 0.0123 + 0.0456),
        0.02,
    );
    assert_eq!(latest["nav.heading"]["magnetic"], false);
    near("nav.attitude", "yaw", deg(0.5), 0.01);
    near("nav.attitude", "pitch", deg(0.05), 0.01);
    near("nav.attitude", "roll", deg(-0.1), 0.01);
    near("nav.rate", "rate", deg(0.0123), 1e-5);
    near("nav.altitude", "altitude", 12.34, 0.011);
    near("nav.altitude", "water_depth", 12.84, 0.012);
    near("nav.velocity", "speed", 5.14, 0.011);
    near("nav.velocity", "course", deg(1.0), 0.01);
    near("env.wind", "speed", 7.5, 0.011);
    near("env.wind", "angle", deg(0.7), 0.01);
    assert_eq!(latest["env.wind"]["reference"], "apparent");
    near("power.battery", "percent", 87.0, 1e-9);
    near("nav.time", "utc", 19000.0 * 86400.0 + 43200.5, 1e-3);
    let g = gnss_position.expect("a position from the GNSS fix");
    assert!((g["lat"].as_f64().unwrap() - 43.5).abs() < 1e-9, "{g}");
    assert!((g["lon"].as_f64().unwrap() + 16.25).abs() < 1e-9, "{g}");
    assert!(
        (g["alt"].as_f64().unwrap() - (12.5 - 40.0)).abs() < 1e-3,
        "{g}"
    );
    assert_eq!(
        (&g["satellites"], &g["fix"]),
        (&json!(12), &json!(4)),
        "{g}"
    );

    // the fast packet with a lost frame, dropped and counted on the CAN medium, and nothing
    // from its sender
    let (n, rejected) = lost_counted.expect("seabus.media counts the lost frame");
    assert!(n >= 1, "{rejected}");
    assert!(
        !latest.contains_key("n2k.99.gnssPositionData"),
        "a message with a lost frame was published"
    );
    assert!(wait_for(&mut node, Duration::from_secs(10)).is_some_and(|s| s.success()));
}

#[test]
fn the_example_system_checks() {
    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/nmea2000.xml"));
    let out = check(path);
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_bad_database_stops_check_with_its_place() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("pgns.json"),
        "{\n  \"PGNs\": [\n    {\"PGN\": 127250, \"Id\": \"vesselHeading\",\n     \"Fields\": [{\"Id\": \"sid\", \"FieldType\": \"NUMBER\", \"BitLength\": \"8\"}]}\n  ]\n}\n",
    )
    .unwrap();
    let path = dir.path().join("system.xml");
    std::fs::write(
        &path,
        r#"<seabus node="n">
  <medium name="bus" url="inproc://"/>
  <medium name="n2k" url="slcan+pty:///tmp/never-opened"/>
  <module name="nmea2000" type="nmea2000" media="n2k bus" database="pgns.json"/>
</seabus>"#,
    )
    .unwrap();
    let out = check(&path);
    let said =
        String::from_utf8_lossy(&out.stderr).to_string() + &String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(
        said.contains(
            "pgns.json:4:54: PGNs[0] (127250 vesselHeading).Fields[0] (sid).BitLength: expected a whole number of 0 or more, found \"8\""
        ),
        "{said}"
    );
}
