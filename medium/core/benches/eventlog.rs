//! LCM event logs: writing and reading 200 000 events through a file (in the page cache), 64-byte
//! and 4 KiB data. The reference for reading is the bare file read (64 KiB at a time into one
//! buffer, nothing parsed), the ceiling of any reader. Prints events per second and the read ratio.
//!
//! Run: `cargo bench -p seabus-medium --bench eventlog`

use seabus_medium::eventlog::{Reader, Writer};
use std::hint::black_box;
use std::io::Read;
use std::time::Instant;

/// Best of five runs of `f`, in seconds.
fn best(mut f: impl FnMut()) -> f64 {
    (0..5)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let events: u64 = 200_000;
    let mut goals = seabus_bench::Goals::new();
    println!("LCM event log, {events} events through a file (best of 5):");
    for size in [64usize, 4096] {
        let path = dir.path().join(format!("bench-{size}.lcm"));
        let data = vec![0xA5u8; size];
        let write = best(|| {
            let mut w = Writer::create(&path).expect("the log is created");
            for i in 0..events {
                w.write(i as i64, "POSE_ESTIMATE", black_box(&data))
                    .expect("an event is written");
            }
            w.finish().expect("the log is written");
        });
        let bytes = std::fs::metadata(&path).expect("the log").len();
        let read = best(|| {
            let mut r = Reader::open(&path).expect("the log opens");
            let mut n = 0u64;
            while let Some(e) = r.next_event().expect("no damage") {
                black_box(e.data);
                n += 1;
            }
            assert_eq!(n, events);
        });
        let raw = best(|| {
            let mut file = std::fs::File::open(&path).expect("the log opens");
            let mut buf = vec![0u8; 1 << 16];
            let mut total = 0u64;
            loop {
                match file.read(&mut buf).expect("the log reads") {
                    0 => break,
                    n => total += black_box(&buf[..n]).len() as u64,
                }
            }
            assert_eq!(total, bytes);
        });
        let rate = |secs: f64| events as f64 / secs / 1e6;
        let mb = |secs: f64| bytes as f64 / secs / 1e6;
        println!(
            "  {size:5} B data: write {:.2} M events/s ({:.0} MB/s), read {:.2} M events/s ({:.0} MB/s), bare file read {:.0} MB/s",
            rate(write),
            mb(write),
            rate(read),
            mb(read),
            mb(raw),
        );
        goals.at_least(
            &format!("event log read, {size} B data / bare file read"),
            raw / read,
            0.5,
        );
    }
    goals.finish();
}
