//! A fleet over Zenoh: a router (Python `eclipse-zenoh`, router mode), three `seabus run` vehicles
//! (each a simulated Iver2 frontseat with its driver, its bus bridged to a Zenoh client medium)
//! and a shore `seabus run` bridging the fleet to a UDP bus that the test watches and commands.
//! Each vehicle lives in its own network namespace; the router and the shore live in a fourth.
//! auv2 and auv3 reach the router over veth pairs; auv1's link loses 20 % of its packets and
//! delays the rest by 100 ms in each direction, like `tc netem loss 20% delay 100ms` (which not
//! every kernel has, the one these tests run on among them): two TUN devices joined by a relay
//! in this test play that cable.
//!
//! Checked on the shore's bus: every vehicle's position arrives, in order and current; a course
//! command sent once to each vehicle is carried exactly once by that vehicle's bus (each vehicle
//! shows its commands on a UDP medium of its own namespace), taken once by its frontseat and
//! acknowledged; no message is seen twice; the router is killed and started again and every node reconnects by
//! itself (positions flow, the fleet shows each vehicle online again, commands are acknowledged);
//! a vehicle killed outright is shown offline within 5 s.
//!
//! Needs root, `ip` (iproute2) and `/dev/net/tun`. Without them it fails with the reason when
//! `SEABUS_REQUIRE_PRIVILEGES` is set (as `scripts/test` does as root), and otherwise says
//! plainly on stderr that it was skipped.

mod common;
use common::*;
use serde_json::Value;
use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

const TEST: &str = "a_fleet_through_a_router_survives_loss_restarts_and_a_lost_vehicle";
/// The shore's bus, inside the router's namespace.
const BUS: &str = "udp://239.255.77.1:47800?ttl=0";
/// Where each vehicle shows the commands its bus carried, inside its namespace.
const WITNESS: &str = "udp://239.255.77.2:47801?ttl=0";
const ROUTER_PORT: u16 = 7447;
const VEHICLES: [&str; 3] = ["auv1", "auv2", "auv3"];
/// Where each vehicle's simulator starts.
const PLACES: [(f64, f64); 3] = [(43.5081, 16.4402), (43.5181, 16.4502), (43.5281, 16.4602)];
/// The vehicle whose link is lossy and slow.
const LOSSY: usize = 0;
const LOSS: f64 = 0.2;
const DELAY: Duration = Duration::from_millis(100);
/// Nothing this test starts lives longer than this.
const LIFETIME: Duration = Duration::from_secs(180);

fn now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// `ip netns exec NS PROGRAM …`
fn in_namespace(ns: &str, program: &str) -> Command {
    let mut c = Command::new("ip");
    c.args(["netns", "exec", ns, program]);
    c.env_remove("RUST_LOG");
    c
}

/// The namespaces: the router's and one per vehicle, removed on drop (the links go with them).
struct Net {
    router: String,
    vehicles: Vec<String>,
    /// links made in this namespace, gone once moved
    links: Vec<String>,
    /// the lossy link between auv1 and the router
    cable: Option<Cable>,
}

impl Net {
    fn new() -> Result<Net, String> {
        let id = std::process::id() % 100_000;
        let mut net = Net {
            router: format!("sbf-r-{id}"),
            vehicles: Vec::new(),
            links: Vec::new(),
            cable: None,
        };
        ip(&["netns", "add", &net.router])?;
        ip(&["-n", &net.router, "link", "set", "lo", "up"])?;
        for n in 1..=VEHICLES.len() {
            let ns = format!("sbf-v{n}-{id}");
            ip(&["netns", "add", &ns])?;
            net.vehicles.push(ns.clone());
            ip(&["-n", &ns, "link", "set", "lo", "up"])?;
            let (near, far) = (format!("sbfr{n}{id}"), format!("sbfv{n}{id}"));
            if n - 1 == LOSSY {
                net.cable = Some(Cable::new((&net.router, &near), (&ns, &far))?);
            } else {
                ip(&["link", "add", &near, "type", "veth", "peer", "name", &far])?;
                net.links.push(near.clone());
                ip(&["link", "set", &near, "netns", &net.router])?;
                ip(&["link", "set", &far, "netns", &ns])?;
            }
            for (ns, dev, host) in [(&net.router, &near, 1), (&ns, &far, 2)] {
                let addr = format!("10.77.{n}.{host}/24");
                ip(&["-n", ns, "addr", "add", &addr, "dev", dev])?;
                ip(&["-n", ns, "link", "set", dev, "up"])?;
            }
        }
        Ok(net)
    }
}

