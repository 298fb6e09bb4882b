//! The shipped `configs/mavlink-moos.xml` run by `seabus run`: a MAVLink ROV (pymavlink as an
//! ArduSub vehicle, `tests/peers/mavlink_ardusub.py`) on UDP, its depth from the external pressure
//! sensor and its heading carried into a MOOSDB as the MOOS-IvP doubles NAV_DEPTH and NAV_HEADING,
//! and its state as a string. Only the ports differ from the file.

mod common;
use common::*;
use seabus_medium_moos::db::MoosDb;
use seabus_medium_moos::wire::data;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mavlink_rov_s_depth_and_heading_reach_moos() {
    let db = MoosDb::start("127.0.0.1:0".parse().unwrap()).await.unwrap();
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
            &format!("moos://127.0.0.1:{}", db.addr().port()),
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
    let _run = spawn_run(&path, &[]);
    let rov_port = free_port();
    let _rov = PythonPeer::mavlink("mavlink_ardusub.py", rov_port, mav_port, 30);
    let deadline = Instant::now() + Duration::from_secs(15);
    while ["NAV_DEPTH", "NAV_HEADING", "VEHICLE_STATE"]
        .iter()
        .any(|v| db.value(v).is_none())
        && Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // SCALED_PRESSURE2 at 1515.0 hPa, sea water (1025 kg/m³), the surface at 1013.25 hPa
    let depth = db.value("NAV_DEPTH").expect("NAV_DEPTH reached the MOOSDB");
    assert_eq!(depth.data_type, data::DOUBLE);
    let expected = (1515.0 - 1013.25) * 100.0 / (1025.0 * 9.80665);
    assert!(
        (depth.value - expected).abs() < 1e-6,
        "NAV_DEPTH {} m, expected {expected} m",
        depth.value
    );
    // ATTITUDE's yaw of -1.57 rad as a heading in degrees, 0 to 360
    let heading = db
        .value("NAV_HEADING")
        .expect("NAV_HEADING reached the MOOSDB");
    assert_eq!(heading.data_type, data::DOUBLE);
    let expected = (-1.57f32 as f64).to_degrees().rem_euclid(360.0);
    assert!(
        (heading.value - expected).abs() < 1e-3,
        "NAV_HEADING {}, expected {expected}",
        heading.value
    );
    let state = db
        .value("VEHICLE_STATE")
        .expect("VEHICLE_STATE reached the MOOSDB");
    assert_eq!(state.data_type, data::STRING);
    let text = String::from_utf8_lossy(&state.string);
    assert!(text.contains("mode=MANUAL"), "{text}");
}
