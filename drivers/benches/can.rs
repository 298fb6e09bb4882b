//! CAN throughput and latency.
//!
//! 1. slcan lines parsed per second: a byte stream of classic, extended and CAN FD frame lines cut
//!    into lines and parsed into frames, and the frames turned into messages' datamaps.
//! 2. DBC signals decoded per second: the example database's thruster and battery messages
//!    decoded into datamaps (Intel, Motorola, signed, scaled, described signals).
//! 3. CAN → bus latency over a pseudo-terminal: a frame sent by seabus's pseudo-terminal slcan
//!    adapter, read by an `slcan://` host medium on its other end and decoded with the DBC; p50 and
//!    p99 at 500 frames per second.
//!
//! No reference is measured beside these, so there is no ratio and no goal: the smoke run
//! (`SEABUS_BENCH_SMOKE=1`) only runs each part shorter.
//!
//! Run: `cargo bench -p seabus-drivers --bench can`

use seabus_bench::scale;
use seabus_drivers::can::dbc::Database;
use seabus_medium::{DataMap, Node, Value};
use seabus_medium_can::frame::CanFrame;
use seabus_medium_can::slcan::{self, Line, Lines};
use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

fn best_of<T>(runs: u32, mut f: impl FnMut() -> (T, Duration)) -> (T, Duration) {
    let mut best = f();
    for _ in 1..runs {
        let r = f();
        if r.1 < best.1 {
            best = r;
        }
    }
    best
}

fn slcan_lines() {
    let mut stream = Vec::new();
    for i in 0..30_000u32 {
        let frame = match i % 3 {
            0 => CanFrame::data(i % 0x800, false, &i.to_le_bytes().repeat(2)).unwrap(),
            1 => CanFrame::data(0x18FF_0000 | i, true, &i.to_be_bytes()).unwrap(),
            _ => CanFrame::fd(i % 0x800, false, &[i as u8; 16], true, false).unwrap(),
        };
        stream.extend(slcan::encode_frame(&frame, None).unwrap());
    }
    let lines = 30_000;
    let runs = scale(5, 3);
    let ((), took) = best_of(runs, || {
        let start = Instant::now();
        let mut n = 0;
        let mut splitter = Lines::new();
        splitter.push(&stream, &mut |l| {
            if let Ok(l) = l
                && let Ok(Line::Frame(f, t)) = slcan::parse_line(l)
            {
                black_box(f.to_map(t.map(u32::from)));
                n += 1;
            }
        });
        assert_eq!(n, lines);
        ((), start.elapsed())
    });
    println!(
        "slcan: {:.2} M lines/s parsed into frames and datamaps ({} bytes, best of {runs})",
        f64::from(lines) / took.as_secs_f64() / 1e6,
        stream.len()
    );
}

fn example() -> Database {
    Database::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/can/vehicle.dbc"))
        .expect("the example database")
}

fn dbc_signals() {
    let db = example();
    let thruster = db.by_name("ThrusterStatus").unwrap();
    let battery = db.by_name("BatteryStatus").unwrap();
    let frames = [
        [0x24, 0xFA, 0xD2, 0x04, 0x41, 0x02, 0, 0],
        [0x12, 0xC0, 0xFF, 0x83, 0xAF, 0xFB, 0, 0],
    ];
    let iters = scale(200_000u32, 50_000);
    let (signals, took) = best_of(scale(5, 3), || {
        let start = Instant::now();
        let mut signals = 0usize;
        for _ in 0..iters {
            let a = thruster.decode(black_box(&frames[0]));
            let b = battery.decode(black_box(&frames[1]));
            signals += a.len() + b.len();
            black_box((a, b));
        }
        (signals, start.elapsed())
    });
    println!(
        "DBC: {:.2} M signals/s decoded ({:.2} M messages/s, {} signals each on average)",
        signals as f64 / took.as_secs_f64() / 1e6,
        f64::from(2 * iters) / took.as_secs_f64() / 1e6,
        signals as f64 / f64::from(2 * iters)
    );
}

fn latency() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let path = std::env::temp_dir().join(format!("seabus-bench-can-{}", std::process::id()));
        let node = Node::new("bench");
        let adapter = seabus_medium_can::schemes().open("adapter", &format!("slcan+pty://{}", path.display()), &node)
            .expect("the pty adapter");
        let host = seabus_medium_can::schemes().open(
            "host",
            &format!("slcan://{}?reopen=20ms", path.display()),
            &node,
        )
        .expect("the slcan host");
        let mut link = host.watch_link();
        let _ = tokio::time::timeout(
            Duration::from_secs(5),
            link.wait_for(|s| *s == seabus_medium::LinkState::Up),
        )
        .await;
        let db = example();
        let status = db.by_name("ThrusterStatus").unwrap().clone();
        let mut rx = host
            .attach_with("rx", 1 << 14, 16)
            .subscribed("can.**")
            .expect("pattern");
        let tx = adapter.attach("tx");
        // the host opens the channel with its first lines: wait until a frame gets through
        for _ in 0..100 {
            let probe = DataMap::new().with("data", Value::Bytes(vec![0; 8]));
            let _ = tx.send("can.101", probe).await;
            if let Ok(Some(_)) = tokio::time::timeout(Duration::from_millis(50), rx.recv()).await {
                break;
            }
        }
        while let Ok(Some(_)) = tokio::time::timeout(Duration::from_millis(100), rx.recv()).await
        {}
        let n = scale(2000usize, 500);
        let receiver = tokio::spawn(async move {
            let mut arrived = Vec::with_capacity(n);
            while let Ok(Some(m)) =
                tokio::time::timeout(Duration::from_millis(500), rx.recv()).await
            {
                let at = Instant::now();
                let Ok(frame) = CanFrame::from_message(m.topic.as_str(), &m.payload) else {
                    continue;
                };
                let map = status.decode(frame.payload());
                if let Some(i) = map.get_i64("Rpm") {
                    arrived.push((i as usize, at));
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
            let due = start + Duration::from_micros(2_000 * i as u64);
            tokio::time::sleep_until(due.into()).await;
            // the frame's Rpm carries its number
            let mut data = [0u8; 8];
            data[..2].copy_from_slice(&(i as i16).to_le_bytes());
            *slot = Some(Instant::now());
            let _ = tx
                .send("can.101", DataMap::new().with("data", Value::Bytes(data.to_vec())))
                .await;
        }
        let arrived = receiver.await.expect("receiver");
        let mut lat: Vec<Duration> = arrived
            .iter()
            .filter_map(|(i, at)| sent_at.get(*i).copied().flatten().map(|s| at.duration_since(s)))
            .collect();
        lat.sort();
        let q = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize].as_secs_f64() * 1e6;
        println!(
            "CAN -> bus over a pty (slcan adapter -> slcan host -> DBC decode), {} of {n} frames at 500/s:",
            lat.len()
        );
        println!("  latency p50 {:.0} us, p99 {:.0} us", q(0.5), q(0.99));
        adapter.close();
        host.close();
    });
}

fn main() {
    slcan_lines();
    dbc_signals();
    latency();
}
