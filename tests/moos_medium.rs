//! The MOOS medium against the real MOOSDB of core-moos (built once by `scripts/peers moos`):
//! register and notify, wildcard registration, interval throttling, key=value strings between two
//! seabus clients, its own writes not taken back, the keep-alive past the DB's 5 s limit, a name
//! already taken (the DB's refusal is the link's reason), and the DB killed and started again (the
//! client connects and registers again).

mod common;
use common::moos::MoosDb;
use seabus_medium::{DataMap, Interface, LinkState, Medium, Message, Node};
use std::time::{Duration, Instant};

fn client(port: u16, name: &str, register: &str) -> Medium {
    seabus_medium_moos::schemes()
        .open(
            name,
            &format!("moos://127.0.0.1:{port}?name={name}&register={register}&reopen=100ms"),
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

/// The next message, at most `within` away.
async fn next(i: &mut Interface, within: Duration) -> Option<Message> {
    tokio::time::timeout(within, i.recv()).await.ok().flatten()
}

fn value(m: &Message) -> Option<f64> {
    m.payload.as_map().and_then(|p| p.get_f64("value"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_register_notify_and_filter_by_pattern_and_interval() {
    let db = MoosDb::start();
    // (not `*`: a MOOSDB writes its own DB_* variables, which A would then receive too)
    let a = client(db.port, "pA", "NAV_*,DESIRED_*,NODE_*");
    let b = client(db.port, "pB", "NAV_*,THROTTLED:0.5");
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

    // not registered for it: B never sees it; A, registered for those patterns, sees B's
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
                .with("MODE", "A=B=C"),
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
                .with("MODE", "A=B=C")
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
    let mut db = MoosDb::start();
    let port = db.port;
    let quiet = client(port, "pQuiet", "NAV_X");
    up(&quiet).await;
    // silent but for its timing messages: still connected after the DB's 5 s limit
    tokio::time::sleep(Duration::from_secs(6)).await;
    assert_eq!(quiet.link_state(), LinkState::Up);

    // a second client with the same name is refused, saying why
    let twin = client(port, "pQuiet", "*");
    let refused = down(&twin, "refused").await;
    assert!(
        matches!(&refused, LinkState::Down(r) if r.contains("refused: A client of this name (\"pQuiet\") already exists")),
        "{refused:?}"
    );
    twin.close();

    // the DB goes away: the link goes down; it comes back on the same port: the client connects
    // and registers again
    db.kill();
    down(&quiet, "").await;
    db.restart();
    up(&quiet).await;
    let mut on_quiet = quiet.attach("q");
    on_quiet.subscribe("**").unwrap();
    let writer = client(port, "pW", "NONE");
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
}
