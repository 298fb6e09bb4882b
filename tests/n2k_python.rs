//! The navigation PGNs (127250, 127251, 127257, 128267, 129025, 129026, 129029) against a second
//! independent NMEA 2000 implementation, the Python `nmea2000` package (its encoder and decoder,
//! driven by `tests/peers/n2k_python.py` as the slcan host of a pseudo-terminal adapter):
//!
//! - seabus sends, Python decodes: `seabus run` claims address 40, the PGNs are published on the
//!   bus as `n2k.out.ID`, and a heading dataset (`compass.heading`, as an NMEA 0183 compass
//!   driver gives it) is re-sent as PGN 127250 through the driver's `send` parameter;
//! - Python encodes, seabus decodes: `seabus spy --n2k --json` shows the same values.
//!
//! Needs Python with `nmea2000`, which `scripts/test` installs.

mod common;
use common::*;
use seabus_medium::{DataMap, Node, Value as V};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Whether Python has `nmea2000` (said when not).
fn python_nmea2000() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import nmea2000"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!("SKIPPED: Python's nmea2000 package is not installed (scripts/test installs it)");
    }
    ok
}

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/n2k_python.py");

/// The navigation PGNs with their fields in canboat's units (radians).
fn messages() -> Vec<(u32, &'static str, Value)> {
    vec![
        (
            127250,
            "vesselHeading",
            json!({"sid": 7, "heading": 1.2345, "deviation": -0.0123, "variation": 0.0456,
                   "reference": "Magnetic"}),
        ),
        (127251, "rateOfTurn", json!({"sid": 1, "rate": 0.0123})),
        (
            127257,
            "attitude",
            json!({"sid": 2, "yaw": 0.5, "pitch": 0.05, "roll": -0.1}),
        ),
        (
            128267,
            "waterDepth",
            json!({"sid": 5, "depth": 12.34, "offset": 0.5, "range": 100}),
        ),
        (
            129025,
            "positionRapidUpdate",
            json!({"latitude": 43.5123456, "longitude": 16.44}),
        ),
        (
            129026,
            "cogSogRapidUpdate",
            json!({"sid": 6, "cogReference": "True", "cog": 1.0, "sog": 5.14}),
        ),
        (
            129029,
            "gnssPositionData",
            json!({"sid": 9, "latitude": 43.5, "longitude": -16.25, "altitude": 12.5,
                   "gnssType": "GPS+GLONASS", "method": "RTK Fixed Integer",
                   "integrity": "Safe", "numberOfSvs": 12, "hdop": 0.8, "pdop": 1.5,
                   "geoidalSeparation": 40.0}),
        ),
    ]
}

/// Field `id` of built-in PGN `pgn`.
fn field(pgn: u32, id: &str) -> seabus_drivers::n2k::pgn::Field {
    let db = seabus_drivers::n2k::builtin::database();
    db.definitions(pgn)[0]
        .fields
        .iter()
        .find(|f| f.id == id)
        .unwrap_or_else(|| panic!("PGN {pgn} has no field {id}"))
        .clone()
}

/// Checks that `got` holds `sent` (canboat's units), within one raw step; `seabus`: `got` is in
/// seabus's units.
fn check(what: &str, pgn: u32, sent: &Value, got: &Value, seabus: bool) {
    for (id, want) in sent.as_object().unwrap() {
        let have = &got[id];
        match want {
            Value::Number(n) => {
                let f = field(pgn, id);
                let mut want = n.as_f64().unwrap();
                let mut tol = f.resolution * 0.51 + 1e-9;
                if seabus {
                    want = f.to_seabus(want);
                    tol = (f.to_seabus(f.resolution) - f.to_seabus(0.0)).abs() * 0.51 + 1e-9;
                }
                let have = have
                    .as_f64()
                    .unwrap_or_else(|| panic!("{what}.{id}: no number in {got}"));
                assert!(
                    (have - want).abs() <= tol,
                    "{what}.{id}: {have}, not {want} (±{tol}): {got}"
                );
            }
            other => assert_eq!(have, other, "{what}.{id}: {got}"),
        }
    }
}

/// Lines of a child's standard output, as JSON values.
fn json_lines(child: &mut std::process::Child) -> std::sync::mpsc::Receiver<Value> {
    let out = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str(&line)
                && tx.send(v).is_err()
            {
                return;
            }
        }
    });
    rx
}

