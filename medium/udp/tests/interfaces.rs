//! Interfaces on the in-process and UDP media, every payload format in and out,
//! queue policies, duplicates, and what the UDP medium does with bad or oversized datagrams.

use seabus_medium::{
    DataMap, FaultConfig, Format, Interface, Kind, Medium, Node, Payload, SendError, TryRecvError,
    Value,
};
use std::time::Duration;
use tokio::time::timeout;

const WAIT: Duration = Duration::from_secs(5);

fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("an ephemeral port")
}

fn group() -> String {
    format!("239.255.{}.{}", fastrand::u8(1..250), fastrand::u8(1..250))
}

fn sample_map() -> DataMap {
    DataMap::new()
        .with("yaw", 12.5f64)
        .with("count", 3i64)
        .with("ok", true)
        .with("name", "iver <2> & \"friends\"")
        .with("raw", vec![0u8, 1, 2, 255])
        .with(
            "list",
            Value::List(vec![1i64.into(), 2.5f64.into(), "x".into()]),
        )
}

fn payload_in(format: Format) -> Payload {
    Payload::from(sample_map())
        .convert(format)
        .expect("datamap converts to every format")
}

/// Pairs of media on which one interface sends and another receives: in-process (one medium),
/// UDP multicast on loopback, and UDP unicast between two peers.
async fn media_pairs(tag: &str) -> Vec<(&'static str, Medium, Medium)> {
    let node = Node::new(tag);
    let bus = Medium::in_process("bus", &node);
    let g = group();
    let port = free_port();
    let url = format!("udp://{g}:{port}?ttl=0&iface=127.0.0.1");
    let m1 = seabus_medium_udp::schemes()
        .open("net", &url, &Node::new("left"))
        .expect("multicast medium opens");
    let m2 = seabus_medium_udp::schemes()
        .open("net", &url, &Node::new("right"))
        .expect("multicast medium opens");
    let (pa, pb) = (free_port(), free_port());
    let u1 = seabus_medium_udp::schemes()
        .open(
            "p2p",
            &format!("udp://127.0.0.1:{pa}?peer=127.0.0.1:{pb}"),
            &Node::new("a"),
        )
        .unwrap();
    let u2 = seabus_medium_udp::schemes()
        .open(
            "p2p",
            &format!("udp://127.0.0.1:{pb}?peer=127.0.0.1:{pa}"),
            &Node::new("b"),
        )
        .unwrap();
    vec![
        ("in-process", bus.clone(), bus),
        ("udp multicast", m1, m2),
        ("udp unicast", u1, u2),
    ]
}

#[tokio::test]
async fn passive_interfaces_convert_every_format_to_every_format() {
    for (what, tx_medium, rx_medium) in media_pairs("passive").await {
        let tx = tx_medium.attach("sender");
        let mut receivers: Vec<(Format, Interface)> = [Format::Bytes, Format::Map, Format::Xml]
            .into_iter()
            .map(|f| {
                (
                    f,
                    rx_medium
                        .attach("receiver")
                        .accepting(f)
                        .subscribed("test.**")
                        .unwrap(),
                )
            })
            .collect();
        for sent in [Format::Bytes, Format::Map, Format::Xml] {
            tx.send("test.formats", payload_in(sent)).await.unwrap();
            for (accepts, rx) in receivers.iter_mut() {
                let m = timeout(WAIT, rx.recv())
                    .await
                    .expect("message arrives")
                    .unwrap();
                assert_eq!(
                    m.payload.format(),
                    *accepts,
                    "{what}: sent {sent}, accepts {accepts}"
                );
                assert_eq!(
                    *m.payload.to_map().unwrap(),
                    sample_map(),
                    "{what}: sent {sent}, accepts {accepts}"
                );
                assert_eq!(m.topic.as_str(), "test.formats");
                assert_eq!(m.kind, Kind::Data);
            }
        }
        for (_, rx) in receivers.iter_mut() {
            assert_eq!(
                rx.try_recv().unwrap_err(),
                TryRecvError::Empty,
                "{what}: nothing more"
            );
            assert_eq!(rx.stats().received, 3);
        }
    }
}

