//! The DSAAV configuration and logging servers run from a system file: a component elsewhere on
//! the backbone finds the configuration server by broadcast, reads its settings and logs at its
//! configured level into the central log, which `seabus log tail` follows.

mod common;
use common::*;
use seabus_dsaav::Database;
use seabus_dsaav::config_service::ConfigClient;
use seabus_dsaav::logging::{Level, Logger};
use seabus_dsaav::rpc::CallOptions;
use seabus_medium::Node;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn servers_from_a_system_file_configure_and_log_components() {
    let backbone = format!("dsaav+udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="vehicle">
  <medium name="bus" url="inproc://"/>
  <medium name="n1" url="{backbone}&amp;node=1"/>
  <module name="config" type="dsaav-config" medium="n1" config="starfish.ini" appdata="app.ini" port="2"/>
  <module name="log" type="dsaav-log" medium="n1" file="vehicle.log" port="0"/>
</seabus>"#
    );
    let (dir, path) = system_file("vehicle.xml", &system);
    let ini = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/starfish.ini"))
        .unwrap();
    std::fs::write(dir.path().join("starfish.ini"), &ini).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    assert!(
        !dir.path().join("vehicle.log").exists(),
        "checking creates nothing"
    );
    let mut run = spawn_run(&path, &[]);

    let me = schemes()
        .open("dsaav", &format!("{backbone}&node=5"), &Node::new("t"))
        .unwrap();
    let opts = CallOptions::default();
    let cfg = ConfigClient::discover(&me, 7, opts)
        .await
        .expect("the server is found");
    assert_eq!(cfg.server().to_string(), "1:2");
    assert_eq!(
        cfg.get_float("MyDepthController", "ControlGain")
            .await
            .unwrap(),
        2.3
    );

    // the logger gets its level and server from the configuration file
    let db = Database::parse("starfish.ini", &ini).unwrap();
    let logger = Logger::new(&me, 8, "MyDepthController", &db, opts).unwrap();
    assert_eq!(logger.level(), Level::Debug);
    logger.log(Level::Info, "controller up").await.unwrap();
    logger.log(Level::Debug, "gain 2.3").await.unwrap();

    let log = dir.path().join("vehicle.log");
    let tail = seabus()
        .args(["log", "tail"])
        .arg(&log)
        .args(["-n", "5", "--for", "1"])
        .output()
        .unwrap();
    assert!(tail.status.success());
    let text = String::from_utf8_lossy(&tail.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert!(
        lines[0].contains("INFO") && lines[0].ends_with("controller up"),
        "{text}"
    );
    assert!(
        lines[1].contains("DEBUG") && lines[1].ends_with("gain 2.3"),
        "{text}"
    );

    // and it follows what is written after it started
    let follow = seabus()
        .args(["log", "tail"])
        .arg(&log)
        .args(["-n", "0", "--for", "4"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    logger.log(Level::Warning, "depth jumped").await.unwrap();
    let started = Instant::now();
    let out = follow.wait_with_output().unwrap();
    assert!(started.elapsed() < Duration::from_secs(10));
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(text.lines().count(), 1, "{text}");
    assert!(
        text.contains("WARNING") && text.trim_end().ends_with("depth jumped"),
        "{text}"
    );

    terminate(&run);
    assert!(wait_for(&mut run, Duration::from_secs(5)).is_some());
}
