//! Shared pieces of the medium benchmarks: the sample message and small statistics.
#![allow(dead_code)]

use seabus_medium::DataMap;
use std::time::{Duration, Instant};

/// A ten-field datamap shaped like a navigation message.
pub fn ten_fields() -> DataMap {
    DataMap::new()
        .with("yaw", 271.25f64)
        .with("pitch", -2.5f64)
        .with("roll", 0.75f64)
        .with("depth", 12.125f64)
        .with("lat", 43.508_123_4f64)
        .with("lon", 16.440_234_5f64)
        .with("fix", 1i64)
        .with("satellites", 9i64)
        .with("source", "gps")
        .with("valid", true)
}

/// The median of a set of rates.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// The `q` quantile (0–1) of durations, in microseconds.
pub fn quantile_us(sorted: &[Duration], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i].as_secs_f64() * 1e6
}

/// Formats a rate in messages per second.
pub fn rate(r: f64) -> String {
    if r >= 1e6 {
        format!("{:.2} M msg/s", r / 1e6)
    } else {
        format!("{:.0} k msg/s", r / 1e3)
    }
}

/// Waits until `deadline`, sleeping while far and spinning when near (for exact pacing).
pub fn pace(deadline: Instant) {
    loop {
        let now = Instant::now();
        if now >= deadline {
            return;
        }
        if deadline - now > Duration::from_micros(200) {
            std::thread::sleep(Duration::from_micros(100));
        } else {
            std::hint::spin_loop();
        }
    }
}
