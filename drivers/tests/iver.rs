//! The Iver2 driver against the simulated frontseat over a real pseudo-terminal: states, course
//! commands that move the vehicle, acknowledgements, refusals with their reasons, commands left
//! unanswered timing out, the link lost and found again, and the Iver3 `$OSI` standing in for `$C`
//! and `$OPI` when they are not requested.

use seabus_medium::{DataMap, Interface, Medium, Message};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::time::Duration;
use tokio::time::{Instant, timeout};

fn registry() -> seabus_modules::Registry {
    let mut reg = seabus_modules::Registry::new();
    reg.set_schemes(seabus_medium_serial::schemes());
    seabus_drivers::register(&mut reg);
    reg
}

async fn start(text: &str) -> Runtime {
    let spec = SystemSpec::parse("test.xml", text).unwrap();
    Runtime::start(&spec, &registry(), Catalogue::built_in())
        .await
        .unwrap_or_else(|e| panic!("{e}"))
}

fn frontseat(path: &str) -> String {
    format!(
        r#"<seabus node="front">
  <medium name="line" url="pty://{path}"/>
  <module name="frontseat" type="iver2-sim" medium="line" lat="43.5" lon="16.4"/>
</seabus>"#
    )
}

fn backseat(path: &str) -> String {
    format!(
        r#"<seabus node="back">
  <medium name="bus" url="inproc://"/>
  <medium name="serial" url="serial://{path}?baud=19200&amp;reopen=100ms"/>
  <module name="iver" type="iver2" media="serial bus" request_every="200ms" data_timeout="1s" ack_timeout="2s"/>
</seabus>"#
    )
}

/// Waits (at most `limit`) for a message on `port` that `want` accepts.
/// A backseat on the serial end of `path` with an `iver2` driver of `attrs`, and an interface
/// watching its bus.
async fn watched_backseat(path: &str, attrs: &str) -> (Runtime, seabus_medium::Medium, Interface) {
    let back = start(&format!(
        r#"<seabus node="back">
  <medium name="bus" url="inproc://"/>
  <medium name="serial" url="serial://{path}?baud=19200&amp;reopen=100ms"/>
  <module name="iver" type="iver2" media="serial bus" {attrs}/>
</seabus>"#
    ))
    .await;
    let bus = back.medium("bus").unwrap().clone();
    let watch = bus
        .attach_with("watch", 1 << 16, 256)
        .subscribed("**")
        .unwrap();
    (back, bus, watch)
}

async fn wait_for(
    port: &mut Interface,
    limit: Duration,
    want: impl Fn(&Message) -> bool,
) -> Message {
    let deadline = Instant::now() + limit;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match timeout(left, port.recv()).await {
            Ok(Some(m)) if want(&m) => return m,
            Ok(Some(_)) => {}
            _ => panic!("nothing wanted arrived within {limit:?}"),
        }
    }
}

fn field<'m>(m: &'m Message, k: &str) -> Option<&'m seabus_medium::Value> {
    m.payload.as_map().and_then(|d| d.get(k))
}

fn text<'m>(m: &'m Message, k: &str) -> &'m str {
    field(m, k).and_then(|v| v.as_str()).unwrap_or("")
}

async fn status(port: &mut Interface, command: &str, state: &str) -> Message {
    wait_for(port, Duration::from_secs(5), |m| {
        m.topic.as_str() == "cmd.status"
            && text(m, "command") == command
            && text(m, "state") == state
    })
    .await
}

async fn control(port: &mut Interface, want: &str) -> Message {
    control_within(port, want, Duration::from_secs(5)).await
}

