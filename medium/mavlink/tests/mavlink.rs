//! The MAVLink medium on loopback sockets, with a stand-in vehicle in the test: over UDP (the
//! medium listening) and TCP (connecting, and listening), its messages, its heartbeat, the
//! vehicles list, the link state, commands, and refusals.

use mavlink::{MavHeader, MavlinkVersion};
use seabus_medium::{DataMap, Interface, LinkState, Medium, Message, Node, SendError, Value};
use seabus_medium_mavlink::Dialect;
use seabus_medium_mavlink::frame::{self, Item, StreamReader};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};

const DIALECT: Dialect = Dialect::ArduPilotMega;

fn open(url: &str) -> Medium {
    seabus_medium_mavlink::schemes()
        .open("mav", url, &Node::new("test"))
        .unwrap_or_else(|e| panic!("{url}: {e}"))
}

fn encode(name: &str, map: &DataMap, sysid: u8, seq: u8) -> Vec<u8> {
    let header = MavHeader {
        system_id: u32::from(sysid),
        component_id: 1,
        sequence: seq,
    };
    DIALECT
        .encode(MavlinkVersion::V2, header, name, map)
        .unwrap()
}

fn sub_heartbeat(armed: bool) -> DataMap {
    DataMap::new()
        .with("custom_mode", 19i64)
        .with("type", "MAV_TYPE_SUBMARINE")
        .with("autopilot", "MAV_AUTOPILOT_ARDUPILOTMEGA")
        .with(
            "base_mode",
            if armed {
                "MAV_MODE_FLAG_SAFETY_ARMED | MAV_MODE_FLAG_CUSTOM_MODE_ENABLED"
            } else {
                "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED"
            },
        )
        .with("system_status", "MAV_STATE_ACTIVE")
        .with("mavlink_version", 3i64)
}

fn attitude(t: i64) -> DataMap {
    DataMap::new()
        .with("time_boot_ms", t)
        .with("roll", 0.1)
        .with("pitch", -0.2)
        .with("yaw", 1.5)
        .with("rollspeed", 0.0)
        .with("pitchspeed", 0.0)
        .with("yawspeed", 0.01)
}

fn arm() -> DataMap {
    DataMap::new()
        .with("target_system", 1i64)
        .with("target_component", 1i64)
        .with("command", "MAV_CMD_COMPONENT_ARM_DISARM")
        .with("confirmation", 0i64)
        .with("param1", 1.0)
        .with("param2", 0.0)
        .with("param3", 0.0)
        .with("param4", 0.0)
        .with("param5", 0.0)
        .with("param6", 0.0)
        .with("param7", 0.0)
}

/// What a test reads from the medium: messages are taken by topic, in the order they came, those
/// of other topics kept for later.
struct Inbox {
    port: Interface,
    kept: Vec<Message>,
}

impl Inbox {
    fn new(port: Interface) -> Inbox {
        Inbox {
            port,
            kept: Vec::new(),
        }
    }

    /// The next message on `topic`, waiting at most `limit`.
    async fn next(&mut self, topic: &str, limit: Duration) -> Message {
        if let Some(i) = self.kept.iter().position(|m| m.topic.as_str() == topic) {
            return self.kept.remove(i);
        }
        let deadline = Instant::now() + limit;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, self.port.recv()).await {
                Ok(Some(m)) if m.topic.as_str() == topic => return m,
                Ok(Some(m)) => self.kept.push(m),
                Ok(None) => panic!("the medium closed before {topic}"),
                Err(_) => panic!("no {topic} within {limit:?}"),
            }
        }
    }
}

/// Waits at most `limit` for the link to be in a state `pred` accepts; returns that state.
async fn link(medium: &Medium, limit: Duration, pred: impl Fn(&LinkState) -> bool) -> LinkState {
    let mut watch = medium.watch_link();
    match tokio::time::timeout(limit, watch.wait_for(|s| pred(s))).await {
        Ok(Ok(s)) => s.clone(),
        _ => panic!("the link stayed {:?} for {limit:?}", medium.link_state()),
    }
}

