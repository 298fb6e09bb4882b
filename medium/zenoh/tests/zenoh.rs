//! The Zenoh medium between two seabus nodes on loopback (a vehicle listening, a shore station
//! connecting), and against a bare Zenoh session standing for a program that is not seabus.

use seabus_medium::{DataMap, Interface, Kind, LinkState, Medium, Node, Payload, Value};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::time::timeout;

const WAIT: Duration = Duration::from_secs(10);

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn open(name: &str, node: &str, url: &str) -> Medium {
    seabus_medium_zenoh::schemes()
        .open(name, url, &Node::new(node))
        .unwrap_or_else(|e| panic!("{url}: {e}"))
}

/// Vehicle auv1's medium `name`, listening on `port` (`options` added to its URL).
fn vehicle_on(name: &str, port: u16, options: &str) -> Medium {
    open(
        name,
        "auv1",
        &format!("zenoh://?listen=tcp/127.0.0.1:{port}&prefix=fleet/auv1&scout=false{options}"),
    )
}

/// The shore's medium `name`, connecting to the vehicle listening on `port`.
fn shore_on(name: &str, port: u16) -> Medium {
    open(
        name,
        "shore",
        &format!("zenoh://?connect=tcp/127.0.0.1:{port}&prefix=fleet&scout=false"),
    )
}

async fn wait_link(m: &Medium, up: bool) {
    let mut w = m.watch_link();
    let res = timeout(WAIT, w.wait_for(|s| matches!(s, LinkState::Up) == up)).await;
    assert!(
        res.is_ok(),
        "{} never {}: {:?}",
        m.name(),
        if up { "up" } else { "down" },
        m.link_state()
    );
}

async fn next(port: &mut Interface) -> seabus_medium::Message {
    timeout(WAIT, port.recv())
        .await
        .expect("a message arrives")
        .expect("open")
}

/// Sends `map` on `topic` from `tx` until `rx` hears something (subscriptions take a moment to
/// reach the other side), then returns what it heard.
async fn send_until_heard(
    tx: &Interface,
    rx: &mut Interface,
    kind: Kind,
    topic: &str,
    map: &DataMap,
) -> seabus_medium::Message {
    for _ in 0..100 {
        match kind {
            Kind::Data => tx.send(topic, Payload::from(map.clone())).await.unwrap(),
            Kind::Command => tx.command(topic, Payload::from(map.clone())).await.unwrap(),
        }
        if let Ok(Some(m)) = timeout(Duration::from_millis(100), rx.recv()).await {
            return m;
        }
    }
    panic!("nothing heard on {topic}");
}

