//! The `mavlink` driver in a running system against pymavlink standing in for an ArduSub ROV on
//! UDP loopback (`tests/peers/mavlink_ardusub.py`): `seabus run` publishes the standard datasets
//! with the values the vehicle sent (and leaves out what it marked unknown); arming and a mode
//! change are acknowledged on `cmd.status`, a mode the vehicle denies is refused with its result, a
//! course goes as a GUIDED target and an altitude is refused; a command it does not answer goes
//! three times (confirmation 0, 1, 2) and times out; a stick's stream of `cmd.manual` reaches it
//! as MANUAL_CONTROL with the same values at the rate sent, and neutral once when it stops; when its heartbeat stops, the link and the vehicle go OFFLINE in
//! the health monitor within 3 s, and commands are refused at once.
//!
//! Commands come as an operator's tools send them: `seabus pub --command` on a network medium
//! bridged to the bus; what the system publishes is read with `seabus spy` on that medium. The
//! seeds of the driver's fuzz target (`fuzz/corpus/mavlink_datasets`) are replayed here as well.

mod common;
use common::*;

// the seeds of the driver's fuzz target run here too
#[path = "../fuzz/properties/mavlink_driver.rs"]
mod properties;
#[macro_use]
#[path = "../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// MAVLink messages through the driver's mappings: datasets with finite numbers and their
    /// required fields, or none; unknown values never published; a stick's values never changed.
    mavlink_datasets_seeds => mavlink_datasets,
}
use serde_json::Value;
use std::process::Stdio;
use std::sync::mpsc;
use std::time::{Duration, Instant};

const RULES: &str = r#"<health publish="vehicle.health" period="250ms">
  <component name="ROV" mode="active" timeout="5s"/>
  <component name="MavLink" mode="link" medium="mav"/>
</health>
"#;

/// A system: the driver between the MAVLink medium and the bus, the health monitor, and a bridge
/// to the network medium `net` where the test publishes commands and spies.
fn system(mav_port: u16, net: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let text = format!(
        r#"<seabus node="rov">
  <medium name="bus" url="inproc://"/>
  <medium name="mav" url="mavlink://udpin:127.0.0.1:{mav_port}?timeout=2s"/>
  <medium name="net" url="{net}"/>
  <module name="rov" type="mavlink" media="mav bus" health="ROV" ack_timeout="400ms"
          retries="2" manual_timeout="1s" water="salt" surface_pressure="1013.25"/>
  <module name="health" type="health-monitor" media="bus mav" rules="health.xml"/>
  <bridge name="link" media="bus net" report="0">
    <route from="bus" to="net" topics="nav.**"/>
    <route from="bus" to="net" topics="power.**"/>
    <route from="bus" to="net" topics="vehicle.**"/>
    <route from="bus" to="net" topics="cmd.status"/>
    <route from="net" to="bus" topics="cmd.**" kind="command"/>
  </bridge>
</seabus>"#
    );
    let (dir, path) = system_file("system.xml", &text);
    std::fs::write(dir.path().join("health.xml"), RULES).expect("the rules are written");
    let checked = check(&path);
    assert_eq!(
        checked.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    (dir, path)
}

/// What the spy shows of a running system.
struct Spy {
    _spy: Running,
    rx: mpsc::Receiver<Value>,
    seen: Vec<Value>,
}

impl Spy {
    fn new(net: &str) -> Spy {
        let (spy, rx) = spy_json(net, 60);
        Spy {
            _spy: spy,
            rx,
            seen: Vec::new(),
        }
    }

    /// The payload of the next message on `topic` that `pred` accepts, within `limit`.
    fn next(&mut self, topic: &str, limit: Duration, pred: impl Fn(&Value) -> bool) -> Value {
        let line = wait_for_line(&self.rx, &mut self.seen, limit, topic, |v| {
            v["topic"] == topic && pred(&v["payload"])
        });
        line["payload"].clone()
    }

    /// The payload of a message on `topic` that `pred` accepts, already seen or within `limit`.
    fn any(&mut self, topic: &str, limit: Duration, pred: impl Fn(&Value) -> bool) -> Value {
        if let Some(v) = self
            .seen
            .iter()
            .find(|v| v["topic"] == topic && pred(&v["payload"]))
        {
            return v["payload"].clone();
        }
        self.next(topic, limit, pred)
    }

    /// The `cmd.status` of command `command` in state `state`.
    fn status(&mut self, command: &str, state: &str, limit: Duration) -> Value {
        self.any("cmd.status", limit, |p| {
            p["command"] == command && p["state"] == state
        })
    }

    fn health(&mut self, component: &str, state: &str, limit: Duration) -> Value {
        self.next("vehicle.health", limit, |p| {
            p["components"][component] == state
        })
    }
}

/// `seabus pub NET TOPIC --command FIELDS…` (`--count`, `--rate` in `extra`), run to its end.
fn command(net: &str, topic: &str, fields: &[&str], extra: &[&str]) {
    let status = seabus()
        .args(["pub", net, topic, "--command"])
        .args(fields)
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .expect("pub runs");
    assert!(status.success(), "seabus pub {topic} {fields:?}: {status}");
}

fn f(v: &Value, k: &str) -> f64 {
    v[k].as_f64()
        .unwrap_or_else(|| panic!("`{k}` is no number in {v}"))
}

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() < 1e-6, "{what}: {a} is not {b}");
}

