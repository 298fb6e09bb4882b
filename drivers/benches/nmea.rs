//! NMEA throughput and latency.
//!
//! 1. Sentences per second through seabus's whole path — framing a byte stream, the checksum, the
//!    serial medium's topic, parsing, and the GPS/heading drivers' conversion to datasets — against
//!    bare `nmea::parse_str` on the same sentences (already cut into strings). Target: at least 0.8×.
//! 2. Serial → bus latency over a pseudo-terminal: a sentence written on the far end of a pty, until
//!    it is taken from an interface on the serial medium; p50 and p99 at 200 sentences per second.
//!
//! Run: `cargo bench -p seabus-drivers --bench nmea`

use seabus_drivers::nmea::sensors::{Role, Sensor};
use seabus_drivers::nmea::sentence::{build, parse};
use seabus_medium::framing::{ChecksumPolicy, Framer, Framing, nmea_sentence};
use seabus_medium::url::MediumUrl;
use seabus_medium::{Node, Payload};
use seabus_medium_serial::{FrameTopics, SerialConfig};
use seabus_modules::{Catalogue, Params};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn sentences() -> Vec<String> {
    let mut out = Vec::new();
    for i in 0..200 {
        let t = 40_000.0 + f64::from(i) * 0.2;
        let lat = 43.5 + f64::from(i) * 1e-5;
        out.push(build::gga("GP", t, lat, 16.44, true, 9));
        out.push(build::rmc("GP", t, "211126", lat, 16.44, 1.5, 90.0));
        out.push(nmea_sentence(
            b'$',
            &format!("GPVTG,{:.1},T,,M,2.9,N,5.4,K,A", f64::from(i % 360)),
        ));
        out.push(nmea_sentence(
            b'$',
            &format!("HEHDT,{:.1},T", f64::from(i % 360)),
        ));
    }
    out
}

/// Sentences per second of the fastest of `rounds` runs of each of `a` and `b`, taken in turns so
/// that both see the same machine (clock speed, other load).
fn best_rates(n: usize, rounds: usize, mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64) {
    let rate = |f: &mut dyn FnMut()| {
        let start = Instant::now();
        f();
        n as f64 / start.elapsed().as_secs_f64()
    };
    (0..rounds).fold((0.0, 0.0), |(ra, rb), _| {
        (ra.max(rate(&mut a)), rb.max(rate(&mut b)))
    })
}

fn throughput() {
    let list = sentences();
    let stream: Vec<u8> = list
        .iter()
        .flat_map(|s| format!("{s}\r\n").into_bytes())
        .collect();
    let reps = 50;
    let n = list.len() * reps;
    let cat = Catalogue::built_in();
    let none = Params::from_pairs(&[]);
    let (mut gps, _) = Sensor::new(&none, &cat, Role::Gps).expect("a GPS driver");
    let (mut compass, _) = Sensor::new(&none, &cat, Role::Heading).expect("a heading driver");
    let cfg = SerialConfig::from_url(&mut MediumUrl::parse("serial:///dev/null").expect("url"))
        .expect("config");
    let mut topics = FrameTopics::new(&cfg);
    let now = tokio::time::Instant::now();
    let bare = || {
        for _ in 0..reps {
            for s in &list {
                let _ = black_box(nmea::parse_str(black_box(s)));
            }
        }
    };
    let ours = || {
        let mut framer = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 256);
        let mut datasets = 0usize;
        for _ in 0..reps {
            framer.push(black_box(&stream), &mut |out| {
                let Ok(frame) = out else { return };
                let topic = topics.topic_of(&frame);
                let payload = Payload::from(frame);
                let line = std::str::from_utf8(payload.as_bytes().expect("bytes")).unwrap_or("");
                if let Ok(p) = parse(line) {
                    datasets += gps.read(&p, now).len() + compass.read(&p, now).len();
                }
                black_box(topic);
            });
        }
        black_box(datasets);
    };
    let (bare, ours) = best_rates(n, 9, bare, ours);
    println!("NMEA sentences (GGA, RMC, VTG, HDT), best of 9 x {n}, taken in turns:");
    println!("  bare nmea::parse_str                              {bare:>9.0} sentences/s");
    println!("  seabus: frame, check, topic, parse, to datasets   {ours:>9.0} sentences/s");
    println!("  ratio {:.2} (target: at least 0.8)", ours / bare);
}

fn latency() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let dir = std::env::temp_dir().join(format!("seabus-bench-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join("line").display().to_string();
        let node = Node::new("bench");
        let far = seabus_medium_serial::schemes()
            .open("far", &format!("pty://{path}"), &node)
            .expect("pty");
        let line = seabus_medium_serial::schemes()
            .open(
                "line",
                &format!("serial://{path}?baud=115200&reopen=20ms"),
                &node,
            )
            .expect("serial");
        let mut link = line.watch_link();
        let _ = tokio::time::timeout(
            Duration::from_secs(5),
            link.wait_for(|s| *s == seabus_medium::LinkState::Up),
        )
        .await;
        let mut rx = line
            .attach_with("rx", 1 << 14, 16)
            .subscribed("nmea.**")
            .expect("pattern");
        let tx = far.attach("tx");
        let n = 2000;
        // the receiver notes when each sentence arrives, on its own task
        let receiver = tokio::spawn(async move {
            let mut arrived = Vec::with_capacity(n);
            while let Ok(Some(m)) =
                tokio::time::timeout(Duration::from_millis(500), rx.recv()).await
            {
                let at = Instant::now();
                if let Some(i) = index(&m) {
                    arrived.push((i, at));
                }
                if arrived.len() == n {
                    break;
                }
            }
            arrived
        });
        let mut sent_at = vec![None; n];
        let start = Instant::now();
        for (i, slot) in sent_at.iter_mut().enumerate() {
            let due = start + Duration::from_micros(5_000 * i as u64);
            tokio::time::sleep_until(due.into()).await;
            let s = nmea_sentence(b'$', &format!("GPHDT,{i},T"));
            *slot = Some(Instant::now());
            let _ = tx.send("out", Payload::from(s.into_bytes())).await;
        }
        let arrived = receiver.await.expect("receiver");
        let mut lat: Vec<Duration> = arrived
            .iter()
            .filter_map(|(i, at)| {
                sent_at
                    .get(*i)
                    .copied()
                    .flatten()
                    .map(|s| at.duration_since(s))
            })
            .collect();
        lat.sort();
        let q = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize].as_secs_f64() * 1e6;
        println!(
            "serial -> bus over a pty, {} of {n} sentences at 200/s:",
            lat.len()
        );
        println!("  latency p50 {:.0} us, p99 {:.0} us", q(0.5), q(0.99));
        far.close();
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// The sentence number carried in a `$GPHDT,<i>,T` sentence.
fn index(m: &seabus_medium::Message) -> Option<usize> {
    let b = m.payload.as_bytes()?;
    String::from_utf8_lossy(b).split(',').nth(1)?.parse().ok()
}

fn main() {
    throughput();
    latency();
}