#[tokio::test]
async fn raw_bytes_and_foreign_xml_reach_only_receivers_that_can_take_them() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut as_bytes = bus
        .attach("b")
        .accepting(Format::Bytes)
        .subscribed("**")
        .unwrap();
    let mut as_map = bus
        .attach("m")
        .accepting(Format::Map)
        .subscribed("**")
        .unwrap();
    let mut as_is = bus.attach("any").subscribed("**").unwrap();
    tx.send("raw.nmea", Payload::from(b"$GPGGA,1*00".as_slice()))
        .await
        .unwrap();
    tx.send("raw.doc", seabus_medium::payload::xml("<mission/>"))
        .await
        .unwrap();
    assert_eq!(
        as_bytes
            .recv()
            .await
            .unwrap()
            .payload
            .as_bytes()
            .unwrap()
            .as_ref(),
        b"$GPGGA,1*00"
    );
    // the foreign XML cannot become bytes: counted, not delivered
    assert_eq!(as_bytes.try_recv().unwrap_err(), TryRecvError::Empty);
    assert_eq!(as_bytes.stats().conversion_errors, 1);
    assert_eq!(as_map.try_recv().unwrap_err(), TryRecvError::Empty);
    assert_eq!(as_map.stats().conversion_errors, 2);
    assert_eq!(as_is.recv().await.unwrap().payload.format(), Format::Bytes);
    assert_eq!(
        as_is.recv().await.unwrap().payload.as_xml(),
        Some("<mission/>")
    );
}

#[tokio::test]
async fn a_slow_subscriber_drops_its_oldest_data_and_slows_no_one() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut fast1 = bus
        .attach_with("fast1", 100_000, 8)
        .subscribed("d")
        .unwrap();
    let mut fast2 = bus
        .attach_with("fast2", 100_000, 8)
        .subscribed("d")
        .unwrap();
    let mut slow = bus.attach_with("slow", 16, 8).subscribed("d").unwrap();
    let total = 10_000i64;
    for i in 0..total {
        tx.send("d", DataMap::new().with("i", i)).await.unwrap();
    }
    for fast in [&mut fast1, &mut fast2] {
        let mut n = 0;
        while let Ok(m) = fast.try_recv() {
            assert_eq!(m.payload.as_map().unwrap().get_i64("i"), Some(n));
            n += 1;
        }
        assert_eq!(n, total);
        assert_eq!(fast.stats().dropped_oldest, 0);
    }
    let st = slow.stats();
    assert_eq!(st.dropped_oldest, (total - 16) as u64);
    assert_eq!(st.pending, 16);
    // what is left is the newest data
    let first = slow.try_recv().unwrap();
    assert_eq!(
        first.payload.as_map().unwrap().get_i64("i"),
        Some(total - 16)
    );
}

#[tokio::test]
async fn commands_are_never_dropped_a_full_queue_holds_the_sender() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut rx = bus.attach_with("rx", 4, 2).subscribed("cmd.**").unwrap();
    let sender = tokio::spawn(async move {
        for i in 0..6i64 {
            tx.command("cmd.course", DataMap::new().with("i", i))
                .await
                .unwrap();
        }
        tx
    });
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert!(
        !sender.is_finished(),
        "the sender waits while the command queue is full"
    );
    assert_eq!(rx.stats().pending, 2);
    let mut got = Vec::new();
    while got.len() < 6 {
        let m = timeout(WAIT, rx.recv()).await.unwrap().unwrap();
        got.push(m.payload.as_map().unwrap().get_i64("i").unwrap());
    }
    assert_eq!(got, [0, 1, 2, 3, 4, 5]);
    timeout(WAIT, sender).await.unwrap().unwrap();
    assert_eq!(rx.stats().commands_refused, 0);
}

#[tokio::test]
async fn commands_are_taken_before_data() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut rx = bus.attach("rx").subscribed("**").unwrap();
    tx.send("d", DataMap::new()).await.unwrap();
    tx.command("c", DataMap::new()).await.unwrap();
    assert_eq!(rx.recv().await.unwrap().kind, Kind::Command);
    assert_eq!(rx.recv().await.unwrap().kind, Kind::Data);
}