#[test]
fn datasets_commands_refusals_and_a_lost_vehicle() {
    let (mav_port, rov_port) = (free_port(), free_port());
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let (_dir, path) = system(mav_port, &net);
    let mut spy = Spy::new(&net);
    let _run = spawn_run(&path, &[]);
    let mut rov = PythonPeer::mavlink("mavlink_ardusub.py", rov_port, mav_port, 60);
    let second = Duration::from_secs(10);

    // the datasets, with the values the ROV sent
    let att = spy.next("nav.attitude", second, |_| true);
    close(f(&att, "yaw"), 360.0 - 1.57f64.to_degrees(), "yaw");
    close(f(&att, "roll"), 0.1f64.to_degrees(), "roll");
    close(f(&att, "pitch"), -0.05f64.to_degrees(), "pitch");
    close(f(&att, "roll_rate"), 0.01f64.to_degrees(), "roll rate");
    close(f(&att, "yaw_rate"), -0.02f64.to_degrees(), "yaw rate");
    let pos = spy.any("nav.position", second, |_| true);
    close(f(&pos, "lat"), 43.5081, "lat");
    close(f(&pos, "lon"), 16.4402, "lon");
    close(f(&pos, "alt"), -12.5, "alt");
    let vel = spy.any("nav.velocity", second, |_| true);
    close(f(&vel, "north"), 0.3, "north");
    close(f(&vel, "east"), -0.4, "east");
    close(f(&vel, "speed"), 0.5, "speed");
    close(f(&vel, "down"), 0.02, "down");
    close(
        f(&vel, "course"),
        360.0 - 0.4f64.atan2(0.3).to_degrees(),
        "course",
    );
    let depth = spy.any("nav.depth", second, |_| true);
    close(
        f(&depth, "depth"),
        (2250.5 - 1013.25) * 100.0 / (1025.0 * 9.80665),
        "depth",
    );
    close(f(&depth, "pressure"), 22.505, "pressure");
    close(f(&depth, "temperature"), 18.5, "temperature");
    let battery = spy.any("power.battery", second, |_| true);
    close(f(&battery, "percent"), 76.0, "percent");
    close(f(&battery, "voltage"), 15.8, "voltage");
    // the ROV's current is -1 (unknown), its heading UINT16_MAX: absent, never numbers
    assert!(battery.get("current").is_none(), "{battery}");
    let state = spy.any("vehicle.state", second, |p| p["mode"] == "MANUAL");
    assert_eq!(state["armed"], false, "{state}");
    assert_eq!(state["control"], "idle", "{state}");
    assert_eq!(state["status"], "STANDBY", "{state}");
    assert_eq!(state["type"], "SUBMARINE", "{state}");
    spy.health("ROV", "HEALTHY", second);

    // arming: pending, acknowledged, and the vehicle armed
    command(&net, "cmd.arm", &["armed=true"], &[]);
    let arm = rov.wait("command", second, |v| v["command"] == 400);
    assert_eq!(
        (&arm["param1"], &arm["confirmation"], &arm["target_system"]),
        (&Value::from(1.0), &Value::from(0), &Value::from(1))
    );
    let pending = spy.status("MAV_CMD_COMPONENT_ARM_DISARM", "pending", second);
    let acked = spy.status("MAV_CMD_COMPONENT_ARM_DISARM", "acknowledged", second);
    assert_eq!(pending["id"], acked["id"]);
    let armed = spy.any("vehicle.state", second, |p| p["armed"] == true);
    assert_eq!(armed["control"], "accepting", "{armed}");
    assert_eq!(armed["status"], "ACTIVE", "{armed}");

    // a mode change, by the name pilots use
    command(&net, "cmd.mode", &["mode=\"DEPTH_HOLD\""], &[]);
    let mode = rov.wait("command", second, |v| v["command"] == 176);
    assert_eq!((f(&mode, "param1"), f(&mode, "param2")), (1.0, 2.0));
    spy.status("MAV_CMD_DO_SET_MODE", "acknowledged", second);
    spy.any("vehicle.state", second, |p| p["mode"] == "DEPTH_HOLD");

    // a mode the ROV denies: refused, with the result named
    command(&net, "cmd.mode", &["mode=\"AUTO\""], &[]);
    rov.wait("command", second, |v| {
        v["command"] == 176 && v["param2"] == 3.0
    });
    let denied = spy.status("MAV_CMD_DO_SET_MODE", "refused", second);
    assert_eq!(denied["error"], "DENIED", "{denied}");
    // a mode ArduSub does not have: refused at once, with the modes it has
    command(&net, "cmd.mode", &["mode=\"LOITER\""], &[]);
    let unknown = spy.any("cmd.status", second, |p| {
        p["state"] == "refused" && p["error"].as_str().is_some_and(|e| e.contains("LOITER"))
    });
    assert!(
        unknown["error"]
            .as_str()
            .is_some_and(|e| e.contains("its modes are STABILIZE")),
        "{unknown}"
    );

    // a course: a GUIDED target, which MAVLink does not acknowledge (`sent`)
    command(
        &net,
        "cmd.course",
        &["heading=90.0", "depth=5.0", "speed=0.5"],
        &[],
    );
    let target = rov.wait("target", second, |_| true);
    // MAV_FRAME_GLOBAL_RELATIVE_ALT_INT; position, vertical speed, accelerations, yaw rate ignored
    assert_eq!(
        (&target["frame"], &target["type_mask"]),
        (&Value::from(6), &Value::from(2531))
    );
    assert!((f(&target, "alt") + 5.0).abs() < 1e-4, "{target}");
    assert!(f(&target, "vx").abs() < 1e-4, "{target}");
    assert!((f(&target, "vy") - 0.5).abs() < 1e-4, "{target}");
    assert!(
        (f(&target, "yaw") - std::f64::consts::FRAC_PI_2).abs() < 1e-4,
        "{target}"
    );
    spy.status("SET_POSITION_TARGET_GLOBAL_INT", "sent", second);
    // an altitude above the floor (a negative depth) is no MAVLink target: refused
    command(
        &net,
        "cmd.course",
        &["heading=90.0", "depth=-2.0", "speed=0.5"],
        &[],
    );
    let altitude = spy.status("SET_POSITION_TARGET_GLOBAL_INT", "refused", second);
    assert!(
        altitude["error"]
            .as_str()
            .is_some_and(|e| e.contains("not an altitude")),
        "{altitude}"
    );

    // no answer: sent again with confirmation 1 and 2, then timed out
    rov.order("mute");
    rov.wait("muted", second, |_| true);
    command(&net, "cmd.arm", &["armed=false"], &[]);
    let timed_out = spy.status("MAV_CMD_COMPONENT_ARM_DISARM", "timed-out", second);
    assert!(
        timed_out["error"]
            .as_str()
            .is_some_and(|e| e.contains("sent 3 times")),
        "{timed_out}"
    );
    rov.wait("command", second, |v| {
        v["command"] == 400 && v["param1"] == 0.0 && v["confirmation"] == 2
    });
    let disarms: Vec<Value> = rov
        .all("command")
        .into_iter()
        .filter(|v| v["command"] == 400 && v["param1"] == 0.0)
        .map(|v| v["confirmation"].clone())
        .collect();
    assert_eq!(disarms, [0, 1, 2].map(Value::from));

    // the heartbeat stops: the link and the vehicle OFFLINE within 3 s
    rov.order("stop-heartbeat");
    let stopped = rov.wait("heartbeat-stopped", second, |_| true);
    let last_heartbeat = Instant::now() - Duration::from_secs_f64(f(&stopped, "since_last"));
    let offline = spy.next("vehicle.health", second, |p| {
        p["components"]["ROV"] == "OFFLINE" && p["components"]["MavLink"] == "OFFLINE"
    });
    let took = last_heartbeat.elapsed();
    assert!(
        took < Duration::from_secs(3) + Duration::from_millis(300),
        "OFFLINE {took:?} after the last heartbeat: {offline}"
    );
    let state = spy.any("vehicle.state", second, |p| {
        p["control"] == "offline" && p["reason"] != "no vehicle heard yet"
    });
    assert!(
        state["reason"]
            .as_str()
            .is_some_and(|r| r.contains("vehicle 1 lost")),
        "{state}"
    );
    // and a command to it is refused at once, saying why
    command(&net, "cmd.arm", &["armed=true"], &[]);
    let refused = spy.any("cmd.status", second, |p| {
        p["command"] == "MAV_CMD_COMPONENT_ARM_DISARM"
            && p["state"] == "refused"
            && p["error"].as_str().is_some_and(|e| e.contains("lost"))
    });
    assert!(refused["id"].is_i64());
    // no heading was ever published: the ROV's hdg is unknown
    assert!(
        !spy.seen.iter().any(|v| v["topic"] == "nav.heading"),
        "a heading was published from an unknown hdg"
    );
}

