//! The MOOS medium against seabus's own small MOOSDB, for what a real DB cannot be made to do: a
//! DB that sends garbage, a clock ahead of this host's, a client's name read late (the skew taken
//! from the handshake's round trip), and the small DB's own behaviour. Register and notify,
//! wildcards, intervals, the keep-alive, a name taken and a restarting DB are tested against the
//! real MOOSDB (`tests/moos_medium.rs` at the workspace's root).

use seabus_medium::{DataMap, LinkState, Medium, Node};
use seabus_medium_moos::db::{Clock, MoosDb};
use seabus_medium_moos::wire::{self, MoosMsg, Packet, Read, data, kind};
use std::net::SocketAddr;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

fn any_port() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

fn client(db: SocketAddr, name: &str, register: &str) -> Medium {
    seabus_medium_moos::schemes()
        .open(
            name,
            &format!(
                "moos://127.0.0.1:{}?name={name}&register={register}&reopen=100ms",
                db.port()
            ),
            &Node::new("t"),
        )
        .expect("the MOOS medium opens")
}

async fn up(m: &Medium) {
    m.link_within(Duration::from_secs(5), |s| *s == LinkState::Up)
        .await
        .expect("connected within 5 s");
}

async fn down(m: &Medium, why: &str) -> LinkState {
    m.link_within(
        Duration::from_secs(5),
        |s| matches!(s, LinkState::Down(r) if r.contains(why)),
    )
    .await
    .unwrap_or_else(|| panic!("the link down ({why}) within 5 s"))
}

/// A DB that welcomes with a clock skew of 100 s, takes one notification, then sends garbage.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_skew_is_taken_and_garbage_from_the_db_is_refused() {
    let listener = tokio::net::TcpListener::bind(any_port()).await.unwrap();
    let addr = listener.local_addr().unwrap();
    let server = tokio::spawn(async move {
        let (mut sock, _) = listener.accept().await.unwrap();
        let mut hello = [0u8; 32];
        sock.read_exact(&mut hello).await.unwrap();
        assert_eq!(hello, wire::handshake());
        let mut buf = Vec::new();
        let mut chunk = [0u8; 4096];
        let mut packets = Vec::new();
        // the introduction, the registrations, then a notification
        while packets
            .iter()
            .flat_map(|p: &Packet| p.messages.iter())
            .all(|m| m.kind != kind::NOTIFY)
        {
            let n = sock.read(&mut chunk).await.unwrap();
            assert!(n > 0, "the client went away");
            buf.extend_from_slice(&chunk[..n]);
            while let Ok(Read::Packet(p, used)) = wire::read_packet(&buf) {
                buf.drain(..used);
                if p.messages.first().is_some_and(|m| m.kind == kind::DATA) {
                    let welcome = MoosMsg {
                        kind: kind::WELCOME,
                        data_type: data::DOUBLE,
                        value: 100.0,
                        string: b"asynchronous".to_vec(),
                        ..MoosMsg::default()
                    };
                    sock.write_all(
                        &Packet {
                            messages: vec![welcome],
                        }
                        .encode(),
                    )
                    .await
                    .unwrap();
                }
                packets.push(p);
            }
        }
        // a packet claiming a negative length
        sock.write_all(&[0xFB, 0xFF, 0xFF, 0xFF, 1, 0, 0, 0, 0])
            .await
            .unwrap();
        let intro = &packets[0].messages[0];
        let notify = packets
            .iter()
            .flat_map(|p| p.messages.iter())
            .find(|m| m.kind == kind::NOTIFY)
            .unwrap()
            .clone();
        (intro.clone(), notify)
    });
    let m = client(addr, "pSkew", "NAV_*");
    up(&m).await;
    m.attach("w")
        .send("NAV_Y", DataMap::new().with("value", 1.0))
        .await
        .unwrap();
    let (intro, notify) = tokio::time::timeout(Duration::from_secs(5), server)
        .await
        .expect("the server finishes")
        .unwrap();
    assert_eq!(
        (
            intro.key.as_slice(),
            intro.string.as_slice(),
            intro.data_type
        ),
        (&b"asynchronous"[..], &b"pSkew"[..], data::STRING)
    );
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    assert!(
        (notify.time - (now + 100.0)).abs() < 2.0,
        "MOOS time = local + skew: {} vs {}",
        notify.time,
        now + 100.0
    );
    assert_eq!(notify.source, b"pSkew");
    let gone = down(&m, "malformed").await;
    assert!(
        matches!(&gone, LinkState::Down(r) if r.contains("a packet length of -5")),
        "{gone:?}"
    );
    assert_eq!(m.stats().rejected.get("moos-bad-length"), Some(&1));
}

