//! The real MOOS peers: a MOOSDB and a libMOOS app (`tests/peers/moos_peer.cpp`), both from
//! core-moos as `scripts/peers moos` builds it once under `target/peers/` (it is run here when
//! `SEABUS_MOOSDB`/`SEABUS_LIBMOOS` are not set, as `./scripts/test` sets them). A build that fails
//! fails the test.

use super::{Running, free_tcp_port, lines_of, peer_paths, succeeds};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// Where the MOOSDB program and libMOOS (its `include/` and `lib/`) are.
pub struct CoreMoos {
    pub moosdb: PathBuf,
    pub libmoos: PathBuf,
}

/// core-moos, built once (by `scripts/peers moos` unless the environment names it).
pub fn core_moos() -> &'static CoreMoos {
    static BUILT: OnceLock<CoreMoos> = OnceLock::new();
    BUILT.get_or_init(|| {
        let mut paths = peer_paths("moos", &["SEABUS_MOOSDB", "SEABUS_LIBMOOS"]).into_iter();
        let (moosdb, libmoos) = (paths.next(), paths.next());
        CoreMoos {
            moosdb: moosdb.expect("the MOOSDB"),
            libmoos: libmoos.expect("libMOOS"),
        }
    })
}

/// The libMOOS app of `tests/peers/moos_peer.cpp`, compiled once per test program.
pub fn moos_peer() -> &'static Path {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT.get_or_init(|| {
        let moos = core_moos();
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = root.join("target/peers/moos-peer");
        std::fs::create_dir_all(&dir).expect("target/peers/moos-peer");
        // one binary per test program, so that programs run at once do not write one file
        let exe = dir.join(format!("moos_peer-{}", std::process::id()));
        succeeds(
            Command::new("g++")
                .args(["-O1", "-std=c++14", "-Wall", "-Werror", "-o"])
                .arg(&exe)
                .arg(root.join("tests/peers/moos_peer.cpp"))
                .arg("-I")
                .arg(moos.libmoos.join("include"))
                .arg(moos.libmoos.join("lib/libMOOS.a"))
                .arg("-lpthread"),
            "g++ tests/peers/moos_peer.cpp with libMOOS",
        );
        exe
    })
}

/// A real MOOSDB on a loopback port of its own, killed when dropped.
pub struct MoosDb {
    pub port: u16,
    dir: tempfile::TempDir,
    db: Option<Running>,
}

impl MoosDb {
    /// Starts a MOOSDB on a free port and waits until it takes connections.
    pub fn start() -> MoosDb {
        let mut db = MoosDb {
            port: free_tcp_port(),
            dir: tempfile::tempdir().expect("a directory for the MOOSDB"),
            db: None,
        };
        db.restart();
        db
    }