#[test]
fn a_stick_stream_reaches_the_rov_at_its_rate_and_goes_neutral_once_when_it_stops() {
    let (mav_port, rov_port) = (free_port(), free_port());
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let (_dir, path) = system(mav_port, &net);
    let mut spy = Spy::new(&net);
    let _run = spawn_run(&path, &[]);
    let mut rov = PythonPeer::mavlink("mavlink_ardusub.py", rov_port, mav_port, 60);
    let second = Duration::from_secs(10);
    spy.health("ROV", "HEALTHY", second);

    // out of range: refused, and nothing reaches the ROV
    command(&net, "cmd.manual", &["x=1500", "y=0", "z=500", "r=0"], &[]);
    let refused = spy.status("MANUAL_CONTROL", "refused", second);
    assert!(
        refused["error"].as_str().is_some_and(|e| e.contains("x")),
        "{refused}"
    );
    // ArduSub's z is 0 to 1000: below is refused too
    command(&net, "cmd.manual", &["x=0", "y=0", "z=-20", "r=0"], &[]);
    let below = spy.any("cmd.status", second, |p| {
        p["command"] == "MANUAL_CONTROL"
            && p["state"] == "refused"
            && p["error"].as_str().is_some_and(|e| e.contains("`z` = -20"))
    });
    assert!(below["id"].is_i64());

    // a stick held: 10 commands at 10 Hz
    command(
        &net,
        "cmd.manual",
        &["x=250", "y=-100", "z=700", "r=50", "buttons=3"],
        &["--count", "10", "--rate", "10"],
    );
    let sent_at = Instant::now();
    // the stream ends; within the driver's 1 s, a neutral follows once
    let neutral = rov.wait("manual", Duration::from_secs(5), |v| v["x"] == 0);
    let neutral_after = sent_at.elapsed();
    rov.drain(Duration::from_millis(2500));
    let manuals = rov.all("manual");
    assert!(
        manuals.iter().all(|v| v["x"] != 1500 && v["z"] != -20),
        "a refused command reached the ROV: {manuals:?}"
    );
    let held: Vec<&Value> = manuals.iter().filter(|v| v["x"] == 250).collect();
    assert_eq!(held.len(), 10, "{manuals:?}");
    for v in &held {
        assert_eq!(
            (&v["y"], &v["z"], &v["r"], &v["buttons"], &v["target"]),
            (
                &Value::from(-100),
                &Value::from(700),
                &Value::from(50),
                &Value::from(3),
                &Value::from(1)
            )
        );
    }
    // at the rate sent: nine gaps of 100 ms
    let span = f(held[9], "t") - f(held[0], "t");
    assert!((0.6..1.3).contains(&span), "10 commands over {span} s");
    // neutral: x = y = r = 0, z = 500, no buttons; once, after the last held one
    assert_eq!(
        (
            &neutral["y"],
            &neutral["z"],
            &neutral["r"],
            &neutral["buttons"]
        ),
        (
            &Value::from(0),
            &Value::from(500),
            &Value::from(0),
            &Value::from(0)
        )
    );
    let neutrals = manuals.iter().filter(|v| v["x"] == 0).count();
    assert_eq!(neutrals, 1, "{manuals:?}");
    let gap = f(&neutral, "t") - f(held[9], "t");
    assert!(
        (0.9..1.6).contains(&gap),
        "neutral {gap} s after the last command (manual_timeout 1s)"
    );
    assert!(neutral_after < Duration::from_secs(4));
    let said = spy.any("cmd.status", second, |p| {
        p["command"] == "MANUAL_CONTROL"
            && p["error"]
                .as_str()
                .is_some_and(|e| e.contains("neutral sent"))
    });
    assert_eq!(said["state"], "sent");
}

#[test]
fn a_bad_parameter_is_refused_with_its_place_and_value() {
    for (attrs, line_col, why) in [
        (
            r#"water="brine""#,
            "3:53",
            "parameter `water`: `brine` is not `salt`, `fresh` or a density in kg/m³ from 900 to 1100",
        ),
        (
            r#"sysid="300""#,
            "3:53",
            "parameter `sysid`: `300` is not a vehicle's system id (1 to 255)",
        ),
        (
            r#"pressure="BAROMETER""#,
            "3:53",
            "parameter `pressure`: `BAROMETER` is not SCALED_PRESSURE, SCALED_PRESSURE2 or SCALED_PRESSURE3",
        ),
    ] {
        let text = format!(
            "<seabus node=\"rov\">\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"rov\" type=\"mavlink\" media=\"bus bus\" {attrs}/>\n</seabus>\n"
        );
        let (_dir, path) = system_file("system.xml", &text);
        let out = check(&path);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert_eq!(
            stderr.trim_end(),
            format!("{}:{line_col}: {why}", path.display()),
            "{attrs}"
        );
    }
}
