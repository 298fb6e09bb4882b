//! A bridge publishes its reports on the media that carry datamaps as they are, and only there: a
//! bridge from a serial line to UDP reports on UDP, carries the line's frames across, and runs
//! without a warning (a serial line cannot carry a report, and is never asked to). A bridge from
//! MOOS to UDP reports on both, its per-route lists flattened for MOOS, with no error counted.

mod common;
use common::*;
use seabus_medium::{Kind, Node, Payload};
use std::io::Write;
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
    let run = spawn_run(&path, &["--for", "10"]);

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
                assert_eq!(map.get_i64("errors"), Some(0), "{map}");
                reports += 1;
            }
            "serial.line" => {
                assert_eq!(m.payload, Payload::from(b"CTD 12.5 35.1".to_vec()));
                lines += 1;
            }
            // the runtime's own status: UDP is the first medium whose peers are seabus programs
            "seabus.media" => {}
            t if t.starts_with("seabus.module.") => {}
            other => panic!("unexpected topic {other} on the UDP side"),
        }
    }
    assert_eq!(lines, 1, "the line crossed once");
    // a report every 500 ms for the 9 s watched, give or take the start
    assert!((14..=19).contains(&reports), "{reports} reports on UDP");

    let warnings = warnings_of(run, Duration::from_secs(15));
    assert!(
        warnings.is_empty(),
        "warnings in 10 s:\n{}",
        warnings.join("\n")
    );
}

/// The WARN and ERROR lines of a finished `seabus run`, after checking that it ended well.
fn warnings_of(run: Running, limit: Duration) -> Vec<String> {
    let (status, stderr) = ended(run, limit);
    let status = status.expect("seabus run --for ends");
    assert!(status.success(), "{status}\n{stderr}");
    stderr
        .lines()
        .filter(|l| l.contains("WARN") || l.contains("ERROR"))
        .map(str::to_string)
        .collect()
}

/// (A build without the MOOS medium has no such bridge: a vehicle's build of serial and UDP runs
/// the others.)
#[cfg(feature = "moos")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bridge_from_moos_to_udp_reports_on_both_with_no_error_and_no_warning() {
    use seabus_medium::{DataMap, Value};
    use seabus_medium_moos::db::MoosDb;
    let db = MoosDb::start("127.0.0.1:0".parse().unwrap()).await.unwrap();
    let port = db.addr().port();
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="gw">
  <medium name="shore" url="moos://127.0.0.1:{port}?name=seabus-gw&amp;register=DEPTH"/>
  <medium name="net" url="{net}"/>
  <bridge name="link" media="shore net" report="500ms" report_on="shore net">
    <route from="shore" topics="DEPTH" rename="nav.depth"/>
    <route from="net" topics="vehicle.mode" rename="VEHICLE_MODE"/>
  </bridge>
</seabus>"#
    );
    let (_sys, path) = system_file("gw.xml", &system);
    let watcher = schemes().open("net", &net, &Node::new("watcher")).unwrap();
    let mut rx = watcher.attach("watch");
    rx.subscribe("**").unwrap();
    let run = spawn_run(&path, &["--for", "10"]);

    // a MOOS app writes DEPTH, a UDP peer says the mode: each crosses
    let app = schemes()
        .open(
            "app",
            &format!("moos://127.0.0.1:{port}?name=pDepth&register=NONE"),
            &Node::new("test"),
        )
        .unwrap();
    let app_tx = app.attach("tx");
    let net_tx = watcher.attach("tx");
    let (mut udp_reports, mut depths) = (Vec::new(), 0);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(9);
    let mut tick = tokio::time::interval(Duration::from_millis(500));
    loop {
        tokio::select! {
            m = tokio::time::timeout_at(deadline, rx.recv()) => {
                let Ok(Some(m)) = m else { break };
                match m.topic.as_str() {
                    "seabus.bridge.link" => {
                        udp_reports.push(m.payload.as_map().expect("a report is a datamap").clone())
                    }
                    "nav.depth" => {
                        assert_eq!(m.payload, Payload::from(DataMap::new().with("value", 12.5)));
                        depths += 1;
                    }
                    "vehicle.mode" => {}
                    // the runtime's own status: UDP is the first medium whose peers are seabus
                    "seabus.media" => {}
                    t if t.starts_with("seabus.module.") => {}
                    other => panic!("unexpected topic {other} on the UDP side"),
                }
            }
            _ = tick.tick() => {
                // the link to the DB may still be coming up: a refused send is tried again
                let _ = app_tx.send("DEPTH", DataMap::new().with("value", 12.5)).await;
                net_tx.send("vehicle.mode", DataMap::new().with("mode", "survey")).await.unwrap();
            }
        }
    }
    assert!(depths >= 10, "{depths} depths crossed to UDP");
    let mode = db.value("VEHICLE_MODE").expect("the mode reached the DB");
    assert_eq!(mode.string, b"mode=survey");

    // the report on UDP: lists as lists, no error
    assert!(
        (14..=19).contains(&udp_reports.len()),
        "{} reports on UDP",
        udp_reports.len()
    );
    let last = udp_reports.last().unwrap();
    assert_eq!(last.get_i64("errors"), Some(0), "{last}");
    assert_eq!(last.get_i64("reports_unpublished"), Some(0), "{last}");
    let Some(Value::List(routes)) = last.get("route_forwarded") else {
        panic!("route_forwarded is a list on UDP: {last}")
    };
    assert_eq!(routes.len(), 2, "{last}");
    assert!(routes.iter().all(|n| n.as_i64().unwrap() > 0), "{last}");

    // and on MOOS, the same report as key=value pairs, the lists one field per route
    let on_moos = db.value("seabus.bridge.link").expect("a report on MOOS");
    let text = String::from_utf8(on_moos.string.clone()).unwrap();
    let report = seabus_medium_moos::parse_pairs(&text).expect("key=value pairs");
    assert_eq!(report.get_i64("errors"), Some(0), "{text}");
    assert!(report.get_i64("route_forwarded.0").unwrap() > 0, "{text}");
    assert!(report.get_i64("route_forwarded.1").unwrap() > 0, "{text}");
    assert!(report.get_f64("route_latency_ms.1").is_some(), "{text}");
    assert!(report.get("route_forwarded").is_none(), "{text}");

    let warnings = warnings_of(run, Duration::from_secs(15));
    assert!(
        warnings.is_empty(),
        "warnings in 10 s:\n{}",
        warnings.join("\n")
    );
}
