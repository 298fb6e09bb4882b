//! The shipped `configs/mavlink-moos.xml` run by `seabus run`: a MAVLink ROV (pymavlink as an
//! ArduSub vehicle, `tests/peers/mavlink_ardusub.py`) on UDP, its depth from the external pressure
//! sensor and its heading carried into a real MOOSDB (core-moos) as the MOOS-IvP doubles NAV_DEPTH
//! and NAV_HEADING, and its state as a string, as a libMOOS app reads them. Only the ports differ
//! from the file.

mod common;
use common::moos::*;
use common::*;
use std::time::Duration;

#[test]
fn a_mavlink_rov_s_depth_and_heading_reach_moos() {
    let db = MoosDb::start();
    let configs = concat!(env!("CARGO_MANIFEST_DIR"), "/configs");
    let shipped = std::fs::read_to_string(format!("{configs}/mavlink-moos.xml")).unwrap();
    let mav_port = free_port();
    let text = shipped
        .replace(
            "mavlink://udpin:0.0.0.0:14550",
            &format!("mavlink://udpin:127.0.0.1:{mav_port}"),
        )
        .replace(
            "moos://127.0.0.1:9000",
            &format!("moos://127.0.0.1:{}", db.port),
        );
    assert_ne!(text, shipped, "the ports are where the test expects them");
    let (dir, path) = system_file("mavlink-moos.xml", &text);
    std::fs::copy(
        format!("{configs}/mavlink-health.xml"),
        dir.path().join("mavlink-health.xml"),
    )
    .unwrap();
    let checked = check(&path);
    assert_eq!(checked.status.code(), Some(0), "{}", stderr(&checked));
    let (_watch, rx) = moos_watch(
        db.port,
        "uWatch",
        40,
        &["NAV_DEPTH", "NAV_HEADING", "VEHICLE_STATE"],
    );
    let _run = spawn_run(&path, &[]);
    let rov_port = free_port();
    let _rov = PythonPeer::mavlink("mavlink_ardusub.py", rov_port, mav_port, 30);
    let got = moos_received(&rx, Duration::from_secs(20), |g| {
        ["NAV_DEPTH", "NAV_HEADING", "VEHICLE_STATE"]
            .iter()
            .all(|v| g.iter().any(|(k, _)| k == v))
    });
    let value = |var: &str| {
        got.iter()
            .rev()
            .find(|(k, _)| k == var)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| panic!("{var} reached the MOOSDB: {got:?}"))
    };
    // SCALED_PRESSURE2 at 1515.0 hPa, sea water (1025 kg/m³), the surface at 1013.25 hPa
    let MoosValue::Double(depth) = value("NAV_DEPTH") else {
        panic!("NAV_DEPTH is a double: {got:?}")
    };
    let expected = (1515.0 - 1013.25) * 100.0 / (1025.0 * 9.80665);
    assert!(
        (depth - expected).abs() < 1e-6,
        "NAV_DEPTH {depth} m, expected {expected} m"
    );
    // ATTITUDE's yaw of -1.57 rad as a heading in degrees, 0 to 360
    let MoosValue::Double(heading) = value("NAV_HEADING") else {
        panic!("NAV_HEADING is a double: {got:?}")
    };
    let expected = (-1.57f32 as f64).to_degrees().rem_euclid(360.0);
    assert!(
        (heading - expected).abs() < 1e-3,
        "NAV_HEADING {heading}, expected {expected}"
    );
    let MoosValue::Text(text) = value("VEHICLE_STATE") else {
        panic!("VEHICLE_STATE is a string: {got:?}")
    };
    assert!(text.contains("mode=MANUAL"), "{text}");
}
