//! The MAVLink medium against pymavlink, an independent MAVLink implementation standing in for an
//! ArduSub ROV on UDP loopback (`tests/peers/mavlink_vehicle.py`): `seabus spy` shows its
//! messages with their values, a command sent with `seabus pub` reaches it and its acknowledgement
//! comes back, it hears seabus's heartbeat with the URL's ids, the link goes down when its
//! heartbeat stops, and corrupt frames are counted by reason while good frames after them still
//! arrive.

mod common;
use common::*;
use seabus_medium::{LinkState, Medium, Node};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::process::Stdio;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The payload of the first spy line on `topic` that `pred` accepts.
fn spied(
    rx: &mpsc::Receiver<Value>,
    seen: &mut Vec<Value>,
    topic: &str,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    if let Some(v) = seen.iter().find(|v| v["topic"] == topic && pred(v)) {
        return v.clone();
    }
    wait_for_line(rx, seen, Duration::from_secs(10), topic, |v| {
        v["topic"] == topic && pred(v)
    })
}

const ARM: [&str; 11] = [
    "target_system=1",
    "target_component=1",
    "command=MAV_CMD_COMPONENT_ARM_DISARM",
    "confirmation=0",
    "param1=1",
    "param2=0",
    "param3=0",
    "param4=0",
    "param5=0",
    "param6=0",
    "param7=0",
];

