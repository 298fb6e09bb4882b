//! MOOS through seabus's client against raw clients through the same MOOSDB (seabus's own), on
//! loopback.
//!
//! 1. Round trip: a notification published by one client, through the DB, to another client
//!    registered for it, 2000 times one after the other; p50 and p99. Floor: the same with two raw
//!    clients that write and read packets on their sockets and do nothing else. The two are taken
//!    in turn, 500 round trips at a time.
//! 2. Messages per second: one client publishes 100 000 notifications as fast as the medium
//!    takes them; the other counts what arrives, from the first sent to the last received. The
//!    reference: a raw client writing the same notifications in packets of up to 1 MiB (as
//!    seabus's client packs what waits), a raw client counting them. Median of 3, taken in turn.
//!
//! Goals: round trip p50 at most 1.2× the raw clients'; messages per second at least 0.9× theirs,
//! with every notification received (the smoke run fails on a loss).
//!
//! Both sides run in a task of a two-thread runtime, as a module's code does. From the thread
//! that blocks on the runtime instead, every message handed to the medium's connection task wakes a
//! worker thread, which costs tens of microseconds on a virtual machine: the round trip was 3.2×
//! the raw clients' that way (the raw clients write their socket themselves).
//!
//! Run: `cargo bench -p seabus-medium-moos --bench moos` (`SEABUS_BENCH_SMOKE=1`: the smoke run,
//! the same sizes: the whole program takes about a second)

use seabus_bench::Goals;
use seabus_medium::{DataMap, Interface, LinkState, Medium, Node};
use seabus_medium_moos::db::MoosDb;
use seabus_medium_moos::wire::{self, MoosMsg, Packet, data, kind};
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpStream;

fn quantiles(mut v: Vec<Duration>) -> (f64, f64) {
    v.sort();
    let q = |p: f64| v[((v.len() - 1) as f64 * p) as usize].as_secs_f64() * 1e6;
    (q(0.5), q(0.99))
}

/// A raw client: handshake and name, then registration for `register` if given.
async fn raw(db: std::net::SocketAddr, name: &str, register: Option<&str>) -> (TcpStream, Vec<u8>) {
    let mut s = TcpStream::connect(db).await.unwrap();
    s.set_nodelay(true).unwrap();
    s.write_all(&wire::hello(name, 0.0)).await.unwrap();
    let mut buf = Vec::new();
    wire::next_packet(&mut s, &mut buf, Duration::from_secs(5))
        .await
        .unwrap();
    if let Some(key) = register {
        let r = MoosMsg {
            kind: kind::REGISTER,
            data_type: data::DOUBLE,
            source: name.as_bytes().to_vec(),
            key: key.as_bytes().to_vec(),
            ..MoosMsg::default()
        };
        s.write_all(&Packet { messages: vec![r] }.encode())
            .await
            .unwrap();
    }
    (s, buf)
}

/// Two raw clients: one publishes, the other is registered for `key`.
struct RawPair {
    tx: TcpStream,
    rx: TcpStream,
    buf: Vec<u8>,
}

impl RawPair {
    async fn open(db: std::net::SocketAddr, name: &str, key: &str) -> RawPair {
        let (tx, _) = raw(db, &format!("{name}-tx"), None).await;
        let (rx, buf) = raw(db, &format!("{name}-rx"), Some(key)).await;
        RawPair { tx, rx, buf }
    }
}

/// `n` round trips through two raw clients, numbered from `from`.
async fn floor(p: &mut RawPair, from: usize, n: usize, out: &mut Vec<Duration>) {
    let RawPair { tx, rx, buf } = p;
    for i in from..from + n {
        let m = MoosMsg {
            kind: kind::NOTIFY,
            data_type: data::DOUBLE,
            source: b"floor-tx".to_vec(),
            key: b"FLOOR".to_vec(),
            value: i as f64,
            ..MoosMsg::default()
        };
        let start = Instant::now();
        tx.write_all(&Packet { messages: vec![m] }.encode())
            .await
            .unwrap();
        loop {
            let p = wire::next_packet(rx, buf, Duration::from_secs(5))
                .await
                .unwrap();
            if p.messages.iter().any(|m| m.value == i as f64) {
                break;
            }
        }
        out.push(start.elapsed());
    }
}

