//! The commands that send (`seabus pub`, `seabus replay`) and a running system against a real
//! MOOSDB (core-moos) that is killed and restarted: they wait for the link, say when it is lost
//! and when it is back, go on, and exit with the code docs/system-files.md gives.

mod common;

use common::moos::*;
use common::*;
use std::process::{Output, Stdio};
use std::time::{Duration, Instant};

/// Starts a `seabus` command with its output captured (killed if the test ends first).
fn spawn(args: &[&str]) -> Running {
    Running(
        seabus()
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("seabus starts"),
    )
}

/// Waits at most `limit` for a command's end: its output, and how long it ran from `started`.
fn output_within(mut run: Running, started: Instant, limit: Duration) -> (Output, Duration) {
    let status = wait_for(&mut run, limit);
    let took = started.elapsed();
    let child = std::mem::replace(
        &mut run.0,
        std::process::Command::new("true").spawn().expect("true"),
    );
    let out = child.wait_with_output().expect("the command's output");
    assert!(
        status.is_some(),
        "ended within {limit:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (out, took)
}

/// The line of `text` holding `what`, and the lines after it.
fn after<'a>(text: &'a str, what: &str) -> Option<&'a str> {
    text.find(what).map(|i| &text[i..])
}

/// The stderr of a command that lived through a lost link: it logged the loss, then the return,
/// and exited with the code documented for what it says it lost.
fn lived_through_a_lost_link(out: &Output) {
    let stderr = stderr(out);
    let lost = after(&stderr, "link lost").unwrap_or_else(|| panic!("the loss logged: {stderr}"));
    assert!(lost.contains("waiting up to 5 s"), "{stderr}");
    assert!(
        after(lost, "link back").is_some(),
        "the return logged: {stderr}"
    );
    assert_eq!(
        out.status.code(),
        Some(documented_code(&stderr)),
        "{stderr}"
    );
}

/// Kills the DB 2 s from now and starts it again 2 s later.
fn kill_and_restart(db: &mut MoosDb) {
    std::thread::sleep(Duration::from_secs(2));
    db.kill();
    std::thread::sleep(Duration::from_secs(2));
    db.restart();
}

/// The exit code `seabus` documents for the output: 4 when it reports messages lost with the link
/// (a MOOSDB killed with a packet in its socket never confirms it), else 0.
fn documented_code(stderr: &str) -> i32 {
    if stderr.contains("lost with the link") {
        4
    } else {
        0
    }
}

/// `seabus pub` onto a MOOSDB killed after 2 s and started again 2 s later: the loss is logged
/// with its reason, the command waits, logs the link's return and sends the rest; a libMOOS app
/// on the restarted DB receives them.
#[test]
fn pub_waits_for_a_restarted_moosdb_and_sends_the_rest() {
    let mut db = MoosDb::start();
    let url = db.url("uPub", "");
    let started = Instant::now();
    let run = spawn(&[
        "pub", &url, "X_PUB", "--count", "120", "--rate", "20", "v=1",
    ]);
    kill_and_restart(&mut db);
    let (_watch, rx) = moos_watch(db.port, "uWatch", 30, &["X_PUB"]);
    let (out, _) = output_within(run, started, Duration::from_secs(30));
    let stderr = stderr(&out);
    // sent before the kill (40 at 20 per second) are not on the new DB; the rest are
    let got = moos_received(&rx, Duration::from_secs(5), |g| g.len() >= 70);
    assert!(
        got.len() >= 70,
        "{} received after the restart: {stderr}",
        got.len()
    );
    assert!(
        got.iter()
            .all(|(k, v)| k == "X_PUB" && *v == MoosValue::Text("v=1".into())),
        "{got:?}"
    );
    lived_through_a_lost_link(&out);
}

/// A MOOSDB that does not come back: `seabus pub` exits 4 once its link wait is over, saying why.
#[test]
fn pub_exits_4_when_the_moosdb_does_not_come_back() {
    let mut db = MoosDb::start();
    let url = db.url("uPub", "");
    let started = Instant::now();
    let run = spawn(&[
        "pub",
        &url,
        "X_PUB",
        "--count",
        "100",
        "--rate",
        "20",
        "--link-wait",
        "2",
        "v=1",
    ]);
    std::thread::sleep(Duration::from_secs(1));
    let killed = started.elapsed();
    db.kill();
    let (out, took) = output_within(run, started, Duration::from_secs(20));
    let stderr = stderr(&out);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains("the link did not come back within 2 s"),
        "{stderr}"
    );
    // two seconds of waiting after the kill, and the time to see it
    assert!(
        took >= killed + Duration::from_secs(2) && took < killed + Duration::from_secs(5),
        "ended {took:?} after the start, the DB killed at {killed:?}"
    );
}

