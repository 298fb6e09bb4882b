//! Counting rejected input and refused requests by reason, and logging them without flooding the
//! log: the first of each reason in a 10 s window is logged, the others of that window are counted
//! and said with the next one logged ("37 more like this in the last 10 s").

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How long a logged event silences the others like it.
pub const WINDOW: Duration = Duration::from_secs(10);

/// Rate-limits one kind of log line: the first event of a [`WINDOW`] is logged, the others are
/// counted and reported with the next one logged.
#[derive(Debug, Default, Clone)]
pub struct Limiter {
    /// When the last logged event was.
    logged: Option<Instant>,
    /// Events not logged since then.
    held: u64,
}

/// What a [`Limiter`] lets through: the events held back before it and over how long. Its
/// `Display` is empty when none were, else ` (37 more like this in the last 10 s)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Held {
    /// Events not logged before this one.
    pub count: u64,
    /// Since the last one logged.
    pub over: Duration,
}

impl fmt::Display for Held {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.count == 0 {
            return Ok(());
        }
        write!(
            f,
            " ({} more like this in the last {} s)",
            self.count,
            self.over.as_secs().max(1)
        )
    }
}

impl Limiter {
    /// Whether an event at `now` is logged: `Some` with what was held back before it, or `None`
    /// (it is counted, to be said with the next one logged).
    pub fn admit(&mut self, now: Instant) -> Option<Held> {
        match self.logged {
            Some(at) if now.saturating_duration_since(at) < WINDOW => {
                self.held += 1;
                None
            }
            last => {
                self.logged = Some(now);
                Some(Held {
                    count: std::mem::take(&mut self.held),
                    over: last.map_or(Duration::ZERO, |at| now.saturating_duration_since(at)),
                })
            }
        }
    }
}

/// Rejections by reason.
#[derive(Debug, Default)]
pub struct Tally {
    counts: Mutex<BTreeMap<String, (u64, Limiter)>>,
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

    /// Counts one rejection and logs it (as `who`) when it is the first of its reason in
    /// [`WINDOW`], with how many were not logged before it. Returns the count of that reason.
    pub fn record(&self, who: &str, reason: &str, detail: impl fmt::Display) -> u64 {
        self.record_at(Instant::now(), who, reason, detail)
    }

    fn record_at(&self, now: Instant, who: &str, reason: &str, detail: impl fmt::Display) -> u64 {
        let (n, logged) = {
            let mut map = self.counts.lock().unwrap_or_else(|p| p.into_inner());
            // the reason's name is copied once, the first time it is counted
            let entry = match map.get_mut(reason) {
                Some(e) => e,
                None => map.entry(reason.to_owned()).or_default(),
            };
            entry.0 += 1;
            (entry.0, entry.1.admit(now))
        };
        if let Some(held) = logged {
            if self.debug {
                tracing::debug!(source = who, reason, count = n, "{detail}{held}");
            } else {
                tracing::warn!(source = who, reason, count = n, "{detail}{held}");
            }
        }
        n
    }

    /// The counts so far.
    pub fn counts(&self) -> BTreeMap<String, u64> {
        self.counts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .map(|(k, (n, _))| (k.clone(), *n))
            .collect()
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

    #[test]
    fn one_line_per_window_then_the_count_of_the_others() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut l = Limiter::default();
        assert_eq!(
            l.admit(at(0)),
            Some(Held {
                count: 0,
                over: Duration::ZERO
            })
        );
        for ms in (100..=9_900).step_by(100) {
            assert_eq!(l.admit(at(ms)), None, "at {ms} ms");
        }
        let next = l.admit(at(12_000)).expect("a new window");
        assert_eq!(next.count, 99);
        assert_eq!(next.to_string(), " (99 more like this in the last 12 s)");
        assert_eq!(l.admit(at(12_001)), None);
        let quiet = l.admit(at(40_000)).expect("a new window");
        assert_eq!(
            (quiet.count, quiet.to_string()),
            (1, " (1 more like this in the last 28 s)".into())
        );
        let alone = l.admit(at(60_000)).expect("a new window");
        assert_eq!(alone.to_string(), "");
    }

    #[test]
    fn a_reason_is_limited_apart_from_the_others() {
        let t = Tally::new();
        let now = Instant::now();
        for _ in 0..50 {
            t.record_at(now, "x", "garbage", "bytes");
        }
        // each reason has its own window: a first bad checksum is not held back by garbage
        let mut counts = t.counts.lock().unwrap();
        let (n, l) = counts.get_mut("garbage").unwrap();
        assert_eq!((*n, l.held), (50, 49));
        assert!(counts.get("checksum").is_none());
        drop(counts);
        t.record_at(now, "x", "checksum", "line");
        assert_eq!(t.counts.lock().unwrap()["checksum"].1.held, 0);
    }
}
