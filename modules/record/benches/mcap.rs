//! MCAP recording: seabus's writer (`seabus_record::Writer`: a channel and schema per topic, a
//! datamap encoded to JSON, zstd chunks) against the `mcap` crate used directly for the same
//! messages (one channel; a byte payload written as it is, a datamap encoded with `serde_json` into
//! one reused buffer, as a program using the crate would; the same options), through a file in the
//! page cache, in one run; and the size of one session as an MCAP file against the LCM event log of
//! the same messages. Goal: seabus's writing rate at least 0.8× the crate's for every message (64 B
//! and 4 kB, bytes and datamaps); the smoke run (`SEABUS_BENCH_SMOKE=1`) writes half as many.
//!
//! Run: `cargo bench -p seabus-record --bench mcap`

use seabus_bench::{Goals, scale};
use seabus_medium::{DataMap, Kind, Message, Origin, Payload, Provenance, Stamp, Topic, Value};
use seabus_modules::Catalogue;
use seabus_record::log::{Kind as LogKind, Writer as LogWriter};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::time::Instant;

/// Best of five runs each of `a` and `b`, taken in turn (so that a slow spell of the machine falls
/// on both), in seconds.
fn best_in_turn(mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64) {
    let time = |f: &mut dyn FnMut()| {
        let start = Instant::now();
        f();
        start.elapsed().as_secs_f64()
    };
    (0..5).fold((f64::INFINITY, f64::INFINITY), |(ta, tb), _| {
        (ta.min(time(&mut a)), tb.min(time(&mut b)))
    })
}

fn message(topic: &Topic, payload: Payload, i: u64) -> Message {
    Message {
        topic: topic.clone(),
        kind: Kind::Data,
        provenance: Provenance {
            origin: Origin::new("bench", "bus", 1),
            seq: i + 1,
            hops: 0,
        },
        stamp: Stamp(1_700_000_000_000_000_000 + i as i64 * 10_000_000),
        payload,
    }
}

/// An attitude whose JSON is about 64 bytes.
fn attitude(i: u64) -> DataMap {
    let f = i as f64;
    DataMap::new()
        .with("yaw", ((f * 0.37) % 360.0 * 100.0).round() / 100.0)
        .with("pitch", ((f * 0.011) % 10.0 * 100.0).round() / 100.0)
        .with("roll", (-(f * 0.013) % 10.0 * 100.0).round() / 100.0)
        .with("yaw_rate", 0.25)
        .with("quality", 3i64)
}

/// A datamap whose JSON is about 4 kB: a sonar-like list of ranges.
fn ranges(i: u64) -> DataMap {
    let list: Vec<Value> = (0..660)
        .map(|k| Value::Float(((i + k) % 997) as f64 * 0.125))
        .collect();
    DataMap::new()
        .with("beam", i as i64)
        .with("ranges", Value::List(list))
}

/// The bare `mcap` crate writing `messages` on one channel, as the seabus writer is set up.
fn bare(path: &std::path::Path, messages: &[Message]) {
    let encoding = match messages[0].payload {
        Payload::Map(_) => "json",
        _ => "application/octet-stream",
    };
    let out = BufWriter::with_capacity(1 << 16, File::create(path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .create(out)
        .unwrap();
    let schema = if encoding == "json" {
        w.add_schema("bench", "jsonschema", b"{\"type\":\"object\"}")
            .unwrap()
    } else {
        0
    };
    let channel = w
        .add_channel(schema, "bench", encoding, &BTreeMap::new())
        .unwrap();
    let mut buffer = Vec::new();
    for (i, m) in messages.iter().enumerate() {
        let d: &[u8] = match &m.payload {
            Payload::Map(map) => {
                buffer.clear();
                serde_json::to_writer(&mut buffer, &**map).unwrap();
                &buffer
            }
            Payload::Bytes(b) => b,
            Payload::Xml(_) => unreachable!("no XML here"),
        };
        let t = 1_700_000_000_000_000_000 + i as u64 * 10_000_000;
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: t,
                publish_time: t,
            },
            d,
        )
        .unwrap();
    }
    w.finish().unwrap();
}

