//! A bridge between a seabus bus and a CAN bus (cannelloni over loopback UDP), both ways, run by
//! `seabus run`: frames cross each way; a CAN side that sends the bridge's own frames back (a
//! looping gateway) does not make them cross again, although CAN frames carry no provenance.

mod common;
use common::*;
use seabus_medium::{DataMap, Node, Value};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_cross_both_ways_and_echoes_do_not_come_back() {
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let peer_port = peer.local_addr().unwrap().port();
    let ours = free_port();
    let bus_url = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="gw">
  <medium name="bus" url="{bus_url}"/>
  <medium name="can" url="cannelloni://127.0.0.1:{peer_port}?bind=127.0.0.1:{ours}"/>
  <bridge name="can-gw" media="bus can" report="200ms">
    <route from="bus" to="can" topics="can.**"/>
    <route from="can" to="bus" topics="can.**"/>
  </bridge>
</seabus>"#
    );
    let (_dir, path) = system_file("gw.xml", &system);
    let _run = spawn_run(&path, &[]);
    let bus = schemes().open("bus", &bus_url, &Node::new("test")).unwrap();
    let mut watch = bus.attach("watch");
    watch.subscribe("can.**").unwrap();
    watch.subscribe("seabus.bridge.**").unwrap();
    let sender = bus.attach("sender");

    // bus → CAN: the frame reaches the CAN side; the looping gateway sends it straight back
    let frame = DataMap::new().with("data", Value::Bytes(vec![1, 2]));
    let mut packet = None;
    for _ in 0..50 {
        sender.send("can.123", frame.clone()).await.unwrap();
        let mut buf = [0u8; 64];
        if let Ok((n, from)) = tokio::task::block_in_place(|| peer.recv_from(&mut buf)) {
            packet = Some((buf[..n].to_vec(), from));
            break;
        }
    }
    let (packet, from) = packet.expect("the bridge sends the bus's frame to the CAN side");
    assert_eq!(&packet[3..], [0, 1, 0, 0, 1, 0x23, 2, 1, 2]);
    peer.send_to(&packet, from).unwrap();

    // CAN → bus: another frame crosses; the echo never did
    peer.send_to(&[2, 0, 9, 0, 1, 0, 0, 4, 0x56, 1, 7], from)
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut echoes = None;
    let mut crossed = Vec::new();
    while Instant::now() < deadline && (echoes.is_none() || crossed.is_empty()) {
        let Ok(Some(m)) = tokio::time::timeout(Duration::from_millis(200), watch.recv()).await
        else {
            continue;
        };
        match m.topic.as_str() {
            "seabus.bridge.can-gw" => {
                let n = m.payload.as_map().and_then(|p| p.get_i64("echoes"));
                if n.is_some_and(|n| n > 0) {
                    echoes = n;
                }
            }
            // what this test sent itself is not what crossed
            _ if &*m.provenance.origin.node == "test" => {}
            t => crossed.push(t.to_string()),
        }
    }
    assert_eq!(
        crossed,
        ["can.456"],
        "only the new frame crosses to the bus"
    );
    assert_eq!(echoes, Some(1), "the echo is counted");
}
