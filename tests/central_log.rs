//! Every module of a system with `<log>` logs through the DSAAV logging service: `seabus run`
//! forwards each module's records to the central log, named after the module (or the component it
//! names), at the level the configuration gives that component.

mod common;
use common::*;
use std::time::Duration;

/// The configuration: WARNING for everyone, INFO for the depth filter.
const INI: &str = "\
[Logging]
Server = 1:0
LogLevel = LOG_WARNING

[Elevators]
Server = 2:0

[DepthSensor]
Server = 4:0

[DepthFilter]
Server = 3:0
Depth.Server = 4:0
Logging.LogLevel = LOG_INFO
";

fn system(dir: &std::path::Path, log_medium: &str) -> String {
    format!(
        r#"<seabus node="vehicle">
  <medium name="n1" url="dsaav+inproc://v?node=1"/>
  <medium name="n2" url="dsaav+inproc://v?node=2"/>
  <medium name="n3" url="dsaav+inproc://v?node=3"/>
  <medium name="n4" url="dsaav+inproc://v?node=4"/>
  <medium name="n9" url="dsaav+inproc://v?node=9"/>
  <module name="config" type="dsaav-config" medium="n1" config="vehicle.ini" appdata="{app}" port="2"/>
  <module name="log" type="dsaav-log" medium="n1" file="{log}" port="0"/>
  <module name="vehicle" type="starfish-vehicle-sim" media="n2 n4" depth="10"/>
  <module name="filter" type="depth-filter" medium="n3"/>
  <module name="archive" type="dsaav-log" medium="n1" file="{missing}" port="9"/>
  <log medium="{log_medium}"/>
</seabus>
"#,
        app = dir.join("app.ini").display(),
        log = dir.join("vehicle.log").display(),
        missing = dir.join("no-such-dir/archive.log").display(),
    )
}

/// Runs the system for two seconds; returns the central log and what the program printed.
fn run(log_medium: &str) -> (String, String) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    std::fs::write(dir.path().join("vehicle.ini"), INI).expect("the configuration is written");
    let path = dir.path().join("vehicle.xml");
    std::fs::write(&path, system(dir.path(), log_medium)).expect("the system file is written");
    let mut child = spawn_run(&path, &["--for", "2"]);
    let status = wait_for(&mut child, Duration::from_secs(20));
    let stderr = {
        let mut s = String::new();
        if let Some(mut e) = child.0.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut e, &mut s);
        }
        s
    };
    assert!(
        status.is_some_and(|s| s.success()),
        "seabus run ends by itself: {status:?}\n{stderr}"
    );
    let log = std::fs::read_to_string(dir.path().join("vehicle.log")).unwrap_or_default();
    (log, stderr)
}

/// The central log's lines as (level, component, text): `TIME LEVEL COMPONENT TEXT`, the middle
/// two padded.
fn records(log: &str) -> Vec<(String, String, String)> {
    let word = |s: &str| -> (String, String) {
        let s = s.trim_start();
        let (w, rest) = s.split_once(' ').unwrap_or((s, ""));
        (w.to_string(), rest.to_string())
    };
    log.lines()
        .map(|l| {
            let (_, rest) = word(l);
            let (level, rest) = word(&rest);
            let (component, text) = word(&rest);
            (level, component, text.trim().to_string())
        })
        .collect()
}

fn check_records(log: &str, stderr: &str) {
    let recs = records(log);
    // a module that cannot start: its failure, an ERROR of its own, reaches the central log
    assert!(
        recs.iter().any(|(l, c, t)| l == "ERROR"
            && c == "archive"
            && t.contains("cannot open the log")
            && t.contains("no-such-dir")),
        "the failing module's error is in the central log:\n{log}"
    );
    // the filter logs at INFO (its own override): where its depth comes from
    assert!(
        recs.iter()
            .any(|(l, c, t)| l == "INFO" && c == "DepthFilter" && t == "depth from 4:0"),
        "the filter's INFO record is in the central log:\n{log}"
    );
    // everyone else logs at WARNING: the system's INFO records stay out
    assert!(
        !recs
            .iter()
            .any(|(l, c, _)| l == "INFO" && c != "DepthFilter"),
        "only DepthFilter logs INFO:\n{log}"
    );
    // and the terminal still shows them all
    assert!(
        stderr.contains("running") && stderr.contains("depth from 4:0"),
        "{stderr}"
    );
    // in time order
    let times: Vec<&str> = log.lines().filter_map(|l| l.split(' ').next()).collect();
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "the central log is chronological:\n{log}"
    );
}

#[test]
fn modules_log_through_the_logging_service_at_their_configured_level() {
    let (log, stderr) = run("n9");
    check_records(&log, &stderr);
}

#[test]
fn records_sent_from_the_logging_servers_own_node_arrive() {
    // the forwarder and the logging server share node 1
    let (log, stderr) = run("n1");
    check_records(&log, &stderr);
}