/// A case: its name, how many messages, and the payload of message `i`.
type Case = (&'static str, u64, fn(u64) -> Payload);

fn seabus(path: &std::path::Path, messages: &[Message]) {
    let mut w = seabus_record::Writer::create(path, true, Catalogue::built_in()).unwrap();
    for m in messages {
        w.write(m, m.stamp).unwrap();
    }
    w.finish().unwrap();
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.mcap");
    let topic = Topic::new("nav.attitude").unwrap();
    println!(
        "MCAP writing through a file (best of 5, taken in turn), seabus against the mcap crate directly:"
    );
    let (many, few) = (scale(200_000, 100_000), scale(20_000, 10_000));
    let cases: [Case; 4] = [
        ("bytes 64 B", many, |i| {
            Payload::from(vec![(i % 251) as u8; 64])
        }),
        ("bytes 4 kB", few, |i| {
            Payload::from(vec![(i % 251) as u8; 4096])
        }),
        ("datamap ~64 B JSON", many, |i| Payload::from(attitude(i))),
        ("datamap ~4 kB JSON", few, |i| Payload::from(ranges(i))),
    ];
    let mut goals = Goals::new();
    for (name, n, make) in cases {
        let messages: Vec<Message> = (0..n).map(|i| message(&topic, make(i), i)).collect();
        let size = match &messages[0].payload {
            Payload::Map(m) => serde_json::to_vec(&**m).unwrap().len(),
            Payload::Bytes(b) => b.len(),
            Payload::Xml(x) => x.len(),
        };
        let (ours, theirs) = best_in_turn(|| seabus(&path, &messages), || bare(&path, &messages));
        println!(
            "  {name:<20} ({size:>4} B): seabus {:>10.0} msg/s, mcap crate {:>10.0} msg/s",
            n as f64 / ours,
            n as f64 / theirs,
        );
        goals.at_least(
            &format!("MCAP write {name}, seabus / mcap crate"),
            theirs / ours,
            0.8,
        );
    }

    // one session: 60 s of a 10 Hz attitude, depth and position, as MCAP and as an LCM event log
    let session: Vec<Message> = (0..600u64)
        .flat_map(|i| {
            let depth = DataMap::new().with("depth", 10.0 + (i as f64 * 0.01).sin());
            let position = DataMap::new()
                .with("lat", 43.5 + i as f64 * 1e-6)
                .with("lon", 16.4 + i as f64 * 1e-6)
                .with("source", "gnss");
            [
                message(
                    &Topic::new("nav.attitude").unwrap(),
                    Payload::from(attitude(i)),
                    i,
                ),
                message(&Topic::new("nav.depth").unwrap(), Payload::from(depth), i),
                message(
                    &Topic::new("nav.position").unwrap(),
                    Payload::from(position),
                    i,
                ),
            ]
        })
        .collect();
    let mut sizes = Vec::new();
    for (kind, name) in [
        (LogKind::Mcap, "session.mcap"),
        (LogKind::Lcm, "session.lcm"),
    ] {
        let p = dir.path().join(name);
        let mut w = LogWriter::create(&p, kind, true, Catalogue::built_in()).unwrap();
        for m in &session {
            w.write(m, m.stamp).unwrap();
        }
        w.finish().unwrap();
        sizes.push(std::fs::metadata(&p).unwrap().len());
    }
    println!(
        "  one minute of attitude, depth and position at 10 Hz ({} messages): MCAP {} B, LCM event \
         log {} B, ratio {:.2}",
        session.len(),
        sizes[0],
        sizes[1],
        sizes[0] as f64 / sizes[1] as f64
    );
    goals.finish();
}