#[tokio::test]
async fn duplicates_from_the_medium_are_dropped_and_counted() {
    let node = Node::new("n");
    let bus = Medium::in_process_with_faults(
        "bus",
        &node,
        FaultConfig {
            duplicate: 1.0,
            reorder: 0.3,
            seed: 5,
            ..FaultConfig::default()
        },
    );
    let tx = bus.attach("tx");
    let mut rx = bus.attach("rx").subscribed("d").unwrap();
    for i in 0..200i64 {
        tx.send("d", DataMap::new().with("i", i)).await.unwrap();
    }
    let mut seen = Vec::new();
    while let Ok(Some(m)) = timeout(Duration::from_millis(200), rx.recv()).await {
        seen.push(m.payload.as_map().unwrap().get_i64("i").unwrap());
    }
    seen.sort();
    assert_eq!(seen, (0..200).collect::<Vec<_>>());
    assert_eq!(rx.stats().duplicates, 200);
    assert_eq!(bus.stats().fault_duplicated, 200);
}

#[tokio::test]
async fn udp_refuses_oversized_messages_at_send() {
    let port = free_port();
    let m = seabus_medium_udp::schemes()
        .open(
            "net",
            &format!("udp://127.0.0.1:{port}?peer=127.0.0.1:{port}"),
            &Node::new("n"),
        )
        .unwrap();
    let tx = m.attach("tx");
    let err = tx
        .send("big", Payload::from(vec![0u8; 70_000]))
        .await
        .unwrap_err();
    match err {
        SendError::TooLarge { size, max, .. } => {
            assert!(size > 70_000);
            assert_eq!(max, 65_507);
        }
        other => panic!("expected TooLarge, got {other}"),
    }
    let small = seabus_medium_udp::schemes()
        .open(
            "net",
            &format!("udp://127.0.0.1:{}?max=100", free_port()),
            &Node::new("n"),
        )
        .unwrap();
    let err = small
        .attach("tx")
        .send("t", Payload::from(vec![0u8; 100]))
        .await
        .unwrap_err();
    assert!(err.to_string().contains("carries at most 100"), "{err}");
}

#[tokio::test]
async fn udp_counts_and_drops_malformed_datagrams_and_keeps_going() {
    let port = free_port();
    let m = seabus_medium_udp::schemes()
        .open("net", &format!("udp://127.0.0.1:{port}"), &Node::new("rx"))
        .unwrap();
    let mut rx = m.attach("rx").subscribed("**").unwrap();
    let raw = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let dest = format!("127.0.0.1:{port}");
    raw.send_to(b"hello, not seabus", &dest).unwrap();
    raw.send_to(b"SB\x01", &dest).unwrap();
    let mut wrong_version = vec![b'S', b'B', 9];
    wrong_version.resize(40, 0);
    raw.send_to(&wrong_version, &dest).unwrap();
    // then a good one from a real sender
    let sender = seabus_medium_udp::schemes()
        .open(
            "net",
            &format!("udp://127.0.0.1:{}?peer={dest}", free_port()),
            &Node::new("tx"),
        )
        .unwrap();
    sender
        .attach("tx")
        .send("ok", DataMap::new().with("v", 1i64))
        .await
        .unwrap();
    let got = timeout(WAIT, rx.recv()).await.unwrap().unwrap();
    assert_eq!(got.topic.as_str(), "ok");
    assert_eq!(got.origin().node.as_ref(), "tx");
    let st = m.stats();
    assert_eq!(st.rejected.get("bad-magic"), Some(&1));
    assert_eq!(st.rejected.get("truncated"), Some(&1));
    assert_eq!(st.rejected.get("bad-version"), Some(&1));
    assert_eq!(st.received, 1);
}

#[tokio::test]
async fn a_node_does_not_hear_its_own_multicast_twice() {
    let url = format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port());
    let m = seabus_medium_udp::schemes()
        .open("net", &url, &Node::new("solo"))
        .unwrap();
    let peer = seabus_medium_udp::schemes()
        .open("net", &url, &Node::new("peer"))
        .unwrap();
    let tx = m.attach("tx");
    let mut local = m.attach("local").subscribed("**").unwrap();
    let mut remote = peer.attach("remote").subscribed("**").unwrap();
    tx.send("hello", DataMap::new()).await.unwrap();
    assert!(timeout(WAIT, local.recv()).await.unwrap().is_some());
    assert!(timeout(WAIT, remote.recv()).await.unwrap().is_some());
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert_eq!(local.try_recv().unwrap_err(), TryRecvError::Empty);
    assert_eq!(
        local.stats().duplicates,
        0,
        "the echo never reached the queue"
    );
    assert_eq!(m.stats().received, 0);
}