/// A DB that answers as a MOOSDB does: its clock 100 s ahead, a timing message sent back with
/// the request's time still in it and the DB's time as the value. The medium's registrations name
/// it as their source (a MOOSDB subscribes the client the source names), and the skew stays near
/// 100 s through the timing replies.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn registrations_name_the_client_and_timing_replies_keep_the_skew() {
    let listener = tokio::net::TcpListener::bind(any_port()).await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (answered_tx, answered) = tokio::sync::oneshot::channel();
    let server = tokio::spawn(async move {
        let db_now = || {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_secs_f64()
                + 100.0
        };
        let (mut sock, _) = listener.accept().await.unwrap();
        let mut hello = [0u8; 32];
        sock.read_exact(&mut hello).await.unwrap();
        let mut buf = Vec::new();
        let mut chunk = [0u8; 4096];
        let (mut registrations, mut timings) = (Vec::new(), 0);
        let mut answered_tx = Some(answered_tx);
        // bounded: the test gives up after 10 s
        loop {
            let n = sock.read(&mut chunk).await.unwrap();
            assert!(n > 0, "the client went away");
            buf.extend_from_slice(&chunk[..n]);
            while let Ok(Read::Packet(p, used)) = wire::read_packet(&buf) {
                buf.drain(..used);
                let Some(first) = p.messages.first() else {
                    continue;
                };
                let reply = match first.kind {
                    kind::DATA => MoosMsg {
                        id: -1,
                        kind: kind::WELCOME,
                        data_type: data::DOUBLE,
                        community: b"#1".to_vec(),
                        value: db_now() - first.time,
                        string: b"asynchronous".to_vec(),
                        ..MoosMsg::default()
                    },
                    kind::TIMING => {
                        timings += 1;
                        MoosMsg {
                            value: db_now(),
                            value2: 0.0,
                            ..first.clone()
                        }
                    }
                    _ => {
                        for m in &p.messages {
                            match m.kind {
                                kind::REGISTER | kind::WILDCARD_REGISTER => {
                                    registrations.push(m.clone())
                                }
                                kind::NOTIFY => return (registrations, m.clone()),
                                _ => {}
                            }
                        }
                        continue;
                    }
                };
                sock.write_all(
                    &Packet {
                        messages: vec![reply],
                    }
                    .encode(),
                )
                .await
                .unwrap();
                if timings == 3
                    && let Some(tx) = answered_tx.take()
                {
                    let _ = tx.send(());
                }
            }
        }
    });
    let m = client(addr, "pTimed", "NAV_X,NAV_*:0.5");
    up(&m).await;
    tokio::time::timeout(Duration::from_secs(10), answered)
        .await
        .expect("three timing replies within 10 s")
        .unwrap();
    m.attach("w")
        .send("NAV_Y", DataMap::new().with("value", 1.0))
        .await
        .unwrap();
    let (registrations, notify) = tokio::time::timeout(Duration::from_secs(5), server)
        .await
        .expect("the server finishes")
        .unwrap();
    assert_eq!(
        registrations
            .iter()
            .map(|r| (r.kind, r.source.as_slice(), r.key.as_slice()))
            .collect::<Vec<_>>(),
        [
            (kind::REGISTER, &b"pTimed"[..], &b"NAV_X"[..]),
            (kind::WILDCARD_REGISTER, &b"pTimed"[..], &b"pTimed"[..]),
        ]
    );
    assert_eq!(
        registrations[1].string,
        b"AppPattern=*,VarPattern=NAV_*,Interval=0.5"
    );
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    assert!(
        (notify.time - (now + 100.0)).abs() < 2.0,
        "MOOS time after three timing replies = local + 100 s: {} vs {}",
        notify.time,
        now + 100.0
    );
}

