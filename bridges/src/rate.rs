//! Route rate limits: a schedule of ideal send times per topic, so that a route's `rate` is the
//! rate delivered from any faster source, and a slower source passes whole.
//!
//! Each (route, topic) keeps the time its next message is due. A message is sent when it arrives
//! no earlier than half a period before that time; the next one is then due a period after the
//! later of the due time and half a period before the arrival. The due times advance by exactly
//! one period per message sent, so over any stretch of a faster source the route delivers its rate
//! (not "a period since the last one", which loses a message every time one arrives a hair early
//! and delivers less); arrivals jittered by up to half a period either way change nothing. A topic
//! silent for a period or more starts afresh: its first message goes at once, and no burst makes
//! up for the silence.

use seabus_medium::Topic;
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::time::Duration;
use tokio::time::Instant;

/// The due times of the rate-limited topics of one bridge's routes.
#[derive(Default)]
pub struct Schedule {
    due: HashMap<(usize, Topic), Instant>,
}

impl Schedule {
    /// Whether a message of `topic` on route `route`, limited to one per `period`, goes at `now`
    /// (it is then counted against the schedule).
    pub fn admit(&mut self, route: usize, topic: &Topic, period: Duration, now: Instant) -> bool {
        let half = period / 2;
        match self.due.entry((route, topic.clone())) {
            Entry::Vacant(e) => {
                e.insert(now + period);
                true
            }
            Entry::Occupied(mut e) => {
                let due = *e.get();
                if now + half < due {
                    return false;
                }
                // silent for a period or more: afresh
                let base = if due + period <= now {
                    now
                } else {
                    due.max(now.checked_sub(half).unwrap_or(now))
                };
                *e.get_mut() = base + period;
                true
            }
        }
    }

    /// Forgets the topics silent for a period or more (they start afresh anyway); `period` is each
    /// route's limit.
    pub fn prune(&mut self, now: Instant, period: impl Fn(usize) -> Option<Duration>) {
        self.due
            .retain(|(route, _), due| period(*route).is_some_and(|p| now < *due + p));
    }

    /// How many topics have a due time.
    pub fn len(&self) -> usize {
        self.due.len()
    }

    /// Whether no topic has a due time.
    pub fn is_empty(&self) -> bool {
        self.due.is_empty()
    }

    /// Forgets every due time.
    pub fn clear(&mut self) {
        self.due.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The times at which a source of `hz` per second, each arrival jittered uniformly by up to
    /// `jitter` either way, delivers through a route limited to `rate` per second, over `secs`
    /// simulated seconds.
    fn delivered(hz: f64, jitter: Duration, rate: f64, secs: u64, seed: u64) -> Vec<Duration> {
        let mut rng = fastrand::Rng::with_seed(seed);
        let t0 = Instant::now();
        let topic = Topic::new("nav.depth").expect("a topic");
        let period = Duration::from_secs_f64(1.0 / rate);
        let mut schedule = Schedule::default();
        let mut out = Vec::new();
        for n in 0..(hz * secs as f64) as u64 {
            // ideal + jitter ± jitter (all a `jitter` later, so that none is before the start)
            let at = Duration::from_secs_f64(n as f64 / hz) + jitter.mul_f64(rng.f64() * 2.0);
            if schedule.admit(0, &topic, period, t0 + at) {
                out.push(at);
            }
        }
        out
    }

    /// Messages delivered per second in each whole 10 s window of `times` over `secs`.
    fn window_rates(times: &[Duration], secs: u64) -> Vec<f64> {
        (0..secs / 10)
            .map(|w| {
                let (from, to) = (
                    Duration::from_secs(w * 10),
                    Duration::from_secs(w * 10 + 10),
                );
                times.iter().filter(|t| **t >= from && **t < to).count() as f64 / 10.0
            })
            .collect()
    }

    /// Every 10 s window of a jittered 10 Hz source through `rate` delivers within `tolerance`.
    fn keeps(rate: f64, tolerance: f64) {
        for (jitter_ms, seed) in [(0, 1), (10, 2), (30, 3), (45, 4)] {
            let times = delivered(10.0, Duration::from_millis(jitter_ms), rate, 120, seed);
            let overall = times.len() as f64 / 120.0;
            assert!(
                (overall - rate).abs() <= tolerance / 4.0,
                "rate {rate}, jitter {jitter_ms} ms: {overall}/s overall"
            );
            for (w, r) in window_rates(&times, 120).iter().enumerate() {
                assert!(
                    (r - rate).abs() <= tolerance,
                    "rate {rate}, jitter {jitter_ms} ms: {r}/s in the window from {}s",
                    w * 10
                );
            }
        }
    }

    #[test]
    fn a_jittered_10_hz_source_at_rate_5_delivers_5_a_second() {
        keeps(5.0, 0.25);
    }

    #[test]
    fn a_jittered_10_hz_source_at_rate_3_delivers_3_a_second() {
        keeps(3.0, 0.15);
    }

    #[test]
    fn a_source_slower_than_the_rate_passes_whole() {
        for (hz, seed) in [(4.0, 5), (2.0, 6), (4.8, 7)] {
            let sent = (hz * 60.0) as usize;
            let times = delivered(hz, Duration::from_millis(20), 5.0, 60, seed);
            assert_eq!(times.len(), sent, "{hz} Hz at rate 5");
        }
    }

    #[test]
    fn topics_and_routes_are_limited_apart_and_a_silent_topic_starts_afresh() {
        let (a, b) = (Topic::new("a").expect("a"), Topic::new("b").expect("b"));
        let period = Duration::from_millis(200);
        let t0 = Instant::now();
        let mut s = Schedule::default();
        assert!(s.admit(0, &a, period, t0));
        assert!(s.admit(0, &b, period, t0));
        assert!(s.admit(1, &a, period, t0));
        // a message early by more than half a period waits
        assert!(!s.admit(0, &a, period, t0 + Duration::from_millis(99)));
        assert!(s.admit(0, &a, period, t0 + Duration::from_millis(100)));
        // after a long silence: the first goes, the next no sooner than half a period later
        let later = t0 + Duration::from_secs(10);
        assert!(s.admit(0, &a, period, later));
        assert!(!s.admit(0, &a, period, later + Duration::from_millis(50)));
        assert!(!s.admit(0, &a, period, later + Duration::from_millis(99)));
        assert!(s.admit(0, &a, period, later + Duration::from_millis(150)));
        // pruning forgets only the silent
        s.prune(later + Duration::from_millis(150), |_| Some(period));
        assert_eq!(s.len(), 1);
    }
}
