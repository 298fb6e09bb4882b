//! `seabus pub` says every payload: a JSON payload (nested maps, lists, bytes, NaN and ±inf) made
//! into an LCM message that a C program of lcm-gen types reads with the exact values; an LCM type's
//! fields checked (a typo or a field left out is refused, naming the type's fields); bytes in hex
//! and base64 forms, and raw frames on a CAN bus, with the medium's refusal said and exit 3.

mod common;
use common::*;
use std::net::UdpSocket;
use std::process::Output;
use std::time::Duration;

fn pub_(args: &[&str]) -> Output {
    seabus()
        .arg("pub")
        .args(args)
        .output()
        .expect("seabus runs")
}

/// A nested message with arrays of structs and numbers, NaN and ±inf, and bytes.
const SURVEY: &str = r#"{
  "utime": 42,
  "name": "dive 7",
  "readings": [
    {"utime": 1, "valid": true, "label": "a", "depth": 1.25},
    {"utime": 2, "valid": false, "label": "b", "depth": {"float": "NaN"}}
  ],
  "depths": [0.5, {"float": "inf"}, {"float": "-inf"}],
  "gains": [[1.5, {"float": "NaN"}], [-2.0, 0.25]],
  "blob": {"base64": "AQIDBA=="}
}"#;

const SURVEY_SEEN: &str = "utime=42 name=646976652037 n=2 \
    readings[0]={utime=1 valid=1 label=61 depth=3ff4000000000000(1.25)} \
    readings[1]={utime=2 valid=0 label=62 depth=7ff8000000000000(nan)} \
    depths[0]=3fe0000000000000(0.5) depths[1]=7ff0000000000000(inf) \
    depths[2]=fff0000000000000(-inf) gains[0][0]=3fc00000(1.5) gains[0][1]=7fc00000(nan) \
    gains[1][0]=c0000000(-2) gains[1][1]=3e800000(0.25) blob=01020304";

#[test]
fn pub_json_of_a_nested_lcm_type_reaches_a_c_subscriber_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let peer = lcm_c_peer(dir.path());
    let types = dir.path().join("lcm_peer.lcm");
    let url = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let file = dir.path().join("survey.json");
    std::fs::write(&file, SURVEY).unwrap();
    let (c, lines) = lcm_c_receiver(&peer, "surveys", &url, "SURVEY", 2, 10);
    let lcm = [
        "--lcm",
        "peer.survey_t",
        "--lcm-types",
        types.to_str().unwrap(),
    ];
    for source in [
        vec!["--json", SURVEY],
        vec!["--json-file", file.to_str().unwrap()],
    ] {
        let out = pub_(&[&[url.as_str(), "SURVEY"][..], &lcm, &source].concat());
        assert!(out.status.success(), "{source:?}: {}", stderr(&out));
    }
    let got = lcm_c_lines(c, lines, Duration::from_secs(10));
    assert_eq!(got, [SURVEY_SEEN, SURVEY_SEEN]);
}

#[test]
fn pub_lcm_refuses_unknown_and_missing_fields_unless_told() {
    let dir = tempfile::tempdir().unwrap();
    let peer = lcm_c_peer(dir.path());
    let types = dir.path().join("lcm_peer.lcm");
    let url = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let (c, lines) = lcm_c_receiver(&peer, "readings", &url, "READING", 1, 10);
    let reading = [
        "--lcm",
        "peer.reading_t",
        "--lcm-types",
        types.to_str().unwrap(),
    ];
    let refused = |fields: &[&str], why: &str| {
        let out = pub_(&[&[url.as_str(), "READING"][..], &reading, fields].concat());
        assert_eq!(out.status.code(), Some(2), "{fields:?}");
        assert_eq!(
            stderr(&out).trim(),
            format!("seabus pub: --lcm peer.reading_t: {why}")
        );
    };
    refused(
        &["valid=true", "label=x", "depht=3.5"],
        "no field `depht`: peer.reading_t has utime, valid, label, depth",
    );
    refused(
        &["valid=true", "label=x"],
        "field `depth` missing (--allow-missing sends defaults): peer.reading_t has utime, valid, \
         label, depth",
    );
    // the same message with --allow-missing: the depth is NaN, as LCM programs read unknown
    let out = pub_(
        &[
            &[url.as_str(), "READING", "utime=9", "valid=true", "label=x"][..],
            &reading,
            &["--allow-missing"],
        ]
        .concat(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let got = lcm_c_lines(c, lines, Duration::from_secs(10));
    assert_eq!(
        got,
        ["utime=9 valid=1 label=78 depth=7ff8000000000000(nan)"]
    );
}

/// What a cannelloni peer receives: the frames of one packet as (id, data).
fn frames(peer: &UdpSocket) -> Vec<(u32, Vec<u8>)> {
    let mut buf = [0u8; 1500];
    let (n, _) = peer
        .recv_from(&mut buf)
        .expect("a cannelloni packet within 5 s");
    let p = &buf[..n];
    // version, op code, sequence number, frame count (big-endian), then the frames
    assert_eq!(p[0], 2, "cannelloni version 2: {p:02x?}");
    let count = u16::from_be_bytes([p[3], p[4]]);
    let mut at = 5;
    let mut out = Vec::new();
    for _ in 0..count {
        let id = u32::from_be_bytes(p[at..at + 4].try_into().unwrap());
        let len = usize::from(p[at + 4] & 0x7f);
        out.push((id, p[at + 5..at + 5 + len].to_vec()));
        at += 5 + len;
    }
    out
}

#[test]
fn pub_sends_bytes_and_raw_can_frames_and_says_when_the_medium_refuses() {
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    peer.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let url = format!(
        "cannelloni://127.0.0.1:{}?bind=127.0.0.1:0",
        peer.local_addr().unwrap().port()
    );
    for args in [
        vec!["can.123", "data=hex:0102aB"],
        vec!["can.123", "data=base64:AQKr"],
        vec!["can.123", "--raw", "hex:0102ab"],
        vec!["can.123", "--raw", "base64:AQKr"],
    ] {
        let out = pub_(&[&[url.as_str()][..], &args].concat());
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        assert_eq!(frames(&peer), [(0x123, vec![1, 2, 0xab])], "{args:?}");
    }
    // what the medium refuses: exit 3, with its reason
    for (args, why) in [
        (
            vec!["can.123", "--raw", "hex:010203040506070809"],
            "seabus pub: not sent: medium `pub`: topic `can.123`: 9 data bytes: a CAN FD frame \
             carries 0–8, 12, 16, 20, 24, 32, 48 or 64",
        ),
        (
            vec!["can.123", "depth=3"],
            "seabus pub: not sent: medium `pub`: topic `can.123`: `depth` is not a CAN frame's \
             field (data, ext, rtr, dlc, fd, brs, esi, error, time_ms); send the frame's data as \
             `data` bytes",
        ),
    ] {
        let out = pub_(&[&[url.as_str()][..], &args].concat());
        assert_eq!(out.status.code(), Some(3), "{args:?}");
        assert_eq!(stderr(&out).trim(), why);
    }
    // bytes written wrong: exit 2, saying how they are written
    let out = pub_(&[url.as_str(), "can.123", "--raw", "0102"]);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        stderr(&out).trim(),
        "seabus pub: --raw `0102`: bytes are written hex:0102 or base64:AQI="
    );
    let out = pub_(&[url.as_str(), "can.123", "data=hex:012"]);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        stderr(&out).trim(),
        "seabus pub: `data`: `hex:012`: hex bytes are two digits each, 3 digits given"
    );
}