/// A raw client of the test MoosDb, for what the medium does not send.
struct Raw {
    sock: tokio::net::TcpStream,
    buf: Vec<u8>,
}

impl Raw {
    async fn connect(db: SocketAddr, name: &str) -> Raw {
        let mut sock = tokio::net::TcpStream::connect(db).await.unwrap();
        sock.write_all(&wire::hello(name, 0.0)).await.unwrap();
        let mut raw = Raw {
            sock,
            buf: Vec::new(),
        };
        let welcome = raw.packet(Duration::from_secs(5)).await.unwrap();
        assert_eq!(welcome.messages[0].kind, kind::WELCOME);
        raw
    }

    async fn send(&mut self, messages: Vec<MoosMsg>) {
        self.sock
            .write_all(&Packet { messages }.encode())
            .await
            .unwrap();
    }

    async fn packet(&mut self, within: Duration) -> Option<Packet> {
        wire::next_packet(&mut self.sock, &mut self.buf, within)
            .await
            .ok()
    }

    /// The keys and values of the notifications that come within 300 ms.
    async fn notified(&mut self) -> Vec<(String, f64)> {
        let mut got = Vec::new();
        while let Some(p) = self.packet(Duration::from_millis(300)).await {
            got.extend(
                p.messages
                    .iter()
                    .filter(|m| m.kind == kind::NOTIFY)
                    .map(|m| (m.key_str(), m.value)),
            );
        }
        got
    }
}

fn raw_msg(kind: u8, source: &str, key: &str, value: f64, string: &str) -> MoosMsg {
    MoosMsg {
        kind,
        data_type: if string.is_empty() {
            data::DOUBLE
        } else {
            data::STRING
        },
        source: source.as_bytes().to_vec(),
        key: key.as_bytes().to_vec(),
        value,
        string: string.as_bytes().to_vec(),
        ..MoosMsg::default()
    }
}

/// The test MoosDb does what core-moos's MOOSDB was seen to do: registrations count for the client
/// their source names, a timing message comes back with the request's time and the DB's time as
/// the value, and unregistering by pattern stops the variables written so far while the pattern
/// still takes new ones.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_test_db_registers_times_and_unregisters_as_a_moosdb() {
    let db = MoosDb::start(any_port()).await.unwrap();
    let mut sub = Raw::connect(db.addr(), "rSub").await;
    let mut publisher = Raw::connect(db.addr(), "rPub").await;

    // a registration without a source subscribes no one
    sub.send(vec![raw_msg(kind::REGISTER, "", "U0", 0.0, "")])
        .await;
    sub.send(vec![
        raw_msg(kind::REGISTER, "rSub", "U1", 0.0, ""),
        raw_msg(
            kind::WILDCARD_REGISTER,
            "rSub",
            "rSub",
            0.0,
            "AppPattern=*,VarPattern=W*,Interval=0",
        ),
    ])
    .await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let write = |v: f64, keys: &[&str]| -> Vec<MoosMsg> {
        keys.iter()
            .map(|k| raw_msg(kind::NOTIFY, "rPub", k, v, ""))
            .collect()
    };
    publisher.send(write(1.0, &["U0", "U1", "W1"])).await;
    assert_eq!(
        sub.notified().await,
        [("U1".to_string(), 1.0), ("W1".to_string(), 1.0)]
    );

    sub.send(vec![
        raw_msg(kind::UNREGISTER, "rSub", "U1", 0.0, ""),
        raw_msg(
            kind::WILDCARD_UNREGISTER,
            "rSub",
            "rSub",
            0.0,
            "AppPattern=*,VarPattern=W*",
        ),
    ])
    .await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    publisher.send(write(2.0, &["U1", "W1", "W2"])).await;
    assert_eq!(sub.notified().await, [("W2".to_string(), 2.0)]);

    let asked = MoosMsg {
        id: 7,
        kind: kind::TIMING,
        data_type: data::DOUBLE,
        key: b"_async_timing".to_vec(),
        time: 1234.5,
        ..MoosMsg::default()
    };
    sub.send(vec![asked.clone()]).await;
    let reply = sub.packet(Duration::from_secs(5)).await.unwrap();
    let t = &reply.messages[0];
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    assert_eq!(
        (t.kind, t.id, t.time, t.key.as_slice()),
        (kind::TIMING, 7, 1234.5, &b"_async_timing"[..])
    );
    assert!((t.value - now).abs() < 2.0, "the DB's time: {}", t.value);
}

