//! The Zenoh medium against the bare `zenoh` crate on loopback, side by side in one run.
//!
//! 1. **Throughput** (peer mode, one session listening on `tcp/127.0.0.1:PORT`, the other
//!    connecting): a publisher sends a fixed number of 64 B or 4 kB messages on one key as fast as
//!    it can; the subscriber counts what arrives. Both sides use seabus's quality of service for
//!    data (`CongestionControl::Drop`, `Priority::Data`, not express), so a publisher that outruns
//!    the link loses messages; the figure is the *delivered* rate, from the first message sent to
//!    the last one received (the drain ends when nothing more arrives for 300 ms), and how many of
//!    those sent arrived is printed beside it. Seabus: `Interface::send` of a bytes payload on one
//!    `zenoh://` medium, the messages taken from an interface subscribed to the topic on the other
//!    (the same key expression as bare's). Bare: a declared publisher's `put`, counted in the
//!    subscriber's callback. Also shown: bare Zenoh with the subscriber's samples taken from a
//!    FIFO channel by a task (the hand-over from Zenoh's thread to the program's that a seabus
//!    interface also makes), and both subscribed by wildcard (`**`, key `bench/**`), as a shore
//!    station subscribes. Best of [`ROUNDS`] rounds taken in turn.
//! 2. **Latency**: the same pairs, 1000 messages of 64 B at 500 per second, one-way (the sender's
//!    wall clock in the payload, read against the receiver's in the same process); best p50 and
//!    best p99 of [`LAT_ROUNDS`] rounds taken in turn.
//! 3. **Fleet**: a bare Zenoh router on `tcp/127.0.0.1:PORT`; 20 vehicles, clients of the router,
//!    each publishing navigation (position, attitude, velocity: three small datamaps) at 10 Hz; one
//!    shore station, a client of the router, subscribed to the whole fleet. The shore runs in a
//!    child process (this binary again), so its CPU time (`getrusage`) is its own; it also reads
//!    the bytes its TCP connection received (`TCP_INFO`). Seabus: 20 `zenoh://` media with prefix
//!    `fleet/auvN` sending datamaps, a shore medium with prefix `fleet` and one interface taking
//!    everything (binary datagrams, and again with `json=true`). Bare: 20 sessions putting the
//!    same datamaps as JSON text, the shore's callback parsing each into a `serde_json::Value`.
//!    Payload bytes are what the samples carried: the JSON text for bare; for seabus the datagram
//!    (or the JSON text and the attached datagram), its length found again on the shore from the
//!    message received. The medium's own `seabus.fleet` announcements are not counted. Lowest
//!    shore CPU of [`FLEET_ROUNDS`] rounds taken in turn.
//!
//! Each part also has a "bare advanced" side: Zenoh-ext's advanced publisher and subscriber
//! configured as the medium configures them for data (the latest sample cached for late joiners,
//! samples numbered with heartbeats so that misses are detected and recovered, history asked of
//! publishers found late), so that what those features cost is told apart from what seabus's own
//! handling costs.
//!
//! Every session has multicast scouting off and listens on loopback only.
//!
//! Goals, against bare Zenoh (callback): 64 B and 4 kB delivered at least 0.8×; latency p50 and
//! p99 at most 1.3×.
//!
//! ```text
//! cargo bench -p seabus-medium-zenoh --bench zenoh [-- throughput|latency|fleet]
//! ```
//!
//! The smoke run (`SEABUS_BENCH_SMOKE=1`) is shorter: fewer messages (and latency rounds), only
//! seabus and bare Zenoh (callback), and no fleet (which has no goal).
//!
//! `-- profile [SIZE]` runs only seabus's flood (64 B unless SIZE is given), five times, to be
//! profiled (`perf record -g`).

#[path = "../../core/benches/common.rs"]
mod common;

use bytes::Bytes;
use seabus_bench::{Goals, scale, smoke};
use seabus_medium::{DataMap, Interface, LinkState, Medium, Node, Payload, Stamp, Topic};
use std::collections::HashSet;
use std::io::BufRead;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, LazyLock, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt};
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::handlers::FifoChannel;
use zenoh::pubsub::Publisher;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::{Config, Session};
use zenoh_ext::{
    AdvancedPublisher, AdvancedPublisherBuilderExt, AdvancedSubscriberBuilderExt, CacheConfig,
    HistoryConfig, MissDetectionConfig, RecoveryConfig,
};

/// Rounds of each throughput run, taken in turn.
const ROUNDS: usize = 3;
/// Rounds of each latency run, taken in turn.
const LAT_ROUNDS: usize = 3;
const LAT_N: usize = 1000;
const LAT_RATE: f64 = 500.0;
const LAT_SIZE: usize = 64;
/// The drain ends when nothing arrives for this long.
const QUIET: Duration = Duration::from_millis(300);
/// The key (and seabus topic `bench.data` under prefix `bench`) of the pair.
const KEY: &str = "bench/bench/data";

