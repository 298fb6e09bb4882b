//! The health monitor in a running system: a component reporting over the network goes OFFLINE
//! when it stops, within its timeout, raising the configured severity and sending the emergency
//! action; it reports again and is HEALTHY again. A serial driver's link that is down makes its
//! component OFFLINE; the monitor's own modules are watched through their states.

mod common;
use common::*;
use std::io::{BufRead, BufReader};
use std::process::Stdio;
use std::sync::mpsc;
use std::time::{Duration, Instant};

const RULES: &str = r#"<health publish="vehicle.health" period="200ms"
        emergency-action='cmd.emergency ballast=drop reason="health emergency"'>
  <component name="DepthSensor" mode="active" timeout="700ms">
    <severity state="OFFLINE" level="EMERGENCY"/>
  </component>
  <component name="Frontseat" mode="link" medium="serial">
    <severity state="OFFLINE" level="WARN"/>
  </component>
  <component name="gen" mode="active" timeout="30s"/>
</health>
"#;

/// Waits for a spy line that `pred` accepts, at most `limit`; every line read is kept in `seen`.
fn wait_for_line(
    rx: &mpsc::Receiver<serde_json::Value>,
    seen: &mut Vec<serde_json::Value>,
    limit: Duration,
    what: &str,
    pred: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = Instant::now() + limit;
    while Instant::now() < deadline {
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(100)) {
            seen.push(v.clone());
            if pred(&v) {
                return v;
            }
        }
    }
    panic!("no {what} within {limit:?}");
}

fn report(net: &str, count: &str) -> std::process::Child {
    seabus()
        .args(["pub", net, "seabus.health.DepthSensor", "state=\"HEALTHY\""])
        .args(["--count", count, "--rate", "10"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("pub starts")
}

#[test]
fn a_silent_component_goes_offline_raises_the_severity_and_comes_back() {
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let missing = format!("/tmp/seabus-health-missing-{}", std::process::id());
    let system = format!(
        r#"<seabus node="h">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="{net}"/>
  <medium name="serial" url="serial://{missing}?baud=9600"/>
  <module name="gen" type="generator" medium="bus" tick="5Hz"/>
  <module name="health" type="health-monitor" media="bus serial" rules="health.xml"/>
  <bridge name="link" media="bus net" report="0">
    <route from="net" to="bus" topics="seabus.health.**"/>
    <route from="bus" to="net" topics="vehicle.health"/>
    <route from="bus" to="net" topics="cmd.**" kind="command"/>
  </bridge>
</seabus>"#
    );
    let (dir, path) = system_file("system.xml", &system);
    std::fs::write(dir.path().join("health.xml"), RULES).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.code() == Some(0),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let mut run = spawn_run(&path, &[]);
    let mut spy = seabus()
        .args(["spy", &net, "--json", "--for", "30"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spy starts");
    let (tx, rx) = mpsc::channel();
    let out = spy.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line)
                && tx.send(v).is_err()
            {
                return;
            }
        }
    });
    let component = |v: &serde_json::Value, name: &str| {
        v["payload"]["components"][name]
            .as_str()
            .map(str::to_string)
    };
    let snapshot = |v: &serde_json::Value| v["topic"] == "vehicle.health";
    let mut seen = Vec::new();

    // reporting: healthy; the serial link is down: its component OFFLINE
    let mut first = report(&net, "15");
    let healthy = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "a healthy DepthSensor",
        |v| {
            snapshot(v)
                && component(v, "DepthSensor").as_deref() == Some("HEALTHY")
                && component(v, "Frontseat").as_deref() == Some("OFFLINE")
                && component(v, "gen").as_deref() == Some("HEALTHY")
        },
    );
    assert_eq!(healthy["payload"]["severity"], "WARN", "{healthy}");
    let _ = first.wait();

    // silent: OFFLINE after its timeout, EMERGENCY, and the emergency action once
    let stopped = Instant::now();
    let offline = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(5),
        "DepthSensor OFFLINE",
        |v| snapshot(v) && component(v, "DepthSensor").as_deref() == Some("OFFLINE"),
    );
    assert_eq!(offline["payload"]["severity"], "EMERGENCY", "{offline}");
    assert!(
        stopped.elapsed() < Duration::from_secs(3),
        "marked OFFLINE {:?} after the last report (timeout 700 ms)",
        stopped.elapsed()
    );
    // the action goes out as the severity changes, before the snapshot that shows it
    let is_action = |v: &serde_json::Value| v["topic"] == "cmd.emergency";
    let action = match seen.iter().find(|v| is_action(v)) {
        Some(a) => a.clone(),
        None => wait_for_line(
            &rx,
            &mut seen,
            Duration::from_secs(5),
            "the emergency action",
            is_action,
        ),
    };
    assert_eq!(action["kind"], "command");
    assert_eq!(action["payload"]["ballast"], "drop");
    assert_eq!(action["payload"]["reason"], "health emergency");

    // back: HEALTHY, and the severity falls
    let mut again = report(&net, "15");
    let back = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "DepthSensor HEALTHY again",
        |v| snapshot(v) && component(v, "DepthSensor").as_deref() == Some("HEALTHY"),
    );
    assert_eq!(back["payload"]["severity"], "WARN", "{back}");
    let _ = again.wait();
    assert_eq!(
        seen.iter().filter(|v| is_action(v)).count(),
        1,
        "the emergency action is sent once per entry into EMERGENCY"
    );

    terminate(&run);
    assert!(wait_for(&mut run, Duration::from_secs(5)).is_some());
    let _ = spy.kill();
    let _ = spy.wait();
}
