//! LCM channel names that are not seabus topics (`POSE.`, `.POSE`, `a..b`, `cam*`, `with space`):
//! a liblcm program publishes them, `seabus record` keeps them in its log as they came and `seabus
//! spy` shows them quoted; `lcm-logplayer` of that log, and `seabus replay` of it onto LCM, reach
//! a liblcm subscriber on those very channels.
//!
//! The C program `tests/peers/lcm_channels.c` is built here against liblcm (`liblcm-dev`, which
//! `./scripts/test` installs).

mod common;
use common::*;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The odd names, and one that is a topic.
const CHANNELS: [&str; 6] = ["POSE.", ".POSE", "a..b", "cam*", "with space", "nav.depth"];

/// Builds the C peer in `dir`.
fn build_peer(dir: &Path) -> PathBuf {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/lcm_channels.c");
    let program = dir.join("lcm_channels");
    succeeds(
        Command::new("cc")
            .arg("-Wall")
            .arg("-o")
            .arg(&program)
            .arg(&source)
            .arg("-llcm"),
        "cc building the C peer against liblcm (./scripts/test installs liblcm-dev)",
    );
    program
}

/// A loopback LCM group of the test's own.
fn lcm_url() -> String {
    format!("udpm://{}:{}?ttl=0", group(), free_port())
}

/// A liblcm subscriber to every channel of `url` for `secs`, once it says it is subscribed.
fn subscriber(peer: &Path, url: &str, secs: u32) -> (Running, std::sync::mpsc::Receiver<String>) {
    subscribed(peer, "sub", url, secs)
}

/// A liblcm subscriber to every channel (`.*`) in `mode` (`sub`; `sizes`: each message's size
/// for its data; `sums`: its size and hash).
fn subscribed(
    peer: &Path,
    mode: &str,
    url: &str,
    secs: u32,
) -> (Running, std::sync::mpsc::Receiver<String>) {
    let mut sub = Running(
        Command::new(peer)
            .args([mode, url, &secs.to_string()])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("the subscriber starts"),
    );
    let rx = lines_of(sub.0.stdout.take().expect("piped"), Some);
    assert_eq!(
        rx.recv_timeout(Duration::from_secs(5)).as_deref(),
        Ok("ready"),
        "the subscriber subscribes"
    );
    (sub, rx)
}

/// The (channel, data) lines a subscriber printed within `limit`, until it has `want` of them.
fn received(
    rx: &std::sync::mpsc::Receiver<String>,
    want: usize,
    limit: Duration,
) -> Vec<(String, String)> {
    let deadline = Instant::now() + limit;
    let mut got = Vec::new();
    while got.len() < want && Instant::now() < deadline {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) {
            let (channel, data) = line.split_once('\t').expect("CHANNEL<TAB>DATA");
            got.push((channel.to_string(), data.to_string()));
        }
    }
    got
}

/// Every channel three times, each with its own name as data, in the order published.
fn published() -> Vec<(String, String)> {
    (0..3)
        .flat_map(|_| CHANNELS.iter().map(|c| (c.to_string(), c.to_string())))
        .collect()
}

