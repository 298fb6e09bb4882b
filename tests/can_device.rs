//! CAN devices from a DBC file, run by `seabus run` with python-can playing the thruster and the
//! battery pack on the other end of an slcan pseudo-terminal: their frames arrive on the bus as
//! named datamaps with the values computed by hand; a command on the bus leaves as the frame
//! computed by hand; a command out of range is refused on `cmd.status` with the reason.

mod common;
use common::*;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

/// The devices: send their frames every 100 ms until a thruster command arrives, print it, stop.
const DEVICES: &str = r#"
import can, json, sys, time
bus = can.Bus(interface="slcan", channel=sys.argv[1], bitrate=500000, sleep_after_open=0)
status = can.Message(arbitration_id=0x101, is_extended_id=False, data=bytes.fromhex("24fad20441020000"))
battery = can.Message(arbitration_id=0x18FF50E5, is_extended_id=True, data=bytes.fromhex("12c0ff83affb0000"))
deadline = time.time() + 30
while time.time() < deadline:
    bus.send(status)
    bus.send(battery)
    m = bus.recv(timeout=0.1)
    if m is not None and m.arbitration_id == 0x100:
        print(json.dumps({"id": m.arbitration_id, "data": bytes(m.data).hex()}), flush=True)
        break
bus.shutdown()
"#;

#[test]
fn dbc_devices_publish_their_messages_and_take_commands() {
    let configs = concat!(env!("CARGO_MANIFEST_DIR"), "/configs");
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="can-test">
  <medium name="bus" url="{bus}"/>
  <medium name="can" url="slcan+pty://{}"/>
  <module name="thruster" type="can-device" media="can bus" dbc="{configs}/can/vehicle.dbc" node="SEABUS"
          messages="ThrusterCommand, ThrusterStatus"/>
  <module name="battery" type="can-device" media="can bus" dbc="{configs}/can/vehicle.dbc" node="SEABUS"
          messages="BatteryStatus"/>
</seabus>"#,
        pty.display()
    );
    let path = dir.path().join("system.xml");
    std::fs::write(&path, system).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let (_spy, rx) = spy_json(&bus, 40);
    let _run = spawn_run(&path, &[]);
    // the pseudo-terminal appears when the system runs
    assert!(
        wait_for_path(&pty, Duration::from_secs(5)),
        "the pseudo-terminal {} appeared",
        pty.display()
    );
    let mut devices = Running(
        Command::new("python3")
            .args(["-c", DEVICES])
            .arg(&pty)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("python3 starts"),
    );
    let mut seen = Vec::new();
    let status = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(15),
        "thruster.ThrusterStatus",
        |v| v["topic"] == "thruster.ThrusterStatus",
    );
    let p = &status["payload"];
    assert_eq!(p["Rpm"], -1500, "{status}");
    assert!(
        (p["Current"].as_f64().unwrap() - 12.34).abs() < 1e-9,
        "{status}"
    );
    assert_eq!(p["Temperature"], 25, "{status}");
    assert_eq!(p["Fault_text"], "OverTemp", "{status}");
    let battery = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "battery.BatteryStatus",
        |v| v["topic"] == "battery.BatteryStatus",
    );
    let b = &battery["payload"];
    assert!(
        (b["Voltage"].as_f64().unwrap() - 48.0).abs() < 1e-9,
        "{battery}"
    );
    assert!(
        (b["Current"].as_f64().unwrap() + 12.5).abs() < 1e-9,
        "{battery}"
    );
    assert!(
        (b["StateOfCharge"].as_f64().unwrap() - 87.5).abs() < 1e-9,
        "{battery}"
    );
    assert_eq!(b["Temperature"], -5, "{battery}");

    // a command out of range is refused with the reason
    let publish = |args: &[&str]| {
        let out = seabus()
            .args(["pub", &bus, "thruster.ThrusterCommand"])
            .args(args)
            .arg("--command")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    publish(&["Mode=Rpm", "Rpm=3500"]);
    let refused = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "the refusal",
        |v| v["topic"] == "cmd.status" && v["payload"]["state"] == "refused",
    );
    assert_eq!(refused["payload"]["command"], "ThrusterCommand");
    assert_eq!(
        refused["payload"]["error"],
        "ThrusterCommand: signal `Rpm`: 3500 rpm is outside [-3000 … 3000]"
    );

    // a good command leaves as the frame computed by hand: Mode 1, Rpm 0x04B0, RampTime 25
    publish(&["Mode=Rpm", "Rpm=1200", "RampTime=2.5"]);
    let sent = wait_for_line(
        &rx,
        &mut seen,
        Duration::from_secs(10),
        "the command sent",
        |v| v["topic"] == "cmd.status" && v["payload"]["state"] == "sent",
    );
    assert_eq!(sent["payload"]["command"], "ThrusterCommand");
    let out = devices.0.stdout.take().unwrap();
    let line = BufReader::new(out)
        .lines()
        .map_while(Result::ok)
        .find(|l| l.starts_with('{'))
        .expect("the devices saw the command");
    let frame: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(frame["id"], 0x100);
    assert_eq!(frame["data"], "01b0041900000000");
    assert!(wait_for(&mut devices, Duration::from_secs(10)).is_some_and(|s| s.success()));
}
