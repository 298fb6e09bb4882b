//! The Foxglove live view of `seabus demo` against the official protocol library
//! (`@foxglove/ws-protocol` in Node, `tests/peers/foxglove_client.js`): the channels advertised
//! with their JSON Schemas, Foxglove's well-known messages beside them, twenty messages of the
//! position and the attitude whose values are those `seabus spy` sees on the demo's uplink, a
//! command the server does not take refused with a status, and one it takes sent on the bus.
//!
//! Needs Node with `@foxglove/ws-protocol` and `ws`, which `scripts/test` installs under
//! `target/node-foxglove` (named in `SEABUS_FOXGLOVE_NODE`).

mod common;
use common::*;
use serde_json::Value as Json;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// Where `@foxglove/ws-protocol` and `ws` are: `SEABUS_FOXGLOVE_NODE`, else where `scripts/test`
/// puts them.
fn node_modules() -> PathBuf {
    let modules = match std::env::var_os("SEABUS_FOXGLOVE_NODE") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-foxglove/node_modules"),
    };
    assert!(
        modules.join("@foxglove/ws-protocol/package.json").is_file() && modules.join("ws").is_dir(),
        "@foxglove/ws-protocol and ws are not in {}: run ./scripts/test, which installs them",
        modules.display()
    );
    modules
}

/// Whether two JSON values hold the same values, numbers compared as numbers (JavaScript writes the
/// float 0.0 as `0`).
fn same_values(a: &Json, b: &Json) -> bool {
    match (a, b) {
        (Json::Number(x), Json::Number(y)) => x.as_f64() == y.as_f64(),
        (Json::Object(x), Json::Object(y)) => {
            x.len() == y.len()
                && x.iter()
                    .all(|(k, v)| y.get(k).is_some_and(|w| same_values(v, w)))
        }
        (Json::Array(x), Json::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(v, w)| same_values(v, w))
        }
        _ => a == b,
    }
}

/// The demo's uplink: every bus topic, as the demo's system file says.
const UPLINK: &str = "udp://239.255.42.1:47800?ttl=0";

