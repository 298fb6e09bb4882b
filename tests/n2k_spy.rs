//! `seabus spy --n2k` on a live NMEA 2000 network: canboatjs (`tests/peers/n2k_canboat.js`) sends
//! a vessel heading and a GNSS position (a fast packet), and a GNSS position with a lost frame,
//! as an slcan host on the spy's pseudo-terminal adapter; the spy prints each PGN with its name
//! and its fields' names and units (as JSON lines with `--json`, as a table without), and says
//! how many frames made no PGN, and why.
//!
//! Needs Node with `@canboat/canboatjs`, which `scripts/test` installs and names in
//! `SEABUS_CANBOATJS`.

mod common;
use common::*;
use serde_json::{Value, json};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Where canboatjs is (see `tests/n2k_send.rs`).
fn canboatjs() -> Option<PathBuf> {
    let modules = match std::env::var_os("SEABUS_CANBOATJS") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-canboat/node_modules"),
    };
    let found = modules.join("@canboat/canboatjs/package.json").is_file();
    if std::env::var_os("SEABUS_CANBOATJS").is_some() {
        assert!(
            found,
            "SEABUS_CANBOATJS={} holds no canboatjs",
            modules.display()
        );
    }
    found.then_some(modules)
}

fn messages() -> Value {
    json!([
        {"pgn": 127250, "prio": 2, "src": 35, "dst": 255,
         "fields": {"sid": 7, "heading": 1.2345, "deviation": -0.0123, "variation": 0.0456,
                    "reference": "Magnetic"}},
        {"pgn": 129029, "prio": 3, "src": 7, "dst": 255,
         "fields": {"sid": 9, "date": 19000, "time": 36000.5, "latitude": 43.5,
                    "longitude": -16.25, "altitude": 12.5, "gnssType": "GPS+GLONASS",
                    "method": "RTK Fixed Integer", "integrity": "Safe", "numberOfSvs": 12,
                    "hdop": 0.8, "pdop": 1.5, "geoidalSeparation": 40.0, "referenceStations": 0}}
    ])
}

/// Runs `seabus spy slcan+pty://PTY --n2k ARGS --for SECS` with canboatjs sending on the
/// pseudo-terminal; gives its standard output and error.
fn spy_with_canboatjs(modules: &Path, args: &[&str], secs: u32) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let spy = seabus()
        .arg("spy")
        .arg(format!("slcan+pty://{}", pty.display()))
        .arg("--n2k")
        .args(args)
        .args(["--for", &secs.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("seabus spy runs");
    let mut spy = Running(spy);
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
            .arg((secs - 2).to_string())
            .env("NODE_PATH", modules)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node runs"),
    );
    let mut stdin = node.0.stdin.take().unwrap();
    writeln!(stdin, "{}", messages()).unwrap();
    stdin.flush().unwrap();
    let out = spy.0.stdout.take().unwrap();
    let err = spy.0.stderr.take().unwrap();
    let err = std::thread::spawn(move || {
        let mut s = String::new();
        for l in BufReader::new(err).lines().map_while(Result::ok) {
            s.push_str(&l);
            s.push('\n');
        }
        s
    });
    let mut text = String::new();
    let deadline = Instant::now() + Duration::from_secs(u64::from(secs) + 10);
    for line in BufReader::new(out).lines().map_while(Result::ok) {
        text.push_str(&line);
        text.push('\n');
        if Instant::now() > deadline {
            break;
        }
    }
    let status = wait_for(&mut spy, Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    drop(stdin);
    let _ = wait_for(&mut node, Duration::from_secs(5));
    (text, err.join().unwrap())
}

#[test]
fn the_spy_shows_canboatjs_pgns_with_names_and_units() {
    let Some(modules) = canboatjs() else {
        eprintln!(
            "SKIPPED the_spy_shows_canboatjs_pgns_with_names_and_units: canboatjs is not \
             installed (scripts/test installs it and sets SEABUS_CANBOATJS)"
        );
        return;
    };
    // --json: one object per PGN
    let (out, err) = spy_with_canboatjs(&modules, &["--json"], 6);
    let lines: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
        .collect();
    let heading = lines
        .iter()
        .find(|l| l["topic"] == "n2k.35.vesselHeading")
        .unwrap_or_else(|| panic!("no heading in {out}"));
    assert_eq!(
        (
            &heading["pgn"],
            &heading["description"],
            &heading["src"],
            &heading["prio"]
        ),
        (
            &json!(127250),
            &json!("Vessel Heading"),
            &json!(35),
            &json!(2)
        ),
        "{heading}"
    );
    assert_eq!(heading["names"]["heading"], "Heading", "{heading}");
    assert_eq!(heading["units"]["heading"], "deg", "{heading}");
    let h = heading["fields"]["heading"].as_f64().unwrap();
    assert!((h - 1.2345f64.to_degrees()).abs() < 0.006, "{heading}");
    assert_eq!(heading["fields"]["reference"], "Magnetic", "{heading}");
    let gnss = lines
        .iter()
        .find(|l| l["topic"] == "n2k.7.gnssPositionData")
        .unwrap_or_else(|| panic!("no GNSS position in {out}"));
    assert_eq!(gnss["description"], "GNSS Position Data", "{gnss}");
    assert_eq!(gnss["fields"]["latitude"], 43.5, "{gnss}");
    assert_eq!(gnss["fields"]["method"], "RTK Fixed Integer", "{gnss}");
    assert_eq!(gnss["units"]["altitude"], "m", "{gnss}");
    // the GNSS position with a lost frame is never shown, and is counted
    assert!(
        !lines.iter().any(|l| l["src"] == 99),
        "a broken fast packet was shown: {out}"
    );
    assert!(
        err.contains("NMEA 2000 frames that made no PGN")
            && err.contains("n2k-fast-packet-lost-frame"),
        "{err}"
    );

    // the table: a row per PGN and source, its fields by name with units
    let (out, _) = spy_with_canboatjs(&modules, &[], 6);
    let row = out
        .lines()
        .find(|l| l.starts_with("n2k.35.vesselHeading"))
        .unwrap_or_else(|| panic!("no heading row in {out}"));
    assert!(
        row.contains("SID=7 Heading (deg)=70.73164 Deviation (deg)=-0.704738"),
        "{row}"
    );
    assert!(
        out.lines().any(|l| l.starts_with("n2k.7.gnssPositionData")),
        "{out}"
    );
}
