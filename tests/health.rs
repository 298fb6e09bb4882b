//! The health monitor in a running system: a component reporting over the network goes OFFLINE
//! when it stops, within its timeout, raising the configured severity and sending the emergency
//! action; it reports again and is HEALTHY again. A serial driver's link that is down makes its
//! component OFFLINE; the monitor's own modules are watched through their states. A frontseat
//! that stops sending navigation while its serial line stays open leaves HEALTHY, with the
//! silent topic named, and comes back when its data does.

mod common;
use common::*;
use std::cell::Cell;
use std::process::Stdio;
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
    let (mut spy, rx) = spy_json(&net, 30);
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

/// The paper's depth-control example with its health rules (configs/starfish-health.xml) over a
/// UDP backbone: the components report to the health monitor by RPC and it polls the passive ones
/// (the logging server, the controller) with the health call. The controller runs in a process of
/// its own; when that process dies the controller is OFFLINE within its timeout and the vehicle in
/// EMERGENCY; restarted, it is HEALTHY again.
#[test]
fn starfish_components_report_over_dsaav_and_a_dead_controller_goes_offline() {
    let dir = tempfile::tempdir().unwrap();
    let configs = concat!(env!("CARGO_MANIFEST_DIR"), "/configs");
    for f in ["starfish.ini", "starfish-health.xml"] {
        std::fs::copy(format!("{configs}/{f}"), dir.path().join(f)).unwrap();
    }
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let (g, p) = (group(), free_port());
    let node =
        |n: u16| format!(r#"  <medium name="n{n}" url="dsaav+udp://{g}:{p}?ttl=0&amp;node={n}"/>"#);
    let vehicle = format!(
        r#"<seabus node="starfish">
  <medium name="bus" url="{bus}"/>
{}
{}
{}
{}
  <module name="config" type="dsaav-config" medium="n1" config="starfish.ini" appdata="app.ini" port="2"/>
  <module name="log" type="dsaav-log" medium="n1" file="vehicle.log" port="0"/>
  <module name="health" type="health-monitor" media="bus n1" rules="starfish-health.xml" dsaav="n1" port="1"/>
  <module name="vehicle" type="starfish-vehicle-sim" media="n2 n4" depth="10"/>
  <module name="filter" type="depth-filter" medium="n3"/>
</seabus>
"#,
        node(1),
        node(2),
        node(3),
        node(4)
    );
    let controller = format!(
        r#"<seabus node="controller">
{}
  <module name="controller" type="depth-controller" medium="n5" target="5"/>
</seabus>
"#,
        node(5)
    );
    let (pv, pc) = (
        dir.path().join("vehicle.xml"),
        dir.path().join("controller.xml"),
    );
    std::fs::write(&pv, vehicle).unwrap();
    std::fs::write(&pc, controller).unwrap();
    for p in [&pv, &pc] {
        let checked = check(p);
        assert!(
            checked.status.success(),
            "{}",
            String::from_utf8_lossy(&checked.stderr)
        );
    }
    let (_spy, rx) = spy_json(&bus, 40);
    let _vehicle = spawn_run(&pv, &[]);
    let mut ctl = spawn_run(&pc, &[]);
    let state = |v: &serde_json::Value, name: &str| {
        v["payload"]["components"][name]
            .as_str()
            .unwrap_or("")
            .to_string()
    };
    let all = [
        "Logging",
        "Elevators",
        "DepthSensor",
        "DepthFilter",
        "MyDepthController",
    ];
    let snapshot = |v: &serde_json::Value| v["topic"] == "vehicle.health";
    let mut seen = Vec::new();
    // every component starts HEALTHY with one timeout (at most 3 s) to be heard from: a snapshot
    // after that shows what they said
    let started = Instant::now();
    let healthy = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(15),
        "every component HEALTHY",
        |v| {
            snapshot(v)
                && started.elapsed() > Duration::from_secs(4)
                && all.iter().all(|c| state(v, c) == "HEALTHY")
        },
    );
    assert_eq!(healthy["payload"]["severity"], "NONE", "{healthy}");

    // the controller's process dies: its polls go unanswered
    ctl.kill().unwrap();
    let _ = ctl.wait();
    let killed = Instant::now();
    let offline = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "MyDepthController OFFLINE",
        |v| snapshot(v) && state(v, "MyDepthController") == "OFFLINE",
    );
    assert_eq!(offline["payload"]["severity"], "EMERGENCY", "{offline}");
    // timeout 2 s after its last answer (polled every 500 ms), published within a period (1 s)
    assert!(
        killed.elapsed() < Duration::from_secs(5),
        "OFFLINE {:?} after the controller died",
        killed.elapsed()
    );
    let is_action = |v: &serde_json::Value| v["topic"] == "cmd.emergency";
    if !seen.iter().any(is_action) {
        wait_for_line(
            &rx,
            &mut seen,
            Duration::from_secs(5),
            "the emergency action",
            is_action,
        );
    }
    // the others are untouched
    for c in &all[..4] {
        assert_eq!(state(&offline, c), "HEALTHY", "{c}: {offline}");
    }

    // restarted: HEALTHY again, the severity falls
    let _again = spawn_run(&pc, &[]);
    let back = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(15),
        "MyDepthController HEALTHY again",
        |v| snapshot(v) && all.iter().all(|c| state(v, c) == "HEALTHY"),
    );
    assert_eq!(back["payload"]["severity"], "NONE", "{back}");
}

/// The seconds in a reason's `TOPIC silent for 4.2 s`.
fn silent_for(reason: &str, topic: &str) -> Option<f64> {
    let rest = reason.split("; ").find_map(|r| r.strip_prefix(topic))?;
    rest.strip_prefix(" silent for ")?
        .strip_suffix(" s")
        .and_then(|n| n.parse().ok())
}

