//! Counting rejected input and refused requests by reason, and logging them without flooding the
//! log: the first few of each reason, then every power of two.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Mutex;

/// Rejections by reason.
#[derive(Debug, Default)]
pub struct Tally {
    counts: Mutex<BTreeMap<String, u64>>,
}

impl Tally {
    /// An empty tally.
    pub fn new() -> Tally {
        Tally::default()
    }

    /// Counts one rejection; logs it (as `who`) when it is one of the first five of its reason or
    /// its count is a power of two. Returns the count of that reason.
    pub fn record(&self, who: &str, reason: &str, detail: impl fmt::Display) -> u64 {
        let n = {
            let mut map = self.counts.lock().unwrap_or_else(|p| p.into_inner());
            let n = map.entry(reason.to_string()).or_insert(0);
            *n += 1;
            *n
        };
        if n <= 5 || n.is_power_of_two() {
            tracing::warn!(source = who, reason, count = n, "{detail}");
        }
        n
    }

    /// The counts so far.
    pub fn counts(&self) -> BTreeMap<String, u64> {
        self.counts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// The count of one reason.
    pub fn count(&self, reason: &str) -> u64 {
        self.counts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(reason)
            .copied()
            .unwrap_or(0)
    }

    /// All rejections.
    pub fn total(&self) -> u64 {
        self.counts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .values()
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_by_reason() {
        let t = Tally::new();
        for _ in 0..3 {
            t.record("x", "garbage", "bytes");
        }
        t.record("x", "too-long", "line");
        assert_eq!(
            (t.count("garbage"), t.count("too-long"), t.total()),
            (3, 1, 4)
        );
    }
}