const VEHICLES: usize = 20;
const NAV_HZ: f64 = 10.0;
const FLEET_SECONDS: f64 = 4.0;
const FLEET_ROUNDS: usize = 2;

static T0: LazyLock<Instant> = LazyLock::new(Instant::now);

fn since_t0() -> u64 {
    T0.elapsed().as_nanos() as u64
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("an ephemeral port")
}

/// A Zenoh configuration: `mode`, loopback endpoints, multicast scouting off.
fn zconfig(mode: &str, listen: &[String], connect: &[String]) -> Config {
    let mut c = Config::default();
    let list = |v: &[String]| serde_json::to_string(v).expect("json");
    c.insert_json5("mode", &format!("\"{mode}\""))
        .expect("mode");
    c.insert_json5("scouting/multicast/enabled", "false")
        .expect("scouting");
    c.insert_json5("listen/endpoints", &list(listen))
        .expect("listen");
    c.insert_json5("connect/endpoints", &list(connect))
        .expect("connect");
    c
}

fn open_medium(node: &str, url: &str) -> Medium {
    seabus_medium_zenoh::schemes()
        .open("net", url, &Node::new(node))
        .unwrap_or_else(|e| panic!("{url}: {e}"))
}

/// What a receiver saw.
#[derive(Default)]
struct Seen {
    count: AtomicU64,
    /// when the last message arrived, ns since [`T0`]
    last: AtomicU64,
    /// one-way latencies (ns), when kept
    latencies: Mutex<Vec<u64>>,
    keep_latencies: bool,
}

impl Seen {
    fn new(keep_latencies: bool) -> Arc<Seen> {
        Arc::new(Seen {
            keep_latencies,
            ..Seen::default()
        })
    }

