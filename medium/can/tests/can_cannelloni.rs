//! cannelloni over loopback UDP: a peer's packets, written byte by byte from the format notes,
//! arrive as CAN messages; what seabus sends arrives as exactly those bytes; damaged packets and
//! packets from strangers are counted and dropped; two seabus media talk to each other.

use seabus_medium::{DataMap, Interface, Medium, Message, Node, Value};
use seabus_medium_can::frame::CanFrame;
use std::net::UdpSocket;
use std::time::Duration;

fn bytes(v: &[u8]) -> Value {
    Value::Bytes(v.to_vec())
}

fn open(url: &str) -> Medium {
    seabus_medium_can::schemes()
        .open("can", url, &Node::new("t"))
        .expect("the CAN medium opens")
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

async fn next(iface: &mut Interface) -> Message {
    tokio::time::timeout(Duration::from_secs(5), iface.recv())
        .await
        .expect("a frame within 5 s")
        .expect("the medium is open")
}

fn frame_of(m: &Message) -> CanFrame {
    CanFrame::from_message(m.topic.as_str(), &m.payload).expect("a CAN frame")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn packets_from_the_notes_both_ways() {
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let peer_port = peer.local_addr().unwrap().port();
    let ours = free_port();
    let medium = open(&format!(
        "cannelloni://127.0.0.1:{peer_port}?bind=127.0.0.1:{ours}"
    ));
    let mut iface = medium.attach("test");
    iface.subscribe("can.**").unwrap();

    // the peer's packet: extended 0x18FF50E5 [AA], remote 0x7FF asking 4, FD ext 0x10 BRS+ESI
    let packet = [
        &[2u8, 0, 9, 0, 3][..],
        &[0x98, 0xFF, 0x50, 0xE5, 1, 0xAA],
        &[0x40, 0x00, 0x07, 0xFF, 4],
        &[0x80, 0x00, 0x00, 0x10, 0x8C, 0x03],
        &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12],
    ]
    .concat();
    peer.send_to(&packet, ("127.0.0.1", ours)).unwrap();
    let a = next(&mut iface).await;
    assert_eq!(a.topic.as_str(), "can.18ff50e5");
    assert_eq!(
        frame_of(&a),
        CanFrame::data(0x18FF_50E5, true, &[0xAA]).unwrap()
    );
    let b = next(&mut iface).await;
    assert_eq!(frame_of(&b), CanFrame::remote(0x7FF, false, 4).unwrap());
    let c = next(&mut iface).await;
    let map = c.payload.as_map().unwrap();
    assert_eq!(
        (map.get("fd"), map.get("brs"), map.get("esi")),
        (
            Some(&Value::Bool(true)),
            Some(&Value::Bool(true)),
            Some(&Value::Bool(true))
        )
    );
    assert_eq!(frame_of(&c).payload(), (1..=12).collect::<Vec<u8>>());

    // seabus's frames: one packet each, numbered from 0, exactly the notes' bytes
    let sends = [
        ("can.123", DataMap::new().with("data", bytes(&[0xDE, 0xAD]))),
        (
            "can.00000005",
            DataMap::new().with("rtr", true).with("dlc", 8i64),
        ),
        (
            "can.7ff",
            DataMap::new()
                .with("data", bytes(&[0; 16]))
                .with("fd", true)
                .with("brs", true),
        ),
    ];
    let want: [Vec<u8>; 3] = [
        vec![2, 0, 0, 0, 1, 0x00, 0x00, 0x01, 0x23, 2, 0xDE, 0xAD],
        vec![2, 0, 1, 0, 1, 0xC0, 0x00, 0x00, 0x05, 8],
        [
            &[2u8, 0, 2, 0, 1, 0x00, 0x00, 0x07, 0xFF, 0x90, 0x01][..],
            &[0; 16],
        ]
        .concat(),
    ];
    let mut buf = [0u8; 256];
    for ((topic, map), want) in sends.into_iter().zip(want) {
        iface.send(topic, map).await.unwrap();
        let (n, from) = tokio::task::block_in_place(|| peer.recv_from(&mut buf)).unwrap();
        assert_eq!(from.port(), ours);
        assert_eq!(&buf[..n], &want[..], "{topic}");
    }

    // a damaged packet and a stranger's packet are counted; the good one after still arrives
    peer.send_to(&[2, 0, 0, 0, 1, 0, 0, 1], ("127.0.0.1", ours))
        .unwrap();
    let stranger = UdpSocket::bind("127.0.0.2:0").unwrap();
    stranger
        .send_to(&[2, 0, 0, 0, 1, 0, 0, 1, 0x11, 0], ("127.0.0.1", ours))
        .unwrap();
    peer.send_to(&[2, 0, 3, 0, 1, 0, 0, 0, 0x42, 0], ("127.0.0.1", ours))
        .unwrap();
    assert_eq!(next(&mut iface).await.topic.as_str(), "can.042");
    let rejected = medium.stats().rejected;
    assert_eq!(rejected.get("cannelloni-count"), Some(&1), "{rejected:?}");
    assert_eq!(
        rejected.get("cannelloni-unknown-peer"),
        Some(&1),
        "{rejected:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_media_talk_through_cannelloni() {
    let (pa, pb) = (free_port(), free_port());
    let a = open(&format!("cannelloni://127.0.0.1:{pb}?bind=127.0.0.1:{pa}"));
    let b = open(&format!(
        "cannelloni://127.0.0.1:{pa}?bind=127.0.0.1:{pb}&filter=100:700"
    ));
    let mut on_b = b.attach("b");
    on_b.subscribe("can.**").unwrap();
    let on_a = a.attach("a");
    // only 0x100–0x1ff pass b's filter
    for id in ["can.200", "can.1ab"] {
        on_a.send(id, DataMap::new().with("data", bytes(&[1, 2])))
            .await
            .unwrap();
    }
    let m = next(&mut on_b).await;
    assert_eq!(frame_of(&m), CanFrame::data(0x1AB, false, &[1, 2]).unwrap());
}