impl Drop for Net {
    fn drop(&mut self) {
        self.cable.take();
        for link in &self.links {
            let _ = ip(&["link", "del", link]);
        }
        for ns in self.vehicles.iter().chain([&self.router]) {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}

/// A lossy, slow cable: a TUN device in each of two namespaces and threads carrying the packets
/// between them, dropping `LOSS` of them and delaying the rest by `DELAY`, each way.
struct Cable {
    stop: Arc<AtomicBool>,
    /// packets carried and dropped, each way
    counts: Arc<[AtomicU64; 4]>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

/// Opens TUN device `name` (IP packets, no header) in namespace `ns`.
fn tun(ns: &str, name: &str) -> Result<File, String> {
    #[repr(C)]
    struct IfReq {
        name: [u8; libc::IFNAMSIZ],
        flags: libc::c_short,
        _rest: [u8; 22],
    }
    const TUNSETIFF: libc::c_ulong = 0x4004_54ca;
    let (ns, name) = (ns.to_string(), name.to_string());
    std::thread::spawn(move || {
        // (the device is made in the namespace of the thread that asks for it)
        enter_namespace(&ns).map_err(|e| format!("entering {ns}: {e}"))?;
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open("/dev/net/tun")
            .map_err(|e| format!("/dev/net/tun: {e}"))?;
        let mut req = IfReq {
            name: [0; libc::IFNAMSIZ],
            flags: (libc::IFF_TUN | libc::IFF_NO_PI) as libc::c_short,
            _rest: [0; 22],
        };
        req.name[..name.len()].copy_from_slice(name.as_bytes());
        // SAFETY: TUNSETIFF on a file we own, with an ifreq laid out as the kernel reads it
        if unsafe { libc::ioctl(f.as_raw_fd(), TUNSETIFF as _, &mut req) } != 0 {
            return Err(format!(
                "TUN device {name}: {}",
                std::io::Error::last_os_error()
            ));
        }
        Ok(f)
    })
    .join()
    .map_err(|_| "the thread making a TUN device panicked".to_string())?
}

impl Cable {
    fn new(a: (&str, &str), b: (&str, &str)) -> Result<Cable, String> {
        let ends = [Arc::new(tun(a.0, a.1)?), Arc::new(tun(b.0, b.1)?)];
        let stop = Arc::new(AtomicBool::new(false));
        let counts: Arc<[AtomicU64; 4]> = Arc::new(Default::default());
        let mut threads = Vec::new();
        for way in 0..2 {
            let (from, to) = (ends[way].clone(), ends[1 - way].clone());
            let (tx, rx) = mpsc::channel::<(Instant, Vec<u8>)>();
            let (stop_r, counts_r) = (stop.clone(), counts.clone());
            threads.push(std::thread::spawn(move || {
                carry_in(&from, &tx, &stop_r, &counts_r, way)
            }));
            let stop_w = stop.clone();
            threads.push(std::thread::spawn(move || carry_out(&to, &rx, &stop_w)));
        }
        Ok(Cable {
            stop,
            counts,
            threads,
        })
    }

    /// (carried, dropped) in direction `way`: 0 from the router, 1 to it.
    fn counts(&self, way: usize) -> (u64, u64) {
        (
            self.counts[2 * way].load(Ordering::Relaxed),
            self.counts[2 * way + 1].load(Ordering::Relaxed),
        )
    }
}

/// Reads packets from one end: a share of them is dropped, the rest queued for `DELAY`.
fn carry_in(
    from: &File,
    tx: &mpsc::Sender<(Instant, Vec<u8>)>,
    stop: &AtomicBool,
    counts: &[AtomicU64; 4],
    way: usize,
) {
    use std::io::Read;
    let start = Instant::now();
    let mut buf = vec![0u8; 65536];
    while !stop.load(Ordering::Relaxed) && start.elapsed() < LIFETIME {
        let mut pfd = libc::pollfd {
            fd: from.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: poll(2) on one descriptor we hold
        if unsafe { libc::poll(&mut pfd, 1, 100) } <= 0 {
            continue;
        }
        let Ok(n) = (&*from).read(&mut buf) else {
            continue;
        };
        if fastrand::f64() < LOSS {
            counts[2 * way + 1].fetch_add(1, Ordering::Relaxed);
            continue;
        }
        counts[2 * way].fetch_add(1, Ordering::Relaxed);
        if tx
            .send((Instant::now() + DELAY, buf[..n].to_vec()))
            .is_err()
        {
            return;
        }
    }
}

/// Writes the queued packets to the other end when their time comes.
fn carry_out(to: &File, rx: &mpsc::Receiver<(Instant, Vec<u8>)>, stop: &AtomicBool) {
    use std::io::Write;
    let start = Instant::now();
    while !stop.load(Ordering::Relaxed) && start.elapsed() < LIFETIME {
        let Ok((due, packet)) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        let _ = (&*to).write(&packet);
    }
}

impl Drop for Cable {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The programs' output files, shown when the test fails.
struct Logs(Vec<PathBuf>);

impl Logs {
    fn file(&mut self, dir: &Path, name: &str) -> (Stdio, Stdio) {
        let path = dir.join(format!("{name}.log"));
        let f = File::create(&path).expect("a log file");
        self.0.push(path);
        (f.try_clone().unwrap().into(), f.into())
    }
}

impl Drop for Logs {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            return;
        }
        for path in &self.0 {
            let text = std::fs::read_to_string(path).unwrap_or_default();
            let lines: Vec<&str> = text.lines().collect();
            let tail = &lines[lines.len().saturating_sub(25)..];
            eprintln!("--- {} ---\n{}", path.display(), tail.join("\n"));
        }
    }
}

fn vehicle_system(n: usize, dir: &Path) -> String {
    let name = VEHICLES[n];
    let (lat, lon) = PLACES[n];
    let line = dir.join(format!("{name}-frontseat")).display().to_string();
    let zenoh = format!(
        "zenoh://?mode=client&amp;connect=tcp/10.77.{}.1:{ROUTER_PORT}&amp;prefix=fleet/{name}&amp;scout=false",
        n + 1
    );
    format!(
        r#"<seabus node="{name}">
  <medium name="bus" url="inproc://"/>
  <medium name="frontseat" url="pty://{line}?framing=lines"/>
  <medium name="serial" url="serial://{line}?baud=19200&amp;framing=nmea"/>
  <medium name="fleet" url="{zenoh}"/>
  <module name="frontseat-sim" type="iver2-sim" media="frontseat" lat="{lat}" lon="{lon}" autostart="true"/>
  <module name="iver" type="iver2" media="serial bus" version="5" request_every="250ms"/>
  <medium name="witness" url="{WITNESS}"/>
  <bridge name="shore" media="bus fleet" report="0">
    <route from="bus" to="fleet" topics="**"/>
    <route from="fleet" to="bus" topics="cmd.**" kind="command"/>
  </bridge>
  <bridge name="witness" media="bus witness" report="0">
    <route from="bus" to="witness" topics="cmd.**"/>
  </bridge>
</seabus>"#
    )
}

fn shore_system() -> String {
    let zenoh = format!(
        "zenoh://?mode=client&amp;connect=tcp/127.0.0.1:{ROUTER_PORT}&amp;prefix=fleet&amp;scout=false"
    );
    format!(
        r#"<seabus node="shore">
  <medium name="bus" url="{BUS}"/>
  <medium name="fleet" url="{zenoh}"/>
  <bridge name="vehicles" media="bus fleet" report="0">
    <route from="fleet" to="bus" topics="*.nav.position"/>
    <route from="fleet" to="bus" topics="*.cmd.status"/>
    <route from="fleet" to="bus" topics="seabus.fleet"/>
    <route from="bus" to="fleet" topics="*.cmd.**" kind="command"/>
  </bridge>
</seabus>"#
    )
}

/// Starts `seabus run FILE` in namespace `ns`, its output to `log`.
fn run_in(ns: &str, path: &Path, log: (Stdio, Stdio)) -> Running {
    Running(
        in_namespace(ns, env!("CARGO_BIN_EXE_seabus"))
            .arg("run")
            .arg(path)
            .stdin(Stdio::null())
            .stdout(log.0)
            .stderr(log.1)
            .spawn()
            .expect("seabus run starts"),
    )
}

/// Starts the router in namespace `ns` and waits (at most 15 s) until it listens.
fn start_router(ns: &str, log: Stdio) -> Running {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/zenoh_router.py");
    let endpoint = format!("tcp/0.0.0.0:{ROUTER_PORT}");
    let mut router = Running(
        in_namespace(ns, "python3")
            .args([script, &endpoint, &LIFETIME.as_secs().to_string()])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .expect("python3 runs"),
    );
    let out = router.0.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        let mut first = String::new();
        let _ = std::io::BufReader::new(out).read_line(&mut first);
        let _ = tx.send(first);
    });
    let said = rx.recv_timeout(Duration::from_secs(15));
    assert_eq!(
        said.as_deref().map(str::trim),
        Ok("ready"),
        "the router did not start"
    );
    router
}

/// Sends a course command to `vehicle` through the shore's bus: the origin it was sent as.
fn command(ns: &str, vehicle: &str, heading: f64) -> String {
    let mut pubber = in_namespace(ns, env!("CARGO_BIN_EXE_seabus"))
        .args([
            "pub",
            BUS,
            &format!("{vehicle}.cmd.course"),
            &format!("heading={heading:.1}"),
            "depth=2.0",
            "speed=1.2",
            // (held for a minute, so that the frontseat stays under command between the rounds)
            "timeout=60.0",
            "--command",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("seabus pub starts");
    // (`ip netns exec` becomes the program: the pid is seabus pub's own)
    let pid = pubber.id();
    let status = wait_for(&mut pubber, Duration::from_secs(10));
    assert!(
        status.is_some_and(|s| s.success()),
        "seabus pub to {vehicle} failed"
    );
    format!("pub-{pid}/pub")
}

/// Starts `seabus spy URL --json` in namespace `ns`: what it shows, as it comes.
fn spy(ns: &str, url: &str) -> (Running, Watch) {
    let mut spy = Running(
        in_namespace(ns, env!("CARGO_BIN_EXE_seabus"))
            .args([
                "spy",
                url,
                "--json",
                "--for",
                &LIFETIME.as_secs().to_string(),
            ])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("seabus spy starts"),
    );
    let (tx, rx) = mpsc::channel();
    let out = spy.0.stdout.take().unwrap();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str::<Value>(&line)
                && tx.send(v).is_err()
            {
                return;
            }
        }
    });
    (
        spy,
        Watch {
            rx,
            seen: Vec::new(),
        },
    )
}