    /// Starts (again) the MOOSDB on its port.
    pub fn restart(&mut self) {
        let child = Command::new(&core_moos().moosdb)
            .arg(format!("--moos_port={}", self.port))
            .args(["--moos_suicide_disable", "--moos_no_colour"])
            .current_dir(self.dir.path())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("the MOOSDB starts");
        self.db = Some(Running(child));
        let deadline = Instant::now() + Duration::from_secs(10);
        while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(Instant::now() < deadline, "the MOOSDB listens within 10 s");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Kills the MOOSDB (as a crash would: no goodbye to its clients).
    pub fn kill(&mut self) {
        if let Some(mut db) = self.db.take() {
            let _ = db.0.kill();
            let _ = db.0.wait();
        }
    }

    /// `moos://127.0.0.1:PORT?name=NAME` and `extra` options.
    pub fn url(&self, name: &str, extra: &str) -> String {
        format!("moos://127.0.0.1:{}?name={name}{extra}", self.port)
    }
}

/// A MOOS value as the libMOOS app received it.
#[derive(Debug, Clone, PartialEq)]
pub enum MoosValue {
    Double(f64),
    Text(String),
    Binary(Vec<u8>),
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Vec<u8> {
    (0..text.len() / 2)
        .map(|i| u8::from_str_radix(&text[2 * i..2 * i + 2], 16).expect("hex"))
        .collect()
}

/// What libMOOS's `MOOSValFromString` finds for each of `keys` in `text`.
pub fn lookups(cases: &[(&str, Vec<String>)]) -> Vec<Vec<Option<String>>> {
    let mut child = Command::new(moos_peer())
        .arg("lookup")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("moos_peer lookup starts");
    {
        let mut input = child.stdin.take().expect("piped");
        for (text, keys) in cases {
            let mut line = hex(text.as_bytes());
            for k in keys {
                line.push(' ');
                line.push_str(&hex(k.as_bytes()));
            }
            line.push('\n');
            std::io::Write::write_all(&mut input, line.as_bytes()).expect("written");
        }
    }
    let out = child.wait_with_output().expect("moos_peer lookup ends");
    assert!(out.status.success(), "moos_peer lookup failed");
    String::from_utf8(out.stdout)
        .expect("text")
        .lines()
        .map(|l| {
            l.split(' ')
                .filter(|w| !w.is_empty())
                .map(|w| {
                    w.strip_prefix("1:")
                        .map(|h| String::from_utf8(unhex(h)).expect("UTF-8 value"))
                })
                .collect()
        })
        .collect()
}

/// A libMOOS app `name` writing each `(variable, value)` in order to the DB on `port`; returns
/// once they are sent.
pub fn moos_notify(port: u16, name: &str, writes: &[(&str, MoosValue)]) {
    let mut cmd = Command::new(moos_peer());
    cmd.args(["notify", "127.0.0.1", &port.to_string(), name]);
    for (var, value) in writes {
        match value {
            MoosValue::Double(d) => cmd.args([*var, "D", &format!("{d:?}")]),
            MoosValue::Text(t) => cmd.args([*var, "S", &hex(t.as_bytes())]),
            MoosValue::Binary(_) => panic!("moos_peer notify writes strings and doubles"),
        };
    }
    succeeds(&mut cmd, "moos_peer notify");
}

/// A libMOOS app `name` registered for `vars` on the DB on `port` for `secs` seconds; returns
/// once it is registered, with what it receives to come.
pub fn moos_watch(
    port: u16,
    name: &str,
    secs: u32,
    vars: &[&str],
) -> (Running, std::sync::mpsc::Receiver<(String, MoosValue)>) {
    let mut child = Running(
        Command::new(moos_peer())
            .args([
                "watch",
                "127.0.0.1",
                &port.to_string(),
                name,
                &secs.to_string(),
            ])
            .args(vars)
            .stdout(Stdio::piped())
            .spawn()
            .expect("moos_peer watch starts"),
    );
    let rx = lines_of(child.0.stdout.take().expect("piped"), |line| {
        if line == "ready" {
            return Some(("ready".to_string(), MoosValue::Double(0.0)));
        }
        let mut parts = line.splitn(3, '\t');
        let (var, kind, value) = (parts.next()?, parts.next()?, parts.next()?);
        let value = match kind {
            "D" => MoosValue::Double(value.parse().ok()?),
            "S" => MoosValue::Text(String::from_utf8(unhex(value)).ok()?),
            _ => MoosValue::Binary(unhex(value)),
        };
        Some((var.to_string(), value))
    });
    let ready = rx.recv_timeout(Duration::from_secs(15));
    assert!(
        matches!(&ready, Ok((r, _)) if r == "ready"),
        "moos_peer watch registers within 15 s: {ready:?}"
    );
    (child, rx)
}

/// The values the watcher received within `limit`, until `done` says they are enough.
pub fn moos_received(
    rx: &std::sync::mpsc::Receiver<(String, MoosValue)>,
    limit: Duration,
    mut done: impl FnMut(&[(String, MoosValue)]) -> bool,
) -> Vec<(String, MoosValue)> {
    let deadline = Instant::now() + limit;
    let mut got = Vec::new();
    while !done(&got) && Instant::now() < deadline {
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(50)) {
            got.push(v);
        }
    }
    got
}
