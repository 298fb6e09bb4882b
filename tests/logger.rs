//! The central data logger run by `seabus run`: its CSV and its binary log, read back (the binary
//! one through `seabus export`), hold exactly what was published on the bus, with seabus's
//! timestamps; killed mid-run, it loses at most the last second. In MCAP, its files rotate by
//! age, each one complete for Python's `mcap`, together holding every message once; killed, the
//! file it was writing reads up to its last second.

mod common;
use common::*;
use std::collections::BTreeMap;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

fn system(bus: &str, dir: &std::path::Path, count: &str, logger: &str) -> String {
    format!(
        r#"<seabus node="log">
  <medium name="bus" url="{bus}"/>
  <module name="gen" type="generator" medium="bus" tick="50Hz" topic="test.counter" {count}/>
  <module name="logger" type="logger" medium="bus" dir="{}" topics="test.**" {logger}/>
</seabus>"#,
        dir.display()
    )
}

/// The CSV's rows: time and counter.
fn csv_rows(path: &std::path::Path) -> Vec<(f64, i64)> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    assert_eq!(header.first(), Some(&"time"), "{header:?}");
    let at = header
        .iter()
        .position(|h| *h == "counter")
        .expect("a counter column");
    lines
        .filter_map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            Some((cells[0].parse().ok()?, cells.get(at)?.parse().ok()?))
        })
        .collect()
}

