//! Every example system in `configs/` runs for 10 s as a user would start it, and says no warning
//! twice: a warning that comes back (a bridge report a medium cannot carry, a medium whose link is
//! down refusing every message) is said once and then counted, never repeated every second.
//!
//! The systems run as they are written, without their hardware or servers (a serial port that is
//! not there, a MOOSDB not running): what is missing is said once.

mod common;
use common::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Example systems that cannot run on a machine as it comes, with why.
const NOT_RUN: &[(&str, &str)] = &[
    (
        "fleet/auv1.xml",
        "needs the fleet's TLS certificates (certs/) and a seabus built with `zenoh`",
    ),
    (
        "fleet/auv2.xml",
        "needs the fleet's TLS certificates (certs/) and a seabus built with `zenoh`",
    ),
    (
        "fleet/shore.xml",
        "needs the fleet's TLS certificates (certs/) and a seabus built with `zenoh`",
    ),
];

/// The system files under `configs/` (those whose root is `<seabus>` and that name media).
fn example_systems() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut found = Vec::new();
    let mut dirs = vec![root];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "xml") {
                let text = std::fs::read_to_string(&path).unwrap();
                if text.contains("<seabus") && text.contains("<medium ") {
                    found.push(path);
                }
            }
        }
    }
    found.sort();
    found
}

fn name_of(path: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    path.strip_prefix(root).unwrap().display().to_string()
}

/// Starts one example system for 10 s: the demo as `seabus demo` (its system is
/// `configs/demo.xml`, with one-time console users), the others with `seabus run`.
fn start(path: &Path) -> Running {
    let mut c = seabus();
    if name_of(path) == "demo.xml" {
        c.arg("demo");
    } else {
        c.arg("run").arg(path);
    }
    Running(
        c.args(["--for", "10"])
            .current_dir(path.parent().unwrap())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("seabus starts"),
    )
}

/// The warnings said more than once (the same text, whatever its time), with how often.
fn repeated_warnings(stderr: &str) -> BTreeMap<String, usize> {
    let mut seen = BTreeMap::new();
    for line in stderr.lines() {
        if !(line.contains(" WARN ") || line.contains(" ERROR ")) {
            continue;
        }
        // the first word is the time
        let text = line.split_once(' ').map_or(line, |(_, rest)| rest).trim();
        *seen.entry(text.to_string()).or_insert(0) += 1;
    }
    seen.retain(|_, n| *n > 1);
    seen
}

#[test]
fn every_example_system_runs_10_s_without_repeating_a_warning() {
    let systems = example_systems();
    let names: Vec<String> = systems.iter().map(|p| name_of(p)).collect();
    for (name, _) in NOT_RUN {
        assert!(
            names.iter().any(|n| n == name),
            "{name} is no longer in configs/"
        );
    }
    let to_run: Vec<&PathBuf> = systems
        .iter()
        .filter(|p| !NOT_RUN.iter().any(|(n, _)| *n == name_of(p)))
        .collect();
    assert!(to_run.len() >= 8, "{names:?}");
    for (name, why) in NOT_RUN {
        eprintln!("not run: {name}: {why}");
    }
    // two of them listen on MAVLink's port 14550: they run one after the other
    let (first, second): (Vec<&PathBuf>, Vec<&PathBuf>) = to_run
        .iter()
        .partition(|p| name_of(p) != "mavlink-moos.xml");
    let mut failures = Vec::new();
    for wave in [first, second] {
        let running: Vec<(String, Running)> = wave.iter().map(|p| (name_of(p), start(p))).collect();
        for (name, run) in running {
            let (status, stderr) = ended(run, Duration::from_secs(30));
            match status {
                Some(s) if s.success() => {}
                other => failures.push(format!("{name}: ended {other:?}:\n{stderr}")),
            }
            for (text, n) in repeated_warnings(&stderr) {
                failures.push(format!("{name}: said {n} times: {text}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_warning_said_twice_is_found_and_one_said_once_is_not() {
    let log = "2026-01-01T00:00:00.1Z  WARN link down: x medium=a\n\
               2026-01-01T00:00:01.1Z  WARN link down: x medium=a\n\
               2026-01-01T00:00:01.2Z  WARN link down: y medium=b\n\
               2026-01-01T00:00:01.3Z  INFO up medium=b\n\
               2026-01-01T00:00:01.4Z  INFO up medium=b\n";
    assert_eq!(
        repeated_warnings(log),
        BTreeMap::from([("WARN link down: x medium=a".to_string(), 2)])
    );
}
