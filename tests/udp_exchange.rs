//! Two `seabus run` processes exchange messages over UDP on loopback; a third, `seabus spy --json`,
//! checks what crossed. Both stop on SIGTERM and SIGINT within two seconds and exit 0.

mod common;
use common::*;
use std::time::{Duration, Instant};

fn vehicle_side(net: &str) -> String {
    format!(
        r#"<seabus node="alpha">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="{net}"/>
  <module name="vehicle" type="vehicle-sim" medium="bus" tick="10Hz"/>
  <bridge name="link" media="bus net">
    <route from="bus" topics="nav.**"/>
    <route from="bus" topics="vehicle.**"/>
    <route from="bus" topics="cmd.status"/>
    <route from="net" topics="cmd.**" kind="command"/>
  </bridge>
</seabus>"#
    )
}

fn helm_side(net: &str) -> String {
    format!(
        r#"<seabus node="bravo">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="{net}"/>
  <module name="helm" type="square" medium="bus" tick="5Hz" heading="90" speed="1.2" side="1000"/>
  <module name="feet" type="convert" medium="bus" input="nav.depth" output="bravo.depth_ft"
          fields="depth*3.28084 as depth_ft" keep="false"/>
  <bridge name="link" media="bus net">
    <route from="bus" topics="cmd.**"/>
    <route from="bus" topics="bravo.**"/>
    <route from="net" topics="nav.**"/>
  </bridge>
</seabus>"#
    )
}

#[test]
fn two_processes_exchange_over_udp_and_a_third_sees_it() {
    let net = format!(
        "udp://{}:{}?ttl=0&amp;iface=127.0.0.1",
        group(),
        free_port()
    );
    let spy_url = net.replace("&amp;", "&");
    let (_d1, alpha) = system_file("alpha.xml", &vehicle_side(&net));
    let (_d2, bravo) = system_file("bravo.xml", &helm_side(&net));
    for f in [&alpha, &bravo] {
        assert_eq!(check(f).status.code(), Some(0));
    }
    let mut a = spawn_run(&alpha, &[]);
    let mut b = spawn_run(&bravo, &[]);
    let spy = succeeds(
        seabus().args(["spy", &spy_url, "--json", "--for", "4"]),
        "seabus spy",
    );

    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&spy.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("one JSON object per line"))
        .collect();
    let from = |topic: &str, origin: &str| -> Vec<&serde_json::Value> {
        lines
            .iter()
            .filter(|m| m["topic"] == topic && m["origin"] == origin)
            .collect()
    };
    // every line has the promised keys
    for m in &lines {
        for key in ["topic", "origin", "seq", "stamp", "payload"] {
            assert!(m.get(key).is_some(), "{key} missing in {m}");
        }
    }
    // bravo's helm commands reach the net
    let commands = from("cmd.course", "bravo/bus");
    assert!(
        !commands.is_empty(),
        "no course command from bravo in {} lines",
        lines.len()
    );
    assert_eq!(commands[0]["kind"], "command");
    assert_eq!(commands[0]["payload"]["heading"], 90.0);
    // alpha's vehicle received them: its state reports the commanded heading
    let states = from("vehicle.state", "alpha/bus");
    assert!(
        states
            .iter()
            .any(|s| s["payload"]["commanded_heading"] == 90.0),
        "alpha never reported following bravo's command: {states:?}"
    );
    // and answered each one it took on cmd.status, naming the command's origin and number
    let answers = from("cmd.status", "alpha/bus");
    let answered: Vec<(&str, i64)> = answers
        .iter()
        .map(|a| {
            assert_eq!(
                (&a["payload"]["command"], &a["payload"]["state"]),
                (
                    &serde_json::json!("course"),
                    &serde_json::json!("acknowledged")
                ),
                "{a}"
            );
            (
                a["payload"]["origin"].as_str().unwrap_or("?"),
                a["payload"]["request_seq"].as_i64().unwrap_or(-1),
            )
        })
        .collect();
    let sent: Vec<(&str, i64)> = commands
        .iter()
        .map(|c| ("bravo/bus", c["seq"].as_i64().unwrap()))
        .collect();
    // (commands sent before the spy listened are answered too, with lower numbers)
    let first = sent.iter().map(|(_, q)| *q).min().unwrap_or(i64::MAX);
    let unknown: Vec<&(&str, i64)> = answered
        .iter()
        .filter(|a| a.0 != "bravo/bus" || (a.1 >= first && !sent.contains(a)))
        .collect();
    assert_eq!(
        unknown,
        Vec::<&(&str, i64)>::new(),
        "answers to no command sent: {sent:?}"
    );
    assert!(
        answered.iter().filter(|a| sent.contains(a)).count() >= 2,
        "answers {answered:?} to the commands {sent:?}"
    );
    // bravo received alpha's depth and converted it
    let feet = from("bravo.depth_ft", "bravo/bus");
    assert!(!feet.is_empty(), "bravo never converted alpha's depth");
    assert!(feet[0]["payload"]["depth_ft"].is_number());
    // sequence numbers of one origin only grow, and nothing is seen twice
    let mut seqs: Vec<(String, u64)> = lines
        .iter()
        .map(|m| {
            (
                m["origin"].as_str().unwrap().to_string(),
                m["seq"].as_u64().unwrap(),
            )
        })
        .collect();
    let n = seqs.len();
    seqs.sort();
    seqs.dedup();
    assert_eq!(seqs.len(), n, "a message reached the spy twice");

    for (name, child) in [("alpha", &mut a), ("bravo", &mut b)] {
        terminate(child);
        let start = Instant::now();
        let status = wait_for(child, Duration::from_secs(5))
            .unwrap_or_else(|| panic!("{name} did not stop"));
        assert!(
            start.elapsed() < Duration::from_secs(2),
            "{name} took {:?} to stop",
            start.elapsed()
        );
        assert!(status.success(), "{name} exited with {status}");
    }
}

#[test]
fn ctrl_c_stops_a_running_system_within_two_seconds() {
    let (_d, path) = system_file(
        "s.xml",
        "<seabus><medium name=\"bus\" url=\"inproc://\"/>\
         <module name=\"v\" type=\"vehicle-sim\" medium=\"bus\" tick=\"50Hz\"/>\
         <module name=\"g\" type=\"generator\" medium=\"bus\" tick=\"100Hz\"/></seabus>",
    );
    let mut child = spawn_run(&path, &[]);
    std::thread::sleep(Duration::from_millis(500));
    assert!(child.try_wait().unwrap().is_none(), "still running");
    // SAFETY: kill(2) on our own child's pid
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
    let start = Instant::now();
    let status = wait_for(&mut child, Duration::from_secs(5)).expect("stops");
    assert!(
        start.elapsed() < Duration::from_secs(2),
        "took {:?}",
        start.elapsed()
    );
    assert!(status.success());
}

#[test]
fn run_for_stops_by_itself() {
    let (_d, path) = system_file(
        "s.xml",
        "<seabus><medium name=\"bus\" url=\"inproc://\"/></seabus>",
    );
    let mut child = spawn_run(&path, &["--for", "0.3"]);
    let status = wait_for(&mut child, Duration::from_secs(5)).expect("stops by itself");
    assert!(status.success());
}