/// The demo's frontseat (the Iver2 simulator on a pseudo-terminal, the Iver2 driver on the serial
/// end, the NMEA sensors line) under the demo's health rules (configs/demo-health.xml). The
/// simulator goes quiet for 5 s of every 9 (from 4 s after it starts): its pseudo-terminal stays
/// open, so the serial link stays up, but no navigation comes. The health snapshot leaves HEALTHY
/// within 3 s of the last navigation message, names the silent topic in its reasons, goes OFFLINE
/// after the rules' 3 s, and is HEALTHY again once the navigation flows again.
#[test]
fn a_frontseat_that_stops_navigating_on_an_open_line_leaves_healthy_and_comes_back() {
    let dir = tempfile::tempdir().unwrap();
    let rules = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/demo-health.xml");
    std::fs::copy(rules, dir.path().join("health.xml")).unwrap();
    let (front, sensors) = (dir.path().join("frontseat"), dir.path().join("sensors"));
    let (front, sensors) = (front.display(), sensors.display());
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="health-data">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="{net}"/>
  <medium name="frontseat" url="pty://{front}?framing=lines"/>
  <medium name="serial" url="serial://{front}?baud=19200&amp;framing=nmea"/>
  <medium name="sensors-out" url="pty://{sensors}"/>
  <medium name="sensors" url="serial://{sensors}?baud=4800&amp;framing=nmea"/>
  <module name="frontseat-sim" type="iver2-sim" media="frontseat sensors-out" autostart="true"
          silence_every="9s" silence_for="5s"/>
  <module name="iver" type="iver2" media="serial bus" version="5" request_every="250ms"/>
  <module name="health" type="health-monitor" media="bus serial sensors" rules="health.xml"/>
  <bridge name="link" media="bus net" report="0">
    <route from="bus" to="net" topics="vehicle.health"/>
    <route from="bus" to="net" topics="nav.position"/>
  </bridge>
</seabus>"#
    );
    let path = dir.path().join("system.xml");
    std::fs::write(&path, system).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let (mut spy, rx) = spy_json(&net, 60);
    let mut run = spawn_run(&path, &[]);
    let snapshot = |v: &serde_json::Value| v["topic"] == "vehicle.health";
    let is_nav = |v: &serde_json::Value| v["topic"] == "nav.position";
    let navigation = |v: &serde_json::Value| v["payload"]["components"]["Navigation"].clone();
    let all_healthy = |v: &serde_json::Value| {
        snapshot(v)
            && ["Frontseat", "Navigation", "VehicleState", "Sensors"]
                .iter()
                .all(|c| v["payload"]["components"][c] == "HEALTHY")
    };
    let mut seen = Vec::new();

    // the navigation flows: everything HEALTHY, nothing to explain
    let heard = Cell::new(false);
    let healthy = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(20),
        "a HEALTHY snapshot after navigation",
        |v| {
            heard.set(heard.get() || is_nav(v));
            heard.get() && all_healthy(v)
        },
    );
    assert_eq!(healthy["payload"]["severity"], "NONE", "{healthy}");
    assert_eq!(
        healthy["payload"]["reasons"],
        serde_json::json!({}),
        "{healthy}"
    );

    // the frontseat goes quiet on an open line: Navigation leaves HEALTHY within 3 s
    let last_nav = Cell::new(Instant::now());
    let silent = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(15),
        "Navigation leaving HEALTHY",
        |v| {
            if is_nav(v) {
                last_nav.set(Instant::now());
            }
            snapshot(v) && navigation(v) != "HEALTHY"
        },
    );
    let after = last_nav.get().elapsed();
    assert!(
        after < Duration::from_secs(3),
        "left HEALTHY {after:?} after the last navigation message"
    );
    assert_eq!(navigation(&silent), "UNAVAILABLE", "{silent}");
    assert_eq!(silent["payload"]["severity"], "WARN", "{silent}");
    assert_eq!(
        silent["payload"]["components"]["Frontseat"], "HEALTHY",
        "the serial link stays up: {silent}"
    );
    let reason = silent["payload"]["reasons"]["Navigation"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    let secs = silent_for(&reason, "nav.position").unwrap_or(-1.0);
    assert!((1.0..3.0).contains(&secs), "{reason}");

    // still quiet after the rules' timeout (3 s): OFFLINE, an abort
    let offline = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(5),
        "Navigation OFFLINE",
        |v| snapshot(v) && navigation(v) == "OFFLINE",
    );
    assert_eq!(offline["payload"]["severity"], "ABORT", "{offline}");
    let reason = offline["payload"]["reasons"]["Navigation"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    let secs = silent_for(&reason, "nav.position").unwrap_or(-1.0);
    assert!((3.0..5.0).contains(&secs), "{reason}");
    assert!(silent_for(&reason, "nav.attitude").is_some(), "{reason}");

    // the frontseat speaks again: HEALTHY, the severity back to NONE, nothing to explain
    let resumed = Cell::new(false);
    let back = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "a HEALTHY snapshot after the navigation resumed",
        |v| {
            resumed.set(resumed.get() || is_nav(v));
            resumed.get() && all_healthy(v)
        },
    );
    assert_eq!(back["payload"]["severity"], "NONE", "{back}");
    assert_eq!(back["payload"]["reasons"], serde_json::json!({}), "{back}");

    terminate(&run);
    assert!(wait_for(&mut run, Duration::from_secs(5)).is_some());
    let _ = spy.kill();
    let _ = spy.wait();
}