#[tokio::test(flavor = "multi_thread")]
async fn python_nmea2000_decodes_the_navigation_pgns_seabus_sends() {
    if !python_nmea2000() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="n2k-python">
  <medium name="bus" url="{}"/>
  <medium name="n2k" url="slcan+pty://{}"/>
  <module name="nmea2000" type="nmea2000" media="n2k bus" address="40" unique_number="77"
          send="compass.heading=vesselHeading"/>
</seabus>"#,
        bus.replace('&', "&amp;"),
        pty.display()
    );
    let path = dir.path().join("system.xml");
    std::fs::write(&path, system).unwrap();
    let checked = common::check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let medium = schemes().open("bus", &bus, &Node::new("n2k-test")).unwrap();
    let mut status = medium.attach("watch");
    status.subscribe("n2k.status").unwrap();
    let tx = medium.attach("send");
    let _run = spawn_run(&path, &[]);
    assert!(wait_for_path(&pty, Duration::from_secs(10)));
    let mut py = Running(
        Command::new("python3")
            .args([SCRIPT, "read"])
            .arg(&pty)
            .arg("40")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("python3 runs"),
    );
    let rx = json_lines(&mut py);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(15);
    let mut claimed = false;
    while let Ok(Some(m)) = tokio::time::timeout_at(deadline, status.recv()).await {
        if m.payload.as_map().unwrap().get_str("state") == Some("claimed") {
            claimed = true;
            break;
        }
    }
    assert!(claimed, "the driver claimed an address within 15 s");

    // the PGNs on n2k.out (the heading as the dataset instead), until Python decoded each
    let compass = DataMap::new()
        .and("heading", V::Float(45.0))
        .and("magnetic", V::Bool(false))
        .and("sources", V::from("HDT"));
    let mut decoded: HashMap<u32, Value> = HashMap::new();
    for _round in 0..20 {
        for (pgn, id, fields) in messages().into_iter().skip(1) {
            let mut m = DataMap::new();
            for (k, v) in fields.as_object().unwrap() {
                let value = match v {
                    Value::Number(n) => V::Float(field(pgn, k).to_seabus(n.as_f64().unwrap())),
                    Value::String(s) => V::from(s.clone()),
                    other => panic!("{other}"),
                };
                m.insert(k.clone(), value);
            }
            tx.publish(
                seabus_medium::Kind::Data,
                format!("n2k.out.{id}").as_str(),
                m,
            )
            .await
            .unwrap();
        }
        tx.publish(
            seabus_medium::Kind::Data,
            "compass.heading",
            compass.clone(),
        )
        .await
        .unwrap();
        let until = std::time::Instant::now() + Duration::from_millis(500);
        while let Ok(v) =
            rx.recv_timeout(until.saturating_duration_since(std::time::Instant::now()))
        {
            if v["event"] == "pgn" {
                decoded.insert(v["pgn"].as_u64().unwrap() as u32, v);
            }
        }
        if messages().iter().all(|(p, _, _)| decoded.contains_key(p)) {
            break;
        }
    }
    for (pgn, id, fields) in messages().into_iter().skip(1) {
        let got = decoded
            .get(&pgn)
            .unwrap_or_else(|| panic!("Python decoded no PGN {pgn}: {decoded:?}"));
        assert_eq!((&got["id"], &got["src"]), (&json!(id), &json!(40)), "{got}");
        check(&format!("PGN {pgn}"), pgn, &fields, &got["fields"], false);
    }
    let heading = decoded
        .get(&127250)
        .unwrap_or_else(|| panic!("Python decoded no heading: {decoded:?}"));
    check(
        "the compass heading",
        127250,
        &json!({"heading": 45f64.to_radians(), "reference": "True"}),
        &heading["fields"],
        false,
    );
    assert_eq!(heading["src"], 40, "{heading}");
    // what the dataset lacks went as "not available"
    assert!(heading["fields"].get("deviation").is_none(), "{heading}");
}

#[test]
fn seabus_decodes_the_navigation_pgns_python_nmea2000_encodes() {
    if !python_nmea2000() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let mut spy = Running(
        seabus()
            .arg("spy")
            .arg(format!("slcan+pty://{}", pty.display()))
            .args(["--n2k", "--json", "--for", "8"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("seabus spy runs"),
    );
    let rx = json_lines(&mut spy);
    assert!(wait_for_path(&pty, Duration::from_secs(10)));
    let list: Vec<Value> = messages()
        .into_iter()
        .map(|(pgn, id, fields)| json!({"pgn": pgn, "id": id, "prio": 3, "src": 22, "fields": fields}))
        .collect();
    let mut py = Running(
        Command::new("python3")
            .args([SCRIPT, "write"])
            .arg(&pty)
            .arg("6")
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("python3 runs"),
    );
    let mut stdin = py.0.stdin.take().unwrap();
    writeln!(stdin, "{}", Value::Array(list)).unwrap();
    stdin.flush().unwrap();
    let mut got: HashMap<u32, Value> = HashMap::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(15);
    while std::time::Instant::now() < deadline
        && !messages().iter().all(|(p, _, _)| got.contains_key(p))
    {
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(100)) {
            got.insert(v["pgn"].as_u64().unwrap_or(0) as u32, v);
        }
    }
    drop(stdin);
    for (pgn, id, fields) in messages() {
        let v = got
            .get(&pgn)
            .unwrap_or_else(|| panic!("the spy showed no PGN {pgn}: {got:?}"));
        assert_eq!(
            (&v["topic"], &v["src"], &v["prio"]),
            (&json!(format!("n2k.22.{id}")), &json!(22), &json!(3)),
            "{v}"
        );
        check(&format!("PGN {pgn}"), pgn, &fields, &v["fields"], true);
    }
}