/// `n` round trips through two seabus clients, numbered from `from`.
async fn round_trips(
    tx: &Interface,
    rx: &mut Interface,
    from: usize,
    n: usize,
    out: &mut Vec<Duration>,
) {
    for i in from..from + n {
        let start = Instant::now();
        tx.send("RTT", DataMap::new().with("value", i as f64))
            .await
            .unwrap();
        loop {
            let m = tokio::time::timeout(Duration::from_secs(5), rx.recv())
                .await
                .expect("a reply")
                .expect("open");
            if m.payload.as_map().and_then(|p| p.get_f64("value")) == Some(i as f64) {
                break;
            }
        }
        out.push(start.elapsed());
    }
}

/// A flood through two raw clients: `total` notifications in packets of up to 1 MiB, counted by
/// a task of their own; returns the pair, how many arrived and the time from the first sent to
/// the last received.
async fn raw_flood(p: RawPair, total: u32) -> (RawPair, u32, Duration) {
    let RawPair {
        mut tx,
        mut rx,
        mut buf,
    } = p;
    let start = Instant::now();
    let reader = tokio::spawn(async move {
        let mut got = 0u32;
        let mut last = start;
        while got < total {
            let Ok(p) = wire::next_packet(&mut rx, &mut buf, Duration::from_secs(2)).await else {
                break;
            };
            got += p
                .messages
                .iter()
                .filter(|m| m.kind == kind::NOTIFY && m.key == b"RAWFLOOD")
                .count() as u32;
            last = Instant::now();
        }
        (rx, buf, got, last - start)
    });
    let mut body = Vec::new();
    let mut count = 0i32;
    for i in 0..total {
        MoosMsg {
            kind: kind::NOTIFY,
            data_type: data::DOUBLE,
            source: b"flood-tx".to_vec(),
            key: b"RAWFLOOD".to_vec(),
            value: f64::from(i),
            ..MoosMsg::default()
        }
        .encode_into(&mut body);
        count += 1;
        if body.len() >= 1 << 20 || i + 1 == total {
            let mut packet = Vec::with_capacity(body.len() + wire::PACKET_HEADER);
            packet.extend_from_slice(&((body.len() + wire::PACKET_HEADER) as i32).to_le_bytes());
            packet.extend_from_slice(&count.to_le_bytes());
            packet.push(0);
            packet.extend_from_slice(&body);
            tx.write_all(&packet).await.unwrap();
            body.clear();
            count = 0;
        }
    }
    let (rx, buf, got, took) = reader.await.unwrap();
    (RawPair { tx, rx, buf }, got, took)
}

/// A flood through two seabus clients: `total` notifications as fast as the medium takes them,
/// counted by a task of their own; returns the receiving interface, how many arrived, the time
/// from the first sent to the last received, and the time the sending took.
async fn seabus_flood(
    tx: &Interface,
    mut rx: Interface,
    total: u32,
) -> (Interface, u32, Duration, Duration) {
    let start = Instant::now();
    let reader = tokio::spawn(async move {
        let mut got = 0u32;
        let mut last = start;
        while let Ok(Some(m)) = tokio::time::timeout(Duration::from_secs(2), rx.recv()).await {
            if m.topic.as_str() == "FLOOD" {
                got += 1;
                last = Instant::now();
                if got == total {
                    break;
                }
            }
        }
        (rx, got, last - start)
    });
    for i in 0..total {
        tx.send("FLOOD", DataMap::new().with("value", f64::from(i)))
            .await
            .unwrap();
    }
    let sent_in = start.elapsed();
    let (rx, got, took) = reader.await.unwrap();
    (rx, got, took, sent_in)
}

