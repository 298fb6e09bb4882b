//! The paper's UDP bridge between two hosts: the vehicle (raw Ethernet DSAAV, with its
//! configuration server and the bridge) in one network namespace, control stations in the other
//! reaching it over UDP. An allowed station finds the configuration server by broadcast and reads
//! a setting; a station whose address is not on the allow-list gets nothing.
//!
//! Needs root and `ip` (iproute2). Without them it fails with the reason when
//! `SEABUS_REQUIRE_PRIVILEGES` is set (as `scripts/test` does as root), and otherwise says
//! plainly on stderr that it was skipped.

mod common;
use common::*;
use seabus_dsaav::config_service::ConfigClient;
use seabus_dsaav::rpc::CallOptions;
use seabus_medium::Node;
use std::process::{Command, Stdio};
use std::time::Duration;

/// As a station in namespace `ns` bound to `me`, finds the configuration server through the
/// bridge at `bridge` and reads MyDepthController's ControlGain.
fn station(ns: String, me: String, bridge: String, node: u16) -> Result<f64, String> {
    std::thread::spawn(move || {
        enter_namespace(&ns).map_err(|e| e.to_string())?;
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| e.to_string())?;
        rt.block_on(async move {
            let url = format!("dsaav+udp://{me}?peer={bridge}&node={node}");
            let m = schemes()
                .open("wifi", &url, &Node::new("station"))
                .map_err(|e| e.to_string())?;
            let opts = CallOptions {
                timeout: Duration::from_secs(3),
                ..CallOptions::default()
            };
            let cfg = ConfigClient::discover(&m, 7, opts)
                .await
                .map_err(|e| e.to_string())?;
            cfg.get_float("MyDepthController", "ControlGain")
                .await
                .map_err(|e| e.to_string())
        })
    })
    .join()
    .map_err(|_| "the station thread panicked".to_string())?
}

#[test]
fn stations_on_the_allow_list_reach_the_vehicle_over_udp() {
    let Some(hosts) = Hosts::for_test("stations_on_the_allow_list_reach_the_vehicle_over_udp")
    else {
        return;
    };
    let s = hosts.subnet;
    // a second address on the station host, not on the allow-list
    ip(&[
        "-n",
        &hosts.b,
        "addr",
        "add",
        &format!("10.77.{s}.3/24"),
        "dev",
        &hosts.dev_b,
    ])
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let ini = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/starfish.ini"))
        .unwrap();
    std::fs::write(dir.path().join("starfish.ini"), ini).unwrap();
    let vehicle = format!(
        r#"<seabus node="vehicle">
  <medium name="bus" url="inproc://"/>
  <medium name="n1" url="dsaav+eth://{dev}?node=1"/>
  <medium name="vehicle" url="dsaav+eth://{dev}?relay"/>
  <medium name="stations" url="dsaav+udp://10.77.{s}.1:47999?relay"/>
  <module name="config" type="dsaav-config" medium="n1" config="starfish.ini" appdata="{app}" port="2"/>
  <module name="wifi" type="dsaav-udp-bridge" media="vehicle stations bus" allow="10.77.{s}.2"/>
</seabus>"#,
        dev = hosts.dev_a,
        app = dir.path().join("app.ini").display()
    );
    let path = dir.path().join("vehicle.xml");
    std::fs::write(&path, vehicle).unwrap();
    let mut run = Running(
        Command::new("ip")
            .args([
                "netns",
                "exec",
                &hosts.a,
                env!("CARGO_BIN_EXE_seabus"),
                "run",
            ])
            .arg(&path)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("the vehicle starts"),
    );
    std::thread::sleep(Duration::from_millis(500));
    let bridge = format!("10.77.{s}.1:47999");
    let allowed = station(
        hosts.b.clone(),
        format!("10.77.{s}.2:47998"),
        bridge.clone(),
        100,
    );
    assert_eq!(allowed, Ok(2.3));
    let refused = station(hosts.b.clone(), format!("10.77.{s}.3:47998"), bridge, 101);
    assert!(
        refused.as_ref().is_err_and(|e| e.contains("no reply")),
        "a station off the allow-list reached the vehicle: {refused:?}"
    );
    terminate(&run);
    assert!(wait_for(&mut run, Duration::from_secs(5)).is_some());
}