fn local_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// Starts a DB on `addr`, waiting (at most 5 s) for the port to be free again.
async fn db_on(addr: SocketAddr, clock: Clock) -> MoosDb {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        match MoosDb::start_with(addr, clock).await {
            Ok(db) => return db,
            Err(e) if Instant::now() < deadline => {
                let _ = e;
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            Err(e) => panic!("cannot listen on {addr} again: {e}"),
        }
    }
}

/// Writes `NAV_CLOCK` through `m` and returns how far the time it carried was from the local
/// clock while it was sent (0 when it lies between the send and its arrival at the DB).
async fn stamp_offset(m: &Medium, db: &MoosDb, n: f64) -> f64 {
    let tx = m.attach("clock");
    let before = local_now();
    tx.send("NAV_CLOCK", DataMap::new().with("value", n))
        .await
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while db.value("NAV_CLOCK").is_none_or(|v| v.value != n) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    let after = local_now();
    let stamped = db
        .value("NAV_CLOCK")
        .expect("the write reached the DB")
        .time;
    if stamped < before {
        stamped - before
    } else if stamped > after {
        stamped - after
    } else {
        0.0
    }
}

/// A DB on this host that reads a client's name 100 ms late (as a MOOSDB does): the skew is 0
/// within 1 ms from the first message on, and again after the DB restarts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn on_one_host_the_skew_is_zero_at_once_and_after_reconnecting() {
    let slow = Clock {
        ahead: 0.0,
        welcome_delay: Duration::from_millis(100),
    };
    let db = MoosDb::start_with(any_port(), slow).await.unwrap();
    let addr = db.addr();
    let m = client(addr, "pClock", "NONE");
    up(&m).await;
    let off = stamp_offset(&m, &db, 1.0).await;
    assert!(off.abs() < 0.001, "MOOS time off by {off} s at once");
    // the timing replies keep it there
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let off = stamp_offset(&m, &db, 2.0).await;
    assert!(off.abs() < 0.001, "MOOS time off by {off} s after 2.5 s");
    let mut db = db;
    for round in 0..2 {
        drop(db);
        down(&m, "").await;
        db = db_on(addr, slow).await;
        up(&m).await;
        let off = stamp_offset(&m, &db, 3.0 + f64::from(round)).await;
        assert!(
            off.abs() < 0.001,
            "MOOS time off by {off} s after reconnect {round}"
        );
    }
}

/// A DB whose clock runs 5 s ahead (another host), reading names 100 ms late: the skew is 5 s
/// from the first message on, within the handshake's return leg (a few milliseconds for a debug
/// build on a busy machine; the DB's own measure in its welcome would be 0.1 s off).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_db_clock_ahead_gives_its_skew_at_once() {
    let db = MoosDb::start_with(
        any_port(),
        Clock {
            ahead: 5.0,
            welcome_delay: Duration::from_millis(100),
        },
    )
    .await
    .unwrap();
    let m = client(db.addr(), "pAhead", "NONE");
    up(&m).await;
    let off = stamp_offset(&m, &db, 1.0).await;
    assert!((off - 5.0).abs() < 0.01, "MOOS time ahead by {off} s");
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let off = stamp_offset(&m, &db, 2.0).await;
    assert!(
        (off - 5.0).abs() < 0.01,
        "MOOS time ahead by {off} s after 2.5 s"
    );
}
