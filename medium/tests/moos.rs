//! The MOOS medium against a MOOSDB: the handshake, register and notify, wildcard registration,
//! interval throttling, structured values as key=value strings, the keep-alive, a name already
//! taken, the DB restarting (clients reconnect and register again), and a DB that sends garbage.

use seabus_medium::moos::db::MoosDb;
use seabus_medium::moos::wire::{self, MoosMsg, Packet, Read, data, kind};
use seabus_medium::{DataMap, Interface, LinkState, Medium, Message, Node};
use std::net::SocketAddr;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

fn any_port() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

fn client(db: SocketAddr, name: &str, register: &str) -> Medium {
    Medium::open(
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
    let mut link = m.watch_link();
    tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| *s == LinkState::Up),
    )
    .await
    .expect("connected within 5 s")
    .expect("the medium is open");
}

/// The next message, at most `within` away.
async fn next(i: &mut Interface, within: Duration) -> Option<Message> {
    tokio::time::timeout(within, i.recv()).await.ok().flatten()
}

fn value(m: &Message) -> Option<f64> {
    m.payload.as_map().and_then(|p| p.get_f64("value"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_register_notify_and_filter_by_pattern_and_interval() {
    let db = MoosDb::start(any_port()).await.unwrap();
    let a = client(db.addr(), "pA", "*");
    let b = client(db.addr(), "pB", "NAV_*,THROTTLED:0.5");
    up(&a).await;
    up(&b).await;
    let mut on_a = a.attach("a");
    on_a.subscribe("**").unwrap();
    let mut on_b = b.attach("b");
    on_b.subscribe("**").unwrap();
    let send_a = a.attach("send");
    // registrations arrive after the welcome: the first notification shows they took effect
    let mut got = None;
    for _ in 0..50 {
        send_a
            .send("NAV_DEPTH", DataMap::new().with("value", 12.5))
            .await
            .unwrap();
        if let Some(m) = next(&mut on_b, Duration::from_millis(100)).await {
            got = Some(m);
            break;
        }
    }
    let m = got.expect("B gets NAV_DEPTH");
    assert_eq!((m.topic.as_str(), value(&m)), ("NAV_DEPTH", Some(12.5)));
    assert_eq!(db.clients(), ["pA", "pB"]);

    // not registered for it: B never sees it; A, registered for everything, sees B's
    send_a
        .send("DESIRED_HEADING", DataMap::new().with("value", 90.0))
        .await
        .unwrap();
    b.attach("send")
        .send(
            "NODE_REPORT",
            DataMap::new()
                .with("NAME", "auv1")
                .with("X", 10.5)
                .with("MODE", "A,B=C"),
        )
        .await
        .unwrap();
    // A's interface also sees what A's other interface sent (local delivery): look for B's
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut report = None;
    while Instant::now() < deadline && report.is_none() {
        if let Some(m) = next(&mut on_a, Duration::from_millis(100)).await
            && m.topic.as_str() == "NODE_REPORT"
        {
            report = Some(m);
        }
    }
    let report = report.expect("A gets B's report");
    assert_eq!(
        report.payload.as_map().cloned(),
        Some(
            DataMap::new()
                .with("NAME", "auv1")
                .with("X", 10.5)
                .with("MODE", "A,B=C")
        )
    );
    // from the DB A took only B's report: its own writes, which the DB sends back to it, are not
    // delivered again
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(a.stats().received, 1, "{:?}", a.stats());
    while next(&mut on_b, Duration::from_millis(300)).await.is_some() {}

    // 20 writes over a second: B, registered with a 0.5 s interval, gets two or three of them
    for i in 0..20 {
        send_a
            .send("THROTTLED", DataMap::new().with("value", f64::from(i)))
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let mut throttled = Vec::new();
    while let Some(m) = next(&mut on_b, Duration::from_millis(600)).await {
        if m.topic.as_str() == "THROTTLED" {
            throttled.push(value(&m).unwrap());
        }
    }
    assert!(
        (2..=3).contains(&throttled.len()),
        "a 0.5 s interval over 1 s of writes: {throttled:?}"
    );
    assert_eq!(throttled[0], 0.0, "the first write goes at once");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn keep_alive_names_taken_and_a_restarting_db() {
    let db = MoosDb::start(any_port()).await.unwrap();
    let addr = db.addr();
    let quiet = client(addr, "pQuiet", "NAV_X");
    up(&quiet).await;
    // silent but for its timing messages: still connected after the DB's 5 s limit
    tokio::time::sleep(Duration::from_secs(6)).await;
    assert_eq!(db.clients(), ["pQuiet"]);
    assert_eq!(quiet.link_state(), LinkState::Up);

    // a second client with the same name is refused, saying why
    let twin = client(addr, "pQuiet", "*");
    let mut link = twin.watch_link();
    let refused = tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| matches!(s, LinkState::Down(r) if r.contains("refused"))),
    )
    .await
    .expect("the refusal within 5 s")
    .unwrap()
    .clone();
    assert!(
        matches!(&refused, LinkState::Down(r) if r.contains("a client called `pQuiet` is already connected")),
        "{refused:?}"
    );
    twin.close();

    // the DB goes away: the link goes down; it comes back on the same port: the client connects
    // and registers again
    drop(db);
    let mut link = quiet.watch_link();
    tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| matches!(s, LinkState::Down(_))),
    )
    .await
    .expect("the link goes down")
    .unwrap();
    let db = {
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match MoosDb::start(addr).await {
                Ok(db) => break db,
                Err(e) if Instant::now() < deadline => {
                    let _ = e;
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                Err(e) => panic!("cannot listen on {addr} again: {e}"),
            }
        }
    };
    up(&quiet).await;
    let mut on_quiet = quiet.attach("q");
    on_quiet.subscribe("**").unwrap();
    let writer = client(addr, "pW", "NONE");
    up(&writer).await;
    let tx = writer.attach("w");
    let mut got = None;
    for _ in 0..50 {
        tx.send("NAV_X", DataMap::new().with("value", 3.0))
            .await
            .unwrap();
        if let Some(m) = next(&mut on_quiet, Duration::from_millis(100)).await {
            got = Some(m);
            break;
        }
    }
    let m = got.expect("registered again after the restart");
    assert_eq!((m.topic.as_str(), value(&m)), ("NAV_X", Some(3.0)));
    drop(db);
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
    let mut link = m.watch_link();
    let down = tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| matches!(s, LinkState::Down(r) if r.contains("malformed"))),
    )
    .await
    .expect("the garbage takes the link down")
    .unwrap()
    .clone();
    assert!(
        matches!(&down, LinkState::Down(r) if r.contains("a packet length of -5")),
        "{down:?}"
    );
    assert_eq!(m.stats().rejected.get("moos-bad-length"), Some(&1));
}
