//! Estimator and logger rates.
//!
//! 1. EKF updates per second: `PositionEkf` dead-reckoning steps (predict) and GPS fixes (update).
//! 2. Depth Kalman updates per second.
//! 3. The `logger` module's sustained rate to disk: a generator-like flood of ten-field datamaps
//!    on an in-process bus for three seconds (one in the smoke run), a binary log and a CSV
//!    written; what reached the files, per second.
//!
//! No reference is measured beside these, so there is no ratio and no goal: the smoke run
//! (`SEABUS_BENCH_SMOKE=1`) only runs each part shorter.
//!
//! Run: `cargo bench -p seabus-support --bench estimate`

use seabus_bench::scale;
use seabus_medium::DataMap;
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use seabus_support::estimate::{DepthKalman, PositionEkf};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn ekf() {
    let n = scale(1_000_000u32, 200_000);
    let mut e = PositionEkf::new(0.0, 0.0, 3.0, 10.0, 0.03);
    let start = Instant::now();
    for i in 0..n {
        e.predict(0.2, f64::from(i % 360), 1.5, 0.01);
    }
    let predict = start.elapsed();
    let start = Instant::now();
    for i in 0..n {
        e.gps(f64::from(i % 100), f64::from(i % 77), 2.0);
    }
    let update = start.elapsed();
    black_box(e.position());
    println!(
        "EKF: {:.2} M predictions/s, {:.2} M GPS updates/s",
        f64::from(n) / predict.as_secs_f64() / 1e6,
        f64::from(n) / update.as_secs_f64() / 1e6
    );
    let mut k = DepthKalman::new(0.2, 0.3);
    let start = Instant::now();
    for i in 0..n {
        black_box(k.update(0.1, 10.0 + f64::from(i % 7) * 0.01));
    }
    println!(
        "depth Kalman: {:.2} M updates/s",
        f64::from(n) / start.elapsed().as_secs_f64() / 1e6
    );
}

fn logger() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let dir = std::env::temp_dir().join(format!("seabus-bench-logger-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let spec = SystemSpec::parse(
            "bench.xml",
            &format!(
                r#"<seabus node="b"><medium name="bus" url="inproc://"/>
<module name="logger" type="logger" medium="bus" dir="{}"/></seabus>"#,
                dir.display()
            ),
        )
        .unwrap();
        let runtime = Runtime::start(&spec, &seabus_support::registry(), Catalogue::built_in())
            .await
            .unwrap();
        let tx = runtime.medium("bus").unwrap().attach("tx");
        tokio::time::sleep(Duration::from_millis(200)).await;
        let flood = Duration::from_secs(scale(3, 1));
        let start = Instant::now();
        let mut sent = 0u64;
        while start.elapsed() < flood {
            for _ in 0..100 {
                let m = DataMap::new()
                    .with("lat", 43.5 + sent as f64 * 1e-7)
                    .with("lon", 16.4)
                    .with("depth", 12.5)
                    .with("heading", 271.3)
                    .with("pitch", -1.2)
                    .with("roll", 0.4)
                    .with("speed", 1.5)
                    .with("fix", 1i64)
                    .with("mode", "survey")
                    .with("seq", sent as i64);
                let _ = tx.send("nav.state", m).await;
                sent += 1;
            }
            tokio::task::yield_now().await;
        }
        let elapsed = start.elapsed();
        runtime.shutdown().await;
        let csv = std::fs::read_to_string(dir.join("nav.state.csv")).unwrap_or_default();
        let rows = csv.lines().count().saturating_sub(1) as f64;
        let bytes: u64 = std::fs::read_dir(&dir)
            .map(|d| d.filter_map(|e| e.ok()?.metadata().ok()).map(|m| m.len()).sum())
            .unwrap_or(0);
        println!(
            "logger: {:.0} k msg/s sustained to disk ({} of {sent} offered in {:.1} s kept, {:.1} MB written)",
            rows / elapsed.as_secs_f64() / 1e3,
            rows as u64,
            elapsed.as_secs_f64(),
            bytes as f64 / 1e6
        );
        let _ = std::fs::remove_dir_all(&dir);
    });
}

fn main() {
    ekf();
    logger();
}
