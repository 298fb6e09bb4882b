//! DSAAV IComms over raw Ethernet between two hosts: two network namespaces of our own joined by a
//! veth pair. `seabus pub` on node 1 in one sends to node 2; `seabus spy` on node 2 in the other
//! sees the message, decoded through the dictionary.
//!
//! Needs root and `ip` (iproute2). Without them it fails with the reason when
//! `SEABUS_REQUIRE_PRIVILEGES` is set (as `scripts/test` does as root), and otherwise says
//! plainly on stderr that it was skipped.

mod common;
use common::*;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

#[test]
fn an_icomms_message_crosses_raw_ethernet_to_another_host() {
    let Some(hosts) = Hosts::for_test("an_icomms_message_crosses_raw_ethernet_to_another_host")
    else {
        return;
    };
    let exe = env!("CARGO_BIN_EXE_seabus");
    let mut spy = Command::new("ip")
        .args(["netns", "exec", &hosts.a, exe, "spy"])
        .arg(format!("dsaav+eth://{}?node=2", hosts.dev_a))
        .args(["--json", "--for", "10"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spy starts");
    let mut sender = Command::new("ip")
        .args(["netns", "exec", &hosts.b, exe, "pub"])
        .arg(format!("dsaav+eth://{}?node=1&port=3", hosts.dev_b))
        .args([
            "dsaav.data",
            "depth=3.5",
            "component=\"DepthSensor\"",
            "@dst=2:0",
        ])
        .args(["--count", "50", "--rate", "10"])
        .stdout(Stdio::null())
        .spawn()
        .expect("pub starts");
    let mut line = String::new();
    BufReader::new(spy.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let _ = sender.kill();
    let _ = sender.wait();
    let _ = spy.kill();
    let _ = spy.wait();
    let msg: serde_json::Value = serde_json::from_str(&line)
        .unwrap_or_else(|e| panic!("spy printed a message as JSON ({e}): {line:?}"));
    assert_eq!(msg["topic"], "dsaav.data");
    assert_eq!(msg["origin"], "dsaav@1/spy");
    assert_eq!(msg["payload"]["@src"], "1:3");
    assert_eq!(msg["payload"]["@dst"], "2:0");
    assert_eq!(msg["payload"]["depth"], 3.5);
    assert_eq!(msg["payload"]["component"], "DepthSensor");
}
