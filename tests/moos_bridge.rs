//! A bridge between a seabus bus and a real MOOSDB (core-moos), run by `seabus run`: a route that
//! keeps one field renamed `value` makes it a MOOS double, a whole datamap becomes a key=value
//! string (as a libMOOS app reads them), and a libMOOS app's double arrives on the bus as a named
//! field. And, against seabus's own small MOOSDB (which can be made to read a client's name late,
//! as no real DB can be told to), `seabus pub` waits for the DB and stamps what it sends as sent.

mod common;
use common::*;
use seabus_medium_moos::db::{Clock, MoosDb};
use seabus_medium_moos::wire::data;
use std::time::{Duration, Instant};

#[test]
fn routes_map_datamaps_to_moos_doubles_and_strings_and_back() {
    let db = common::moos::MoosDb::start();
    let port = db.port;
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let grid = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="gw">
  <medium name="bus" url="{bus}"/>
  <medium name="shore" url="moos://127.0.0.1:{port}?name=seabus-gw&amp;register=DESIRED_DEPTH"/>
  <bridge name="to-shore" media="bus shore" report="0">
    <route from="bus" to="shore" topics="nav.depth.filtered" rename="NAV_DEPTH" keep="false">
      <field name="depth" rename="value"/>
    </route>
    <route from="bus" to="shore" topics="vehicle.state" rename="VEHICLE_STATE"/>
    <route from="shore" to="bus" topics="DESIRED_DEPTH" rename="cmd.depth" keep="false">
      <field name="value" rename="depth"/>
    </route>
    <route from="bus" to="shore" topics="nav.local" rename="NAV_X" keep="false">
      <field name="x" rename="value"/>
    </route>
    <route from="bus" to="shore" topics="nav.local" rename="NAV_Y" keep="false">
      <field name="y" rename="value"/>
    </route>
  </bridge>
  <medium name="grid" url="{grid}"/>
  <bridge name="to-grid" media="bus grid" report="0">
    <route from="bus" to="grid" topics="nav.local" rename="grid.east" keep="false">
      <field name="x" rename="metres"/>
    </route>
    <route from="bus" to="grid" topics="nav.local" rename="grid.north" keep="false">
      <field name="y" rename="metres"/>
    </route>
  </bridge>
</seabus>"#
    );
    let (_dir, path) = system_file("gw.xml", &system);
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let wanted = ["NAV_DEPTH", "VEHICLE_STATE", "NAV_X", "NAV_Y"];
    let (_watch, moos) = common::moos::moos_watch(port, "uWatch", 40, &wanted);
    let _run = spawn_run(&path, &[]);
    let (_spy, rx) = spy_json(&bus, 30);
    let (_grid_spy, grid_rx) = spy_json(&grid, 30);

    // bus → MOOS: one field as a double, a whole datamap as a string; every route that matches
    // forwards, each with its own name and fields: two MOOS variables of one topic, and two
    // seabus topics on one medium (each a message of its own there)
    let publish = |topic: &str, fields: &[&str]| {
        let out = seabus()
            .args(["pub", &bus, topic])
            .args(fields)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    while !wanted.iter().all(|w| got.iter().any(|(k, _)| k == w)) && Instant::now() < deadline {
        publish("nav.depth.filtered", &["depth=12.5", "vertical_speed=0.1"]);
        publish("vehicle.state", &["mode=survey", "control=in-control"]);
        publish("nav.local", &["x=10.5", "y=-20.25"]);
        got.extend(common::moos::moos_received(
            &moos,
            Duration::from_millis(300),
            |_| false,
        ));
    }
    let value = |var: &str| {
        got.iter()
            .find(|(k, _)| k == var)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| panic!("{var} reached the MOOSDB: {got:?}"))
    };
    use common::moos::MoosValue;
    assert_eq!(value("NAV_X"), MoosValue::Double(10.5));
    assert_eq!(value("NAV_Y"), MoosValue::Double(-20.25));
    assert_eq!(value("NAV_DEPTH"), MoosValue::Double(12.5));
    assert_eq!(
        value("VEHICLE_STATE"),
        MoosValue::Text("mode=survey,control=in-control".into())
    );
    let mut seen = Vec::new();
    let east = wait_for_line(
        &grid_rx,
        &mut seen,
        Duration::from_secs(5),
        "grid.east",
        |v| v["topic"] == "grid.east",
    );
    let north = match seen.iter().find(|v| v["topic"] == "grid.north") {
        Some(v) => v.clone(),
        None => wait_for_line(
            &grid_rx,
            &mut seen,
            Duration::from_secs(5),
            "grid.north",
            |v| v["topic"] == "grid.north",
        ),
    };
    assert_eq!(
        (&east["payload"], &north["payload"]),
        (
            &serde_json::json!({"metres": 10.5}),
            &serde_json::json!({"metres": -20.25})
        )
    );

    // MOOS → bus: a libMOOS app's double arrives as a named field
    let mut seen = Vec::new();
    let mut got = None;
    for _ in 0..20 {
        common::moos::moos_notify(port, "pHelm", &[("DESIRED_DEPTH", MoosValue::Double(5.0))]);
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(500)) {
            if v["topic"] == "cmd.depth" {
                got = Some(v);
                break;
            }
            seen.push(v);
        }
    }
    let v = got.unwrap_or_else(|| {
        wait_for_line(&rx, &mut seen, Duration::from_secs(5), "cmd.depth", |v| {
            v["topic"] == "cmd.depth"
        })
    });
    assert_eq!(v["payload"], serde_json::json!({"depth": 5.0}), "{v}");
}

/// `seabus pub` on a `moos://` medium waits for the connection to the DB, and what it sent is
/// written before it exits: one run, one value in the DB. The DB reads the client's name 100 ms
/// late, as a MOOSDB does; the value is stamped with the time it was sent all the same (the DB
/// runs on this host: its clock is ours), not 100 ms ahead.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pub_waits_for_the_moosdb_and_sends_before_exiting() {
    let slow = Clock {
        ahead: 0.0,
        welcome_delay: Duration::from_millis(100),
    };
    let db = MoosDb::start_with("127.0.0.1:0".parse().unwrap(), slow)
        .await
        .unwrap();
    let now = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64()
    };
    let started = now();
    let url = format!("moos://127.0.0.1:{}?name=cli", db.addr().port());
    let out = tokio::task::spawn_blocking(move || {
        seabus()
            .args(["pub", &url, "NAV_X", "value=4.5"])
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let deadline = Instant::now() + Duration::from_secs(2);
    while db.value("NAV_X").is_none() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let x = db.value("NAV_X").expect("NAV_X reached the DB");
    let ended = now();
    assert_eq!(
        (x.data_type, x.value, x.source.as_slice()),
        (data::DOUBLE, 4.5, &b"cli"[..])
    );
    assert!(
        x.time >= started && x.time <= ended,
        "stamped {:.4} s after pub started, {:.4} s after it ended",
        x.time - started,
        x.time - ended
    );
}
