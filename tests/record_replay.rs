//! `seabus record` and `seabus replay` against real LCM tools: logs seabus writes read in Python's
//! `lcm.EventLog`, logs `lcm-logger` writes replayed onto a seabus medium (channel filter, start
//! offset, speed), and damaged logs replayed up to the damage. Every medium is a loopback multicast
//! group with ttl 0 of the test's own.

mod common;
use common::*;
use seabus_medium::eventlog::{OwnedEvent, Reader, Writer};
use seabus_medium::{DataMap, Value, binary};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A loopback multicast medium of the test's own.
fn udp_url() -> String {
    format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port())
}

/// Fails unless Python's `lcm` package is installed.
fn require_python_lcm() {
    let ok = Command::new("python3")
        .args(["-c", "import lcm"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        ok,
        "the python3 package `lcm` is missing: run ./scripts/test, which installs it"
    );
}

/// Fails unless `lcm-logger` runs.
fn require_lcm_logger() {
    let ok = Command::new("lcm-logger")
        .arg("--help")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    assert!(
        ok,
        "`lcm-logger` is missing: run ./scripts/test, which installs it (Python package lcm)"
    );
}

/// Every event of a log; fails on damage.
fn read_log(path: &Path) -> Vec<OwnedEvent> {
    let mut r = Reader::open(path).expect("the log opens");
    let mut events = Vec::new();
    for _ in 0..100_000 {
        match r.next_event() {
            Ok(Some(e)) => events.push(e.into_owned()),
            Ok(None) => return events,
            Err(d) => panic!("{}: {d}", path.display()),
        }
    }
    panic!("more than 100000 events in {}", path.display());
}

/// Starts `seabus spy URL --json` and waits until it has joined the group.
fn start_spy(url: &str) -> Child {
    let spy = spawn_spy(url, &["--json", "--for", "30"]);
    std::thread::sleep(Duration::from_millis(400));
    spy
}

/// A message as `seabus spy --json` printed it: topic, payload bytes and stamp (seconds).
struct Seen {
    topic: String,
    bytes: Vec<u8>,
    stamp: f64,
}

/// Stops a spy with SIGINT once what was sent has had time to arrive, and reads what it printed.
fn stop_spy(spy: Child) -> Vec<Seen> {
    std::thread::sleep(Duration::from_millis(300));
    interrupt(&spy);
    let out = finish(spy);
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|line| {
            let m: serde_json::Value = serde_json::from_str(line).expect("a JSON line");
            assert_eq!(m["format"], "bytes", "{line}");
            // the payload is {"base64": …}, which the JSON datamap form reads as bytes
            let map = seabus_medium::json::from_json(&format!("{{\"p\":{}}}", m["payload"]))
                .expect("a bytes payload");
            let Some(Value::Bytes(bytes)) = map.get("p") else {
                panic!("not a bytes payload: {line}");
            };
            Seen {
                topic: m["topic"].as_str().expect("a topic").to_string(),
                bytes: bytes.clone(),
                stamp: m["stamp"].as_f64().expect("a stamp"),
            }
        })
        .collect()
}

/// Runs `seabus replay FILE URL ARGS…`, at most 15 s.
fn replay(file: &Path, url: &str, args: &[&str]) -> Output {
    let child = seabus()
        .arg("replay")
        .arg(file)
        .arg(url)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("replay starts");
    let mut child = child;
    let status = wait_for(&mut child, Duration::from_secs(15));
    let out = child.wait_with_output().expect("the output of replay");
    assert!(
        status.is_some(),
        "replay did not finish within 15 s: {}",
        stderr(&out)
    );
    out
}

/// Replays `file` on a fresh medium with `args` and returns what a spy saw and replay's output.
fn replay_seen(file: &Path, args: &[&str]) -> (Vec<Seen>, Output) {
    let url = udp_url();
    let spy = start_spy(&url);
    let out = replay(file, &url, args);
    (stop_spy(spy), out)
}

