//! Address claim on one NMEA 2000 network shared by two `seabus run` nodes and canboat's own
//! device implementation (canboatjs's `N2kDevice`, `tests/peers/n2k_canboat_device.js`), all
//! preferring address 40.
//!
//! The network is a relay in this file that plays the wire: it is the slcan host of each node's
//! pseudo-terminal adapter (`slcan+pty://`) and the other end of the canboatjs device's slcan
//! lines (its standard input and output: canboatjs's CAN device needs SocketCAN, which this
//! kernel lacks, so its `N2kDevice` is given the frames as lines), and copies every frame to
//! every other port. When a port joins it asks for everyone's claims on it (an ISO Request from
//! the null address, as a device starting up does), since a node's first claim went out before
//! the relay had opened its channel.
//!
//! The devices join one after another: canboatjs (NAME highest) takes 40; node B (middle NAME)
//! claims 40 and wins it, canboatjs moves to 41; node A (lowest NAME) claims 40 and wins it, B
//! moves to the next address nobody holds, 42. Each then sends vessel headings from its address.
//! Then node C, not arbitrary-address capable, claims 40: that is the NAME's top bit, so C's NAME
//! is the lowest; A moves to 41, which it never heard claimed, and canboatjs, whose NAME is higher
//! than A's, moves on to 43; last, node D, not capable either and with a higher unique
//! number than C, claims 40: C defends it, D says it cannot claim (a claim from 254) and sends
//! nothing.

mod common;
use common::*;
use seabus_drivers::n2k::frame::Header;
use seabus_medium::{DataMap, Node, Value as V};
use serde_json::Value;
use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

/// Where canboatjs is (see `tests/n2k_send.rs`).
fn canboatjs() -> Option<PathBuf> {
    let modules = match std::env::var_os("SEABUS_CANBOATJS") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-canboat/node_modules"),
    };
    let found = modules.join("@canboat/canboatjs/package.json").is_file();
    if std::env::var_os("SEABUS_CANBOATJS").is_some() {
        assert!(
            found,
            "SEABUS_CANBOATJS={} holds no canboatjs",
            modules.display()
        );
    }
    found.then_some(modules)
}

type Port = Arc<Mutex<Box<dyn Write + Send>>>;

/// The wire: every frame a port sends goes to every other port; each is logged with its port.
#[derive(Clone, Default)]
struct Relay {
    ports: Arc<Mutex<Vec<Port>>>,
    log: Arc<Mutex<Vec<(usize, Header)>>>,
}

impl Relay {
    /// Adds a port; its lines that are not frames go to `other`.
    fn add(
        &self,
        reader: impl Read + Send + 'static,
        writer: impl Write + Send + 'static,
        other: Option<mpsc::Sender<String>>,
    ) -> usize {
        let port: Port = Arc::new(Mutex::new(Box::new(writer)));
        let index = {
            let mut ports = self.ports.lock().unwrap();
            ports.push(port);
            ports.len() - 1
        };
        let relay = self.clone();
        std::thread::spawn(move || {
            let mut r = BufReader::new(reader);
            let mut line = Vec::new();
            // each line ends in CR (slcan) or LF (the device's JSON); the loop ends with the port
            loop {
                line.clear();
                let mut byte = [0u8; 1];
                loop {
                    match r.read(&mut byte) {
                        Ok(1) if byte[0] == b'\r' || byte[0] == b'\n' => break,
                        Ok(1) if line.len() < 4096 => line.push(byte[0]),
                        Ok(1) => line.clear(),
                        _ => return,
                    }
                }
                let text = String::from_utf8_lossy(&line);
                let text = text.trim_start_matches(['\x07', 'z', 'Z']);
                if let Some(frame) = text.strip_prefix('T')
                    && let Some(id) = frame.get(..8).and_then(|h| u32::from_str_radix(h, 16).ok())
                {
                    relay.log.lock().unwrap().push((index, Header::from_id(id)));
                    let ports = relay.ports.lock().unwrap().clone();
                    for (i, p) in ports.iter().enumerate() {
                        if i != index {
                            let mut w = p.lock().unwrap();
                            let _ = w.write_all(format!("{text}\r").as_bytes());
                            let _ = w.flush();
                        }
                    }
                } else if let Some(tx) = &other
                    && text.starts_with('{')
                {
                    let _ = tx.send(text.to_string());
                }
            }
        });
        index
    }

    /// Opens a node's pseudo-terminal adapter as its host, and asks for the claims on it.
    fn add_pty(&self, path: &Path) -> usize {
        assert!(
            wait_for_path(path, Duration::from_secs(10)),
            "the pseudo-terminal {} appeared",
            path.display()
        );
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .unwrap();
        let mut w = f.try_clone().unwrap();
        // open at 250 kbit/s; then an ISO Request for PGN 60928 from 254 to everyone
        w.write_all(b"C\rS5\rO\rT18EAFFFE300EE00\r").unwrap();
        self.add(f, w, None)
    }