async fn control_within(port: &mut Interface, want: &str, limit: Duration) -> Message {
    wait_for(port, limit, |m| {
        m.topic.as_str() == "vehicle.state" && text(m, "control") == want
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_driver_commands_the_simulated_frontseat_over_a_pty() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frontseat").display().to_string();
    let front = start(&frontseat(&path)).await;
    let back = start(&backseat(&path)).await;
    let bus: Medium = back.medium("bus").unwrap().clone();
    let mut watch = bus
        .attach_with("watch", 1 << 16, 256)
        .subscribed("**")
        .unwrap();
    let cmd = bus.attach("operator");

    // the simulated frontseat starts stopped: the driver sees it idle and refuses a course
    let idle = control(&mut watch, "idle").await;
    assert_eq!(text(&idle, "mode"), "S");
    cmd.command(
        "cmd.course",
        DataMap::new()
            .with("heading", 90.0)
            .with("depth", 2.0)
            .with("speed", 1.5),
    )
    .await
    .unwrap();
    let refused = status(&mut watch, "OMS", "refused").await;
    assert!(text(&refused, "error").contains("stopped"), "{refused:?}");
    assert_eq!(text(&refused, "origin"), "back/bus");

    // a mission start goes out, is pending, then acknowledged
    cmd.command(
        "cmd.mission",
        DataMap::new().with("action", "start").with("name", "t.mis"),
    )
    .await
    .unwrap();
    status(&mut watch, "OMSTART", "pending").await;
    status(&mut watch, "OMSTART", "acknowledged").await;
    control(&mut watch, "accepting").await;

    // a course is taken, acknowledged, and moves the vehicle; the backseat is then in control
    cmd.command(
        "cmd.course",
        DataMap::new()
            .with("heading", 90.0)
            .with("depth", 2.0)
            .with("speed", 1.5)
            .with("timeout", 30.0),
    )
    .await
    .unwrap();
    status(&mut watch, "OMS", "acknowledged").await;
    let in_control = control(&mut watch, "in-control").await;
    assert_eq!(
        field(&in_control, "commanded_heading").and_then(|v| v.as_f64()),
        Some(90.0)
    );
    wait_for(&mut watch, Duration::from_secs(15), |m| {
        m.topic.as_str() == "nav.attitude"
            && field(m, "yaw")
                .and_then(|v| v.as_f64())
                .is_some_and(|y| y > 60.0)
    })
    .await;
    wait_for(&mut watch, Duration::from_secs(15), |m| {
        m.topic.as_str() == "nav.depth"
            && field(m, "depth")
                .and_then(|v| v.as_f64())
                .is_some_and(|d| d > 1.0)
    })
    .await;
    let battery = wait_for(&mut watch, Duration::from_secs(5), |m| {
        m.topic.as_str() == "power.battery"
    })
    .await;
    assert!(
        field(&battery, "percent")
            .and_then(|v| v.as_f64())
            .is_some_and(|p| p > 90.0)
    );

    // a course the frontseat finds bad comes back refused with the error's text
    cmd.command(
        "cmd.course",
        DataMap::new()
            .with("heading", 90.0)
            .with("depth", 2.0)
            .with("speed", 6.0),
    )
    .await
    .unwrap();
    let bad = status(&mut watch, "OMS", "refused").await;
    assert_eq!(text(&bad, "error"), "error 20: bad $OMS values");
    // and one the dataset forbids never leaves the backseat
    cmd.command(
        "cmd.course",
        DataMap::new()
            .with("heading", 400.0)
            .with("depth", 2.0)
            .with("speed", 1.0),
    )
    .await
    .unwrap();
    let invalid = status(&mut watch, "OMS", "refused").await;
    assert!(
        text(&invalid, "error").contains("`heading` = 400"),
        "{invalid:?}"
    );

    // the link goes: the frontseat is reported offline; it comes back: the driver recovers by itself
    front.shutdown().await;
    let offline = control(&mut watch, "offline").await;
    assert!(!text(&offline, "reason").is_empty());
    let front = start(&frontseat(&path)).await;
    let back_again = control(&mut watch, "idle").await;
    assert_eq!(
        text(&back_again, "mode"),
        "S",
        "a fresh simulator starts stopped"
    );
    assert_eq!(watch.stats().dropped_oldest, 0);
    front.shutdown().await;
    back.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn course_commands_keep_the_frontseat_alive_and_stop_when_they_stop() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frontseat").display().to_string();
    let front = start(&frontseat(&path)).await;
    let back = start(&backseat(&path)).await;
    let bus = back.medium("bus").unwrap().clone();
    let mut watch = bus
        .attach_with("watch", 1 << 16, 256)
        .subscribed("**")
        .unwrap();
    let cmd = bus.attach("operator");
    control(&mut watch, "idle").await;
    cmd.command("cmd.mission", DataMap::new().with("action", "start"))
        .await
        .unwrap();
    control(&mut watch, "accepting").await;
    // one course command valid for 2 s: the driver repeats $OMS (5 s keep-alive) for those 2 s only
    cmd.command(
        "cmd.course",
        DataMap::new()
            .with("heading", 45.0)
            .with("depth", 0.0)
            .with("speed", 1.0)
            .with("timeout", 2.0),
    )
    .await
    .unwrap();
    control(&mut watch, "in-control").await;
    // the last repeat goes out about 2 s in; the frontseat's 5 s keep-alive then lapses and the
    // simulated frontseat stops, about 7 s after the command and not before 5 s
    let started = Instant::now();
    let stopped = control_within(&mut watch, "idle", Duration::from_secs(15)).await;
    let waited = started.elapsed();
    assert_eq!(text(&stopped, "mode"), "S");
    assert!(
        waited >= Duration::from_secs(4),
        "stopped after only {waited:?}"
    );
    front.shutdown().await;
    back.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_compass_or_power_the_iver3_osi_gives_depth_battery_and_vehicle_info() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frontseat").display().to_string();
    let front = start(&format!(
        r#"<seabus node="front">
  <medium name="line" url="pty://{path}"/>
  <module name="frontseat" type="iver2-sim" medium="line" lat="43.5" lon="16.4" osi="iver3"/>
</seabus>"#
    ))
    .await;
    let (back, _bus, mut watch) = watched_backseat(
        &path,
        r#"request="G S" request_every="200ms" data_timeout="1s""#,
    )
    .await;
    let info = wait_for(&mut watch, Duration::from_secs(5), |m| {
        m.topic.as_str() == "vehicle.info"
    })
    .await;
    assert_eq!(
        (text(&info, "vehicle"), text(&info, "version")),
        ("iver2-sim", "5.0")
    );
    assert_eq!(
        (
            field(&info, "srp").and_then(|v| v.as_bool()),
            field(&info, "flag_20").and_then(|v| v.as_bool()),
            field(&info, "battery").and_then(|v| v.as_f64()),
        ),
        (Some(false), Some(false), Some(100.0))
    );
    // depth from $OSI: the simulated vehicle floats at the surface
    let depth = wait_for(&mut watch, Duration::from_secs(2), |m| {
        m.topic.as_str() == "nav.depth"
    })
    .await;
    assert_eq!(field(&depth, "depth").and_then(|v| v.as_f64()), Some(0.0));
    // the battery from the $OSI field: a percent, without the $OPI's volts
    let battery = wait_for(&mut watch, Duration::from_secs(2), |m| {
        m.topic.as_str() == "power.battery"
    })
    .await;
    assert_eq!(
        field(&battery, "percent").and_then(|v| v.as_f64()),
        Some(100.0)
    );
    assert!(field(&battery, "voltage").is_none(), "{battery:?}");
    // an $OSI every 200 ms, but vehicle.info only when it changes or every 5 s
    let (mut depths, mut infos) = (0, 0);
    let until = Instant::now() + Duration::from_secs(2);
    while let Ok(Some(m)) = tokio::time::timeout_at(until, watch.recv()).await {
        match m.topic.as_str() {
            "nav.depth" => depths += 1,
            "vehicle.info" => infos += 1,
            "nav.attitude" => panic!("no $C was requested: {m:?}"),
            _ => {}
        }
    }
    assert!(depths >= 5, "only {depths} depths in 2 s");
    assert_eq!(infos, 0, "vehicle.info repeated within 5 s");
    front.shutdown().await;
    back.shutdown().await;
}

/// A frontseat that sends its state and compass but acknowledges nothing: what the driver sends it
/// is handed back on the channel.
fn mute_frontseat(path: &str) -> (Medium, tokio::sync::mpsc::Receiver<String>) {
    use seabus_drivers::iver::protocol::{Compass, Osi};
    use seabus_medium::{Node, Payload};
    let line = seabus_medium_serial::schemes()
        .open(
            "mute",
            &format!("pty://{path}?framing=lines"),
            &Node::new("mute"),
        )
        .unwrap_or_else(|e| panic!("{e}"));
    let mut port = line.attach("frontseat").subscribed("**").unwrap();
    let (heard, hear) = tokio::sync::mpsc::channel(256);
    let osi = Osi {
        fins: "8080808080".into(),
        mode: "S".into(),
        next_waypoint: Some(1),
        lat: Some(43.5),
        lon: Some(16.4),
        speed_knots: Some(0.0),
        distance_to_waypoint: Some(0.0),
        error: "N".into(),
        altimeter_feet: Some(30.0),
        park_time: None,
        declination: Some(0.0),
        mission: "mute.mis".into(),
        remaining: Some(0.0),
        heading: Some(10.0),
        depth_feet: Some(0.0),
        iver3: None,
        extra: Vec::new(),
    }
    .sentence();
    let compass = Compass {
        heading: 10.0,
        pitch: 0.0,
        roll: 0.0,
        temperature: Some(15.0),
        depth_feet: Some(0.0),
    }
    .sentence();
    tokio::spawn(async move {
        // at most 30 s of 100 ms rounds
        for _ in 0..300 {
            for s in [&osi, &compass] {
                let _ = port
                    .send("out", Payload::from(s.clone().into_bytes()))
                    .await;
            }
            let until = Instant::now() + Duration::from_millis(100);
            while let Ok(Some(m)) = tokio::time::timeout_at(until, port.recv()).await {
                let text =
                    String::from_utf8_lossy(m.payload.as_bytes().map_or(&[][..], |b| &b[..]))
                        .to_string();
                let _ = heard.try_send(text);
            }
        }
    });
    (line, hear)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_command_the_frontseat_never_acknowledges_times_out() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frontseat").display().to_string();
    let (_front, mut heard) = mute_frontseat(&path);
    let (back, bus, mut watch) = watched_backseat(
        &path,
        r#"request_every="200ms" data_timeout="1s" ack_timeout="500ms""#,
    )
    .await;
    control(&mut watch, "idle").await;
    bus.attach("operator")
        .command("cmd.mission", DataMap::new().with("action", "start"))
        .await
        .unwrap();
    status(&mut watch, "OMSTART", "pending").await;
    let late = status(&mut watch, "OMSTART", "timed-out").await;
    assert_eq!(text(&late, "error"), "no $ACK within 0.5s", "{late:?}");
    // the command did go out on the line: it was the frontseat that kept quiet
    let deadline = Instant::now() + Duration::from_secs(2);
    let mut went_out = false;
    while let Ok(Some(line)) = tokio::time::timeout_at(deadline, heard.recv()).await {
        if line.starts_with("$OMSTART") {
            went_out = true;
            break;
        }
    }
    assert!(went_out, "no $OMSTART reached the frontseat");
    back.shutdown().await;
}
