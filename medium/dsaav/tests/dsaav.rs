//! The DSAAV IComms medium on its in-process and UDP backbones: addressed messages and channel
//! broadcasts between nodes, the dictionary mapping both ways, and what is refused and counted
//! (malformed frames, unknown keys, oversize strings, topics and keys it cannot carry).

use seabus_medium::{DataMap, Interface, Medium, Message, Node, SendError, Value};
use seabus_medium_dsaav::wire::{Address, Destination, Frame, Param};
use std::net::UdpSocket;
use std::time::Duration;
use tokio::time::timeout;

const WAIT: Duration = Duration::from_secs(5);

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

async fn next(iface: &mut Interface) -> Message {
    timeout(WAIT, iface.recv())
        .await
        .expect("a message in time")
        .expect("medium open")
}

/// Three nodes on one backbone: node 1 sends to node 2, then broadcasts on channel 4.
async fn exchange(base: &str) {
    let sep = if base.contains('?') { '&' } else { '?' };
    let one = open(&format!("{base}{sep}node=1&port=7"));
    let two = open(&format!("{base}{sep}node=2"));
    let three = open(&format!("{base}{sep}node=3"));
    let mut at_two = two.attach("t").subscribed("dsaav.**").unwrap();
    let mut at_three = three.attach("t").subscribed("dsaav.**").unwrap();
    let sender = one.attach("t");
    sender
        .send(
            "dsaav.data",
            DataMap::new()
                .with("@dst", "2:5")
                .with("depth", 12.25f64)
                .with("gain", 0.5f64)
                .with("count", 3i64)
                .with("component", "DepthSensor"),
        )
        .await
        .unwrap();
    let m = next(&mut at_two).await;
    assert_eq!(m.topic.as_str(), "dsaav.data");
    let map = m.payload.as_map().unwrap();
    assert_eq!(map.get_str("@src"), Some("1:7"));
    assert_eq!(map.get_str("@dst"), Some("2:5"));
    assert_eq!(map.get_f64("depth"), Some(12.25));
    assert_eq!(
        map.get_f64("gain"),
        Some(0.5),
        "a float key travels as 32 bits"
    );
    assert_eq!(map.get_i64("count"), Some(3));
    assert_eq!(map.get_str("component"), Some("DepthSensor"));
    assert!(map.get_i64("@id").is_some_and(|id| id > 0));
    sender
        .send(
            "dsaav.notify",
            DataMap::new()
                .with("@channel", 4i64)
                .with("@ref", 99i64)
                .with("heading", 270.0f64),
        )
        .await
        .unwrap();
    // node 3 gets only the broadcast: the first message was for node 2
    let m = next(&mut at_three).await;
    assert_eq!(m.topic.as_str(), "dsaav.notify");
    let map = m.payload.as_map().unwrap();
    assert_eq!(
        (map.get_i64("@channel"), map.get_i64("@ref")),
        (Some(4), Some(99))
    );
    let m = next(&mut at_two).await;
    assert_eq!(m.topic.as_str(), "dsaav.notify");
    // and the sender never hears its own frames back from the backbone
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert_eq!(one.stats().received, 0, "no echo of its own frames");
    assert_eq!(one.stats().transmitted, 2);
}

#[tokio::test]
async fn nodes_exchange_messages_in_process() {
    exchange(&format!("dsaav+inproc://t{}", fastrand::u32(..))).await;
}

#[tokio::test]
async fn nodes_exchange_messages_over_udp() {
    let url = format!(
        "dsaav+udp://239.255.{}.{}:{}?ttl=0",
        fastrand::u8(1..250),
        fastrand::u8(1..250),
        fastrand::u16(20_000..60_000)
    );
    exchange(&url).await;
}

#[tokio::test]
async fn what_cannot_be_carried_is_refused_naming_why() {
    let m = open(&format!("dsaav+inproc://r{}?node=1", fastrand::u32(..)));
    let port = m.attach("t");
    let refused = |r: Result<(), SendError>| match r {
        Err(SendError::Io { reason, .. }) => reason,
        Err(SendError::TooLarge { size, .. }) => format!("too large: {size}"),
        other => panic!("not refused: {other:?}"),
    };
    let e = refused(port.send("nav.depth", DataMap::new()).await);
    assert!(e.contains("carries topics dsaav.TYPE"), "{e}");
    let e = refused(port.send("dsaav.nosuch", DataMap::new()).await);
    assert!(e.contains("`nosuch` is not a DSAAV message type"), "{e}");
    let e = refused(
        port.send("dsaav.data", DataMap::new().with("salinity", 35.0f64))
            .await,
    );
    assert!(
        e.contains("`salinity` is not a key of the DSAAV dictionary"),
        "{e}"
    );
    let e = refused(
        port.send("dsaav.data", DataMap::new().with("count", "three"))
            .await,
    );
    assert!(e.contains("`count` is int in the DSAAV dictionary"), "{e}");
    let e = refused(
        port.send("dsaav.data", DataMap::new().with("@dst", "2"))
            .await,
    );
    assert!(
        e.contains("`2` is not an address: expected `node:port`"),
        "{e}"
    );
    let e = refused(
        port.send("dsaav.data", DataMap::new().with("text", "x".repeat(2000)))
            .await,
    );
    assert!(e.contains("too large"), "{e}");
    let e = refused(
        port.send("dsaav.data", DataMap::new().with("text", "x".repeat(1100)))
            .await,
    );
    assert!(e.contains("at most 1024 bytes"), "{e}");
}