    /// The sources port `port` sent PGN `pgn` from, since log entry `from`.
    fn sources(&self, port: usize, pgn: u32, from: usize) -> Vec<u8> {
        let log = self.log.lock().unwrap();
        let mut s: Vec<u8> = log
            .iter()
            .skip(from)
            .filter(|(p, h)| *p == port && h.pgn == pgn)
            .map(|(_, h)| h.source)
            .collect();
        s.dedup();
        s
    }
}

/// A node's system: its own UDP bus, an slcan pseudo-terminal, the driver claiming 40 (with
/// `extra` attributes).
fn node(dir: &Path, name: &str, unique: u32, extra: &str) -> (PathBuf, PathBuf, String) {
    let pty = dir.join(format!("{name}.can"));
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let text = format!(
        r#"<seabus node="{name}">
  <medium name="bus" url="{}"/>
  <medium name="n2k" url="slcan+pty://{}"/>
  <module name="nmea2000" type="nmea2000" media="n2k bus" address="40"
          unique_number="{unique}" manufacturer_code="999" {extra}/>
</seabus>"#,
        bus.replace('&', "&amp;"),
        pty.display()
    );
    let path = dir.join(format!("{name}.xml"));
    std::fs::write(&path, text).unwrap();
    let checked = check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    (path, pty, bus)
}

/// A node on the network: `seabus run` of its system, and on its bus a watcher of `n2k.status`
/// and a sender; `port` is its port on the relay.
struct Joined {
    _run: Running,
    _bus: seabus_medium::Medium,
    rx: seabus_medium::Interface,
    tx: seabus_medium::Interface,
    port: usize,
}

/// Starts node `name` ([`node`]) and joins it to the network through `relay`, its bus watched
/// from before it starts.
fn join(relay: &Relay, dir: &Path, name: &str, unique: u32, extra: &str) -> Joined {
    let (path, pty, bus) = node(dir, name, unique, extra);
    let watch = schemes()
        .open("bus", &bus, &Node::new(&format!("watch-{name}")))
        .unwrap();
    let mut rx = watch.attach("watch");
    rx.subscribe("n2k.status").unwrap();
    let tx = watch.attach("send");
    let run = spawn_run(&path, &[]);
    let port = relay.add_pty(&pty);
    Joined {
        _run: run,
        _bus: watch,
        rx,
        tx,
        port,
    }
}

