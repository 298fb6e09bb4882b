//! Counting rejected input and refused requests by reason, and logging them without flooding the
//! log: the first few of each reason, then every power of two.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Mutex;

/// Rejections by reason.
#[derive(Debug, Default)]
pub struct Tally {
    counts: Mutex<BTreeMap<String, u64>>,
    /// Logged at DEBUG rather than WARN: input known to carry noise (a simulator that injects
    /// faults), still counted.
    debug: bool,
}

impl Tally {
    /// An empty tally.
    pub fn new() -> Tally {
        Tally::default()
    }

    /// An empty tally that logs at DEBUG (what it counts is expected).
    pub fn logged_at_debug() -> Tally {
        Tally {
            debug: true,
            ..Tally::default()
        }
    }

    /// Counts one rejection; logs it (as `who`) when it is one of the first five of its reason or
    /// its count is a power of two. Returns the count of that reason.
    pub fn record(&self, who: &str, reason: &str, detail: impl fmt::Display) -> u64 {
        let n = {
            let mut map = self.counts.lock().unwrap_or_else(|p| p.into_inner());
            // the reason's name is copied once, the first time it is counted
            if let Some(n) = map.get_mut(reason) {
                *n += 1;
                *n
            } else {
                map.insert(reason.to_owned(), 1);
                1
            }
        };
        if n <= 5 || n.is_power_of_two() {
            if self.debug {
                tracing::debug!(source = who, reason, count = n, "{detail}");
            } else {
                tracing::warn!(source = who, reason, count = n, "{detail}");
            }
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_by_reason() {
        let t = Tally::new();
        let garbage: Vec<u64> = (0..3).map(|_| t.record("x", "garbage", "bytes")).collect();
        assert_eq!(garbage, [1, 2, 3]);
        assert_eq!(t.record("x", "too-long", "line"), 1);
        assert_eq!(
            t.counts(),
            BTreeMap::from([("garbage".to_string(), 3), ("too-long".to_string(), 1)])
        );
    }
}
