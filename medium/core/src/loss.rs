//! Input a medium read but a receiver never got: data messages dropped from a receiver's full
//! queue (oldest first), and characters a serial device lost before seabus read them (overruns,
//! as the kernel counts them). Both are counted for good — queue drops by receiver — and shown in
//! [`crate::MediumStats`].
//!
//! Losses come in bursts (a device sending 1 MB/s for a second, a module too slow for it), so they
//! are logged by the burst: when nothing more was lost for [`BURST_QUIET`], one warning says how
//! much the burst lost, over how long and why ("412 messages lost in a burst over 1.2 s (queue of
//! gps full)"; with several receivers, each one's count: "messages lost in a burst over 2.0 s
//! (queues full: compass 310, gps 296)"). Loss that goes on without a pause is said every
//! [`BURST_LONGEST`] ("… lost in the last 10.0 s (…), still losing"). A task waits for the end of a burst while there is one, and
//! only then: a medium that loses nothing costs nothing.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::time::Instant;

/// A burst of losses ends when nothing more was lost for this long.
pub const BURST_QUIET: Duration = Duration::from_secs(1);
/// Loss that goes on this long without a pause is said without waiting for its end, then again
/// every as long.
pub const BURST_LONGEST: Duration = Duration::from_secs(10);

/// What one burst lost.
#[derive(Debug, Clone)]
struct Burst {
    first: Instant,
    last: Instant,
    /// messages dropped from full queues, by receiver
    queues: BTreeMap<Arc<str>, u64>,
    overruns: u64,
    /// messages the wire says were sent and never arrived
    missed: u64,
}

impl Burst {
    fn new(now: Instant) -> Burst {
        Burst {
            first: now,
            last: now,
            queues: BTreeMap::new(),
            overruns: 0,
            missed: 0,
        }
    }

    fn is_empty(&self) -> bool {
        self.overruns == 0 && self.missed == 0 && self.queues.values().all(|n| *n == 0)
    }

    /// The warning's text; `going_on` for a loss that has not ended yet.
    fn describe(&self, now: Instant, going_on: bool) -> String {
        // what was lost and why: a count and its cause
        let mut lost: Vec<(String, String)> = Vec::new();
        let full: Vec<_> = self.queues.iter().filter(|(_, n)| **n > 0).collect();
        match full.as_slice() {
            [] => {}
            [(who, n)] => lost.push((format!("{n} messages"), format!("queue of {who} full"))),
            several => {
                let mut by = "queues full:".to_string();
                for (i, (who, n)) in several.iter().enumerate() {
                    let _ = write!(by, "{} {who} {n}", if i == 0 { "" } else { "," });
                }
                lost.push(("messages".to_string(), by));
            }
        }
        if self.overruns > 0 {
            let count = format!("{} characters", self.overruns);
            lost.push((count, "device overrun".to_string()));
        }
        if self.missed > 0 {
            let count = format!("{} messages", self.missed);
            lost.push((count, "missed on the wire".to_string()));
        }
        let when = if going_on {
            let secs = now.saturating_duration_since(self.first).as_secs_f64();
            format!("in the last {secs:.1} s")
        } else {
            let secs = self
                .last
                .saturating_duration_since(self.first)
                .as_secs_f64();
            match secs < 0.05 {
                true => "at once".to_string(),
                false => format!("in a burst over {secs:.1} s"),
            }
        };
        let still = if going_on { ", still losing" } else { "" };
        match lost.as_slice() {
            [(count, cause)] => format!("{count} lost {when} ({cause}){still}"),
            _ => {
                let what: Vec<String> =
                    lost.iter().map(|(c, why)| format!("{c} ({why})")).collect();
                format!("{} lost {when}{still}", what.join(" and "))
            }
        }
    }
}

#[derive(Debug, Default)]
struct State {
    /// every message dropped from a full queue, by receiver
    queues: BTreeMap<Arc<str>, u64>,
    overruns: u64,
    /// messages missed on the wire, by topic
    missed: BTreeMap<String, u64>,
    /// the burst under way
    burst: Option<Burst>,
    /// whether a task waits for the burst's end
    watched: bool,
}

/// A medium's losses: counted for good, and logged once a burst of them ends.
#[derive(Debug)]
pub struct Losses {
    medium: Arc<str>,
    state: Mutex<State>,
}