#[test]
fn spy_shows_an_ardusub_vehicle_and_pub_arms_it() {
    let (spy_port, vehicle_port) = (free_port(), free_port());
    let url = format!("mavlink://udpin:127.0.0.1:{spy_port}?sysid=250&compid=191");
    let (spy, rx) = spy_json(&url, 30);
    let origin = format!("spy-{}/spy", spy.id());
    let mut vehicle = PythonPeer::mavlink("mavlink_vehicle.py", vehicle_port, spy_port, 40);
    let mut seen = Vec::new();

    // the vehicle's messages, with its values, originating at the spy's medium
    let att = spied(&rx, &mut seen, "mavlink.1.ATTITUDE", |_| true);
    assert_eq!(
        (&att["kind"], &att["origin"], &att["hops"]),
        (&json!("data"), &json!(origin), &json!(0))
    );
    let p = &att["payload"];
    assert_eq!(
        [
            &p["roll"],
            &p["pitch"],
            &p["yaw"],
            &p["rollspeed"],
            &p["yawspeed"]
        ],
        [
            &json!(0.1),
            &json!(-0.05),
            &json!(1.57),
            &json!(0.01),
            &json!(-0.02)
        ],
        "{att}"
    );
    assert!(p["time_boot_ms"].as_i64().is_some(), "{att}");
    assert_eq!((&p["sysid"], &p["compid"]), (&json!(1), &json!(1)));
    let pos = spied(&rx, &mut seen, "mavlink.1.GLOBAL_POSITION_INT", |_| true);
    let p = &pos["payload"];
    assert_eq!(
        [
            &p["lat"],
            &p["lon"],
            &p["alt"],
            &p["relative_alt"],
            &p["vx"],
            &p["vy"],
            &p["vz"],
            &p["hdg"]
        ],
        [
            &json!(435081000),
            &json!(164402000),
            &json!(-12500),
            &json!(-12500),
            &json!(10),
            &json!(-5),
            &json!(2),
            &json!(9000)
        ],
        "{pos}"
    );
    let pressure = spied(&rx, &mut seen, "mavlink.1.SCALED_PRESSURE", |_| true);
    let p = &pressure["payload"];
    assert_eq!(
        [&p["press_abs"], &p["press_diff"], &p["temperature"]],
        [&json!(2250.5), &json!(0.0), &json!(1850)],
        "{pressure}"
    );
    let status = spied(&rx, &mut seen, "mavlink.1.SYS_STATUS", |_| true);
    let p = &status["payload"];
    assert_eq!(
        [
            &p["voltage_battery"],
            &p["current_battery"],
            &p["battery_remaining"],
            &p["load"],
            &p["onboard_control_sensors_present"]
        ],
        [
            &json!(15800),
            &json!(420),
            &json!(76),
            &json!(250),
            &json!("MAV_SYS_STATUS_SENSOR_3D_GYRO | MAV_SYS_STATUS_SENSOR_3D_ACCEL")
        ],
        "{status}"
    );
    let hb = spied(&rx, &mut seen, "mavlink.1.HEARTBEAT", |_| true);
    let p = &hb["payload"];
    assert_eq!(
        [
            &p["type"],
            &p["autopilot"],
            &p["base_mode"],
            &p["custom_mode"],
            &p["system_status"]
        ],
        [
            &json!("MAV_TYPE_SUBMARINE"),
            &json!("MAV_AUTOPILOT_ARDUPILOTMEGA"),
            &json!("MAV_MODE_FLAG_CUSTOM_MODE_ENABLED"),
            &json!(19),
            &json!("MAV_STATE_ACTIVE")
        ],
        "{hb}"
    );
    let listed = spied(&rx, &mut seen, "mavlink.vehicles", |_| true);
    let p = &listed["payload"];
    assert_eq!(
        [
            &p["sysid"],
            &p["compid"],
            &p["type"],
            &p["autopilot"],
            &p["armed"],
            &p["custom_mode"],
            &p["alive"]
        ],
        [
            &json!(1),
            &json!(1),
            &json!("MAV_TYPE_SUBMARINE"),
            &json!("MAV_AUTOPILOT_ARDUPILOTMEGA"),
            &json!(false),
            &json!(19),
            &json!(true)
        ],
        "{listed}"
    );
    assert!(
        p["last_heard"].as_f64().is_some_and(|t| t > 1.7e9),
        "{listed}"
    );

    // pymavlink hears the spy's heartbeat, with the URL's ids: a ground station (MAV_TYPE_GCS = 6)
    // without an autopilot (MAV_AUTOPILOT_INVALID = 8)
    let heard = vehicle.wait("heartbeat", Duration::from_secs(10), |v| v["sysid"] == 250);
    assert_eq!(
        (&heard["compid"], &heard["type"], &heard["autopilot"]),
        (&json!(191), &json!(6), &json!(8))
    );

    // a command without a field is refused by the medium (exit 3), naming the field
    let to = format!("mavlink://udpout:127.0.0.1:{vehicle_port}");
    let refused = seabus()
        .args(["pub", &to, "mavlink.1.COMMAND_LONG"])
        .args(&ARM[..10])
        .arg("--command")
        .output()
        .expect("seabus pub runs");
    assert_eq!(refused.status.code(), Some(3));
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(
        said.contains("COMMAND_LONG: missing field `param7`"),
        "{said}"
    );

    // seabus pub arms it: pymavlink gets the command from pub's ids and acknowledges it
    let mut publish = Running(
        seabus()
            .args(["pub", &to, "mavlink.1.COMMAND_LONG"])
            .args(ARM)
            .arg("--command")
            .stderr(Stdio::piped())
            .spawn()
            .expect("seabus pub runs"),
    );
    let status = wait_for(&mut publish, Duration::from_secs(15));
    let mut said = String::new();
    if let Some(mut err) = publish.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut err, &mut said);
    }
    assert!(status.is_some_and(|s| s.success()), "seabus pub: {said}");
    let command = vehicle.wait("command", Duration::from_secs(10), |_| true);
    assert_eq!(
        [
            &command["sysid"],
            &command["compid"],
            &command["command"],
            &command["target_system"],
            &command["target_component"],
            &command["param1"]
        ],
        [
            &json!(255),
            &json!(190),
            &json!(400),
            &json!(1),
            &json!(1),
            &json!(1.0)
        ]
    );
    let ack = spied(&rx, &mut seen, "mavlink.1.COMMAND_ACK", |_| true);
    let p = &ack["payload"];
    assert_eq!(
        [
            &p["command"],
            &p["result"],
            &p["target_system"],
            &p["target_component"]
        ],
        [
            &json!("MAV_CMD_COMPONENT_ARM_DISARM"),
            &json!("MAV_RESULT_ACCEPTED"),
            &json!(255),
            &json!(190)
        ],
        "{ack}"
    );
    // and its next heartbeat says it is armed
    let armed = spied(&rx, &mut seen, "mavlink.vehicles", |v| {
        v["payload"]["armed"] == true
    });
    assert_eq!(armed["payload"]["sysid"], 1);
}