    fn hit(&self, data: &[u8]) {
        if self.keep_latencies && data.len() >= 8 {
            let sent = i64::from_le_bytes(data[..8].try_into().expect("8 bytes"));
            let lat = (Stamp::now().0 - sent).max(0) as u64;
            self.latencies.lock().expect("lock").push(lat);
        }
        self.last.store(since_t0(), Ordering::Relaxed);
        self.count.fetch_add(1, Ordering::Relaxed);
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Side {
    /// two seabus `zenoh://` media, the interface subscribed to the topic
    Seabus,
    /// two bare sessions, the subscriber's callback counting
    Bare,
    /// two bare sessions, samples taken from a FIFO channel by a task
    BareChannel,
    /// seabus, the interface subscribed to `**` (key `bench/**`), as a shore station subscribes
    SeabusWild,
    /// bare, the callback's subscriber on `bench/**`
    BareWild,
    /// bare Zenoh-ext advanced publisher and subscriber, configured as the medium configures
    /// them for data (latest sample cached, sample numbering and heartbeats, history, recovery)
    BareAdvanced,
}

impl Side {
    fn label(self) -> &'static str {
        match self {
            Side::Seabus => "seabus",
            Side::Bare => "bare (callback)",
            Side::BareChannel => "bare (channel)",
            Side::SeabusWild => "seabus, on **",
            Side::BareWild => "bare, on bench/**",
            Side::BareAdvanced => "bare advanced",
        }
    }
}

/// A publisher and a subscriber on loopback.
enum Pair {
    Seabus {
        tx: Interface,
        topic: Topic,
        media: [Medium; 2],
    },
    Bare {
        publisher: BarePublisher,
        sessions: [Session; 2],
        _subscriber: Box<dyn Send>,
    },
}

/// A bare publisher: plain, or Zenoh-ext's advanced one.
enum BarePublisher {
    Plain(Publisher<'static>),
    Advanced(AdvancedPublisher<'static>),
}

/// How soon after a sample an advanced publisher says how many it sent (the medium's value).
const HEARTBEAT: Duration = Duration::from_millis(500);

impl BarePublisher {
    /// Declares a publisher on `key` with the medium's quality of service for data.
    async fn declare(session: &Session, key: String, advanced: bool, json: bool) -> BarePublisher {
        let encoding = if json {
            Encoding::APPLICATION_JSON
        } else {
            Encoding::default()
        };
        let builder = session
            .declare_publisher(key)
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::Data)
            .encoding(encoding);
        if advanced {
            BarePublisher::Advanced(
                builder
                    .cache(CacheConfig::default().max_samples(1))
                    .sample_miss_detection(
                        MissDetectionConfig::default().sporadic_heartbeat(HEARTBEAT),
                    )
                    .publisher_detection()
                    .await
                    .expect("publisher"),
            )
        } else {
            BarePublisher::Plain(builder.await.expect("publisher"))
        }
    }

    async fn put(&self, payload: impl Into<ZBytes>) {
        let _ = match self {
            BarePublisher::Plain(p) => p.put(payload).await,
            BarePublisher::Advanced(p) => p.put(payload).await,
        };
    }
}

impl Pair {
    async fn open(side: Side, seen: Arc<Seen>, capacity: usize) -> Pair {
        let port = free_port();
        let listen = format!("tcp/127.0.0.1:{port}");
        match side {
            Side::Seabus | Side::SeabusWild => {
                let rx = open_medium(
                    "rx",
                    &format!("zenoh://?listen={listen}&prefix=bench&scout=false"),
                );
                let tx = open_medium(
                    "tx",
                    &format!(
                        "zenoh://?connect={listen}&listen=tcp/127.0.0.1:0&prefix=bench&scout=false"
                    ),
                );
                let mut port = rx
                    .attach_with("rx", capacity, 16)
                    .subscribed(if side == Side::Seabus {
                        "bench.data"
                    } else {
                        "**"
                    })
                    .expect("pattern");
                tokio::spawn(async move {
                    while let Some(m) = port.recv().await {
                        seen.hit(m.payload.as_bytes().map_or(&[][..], |b| &b[..]));
                    }
                });
                Pair::Seabus {
                    tx: tx.attach("tx"),
                    topic: Topic::new("bench.data").expect("topic"),
                    media: [rx, tx],
                }
            }
            Side::Bare | Side::BareChannel | Side::BareWild | Side::BareAdvanced => {
                let rx = zenoh::open(zconfig("peer", std::slice::from_ref(&listen), &[]))
                    .await
                    .expect("session");
                let tx = zenoh::open(zconfig("peer", &["tcp/127.0.0.1:0".to_string()], &[listen]))
                    .await
                    .expect("session");
                let subscriber: Box<dyn Send> = if side == Side::BareAdvanced {
                    let seen = seen.clone();
                    Box::new(
                        rx.declare_subscriber(KEY)
                            .history(
                                HistoryConfig::default()
                                    .detect_late_publishers()
                                    .max_samples(1),
                            )
                            .recovery(RecoveryConfig::default().heartbeat())
                            .subscriber_detection()
                            .callback(move |s| seen.hit(&s.payload().to_bytes()))
                            .await
                            .expect("subscriber"),
                    )
                } else if side != Side::BareChannel {
                    let seen = seen.clone();
                    let key = if side == Side::Bare { KEY } else { "bench/**" };
                    Box::new(
                        rx.declare_subscriber(key)
                            .callback(move |s| seen.hit(&s.payload().to_bytes()))
                            .await
                            .expect("subscriber"),
                    )
                } else {
                    let sub = rx
                        .declare_subscriber(KEY)
                        .with(FifoChannel::new(capacity))
                        .await
                        .expect("subscriber");
                    let handler = sub.handler().clone();
                    tokio::spawn(async move {
                        while let Ok(s) = handler.recv_async().await {
                            seen.hit(&s.payload().to_bytes());
                        }
                    });
                    Box::new(sub)
                };
                let publisher =
                    BarePublisher::declare(&tx, KEY.to_string(), side == Side::BareAdvanced, false)
                        .await;
                Pair::Bare {
                    publisher,
                    sessions: [rx, tx],
                    _subscriber: subscriber,
                }
            }
        }
    }

    async fn put(&self, data: &Bytes) {
        match self {
            Pair::Seabus { tx, topic, .. } => {
                let _ = tx.send(topic, Payload::from(data.clone())).await;
            }
            Pair::Bare { publisher, .. } => publisher.put(data.clone()).await,
        }
    }

