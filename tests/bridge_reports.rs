//! A bridge publishes its reports on the media that carry datamaps as they are, and only there: a
//! bridge from a serial line to UDP reports on UDP, carries the line's frames across, and runs
//! without a warning (a serial line cannot carry a report, and is never asked to).

mod common;
use common::*;
use seabus_medium::{Kind, Node, Payload};
use std::io::{Read, Write};
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread")]
async fn a_bridge_from_a_serial_line_to_udp_reports_on_udp_and_logs_no_warning() {
    let dir = tempfile::tempdir().unwrap();
    let line = dir.path().join("line");
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="gw">
  <medium name="line" url="pty://{}?framing=lines&amp;topic=serial.line"/>
  <medium name="net" url="{}"/>
  <bridge name="uplink" media="line net" report="500ms">
    <route from="line" topics="serial.**"/>
  </bridge>
</seabus>"#,
        line.display(),
        net.replace('&', "&amp;")
    );
    let (_sys, path) = system_file("gw.xml", &system);
    let watcher = schemes().open("net", &net, &Node::new("watcher")).unwrap();
    let mut rx = watcher.attach("watch");
    rx.subscribe("**").unwrap();
    let mut run = spawn_run(&path, &["--for", "10"]);

    // the pseudo-terminal appears once the system runs; a line written to it crosses to UDP
    let start = Instant::now();
    let mut device = loop {
        match std::fs::OpenOptions::new().write(true).open(&line) {
            Ok(f) => break f,
            Err(_) if start.elapsed() < Duration::from_secs(10) => {
                std::thread::sleep(Duration::from_millis(20))
            }
            Err(e) => panic!("{}: {e}", line.display()),
        }
    };
    let (mut reports, mut lines) = (0, 0);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(9);
    let mut written = false;
    while let Ok(Some(m)) = tokio::time::timeout_at(deadline, rx.recv()).await {
        if !written {
            device.write_all(b"CTD 12.5 35.1\n").unwrap();
            written = true;
        }
        match m.topic.as_str() {
            "seabus.bridge.uplink" => {
                assert_eq!(m.kind, Kind::Data);
                let map = m.payload.as_map().expect("a report is a datamap").clone();
                assert!(map.get_i64("forwarded").is_some(), "{map}");
                reports += 1;
            }
            "serial.line" => {
                assert_eq!(m.payload, Payload::from(b"CTD 12.5 35.1".to_vec()));
                lines += 1;
            }
            other => panic!("unexpected topic {other} on the UDP side"),
        }
    }
    assert_eq!(lines, 1, "the line crossed once");
    // a report every 500 ms for the 9 s watched, give or take the start
    assert!((14..=19).contains(&reports), "{reports} reports on UDP");

    let status = wait_for(&mut run, Duration::from_secs(15)).expect("seabus run --for 10 ends");
    assert!(status.success(), "{status}");
    let mut stderr = String::new();
    run.stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("WARN") || l.contains("ERROR"))
        .collect();
    assert!(
        warnings.is_empty(),
        "warnings in 10 s:\n{}",
        warnings.join("\n")
    );
}