/// What a bus carried, each message with the moment it was read.
struct Watch {
    rx: mpsc::Receiver<Value>,
    seen: Vec<(Instant, Value)>,
}

impl Watch {
    /// Reads what came, waiting at most `wait` for the first; each message gets `arrived`, the
    /// time it was read (seconds since 1970).
    fn read(&mut self, wait: Duration) {
        let mut first = self.rx.recv_timeout(wait).ok();
        while let Some(mut v) = first.take().or_else(|| self.rx.try_recv().ok()) {
            if let Some(fields) = v.as_object_mut() {
                fields.insert("arrived".into(), now().into());
            }
            self.seen.push((Instant::now(), v));
        }
    }

    /// Reads until `found` answers, at most `limit`; the time it took.
    fn until<T>(
        &mut self,
        limit: Duration,
        what: &str,
        mut found: impl FnMut(&[(Instant, Value)]) -> Option<T>,
    ) -> (T, Duration) {
        let start = Instant::now();
        loop {
            self.read(Duration::from_millis(20));
            if let Some(t) = found(&self.seen) {
                return (t, start.elapsed());
            }
            if start.elapsed() > limit {
                let last: Vec<String> = self
                    .seen
                    .iter()
                    .rev()
                    .take(30)
                    .map(|(_, v)| v.to_string())
                    .collect();
                panic!(
                    "{what}: not within {limit:?}; the shore's bus carried {} messages, the last:\n{}",
                    self.seen.len(),
                    last.join("\n")
                );
            }
        }
    }