impl Losses {
    /// The losses of the medium called `medium`.
    pub fn new(medium: Arc<str>) -> Arc<Losses> {
        Arc::new(Losses {
            medium,
            state: Mutex::new(State::default()),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Counts `n` data messages dropped because the queue of `receiver` was full.
    pub fn queue_full(self: &Arc<Self>, receiver: &Arc<str>, n: u64) {
        if n == 0 {
            return;
        }
        self.note(|st, burst| {
            *st.queues.entry(receiver.clone()).or_default() += n;
            *burst.queues.entry(receiver.clone()).or_default() += n;
        });
    }

    /// Counts `n` characters the device lost before they were read (overruns).
    pub fn overrun(self: &Arc<Self>, n: u64) {
        if n == 0 {
            return;
        }
        self.note(|st, burst| {
            st.overruns += n;
            burst.overruns += n;
        });
    }

    /// Counts `n` messages of `topic` the wire says were sent and never arrived (a sender's
    /// numbering skipped them).
    pub fn missed(self: &Arc<Self>, topic: &str, n: u64) {
        if n == 0 {
            return;
        }
        self.note(|st, burst| {
            *st.missed.entry(topic.to_string()).or_default() += n;
            burst.missed += n;
        });
    }

    /// Every message missed on the wire so far, by topic.
    pub fn missed_by_topic(&self) -> BTreeMap<String, u64> {
        self.lock().missed.clone()
    }

    /// Every message dropped from a full queue so far, by receiver.
    pub fn by_receiver(&self) -> BTreeMap<String, u64> {
        self.lock()
            .queues
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect()
    }

    /// Every overrun counted so far.
    pub fn overruns(&self) -> u64 {
        self.lock().overruns
    }

    /// Adds a loss to the counts and to the burst under way (starting one), and makes sure a task
    /// waits for the burst's end.
    fn note(self: &Arc<Self>, add: impl FnOnce(&mut State, &mut Burst)) {
        let now = Instant::now();
        let (ended, watch) = {
            let mut guard = self.lock();
            let st = &mut *guard;
            // without a task to watch it (no runtime here), a burst long over is said now
            let ended = match &st.burst {
                Some(b) if !st.watched && now >= b.last + BURST_QUIET => st.burst.take(),
                _ => None,
            };
            let mut burst = st.burst.take().unwrap_or_else(|| Burst::new(now));
            add(st, &mut burst);
            burst.last = now;
            st.burst = Some(burst);
            let watch = !st.watched && tokio::runtime::Handle::try_current().is_ok();
            st.watched |= watch;
            (ended, watch)
        };
        if let Some(b) = ended {
            self.say(&b, now, false);
        }
        if watch {
            tokio::spawn(self.clone().watch());
        }
    }

    /// Waits for the end of the burst under way, saying it then (and every [`BURST_LONGEST`] while
    /// it goes on).
    async fn watch(self: Arc<Self>) {
        loop {
            let due = {
                let mut st = self.lock();
                match &st.burst {
                    Some(b) => (b.last + BURST_QUIET).min(b.first + BURST_LONGEST),
                    None => {
                        st.watched = false;
                        return;
                    }
                }
            };
            tokio::time::sleep_until(due).await;
            let now = Instant::now();
            let said = {
                let mut st = self.lock();
                match st.burst.take() {
                    Some(b) if now >= b.last + BURST_QUIET => {
                        st.watched = false;
                        Some((b, false))
                    }
                    Some(b) if now >= b.first + BURST_LONGEST => {
                        // said so far; what follows is counted from now
                        st.burst = Some(Burst {
                            last: b.last,
                            ..Burst::new(now)
                        });
                        Some((b, true))
                    }
                    other => {
                        st.burst = other;
                        None
                    }
                }
            };
            match said {
                Some((b, going_on)) => {
                    self.say(&b, now, going_on);
                    if !going_on {
                        return;
                    }
                }
                None => continue,
            }
        }
    }

    fn say(&self, burst: &Burst, now: Instant, going_on: bool) {
        if burst.is_empty() {
            return;
        }
        let text = burst.describe(now, going_on);
        tracing::warn!(medium = %self.medium, "{text}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex as StdMutex;
    use tracing::span;

    /// The warnings logged on this thread.
    #[derive(Clone, Default)]
    struct Warnings(Arc<StdMutex<Vec<String>>>);

    impl tracing::Subscriber for Warnings {
        fn enabled(&self, m: &tracing::Metadata<'_>) -> bool {
            *m.level() <= tracing::Level::WARN
        }
        fn new_span(&self, _: &span::Attributes<'_>) -> span::Id {
            span::Id::from_u64(1)
        }
        fn record(&self, _: &span::Id, _: &span::Record<'_>) {}
        fn record_follows_from(&self, _: &span::Id, _: &span::Id) {}
        fn event(&self, e: &tracing::Event<'_>) {
            let mut line = String::new();
            e.record(&mut |f: &tracing::field::Field, v: &dyn std::fmt::Debug| {
                line += &format!("{f}={v:?} ");
            });
            self.0.lock().unwrap().push(line.trim_end().to_string());
        }
        fn enter(&self, _: &span::Id) {}
        fn exit(&self, _: &span::Id) {}
    }

    impl Warnings {
        fn take(&self) -> Vec<String> {
            std::mem::take(&mut *self.0.lock().unwrap())
        }
    }

    async fn advance(ms: u64) {
        tokio::time::sleep(Duration::from_millis(ms)).await;
    }

    #[tokio::test(start_paused = true)]
    async fn a_burst_is_said_once_when_it_ends_with_its_count_and_cause() {
        let warnings = Warnings::default();
        let _caught = tracing::subscriber::set_default(warnings.clone());
        let losses = Losses::new(Arc::from("gps-line"));
        let gps: Arc<str> = Arc::from("gps");
        // 412 drops over 1.2 s, a few milliseconds apart
        for i in 0..412u64 {
            losses.queue_full(&gps, 1);
            if i % 4 == 0 {
                advance(12).await;
            }
        }
        assert!(warnings.take().is_empty(), "nothing said while it goes on");
        advance(900).await;
        assert!(warnings.take().is_empty(), "not quiet for long enough yet");
        advance(200).await;
        let said = warnings.take();
        assert_eq!(
            said,
            ["message=412 messages lost in a burst over 1.2 s (queue of gps full) medium=gps-line"]
        );
        advance(5_000).await;
        assert!(warnings.take().is_empty(), "one warning a burst");
        assert_eq!(losses.by_receiver(), BTreeMap::from([("gps".into(), 412)]));
        // the next burst is a burst of its own, here with two receivers and the device
        let compass: Arc<str> = Arc::from("compass");
        losses.queue_full(&gps, 3);
        losses.queue_full(&compass, 2);
        losses.overrun(7);
        advance(1_100).await;
        assert_eq!(
            warnings.take(),
            [
                "message=messages (queues full: compass 2, gps 3) and 7 characters (device overrun) lost at once medium=gps-line"
            ]
        );
        assert_eq!(
            losses.by_receiver(),
            BTreeMap::from([("compass".into(), 2), ("gps".into(), 415)])
        );
        assert_eq!(losses.overruns(), 7);
    }

    #[tokio::test(start_paused = true)]
    async fn loss_without_a_pause_is_said_every_ten_seconds() {
        let warnings = Warnings::default();
        let _caught = tracing::subscriber::set_default(warnings.clone());
        let losses = Losses::new(Arc::from("line"));
        let slow: Arc<str> = Arc::from("slow");
        // one drop every 300 ms for 25 s
        for _ in 0..84 {
            losses.queue_full(&slow, 1);
            advance(300).await;
        }
        advance(2_000).await;
        let said = warnings.take();
        assert_eq!(said.len(), 3, "{said:?}");
        assert!(
            said[0].starts_with(
                "message=34 messages lost in the last 10.0 s (queue of slow full), still losing"
            ),
            "{said:?}"
        );
        assert!(
            said[1].starts_with(
                "message=33 messages lost in the last 10.0 s (queue of slow full), still losing"
            ),
            "{said:?}"
        );
        assert!(
            said[2]
                .starts_with("message=17 messages lost in a burst over 4.9 s (queue of slow full)"),
            "{said:?}"
        );
        assert_eq!(losses.by_receiver()["slow"], 84);
    }

    #[test]
    fn without_a_runtime_a_burst_is_said_when_the_next_begins() {
        let warnings = Warnings::default();
        let _caught = tracing::subscriber::set_default(warnings.clone());
        let losses = Losses::new(Arc::from("m"));
        losses.overrun(2);
        assert!(warnings.take().is_empty());
        losses.state.lock().unwrap().burst.as_mut().unwrap().last -= BURST_QUIET;
        losses.overrun(1);
        assert_eq!(
            warnings.take(),
            ["message=2 characters lost at once (device overrun) medium=m"]
        );
        assert_eq!(losses.overruns(), 3);
    }
}