/// A decoded frame: sender, message name and fields.
type Heard = (u32, u8, &'static str, DataMap);

fn decode(f: frame::Frame) -> Heard {
    let (name, map) = DIALECT.decode(&f.raw).unwrap();
    (f.raw.system_id(), f.raw.component_id(), name, map)
}

/// Reads datagrams at `sock` until a frame `pred` accepts, at most `limit`.
async fn udp_until(sock: &UdpSocket, limit: Duration, pred: impl Fn(&Heard) -> bool) -> Heard {
    let deadline = Instant::now() + limit;
    let mut buf = vec![0u8; 2048];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let n = match tokio::time::timeout(left, sock.recv(&mut buf)).await {
            Ok(r) => r.unwrap(),
            Err(_) => panic!("no such frame within {limit:?}"),
        };
        let mut found = None;
        frame::datagram(DIALECT, &buf[..n], |item| {
            if let Item::Frame(f) = item {
                let heard = decode(f);
                if found.is_none() && pred(&heard) {
                    found = Some(heard);
                }
            }
        });
        if let Some(h) = found {
            return h;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_over_udp_is_heard_listed_commanded_and_lost() {
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let medium = open(&format!(
        "mavlink://udpin:127.0.0.1:{port}?sysid=250&compid=191&heartbeat=100ms&timeout=600ms"
    ));
    assert_eq!(
        medium.link_state(),
        LinkState::Down("no vehicle heard yet".into())
    );
    let mut rx = Inbox::new(medium.attach("test").subscribed("mavlink.**").unwrap());
    let tx = medium.attach("sender");
    // nobody heard yet: nowhere to send
    match tx.command("mavlink.1.COMMAND_LONG", arm()).await {
        Err(SendError::LinkDown { reason, .. }) => {
            assert!(
                reason.starts_with("no peer heard on udpin:127.0.0.1:"),
                "{reason}"
            )
        }
        other => panic!("{other:?}"),
    }

    let vehicle = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    vehicle.connect(("127.0.0.1", port)).await.unwrap();
    let (stop, mut stopped) = tokio::sync::watch::channel(false);
    let beating = {
        let vehicle = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        vehicle.connect(("127.0.0.1", port)).await.unwrap();
        tokio::spawn(async move {
            for seq in 0..200u8 {
                vehicle
                    .send(&encode("HEARTBEAT", &sub_heartbeat(seq >= 3), 1, seq))
                    .await
                    .unwrap();
                tokio::select! {
                    _ = tokio::time::sleep(Duration::from_millis(100)) => {}
                    _ = stopped.changed() => return Instant::now(),
                }
            }
            Instant::now()
        })
    };
    vehicle
        .send(&encode("ATTITUDE", &attitude(1234), 1, 0))
        .await
        .unwrap();
    link(&medium, Duration::from_secs(3), |s| *s == LinkState::Up).await;
    let att = rx.next("mavlink.1.ATTITUDE", Duration::from_secs(3)).await;
    let att = att.payload.as_map().unwrap();
    assert_eq!(att.get_i64("time_boot_ms"), Some(1234));
    assert_eq!(att.get("roll"), Some(&Value::Float(0.1)));
    assert_eq!(att.get("pitch"), Some(&Value::Float(-0.2)));
    assert_eq!(
        (att.get_i64("sysid"), att.get_i64("compid")),
        (Some(1), Some(1))
    );

    // the vehicles list: on the vehicle's first heartbeat, then when it arms
    let first = rx.next("mavlink.vehicles", Duration::from_secs(3)).await;
    let first = first.payload.as_map().unwrap().clone();
    assert_eq!(
        (
            first.get_i64("sysid"),
            first.get_str("type"),
            first.get_str("autopilot"),
            first.get_bool("armed"),
            first.get_i64("custom_mode"),
            first.get_bool("alive")
        ),
        (
            Some(1),
            Some("MAV_TYPE_SUBMARINE"),
            Some("MAV_AUTOPILOT_ARDUPILOTMEGA"),
            Some(false),
            Some(19),
            Some(true)
        )
    );
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        let v = rx.next("mavlink.vehicles", Duration::from_secs(3)).await;
        if v.payload.as_map().unwrap().get_bool("armed") == Some(true) {
            break;
        }
        assert!(Instant::now() < deadline, "the vehicle never showed armed");
    }

    // the vehicle hears the medium's heartbeat, with the URL's ids
    let (s, c, _, hb) = udp_until(&vehicle, Duration::from_secs(3), |h| h.2 == "HEARTBEAT").await;
    assert_eq!((s, c), (250, 191));
    assert_eq!(
        (hb.get_str("type"), hb.get_str("autopilot")),
        (Some("MAV_TYPE_GCS"), Some("MAV_AUTOPILOT_INVALID"))
    );

    // a command goes out with the medium's ids and the datamap's fields
    tx.command("mavlink.1.COMMAND_LONG", arm()).await.unwrap();
    let (s, c, _, cmd) =
        udp_until(&vehicle, Duration::from_secs(3), |h| h.2 == "COMMAND_LONG").await;
    assert_eq!((s, c), (250, 191));
    assert_eq!(
        (
            cmd.get_str("command"),
            cmd.get_i64("target_system"),
            cmd.get("param1")
        ),
        (
            Some("MAV_CMD_COMPONENT_ARM_DISARM"),
            Some(1),
            Some(&Value::Float(1.0))
        )
    );
    // what cannot be a MAVLink message is refused, saying why
    let mut short = arm();
    short.remove("param3");
    let e = tx
        .send("mavlink.1.COMMAND_LONG", short)
        .await
        .unwrap_err()
        .to_string();
    assert_eq!(e, "medium `mav`: COMMAND_LONG: missing field `param3`");
    let e = tx
        .send("nav.attitude", attitude(1))
        .await
        .unwrap_err()
        .to_string();
    assert!(e.contains("mavlink.SYSID.MESSAGE_NAME"), "{e}");

    // the vehicle falls silent: the link goes down after the timeout, and the list says so
    stop.send(true).unwrap();
    let last = beating.await.unwrap();
    let down = link(&medium, Duration::from_secs(3), |s| *s != LinkState::Up).await;
    let after = last.elapsed();
    assert_eq!(
        down,
        LinkState::Down("no heartbeat from the vehicle (system 1, component 1) for 600ms".into())
    );
    assert!(
        after >= Duration::from_millis(400) && after < Duration::from_millis(1500),
        "{after:?}"
    );
    loop {
        let v = rx.next("mavlink.vehicles", Duration::from_secs(3)).await;
        if v.payload.as_map().unwrap().get_bool("alive") == Some(false) {
            break;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tcp_vehicle_is_reached_again_after_the_connection_is_lost() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let medium = open(&format!(
        "mavlink://tcpout:127.0.0.1:{port}?reopen=100ms&heartbeat=100ms"
    ));
    let mut rx = Inbox::new(medium.attach("test").subscribed("mavlink.1.*").unwrap());
    let (mut conn, _) = tokio::time::timeout(Duration::from_secs(3), listener.accept())
        .await
        .unwrap()
        .unwrap();
    // good frames with garbage, a corrupted frame and a frame of no known message between them,
    // in one write
    let mut bad_crc = encode("ATTITUDE", &attitude(2), 1, 1);
    let n = bad_crc.len();
    bad_crc[n - 2] ^= 0x55;
    let mut unknown = encode("ATTITUDE", &attitude(3), 1, 2);
    unknown[7..10].copy_from_slice(&16_000_000u32.to_le_bytes()[..3]);
    let mut bytes = encode("HEARTBEAT", &sub_heartbeat(false), 1, 0);
    bytes.extend_from_slice(b"line noise");
    bytes.extend(bad_crc);
    bytes.extend(unknown);
    bytes.extend(encode("ATTITUDE", &attitude(4), 1, 3));
    conn.write_all(&bytes).await.unwrap();
    link(&medium, Duration::from_secs(3), |s| *s == LinkState::Up).await;
    let att = rx.next("mavlink.1.ATTITUDE", Duration::from_secs(3)).await;
    assert_eq!(
        att.payload.as_map().unwrap().get_i64("time_boot_ms"),
        Some(4)
    );
    let rejected = medium.stats().rejected;
    assert_eq!(
        rejected,
        [("bad-crc", 1), ("garbage", 1), ("unknown-message", 1)]
            .into_iter()
            .map(|(k, n)| (k.to_string(), n))
            .collect()
    );
    // the medium's heartbeat comes on the connection
    let mut reader = StreamReader::default();
    let mut buf = [0u8; 512];
    let deadline = Instant::now() + Duration::from_secs(3);
    let mut heard = None;
    while heard.is_none() && Instant::now() < deadline {
        let n = tokio::time::timeout(Duration::from_secs(3), conn.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        reader.push(DIALECT, &buf[..n], |item| {
            if let Item::Frame(f) = item {
                heard.get_or_insert(decode(f));
            }
        });
    }
    let (s, c, name, _) = heard.expect("the medium's heartbeat");
    assert_eq!((s, c, name), (255, 190, "HEARTBEAT"));

    // the vehicle's end closes: down at once with the reason, then connected again
    drop(conn);
    let down = link(&medium, Duration::from_secs(3), |s| *s != LinkState::Up).await;
    let LinkState::Down(why) = down else {
        unreachable!()
    };
    assert!(why.contains(&format!("tcpout:127.0.0.1:{port}")), "{why}");
    let (mut conn, _) = tokio::time::timeout(Duration::from_secs(3), listener.accept())
        .await
        .unwrap()
        .unwrap();
    conn.write_all(&encode("HEARTBEAT", &sub_heartbeat(true), 1, 4))
        .await
        .unwrap();
    link(&medium, Duration::from_secs(3), |s| *s == LinkState::Up).await;
    // commands go out on the new connection
    let tx = medium.attach("sender");
    tx.command("mavlink.1.COMMAND_LONG", arm()).await.unwrap();
    medium.flush().await;
    let mut reader = StreamReader::default();
    let mut command = None;
    let deadline = Instant::now() + Duration::from_secs(3);
    while command.is_none() && Instant::now() < deadline {
        let n = tokio::time::timeout(Duration::from_secs(3), conn.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        reader.push(DIALECT, &buf[..n], |item| {
            if let Item::Frame(f) = item {
                let h = decode(f);
                if h.2 == "COMMAND_LONG" {
                    command = Some(h);
                }
            }
        });
    }
    let (_, _, _, cmd) = command.expect("the command");
    assert_eq!(cmd.get_str("command"), Some("MAV_CMD_COMPONENT_ARM_DISARM"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tcp_listening_medium_serves_a_client() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let medium = open(&format!("mavlink://tcpin:127.0.0.1:{port}?version=1"));
    let tx = medium.attach("sender");
    match tx.command("mavlink.1.COMMAND_LONG", arm()).await {
        Err(SendError::LinkDown { reason, .. }) => {
            assert!(
                reason.starts_with("a client's connection on 127.0.0.1:"),
                "{reason}"
            )
        }
        other => panic!("{other:?}"),
    }
    let mut client = TcpStream::connect(("127.0.0.1", port)).await.unwrap();
    client
        .write_all(&encode("HEARTBEAT", &sub_heartbeat(false), 7, 0))
        .await
        .unwrap();
    link(&medium, Duration::from_secs(3), |s| *s == LinkState::Up).await;
    tx.command("mavlink.7.COMMAND_LONG", arm()).await.unwrap();
    // version=1: MAVLink 1 frames
    let mut buf = [0u8; 512];
    let mut reader = StreamReader::default();
    let mut command = None;
    let deadline = Instant::now() + Duration::from_secs(3);
    while command.is_none() && Instant::now() < deadline {
        let n = tokio::time::timeout(Duration::from_secs(3), client.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        reader.push(DIALECT, &buf[..n], |item| {
            if let Item::Frame(f) = item
                && f.raw.version() == MavlinkVersion::V1
            {
                let h = decode(f);
                if h.2 == "COMMAND_LONG" {
                    command = Some(h);
                }
            }
        });
    }
    assert!(command.is_some(), "a MAVLink 1 COMMAND_LONG");
}