#[test]
fn odd_lcm_channel_names_are_recorded_shown_and_replayed_as_they_came() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let peer = build_peer(dir.path());
    let url = lcm_url();
    let log = dir.path().join("odd.lcm");
    let record = spawn_record(&url, &log, 3);
    let spy = spawn_spy(&url, &["--for", "3"]);
    std::thread::sleep(Duration::from_millis(700));
    let out = Command::new(&peer)
        .arg("pub")
        .arg(&url)
        .args(CHANNELS)
        .output()
        .expect("the publisher runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let recorded = finish(record);
    assert_eq!(recorded.status.code(), Some(0), "{}", stderr(&recorded));
    assert!(
        stderr(&recorded).contains("18 events") && stderr(&recorded).contains("6 channels"),
        "{}",
        stderr(&recorded)
    );

    // the log holds every channel as it came, each event's data as sent
    let mut reader = seabus_medium::eventlog::Reader::open(&log).expect("the log opens");
    let mut events = Vec::new();
    for _ in 0..100 {
        match reader.next_event() {
            Ok(Some(e)) => events.push((
                e.channel.to_string(),
                String::from_utf8_lossy(e.data).into_owned(),
            )),
            Ok(None) => break,
            Err(d) => panic!("{}: {d}", log.display()),
        }
    }
    assert_eq!(events, published());

    // spy's table names them quoted, a topic as it is
    let shown = finish(spy);
    let table = String::from_utf8_lossy(&shown.stdout);
    for name in &CHANNELS[..5] {
        assert!(
            table.lines().any(|l| l.starts_with(&format!("{name:?} "))),
            "{name:?} in\n{table}"
        );
    }
    assert!(
        table.lines().any(|l| l.starts_with("nav.depth ")),
        "{table}"
    );

    // lcm-logplayer of seabus's log reaches a liblcm subscriber on those channels
    let again = lcm_url();
    let (_sub, rx) = subscriber(&peer, &again, 10);
    let played = Command::new("lcm-logplayer")
        .arg(format!("--lcm-url={again}"))
        .arg("--speed=4")
        .arg(&log)
        .output()
        .expect("lcm-logplayer runs (./scripts/test installs it: pip install lcm)");
    assert!(played.status.success(), "{}", stderr(&played));
    assert_eq!(received(&rx, 18, Duration::from_secs(5)), published());

    // and so does `seabus replay` onto LCM
    let third = lcm_url();
    let (_sub, rx) = subscriber(&peer, &third, 10);
    let replayed = seabus()
        .arg("replay")
        .arg(&log)
        .arg(&third)
        .args(["--speed", "4"])
        .output()
        .expect("replay runs");
    assert_eq!(replayed.status.code(), Some(0), "{}", stderr(&replayed));
    assert!(
        stderr(&replayed).contains("18 events sent on 6 channels"),
        "{}",
        stderr(&replayed)
    );
    assert_eq!(received(&rx, 18, Duration::from_secs(5)), published());
}