    /// Reads for `time`.
    fn keep_reading(&mut self, time: Duration) {
        let start = Instant::now();
        while start.elapsed() < time {
            self.read(Duration::from_millis(20));
        }
    }
}

fn is(v: &Value, topic: &str) -> bool {
    v["topic"] == topic
}

fn fleet_says<'a>(
    seen: &'a [(Instant, Value)],
    node: &str,
) -> impl Iterator<Item = &'a (Instant, Value)> {
    seen.iter()
        .filter(move |(_, v)| is(v, "seabus.fleet") && v["payload"]["node"] == node)
}

/// The OMS statuses from `vehicle` answering the command sent as `origin`.
fn oms_states(seen: &[(Instant, Value)], vehicle: &str, origin: &str) -> Vec<String> {
    seen.iter()
        .map(|(_, v)| v)
        .filter(|v| {
            is(v, &format!("{vehicle}.cmd.status"))
                && v["payload"]["command"] == "OMS"
                && v["payload"]["origin"] == origin
        })
        .map(|v| v["payload"]["state"].as_str().unwrap_or("?").to_string())
        .collect()
}

/// Sends one course command to every vehicle and waits until each is acknowledged; then reads
/// 2 s more, and checks that each vehicle's bus carried it exactly once and its frontseat took it
/// once as a new course.
fn command_every_vehicle(
    shore: &mut Watch,
    witnesses: &mut [Watch],
    ns: &str,
    heading: f64,
    limit: Duration,
) -> Duration {
    let origins: Vec<String> = VEHICLES.iter().map(|v| command(ns, v, heading)).collect();
    let (_, took) = shore.until(limit, "every vehicle acknowledging its course", |seen| {
        VEHICLES
            .iter()
            .zip(&origins)
            .all(|(v, o)| oms_states(seen, v, o).iter().any(|s| s != "pending"))
            .then_some(())
    });
    shore.keep_reading(Duration::from_secs(2));
    for ((v, o), witness) in VEHICLES.iter().zip(&origins).zip(witnesses.iter_mut()) {
        witness.read(Duration::ZERO);
        let arrived: Vec<&Value> = witness
            .seen
            .iter()
            .map(|(_, m)| m)
            .filter(|m| m["origin"] == o.as_str())
            .collect();
        assert_eq!(
            arrived.len(),
            1,
            "{v}'s bus carried its command {o} so: {arrived:?}"
        );
        assert_eq!(arrived[0]["topic"], "cmd.course", "{}", arrived[0]);
        assert_eq!(arrived[0]["kind"], "command", "{}", arrived[0]);
        assert_eq!(arrived[0]["payload"]["heading"], heading, "{}", arrived[0]);
        assert_eq!(
            oms_states(&shore.seen, v, o),
            ["pending", "acknowledged"],
            "{v}'s course command (sent once as {o}) at its frontseat"
        );
    }
    took
}