    /// Sends until the subscriber hears, then lets the warm-up drain and clears the count.
    async fn warm_up(&self, seen: &Seen, data: &Bytes) {
        let deadline = Instant::now() + Duration::from_secs(15);
        while seen.count.load(Ordering::Relaxed) == 0 {
            assert!(Instant::now() < deadline, "the pair never connected");
            self.put(data).await;
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
        seen.count.store(0, Ordering::Relaxed);
        seen.latencies.lock().expect("lock").clear();
    }

    async fn close(self) {
        match self {
            Pair::Seabus { media, .. } => {
                for m in media {
                    m.close();
                }
            }
            Pair::Bare {
                publisher,
                sessions,
                _subscriber,
            } => {
                drop(publisher);
                drop(_subscriber);
                for s in sessions {
                    let _ = s.close().await;
                }
            }
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Waits until `seen` has `n` messages or nothing arrives for [`QUIET`].
async fn drain(seen: &Seen, n: u64) {
    let mut last_count = u64::MAX;
    let mut still_since = Instant::now();
    loop {
        let c = seen.count.load(Ordering::Relaxed);
        if c >= n {
            return;
        }
        if c != last_count {
            last_count = c;
            still_since = Instant::now();
        } else if still_since.elapsed() >= QUIET {
            return;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

struct Flood {
    /// sent per second
    offered: f64,
    /// delivered per second
    delivered: f64,
    arrived: u64,
}

async fn flood(side: Side, size: usize, n: usize) -> Flood {
    let seen = Seen::new(false);
    let pair = Pair::open(side, seen.clone(), n + 16).await;
    let data = Bytes::from(vec![0x5au8; size]);
    pair.warm_up(&seen, &data).await;
    let start = since_t0();
    for _ in 0..n {
        pair.put(&data).await;
    }
    let sent = since_t0();
    drain(&seen, n as u64).await;
    let arrived = seen.count.load(Ordering::Relaxed);
    let last = seen.last.load(Ordering::Relaxed).max(start + 1);
    pair.close().await;
    Flood {
        offered: n as f64 / ((sent - start) as f64 * 1e-9),
        delivered: arrived as f64 / ((last - start) as f64 * 1e-9),
        arrived,
    }
}

async fn one_way(side: Side, n: usize) -> (f64, f64) {
    let seen = Seen::new(true);
    let pair = Pair::open(side, seen.clone(), n + 16).await;
    let mut data = vec![0u8; LAT_SIZE];
    let stamped = |data: &mut Vec<u8>| {
        data[..8].copy_from_slice(&Stamp::now().0.to_le_bytes());
        Bytes::copy_from_slice(data)
    };
    pair.warm_up(&seen, &stamped(&mut data)).await;
    let start = tokio::time::Instant::now();
    for i in 0..n {
        tokio::time::sleep_until(start + Duration::from_secs_f64(i as f64 / LAT_RATE)).await;
        pair.put(&stamped(&mut data)).await;
    }
    drain(&seen, n as u64).await;
    pair.close().await;
    let mut l: Vec<Duration> = std::mem::take(&mut *seen.latencies.lock().expect("lock"))
        .into_iter()
        .map(Duration::from_nanos)
        .collect();
    assert!(l.len() >= n * 9 / 10, "only {} of {n} arrived", l.len());
    l.sort();
    (common::quantile_us(&l, 0.5), common::quantile_us(&l, 0.99))
}

const PAIR_SIDES: [Side; 4] = [
    Side::Bare,
    Side::BareChannel,
    Side::Seabus,
    Side::BareAdvanced,
];
const FLOOD_SIDES: [Side; 6] = [
    Side::Bare,
    Side::BareChannel,
    Side::Seabus,
    Side::BareAdvanced,
    Side::BareWild,
    Side::SeabusWild,
];
/// The sides of the smoke run: those the goals compare.
const SMOKE_SIDES: [Side; 2] = [Side::Bare, Side::Seabus];

/// `sides`' figures, found by side.
struct BySide<'a, T>(&'a [Side], &'a [T]);

impl<T> BySide<'_, T> {
    fn get(&self, side: Side) -> Option<&T> {
        self.0.iter().position(|s| *s == side).map(|i| &self.1[i])
    }
}

async fn throughput(goals: &mut Goals) {
    let rounds = ROUNDS;
    let sides: &[Side] = if smoke() { &SMOKE_SIDES } else { &FLOOD_SIDES };
    println!(
        "Throughput, peer to peer on loopback, CongestionControl::Drop on both sides, best of {rounds} rounds taken in turn:"
    );
    for (size, n) in [
        (64usize, scale(200_000usize, 50_000)),
        (4096, scale(50_000, 20_000)),
    ] {
        let mut best: Vec<Option<Flood>> = (0..sides.len()).map(|_| None).collect();
        for _ in 0..rounds {
            for (i, side) in sides.iter().enumerate() {
                let f = flood(*side, size, n).await;
                if best[i].as_ref().is_none_or(|b| f.delivered > b.delivered) {
                    best[i] = Some(f);
                }
            }
        }
        let best: Vec<Flood> = best.into_iter().map(|b| b.expect("a round")).collect();
        for (side, f) in sides.iter().zip(&best) {
            println!(
                "  {size:>4} B {:<17} delivered {:>12} ({} of {n} arrived; offered {})",
                side.label(),
                common::rate(f.delivered),
                f.arrived,
                common::rate(f.offered),
            );
        }
        let by = BySide(sides, &best);
        let rate = |side| by.get(side).map_or(f64::NAN, |f| f.delivered);
        let seabus = rate(Side::Seabus);
        if !smoke() {
            println!(
                "  {size:>4} B ratio seabus / bare (channel) {:.2}; seabus / bare advanced {:.2}; seabus on ** / bare on bench/** {:.2}",
                seabus / rate(Side::BareChannel),
                seabus / rate(Side::BareAdvanced),
                rate(Side::SeabusWild) / rate(Side::BareWild)
            );
        }
        let name = format!("{size} B delivered, seabus / bare (callback)");
        let ratio = seabus / rate(Side::Bare);
        if size < 1024 {
            goals.aim_at_least(
                &name,
                ratio,
                0.8,
                "every message is a put of its own: 0.8 leaves about what the put alone takes (BENCHMARKS.md)",
            );
        } else {
            goals.at_least(&name, ratio, 0.8);
        }
    }
}

async fn latency(goals: &mut Goals) {
    let rounds = scale(LAT_ROUNDS, 2);
    let n = scale(LAT_N, 500);
    let sides: &[Side] = if smoke() { &SMOKE_SIDES } else { &PAIR_SIDES };
    println!(
        "One-way latency, peer to peer on loopback, {n} messages of {LAT_SIZE} B at {LAT_RATE} per second, best of {rounds} rounds taken in turn:"
    );
    let mut best = vec![(f64::MAX, f64::MAX); sides.len()];
    for _ in 0..rounds {
        for (i, side) in sides.iter().enumerate() {
            let (p50, p99) = one_way(*side, n).await;
            best[i] = (best[i].0.min(p50), best[i].1.min(p99));
        }
    }
    for (side, (p50, p99)) in sides.iter().zip(&best) {
        println!("  {:<17} p50 {p50:.1} us  p99 {p99:.1} us", side.label());
    }
    let by = BySide(sides, &best);
    let of = |side| by.get(side).copied().unwrap_or((f64::NAN, f64::NAN));
    let (seabus, bare) = (of(Side::Seabus), of(Side::Bare));
    if !smoke() {
        let (channel, advanced) = (of(Side::BareChannel), of(Side::BareAdvanced));
        println!(
            "  ratio seabus / bare (channel) p50 {:.2} p99 {:.2}; seabus / bare advanced p50 {:.2} p99 {:.2}",
            seabus.0 / channel.0,
            seabus.1 / channel.1,
            seabus.0 / advanced.0,
            seabus.1 / advanced.1
        );
    }
    goals.at_most(
        "latency p50, seabus / bare (callback)",
        seabus.0 / bare.0,
        1.3,
    );
    goals.at_most(
        "latency p99, seabus / bare (callback)",
        seabus.1 / bare.1,
        1.3,
    );
}

// ---------------------------------------------------------------- fleet

/// A vehicle's navigation at tick `n`: three small datamaps.
fn navigation(v: usize, n: u64) -> [(&'static str, DataMap); 3] {
    let t = n as f64 * 0.1 + v as f64;
    [
        (
            "nav.position",
            DataMap::new()
                .with("lat", 43.508_123 + t * 1e-6)
                .with("lon", 16.440_234 + t * 1e-6)
                .with("depth", 12.5 + (t * 0.1).sin())
                .with("altitude", 8.25 - (t * 0.1).cos()),
        ),
        (
            "nav.attitude",
            DataMap::new()
                .with("roll", 0.5 * (t * 0.3).sin())
                .with("pitch", -1.5 + 0.2 * (t * 0.2).cos())
                .with("yaw", (t * 3.0) % 360.0),
        ),
        (
            "nav.velocity",
            DataMap::new()
                .with("u", 1.5 + 0.01 * (t * 0.7).sin())
                .with("v", 0.02 * (t * 0.5).cos())
                .with("w", -0.01),
        ),
    ]
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Fleet {
    Seabus,
    SeabusJson,
    Bare,
    BareAdvanced,
}

impl Fleet {
    fn arg(self) -> &'static str {
        match self {
            Fleet::Seabus => "seabus",
            Fleet::SeabusJson => "seabus-json",
            Fleet::Bare => "bare",
            Fleet::BareAdvanced => "bare-advanced",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Fleet::Seabus => "seabus (datagrams)",
            Fleet::SeabusJson => "seabus (json=true)",
            Fleet::Bare => "bare (JSON)",
            Fleet::BareAdvanced => "bare advanced (JSON)",
        }
    }
}

/// The vehicles of one fleet run: their publishing tasks and what to close.
struct Vehicles {
    tasks: Vec<tokio::task::JoinHandle<()>>,
    media: Vec<Medium>,
    sessions: Vec<Session>,
}

impl Vehicles {
    async fn start(kind: Fleet, router: &str) -> Vehicles {
        let mut v = Vehicles {
            tasks: Vec::new(),
            media: Vec::new(),
            sessions: Vec::new(),
        };
        let period = Duration::from_secs_f64(1.0 / NAV_HZ);
        for i in 0..VEHICLES {
            // the vehicles' ticks spread over the period
            let phase = period.mul_f64(i as f64 / VEHICLES as f64);
            if matches!(kind, Fleet::Bare | Fleet::BareAdvanced) {
                let s = zenoh::open(zconfig("client", &[], &[router.to_string()]))
                    .await
                    .expect("vehicle session");
                let mut pubs = Vec::new();
                for (topic, _) in navigation(i, 0) {
                    let key = format!("fleet/auv{i}/{}", topic.replace('.', "/"));
                    pubs.push(
                        BarePublisher::declare(&s, key, kind == Fleet::BareAdvanced, true).await,
                    );
                }
                v.sessions.push(s);
                v.tasks.push(tokio::spawn(async move {
                    tokio::time::sleep(phase).await;
                    let mut tick = tokio::time::interval(period);
                    for n in 0.. {
                        tick.tick().await;
                        for (p, (_, map)) in pubs.iter().zip(navigation(i, n)) {
                            let text = seabus_medium::json::to_json(&map).expect("json");
                            p.put(text).await;
                        }
                    }
                }));
            } else {
                let json = kind == Fleet::SeabusJson;
                let m = open_medium(
                    &format!("auv{i}"),
                    &format!(
                        "zenoh://?mode=client&connect={router}&prefix=fleet/auv{i}&scout=false&json={json}"
                    ),
                );
                let tx = m.attach("nav");
                v.media.push(m);
                v.tasks.push(tokio::spawn(async move {
                    tokio::time::sleep(phase).await;
                    let mut tick = tokio::time::interval(period);
                    for n in 0.. {
                        tick.tick().await;
                        for (topic, map) in navigation(i, n) {
                            let _ = tx.send(topic, map).await;
                        }
                    }
                }));
            }
        }
        v
    }

    async fn stop(self) {
        for t in &self.tasks {
            t.abort();
        }
        for m in self.media {
            m.close();
        }
        for s in self.sessions {
            let _ = s.close().await;
        }
    }
}

/// What the shore reported for one fleet run.
struct ShoreFigures {
    cpu_share: f64,
    messages: u64,
    payload_bytes: u64,
    tcp_bytes: u64,
    seconds: f64,
    vehicles: u64,
}

impl ShoreFigures {
    fn per_vehicle(&self, bytes: u64) -> f64 {
        bytes as f64 / self.seconds / VEHICLES as f64
    }
}

async fn fleet_run(kind: Fleet, router_port: u16) -> ShoreFigures {
    let router = format!("tcp/127.0.0.1:{router_port}");
    let mut child = tokio::process::Command::new(std::env::current_exe().expect("this binary"))
        .args(["--shore", kind.arg(), &router])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("the shore starts");
    let mut stdin = child.stdin.take().expect("stdin");
    let mut lines = tokio::io::BufReader::new(child.stdout.take().expect("stdout")).lines();
    let ready = tokio::time::timeout(Duration::from_secs(20), lines.next_line())
        .await
        .expect("the shore is ready in time")
        .expect("the shore's output");
    assert_eq!(ready.as_deref(), Some("ready"));
    let vehicles = Vehicles::start(kind, &router).await;
    // sessions open, subscriptions reach the vehicles, the first ticks pass
    tokio::time::sleep(Duration::from_millis(1200)).await;
    stdin.write_all(b"go\n").await.expect("go");
    stdin.flush().await.expect("go");
    tokio::time::sleep(Duration::from_secs_f64(FLEET_SECONDS)).await;
    stdin.write_all(b"stop\n").await.expect("stop");
    stdin.flush().await.expect("stop");
    let result = tokio::time::timeout(Duration::from_secs(10), lines.next_line())
        .await
        .expect("the shore answers in time")
        .expect("the shore's output")
        .expect("a result line");
    vehicles.stop().await;
    let _ = tokio::time::timeout(Duration::from_secs(5), child.wait()).await;
    let f: Vec<f64> = result
        .split_whitespace()
        .map(|x| x.parse().expect("a number"))
        .collect();
    tokio::time::sleep(Duration::from_millis(200)).await;
    ShoreFigures {
        cpu_share: 100.0 * f[3] / f[4],
        messages: f[0] as u64,
        payload_bytes: f[1] as u64,
        tcp_bytes: f[2] as u64,
        seconds: f[4],
        vehicles: f[5] as u64,
    }
}

async fn fleet() {
    let port = free_port();
    let router = zenoh::open(zconfig("router", &[format!("tcp/127.0.0.1:{port}")], &[]))
        .await
        .expect("the router opens");
    println!(
        "Fleet: {VEHICLES} vehicles × 3 navigation topics at {NAV_HZ} Hz through one router into one shore station (its own process), {FLEET_SECONDS} s per run, lowest shore CPU of {FLEET_ROUNDS} rounds taken in turn:"
    );
    let kinds = [
        Fleet::Bare,
        Fleet::Seabus,
        Fleet::SeabusJson,
        Fleet::BareAdvanced,
    ];
    let mut best: Vec<Option<ShoreFigures>> = kinds.iter().map(|_| None).collect();
    for _ in 0..FLEET_ROUNDS {
        for (i, kind) in kinds.iter().enumerate() {
            let f = fleet_run(*kind, port).await;
            if best[i].as_ref().is_none_or(|b| f.cpu_share < b.cpu_share) {
                best[i] = Some(f);
            }
        }
    }
    let expected = (VEHICLES as f64 * 3.0 * NAV_HZ * FLEET_SECONDS).round() as u64;
    let best: Vec<ShoreFigures> = best.into_iter().map(|b| b.expect("a round")).collect();
    for (kind, f) in kinds.iter().zip(&best) {
        println!(
            "  {:<21} shore CPU {:.2} % of a core; per vehicle: payload {:.0} B/s, TCP {:.0} B/s; {} messages (about {expected} sent) from {} vehicles",
            kind.label(),
            f.cpu_share,
            f.per_vehicle(f.payload_bytes),
            f.per_vehicle(f.tcp_bytes),
            f.messages,
            f.vehicles
        );
    }
    let ratio = |i: usize, reference: usize| {
        println!(
            "  ratio {} / {}: shore CPU {:.2}, payload bytes {:.2}, TCP bytes {:.2}",
            kinds[i].label(),
            kinds[reference].label(),
            best[i].cpu_share / best[reference].cpu_share,
            best[i].per_vehicle(best[i].payload_bytes)
                / best[reference].per_vehicle(best[reference].payload_bytes),
            best[i].per_vehicle(best[i].tcp_bytes)
                / best[reference].per_vehicle(best[reference].tcp_bytes),
        );
    };
    for (i, reference) in [(1, 0), (2, 0), (3, 0), (1, 3), (2, 3)] {
        ratio(i, reference);
    }
    let _ = router.close().await;
}

// ---------------------------------------------------------------- the shore (child process)

fn cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct we own
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
    t(u.ru_utime) + t(u.ru_stime)
}

/// Bytes received so far on this process's TCP sockets (`TCP_INFO`'s `tcpi_bytes_received`).
fn tcp_bytes_received() -> u64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/fd") else {
        return 0;
    };
    let mut total = 0;
    for e in dir.flatten() {
        let is_socket = std::fs::read_link(e.path())
            .map(|l| l.to_string_lossy().starts_with("socket:"))
            .unwrap_or(false);
        let Some(fd) = e.file_name().to_str().and_then(|n| n.parse::<i32>().ok()) else {
            continue;
        };
        if !is_socket {
            continue;
        }
        // SAFETY: getsockopt writes at most `len` bytes into the struct we own
        let mut info: libc::tcp_info = unsafe { std::mem::zeroed() };
        let mut len = std::mem::size_of::<libc::tcp_info>() as libc::socklen_t;
        let r = unsafe {
            libc::getsockopt(
                fd,
                libc::IPPROTO_TCP,
                libc::TCP_INFO,
                (&mut info as *mut libc::tcp_info).cast(),
                &mut len,
            )
        };
        if r == 0 {
            total += info.tcpi_bytes_received;
        }
    }
    total
}

#[derive(Default)]
struct ShoreSeen {
    messages: AtomicU64,
    bytes: AtomicU64,
    vehicles: Mutex<HashSet<String>>,
}

impl ShoreSeen {
    fn hit(&self, vehicle: &str, bytes: usize) {
        self.messages.fetch_add(1, Ordering::Relaxed);
        self.bytes.fetch_add(bytes as u64, Ordering::Relaxed);
        let mut v = self.vehicles.lock().expect("lock");
        if !v.contains(vehicle) {
            v.insert(vehicle.to_string());
        }
    }
}

/// The shore station: opens, says `ready`, measures between `go` and `stop` on stdin, prints
/// `messages payload-bytes tcp-bytes cpu-seconds wall-seconds vehicles`.
fn shore(kind: &str, router: &str) {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let seen = Arc::new(ShoreSeen::default());
    let keep: Box<dyn std::any::Any> = rt.block_on(async {
        if kind.starts_with("bare") {
            let s = zenoh::open(zconfig("client", &[], &[router.to_string()]))
                .await
                .expect("shore session");
            let seen = seen.clone();
            let take = move |sample: zenoh::sample::Sample| {
                let payload = sample.payload().to_bytes();
                let value: serde_json::Value = serde_json::from_slice(&payload).unwrap_or_default();
                std::hint::black_box(value);
                let vehicle = sample.key_expr().as_str().split('/').nth(1).unwrap_or("");
                let att = sample.attachment().map_or(0, |a| a.len());
                seen.hit(vehicle, payload.len() + att);
            };
            let sub: Box<dyn std::any::Any> = if kind == "bare" {
                Box::new(
                    s.declare_subscriber("fleet/**")
                        .callback(take)
                        .await
                        .expect("subscriber"),
                )
            } else {
                Box::new(
                    s.declare_subscriber("fleet/**")
                        .history(
                            HistoryConfig::default()
                                .detect_late_publishers()
                                .max_samples(1),
                        )
                        .recovery(RecoveryConfig::default().heartbeat())
                        .subscriber_detection()
                        .callback(take)
                        .await
                        .expect("subscriber"),
                )
            };
            Box::new((s, sub)) as Box<dyn std::any::Any>
        } else {
            let url = format!("zenoh://?mode=client&connect={router}&prefix=fleet&scout=false");
            let m = open_medium("shore", &url);
            let mut port = m
                .attach_with("shore", 4096, 16)
                .subscribed("**")
                .expect("pattern");
            let json = kind == "seabus-json";
            let seen = seen.clone();
            tokio::spawn(async move {
                while let Some(mut msg) = port.recv().await {
                    // what the wire carried: the datagram with the sender's own topic (the
                    // shore's has the vehicle's name in front), or the JSON text and the
                    // datagram without payload
                    // (the medium's own announcements, `seabus.fleet`, are not the vehicles')
                    let Some((vehicle, sent)) = msg
                        .topic
                        .as_str()
                        .split_once('.')
                        .filter(|(v, _)| v.starts_with("auv"))
                    else {
                        continue;
                    };
                    let vehicle = vehicle.to_string();
                    let sent_topic = Topic::new(sent).expect("topic");
                    msg.topic = sent_topic;
                    let bytes = if json {
                        let map = msg.payload.to_map().expect("a datamap");
                        let text = seabus_medium::json::to_json(&map).expect("json");
                        msg.payload = Payload::Bytes(Bytes::new());
                        text.len()
                            + seabus_medium::datagram::encode(&msg, 0)
                                .expect("datagram")
                                .len()
                    } else {
                        seabus_medium::datagram::encode(&msg, 0)
                            .expect("datagram")
                            .len()
                    };
                    seen.hit(&vehicle, bytes);
                }
            });
            let mut link = m.watch_link();
            let _ = tokio::time::timeout(
                Duration::from_secs(10),
                link.wait_for(|s| matches!(s, LinkState::Up)),
            )
            .await;
            Box::new(m) as Box<dyn std::any::Any>
        }
    });
    println!("ready");
    let stdin = std::io::stdin();
    let mut line = String::new();
    let _ = stdin.lock().read_line(&mut line);
    let (cpu0, t0, tcp0) = (cpu_seconds(), Instant::now(), tcp_bytes_received());
    let (m0, b0) = (
        seen.messages.load(Ordering::Relaxed),
        seen.bytes.load(Ordering::Relaxed),
    );
    line.clear();
    let _ = stdin.lock().read_line(&mut line);
    let (cpu, wall, tcp) = (
        cpu_seconds() - cpu0,
        t0.elapsed().as_secs_f64(),
        tcp_bytes_received() - tcp0,
    );
    let (m, b) = (
        seen.messages.load(Ordering::Relaxed) - m0,
        seen.bytes.load(Ordering::Relaxed) - b0,
    );
    let vehicles = seen.vehicles.lock().expect("lock").len();
    println!("{m} {b} {tcp} {cpu} {wall} {vehicles}");
    use std::io::Write;
    let _ = std::io::stdout().flush();
    // the sessions end with the process
    let _ = keep;
    std::process::exit(0);
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--shore") {
        shore(&args[1], &args[2]);
        return;
    }
    let parts = ["throughput", "latency", "fleet"];
    let chosen: Vec<&str> = parts
        .iter()
        .copied()
        .filter(|p| args.iter().any(|a| a == p))
        .collect();
    let profile = args.iter().any(|a| a == "profile");
    let run = |p: &str| !profile && (chosen.is_empty() || chosen.contains(&p));
    LazyLock::force(&T0);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let started = Instant::now();
    let mut goals = Goals::new();
    rt.block_on(async {
        if run("throughput") {
            throughput(&mut goals).await;
        }
        if run("latency") {
            latency(&mut goals).await;
        }
        if run("fleet") {
            if smoke() {
                println!("Fleet: not in the smoke run (no goal)");
            } else {
                fleet().await;
            }
        }
        if profile {
            // seabus's flood alone, for `perf record`
            let size = args.iter().find_map(|a| a.parse().ok()).unwrap_or(64usize);
            for _ in 0..5 {
                let f = flood(Side::Seabus, size, 200_000).await;
                println!(
                    "seabus {size} B: delivered {}, {} arrived",
                    common::rate(f.delivered),
                    f.arrived
                );
            }
        }
    });
    println!("(bench took {:.0} s)", started.elapsed().as_secs_f64());
    rt.shutdown_timeout(Duration::from_secs(1));
    goals.finish();
}