#[tokio::test]
async fn malformed_frames_and_unknown_keys_are_counted_and_the_rest_goes_on() {
    let (a, b, port) = (
        fastrand::u8(1..250),
        fastrand::u8(1..250),
        fastrand::u16(20_000..60_000),
    );
    let m = open(&format!("dsaav+udp://239.255.{a}.{b}:{port}?ttl=0&node=2"));
    let mut iface = m.attach("t").subscribed("dsaav.**").unwrap();
    let sock = UdpSocket::bind("0.0.0.0:0").unwrap();
    sock.set_multicast_ttl_v4(0).unwrap();
    let _ = socket2::SockRef::from(&sock).set_multicast_if_v4(&std::net::Ipv4Addr::LOCALHOST);
    let to = format!("239.255.{a}.{b}:{port}");
    let good = Frame {
        src: Address { node: 9, port: 0 },
        dst: Destination::To(Address { node: 2, port: 0 }),
        id: 1,
        kind: 1,
        reference: 0,
        params: vec![(102, Param::Double(4.5)), (4000, Param::Int(7))],
    }
    .encode()
    .unwrap();
    let mut bad_string = good.clone();
    bad_string.truncate(26);
    bad_string[25] = 1;
    bad_string.extend_from_slice(&[0, 3, 4, 0, 2, 0xff, 0xfe]);
    let len = bad_string.len() as u16;
    bad_string[2..4].copy_from_slice(&len.to_be_bytes());
    for d in [
        b"not a frame at all, but long enough".to_vec(),
        good[..good.len() - 2].to_vec(),
        bad_string,
        good.clone(),
    ] {
        sock.send_to(&d, &to).unwrap();
    }
    let msg = next(&mut iface).await;
    let map = msg.payload.as_map().unwrap();
    assert_eq!(map.get_f64("depth"), Some(4.5));
    assert_eq!(
        map.get("k4000").and_then(Value::as_i64),
        Some(7),
        "an unknown key is kept by number"
    );
    assert_eq!(msg.origin().node.as_ref(), "dsaav@9");
    let rejected = m.stats().rejected;
    for reason in [
        "dsaav-bad-magic",
        "dsaav-bad-length",
        "dsaav-bad-string",
        "dsaav-unknown-key",
    ] {
        assert_eq!(
            rejected.get(reason).copied(),
            Some(1),
            "{reason}: {rejected:?}"
        );
    }
}

/// A medium's own interfaces see what it sends as a receiver on its node reads it from the wire:
/// the header keys, the values as the wire carries them; a message to another node not at all.
#[tokio::test]
async fn local_interfaces_see_what_a_receiver_on_the_node_would() {
    let bus = format!("dsaav+inproc://l{}", fastrand::u32(..));
    let one = open(&format!("{bus}?node=1&port=7"));
    let two = open(&format!("{bus}?node=2"));
    let mut here = one.attach("here").subscribed("dsaav.**").unwrap();
    let mut there = two.attach("there").subscribed("dsaav.**").unwrap();
    let sender = one.attach("sender");
    // to node 2: node 2 gets it, node 1's interfaces do not
    sender
        .send(
            "dsaav.data",
            DataMap::new().with("@dst", "2:3").with("count", 1i64),
        )
        .await
        .unwrap();
    let m = next(&mut there).await;
    assert_eq!(m.payload.as_map().unwrap().get_i64("count"), Some(1));
    // to a port of node 1, from port 9
    sender
        .send(
            "dsaav.data",
            DataMap::new()
                .with("@dst", "1:4")
                .with("@port", 9i64)
                .with("gain", 0.1f64)
                .with("count", 2i64),
        )
        .await
        .unwrap();
    let m = next(&mut here).await;
    let map = m.payload.as_map().unwrap();
    assert_eq!(
        map.get_i64("count"),
        Some(2),
        "the message to node 2 was delivered here"
    );
    assert_eq!(map.get_str("@src"), Some("1:9"));
    assert_eq!(map.get_str("@dst"), Some("1:4"));
    assert!(map.get_i64("@id").is_some_and(|id| id > 0));
    assert_eq!(map.get("@port"), None, "not a header the wire gives");
    assert_eq!(
        map.get_f64("gain"),
        Some(f64::from(0.1f32)),
        "as the wire carries it"
    );
    // a broadcast, its type by number: the same here as on node 2
    sender
        .send(
            "dsaav.2",
            DataMap::new()
                .with("@channel", 4i64)
                .with("@ref", 8i64)
                .with("count", 3i64),
        )
        .await
        .unwrap();
    let (mine, theirs) = (next(&mut here).await, next(&mut there).await);
    assert_eq!(mine.topic.as_str(), "dsaav.rpc-request");
    assert_eq!(mine.topic, theirs.topic);
    assert_eq!(mine.payload.as_map(), theirs.payload.as_map());
    assert_eq!(mine.payload.as_map().unwrap().get_str("@src"), Some("1:7"));
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert!(here.try_recv().is_err(), "nothing else here");
    assert!(there.try_recv().is_err(), "nothing else there");
    assert_eq!(one.stats().transmitted, 3);
}