/// The first message on `topic` at `port` whose datamap `pred` accepts, within `limit`.
fn message(
    rt: &tokio::runtime::Runtime,
    port: &mut seabus_medium::Interface,
    limit: Duration,
    pred: impl Fn(&seabus_medium::DataMap) -> bool,
) -> seabus_medium::DataMap {
    let deadline = Instant::now() + limit;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match rt.block_on(tokio::time::timeout(left, port.recv())) {
            Ok(Some(m)) => {
                let map = m.payload.as_map().expect("a datamap").clone();
                if pred(&map) {
                    return map;
                }
            }
            Ok(None) => panic!("the medium closed"),
            Err(_) => panic!("no such message within {limit:?}"),
        }
    }
}

/// Waits at most `limit` for the link to be in a state `pred` accepts.
fn link(
    rt: &tokio::runtime::Runtime,
    medium: &Medium,
    limit: Duration,
    pred: impl Fn(&LinkState) -> bool,
) -> LinkState {
    let mut watch = medium.watch_link();
    match rt.block_on(tokio::time::timeout(limit, watch.wait_for(|s| pred(s)))) {
        Ok(Ok(s)) => s.clone(),
        _ => panic!("the link stayed {:?} for {limit:?}", medium.link_state()),
    }
}

#[test]
fn corrupt_frames_are_counted_and_a_silent_vehicle_takes_the_link_down() {
    let rt = tokio::runtime::Runtime::new().expect("a runtime");
    let _inside = rt.enter();
    let (port, vehicle_port) = (free_port(), free_port());
    let medium = seabus_medium_mavlink::schemes()
        .open(
            "rov",
            &format!("mavlink://udpin:127.0.0.1:{port}"),
            &Node::new("test"),
        )
        .expect("the medium opens");
    let mut attitudes = medium
        .attach("test")
        .subscribed("mavlink.1.ATTITUDE")
        .unwrap();
    let mut vehicles = medium
        .attach("vehicles")
        .subscribed("mavlink.vehicles")
        .unwrap();
    let mut vehicle = PythonPeer::mavlink("mavlink_vehicle.py", vehicle_port, port, 40);
    link(&rt, &medium, Duration::from_secs(10), |s| {
        *s == LinkState::Up
    });
    message(&rt, &mut attitudes, Duration::from_secs(5), |_| true);
    assert!(medium.stats().rejected.is_empty());

    // a frame with a bad checksum, one of an unknown message, one cut off and garbage, then a
    // good ATTITUDE: each counted under its reason, and the good frame arrives
    vehicle.order("corrupt");
    vehicle.wait("corrupt-sent", Duration::from_secs(5), |_| true);
    message(&rt, &mut attitudes, Duration::from_secs(5), |m| {
        m.get_i64("time_boot_ms") == Some(424_242)
    });
    let stats = medium.stats();
    let expected: BTreeMap<String, u64> = [
        ("bad-crc", 1),
        ("garbage", 1),
        ("truncated", 1),
        ("unknown-message", 1),
    ]
    .into_iter()
    .map(|(k, n)| (k.to_string(), n))
    .collect();
    assert_eq!(stats.rejected, expected);
    // two whole ATTITUDE frames of 40 bytes, a frame cut after 14 and 22 bytes of garbage
    assert_eq!(stats.dropped_bytes, 40 + 40 + 14 + 22);
    assert_eq!(medium.link_state(), LinkState::Up);

    // the heartbeat stops (the rest goes on): the link goes down 3 s after the last one came,
    // within 3 s of the heartbeat stopping
    vehicle.order("stop-heartbeat");
    vehicle.wait("heartbeat-stopped", Duration::from_secs(5), |_| true);
    let stopped = Instant::now();
    let down = link(&rt, &medium, Duration::from_secs(5), |s| {
        *s != LinkState::Up
    });
    let down_at = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("after 1970")
        .as_secs_f64();
    let after = stopped.elapsed().as_secs_f64();
    assert_eq!(
        down,
        LinkState::Down("no heartbeat from the vehicle (system 1, component 1) for 3s".into())
    );
    assert!(after < 3.5, "down {after:.2} s after the heartbeat stopped");
    let silent = message(&rt, &mut vehicles, Duration::from_secs(5), |m| {
        m.get_bool("alive") == Some(false)
    });
    let last = silent
        .get_f64("last_heard")
        .expect("when it was last heard");
    let quiet = down_at - last;
    assert!(
        (2.95..3.6).contains(&quiet),
        "down {quiet:.2} s after the last heartbeat came"
    );
    // its other messages still come
    message(&rt, &mut attitudes, Duration::from_secs(5), |_| true);
    assert!(matches!(medium.link_state(), LinkState::Down(_)));
}