/// No MOOSDB at all: `seabus pub` exits 4 once its link wait is over.
#[test]
fn pub_exits_4_when_the_link_does_not_come_up() {
    let url = format!("moos://127.0.0.1:{}?name=uPub", free_tcp_port());
    let started = Instant::now();
    let run = spawn(&["pub", &url, "X_PUB", "--link-wait", "1", "v=1"]);
    let (out, took) = output_within(run, started, Duration::from_secs(20));
    let stderr = stderr(&out);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(
        stderr.contains("the link did not come up within 1 s"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(5), "{took:?}");
}

/// An LCM event log written by Python's `lcm` (its EventLog): `count` events on channel `EVT`,
/// `event-0`, `event-1`, … `gap_us` apart.
fn event_log(path: &std::path::Path, count: u32, gap_us: u64) {
    python(
        "import lcm, sys\n\
         log = lcm.EventLog(sys.argv[1], 'w', overwrite=True)\n\
         for i in range(int(sys.argv[2])):\n\
         \x20   log.write_event(1_000_000 + i * int(sys.argv[3]), 'EVT', b'event-%d' % i)\n\
         log.close()\n",
        &[
            &path.display().to_string(),
            &count.to_string(),
            &gap_us.to_string(),
        ],
        &[],
    );
}

/// The events' numbers, as the libMOOS app received them.
fn numbers(got: &[(String, MoosValue)]) -> Vec<u32> {
    got.iter()
        .map(|(k, v)| {
            assert_eq!(k, "EVT");
            let bytes = match v {
                MoosValue::Binary(b) => b.clone(),
                MoosValue::Text(t) => t.clone().into_bytes(),
                other => panic!("EVT is a string: {other:?}"),
            };
            let text = String::from_utf8(bytes).expect("text");
            text.strip_prefix("event-")
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("an event: {text}"))
        })
        .collect()
}

/// `seabus replay` onto `moos://` sends nothing before its link is up: the first event arrives.
#[test]
fn replay_onto_moos_waits_for_the_link_and_sends_every_event() {
    let db = MoosDb::start();
    let dir = tempfile::tempdir().expect("dir");
    let log = dir.path().join("events.lcm");
    event_log(&log, 20, 10_000);
    let (_watch, rx) = moos_watch(db.port, "uWatch", 30, &["EVT"]);
    let url = db.url("uReplay", "");
    let started = Instant::now();
    let run = spawn(&["replay", &log.display().to_string(), &url]);
    let (out, _) = output_within(run, started, Duration::from_secs(20));
    let stderr = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let got = moos_received(&rx, Duration::from_secs(5), |g| g.len() >= 20);
    assert_eq!(numbers(&got), (0..20).collect::<Vec<_>>(), "{stderr}");
}

/// `seabus replay` onto a MOOSDB killed and started again: it waits, logs both, and goes on with
/// the event it was sending, so the restarted DB has every event from its return to the end.
#[test]
fn replay_waits_for_a_restarted_moosdb_and_sends_the_rest_in_order() {
    let mut db = MoosDb::start();
    let dir = tempfile::tempdir().expect("dir");
    let log = dir.path().join("events.lcm");
    // 100 events 100 ms apart: 10 s at speed 1
    event_log(&log, 100, 100_000);
    let url = db.url("uReplay", "");
    let started = Instant::now();
    let run = spawn(&["replay", &log.display().to_string(), &url]);
    kill_and_restart(&mut db);
    let (_watch, rx) = moos_watch(db.port, "uWatch", 30, &["EVT"]);
    let (out, _) = output_within(run, started, Duration::from_secs(40));
    let stderr = stderr(&out);
    let got = numbers(&moos_received(&rx, Duration::from_secs(5), |g| {
        numbers(g).last() == Some(&99)
    }));
    let first = *got
        .first()
        .unwrap_or_else(|| panic!("events after the restart: {stderr}"));
    assert!(first <= 40, "the replay waited rather than skip: {got:?}");
    assert_eq!(got, (first..100).collect::<Vec<_>>(), "{stderr}");
    lived_through_a_lost_link(&out);
}

/// A system bridging its inproc bus to MOOS starts without a warning: what goes out before the
/// MOOS link is up (the runtime's first status, a generator's first values) waits for it.
#[test]
fn a_bridge_to_moos_starts_without_a_warning_and_loses_nothing() {
    let db = MoosDb::start();
    let system = format!(
        r#"<seabus node="gw">
  <medium name="bus" url="inproc://"/>
  <medium name="moos" url="{}"/>
  <module name="gen" type="generator" medium="bus" topic="GEN" tick="20Hz" count="3"/>
  <bridge name="out" media="bus moos" report="0">
    <route from="bus" to="moos" topics="GEN"/>
  </bridge>
</seabus>"#,
        db.url("gw", "&amp;register=NONE"),
    );
    let (_dir, path) = system_file("gen.xml", &system);
    let checked = check(&path);
    assert!(checked.status.success(), "{}", stderr(&checked));
    let (_watch, rx) = moos_watch(db.port, "uWatch", 30, &["GEN"]);
    let run = spawn_run(&path, &["--for", "4"]);
    let got = moos_received(&rx, Duration::from_secs(10), |g| g.len() >= 3);
    let (status, stderr) = ended(run, Duration::from_secs(15));
    assert!(status.is_some_and(|s| s.success()), "{stderr}");
    let counters: Vec<&str> = got
        .iter()
        .map(|(_, v)| match v {
            MoosValue::Text(t) => t
                .split(',')
                .find_map(|p| p.strip_prefix("counter="))
                .unwrap_or_else(|| panic!("a counter in {t}")),
            other => panic!("GEN is a string of pairs: {other:?}"),
        })
        .collect();
    assert_eq!(counters, ["0", "1", "2"], "{got:?} {stderr}");
    assert!(!stderr.contains("WARN"), "{stderr}");
}