/// A UDP port nobody uses right now.
fn unused_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("an ephemeral port")
}

#[tokio::test]
async fn a_relay_medium_carries_every_frame_as_it_is_both_ways() {
    let (relay_port, node_port) = (unused_port(), unused_port());
    let relay = open(&format!("dsaav+udp://127.0.0.1:{relay_port}?relay"));
    assert!(relay.capabilities().is_native("dsaav-frames"));
    let node = open(&format!(
        "dsaav+udp://127.0.0.1:{node_port}?peer=127.0.0.1:{relay_port}&node=9"
    ));
    let mut at_relay = relay.attach("t").subscribed("**").unwrap();
    let mut at_node = node.attach("t").subscribed("dsaav.**").unwrap();
    // a node's frame to another node (not the relay's: it has none) arrives as it is
    node.attach("s")
        .send(
            "dsaav.data",
            DataMap::new().with("@dst", "4:2").with("depth", 3.5f64),
        )
        .await
        .unwrap();
    let m = next(&mut at_relay).await;
    assert_eq!(m.topic.as_str(), "dsaav.frame");
    let map = m.payload.as_map().unwrap().clone();
    assert_eq!(
        map.get_str("from"),
        Some(format!("127.0.0.1:{node_port}").as_str())
    );
    assert_eq!((map.get_i64("src"), map.get_i64("dst")), (Some(9), Some(4)));
    let Some(Value::Bytes(bytes)) = map.get("frame") else {
        panic!("{map}")
    };
    let f = Frame::decode(bytes).unwrap();
    assert_eq!(f.dst, Destination::To(Address { node: 4, port: 2 }));
    // a frame the relay sends to the node's address is read by the node as from node 4
    let back = Frame {
        src: Address { node: 4, port: 2 },
        dst: Destination::To(Address { node: 9, port: 0 }),
        id: 77,
        kind: f.kind,
        reference: f.id,
        params: vec![(f.params[0].0, Param::Double(1.25))],
    };
    relay
        .attach("s")
        .send(
            "dsaav.frame",
            DataMap::new()
                .with("frame", Value::Bytes(back.encode().unwrap()))
                .with("to", format!("127.0.0.1:{node_port}")),
        )
        .await
        .unwrap();
    let m = next(&mut at_node).await;
    let map = m.payload.as_map().unwrap();
    assert_eq!(map.get_str("@src"), Some("4:2"));
    // the relay medium's other interfaces see what was sent on it, as on any medium
    let local = next(&mut at_relay).await;
    assert_eq!(
        local.payload.as_map().unwrap().get_str("to"),
        Some(format!("127.0.0.1:{node_port}").as_str())
    );
    assert_eq!(
        (map.get_i64("@id"), map.get_i64("@ref")),
        (Some(77), Some(i64::from(f.id)))
    );
    assert_eq!(map.get_f64("depth"), Some(1.25));
    // what is not a frame is refused at send, and bytes that are not one are counted at receipt
    let refused = relay
        .attach("s")
        .send(
            "dsaav.frame",
            DataMap::new().with("frame", Value::Bytes(vec![1, 2, 3])),
        )
        .await;
    assert!(matches!(refused, Err(SendError::Io { .. })), "{refused:?}");
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .send_to(b"not a frame", ("127.0.0.1", relay_port))
        .unwrap();
    let start = std::time::Instant::now();
    while relay.stats().rejected_total() == 0 && start.elapsed() < WAIT {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert_eq!(relay.stats().rejected_total(), 1);
    assert!(
        at_relay.try_recv().is_err(),
        "nothing is delivered for bytes that are not a frame"
    );
}
