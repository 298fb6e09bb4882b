//! `configs/n2k-lcm.xml` as a user runs it (its pseudo-terminal and LCM group moved to free ones):
//! canboatjs (`tests/peers/n2k_canboat.js`) sends a magnetic vessel heading with its deviation
//! and variation on the slcan pseudo-terminal, and `seabus spy` on the LCM group sees
//! `NAV_HEADING` as `seabus.heading_t` with the true heading.
//!
//! Needs Node with `@canboat/canboatjs`, which `scripts/test` installs and names in
//! `SEABUS_CANBOATJS`.

mod common;
use common::*;
use serde_json::json;
use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

#[test]
fn the_example_system_bridges_an_nmea_2000_heading_into_lcm() {
    let modules = match std::env::var_os("SEABUS_CANBOATJS") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-canboat/node_modules"),
    };
    if !modules.join("@canboat/canboatjs/package.json").is_file() {
        assert!(
            std::env::var_os("SEABUS_CANBOATJS").is_none(),
            "SEABUS_CANBOATJS={} holds no canboatjs",
            modules.display()
        );
        eprintln!(
            "SKIPPED the_example_system_bridges_an_nmea_2000_heading_into_lcm: canboatjs is not \
             installed (scripts/test installs it and sets SEABUS_CANBOATJS)"
        );
        return;
    }
    let example =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/n2k-lcm.xml"))
            .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let lcm = format!("udpm://{}:{}?ttl=0", group(), free_port());
    assert!(
        example.contains("/tmp/seabus-n2k-lcm")
            && example.contains("udpm://239.255.76.67:7667?ttl=0")
    );
    let system = example
        .replace("/tmp/seabus-n2k-lcm", &pty.display().to_string())
        .replace("udpm://239.255.76.67:7667?ttl=0", &lcm);
    let path = dir.path().join("n2k-lcm.xml");
    std::fs::write(&path, system).unwrap();
    let (_spy, rx) = spy_json(&lcm, 30);
    let _run = spawn_run(&path, &[]);
    assert!(wait_for_path(&pty, Duration::from_secs(10)));
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/n2k_canboat.js");
    let mut node = Running(
        Command::new("node")
            .arg(script)
            .arg(&pty)
            .arg("20")
            .env("NODE_PATH", &modules)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node runs"),
    );
    let mut stdin = node.0.stdin.take().unwrap();
    let list = json!([
        {"pgn": 127250, "prio": 2, "src": 35, "dst": 255,
         "fields": {"sid": 7, "heading": 1.2345, "deviation": -0.0123, "variation": 0.0456,
                    "reference": "Magnetic"}},
        {"pgn": 129029, "prio": 3, "src": 7, "dst": 255,
         "fields": {"sid": 9, "latitude": 43.5, "longitude": -16.25, "method": "GNSS fix"}}
    ]);
    writeln!(stdin, "{list}").unwrap();
    stdin.flush().unwrap();
    let mut seen = Vec::new();
    let heading = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(20),
        "NAV_HEADING",
        |v| v["topic"] == "NAV_HEADING",
    );
    assert_eq!(heading["lcm_type"], "seabus.heading_t", "{heading}");
    let h = heading["payload"]["heading"].as_f64().unwrap();
    let want = (1.2345f64 - 0.0123 + 0.0456).to_degrees();
    assert!((h - want).abs() < 0.02, "{h}, not {want}: {heading}");
    assert_eq!(heading["payload"]["magnetic"], false, "{heading}");
    let _ = writeln!(stdin, "stop");
}