#[test]
fn a_fleet_through_a_router_survives_loss_restarts_and_a_lost_vehicle() {
    let Some(net) = privileged(
        TEST,
        Net::new().map_err(|e| format!("cannot make network namespaces and links ({e})")),
    ) else {
        return;
    };
    let began = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let mut logs = Logs(Vec::new());

    // the systems, checked
    let mut files = Vec::new();
    for (n, name) in VEHICLES.iter().enumerate() {
        let path = dir.path().join(format!("{name}.xml"));
        std::fs::write(&path, vehicle_system(n, dir.path())).unwrap();
        files.push(path);
    }
    let shore_file = dir.path().join("shore.xml");
    std::fs::write(&shore_file, shore_system()).unwrap();
    for f in files.iter().chain([&shore_file]) {
        let checked = check(f);
        assert!(
            checked.status.success(),
            "{}: {}",
            f.display(),
            String::from_utf8_lossy(&checked.stderr)
        );
    }

    // the shore's bus and the commands on each vehicle's bus, watched from the start
    let (spy_shore, mut shore) = spy(&net.router, BUS);
    let (witness_spies, mut witnesses): (Vec<Running>, Vec<Watch>) =
        net.vehicles.iter().map(|ns| spy(ns, WITNESS)).unzip();

    let mut router = start_router(&net.router, logs.file(dir.path(), "router-1").1);
    let _shore_run = run_in(&net.router, &shore_file, logs.file(dir.path(), "shore"));
    let mut vehicles: Vec<Running> = (0..VEHICLES.len())
        .map(|n| {
            run_in(
                &net.vehicles[n],
                &files[n],
                logs.file(dir.path(), VEHICLES[n]),
            )
        })
        .collect();

    // every vehicle's position reaches the shore, from where its simulator is
    let (_, first_data) = shore.until(
        Duration::from_secs(30),
        "every vehicle's position",
        |seen| {
            VEHICLES
                .iter()
                .all(|v| {
                    seen.iter()
                        .any(|(_, m)| is(m, &format!("{v}.nav.position")))
                })
                .then_some(())
        },
    );
    for (n, v) in VEHICLES.iter().enumerate() {
        let (_, p) = shore
            .seen
            .iter()
            .find(|(_, m)| is(m, &format!("{v}.nav.position")))
            .unwrap();
        let (lat, lon) = (p["payload"]["lat"].as_f64(), p["payload"]["lon"].as_f64());
        assert!(
            lat.is_some_and(|l| (l - PLACES[n].0).abs() < 0.005)
                && lon.is_some_and(|l| (l - PLACES[n].1).abs() < 0.005),
            "{v}'s position: {p}"
        );
    }
    // and the fleet shows each online
    shore.until(Duration::from_secs(10), "every vehicle online", |seen| {
        VEHICLES
            .iter()
            .all(|v| fleet_says(seen, v).any(|(_, m)| m["payload"]["online"] == true))
            .then_some(())
    });

    // a course command to each vehicle, sent once, arrives once and is acknowledged
    let first_commands = command_every_vehicle(
        &mut shore,
        &mut witnesses,
        &net.router,
        90.0,
        Duration::from_secs(15),
    );

    // the data is current: each vehicle's latest position reaches the shore less than a second
    // after it was taken
    let fresh_from = Instant::now();
    shore.until(
        Duration::from_secs(10),
        "a current position of every vehicle",
        |seen| {
            VEHICLES
                .iter()
                .all(|v| {
                    seen.iter().any(|(at, m)| {
                        *at > fresh_from
                            && is(m, &format!("{v}.nav.position"))
                            && m["stamp"].as_f64().is_some_and(|t| now() - t < 1.0)
                    })
                })
                .then_some(())
        },
    );

    // the router goes, and comes back: every node reconnects by itself
    let (carried, dropped) = (
        net.cable.as_ref().unwrap().counts(0),
        net.cable.as_ref().unwrap().counts(1),
    );
    // SAFETY: kill(2) on our own child's pid
    unsafe {
        libc::kill(router.id() as libc::pid_t, libc::SIGKILL);
    }
    let _ = router.wait();
    let stopped_at = now();
    shore.keep_reading(Duration::from_secs(3));
    let outage_offline: Vec<&str> = VEHICLES
        .iter()
        .copied()
        .filter(|v| {
            fleet_says(&shore.seen, v).any(|(_, m)| {
                m["payload"]["online"] == false
                    && m["payload"]["since"].as_f64() >= Some(stopped_at - 0.5)
            })
        })
        .collect();
    assert_eq!(
        outage_offline, VEHICLES,
        "the shore shows every vehicle offline while the router is away"
    );
    router = start_router(&net.router, logs.file(dir.path(), "router-2").1);
    let restarted = Instant::now();
    let (_, reconnected) = shore.until(
        Duration::from_secs(20),
        "every vehicle's position and membership after the router came back",
        |seen| {
            VEHICLES
                .iter()
                .all(|v| {
                    let data = seen.iter().any(|(at, m)| {
                        *at > restarted
                            && is(m, &format!("{v}.nav.position"))
                            && m["stamp"].as_f64() > Some(stopped_at)
                    });
                    let member = fleet_says(seen, v).any(|(at, m)| {
                        *at > restarted
                            && m["payload"]["online"] == true
                            && m["payload"]["since"].as_f64() > Some(stopped_at)
                    });
                    data && member
                })
                .then_some(())
        },
    );
    // commands find their way through the new router too
    let second_commands = command_every_vehicle(
        &mut shore,
        &mut witnesses,
        &net.router,
        180.0,
        Duration::from_secs(15),
    );

    // a vehicle killed outright is shown offline within 5 s
    let lost = LOSSY;
    let lost_name = VEHICLES[lost];
    // SAFETY: kill(2) on our own child's pid
    unsafe {
        libc::kill(vehicles[lost].id() as libc::pid_t, libc::SIGKILL);
    }
    let killed = Instant::now();
    let _ = vehicles[lost].wait();
    let (_, offline) = shore.until(
        Duration::from_secs(5),
        &format!("{lost_name} offline"),
        |seen| {
            fleet_says(seen, lost_name)
                .any(|(at, m)| *at > killed && m["payload"]["online"] == false)
                .then_some(())
        },
    );
    assert!(
        offline < Duration::from_secs(5),
        "{lost_name} shown offline after {offline:?}"
    );
    shore.keep_reading(Duration::from_secs(1));

    // nothing reached the shore's bus twice, and each vehicle's positions came in order
    let mut ids = HashSet::new();
    for (_, m) in &shore.seen {
        let id = (m["origin"].to_string(), m["seq"].as_u64().unwrap());
        assert!(ids.insert(id), "seen twice on the shore's bus: {m}");
    }
    let mut last_seq: BTreeMap<String, u64> = BTreeMap::new();
    for (_, m) in shore.seen.iter().filter(|(_, m)| {
        m["topic"]
            .as_str()
            .is_some_and(|t| t.ends_with(".nav.position"))
    }) {
        let key = format!("{} {}", m["topic"], m["origin"]);
        let seq = m["seq"].as_u64().unwrap();
        if let Some(before) = last_seq.insert(key, seq) {
            assert!(seq > before, "a position older than the one before it: {m}");
        }
    }
    // the lossy link did lose packets, both ways
    let cable = net.cable.as_ref().unwrap();
    let (to_vehicle, to_router) = (cable.counts(0), cable.counts(1));
    assert!(
        to_vehicle.1 > 0 && to_router.1 > 0,
        "the lossy link dropped nothing: {to_vehicle:?} {to_router:?}"
    );
    let delays: Vec<String> = VEHICLES
        .iter()
        .map(|v| {
            let mut d: Vec<f64> = shore
                .seen
                .iter()
                .filter(|(_, m)| is(m, &format!("{v}.nav.position")))
                .filter_map(|(_, m)| Some(m["arrived"].as_f64()? - m["stamp"].as_f64()?))
                .collect();
            d.sort_by(f64::total_cmp);
            format!(
                "{v} {} positions, delay median {:.3} s max {:.3} s",
                d.len(),
                d[d.len() / 2],
                d[d.len() - 1]
            )
        })
        .collect();
    eprintln!("fleet: {}", delays.join("; "));
    eprintln!(
        "fleet: first data after {first_data:?}; commands acknowledged after {first_commands:?}; \
         before the router stopped the lossy link carried/dropped {carried:?} to {} and {dropped:?} \
         to the router; reconnected {reconnected:?} \
         after the router came back; commands after {second_commands:?}; {lost_name} offline {offline:?} \
         after it was killed; {} messages on the shore's bus; {:?} in all",
        VEHICLES[LOSSY],
        shore.seen.len(),
        began.elapsed()
    );

    for v in vehicles.iter_mut() {
        terminate(v);
        wait_for(v, Duration::from_secs(5));
    }
    // gaps (the router's restart, the lost vehicle) are said once by seabus, counted by topic
    // ("N messages lost … (missed on the wire)"), never line by line by Zenoh itself
    for path in &logs.0 {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            !text.contains("Sample missed"),
            "{}: Zenoh's own gap warnings: {}",
            path.display(),
            text.lines().filter(|l| l.contains("Sample missed")).count()
        );
    }
    terminate(&router);
    terminate(&spy_shore);
    for w in &witness_spies {
        terminate(w);
    }
}