#[tokio::test]
async fn closing_a_medium_ends_its_interfaces_and_refuses_sends() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut rx = bus.attach("rx").subscribed("**").unwrap();
    tx.send("last", DataMap::new()).await.unwrap();
    bus.close();
    assert!(rx.recv().await.is_some(), "what was queued is still read");
    assert!(rx.recv().await.is_none());
    assert!(matches!(
        tx.send("x", DataMap::new()).await,
        Err(SendError::Closed(_))
    ));
}

#[tokio::test]
async fn subscriptions_follow_patterns_and_can_change() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut rx = bus.attach("rx").subscribed("nav.*").unwrap();
    for t in ["nav.depth", "nav.gps.raw", "cmd.course", "nav.attitude"] {
        tx.send(t, DataMap::new()).await.unwrap();
    }
    let topics: Vec<String> = std::iter::from_fn(|| rx.try_recv().ok())
        .map(|m| m.topic.to_string())
        .collect();
    assert_eq!(topics, ["nav.depth", "nav.attitude"]);
    rx.subscribe("cmd.**").unwrap();
    assert!(rx.unsubscribe("nav.*"));
    tx.send("nav.depth", DataMap::new()).await.unwrap();
    tx.command("cmd.course", DataMap::new()).await.unwrap();
    assert_eq!(rx.try_recv().unwrap().topic.as_str(), "cmd.course");
    assert!(rx.try_recv().is_err());
    assert!(tx.send("bad..topic", DataMap::new()).await.is_err());
}

#[tokio::test]
async fn regression_a_command_overtaking_queued_data_loses_none_of_it() {
    // duplicates are judged in arrival order, so a command taken first cannot make older data "late"
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut rx = bus.attach_with("rx", 4096, 8).subscribed("**").unwrap();
    for i in 0..1000i64 {
        tx.send("d", DataMap::new().with("i", i)).await.unwrap();
    }
    assert_eq!(rx.recv().await.unwrap().kind, Kind::Data);
    for i in 1000..2000i64 {
        tx.send("d", DataMap::new().with("i", i)).await.unwrap();
    }
    tx.command("c", DataMap::new()).await.unwrap();
    let mut data = 1;
    let mut commands = 0;
    while let Ok(m) = rx.try_recv() {
        match m.kind {
            Kind::Data => data += 1,
            Kind::Command => commands += 1,
        }
    }
    assert_eq!((data, commands), (2000, 1));
    let st = rx.stats();
    assert_eq!((st.late, st.duplicates, st.dropped_oldest), (0, 0, 0));
}

#[tokio::test]
async fn data_in_hand_counts_against_the_capacity() {
    let bus = Medium::in_process("bus", &Node::new("n"));
    let tx = bus.attach("tx");
    let mut rx = bus.attach_with("rx", 16, 8).subscribed("d").unwrap();
    for i in 0..16i64 {
        tx.send("d", DataMap::new().with("i", i)).await.unwrap();
    }
    // taking one takes the rest in hand as a batch
    assert_eq!(
        rx.recv()
            .await
            .unwrap()
            .payload
            .as_map()
            .unwrap()
            .get_i64("i"),
        Some(0)
    );
    for i in 16..32i64 {
        tx.send("d", DataMap::new().with("i", i)).await.unwrap();
    }
    let rest: Vec<i64> = std::iter::from_fn(|| rx.try_recv().ok())
        .map(|m| m.payload.as_map().unwrap().get_i64("i").unwrap())
        .collect();
    assert!(
        rest.len() <= 17,
        "held {} messages with a capacity of 16",
        rest.len()
    );
    assert_eq!(rest.last(), Some(&31), "the newest data is kept");
    assert_eq!(rx.stats().dropped_oldest as usize, 31 - rest.len());
}

#[tokio::test]
async fn closing_a_udp_medium_frees_its_port() {
    let url = format!("udp://127.0.0.1:{}", free_port());
    let first = seabus_medium_udp::schemes()
        .open("net", &url, &Node::new("n"))
        .unwrap();
    let _still_attached = first.attach("x");
    first.close();
    tokio::task::yield_now().await;
    let again = seabus_medium_udp::schemes().open("net", &url, &Node::new("n"));
    assert!(again.is_ok(), "{:?}", again.err());
}
