//! UDP broadcast between two hosts: two network namespaces of our own joined by a veth pair. One runs
//! a system that broadcasts a generator's messages; `seabus spy` in the other sees them.
//!
//! Needs root and `ip` (iproute2). Without them it fails with the reason when
//! `SEABUS_REQUIRE_PRIVILEGES` is set (as `scripts/test` does as root), and otherwise says
//! plainly on stderr that it was skipped.

mod common;
use common::*;
use std::process::Command;
use std::time::Duration;

#[test]
fn broadcast_reaches_another_host() {
    let Some(hosts) = Hosts::for_test("broadcast_reaches_another_host") else {
        return;
    };
    let port = 40_000 + u16::from(hosts.subnet) * 7;
    let url = format!("udp://10.77.{}.255:{port}?broadcast", hosts.subnet);
    let (_dir, path) = system_file(
        "caster.xml",
        &format!(
            r#"<seabus node="caster">
  <medium name="bus" url="inproc://"/>
  <medium name="lan" url="{url}"/>
  <module name="gen" type="generator" medium="bus" topic="test.cast" tick="20Hz"/>
  <bridge name="out" media="bus lan"><route from="bus" topics="test.**"/></bridge>
</seabus>"#
        ),
    );
    let exe = env!("CARGO_BIN_EXE_seabus");
    let mut caster = Command::new("ip")
        .args(["netns", "exec", &hosts.a, exe, "run"])
        .arg(&path)
        .args(["--for", "10"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("ip netns exec runs");
    let spy = Command::new("ip")
        .args([
            "netns", "exec", &hosts.b, exe, "spy", &url, "--json", "--for", "2",
        ])
        .output()
        .expect("spy runs");
    // `ip netns exec` runs seabus in its own place: the signal reaches seabus
    terminate(&caster);
    let status = wait_for(&mut caster, Duration::from_secs(5));
    assert!(
        spy.status.success(),
        "{}",
        String::from_utf8_lossy(&spy.stderr)
    );
    let got: Vec<serde_json::Value> = String::from_utf8_lossy(&spy.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .filter(|m: &serde_json::Value| m["topic"] == "test.cast")
        .collect();
    assert!(got.len() >= 10, "saw {} broadcast messages", got.len());
    assert!(
        got.iter()
            .all(|m| m["origin"] == "caster/bus" && m["hops"] == 1)
    );
    assert!(
        status.is_some_and(|s| s.success()),
        "the caster stops on SIGTERM"
    );
}