#[test]
fn foxglove_s_own_client_sees_the_demo_s_channels_values_and_command_rules() {
    let modules = node_modules();
    let mut demo = Running(
        seabus()
            .args(["demo", "--for", "40"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the demo starts"),
    );
    let (tx, rx) = mpsc::channel();
    let err = demo.0.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    let url = loop {
        let line = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("the demo prints its Foxglove URL within 20 s");
        if let Some(rest) = line.trim().strip_prefix("Foxglove: ") {
            break rest.split_whitespace().next().unwrap().to_string();
        }
    };
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");
    let (_spy, seen) = spy_json(UPLINK, 40);
    std::thread::sleep(Duration::from_millis(300));

    let client = Command::new("node")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/foxglove_client.js"))
        .args([
            &url,
            "20",
            "nav.position",
            "nav.attitude",
            "foxglove/nav.position",
        ])
        .env("NODE_PATH", &modules)
        .output()
        .expect("node runs");
    assert!(
        client.status.success(),
        "{}{}",
        String::from_utf8_lossy(&client.stderr),
        String::from_utf8_lossy(&client.stdout)
    );
    let got: Json = serde_json::from_slice(&client.stdout).unwrap();
    // the library offers only the protocol's first name, and the server takes it
    assert_eq!(got["protocol"], "foxglove.websocket.v1");
    // a client offering the name Foxglove's SDK gives it is served the same
    let sdk = Command::new("node")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/foxglove_client.js"))
        .args([&url, "3", "nav.position"])
        .env("NODE_PATH", &modules)
        .env("FOXGLOVE_OFFER", "foxglove.sdk.v1")
        .output()
        .expect("node runs");
    assert!(
        sdk.status.success(),
        "{}",
        String::from_utf8_lossy(&sdk.stderr)
    );
    let sdk: Json = serde_json::from_slice(&sdk.stdout).unwrap();
    assert_eq!(sdk["protocol"], "foxglove.sdk.v1");
    let n = sdk["messages"]["nav.position"]
        .as_array()
        .map_or(0, Vec::len);
    assert!(n >= 3, "{n} positions");

    let channel = |topic: &str| -> &Json {
        got["channels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["topic"] == topic)
            .unwrap_or_else(|| panic!("`{topic}` is not advertised: {}", got["channels"]))
    };
    let position = channel("nav.position");
    assert_eq!(
        (
            &position["encoding"],
            &position["schemaName"],
            &position["schemaEncoding"]
        ),
        (
            &Json::from("json"),
            &Json::from("seabus.position"),
            &Json::from("jsonschema")
        )
    );
    let schema: Json = serde_json::from_str(position["schema"].as_str().unwrap()).unwrap();
    assert_eq!(schema["properties"]["lat"]["type"], "number");
    // lat is required: in its place, or (NaN, ±inf) under `$nonfinite`
    assert!(
        schema["allOf"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!({"anyOf": [
                {"required": ["lat"]},
                {"required": ["$nonfinite"], "properties": {"$nonfinite": {"required": ["lat"]}}},
            ]})),
        "{schema}"
    );
    assert_eq!(channel("nav.attitude")["schemaName"], "seabus.attitude");
    let fix = channel("foxglove/nav.position");
    assert_eq!(
        (&fix["schemaName"], &fix["encoding"]),
        (&Json::from("foxglove.LocationFix"), &Json::from("protobuf"))
    );
    assert_eq!(
        channel("foxglove/tf")["schemaName"],
        "foxglove.FrameTransform"
    );
    assert_eq!(
        got["messages"]["foxglove/nav.position"]
            .as_array()
            .unwrap()
            .len(),
        20
    );

    // every message the client decoded is one the spy saw on the uplink: same stamp, same values
    let mut spied: Vec<Json> = Vec::new();
    for topic in ["nav.position", "nav.attitude"] {
        let messages = got["messages"][topic].as_array().unwrap();
        assert_eq!(messages.len(), 20, "{topic}");
        for m in messages {
            let ns: i64 = m["timestamp"].as_str().unwrap().parse().unwrap();
            let same = |v: &Json| {
                v["topic"] == topic
                    && v["stamp"]
                        .as_f64()
                        .is_some_and(|s| ((s * 1e9) as i64 - ns).abs() < 2_000)
            };
            let spy = match spied.iter().find(|v| same(v)) {
                Some(v) => v.clone(),
                None => wait_for_line(&seen, &mut spied, Duration::from_secs(5), topic, same),
            };
            assert!(
                same_values(&spy["payload"], &m["data"]),
                "{topic} at {ns}: the spy saw {}, the client got {}",
                spy["payload"],
                m["data"]
            );
        }
    }

    // the server takes cmd.course only; the course reached the bus as a command
    let statuses = got["statuses"].as_array().unwrap();
    assert_eq!(statuses.len(), 1, "{statuses:?}");
    assert_eq!(
        statuses[0]["message"],
        "refused: `cmd.mission` is not a command this server takes (it takes: cmd.course)"
    );
    let is_course = |v: &Json| v["topic"] == "cmd.course" && v["payload"]["heading"] == 123.0;
    // the spy may have read it already, while the values were being matched
    let course = match spied.iter().find(|v| is_course(v)) {
        Some(v) => v.clone(),
        None => wait_for_line(
            &seen,
            &mut spied,
            Duration::from_secs(5),
            "the client's course on the bus",
            is_course,
        ),
    };
    assert_eq!(course["kind"], "command");
    assert_eq!(course["payload"]["speed"], 1.25);
    assert!(
        spied.iter().all(|v| v["topic"] != "cmd.mission"),
        "a refused command never reaches the bus"
    );
}

#[test]
fn a_quiet_topic_is_unadvertised_junk_is_answered_or_disconnected_and_shown_in_the_log_panel() {
    let modules = node_modules();
    let bus = format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port());
    let text = format!(
        r#"<seabus node="view">
  <medium name="bus" url="{}"/>
  <foxglove listen="127.0.0.1:0" medium="bus" unadvertise="1s"/>
</seabus>"#,
        bus.replace('&', "&amp;")
    );
    let (_dir, path) = system_file("view.xml", &text);
    let mut run = spawn_run(&path, &["--for", "30"]);
    let err = run.0.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    let url = loop {
        let line = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("seabus run prints its Foxglove URL within 20 s");
        if let Some(rest) = line.trim().strip_prefix("Foxglove: ") {
            break rest.split_whitespace().next().unwrap().to_string();
        }
    };
    let mut watcher = Command::new("node")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/foxglove_watch.js"))
        .args([&url, "3"])
        .env("NODE_PATH", &modules)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("node runs");
    // the watch starts once both its connections are open
    let mut watched = BufReader::new(watcher.stdout.take().unwrap());
    let mut first = String::new();
    watched.read_line(&mut first).unwrap();
    assert_eq!(first.trim(), "watching", "the watcher connects");
    // a burst on one topic, the other topic steady for the whole watch
    let burst = seabus()
        .args([
            "pub",
            &bus,
            "lab.burst",
            "n=1",
            "--count",
            "10",
            "--rate",
            "20",
        ])
        .output()
        .unwrap();
    assert!(burst.status.success(), "{}", stderr(&burst));
    let steady = seabus()
        .args([
            "pub",
            &bus,
            "lab.steady",
            "n=2",
            "--count",
            "40",
            "--rate",
            "10",
        ])
        .output()
        .unwrap();
    assert!(steady.status.success(), "{}", stderr(&steady));
    // the watch ends with the steady topic's last message, before the sweep could take it
    let mut input = watcher.stdin.take().unwrap();
    writeln!(input, "lab.steady 39").unwrap();
    drop(input);
    let mut rest = String::new();
    watched.read_to_string(&mut rest).unwrap();
    let out = watcher.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let got: Json = serde_json::from_str(&rest).unwrap();
    let events = got["events"].as_array().unwrap();
    let of = |topic: &str, event: &str| -> Vec<u64> {
        events
            .iter()
            .filter(|e| e["topic"] == topic && e["event"] == event)
            .map(|e| e["t"].as_u64().unwrap())
            .collect()
    };
    let burst_messages: Vec<u64> = got["messages"]["lab.burst"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_u64().unwrap())
        .collect();
    // the message that makes a topic appear is served before any client can have subscribed to
    // its new channel: every other one arrives
    assert_eq!(burst_messages.len(), 9, "{got}");
    assert_eq!(of("lab.burst", "advertise").len(), 1, "{events:?}");
    let gone = of("lab.burst", "unadvertise");
    assert_eq!(
        gone.len(),
        1,
        "the quiet topic is unadvertised once: {events:?}"
    );
    let quiet_for = gone[0] - burst_messages.last().unwrap();
    assert!(
        (900..=2_600).contains(&quiet_for),
        "unadvertised {quiet_for} ms after its last message (unadvertise=1s, swept each second)"
    );
    // the steady topic kept its channel and its messages throughout the junk
    assert!(of("lab.steady", "unadvertise").is_empty(), "{events:?}");
    assert_eq!(got["messages"]["lab.steady"].as_array().unwrap().len(), 39);
    let junk = &got["junk"];
    assert!(junk["sent"].as_u64().unwrap() >= 10, "{junk}");
    assert_eq!(
        junk["statuses"], junk["sent"],
        "every malformed message answered with an error status on its own connection, kept open"
    );
    let closed = junk["closed_at"]
        .as_u64()
        .expect("the garbage closed the connection") as i64
        - junk["garbage_at"].as_i64().unwrap();
    assert!(
        (0..2_000).contains(&closed),
        "closed {closed} ms after bytes that are no frame"
    );
    // seabus counted the server's reports and logged each kind once in the watch (one line per
    // 10 s), also to Foxglove's Log panel as `foxglove.Log`
    let mut said = Vec::new();
    while let Ok(line) = rx.recv_timeout(Duration::from_millis(500)) {
        said.push(line);
    }
    let lines_with = |what: &str| said.iter().filter(|l| l.contains(what)).count();
    assert_eq!(lines_with("malformed message"), 1, "{said:#?}");
    assert_eq!(lines_with("broken connection"), 1, "{said:#?}");
    let logs = got["logs"].as_array().unwrap();
    let malformed = logs
        .iter()
        .find(|l| l["message"].as_str().unwrap().contains("malformed message"))
        .unwrap_or_else(|| panic!("a Log message of the malformed messages: {logs:#?}"));
    assert_eq!(malformed["level"], "WARNING", "{malformed}");
    assert_eq!(
        malformed["name"], "view",
        "named after the node: {malformed}"
    );
    assert!(
        malformed["file"].as_str().unwrap().ends_with(".rs")
            && malformed["line"].as_u64() > Some(0),
        "{malformed}"
    );
}

#[test]
fn seabus_check_reads_the_foxglove_element_and_warns_of_commands_nothing_accepts() {
    let system = |foxglove: &str| {
        format!(
            r#"<seabus node="v">
  <medium name="bus" url="inproc://"/>
  <module name="sim" type="vehicle-sim" medium="bus"/>
  {foxglove}
</seabus>"#
        )
    };
    let (_d, path) = system_file(
        "ok.xml",
        &system(r#"<foxglove medium="bus" commands="cmd.course"/>"#),
    );
    let out = check(&path);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));

    let (_d, path) = system_file(
        "warn.xml",
        &system(r#"<foxglove medium="bus" commands="cmd.course cmd.winch"/>"#),
    );
    let out = check(&path);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let said = String::from_utf8_lossy(&out.stdout).into_owned() + &stderr(&out);
    assert!(
        said.contains(&format!(
            "{}:4:26: warning: no module of {} accepts command `cmd.winch` on `bus`, which \
             Foxglove clients may send",
            path.display(),
            path.display()
        )),
        "{said}"
    );
    assert!(!said.contains("`cmd.course`"), "{said}");

    let (_d, path) = system_file(
        "bad.xml",
        &system(r#"<foxglove listen="everywhere" unadvertise="never"/>"#),
    );
    let out = check(&path);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(&format!(
            "{}:4:13: attribute `listen`: `everywhere` is not an address and port (such as 127.0.0.1:8765)",
            path.display()
        )),
        "{}",
        stderr(&out)
    );

    let (_d, path) = system_file("log.xml", &system(r#"<foxglove log="verbose"/>"#));
    let out = check(&path);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(&format!(
            "{}:4:13: attribute `log`: `verbose` is not a log level: error, warn, info, debug or off",
            path.display()
        )),
        "{}",
        stderr(&out)
    );
}