#[test]
fn what_was_published_is_what_the_logs_hold() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let (_sys, path) = system_file("log.xml", &system(&bus, &logs, "count=\"60\"", ""));
    let (_spy, rx) = spy_json(&bus, 20);
    std::thread::sleep(Duration::from_millis(300));
    let mut run = spawn_run(&path, &["--for", "3"]);
    assert!(wait_for(&mut run, Duration::from_secs(20)).is_some_and(|s| s.success()));
    // what the bus carried, by counter, with seabus's stamp
    let mut published = BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(3);
    while Instant::now() < deadline {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(v) if v["topic"] == "test.counter" => {
                published.insert(
                    v["payload"]["counter"].as_i64().unwrap(),
                    v["stamp"].as_f64().unwrap(),
                );
            }
            Ok(_) => {}
            Err(_) if published.len() >= 60 => break,
            Err(_) => {}
        }
    }
    assert_eq!(published.len(), 60, "the spy saw every message");

    let rows = csv_rows(&logs.join("test.counter.csv"));
    let logged: BTreeMap<i64, f64> = rows.iter().map(|(t, c)| (*c, *t)).collect();
    assert_eq!(rows.len(), 60, "one row per message");
    assert_eq!(
        logged.keys().collect::<Vec<_>>(),
        published.keys().collect::<Vec<_>>()
    );
    for (c, t) in &logged {
        assert!(
            (t - published[c]).abs() < 1e-5,
            "counter {c}: logged at {t}, stamped {}",
            published[c]
        );
    }

    // the binary log, through seabus export: the same events, as JSON and as CSV
    let out = seabus()
        .args(["export", "--topics", "test.**"])
        .arg(&logs)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let exported: BTreeMap<i64, f64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|v| {
            (
                v["payload"]["counter"].as_i64().unwrap(),
                v["time"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(exported.len(), 60);
    for (c, t) in &exported {
        assert!((t - published[c]).abs() < 2e-6, "counter {c}");
    }
    // a window: the first second of the log only
    let t0 = exported.values().cloned().fold(f64::INFINITY, f64::min);
    let window = seabus()
        .args(["export", "--format", "csv", "--out"])
        .arg(dir.path().join("window"))
        .args(["--from", &t0.to_string(), "--to", &(t0 + 0.5).to_string()])
        .arg(&logs)
        .output()
        .unwrap();
    assert!(
        window.status.success(),
        "{}",
        String::from_utf8_lossy(&window.stderr)
    );
    let part = csv_rows(&dir.path().join("window/test.counter.csv"));
    let expected = exported.values().filter(|t| **t < t0 + 0.5).count();
    assert_eq!(part.len(), expected);
    assert!(
        (20..=30).contains(&part.len()),
        "half a second at 50 Hz: {}",
        part.len()
    );
}

#[test]
fn a_crash_loses_at_most_the_last_second() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let (_sys, path) = system_file("log.xml", &system(&bus, &logs, "", ""));
    let mut run = spawn_run(&path, &[]);
    std::thread::sleep(Duration::from_millis(2500));
    run.0.kill().unwrap();
    let killed = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    let _ = run.0.wait();
    let rows = csv_rows(&logs.join("test.counter.csv"));
    let last = rows.last().expect("rows were logged").0;
    assert!(
        killed - last <= 1.1,
        "the last row logged is {:.3} s before the kill",
        killed - last
    );
    // the counters logged have no gaps
    assert!(rows.windows(2).all(|w| w[1].1 == w[0].1 + 1), "{rows:?}");
    // and the binary log reads up to where the crash cut it
    let out = seabus().arg("export").arg(&logs).output().unwrap();
    let events = String::from_utf8_lossy(&out.stdout).lines().count();
    assert!(
        events + 1 >= rows.len(),
        "{events} events, {} rows",
        rows.len()
    );
}

/// The counters `seabus export` finds in `logs`, in order, its exit code and what it said.
fn exported_counters(logs: &std::path::Path) -> (Vec<(i64, f64)>, Option<i32>, String) {
    let out = seabus().arg("export").arg(logs).output().unwrap();
    let counters = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|v| {
            (
                v["payload"]["counter"].as_i64().unwrap(),
                v["time"].as_f64().unwrap(),
            )
        })
        .collect();
    (
        counters,
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The `.mcap` files in `dir`, in name (start time) order.
fn mcap_files(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    files.sort();
    files
}

#[test]
fn mcap_logs_rotate_by_age_each_file_complete_every_message_once() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let text = system(
        &bus,
        &logs,
        "count=\"150\"",
        r#"format="mcap" max_age="1s" csv="false""#,
    );
    let (_sys, path) = system_file("log.xml", &text);
    let mut run = spawn_run(&path, &["--for", "4"]);
    assert!(wait_for(&mut run, Duration::from_secs(20)).is_some_and(|s| s.success()));
    let files = mcap_files(&logs);
    assert!(
        (3..=5).contains(&files.len()),
        "three seconds of messages in files of one second: {files:?}"
    );
    // each file finished: Python reads its summary and its statistics
    let script = r#"
import json, sys
from mcap.reader import make_reader
counts = []
for name in sys.argv[1:]:
    with open(name, "rb") as f:
        summary = make_reader(f).get_summary()
        counts.append(summary.statistics.message_count if summary else None)
print(json.dumps(counts))
"#;
    let names: Vec<&str> = files.iter().map(|f| f.to_str().unwrap()).collect();
    let counts: Vec<Option<u64>> = serde_json::from_str(&python(script, &names, &[])).unwrap();
    assert!(
        counts.iter().all(|c| c.is_some_and(|c| c > 0)),
        "{counts:?}"
    );
    assert_eq!(counts.iter().flatten().sum::<u64>(), 150, "{counts:?}");
    let (counters, code, said) = exported_counters(&logs);
    assert_eq!(code, Some(0), "{said}");
    let values: Vec<i64> = counters.iter().map(|c| c.0).collect();
    assert_eq!(values, (0..150).collect::<Vec<_>>());
}

#[test]
fn a_crash_leaves_an_mcap_log_readable_up_to_its_last_second() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let (_sys, path) = system_file(
        "log.xml",
        &system(&bus, &logs, "", r#"format="mcap" csv="false""#),
    );
    let mut run = spawn_run(&path, &[]);
    std::thread::sleep(Duration::from_millis(2500));
    run.0.kill().unwrap();
    let killed = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    let _ = run.0.wait();
    let files = mcap_files(&logs);
    assert_eq!(files.len(), 1, "{files:?}");
    let (counters, code, said) = exported_counters(&logs);
    assert_eq!(code, Some(1), "the file has no footer: {said}");
    assert!(
        said.contains(&format!("{}: byte ", files[0].display())) && said.contains("(cut short"),
        "{said}"
    );
    let last = counters.last().expect("messages were read").1;
    assert!(
        killed - last <= 1.1,
        "the last message read is {:.3} s before the kill",
        killed - last
    );
    assert!(
        counters.iter().enumerate().all(|(i, c)| c.0 == i as i64),
        "no gaps: {counters:?}"
    );
}