#[test]
fn python_lcm_reads_what_seabus_records() {
    require_python_lcm();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let all = dir.path().join("all.lcm");
    let nav = dir.path().join("nav.lcm");
    let url = udp_url();
    let record = |file: &Path, extra: &[&str]| {
        seabus()
            .args(["record", &url])
            .arg(file)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("record starts")
    };
    let recorders = [record(&all, &[]), record(&nav, &["--channels", r"nav\..*"])];
    std::thread::sleep(Duration::from_millis(400));
    let before = std::time::SystemTime::now();
    let publish = |args: &[&str]| {
        let out = seabus().arg("pub").arg(&url).args(args).output().unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
    };
    publish(&["nav.depth", "depth=4", "--count", "3", "--rate", "20"]);
    publish(&["doc.x", "a=1", "--format", "xml"]);
    std::thread::sleep(Duration::from_millis(300));
    for r in &recorders {
        interrupt(r);
    }
    let [all_out, nav_out] = recorders.map(finish);
    assert!(all_out.status.success(), "{}", stderr(&all_out));
    assert!(
        stderr(&all_out).contains("seabus record: 4 events, ")
            && stderr(&all_out).contains(" bytes, 2 channels in "),
        "{}",
        stderr(&all_out)
    );
    assert!(
        stderr(&nav_out).contains("seabus record: 3 events, "),
        "{}",
        stderr(&nav_out)
    );

    let script = r#"
import json, sys, lcm
for e in lcm.EventLog(sys.argv[1], "r"):
    print(json.dumps([e.eventnum, e.timestamp, e.channel, e.data.hex()]))
"#;
    let read = |file: &Path| -> Vec<(i64, i64, String, Vec<u8>)> {
        python(script, &[file.to_str().unwrap()], &[])
            .lines()
            .map(|l| {
                let (n, t, c, hex): (i64, i64, String, String) =
                    serde_json::from_str(l).expect("a JSON line");
                let data = (0..hex.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
                    .collect();
                (n, t, c, data)
            })
            .collect()
    };
    let events = read(&all);
    let depth = binary::encode(&DataMap::new().with("depth", Value::Int(4))).unwrap();
    let xml = br#"<datamap><int name="a">1</int></datamap>"#.to_vec();
    // before a channel's first datamap and first XML, an event says the format of what follows
    let said = |channel: &str, format: &str| {
        binary::encode(
            &DataMap::new()
                .with("channel", channel)
                .with("format", format),
        )
        .unwrap()
    };
    let (said_map, said_xml) = (said("nav.depth", "map"), said("doc.x", "xml"));
    let got: Vec<(i64, &str, &[u8])> = events
        .iter()
        .map(|(n, _, c, d)| (*n, c.as_str(), d.as_slice()))
        .collect();
    assert_eq!(
        got,
        [
            (0, "seabus.log.format", &said_map[..]),
            (1, "nav.depth", &depth[..]),
            (2, "nav.depth", &depth[..]),
            (3, "nav.depth", &depth[..]),
            (4, "seabus.log.format", &said_xml[..]),
            (5, "doc.x", &xml[..]),
        ]
    );
    let since_epoch = |t: std::time::SystemTime| {
        t.duration_since(std::time::UNIX_EPOCH).unwrap().as_micros() as i64
    };
    let (start, end) = (
        since_epoch(before),
        since_epoch(std::time::SystemTime::now()),
    );
    // (a format event is logged at the time of the event it comes before)
    for pair in events.windows(2) {
        let format_event = pair[0].2 == "seabus.log.format";
        assert!(
            pair[0].1 < pair[1].1 || (format_event && pair[0].1 == pair[1].1),
            "timestamps increase: {events:?}"
        );
    }
    for (_, t, _, _) in &events {
        assert!(
            (start..=end).contains(t),
            "{t} is arrival time, µs since the epoch"
        );
    }
    let nav_events = read(&nav);
    assert_eq!(nav_events.len(), 4, "{nav_events:?}");
    assert!(nav_events[1..].iter().all(|e| e.2 == "nav.depth"));
}

#[test]
fn a_log_lcm_logger_wrote_replays_onto_a_seabus_medium() {
    require_python_lcm();
    require_lcm_logger();
    let dir = tempfile::tempdir().expect("a temporary directory");
    let log = dir.path().join("logger.lcm");
    let lcm_url = format!("udpm://239.255.76.67:{}?ttl=0", free_port());
    // lcm-logger (a Python launcher and the C program) in a process group of its own, so that
    // SIGINT reaches both as Ctrl-C would
    let logger = {
        use std::os::unix::process::CommandExt;
        Command::new("lcm-logger")
            .arg("-q")
            .arg(&log)
            .env("LCM_DEFAULT_URL", &lcm_url)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .expect("lcm-logger starts")
    };
    // warm-up events until the logger has written one, then the events the test checks, with a
    // pause in the middle for --from
    let script = r#"
import os, sys, time, lcm
path = sys.argv[1]
l = lcm.LCM()
deadline = time.time() + 10
while not (os.path.exists(path) and os.path.getsize(path) > 0):
    if time.time() > deadline:
        sys.exit("lcm-logger wrote nothing within 10 s")
    l.publish("WARMUP", b"w")
    time.sleep(0.05)
time.sleep(0.1)
for i, (channel, data) in enumerate([
    ("POSE", bytes([0, 0, 255])),
    ("STATUS", b"a"),
    ("POSE", bytes([1, 0, 255])),
    ("BAD CHANNEL", b"x"),
    ("POSE", bytes([2, 0, 255])),
    ("STATUS", b"b\x00"),
]):
    if i == 4:
        time.sleep(0.5)
    l.publish(channel, data)
    time.sleep(0.1)
"#;
    python(
        script,
        &[log.to_str().unwrap()],
        &[("LCM_DEFAULT_URL", &lcm_url)],
    );
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: kill(2) on the process group of our own child
    unsafe {
        libc::kill(-(logger.id() as libc::pid_t), libc::SIGINT);
    }
    // its exit status is the Python launcher's (which may report the interrupt); the log is what
    // counts, and lcm-logger flushes it every 100 ms
    finish(logger);

    let events = read_log(&log);
    assert!(
        events.iter().zip(0i64..).all(|(e, n)| e.number == n),
        "lcm-logger numbers events from 0"
    );
    let warmups = events.iter().filter(|e| e.channel == "WARMUP").count();
    let checked: Vec<&OwnedEvent> = events.iter().filter(|e| e.channel != "WARMUP").collect();
    let channels: Vec<&str> = checked.iter().map(|e| e.channel.as_str()).collect();
    assert_eq!(
        channels,
        ["POSE", "STATUS", "POSE", "BAD CHANNEL", "POSE", "STATUS"]
    );
    assert!(warmups >= 1);
    let micros = |e: &OwnedEvent| e.timestamp - events[0].timestamp;

    // everything that is a seabus topic, as fast as possible
    let (seen, out) = replay_seen(&log, &["--speed", "max"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let summary = stderr(&out);
    assert!(
        summary.contains(&format!("{} events sent on 3 channels", events.len() - 1))
            && summary
                .contains("; 1 skipped on 1 channel that is not a seabus topic (\"BAD CHANNEL\")"),
        "{summary}"
    );
    let wanted: Vec<(&str, &[u8])> = events
        .iter()
        .filter(|e| e.channel != "BAD CHANNEL")
        .map(|e| (e.channel.as_str(), e.data.as_slice()))
        .collect();
    let got: Vec<(&str, &[u8])> = seen
        .iter()
        .map(|s| (s.topic.as_str(), s.bytes.as_slice()))
        .collect();
    assert_eq!(got, wanted);

    // one channel: the regex matches whole names only
    let (seen, out) = replay_seen(&log, &["--speed", "max", "--channels", "POS|POSE"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let got: Vec<(&str, &[u8])> = seen
        .iter()
        .map(|s| (s.topic.as_str(), s.bytes.as_slice()))
        .collect();
    assert_eq!(
        got,
        [
            ("POSE", &[0u8, 0, 255][..]),
            ("POSE", &[1, 0, 255]),
            ("POSE", &[2, 0, 255])
        ]
    );
    assert!(
        stderr(&out).contains(&format!("{} left out by --channels", events.len() - 3)),
        "{}",
        stderr(&out)
    );

    // from the middle of the pause on: the last POSE and STATUS
    let pause = (micros(checked[3]) + micros(checked[4])) as f64 / 2e6;
    let (seen, out) = replay_seen(&log, &["--from", &format!("{pause:.6}")]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let got: Vec<(&str, &[u8])> = seen
        .iter()
        .map(|s| (s.topic.as_str(), s.bytes.as_slice()))
        .collect();
    assert_eq!(got, [("POSE", &[2u8, 0, 255][..]), ("STATUS", b"b\x00")]);
    assert!(
        stderr(&out).contains(&format!("{} before --from", events.len() - 2)),
        "{}",
        stderr(&out)
    );

    // twice as fast: the checked events come at least half their logged spacing apart (sleeps
    // never end early), with a margin for clock rounding
    let (seen, out) = replay_seen(&log, &["--speed", "2", "--channels", "POSE|STATUS"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(seen.len(), 5);
    let logged = (micros(checked[5]) - micros(checked[0])) as f64 / 1e6;
    let replayed = seen[4].stamp - seen[0].stamp;
    assert!(
        replayed >= logged / 2.0 * 0.95 - 0.002,
        "replayed over {replayed} s, logged over {logged} s"
    );
}

/// A log of `n` events on `dmg.N` channels, 1 ms apart, and where each event starts.
fn damage_log(dir: &Path, n: usize) -> (std::path::PathBuf, Vec<u8>, Vec<u64>) {
    let path = dir.join("whole.lcm");
    let mut w = Writer::create_new(&path).expect("the log is created");
    let mut starts = Vec::new();
    for i in 0..n {
        starts.push(w.bytes());
        w.write(
            1_000_000 + i as i64 * 1000,
            &format!("dmg.e{i}"),
            &[i as u8; 20],
        )
        .expect("an event is written");
    }
    w.finish().expect("the log is written");
    let bytes = std::fs::read(&path).expect("the log reads");
    (path, bytes, starts)
}

#[test]
fn a_damaged_log_replays_up_to_the_damage_and_says_where() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let (whole, bytes, starts) = damage_log(dir.path(), 5);

    let (seen, out) = replay_seen(&whole, &["--speed", "max"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(seen.len(), 5);

    // cut in the middle of the fourth event
    let truncated = dir.path().join("truncated.lcm");
    std::fs::write(&truncated, &bytes[..starts[3] as usize + 30]).unwrap();
    let (seen, out) = replay_seen(&truncated, &["--speed", "max"]);
    let topics: Vec<&str> = seen.iter().map(|s| s.topic.as_str()).collect();
    assert_eq!(topics, ["dmg.e0", "dmg.e1", "dmg.e2"]);
    assert_eq!(seen[2].bytes, [2u8; 20]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains(&format!(
            "truncated.lcm: damaged at byte {}: data length 20 reaches past the end",
            starts[3]
        )),
        "{err}"
    );

    // one byte changed in the middle: the third event's sync word
    let corrupt = dir.path().join("corrupt.lcm");
    let mut changed = bytes.clone();
    changed[starts[2] as usize + 1] ^= 0x40;
    std::fs::write(&corrupt, &changed).unwrap();
    let (seen, out) = replay_seen(&corrupt, &["--speed", "max"]);
    let topics: Vec<&str> = seen.iter().map(|s| s.topic.as_str()).collect();
    assert_eq!(topics, ["dmg.e0", "dmg.e1"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains(&format!(
            "corrupt.lcm: damaged at byte {}: bad sync word 0xEDE1DA01",
            starts[2]
        )),
        "{err}"
    );

    // an impossible channel length in the fifth event's header
    let mut changed = bytes.clone();
    changed[starts[4] as usize + 20] = 0x80;
    std::fs::write(&corrupt, &changed).unwrap();
    let (seen, out) = replay_seen(&corrupt, &["--speed", "max"]);
    assert_eq!(seen.len(), 4);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(&format!("damaged at byte {}: channel length -", starts[4])),
        "{}",
        stderr(&out)
    );
}

#[test]
fn speed_scales_the_logged_spacing() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("slow.lcm");
    let mut w = Writer::create_new(&path).expect("the log is created");
    // ten seconds apart: at speed 1 the replay would outlast the test's bounds
    for i in 0..3i64 {
        w.write(5_000_000 + i * 10_000_000, "speed.test", &[i as u8])
            .expect("an event is written");
    }
    w.finish().expect("the log is written");

    let started = Instant::now();
    let (seen, out) = replay_seen(&path, &["--speed", "20"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(seen.len(), 3);
    for pair in seen.windows(2) {
        let gap = pair[1].stamp - pair[0].stamp;
        assert!(gap >= 0.45, "10 s at speed 20 came {gap} s apart");
    }
    // finishing at all within the replay bound (15 s) shows the speed-up of a 20 s log
    assert!(started.elapsed() < Duration::from_secs(20));

    let (seen, out) = replay_seen(&path, &["--speed", "max"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(seen.len(), 3);
    assert!(
        seen[2].stamp - seen[0].stamp < 10.0,
        "unpaced events are not 10 s apart"
    );

    // --loop goes round until interrupted
    let url = udp_url();
    let spy = start_spy(&url);
    let looping = seabus()
        .arg("replay")
        .arg(&path)
        .arg(&url)
        .args(["--speed", "100", "--loop"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("replay starts");
    std::thread::sleep(Duration::from_millis(1500));
    interrupt(&looping);
    let out = finish(looping);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let seen = stop_spy(spy);
    assert!(seen.len() >= 6, "{} events in 1.5 s of looping", seen.len());
    assert!(stderr(&out).contains(" passes)"), "{}", stderr(&out));

    for (args, reason) in [
        (vec!["--speed", "-1"], "--speed -1: expected"),
        (
            vec!["--speed", "1e-18"],
            "--speed 1e-18: expected a factor from 0.001",
        ),
        (vec!["--from", "-2"], "--from -2: expected"),
        (vec!["--channels", "("], "--channels (:"),
    ] {
        let out = replay(&path, &udp_url(), &args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(stderr(&out).contains(reason), "{args:?}: {}", stderr(&out));
    }
    let out = replay(&dir.path().join("missing.lcm"), &udp_url(), &[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("missing.lcm: cannot open"));
}

/// What a spy printed, as (topic, format, payload) in order.
fn spied(rx: &std::sync::mpsc::Receiver<serde_json::Value>) -> Vec<(String, String, String)> {
    rx.try_iter()
        .map(|m| {
            (
                m["topic"].as_str().expect("a topic").to_string(),
                m["format"].as_str().expect("a format").to_string(),
                m["payload"].to_string(),
            )
        })
        .collect()
}

#[test]
fn a_recording_exported_and_replayed_from_its_folder_gives_the_same_messages() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let logs = dir.path().join("logs");
    std::fs::create_dir(&logs).expect("a folder");
    std::fs::write(logs.join("notes.txt"), "dive 3, calm sea\n").expect("a note");
    let url = udp_url();
    // the traffic as a spy on the medium sees it
    let (live_spy, live) = spy_json(&url, 12);
    // `seabus record` to the README's name, while a simulated vehicle publishes datamaps and
    // `seabus pub` XML text
    let log = logs.join("dive.lcm");
    let record = spawn_record(&url, &log, 4);
    std::thread::sleep(Duration::from_millis(500));
    let system = format!(
        r#"<seabus node="rec-src">
  <medium name="net" url="{}"/>
  <module name="vehicle" type="vehicle-sim" medium="net" tick="5Hz"/>
</seabus>
"#,
        url.replace('&', "&amp;")
    );
    let (_sys_dir, system) = system_file("src.xml", &system);
    let mut run = spawn_run(&system, &["--for", "2"]);
    let xml = seabus()
        .args(["pub", &url, "note.text", "text=\"hello\"", "depth=3.5"])
        .args(["--format", "xml", "--count", "3", "--rate", "5"])
        .output()
        .expect("pub runs");
    assert!(xml.status.success(), "{}", stderr(&xml));
    assert!(wait_for(&mut run, Duration::from_secs(10)).is_some());
    let recorded = finish(record);
    assert_eq!(recorded.status.code(), Some(0), "{}", stderr(&recorded));
    let events: usize = stderr(&recorded)
        .split_whitespace()
        .nth(2)
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("record says how many events: {}", stderr(&recorded)));
    assert!(events >= 10, "{}", stderr(&recorded));
    drop(live_spy);
    let live = spied(&live);

    // export of the folder: the log, whatever its name; the note is named as skipped
    let out = seabus()
        .arg("export")
        .arg(&logs)
        .output()
        .expect("export runs");
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains(&format!(
            "skipped {}: not an LCM event log or MCAP file",
            logs.join("notes.txt").display()
        )),
        "{err}"
    );
    assert!(err.contains(&format!("{events} events")), "{err}");
    let exported: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    assert_eq!(exported.len(), events);

    // replay of the folder to a spy: the same topics, formats and values as the live spy saw
    let again = udp_url();
    let (replay_spy, replayed) = spy_json(&again, 15);
    std::thread::sleep(Duration::from_millis(400));
    let out = replay(&logs, &again, &["--speed", "max"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(&format!("skipped {}", logs.join("notes.txt").display())),
        "{}",
        stderr(&out)
    );
    std::thread::sleep(Duration::from_millis(500));
    drop(replay_spy);
    let replayed = spied(&replayed);
    assert_eq!(replayed.len(), events, "{}", stderr(&out));
    for m in &replayed {
        assert!(
            live.contains(m),
            "replayed {m:?}, which the live spy never saw"
        );
    }
    let formats: std::collections::BTreeSet<&str> =
        replayed.iter().map(|(_, f, _)| f.as_str()).collect();
    assert_eq!(formats, ["map", "xml"].into());
    assert!(
        replayed.contains(&(
            "note.text".to_string(),
            "xml".to_string(),
            live.iter()
                .find(|(t, _, _)| t == "note.text")
                .map(|(_, _, p)| p.clone())
                .expect("the live spy saw the XML"),
        ))
    );
    // and the export has the same topics in the same order, datamaps as their fields
    let topics = |v: &[(String, String, String)]| v.iter().map(|m| m.0.clone()).collect::<Vec<_>>();
    let exported_topics: Vec<String> = exported
        .iter()
        .map(|e| e["topic"].as_str().expect("a topic").to_string())
        .collect();
    assert_eq!(exported_topics, topics(&replayed));
    let (first_map, _) = replayed
        .iter()
        .zip(&exported)
        .find(|((_, f, _), _)| f == "map")
        .expect("a datamap");
    let i = replayed.iter().position(|m| m == first_map).expect("there");
    assert_eq!(
        exported[i]["payload"],
        serde_json::from_str::<serde_json::Value>(&first_map.2).expect("JSON")
    );
}

#[test]
fn a_folder_without_logs_is_refused_by_export_and_replay() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    std::fs::write(dir.path().join("notes.txt"), "nothing recorded\n").expect("a note");
    std::fs::write(dir.path().join("empty.lcm"), "").expect("an empty file");
    let want = format!(
        "{}: no LCM event log or MCAP file in this folder",
        dir.path().display()
    );
    let out = seabus()
        .arg("export")
        .arg(dir.path())
        .output()
        .expect("export runs");
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains(&want), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(&format!(
            "skipped {}: empty",
            dir.path().join("empty.lcm").display()
        )),
        "{}",
        stderr(&out)
    );
    let out = replay(dir.path(), &udp_url(), &[]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains(&want), "{}", stderr(&out));
}