fn pair(json: bool) -> (Medium, Medium) {
    let port = free_port();
    let vehicle = vehicle_on("net", port, &format!("&json={json}"));
    let shore = shore_on("net", port);
    (vehicle, shore)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_and_a_shore_station_exchange_data_and_commands_with_provenance() {
    let (vehicle, shore) = pair(false);
    wait_link(&vehicle, true).await;
    wait_link(&shore, true).await;
    let mut heard = shore.attach("watch").subscribed("*.nav.**").unwrap();
    let mut commands = vehicle.attach("driver").subscribed("cmd.**").unwrap();
    let mut own = vehicle.attach("own").subscribed("nav.**").unwrap();
    let tx = vehicle.attach("nav");
    let att = DataMap::new()
        .and("yaw", 12.5)
        .and("pitch", -1.0)
        .and("roll", 0.25);
    let m = send_until_heard(&tx, &mut heard, Kind::Data, "nav.attitude", &att).await;
    assert_eq!(
        m.topic.as_str(),
        "auv1.nav.attitude",
        "the vehicle's name first on shore"
    );
    assert_eq!(m.kind, Kind::Data);
    assert_eq!(*m.payload.to_map().unwrap(), att);
    let o = m.origin();
    assert_eq!(
        (&*o.node, &*o.medium),
        ("auv1", "net"),
        "provenance rides along"
    );
    // the vehicle's own interface hears its sends locally, once, not back from Zenoh
    let mut seqs = Vec::new();
    while seqs.last() != Some(&m.seq()) {
        let mine = next(&mut own).await;
        assert_eq!(mine.topic.as_str(), "nav.attitude");
        seqs.push(mine.seq());
    }
    assert!(
        seqs.windows(2).all(|w| w[0] < w[1]),
        "each send once: {seqs:?}"
    );
    // a command from shore reaches the vehicle as a command on its own topic
    let course = DataMap::new()
        .and("heading", 90.0)
        .and("depth", 2.0)
        .and("speed", 1.2);
    let c = send_until_heard(
        &shore.attach("pilot"),
        &mut commands,
        Kind::Command,
        "auv1.cmd.course",
        &course,
    )
    .await;
    assert_eq!((c.topic.as_str(), c.kind), ("cmd.course", Kind::Command));
    assert_eq!(*c.payload.to_map().unwrap(), course);
    assert_eq!(&*c.origin().node, "shore");
    // the link follows the connection
    vehicle.close();
    wait_link(&shore, false).await;
    shore.close();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn datamaps_as_json_keep_their_provenance() {
    let (vehicle, shore) = pair(true);
    wait_link(&shore, true).await;
    let mut heard = shore.attach("watch").subscribed("auv1.**").unwrap();
    let pos = DataMap::new()
        .and("lat", 43.5)
        .and("lon", 16.44)
        .and("fix", 4i64)
        .and("source", "rtk");
    let m = send_until_heard(
        &vehicle.attach("gps"),
        &mut heard,
        Kind::Data,
        "nav.position",
        &pos,
    )
    .await;
    assert_eq!(m.topic.as_str(), "auv1.nav.position");
    assert_eq!(*m.payload.to_map().unwrap(), pos);
    assert_eq!(&*m.origin().node, "auv1");
    // bytes still go as a datagram
    vehicle
        .attach("raw")
        .send("nav.raw", Payload::from(b"\x01\x02".as_slice()))
        .await
        .unwrap();
    let raw = loop {
        let m = next(&mut heard).await;
        if m.topic.as_str() == "auv1.nav.raw" {
            break m;
        }
    };
    assert_eq!(raw.payload.as_bytes().unwrap().as_ref(), b"\x01\x02");
    vehicle.close();
    shore.close();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn what_other_zenoh_programs_send_is_read_or_counted() {
    let port = free_port();
    let shore = open(
        "net",
        "shore",
        &format!("zenoh://?listen=tcp/127.0.0.1:{port}&prefix=fleet&scout=false"),
    );
    let mut heard = shore.attach("watch").subscribed("usv9.**").unwrap();
    let mut cfg = zenoh::Config::default();
    cfg.insert_json5("connect/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))
        .unwrap();
    cfg.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    let other = zenoh::open(cfg).await.unwrap();
    wait_link(&shore, true).await;
    // JSON text is a datamap; until the subscription has reached the other side, put again
    let mut got = None;
    for _ in 0..100 {
        other
            .put("fleet/usv9/env/wind", r#"{"speed": 5.5, "angle": 45.0}"#)
            .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
            .await
            .unwrap();
        if let Ok(Some(m)) = timeout(Duration::from_millis(100), heard.recv()).await {
            got = Some(m);
            break;
        }
    }
    let m = got.expect("the JSON sample is heard");
    assert_eq!((m.topic.as_str(), m.kind), ("usv9.env.wind", Kind::Data));
    assert_eq!(
        m.payload.to_map().unwrap().get("speed"),
        Some(&Value::Float(5.5))
    );
    assert_eq!(
        &*m.origin().medium,
        "net",
        "numbered by the medium that heard it"
    );
    // a command says so in its encoding's schema
    other
        .put("fleet/usv9/cmd/stop", r#"{"action": "stop"}"#)
        .encoding(zenoh::bytes::Encoding::from("application/json;command"))
        .await
        .unwrap();
    let c = next(&mut heard).await;
    assert_eq!((c.topic.as_str(), c.kind), ("usv9.cmd.stop", Kind::Command));
    // other bytes are bytes
    other
        .put("fleet/usv9/log", vec![0u8, 159, 146, 150])
        .await
        .unwrap();
    let b = next(&mut heard).await;
    assert_eq!(
        b.payload.as_bytes().unwrap().as_ref(),
        &[0u8, 159, 146, 150]
    );
    // junk that says it is a seabus datagram, and a key that is no topic: counted, nothing else
    other
        .put("fleet/usv9/nav/x", vec![b'S', b'B', 9])
        .encoding(zenoh::bytes::Encoding::APPLICATION_OCTET_STREAM.with_schema("seabus"))
        .await
        .unwrap();
    other.put("fleet/usv9/a b", "x").await.unwrap();
    other.put("fleet/usv9/after", "still here").await.unwrap();
    let after = next(&mut heard).await;
    assert_eq!(
        after.topic.as_str(),
        "usv9.after",
        "the junk delivered nothing"
    );
    let rejected = shore.stats().rejected;
    assert_eq!(rejected.get("bad-key"), Some(&1), "{rejected:?}");
    assert_eq!(rejected.values().sum::<u64>(), 2, "{rejected:?}");
    other.close().await.unwrap();
    shore.close();
}

#[test]
fn urls_say_what_is_wrong() {
    let err = |u: &str| {
        seabus_medium_zenoh::ZenohConfig::from_url(
            &mut seabus_medium::url::MediumUrl::parse(u).unwrap(),
        )
        .unwrap_err()
        .to_string()
    };
    assert!(
        err("zenoh://?mode=hub").contains("option `mode=hub`: expected peer, client or router")
    );
    assert!(err("zenoh://?connect=tcp:1.2.3.4").contains("not a Zenoh endpoint"));
    assert!(err("zenoh://?prefix=fleet/*").contains("option `prefix`"));
    assert!(err("zenoh://host:7447").contains("names no host"));
    assert!(err("zenoh://?mode=client&scout=false").contains("a client needs a router"));
    assert!(err("zenoh://?colour=red").contains("unknown option"));
    assert!(err("zenoh://?ca=ca.pem&cert=a.pem").contains("`cert` and `key` go together"));
    assert!(err("zenoh://?cert=a.pem&key=a.key").contains("TLS needs `ca`"));
    assert!(err("zenoh://?user=auv1").contains("`user` and `password_file` go together"));
}

#[test]
fn a_bad_zenoh_configuration_file_is_placed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zenoh.json5");
    std::fs::write(
        &path,
        "{\n  mode: \"peer\",\n  connect: { endpoints: [\"tcp/1.2.3.4:7447\",] \n  bogus: 3,\n}\n",
    )
    .unwrap();
    let p = path.display().to_string();
    let url = format!("zenoh://?config={p}");
    let err = seabus_medium_zenoh::ZenohConfig::from_url(
        &mut seabus_medium::url::MediumUrl::parse(&url).unwrap(),
    )
    .unwrap()
    .zenoh()
    .unwrap_err();
    assert!(
        err.starts_with(&format!("{p}:3:45: expected array")),
        "{err}"
    );
    assert!(!err.contains(".cargo"), "{err}");
    let missing = seabus_medium_zenoh::ZenohConfig::from_url(
        &mut seabus_medium::url::MediumUrl::parse("zenoh://?config=/nonexistent/z.json5").unwrap(),
    )
    .unwrap()
    .zenoh()
    .unwrap_err();
    assert!(missing.starts_with("/nonexistent/z.json5: "), "{missing}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shore_sees_which_vehicles_are_in_the_fleet_and_which_left() {
    let port = free_port();
    let shore = open(
        "fleet",
        "shore",
        &format!("zenoh://?mode=router&listen=tcp/127.0.0.1:{port}&prefix=fleet&scout=false"),
    );
    let mut fleet = shore.attach("watch").subscribed("seabus.fleet").unwrap();
    let vehicles: Vec<Medium> = (1..=3)
        .map(|i| {
            open(
                "fleet",
                &format!("auv{i}"),
                &format!("zenoh://?mode=client&connect=tcp/127.0.0.1:{port}&prefix=fleet/auv{i}"),
            )
        })
        .collect();
    // every vehicle comes online
    let mut online = std::collections::BTreeSet::new();
    for _ in 0..50 {
        if online.len() == 3 {
            break;
        }
        let m = next(&mut fleet).await;
        let map = m.payload.to_map().unwrap();
        let node = map.get_str("node").unwrap().to_string();
        if map.get_bool("online") == Some(true) && node.starts_with("auv") {
            online.insert(node);
        }
    }
    assert_eq!(online.len(), 3, "{online:?}");
    // one leaves: it is offline within 5 s, the others stay
    let left_at = tokio::time::Instant::now();
    let mut gone = false;
    vehicles[1].close();
    for _ in 0..50 {
        let m = next(&mut fleet).await;
        let map = m.payload.to_map().unwrap();
        if map.get_str("node") == Some("auv2") && map.get_bool("online") == Some(false) {
            gone = true;
            break;
        }
        assert_ne!(
            map.get_bool("online"),
            Some(false),
            "only auv2 leaves: {map:?}"
        );
    }
    assert!(gone, "auv2 is shown offline");
    assert!(
        left_at.elapsed() < Duration::from_secs(5),
        "{:?}",
        left_at.elapsed()
    );
    for v in [&vehicles[0], &vehicles[2]] {
        v.close();
    }
    shore.close();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_started_before_its_router_connects_when_the_router_comes() {
    let port = free_port();
    let vehicle = open(
        "fleet",
        "auv1",
        &format!("zenoh://?mode=client&connect=tcp/127.0.0.1:{port}&prefix=fleet/auv1"),
    );
    tokio::time::sleep(Duration::from_millis(1500)).await;
    assert!(
        matches!(vehicle.link_state(), LinkState::Down(_)),
        "{:?}",
        vehicle.link_state()
    );
    let router = open(
        "fleet",
        "shore",
        &format!("zenoh://?mode=router&listen=tcp/127.0.0.1:{port}&prefix=fleet&scout=false"),
    );
    wait_link(&vehicle, true).await;
    // and when the router goes and comes back, it reconnects by itself
    router.close();
    wait_link(&vehicle, false).await;
    let again = open(
        "fleet",
        "shore",
        &format!("zenoh://?mode=router&listen=tcp/127.0.0.1:{port}&prefix=fleet&scout=false"),
    );
    wait_link(&vehicle, true).await;
    vehicle.close();
    again.close();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_shore_station_that_joins_late_gets_the_current_state_at_once() {
    let port = free_port();
    let vehicle = vehicle_on("fleet", port, "");
    let nav = vehicle.attach("nav");
    // published while nobody listens: an old position, then the current one, and a depth
    let old = DataMap::new().and("lat", 43.0).and("lon", 16.0);
    let now = DataMap::new().and("lat", 43.5081).and("lon", 16.4402);
    nav.send("nav.position", Payload::from(old)).await.unwrap();
    nav.send("nav.position", Payload::from(now.clone()))
        .await
        .unwrap();
    nav.send(
        "nav.depth",
        Payload::from(DataMap::new().and("depth", 12.5)),
    )
    .await
    .unwrap();
    // the shore station starts 10 s after the vehicle
    tokio::time::sleep(Duration::from_secs(10)).await;
    let shore = shore_on("fleet", port);
    let mut heard = shore.attach("console").subscribed("auv1.nav.**").unwrap();
    let joined = tokio::time::Instant::now();
    let mut latest = std::collections::BTreeMap::new();
    while latest.len() < 2 {
        let m = timeout(Duration::from_secs(1), heard.recv())
            .await
            .expect("the current state within 1 s of joining")
            .unwrap();
        latest.insert(m.topic.to_string(), (*m.payload.to_map().unwrap()).clone());
    }
    assert!(
        joined.elapsed() < Duration::from_secs(1),
        "{:?}",
        joined.elapsed()
    );
    assert_eq!(
        latest["auv1.nav.position"], now,
        "the latest value, not the old one"
    );
    assert_eq!(latest["auv1.nav.depth"].get_f64("depth"), Some(12.5));
    assert!(
        timeout(Duration::from_millis(300), heard.recv())
            .await
            .is_err(),
        "nothing older after it"
    );
    assert!(
        shore.stats().missed.is_empty(),
        "{:?}",
        shore.stats().missed
    );
    vehicle.close();
    shore.close();
}

/// A command's statuses sent before the shore first heard their publisher (a vehicle whose link to
/// the router was lost as it took the command, or a console started later): the shore gets each
/// status the publisher keeps, in order, not only the latest: a command's `pending` as well as its
/// outcome.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn command_statuses_sent_before_the_shore_heard_their_publisher_arrive_in_order() {
    let port = free_port();
    let vehicle = vehicle_on("fleet", port, "");
    let oms = vehicle.attach("oms");
    for state in ["pending", "acknowledged"] {
        let status = DataMap::new()
            .and("command", "pub-1/pub#7")
            .and("state", state);
        oms.send("cmd.status", Payload::from(status)).await.unwrap();
    }
    // and a position, of which only the latest is kept
    for lat in [43.0, 43.5] {
        let position = DataMap::new().and("lat", lat).and("lon", 16.4);
        oms.send("nav.position", Payload::from(position))
            .await
            .unwrap();
    }
    let shore = shore_on("fleet", port);
    let mut heard = shore.attach("console").subscribed("auv1.**").unwrap();
    let mut states = Vec::new();
    let mut positions = Vec::new();
    // (each round takes a message or 1 s)
    for _ in 0..10 {
        match timeout(Duration::from_secs(1), heard.recv()).await {
            Ok(Some(m)) => {
                let map = m.payload.to_map().unwrap();
                match m.topic.as_str() {
                    "auv1.cmd.status" => states.push(map.get_str("state").unwrap().to_string()),
                    "auv1.nav.position" => positions.push(map.get_f64("lat").unwrap()),
                    other => panic!("{other}"),
                }
            }
            Ok(None) => panic!("the shore's medium closed"),
            Err(_) if states.len() >= 2 && !positions.is_empty() => break,
            Err(_) => {}
        }
    }
    assert_eq!(states, ["pending", "acknowledged"]);
    assert_eq!(positions, [43.5], "the latest position only");
    assert!(
        shore.stats().missed.is_empty(),
        "{:?}",
        shore.stats().missed
    );
    vehicle.close();
    shore.close();
}

/// Runs openssl in `dir`, failing the test with its output when it fails.
fn openssl(dir: &std::path::Path, args: &[&str]) {
    let out = std::process::Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("openssl runs");
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A certificate authority, certificates it signs for `shore` and `auv1` (valid for 127.0.0.1),
/// and one for `rogue` that signs itself.
fn certificates(dir: &std::path::Path) {
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=fleet-ca",
            "-keyout",
            "ca.key",
            "-out",
            "ca.pem",
        ],
    );
    std::fs::write(
        dir.join("san.cnf"),
        "subjectAltName=IP:127.0.0.1,DNS:localhost\n",
    )
    .unwrap();
    for name in ["shore", "auv1"] {
        let (key, csr, pem) = (
            format!("{name}.key"),
            format!("{name}.csr"),
            format!("{name}.pem"),
        );
        openssl(
            dir,
            &[
                "req",
                "-newkey",
                "rsa:2048",
                "-nodes",
                "-subj",
                &format!("/CN={name}"),
                "-keyout",
                &key,
                "-out",
                &csr,
            ],
        );
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-days",
                "2",
                "-extfile",
                "san.cnf",
                "-out",
                &pem,
            ],
        );
    }
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-subj",
            "/CN=rogue",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
            "-keyout",
            "rogue.key",
            "-out",
            "rogue.pem",
        ],
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_lets_in_the_fleet_and_refuses_a_peer_without_its_certificate() {
    let dir = tempfile::tempdir().unwrap();
    certificates(dir.path());
    let f = |name: &str| dir.path().join(name).display().to_string();
    let port = free_port();
    let shore = open(
        "fleet",
        "shore",
        &format!(
            "zenoh://?mode=router&listen=tls/127.0.0.1:{port}&prefix=fleet&scout=false&ca={}&cert={}&key={}",
            f("ca.pem"),
            f("shore.pem"),
            f("shore.key")
        ),
    );
    let mut heard = shore.attach("watch").subscribed("*.nav.**").unwrap();
    let member = open(
        "fleet",
        "auv1",
        &format!(
            "zenoh://?mode=client&connect=tls/127.0.0.1:{port}&prefix=fleet/auv1&ca={}&cert={}&key={}",
            f("ca.pem"),
            f("auv1.pem"),
            f("auv1.key")
        ),
    );
    let rogue = open(
        "fleet",
        "rogue",
        &format!(
            "zenoh://?mode=client&connect=tls/127.0.0.1:{port}&prefix=fleet/rogue&ca={}&cert={}&key={}",
            f("ca.pem"),
            f("rogue.pem"),
            f("rogue.key")
        ),
    );
    let bare = open(
        "fleet",
        "bare",
        &format!(
            "zenoh://?mode=client&connect=tls/127.0.0.1:{port}&prefix=fleet/bare&ca={}",
            f("ca.pem")
        ),
    );
    wait_link(&member, true).await;
    let depth = DataMap::new().and("depth", 3.5);
    let m = send_until_heard(
        &member.attach("nav"),
        &mut heard,
        Kind::Data,
        "nav.depth",
        &depth,
    )
    .await;
    assert_eq!(m.topic.as_str(), "auv1.nav.depth");
    // the peers the fleet's authority did not sign never get in
    for outsider in [&rogue, &bare] {
        outsider
            .attach("nav")
            .send(
                "nav.depth",
                Payload::from(DataMap::new().and("depth", 99.0)),
            )
            .await
            .ok();
    }
    tokio::time::sleep(Duration::from_secs(3)).await;
    for outsider in [&rogue, &bare] {
        assert!(
            matches!(outsider.link_state(), LinkState::Down(_)),
            "{}: {:?}",
            outsider.node().name,
            outsider.link_state()
        );
    }
    while let Ok(Some(m)) = timeout(Duration::from_millis(200), heard.recv()).await {
        assert!(
            m.topic.as_str().starts_with("auv1."),
            "only the member is heard: {}",
            m.topic
        );
    }
    for m in [member, rogue, bare, shore] {
        m.close();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn users_and_passwords_let_in_who_knows_one() {
    let dir = tempfile::tempdir().unwrap();
    let f = |name: &str| dir.path().join(name).display().to_string();
    std::fs::write(dir.path().join("users.txt"), "auv1:seaweed\nshore:kelp\n").unwrap();
    std::fs::write(dir.path().join("auv1.pw"), "seaweed\n").unwrap();
    std::fs::write(dir.path().join("wrong.pw"), "plankton\n").unwrap();
    std::fs::write(dir.path().join("shore.pw"), "kelp\n").unwrap();
    let port = free_port();
    let shore = open(
        "fleet",
        "shore",
        &format!(
            "zenoh://?mode=router&listen=tcp/127.0.0.1:{port}&prefix=fleet&scout=false&users={}&user=shore&password_file={}",
            f("users.txt"),
            f("shore.pw")
        ),
    );
    let member = open(
        "fleet",
        "auv1",
        &format!(
            "zenoh://?mode=client&connect=tcp/127.0.0.1:{port}&prefix=fleet/auv1&user=auv1&password_file={}",
            f("auv1.pw")
        ),
    );
    let intruder = open(
        "fleet",
        "auv9",
        &format!(
            "zenoh://?mode=client&connect=tcp/127.0.0.1:{port}&prefix=fleet/auv9&user=auv1&password_file={}",
            f("wrong.pw")
        ),
    );
    wait_link(&member, true).await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert!(
        matches!(intruder.link_state(), LinkState::Down(_)),
        "{:?}",
        intruder.link_state()
    );
    for m in [member, intruder, shore] {
        m.close();
    }
}

/// A vehicle's bus bridged to Zenoh by `routes`, running as `seabus run` runs it.
async fn vehicle_system(port: u16, routes: &str) -> seabus_modules::Runtime {
    let text = format!(
        r#"<seabus node="auv1">
  <medium name="bus" url="inproc://"/>
  <medium name="fleet" url="zenoh://?listen=tcp/127.0.0.1:{port}&amp;prefix=fleet/auv1&amp;scout=false"/>
  <bridge name="shore" media="bus fleet" report="0">
{routes}
  </bridge>
</seabus>"#
    );
    let spec = seabus_modules::SystemSpec::parse("auv1.xml", &text).unwrap();
    let mut registry = seabus_modules::Registry::new();
    registry.set_schemes(seabus_medium_zenoh::schemes());
    seabus_bridges::register(&mut registry);
    seabus_modules::Runtime::start(&spec, &registry, seabus_modules::Catalogue::built_in())
        .await
        .unwrap_or_else(|e| panic!("{e}"))
}

/// A bare Zenoh session connected to `port` on loopback.
async fn bare_session(port: u16) -> zenoh::Session {
    let mut cfg = zenoh::Config::default();
    cfg.insert_json5("connect/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))
        .unwrap();
    cfg.insert_json5("listen/endpoints", "[\"tcp/127.0.0.1:0\"]")
        .unwrap();
    cfg.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    zenoh::open(cfg).await.unwrap()
}

/// What a bridge route's `priority`, `congestion` and `express` become on the wire, read by a
/// program that is not seabus from each sample: each attribute a route sets replaces its kind's,
/// the others stay, and a route without any sends with its kind's (command statuses with a
/// command's).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_routes_quality_of_service_reaches_the_wire_attribute_by_attribute() {
    use zenoh::qos::{CongestionControl, Priority};
    let port = free_port();
    let rt = vehicle_system(
        port,
        r#"    <route from="bus" to="fleet" topics="nav.**" priority="data-high" congestion="block" express="true"/>
    <route from="bus" to="fleet" topics="sensors.*" rename="sensors.raw.*" express="true"/>
    <route from="bus" to="fleet" topics="cmd.**" kind="command" priority="realtime"/>
    <route from="bus" to="fleet" topics="**"/>"#,
    )
    .await;
    let bus = rt.medium("bus").unwrap().attach("vehicle");
    let other = bare_session(port).await;
    let heard = other.declare_subscriber("fleet/auv1/**").await.unwrap();
    let expected = std::collections::BTreeMap::from([
        (
            "fleet/auv1/nav/depth",
            (Priority::DataHigh, CongestionControl::Block, true),
        ),
        (
            "fleet/auv1/sensors/raw/temp",
            (Priority::Data, CongestionControl::Drop, true),
        ),
        (
            "fleet/auv1/cmd/course",
            (Priority::RealTime, CongestionControl::Block, true),
        ),
        (
            "fleet/auv1/env/wind",
            (Priority::Data, CongestionControl::Drop, false),
        ),
        // what became of a command is data that goes as a command does
        (
            "fleet/auv1/cmd/status",
            (Priority::InteractiveHigh, CongestionControl::Block, true),
        ),
    ]);
    let mut seen = std::collections::BTreeMap::new();
    let map = DataMap::new().and("x", 1.0);
    // until the bare session's subscription has reached the vehicle, send again
    for _ in 0..100 {
        if seen.len() == expected.len() {
            break;
        }
        for topic in ["nav.depth", "sensors.temp", "env.wind", "cmd.status"] {
            bus.send(topic, Payload::from(map.clone())).await.unwrap();
        }
        bus.command("cmd.course", Payload::from(map.clone()))
            .await
            .unwrap();
        // what came of it (and what the system publishes besides, every second at most)
        for _ in 0..20 {
            let Ok(Ok(s)) = timeout(Duration::from_millis(100), heard.recv_async()).await else {
                break;
            };
            let key = s.key_expr().as_str().to_string();
            if expected.contains_key(key.as_str()) {
                seen.insert(key, (s.priority(), s.congestion_control(), s.express()));
            }
        }
    }
    let seen: std::collections::BTreeMap<&str, _> =
        seen.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    assert_eq!(seen, expected);
    other.close().await.unwrap();
    rt.shutdown().await;
}

/// A quality of service declared for topics already being published takes effect from the next
/// message, and of two declarations matching a topic the first counts.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_quality_of_service_declared_later_applies_from_the_next_message() {
    use seabus_medium::qos::{Priority, Qos};
    let port = free_port();
    let vehicle = vehicle_on("fleet", port, "");
    let other = bare_session(port).await;
    let heard = other.declare_subscriber("fleet/auv1/late/x").await.unwrap();
    let nav = vehicle.attach("nav");
    let text = |t: &str| Payload::from(t.as_bytes().to_vec());
    let carries = |s: &zenoh::sample::Sample, t: &str| {
        let bytes = s.payload().to_bytes();
        bytes.windows(t.len()).any(|w| w == t.as_bytes())
    };
    // until the bare session's subscription has reached the vehicle, send again
    let mut reached = false;
    for _ in 0..100 {
        nav.send("late.x", text("before")).await.unwrap();
        if let Ok(Ok(s)) = timeout(Duration::from_millis(100), heard.recv_async()).await {
            assert_eq!(s.priority(), zenoh::qos::Priority::Data, "data's own");
            reached = true;
            break;
        }
    }
    assert!(reached, "the bare session hears the vehicle");
    let at = |p| Qos {
        priority: Some(p),
        ..Qos::default()
    };
    let late = seabus_medium::Pattern::new("late.**").unwrap();
    let x = seabus_medium::Pattern::new("late.x").unwrap();
    assert!(vehicle.set_qos(&late, None, at(Priority::Background)));
    assert!(vehicle.set_qos(&x, None, at(Priority::Realtime)));
    nav.send("late.x", text("after")).await.unwrap();
    let mut after = None;
    for _ in 0..100 {
        let s = timeout(WAIT, heard.recv_async())
            .await
            .expect("a sample")
            .unwrap();
        if carries(&s, "after") {
            after = Some(s);
            break;
        }
        assert_eq!(s.priority(), zenoh::qos::Priority::Data, "sent before");
    }
    let after = after.expect("the message sent after the declarations");
    assert_eq!(after.priority(), zenoh::qos::Priority::Background);
    // a medium without priorities says so
    let bus = Medium::in_process("bus", &Node::new("auv1"));
    assert!(!bus.set_qos(&late, None, at(Priority::Background)));
    other.close().await.unwrap();
    vehicle.close();
}

/// Every `<<miss:NNNN>>` marker in a datagram.
fn markers(datagram: &[u8]) -> Vec<u32> {
    const TAG: &[u8] = b"<<miss:";
    let mut found = Vec::new();
    let mut rest = datagram;
    while let Some(at) = rest.windows(TAG.len()).position(|w| w == TAG) {
        rest = &rest[at + TAG.len()..];
        if let Some(n) = rest
            .get(..4)
            .and_then(|d| std::str::from_utf8(d).ok())
            .and_then(|d| d.parse().ok())
        {
            found.push(n);
        }
    }
    found
}

/// A UDP relay on loopback between a Zenoh peer that listens (on `listener`) and one that
/// connects to the relay's port instead: datagrams go both ways as they are, except that from
/// the listener to the other peer the first datagram carrying each marker of `chosen` is dropped.
struct Relay {
    port: u16,
    /// the markers of the datagrams dropped
    dropped: Arc<Mutex<std::collections::BTreeSet<u32>>>,
    task: tokio::task::JoinHandle<()>,
}

impl Relay {
    async fn start(listener: u16, chosen: std::collections::BTreeSet<u32>) -> Relay {
        use tokio::net::UdpSocket;
        let front = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let back = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        back.connect(("127.0.0.1", listener)).await.unwrap();
        let port = front.local_addr().unwrap().port();
        let dropped = Arc::new(Mutex::new(std::collections::BTreeSet::new()));
        let gone = dropped.clone();
        let task = tokio::spawn(async move {
            let (mut up, mut down) = (vec![0u8; 65_536], vec![0u8; 65_536]);
            let mut peer = None;
            loop {
                tokio::select! {
                    got = front.recv_from(&mut up) => {
                        if let Ok((n, from)) = got {
                            peer = Some(from);
                            let _ = back.send(&up[..n]).await;
                        }
                    }
                    got = back.recv(&mut down) => {
                        let (Ok(n), Some(to)) = (got, peer) else { continue };
                        let carried = markers(&down[..n]);
                        {
                            let mut gone = gone.lock().unwrap();
                            if carried.iter().any(|m| chosen.contains(m) && !gone.contains(m)) {
                                gone.extend(carried);
                                continue;
                            }
                        }
                        let _ = front.send_to(&down[..n], to).await;
                    }
                }
            }
        });
        Relay {
            port,
            dropped,
            task,
        }
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Two seabus nodes joined by a Zenoh `udp/` link (unreliable) through a relay that drops every
/// fourth message of a burst on its way to the shore: the shore counts each message that never
/// came under its topic, and what arrived plus what is counted missed is what was sent. (The
/// publisher keeps only its latest sample, so a dropped message comes back only if it was the
/// latest when the shore asked for it.)
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn messages_lost_on_an_unreliable_link_are_counted_missed_by_topic() {
    const BURST: u32 = 60;
    const TOPIC: &str = "auv1.test.burst";
    let Lossy {
        vehicle,
        shore,
        relay,
        chosen,
        mut heard,
        tx: _tx,
    } = Lossy::burst("test.burst", BURST).await;
    // what arrives, until every message of the burst has arrived or been counted missed
    let mut arrived = std::collections::BTreeSet::new();
    let missed = |m: &Medium| m.stats().missed.get(TOPIC).copied().unwrap_or(0);
    // (each round takes a message or 100 ms: at most 30 s of waiting)
    for _ in 0..BURST + 300 {
        if arrived.len() as u64 + missed(&shore) >= u64::from(BURST) {
            break;
        }
        if let Ok(Some(m)) = timeout(Duration::from_millis(100), heard.recv()).await {
            let bytes = m.payload.as_bytes().expect("bytes").clone();
            arrived.extend(markers(&bytes));
        }
    }
    let dropped = relay.dropped.lock().unwrap().clone();
    let stats = shore.stats();
    let counted = missed(&shore);
    assert!(
        dropped.is_superset(&chosen),
        "the relay dropped each chosen message: {dropped:?}"
    );
    assert_eq!(
        arrived.len() as u64 + counted,
        u64::from(BURST),
        "arrived {arrived:?}, missed {counted}"
    );
    // each message dropped on the way and never sent again is counted, and nothing else is
    let lost = dropped.difference(&arrived).count() as u64;
    assert_eq!(counted, lost, "dropped {dropped:?}, arrived {arrived:?}");
    assert!(counted > 0, "the publisher keeps only its latest sample");
    assert_eq!(
        stats.missed.keys().collect::<Vec<_>>(),
        [TOPIC],
        "counted under the topic"
    );
    // as `seabus.media` and `seabus spy --stats` show it
    let shown = stats.to_map();
    let by_topic = shown.get("missed").and_then(Value::as_map).unwrap();
    assert_eq!(by_topic.get_i64(TOPIC), Some(counted as i64));
    assert!(stats.has_losses());
    vehicle.close();
    shore.close();
}

/// Two seabus nodes, a vehicle (`auv1`) and the shore, joined by a Zenoh `udp/` link through a
/// [`Relay`] that drops `chosen` on the way to the shore, after a burst on one of the vehicle's
/// topics; the shore's interface `heard` subscribed to it, the vehicle's `tx` that sent it.
struct Lossy {
    vehicle: Medium,
    shore: Medium,
    relay: Relay,
    /// The burst's messages the relay drops: every fourth, none of the last few (so that the
    /// burst ends with one that arrives).
    chosen: std::collections::BTreeSet<u32>,
    heard: seabus_medium::Interface,
    tx: seabus_medium::Interface,
}

impl Lossy {
    /// The link made and heard (bytes with a marker sent on `topic` until one arrives), then a
    /// burst of `burst` messages on it, paced as a sensor would send them.
    async fn burst(topic: &str, burst: u32) -> Lossy {
        let chosen: std::collections::BTreeSet<u32> =
            (0..burst - 4).filter(|i| i % 4 == 3).collect();
        let listener = free_udp_port();
        let vehicle = open(
            "fleet",
            "auv1",
            &format!("zenoh://?listen=udp/127.0.0.1:{listener}&prefix=fleet/auv1&scout=false"),
        );
        let relay = Relay::start(listener, chosen.clone()).await;
        let shore = open(
            "fleet",
            "shore",
            &format!(
                "zenoh://?connect=udp/127.0.0.1:{}&listen=tcp/127.0.0.1:0&prefix=fleet&scout=false",
                relay.port
            ),
        );
        wait_link(&vehicle, true).await;
        wait_link(&shore, true).await;
        let mut heard = shore
            .attach("watch")
            .subscribed(&format!("auv1.{topic}"))
            .unwrap();
        let tx = vehicle.attach("gen");
        // the shore's subscription reaches the vehicle, which then publishes to it
        let mut reached = false;
        for warm in 0..100 {
            let text = format!("<<warm:{warm:04}>>");
            tx.send(topic, Payload::from(text.into_bytes()))
                .await
                .unwrap();
            if let Ok(Some(_)) = timeout(Duration::from_millis(100), heard.recv()).await {
                reached = true;
                break;
            }
        }
        assert!(reached, "the shore hears the vehicle");
        assert_eq!(
            shore.stats().missed,
            Default::default(),
            "nothing missed yet"
        );
        for i in 0..burst {
            let text = format!("<<miss:{i:04}>>");
            tx.send(topic, Payload::from(text.into_bytes()))
                .await
                .unwrap();
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        Lossy {
            vehicle,
            shore,
            relay,
            chosen,
            heard,
            tx,
        }
    }
}

/// Command statuses over the same lossy link: the publisher keeps its last ones, so every status
/// a relay dropped comes back, in order, and none is counted missed (a console sees a command's
/// `pending` as well as its outcome).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn command_statuses_lost_on_an_unreliable_link_come_back_in_order() {
    const BURST: u32 = 24;
    let Lossy {
        vehicle,
        shore,
        relay,
        chosen,
        mut heard,
        tx: _tx,
    } = Lossy::burst("cmd.status", BURST).await;
    let mut arrived = Vec::new();
    // (each round takes a message or 100 ms: at most 30 s of waiting)
    for _ in 0..BURST + 300 {
        if arrived.len() >= BURST as usize {
            break;
        }
        if let Ok(Some(m)) = timeout(Duration::from_millis(100), heard.recv()).await {
            arrived.extend(markers(m.payload.as_bytes().expect("bytes")));
        }
    }
    let dropped = relay.dropped.lock().unwrap().clone();
    assert!(
        dropped.is_superset(&chosen),
        "the relay dropped each chosen status: {dropped:?}"
    );
    assert_eq!(
        arrived,
        (0..BURST).collect::<Vec<_>>(),
        "dropped {dropped:?}"
    );
    assert_eq!(shore.stats().missed, Default::default());
    vehicle.close();
    shore.close();
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}
