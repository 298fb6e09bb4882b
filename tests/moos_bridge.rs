//! A bridge between a seabus bus and a MOOSDB, run by `seabus run`: a route that keeps one field
//! renamed `value` makes it a MOOS double, a whole datamap becomes a key=value string, and a MOOS
//! app's double arrives on the bus as a named field.

mod common;
use common::*;
use seabus_medium::{DataMap, LinkState, Node};
use seabus_medium_moos::db::{Clock, MoosDb};
use seabus_medium_moos::wire::data;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn routes_map_datamaps_to_moos_doubles_and_strings_and_back() {
    let db = MoosDb::start("127.0.0.1:0".parse().unwrap()).await.unwrap();
    let port = db.addr().port();
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
    let _run = spawn_run(&path, &[]);
    let (_spy, rx) = spy_json(&bus, 30);
    let (_grid_spy, grid_rx) = spy_json(&grid, 30);

    // the gateway connects
    let deadline = Instant::now() + Duration::from_secs(10);
    while !db.clients().contains(&"seabus-gw".to_string()) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(
        db.clients().contains(&"seabus-gw".to_string()),
        "{:?}",
        db.clients()
    );

    // bus → MOOS: one field as a double, a whole datamap as a string
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
    let deadline = Instant::now() + Duration::from_secs(10);
    while (db.value("NAV_DEPTH").is_none() || db.value("VEHICLE_STATE").is_none())
        && Instant::now() < deadline
    {
        publish("nav.depth.filtered", &["depth=12.5", "vertical_speed=0.1"]);
        publish("vehicle.state", &["mode=survey", "control=in-control"]);
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    // every route that matches forwards, each with its own name and fields: two MOOS variables
    // of one topic, and two seabus topics on one medium (each a message of its own there)
    let deadline = Instant::now() + Duration::from_secs(10);
    while (db.value("NAV_X").is_none() || db.value("NAV_Y").is_none()) && Instant::now() < deadline
    {
        publish("nav.local", &["x=10.5", "y=-20.25"]);
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let x = db.value("NAV_X").expect("NAV_X reached the DB");
    let y = db.value("NAV_Y").expect("NAV_Y reached the DB");
    assert_eq!(
        (x.data_type, x.value, y.value),
        (data::DOUBLE, 10.5, -20.25)
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
    let depth = db.value("NAV_DEPTH").expect("NAV_DEPTH reached the DB");
    assert_eq!((depth.data_type, depth.value), (data::DOUBLE, 12.5));
    let state = db
        .value("VEHICLE_STATE")
        .expect("VEHICLE_STATE reached the DB");
    assert_eq!(state.data_type, data::STRING);
    assert_eq!(state.string, b"mode=survey,control=in-control");

    // MOOS → bus: an app's double arrives as a named field
    let app = schemes()
        .open(
            "app",
            &format!("moos://127.0.0.1:{port}?name=pHelm&register=NONE"),
            &Node::new("test"),
        )
        .unwrap();
    let mut link = app.watch_link();
    tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| *s == LinkState::Up),
    )
    .await
    .unwrap()
    .unwrap();
    let tx = app.attach("tx");
    let mut seen = Vec::new();
    let mut got = None;
    for _ in 0..50 {
        tx.send("DESIRED_DEPTH", DataMap::new().with("value", 5.0))
            .await
            .unwrap();
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(200)) {
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
