//! `seabus pub` and `seabus spy` against each other on a loopback multicast group: typed fields,
//! counts, commands, formats, and the table view.

mod common;
use common::*;
use std::time::Duration;

#[test]
fn published_fields_arrive_typed_and_counted() {
    let url = format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port());
    let spy = spawn_spy(&url, &["--for", "2.5", "--json"]);
    std::thread::sleep(Duration::from_millis(400));
    let out = seabus()
        .args([
            "pub",
            &url,
            "cmd.course",
            "heading=90",
            "depth=2.5",
            "speed=1",
            "label=\"7\"",
            "armed=true",
        ])
        .args(["--count", "3", "--rate", "20", "--command"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = seabus()
        .args(["pub", &url, "doc.xml", "a=1", "--format", "xml"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let spy = spy.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&spy.stdout);
    // keys in the documented order, the datamap's entries in the order they were given
    let first = text
        .lines()
        .find(|l| l.contains("cmd.course"))
        .expect("a course line");
    assert!(
        first.starts_with("{\"topic\":\"cmd.course\",\"kind\":\"command\",\"origin\":"),
        "{first}"
    );
    assert!(
        first.ends_with(r#""format":"map","payload":{"heading":90,"depth":2.5,"speed":1,"label":"7","armed":true}}"#),
        "{first}"
    );
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let courses: Vec<_> = lines
        .iter()
        .filter(|m| m["topic"] == "cmd.course")
        .collect();
    assert_eq!(courses.len(), 3);
    let p = &courses[0]["payload"];
    assert_eq!(
        (
            p["heading"].as_i64(),
            p["depth"].as_f64(),
            p["armed"].as_bool()
        ),
        (Some(90), Some(2.5), Some(true))
    );
    assert_eq!(p["label"], "7");
    assert_eq!(courses[0]["kind"], "command");
    let seqs: Vec<u64> = courses.iter().map(|m| m["seq"].as_u64().unwrap()).collect();
    assert_eq!(seqs, [1, 2, 3]);
    let doc = lines
        .iter()
        .find(|m| m["topic"] == "doc.xml")
        .expect("the XML message");
    assert_eq!(doc["format"], "xml");
    assert_eq!(doc["payload"], "<datamap><int name=\"a\">1</int></datamap>");
}

#[test]
fn the_table_lists_topics_with_counts_and_origins() {
    let url = format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port());
    let spy = spawn_spy(&url, &["--for", "2.5"]);
    std::thread::sleep(Duration::from_millis(400));
    let out = seabus()
        .args([
            "pub",
            &url,
            "nav.depth",
            "depth=4",
            "--count",
            "5",
            "--rate",
            "50",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let spy = spy.wait_with_output().unwrap();
    let table = String::from_utf8_lossy(&spy.stdout);
    let row = table
        .lines()
        .find(|l| l.starts_with("nav.depth"))
        .unwrap_or_else(|| panic!("no row in {table}"));
    let cols: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(cols[1], "5", "{row}");
    assert!(
        cols[3].starts_with("pub-") && cols[3].ends_with("/pub"),
        "{row}"
    );
    assert!(row.ends_with("depth=4"), "{row}");
}

#[test]
fn bad_arguments_are_refused_with_a_reason() {
    for (args, reason) in [
        (vec!["pub", "udp://239.255.1.1", "t", "a=1"], "needs a port"),
        (
            vec!["pub", "udp://239.255.1.1:5", "bad..topic", "a=1"],
            "empty segment",
        ),
        (
            vec!["pub", "udp://239.255.1.1:5", "t", "novalue"],
            "is not key=value",
        ),
        (
            vec!["pub", "udp://239.255.1.1:5", "t", "--format", "json"],
            "is not a format",
        ),
        (
            vec!["spy", "tcp://x:1", "--for", "0.1"],
            "unknown medium scheme",
        ),
    ] {
        let out = seabus().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(reason), "{args:?}: {err}");
    }
}

#[test]
fn a_burst_from_pub_arrives_whole_and_in_order_before_pub_ends() {
    // sent as fast as pub can, as a stream however slow this build (a gap of a second): the
    // datagrams go out in batches, and the last of them before pub exits
    let rx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let _ = socket2::SockRef::from(&rx).set_recv_buffer_size(4 << 20);
    let port = rx.local_addr().unwrap().port();
    let n = 500;
    succeeds(
        seabus()
            .args(["pub", &format!("udp://127.0.0.1:{port}?send_gap=1s")])
            .args([
                "burst",
                "x=1",
                "--count",
                &n.to_string(),
                "--rate",
                "1000000",
            ]),
        "seabus pub",
    );
    rx.set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    let mut origins = seabus_medium::datagram::Origins::default();
    let mut seqs = Vec::new();
    let mut buf = vec![0u8; 65536];
    while let Ok(len) = rx.recv(&mut buf) {
        let d = bytes::Bytes::copy_from_slice(&buf[..len]);
        let (_, msg) = seabus_medium::datagram::decode(&d, &mut origins).unwrap();
        assert_eq!(msg.topic.as_str(), "burst");
        seqs.push(msg.provenance.seq);
        assert!(seqs.len() <= n, "more than sent");
    }
    assert_eq!(seqs, (1..=n as u64).collect::<Vec<_>>());
}
