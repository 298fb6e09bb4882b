//! A route's `rate` over UDP, end to end: a 10 Hz source through routes limited to 5 and 3 a
//! second arrives at a spy at those rates; a route without a limit passes the source's rate.

mod common;
use common::*;
use std::time::{Duration, Instant};

#[test]
fn a_10_hz_source_crosses_a_udp_bridge_at_its_routes_rates() {
    let port = free_port();
    let system = format!(
        r#"<seabus node="rate-src">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="udp://0.0.0.0:0?peer=127.0.0.1:{port}"/>
  <module name="vehicle" type="vehicle-sim" medium="bus" tick="10Hz"/>
  <bridge name="uplink" media="bus net">
    <route from="bus" to="net" topics="nav.depth" rate="5"/>
    <route from="bus" to="net" topics="nav.attitude" rate="3"/>
    <route from="bus" to="net" topics="nav.velocity"/>
  </bridge>
</seabus>
"#
    );
    let (_dir, path) = system_file("rate.xml", &system);
    let (_spy, rx) = spy_json(&format!("udp://127.0.0.1:{port}"), 20);
    let _run = spawn_run(&path, &["--for", "18"]);
    // arrival times of each topic, from the first message on for 14 s
    let mut arrivals: std::collections::HashMap<String, Vec<Instant>> = Default::default();
    let first = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("the bridge's traffic reaches the spy");
    let start = Instant::now();
    let mut note = |v: &serde_json::Value, at: Instant| {
        if let Some(t) = v["topic"].as_str() {
            arrivals.entry(t.to_string()).or_default().push(at);
        }
    };
    note(&first, start);
    while start.elapsed() < Duration::from_secs(14) {
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(100)) {
            note(&v, Instant::now());
        }
    }
    // messages a second over the 10 s from 3 s after the first message
    let rate = |topic: &str| {
        let (from, to) = (
            start + Duration::from_secs(3),
            start + Duration::from_secs(13),
        );
        let times = arrivals.get(topic).map_or(&[][..], Vec::as_slice);
        times.iter().filter(|t| **t >= from && **t < to).count() as f64 / 10.0
    };
    let (depth, attitude, velocity) = (
        rate("nav.depth"),
        rate("nav.attitude"),
        rate("nav.velocity"),
    );
    assert!(
        (velocity - 10.0).abs() <= 0.5,
        "the source: {velocity}/s, not 10"
    );
    assert!((depth - 5.0).abs() <= 0.25, "rate 5: {depth}/s");
    assert!((attitude - 3.0).abs() <= 0.15, "rate 3: {attitude}/s");
}
