//! MOOS through seabus's client against the DB's own floor, on loopback, with seabus's MOOSDB.
//!
//! 1. Round trip: a notification published by one client, through the DB, to another client
//!    registered for it, 2000 times one after the other; p50 and p99. Floor: the same with two raw
//!    clients that write and read packets on their sockets and do nothing else.
//! 2. Messages per second: one client publishes 100 000 notifications as fast as the medium
//!    takes them; the other counts what arrives.
//!
//! Run: `cargo bench -p seabus-medium --bench moos`

use seabus_medium::{DataMap, LinkState, Medium, Node};
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

async fn floor(db: std::net::SocketAddr, n: usize) -> Vec<Duration> {
    let (mut tx, _) = raw(db, "floor-tx", None).await;
    let (mut rx, mut buf) = raw(db, "floor-rx", Some("FLOOR")).await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
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
            let p = wire::next_packet(&mut rx, &mut buf, Duration::from_secs(5))
                .await
                .unwrap();
            if p.messages.iter().any(|m| m.value == i as f64) {
                break;
            }
        }
        out.push(start.elapsed());
    }
    out
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
    rt.block_on(async {
        let db = MoosDb::start("127.0.0.1:0".parse().unwrap()).await.unwrap();
        let port = db.addr().port();
        let n = 2000;
        let (f50, f99) = quantiles(floor(db.addr(), n).await);

        let node = Node::new("bench");
        let open = |name: &str, reg: &str| {
            seabus_medium_moos::schemes().open(
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
        let mut lat = Vec::with_capacity(n);
        for i in 0..n {
            let start = Instant::now();
            tx.send("RTT", DataMap::new().with("value", i as f64)).await.unwrap();
            loop {
                let m = tokio::time::timeout(Duration::from_secs(5), rx.recv())
                    .await
                    .expect("a reply")
                    .expect("open");
                if m.payload.as_map().and_then(|p| p.get_f64("value")) == Some(i as f64) {
                    break;
                }
            }
            lat.push(start.elapsed());
        }
        let (s50, s99) = quantiles(lat);
        println!("MOOS round trip publish -> DB -> subscriber, {n} in turn:");
        println!("  floor (raw sockets)  p50 {f50:.1} us, p99 {f99:.1} us");
        println!("  seabus client        p50 {s50:.1} us, p99 {s99:.1} us   ({:.2}x the floor at p50)", s50 / f50);

        let total = 100_000u32;
        let counter = tokio::spawn(async move {
            let mut got = 0u32;
            let start = Instant::now();
            while let Ok(Some(m)) = tokio::time::timeout(Duration::from_secs(2), rx.recv()).await {
                if m.topic.as_str() == "FLOOD" {
                    got += 1;
                    if got == total {
                        break;
                    }
                }
            }
            (got, start.elapsed())
        });
        let start = Instant::now();
        for i in 0..total {
            tx.send("FLOOD", DataMap::new().with("value", f64::from(i))).await.unwrap();
        }
        let sent_in = start.elapsed();
        let (got, took) = counter.await.unwrap();
        println!(
            "  throughput: {:.0} k msg/s sent, {got} of {total} received in {:.2} s ({:.0} k msg/s)",
            f64::from(total) / sent_in.as_secs_f64() / 1e3,
            took.as_secs_f64(),
            f64::from(got) / took.as_secs_f64() / 1e3
        );
        a.close();
        b.close();
        drop(db);
    });
}