async fn up(m: &Medium) {
    let mut link = m.watch_link();
    let _ = tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| *s == LinkState::Up),
    )
    .await;
}

fn main() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut goals = Goals::new();
    // the clients run in a task of the runtime, as a module's code does (not on the thread that
    // blocks on the runtime, from where every hand-over to a task wakes a worker thread)
    let goals = rt.block_on(async {
        tokio::spawn(async move {
        let db = MoosDb::start("127.0.0.1:0".parse().unwrap()).await.unwrap();
        let port = db.addr().port();
        let mut floor_pair = RawPair::open(db.addr(), "floor", "FLOOR").await;
        let mut flood_pair = RawPair::open(db.addr(), "flood", "RAWFLOOD").await;

        let node = Node::new("bench");
        let open = |name: &str, reg: &str| {
            seabus_medium_moos::schemes()
                .open(
                    name,
                    &format!("moos://127.0.0.1:{port}?name={name}&register={reg}"),
                    &node,
                )
                .unwrap()
        };
        let a = open("seabus-tx", "NONE");
        let b = open("seabus-rx", "RTT,FLOOD");
        up(&a).await;
        up(&b).await;
        let tx = a.attach("tx");
        let mut rx = b.attach_with("rx", 1 << 18, 16);
        rx.subscribe("**").unwrap();
        tokio::time::sleep(Duration::from_millis(200)).await;

        // round trips, raw and seabus in turn, 500 at a time
        let (n, block) = (2000, 500);
        let (mut raw_lat, mut sb_lat) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for from in (0..n).step_by(block) {
            floor(&mut floor_pair, from, block, &mut raw_lat).await;
            round_trips(&tx, &mut rx, from, block, &mut sb_lat).await;
        }
        let ((f50, f99), (s50, s99)) = (quantiles(raw_lat), quantiles(sb_lat));
        println!("MOOS round trip publish -> DB -> subscriber, {n} in turn:");
        println!("  floor (raw clients)  p50 {f50:.1} us, p99 {f99:.1} us");
        println!("  seabus client        p50 {s50:.1} us, p99 {s99:.1} us");
        goals.at_most("round trip p50, seabus / raw clients", s50 / f50, 1.2);

        // floods, raw and seabus in turn
        let total = 100_000u32;
        let (mut raw_rates, mut sb_rates, mut sb_sent) = (Vec::new(), Vec::new(), Vec::new());
        let mut all = true;
        for _ in 0..3 {
            let (pair, got, took) = raw_flood(flood_pair, total).await;
            flood_pair = pair;
            all &= goals.none_lost(
                "notifications through the MOOSDB to raw clients",
                total as usize,
                got as usize,
            );
            raw_rates.push(f64::from(got) / took.as_secs_f64());
            let (back, got, took, sent_in) = seabus_flood(&tx, rx, total).await;
            rx = back;
            all &= goals.none_lost(
                "notifications through the MOOSDB to seabus clients",
                total as usize,
                got as usize,
            );
            sb_rates.push(f64::from(got) / took.as_secs_f64());
            sb_sent.push(f64::from(total) / sent_in.as_secs_f64());
        }
        let (r, s) = (median(raw_rates), median(sb_rates));
        println!(
            "  throughput, {total} notifications, median of 3: raw clients {:.0} k msg/s received   seabus {:.0} k msg/s sent, {:.0} k msg/s received",
            r / 1e3,
            median(sb_sent) / 1e3,
            s / 1e3,
        );
        if all {
            println!("  every notification received");
        }
        goals.at_least("messages per second, seabus / raw clients", s / r, 0.9);
        a.close();
        b.close();
        drop(db);
        goals
        })
        .await
        .expect("the benchmark's task")
    });
    goals.finish();
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}
