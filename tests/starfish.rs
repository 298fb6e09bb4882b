//! The STARFISH paper's depth-control example run by `seabus run`: the controller holds the
//! vehicle at its target depth through the filter, plumbed only by the configuration file; the same
//! components run unchanged in-process, over UDP, and over raw Ethernet between two network
//! namespaces; changing only the configuration makes the controller read the sensor straight.
//!
//! The raw Ethernet run needs root and `ip` (iproute2): without them it fails with the reason
//! when `SEABUS_REQUIRE_PRIVILEGES` is set, and otherwise says plainly on stderr that it was skipped.

mod common;
use common::*;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const TARGET: f64 = 5.0;

/// The module lines of the example, nodes named `n1` … `n5`, files in `dir`.
fn modules(dir: &Path, which: &[&str]) -> String {
    let lines = [
        (
            "config",
            format!(
                r#"<module name="config" type="dsaav-config" medium="n1" config="starfish.ini" appdata="{}" port="2"/>"#,
                dir.join("app.ini").display()
            ),
        ),
        (
            "log",
            format!(
                r#"<module name="log" type="dsaav-log" medium="n1" file="{}" port="0"/>"#,
                dir.join("vehicle.log").display()
            ),
        ),
        (
            "vehicle",
            r#"<module name="vehicle" type="starfish-vehicle-sim" media="n2 n4" depth="10" rate="0.2"/>"#
                .to_string(),
        ),
        (
            "filter",
            r#"<module name="filter" type="depth-filter" medium="n3"/>"#.to_string(),
        ),
        (
            "controller",
            format!(r#"<module name="controller" type="depth-controller" medium="n5" target="{TARGET}"/>"#),
        ),
    ];
    lines
        .iter()
        .filter(|(n, _)| which.contains(n))
        .map(|(_, l)| format!("  {l}\n"))
        .collect()
}

fn system(url: impl Fn(u16) -> String, nodes: &[u16], modules: &str) -> String {
    let media: String = nodes
        .iter()
        .map(|n| format!("  <medium name=\"n{n}\" url=\"{}\"/>\n", url(*n)))
        .collect();
    format!("<seabus node=\"starfish\">\n{media}{modules}</seabus>\n")
}

/// Writes the paper's configuration (with `[Depth]` served from `depth_server`) into `dir`.
fn configuration(dir: &Path, depth_server: &str) {
    let ini = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/starfish.ini"))
        .expect("configs/starfish.ini");
    let ini = ini.replace(
        "Server = 3:0                  # depth from node 3",
        &format!("Server = {depth_server}                  # depth from node 3"),
    );
    std::fs::write(dir.join("starfish.ini"), ini).unwrap();
}

/// What the controller logged: where it read depth from, and the depths it saw.
fn controller_log(dir: &Path) -> (String, Vec<f64>) {
    let text = std::fs::read_to_string(dir.join("vehicle.log")).unwrap_or_default();
    let plumbing = text
        .lines()
        .find_map(|l| l.split("depth from ").nth(1))
        .map(|s| s.split(',').next().unwrap_or("").to_string())
        .unwrap_or_default();
    let depths = text
        .lines()
        .filter_map(|l| l.split("depth=").nth(1))
        .filter_map(|s| s.split_whitespace().next()?.parse().ok())
        .collect();
    (plumbing, depths)
}

fn assert_held(dir: &Path, from: &str) {
    let (plumbing, depths) = controller_log(dir);
    assert_eq!(plumbing, from, "the controller's depth server");
    assert!(depths.len() > 20, "the controller ran: {depths:?}");
    let last = depths[depths.len() - 1];
    assert!(
        (last - TARGET).abs() < 0.5,
        "held at {last} m, target {TARGET} m; depths {depths:?}"
    );
    assert!(depths[0] > 9.0, "it started at 10 m: {depths:?}");
}

fn run_for(path: &Path, secs: &str) {
    let status = seabus()
        .args(["run"])
        .arg(path)
        .args(["--for", secs])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
}

#[test]
fn the_depth_is_held_in_process_through_the_filter() {
    let dir = tempfile::tempdir().unwrap();
    configuration(dir.path(), "3:0");
    let all = ["config", "log", "vehicle", "filter", "controller"];
    let text = system(
        |n| format!("dsaav+inproc://starfish?node={n}"),
        &[1, 2, 3, 4, 5],
        &modules(dir.path(), &all),
    );
    let path = dir.path().join("starfish.xml");
    std::fs::write(&path, text).unwrap();
    run_for(&path, "8");
    assert_held(dir.path(), "3:0");
}

#[test]
fn the_same_components_run_over_udp_and_the_configuration_replumbs_them() {
    let dir = tempfile::tempdir().unwrap();
    // the controller reads the sensor straight: only the configuration changed
    configuration(dir.path(), "4:0");
    let (g, p) = (group(), free_port());
    let all = ["config", "log", "vehicle", "filter", "controller"];
    let text = system(
        |n| format!("dsaav+udp://{g}:{p}?ttl=0&amp;node={n}"),
        &[1, 2, 3, 4, 5],
        &modules(dir.path(), &all),
    );
    let path = dir.path().join("starfish.xml");
    std::fs::write(&path, text).unwrap();
    run_for(&path, "8");
    assert_held(dir.path(), "4:0");
}

#[test]
fn the_same_components_run_over_raw_ethernet_between_two_hosts() {
    let Some(hosts) =
        Hosts::for_test("the_same_components_run_over_raw_ethernet_between_two_hosts")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    configuration(dir.path(), "3:0");
    // host a: configuration, logging and the vehicle; host b: filter and controller
    let a = system(
        |n| format!("dsaav+eth://{}?node={n}", hosts.dev_a),
        &[1, 2, 4],
        &modules(dir.path(), &["config", "log", "vehicle"]),
    );
    let b = system(
        |n| format!("dsaav+eth://{}?node={n}", hosts.dev_b),
        &[3, 5],
        &modules(dir.path(), &["filter", "controller"]),
    );
    let (pa, pb) = (dir.path().join("a.xml"), dir.path().join("b.xml"));
    std::fs::write(&pa, a).unwrap();
    std::fs::write(&pb, b).unwrap();
    let exe = env!("CARGO_BIN_EXE_seabus");
    let start = |ns: &str, path: &Path, secs: &str| {
        Command::new("ip")
            .args(["netns", "exec", ns, exe, "run"])
            .arg(path)
            .args(["--for", secs])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("seabus run starts")
    };
    let mut host_a = start(&hosts.a, &pa, "10");
    std::thread::sleep(Duration::from_millis(300));
    let mut host_b = start(&hosts.b, &pb, "9");
    assert!(wait_for(&mut host_b, Duration::from_secs(20)).is_some_and(|s| s.success()));
    assert!(wait_for(&mut host_a, Duration::from_secs(20)).is_some_and(|s| s.success()));
    assert_held(dir.path(), "3:0");
}

#[test]
fn sentuators_reach_the_bus_as_datasets_and_take_actuator_commands() {
    let dir = tempfile::tempdir().unwrap();
    configuration(dir.path(), "3:0");
    let ini = dir.path().join("starfish.ini");
    let text = std::fs::read_to_string(&ini).unwrap();
    std::fs::write(
        &ini,
        text.replace(
            "Server = 4:0                  # driver on node 4, port 0",
            "Server = 4:0\nListeners = 6:1",
        ),
    )
    .unwrap();
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let dsaav = system(
        |n| format!("dsaav+inproc://starfish?node={n}"),
        &[1, 2, 4, 6],
        &modules(dir.path(), &["config", "log", "vehicle"]),
    );
    let text = dsaav.replace(
        "<seabus node=\"starfish\">\n",
        &format!(
            "<seabus node=\"starfish\">\n  <medium name=\"bus\" url=\"inproc://\"/>\n  \
             <medium name=\"net\" url=\"{net}\"/>\n  \
             <module name=\"sentuators\" type=\"dsaav-sentuators\" media=\"bus n6\" port=\"1\" elevators=\"2:0\"/>\n  \
             <bridge name=\"out\" media=\"bus net\" report=\"0\">\n    \
             <route from=\"bus\" to=\"net\" topics=\"nav.**\"/>\n    \
             <route from=\"net\" to=\"bus\" topics=\"cmd.**\" kind=\"command\"/>\n  </bridge>\n"
        ),
    );
    let path = dir.path().join("starfish.xml");
    std::fs::write(&path, text).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let _run = spawn_run(&path, &[]);
    let spy = |secs: &str| {
        let out = seabus()
            .args([
                "spy",
                &net,
                "--json",
                "--topics",
                "nav.depth",
                "--for",
                secs,
            ])
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .filter_map(|v| v["payload"]["depth"].as_f64())
            .collect::<Vec<f64>>()
    };
    // the depth sensor's notifications arrive as the depth dataset; the vehicle holds 10 m
    let before = spy("2");
    assert!(before.len() > 5, "nav.depth from the sensor: {before:?}");
    assert!(before.iter().all(|d| (d - 10.0).abs() < 1e-9), "{before:?}");
    // an actuator command on the bus sets the elevators: nose up, the vehicle rises
    let sent = seabus()
        .args([
            "pub",
            &net,
            "cmd.actuator",
            "thrust=0",
            "elevator=10",
            "--command",
        ])
        .status()
        .unwrap();
    assert!(sent.success());
    let after = spy("2");
    assert!(
        after.last().is_some_and(|d| *d < 9.5),
        "the vehicle rises after the elevator command: {after:?}"
    );
}