/// A system whose first medium is LCM, with a seabus bus beside it bridged to it by one typed
/// route: a liblcm subscriber on `.*` hears only that route's channel, in LCM's encoding (the
/// size of `seabus.depth_t`), and nothing of seabus's own (module states, media counters, the
/// bridge's report).
#[test]
fn a_liblcm_subscriber_on_every_channel_hears_only_what_the_routes_ask_for() {
    let dir = tempfile::tempdir().expect("dir");
    let peer = build_peer(dir.path());
    let url = lcm_url();
    let system = format!(
        r#"<seabus node="lcm-first">
  <medium name="lcm" url="{url}"/>
  <medium name="bus" url="inproc://"/>
  <module name="vehicle" type="vehicle-sim" medium="bus" tick="5Hz"/>
  <bridge name="to-lcm" media="bus lcm">
    <route from="bus" to="lcm" topics="nav.depth" rename="NAV_DEPTH" lcm="seabus.depth_t"/>
  </bridge>
</seabus>
"#
    );
    let (_dir, path) = system_file("lcm-first.xml", &system);
    let (_sub, rx) = subscribed(&peer, "sizes", &url, 8);
    // and lcm-logger, as LCM users record a vehicle
    let log = dir.path().join("run.lcmlog");
    let logger = Running(
        Command::new("lcm-logger")
            .arg(format!("--lcm-url={url}"))
            .arg("-f")
            .arg(&log)
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("lcm-logger starts (scripts/test installs it with Python's lcm)"),
    );
    let _run = spawn_run(&path, &["--for", "6"]);
    let mut channels = std::collections::BTreeMap::<String, Vec<String>>::new();
    let deadline = Instant::now() + Duration::from_secs(8);
    while Instant::now() < deadline {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) {
            let (channel, size) = line.split_once('\t').expect("CHANNEL<TAB>SIZE");
            // liblcm's own start-up self test, which lcm-logger sends
            if channel == "LCM_SELF_TEST" {
                continue;
            }
            channels
                .entry(channel.to_string())
                .or_default()
                .push(size.to_string());
        }
    }
    assert_eq!(
        channels.keys().collect::<Vec<_>>(),
        ["NAV_DEPTH"],
        "{channels:?}"
    );
    // 8 bytes of fingerprint, then the stamp (int64) and four doubles of seabus.depth_t
    let sizes = &channels["NAV_DEPTH"];
    assert!(sizes.len() >= 10, "{} NAV_DEPTH in 6 s", sizes.len());
    assert!(sizes.iter().all(|s| s == "48"), "{sizes:?}");
    // lcm-logger's log of the run decodes entirely with the lcm-gen classes of seabus's types
    interrupt(&logger);
    let mut logger = logger;
    assert!(
        wait_for(&mut logger, Duration::from_secs(5)).is_some(),
        "lcm-logger ends on Ctrl-C"
    );
    let classes = dir.path().join("classes");
    std::fs::create_dir_all(&classes).expect("a folder");
    succeeds(
        Command::new("lcm-gen")
            .arg("-p")
            .arg("--ppath")
            .arg(&classes)
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/configs/lcm/seabus.lcm"
            )),
        "lcm-gen -p configs/lcm/seabus.lcm",
    );
    let decode = "import sys, math, lcm\n\
                  from seabus import depth_t\n\
                  events = [e for e in lcm.EventLog(sys.argv[1], 'r') if e.channel != 'LCM_SELF_TEST']\n\
                  assert events, 'an empty log'\n\
                  for e in events:\n\
                  \x20   assert e.channel == 'NAV_DEPTH', e.channel\n\
                  \x20   m = depth_t.decode(e.data)\n\
                  \x20   assert m.utime > 0 and math.isfinite(m.depth), (m.utime, m.depth)\n\
                  print(len(events))\n";
    let logged: usize = python(
        decode,
        &[log.to_str().expect("a path")],
        &[("PYTHONPATH", classes.to_str().expect("a path"))],
    )
    .trim()
    .parse()
    .expect("the number of events decoded");
    assert!(logged >= 10, "{logged} events in lcm-logger's log");
}

/// `seabus pub --raw-file` sends a payload too long for the command line, from a file or from
/// standard input: a liblcm subscriber receives its 100 000 bytes (fragmented by LCM), as they are
/// (their FNV-1a hash, computed by the subscriber).
#[test]
fn pub_sends_a_hundred_kilobytes_from_a_file_or_standard_input() {
    let dir = tempfile::tempdir().expect("dir");
    let peer = build_peer(dir.path());
    let url = lcm_url();
    let file = dir.path().join("image.bin");
    let bytes: Vec<u8> = (0..100_000u32).map(|i| (i % 251) as u8).collect();
    std::fs::write(&file, &bytes).expect("written");
    let hash = bytes.iter().fold(2_166_136_261u32, |h, &b| {
        (h ^ u32::from(b)).wrapping_mul(16_777_619)
    });
    let (_sub, rx) = subscribed(&peer, "sums", &url, 10);
    succeeds(
        seabus()
            .args(["pub", &url, "IMAGE_FILE", "--raw-file"])
            .arg(&file),
        "seabus pub --raw-file FILE",
    );
    let mut pipe = seabus()
        .args(["pub", &url, "IMAGE_STDIN", "--raw-file", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("seabus pub starts");
    std::io::Write::write_all(&mut pipe.stdin.take().expect("piped"), &bytes).expect("written");
    let out = pipe.wait_with_output().expect("seabus pub ends");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sums = format!("100000\t{hash:08x}");
    assert_eq!(
        received(&rx, 2, Duration::from_secs(5)),
        [
            ("IMAGE_FILE".to_string(), sums.clone()),
            ("IMAGE_STDIN".to_string(), sums)
        ]
    );
    // a file that is not there is named
    let out = seabus()
        .args(["pub", &url, "IMAGE", "--raw-file", "/no/such.bin"])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .starts_with("seabus pub: --raw-file /no/such.bin: No such file"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
