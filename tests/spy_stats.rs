//! `seabus spy --stats` on a pseudo-terminal it makes: what a device writes into it, garbage and a
//! bad sentence among the good ones, comes out as the medium's counters, every 5 s and at the end.

mod common;
use common::*;
use std::io::{Read, Write};
use std::process::Stdio;
use std::time::{Duration, Instant};

/// The value of counter `name` in a stats line (`name=value`, a number or `{…}`).
fn counter<'a>(line: &'a str, name: &str) -> &'a str {
    let key = format!(" {name}=");
    let at = line
        .find(&key)
        .unwrap_or_else(|| panic!("no {name} in {line}"))
        + key.len();
    let rest = &line[at..];
    let end = if rest.starts_with('{') {
        rest.find('}').map_or(rest.len(), |i| i + 1)
    } else {
        rest.find(' ').unwrap_or(rest.len())
    };
    &rest[..end]
}

#[test]
fn spy_stats_prints_what_the_medium_read_rejected_and_dropped() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("gps");
    let url = format!("pty://{}", link.display());
    let spy = Running(
        seabus()
            .args(["spy", &url, "--stats", "--for", "5.5"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spy starts"),
    );
    // the pseudo-terminal appears once the spy runs: a device writes into its other end
    let start = Instant::now();
    let mut device = loop {
        match std::fs::OpenOptions::new().write(true).open(&link) {
            Ok(f) => break f,
            Err(_) if start.elapsed() < Duration::from_secs(5) => {
                std::thread::sleep(Duration::from_millis(20))
            }
            Err(e) => panic!("{}: {e}", link.display()),
        }
    };
    let good = "$GPHDT,274.1,T*35\r\n";
    let mut input = good.repeat(5);
    // 4 bytes of garbage, and a sentence of 15 bytes with a wrong checksum
    input += "junk\r\n$GPHDT,1.0,T*00\r\n";
    input += &good.repeat(3);
    device.write_all(input.as_bytes()).unwrap();
    let mut spy = spy;
    let status = wait_for(&mut spy, Duration::from_secs(15)).expect("the spy ends by itself");
    assert!(status.success(), "{status}");
    let mut stderr = String::new();
    spy.stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with(&format!("seabus spy: stats of {url} after ")))
        .collect();
    // one line after 5 s, one at the end
    assert_eq!(lines.len(), 2, "{stderr}");
    let last = lines[1];
    assert_eq!(counter(last, "received"), "8", "{last}");
    assert_eq!(
        counter(last, "rejected"),
        "{bad-checksum=1, garbage=1}",
        "{last}"
    );
    assert_eq!(counter(last, "dropped_bytes"), "19", "{last}");
    assert_eq!(counter(last, "overruns"), "0", "{last}");
    assert_eq!(counter(last, "queue_dropped"), "{}", "{last}");
    // everything had arrived by 5 s: the two say the same
    let counters = |l: &str| l.split_once(" s: ").map(|(_, c)| c.to_string());
    let after = |l: &str| -> f64 {
        let (_, rest) = l.split_once(" after ").unwrap();
        rest.split_once(" s: ").unwrap().0.parse().unwrap()
    };
    // the first when its 5 s are up (a busy machine may take it a little later), before the end
    assert!((5.0..5.5).contains(&after(lines[0])), "{stderr}");
    assert!(after(last) >= 5.5, "{stderr}");
    assert_eq!(counters(lines[0]), counters(last), "{stderr}");
    // the table names what arrived
    let mut stdout = String::new();
    spy.stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    assert!(stdout.contains("nmea.GPHDT"), "{stdout}");
}
