//! A seabus vehicle on Zenoh and an independent Zenoh program (Python `eclipse-zenoh`): the
//! program reads the vehicle's data as JSON and sends a course command, which reaches the
//! simulated Iver2 frontseat and is acknowledged back to the program.

mod common;
use common::*;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Checks and runs the system file at `path`, and starts the Python peer on the Zenoh medium it
/// listens with on `port`, under `prefix`, for `secs`: the system, the peer and its lines.
fn run_with_peer(
    path: &std::path::Path,
    port: u16,
    prefix: &str,
    secs: u32,
) -> (
    Running,
    std::process::Child,
    BufReader<std::process::ChildStdout>,
) {
    let checked = check(path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let run = spawn_run(path, &[]);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/zenoh_peer.py");
    let mut peer = Command::new("python3")
        .args([
            script,
            &format!("tcp/127.0.0.1:{port}"),
            prefix,
            &secs.to_string(),
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    let out = BufReader::new(peer.stdout.take().unwrap());
    (run, peer, out)
}

#[test]
fn a_python_zenoh_program_reads_the_vehicle_and_commands_it() {
    let dir = tempfile::tempdir().unwrap();
    let line = dir.path().join("frontseat").display().to_string();
    let port = free_tcp_port();
    let system = format!(
        r#"<seabus node="auv1">
  <medium name="bus" url="inproc://"/>
  <medium name="frontseat" url="pty://{line}?framing=lines"/>
  <medium name="serial" url="serial://{line}?baud=19200&amp;framing=nmea"/>
  <medium name="fleet" url="zenoh://?listen=tcp/127.0.0.1:{port}&amp;prefix=fleet/auv1&amp;scout=false&amp;json=true"/>
  <module name="frontseat-sim" type="iver2-sim" media="frontseat" lat="43.5081" lon="16.4402" autostart="true"/>
  <module name="iver" type="iver2" media="serial bus" version="5" request_every="250ms"/>
  <bridge name="shore" media="bus fleet" report="0">
    <route from="bus" to="fleet" topics="**"/>
    <route from="fleet" to="bus" topics="cmd.**" kind="command"/>
  </bridge>
</seabus>"#
    );
    let (_sys, path) = system_file("auv1.xml", &system);
    let (_run, mut peer, out) = run_with_peer(&path, port, "fleet/auv1", 30);
    let mut position = None;
    let mut statuses = Vec::new();
    for line in out.lines().map_while(Result::ok) {
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        match v["key"].as_str() {
            Some("fleet/auv1/nav/position") => position = Some(v.clone()),
            Some("fleet/auv1/cmd/status") => statuses.push(v["value"].clone()),
            _ => {}
        }
    }
    let status = wait_for(&mut peer, Duration::from_secs(40));
    assert!(
        status.is_some_and(|s| s.success()),
        "the Python peer ends well"
    );
    let position = position.expect("the program read the vehicle's position");
    assert_eq!(position["encoding"], "application/json", "{position}");
    let lat = position["value"]["lat"].as_f64().unwrap();
    let lon = position["value"]["lon"].as_f64().unwrap();
    assert!(
        (lat - 43.5081).abs() < 0.01 && (lon - 16.4402).abs() < 0.01,
        "{position}"
    );
    // the course went to the frontseat as Remote Helm's $OMS, which it acknowledged
    let oms: Vec<&serde_json::Value> = statuses.iter().filter(|s| s["command"] == "OMS").collect();
    assert_eq!(
        oms.iter()
            .map(|s| s["state"].as_str().unwrap())
            .collect::<Vec<_>>(),
        ["pending", "acknowledged"],
        "{statuses:?}"
    );
    assert_eq!(oms[1]["error"], "", "{statuses:?}");
}

/// A shore, whose Zenoh prefix is the whole fleet's key space: its own bridge report goes under its
/// node's name (`fleet/shore/seabus/bridge/fleet`), where a `fleet/*/**` subscriber sees a node
/// called `shore`, never one called `seabus`.
#[test]
fn a_shore_s_own_status_goes_under_its_name_in_the_fleet_s_key_space() {
    let port = free_tcp_port();
    let system = format!(
        r#"<seabus node="shore">
  <medium name="bus" url="inproc://"/>
  <medium name="fleet" url="zenoh://?mode=router&amp;listen=tcp/127.0.0.1:{port}&amp;prefix=fleet&amp;scout=false&amp;json=true"/>
  <module name="gen" type="generator" medium="bus" topic="shore.test" tick="5Hz"/>
  <bridge name="fleet" media="bus fleet" report="1s">
    <route from="bus" to="fleet" topics="shore.test"/>
  </bridge>
</seabus>"#
    );
    let (_sys, path) = system_file("shore.xml", &system);
    let (_run, mut peer, out) = run_with_peer(&path, port, "fleet", 6);
    let keys: Vec<String> = out
        .lines()
        .map_while(Result::ok)
        .filter_map(|l| {
            let v: serde_json::Value = serde_json::from_str(&l).ok()?;
            v["key"].as_str().map(str::to_string)
        })
        .collect();
    let status = wait_for(&mut peer, Duration::from_secs(20));
    assert!(
        status.is_some_and(|s| s.success()),
        "the Python peer ends well"
    );
    assert!(
        keys.iter().any(|k| k == "fleet/shore/seabus/bridge/fleet"),
        "{keys:?}"
    );
    assert!(keys.iter().any(|k| k == "fleet/shore/test"), "{keys:?}");
    assert!(
        !keys.iter().any(|k| k.starts_with("fleet/seabus/")),
        "{keys:?}"
    );
}