/// Has each of `nodes` send a vessel heading `rounds` times, 100 ms apart, then waits 500 ms for
/// the frames to cross the relay.
async fn send_headings(nodes: &[&Joined], rounds: usize) {
    for _ in 0..rounds {
        for n in nodes {
            n.tx.publish(
                seabus_medium::Kind::Data,
                "n2k.out.vesselHeading",
                DataMap::new().and("heading", V::Float(45.0)),
            )
            .await
            .unwrap();
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
}

/// The latest `n2k.status` of a node, waiting (at most `limit`) for one `pred` accepts.
async fn status_until(
    rx: &mut seabus_medium::Interface,
    limit: Duration,
    what: &str,
    pred: impl Fn(&DataMap) -> bool,
) -> DataMap {
    let deadline = tokio::time::Instant::now() + limit;
    let mut last = None;
    while let Ok(Some(m)) = tokio::time::timeout_at(deadline, rx.recv()).await {
        let map = m.payload.as_map().unwrap().clone();
        if pred(&map) {
            return map;
        }
        last = Some(map);
    }
    panic!("{what}: no such status within {limit:?}; the last was {last:?}");
}

/// Waits (at most `limit`) for the device to report `address` with sending allowed.
fn device_at(rx: &mpsc::Receiver<String>, address: u64, limit: Duration) -> Vec<Value> {
    let deadline = Instant::now() + limit;
    let mut seen = Vec::new();
    while Instant::now() < deadline {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(100))
            && let Ok(v) = serde_json::from_str::<Value>(&line)
        {
            seen.push(v.clone());
            if v["address"] == address && v["cansend"] == true {
                return seen;
            }
        }
    }
    panic!("the canboatjs device did not hold {address} within {limit:?}: {seen:?}");
}

fn claimed_at(address: i64) -> impl Fn(&DataMap) -> bool {
    move |m| m.get_str("state") == Some("claimed") && m.get_i64("address") == Some(address)
}

#[tokio::test(flavor = "multi_thread")]
async fn the_lowest_name_keeps_the_address_and_the_others_move_to_free_ones() {
    let Some(modules) = canboatjs() else {
        eprintln!(
            "SKIPPED the_lowest_name_keeps_the_address_and_the_others_move_to_free_ones: \
             canboatjs is not installed (scripts/test installs it and sets SEABUS_CANBOATJS)"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let relay = Relay::default();

    // canboatjs, the highest NAME (same fields, unique number 300000), takes 40
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/peers/n2k_canboat_device.js"
    );
    let mut device = Running(
        Command::new("node")
            .args([script, "40", "300000", "60"])
            .env("NODE_PATH", &modules)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node runs"),
    );
    let (dtx, drx) = mpsc::channel();
    let dev_port = relay.add(
        device.0.stdout.take().unwrap(),
        device.0.stdin.take().unwrap(),
        Some(dtx),
    );
    device_at(&drx, 40, Duration::from_secs(10));

    // node B, the middle NAME, claims 40 and keeps it; canboatjs moves to 41
    let mut b = join(&relay, dir.path(), "b", 200000, "");
    device_at(&drx, 41, Duration::from_secs(10));
    status_until(
        &mut b.rx,
        Duration::from_secs(10),
        "B at 40",
        claimed_at(40),
    )
    .await;

    // node A, the lowest NAME, claims 40 and keeps it; B moves to 42 (41 is canboatjs's)
    let mut a = join(&relay, dir.path(), "a", 100000, "");
    let b_status = status_until(
        &mut b.rx,
        Duration::from_secs(10),
        "B at 42",
        claimed_at(42),
    )
    .await;
    let a_status = status_until(
        &mut a.rx,
        Duration::from_secs(10),
        "A at 40",
        claimed_at(40),
    )
    .await;
    // each knows who holds what
    let devices = b_status.get("devices").and_then(V::as_map).unwrap();
    assert_eq!(devices.len(), 2, "{b_status}");
    assert!(
        devices.get("40").is_some() && devices.get("41").is_some(),
        "{b_status}"
    );
    assert!(
        a_status.get_str("name").unwrap() < b_status.get_str("name").unwrap(),
        "{a_status} {b_status}"
    );

    // everyone sends headings from the address it ended with
    let mark = relay.log.lock().unwrap().len();
    send_headings(&[&a, &b], 10).await;
    assert_eq!(relay.sources(a.port, 127250, mark), [40]);
    assert_eq!(relay.sources(b.port, 127250, mark), [42]);
    assert_eq!(relay.sources(dev_port, 127250, mark), [41]);
    // and their claims came from there
    assert_eq!(relay.sources(b.port, 60928, 0), [40, 42]);
    assert_eq!(relay.sources(a.port, 60928, 0), [40]);

    // node C, not arbitrary-address capable, claims 40: that bit is the NAME's top one, so C's
    // NAME is lower than every capable device's whatever its unique number. A moves to 41: it
    // joined after canboatjs's claim of 41 and never heard it; canboatjs, whose NAME is higher
    // than A's, moves on to 43 (42 is B's)
    let mut c = join(
        &relay,
        dir.path(),
        "c",
        400000,
        r#"arbitrary_address="false""#,
    );
    status_until(
        &mut a.rx,
        Duration::from_secs(10),
        "A at 41",
        claimed_at(41),
    )
    .await;
    device_at(&drx, 43, Duration::from_secs(10));
    status_until(
        &mut c.rx,
        Duration::from_secs(10),
        "C at 40",
        claimed_at(40),
    )
    .await;

    // node D, not capable either and with a higher unique number, claims 40: C defends it, and D
    // says it cannot claim (a claim from 254) and sends nothing
    let mut d = join(
        &relay,
        dir.path(),
        "d",
        500000,
        r#"arbitrary_address="false""#,
    );
    let d_status = status_until(&mut d.rx, Duration::from_secs(10), "D cannot claim", |m| {
        m.get_str("state") == Some("cannot-claim")
    })
    .await;
    assert_eq!(d_status.get_i64("address"), Some(254), "{d_status}");
    let mark = relay.log.lock().unwrap().len();
    send_headings(&[&a, &b, &c, &d], 5).await;
    assert_eq!(relay.sources(a.port, 127250, mark), [41]);
    assert_eq!(relay.sources(b.port, 127250, mark), [42]);
    assert_eq!(relay.sources(c.port, 127250, mark), [40]);
    assert_eq!(relay.sources(dev_port, 127250, mark), [43]);
    assert_eq!(relay.sources(d.port, 127250, mark), Vec::<u8>::new());
    assert_eq!(relay.sources(d.port, 60928, 0), [40, 254]);
    let d_status = status_until(&mut d.rx, Duration::from_secs(8), "D's refusals", |m| {
        m.get("refused")
            .and_then(V::as_map)
            .and_then(|r| r.get_i64("n2k-send-no-address"))
            .is_some_and(|n| n >= 5)
    })
    .await;
    assert_eq!(d_status.get_i64("sent"), Some(0), "{d_status}");
}
