//! The wall clock as a message's stamp reads it: the system's time, read cheaply.
//!
//! Every publication is stamped, so reading the clock is on every message's path; the system
//! call's fast form (`clock_gettime` in the vDSO) costs as much as the rest of an in-process
//! hand-out. On x86-64 Linux, when the kernel keeps its time on the CPU's time-stamp counter (its
//! clocksource is `tsc`, which it keeps only for a counter that runs at a constant rate and agrees
//! across CPUs), [`now_ns`] reads the counter (one instruction) and scales it from an *anchor*: the
//! system clock read together with the counter on the same thread, at most [`ANCHOR_SPAN_NS`]
//! before. The counter's rate is measured against the monotonic clock (which the time service
//! slews as it slews the wall clock, but never steps) over the whole life of the process, so the
//! rate only improves; each new anchor takes in whatever the time service did to the wall clock
//! since the last. Within a span the stamp can be off the system clock by the difference between
//! the clock's current slew and its average (at most 1 000 ppm apart: 10 µs in a span), and a
//! step of the clock shows in each thread within a span.
//!
//! Elsewhere, in the first [`CALIBRATION_NS`] of the process, and whenever a new measurement of the
//! counter's rate disagrees with the last by more than 1 % or the counter has gone back (a host
//! resumed, a virtual machine moved: the rate is then measured again), the clock is read. Whether
//! the kernel still keeps its time on the counter is looked at again every second.
//!
//! What may depend on it: [`crate::message::Stamp::now`] reads it; nothing else needs to.

/// Nanoseconds since the Unix epoch, now.
pub fn now_ns() -> i64 {
    #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
    return counter::now_ns();
    #[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
    read(libc::CLOCK_REALTIME)
}

/// A clock read through the system call (`clock_gettime`): nanoseconds.
fn read(clock: libc::clockid_t) -> i64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid timespec for the call to fill, and the clocks asked for
    // (CLOCK_REALTIME, CLOCK_MONOTONIC) always exist, so the call cannot fail.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    // (both fields are 32 bits wide on some 32-bit targets)
    #[allow(clippy::unnecessary_cast)]
    (ts.tv_sec as i64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as i64)
}

/// Longest a thread scales the counter from one reading of the system clock: 10 ms.
pub const ANCHOR_SPAN_NS: i64 = 10_000_000;
/// How long the counter's rate is measured before it is used: 100 ms.
pub const CALIBRATION_NS: i64 = 100_000_000;
/// Most a new measurement of the counter's rate may differ from the last, relatively, before
/// the counter is taken to have jumped and is measured again.
const MAX_RATE_CHANGE: f64 = 0.01;

/// A reading of the system clock and the counter together, and how to go on from it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Anchor {
    /// the counter when the clock was read
    ticks: u64,
    /// the clock then
    ns: i64,
    /// nanoseconds per tick of the counter
    ns_per_tick: f64,
    /// ticks after which the clock is read again ([`ANCHOR_SPAN_NS`])
    span: u64,
}

impl Anchor {
    /// An anchor at `ticks` and `ns`, the counter going `ns_per_tick`; `None` for a rate that
    /// cannot be one (a counter that did not move).
    fn new(ticks: u64, ns: i64, ns_per_tick: f64) -> Option<Anchor> {
        (ns_per_tick.is_finite() && ns_per_tick > 0.0).then(|| Anchor {
            ticks,
            ns,
            ns_per_tick,
            span: (ANCHOR_SPAN_NS as f64 / ns_per_tick) as u64,
        })
    }

    /// The time at `ticks`, when they lie within the anchor's span.
    fn at(&self, ticks: u64) -> Option<i64> {
        // (a counter behind the anchor wraps to a huge difference, out of the span)
        let since = ticks.wrapping_sub(self.ticks);
        (since < self.span).then(|| self.ns + (since as f64 * self.ns_per_tick) as i64)
    }
}

/// The counter's rate: nanoseconds per tick, from two readings of it and of a clock.
fn rate(first: (u64, i64), last: (u64, i64)) -> Option<f64> {
    let ticks = last.0.checked_sub(first.0)?;
    let ns = last.1.checked_sub(first.1)?;
    (ticks > 0 && ns >= CALIBRATION_NS).then(|| ns as f64 / ticks as f64)
}

/// What a measurement of the counter's rate says.
#[derive(Debug, PartialEq)]
enum Measured {
    /// Nanoseconds per tick.
    Rate(f64),
    /// Not measured for long enough yet.
    Wait,
    /// The counter went back or jumped: measure again from now.
    Again,
}

/// The counter's rate from `origin` to `now` (each the counter and the monotonic clock), checked
/// against the `last` rate measured.
fn measure(origin: (u64, i64), now: (u64, i64), last: Option<f64>) -> Measured {
    let forward = now.0 >= origin.0 && now.1 >= origin.1;
    if forward && now.1 - origin.1 < CALIBRATION_NS {
        return Measured::Wait;
    }
    match rate(origin, now) {
        // (a counter between 10 MHz and 100 GHz)
        Some(r)
            if (0.01..=100.0).contains(&r)
                && last.is_none_or(|l| ((r - l) / l).abs() <= MAX_RATE_CHANGE) =>
        {
            Measured::Rate(r)
        }
        _ => Measured::Again,
    }
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
mod counter {
    use super::{Anchor, read};
    use super::{CALIBRATION_NS, Measured, measure};
    use std::cell::Cell;
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicI64, Ordering};

    fn ticks() -> u64 {
        // SAFETY: RDTSC exists on every x86-64 CPU and only reads the counter
        unsafe { core::arch::x86_64::_rdtsc() }
    }

    /// `clock` read between two readings of the counter, and the counter's midpoint: the
    /// closest of three tries (a thread paused between the readings would pair the clock with a
    /// counter far from it).
    fn together(clock: libc::clockid_t) -> (u64, i64) {
        let mut best = (u64::MAX, 0, 0);
        for _ in 0..3 {
            let before = ticks();
            let ns = read(clock);
            let gap = ticks().wrapping_sub(before);
            if gap < best.0 {
                best = (gap, before + gap / 2, ns);
            }
        }
        (best.1, best.2)
    }

    /// Whether the kernel keeps its time on the counter (the counter is trusted only then).
    pub(super) fn on_counter() -> bool {
        std::fs::read_to_string("/sys/devices/system/clocksource/clocksource0/current_clocksource")
            .is_ok_and(|source| source.trim() == "tsc")
    }

    /// How often whether the kernel keeps its time on the counter is looked at again: 1 s.
    const CHECK_EVERY_NS: i64 = 1_000_000_000;

    /// The process's measurement of the counter.
    struct Calibration {
        /// the counter and the monotonic clock when the measurement began
        origin: Option<(u64, i64)>,
        /// the last rate measured
        rate: Option<f64>,
        /// whether the counter is trusted, and when that was looked at (monotonic)
        trusted: bool,
        checked_at: Option<i64>,
    }

    static CALIBRATION: Mutex<Calibration> = Mutex::new(Calibration {
        origin: None,
        rate: None,
        trusted: false,
        checked_at: None,
    });

    /// Until when (the system clock, ns) stamps read the clock without looking at the
    /// calibration: while the counter is not trusted, or its rate is being measured, every stamp
    /// would otherwise take the calibration's lock.
    static READ_UNTIL: AtomicI64 = AtomicI64::new(i64::MIN);

    thread_local! {
        pub(super) static ANCHOR: Cell<Option<Anchor>> = const { Cell::new(None) };
    }

    /// The wall clock, scaled from this thread's anchor when it can be.
    pub(super) fn now_ns() -> i64 {
        let now = ticks();
        if let Some(ns) = ANCHOR.with(Cell::get).and_then(|a| a.at(now)) {
            return ns;
        }
        anchor()
    }

    /// The counter's rate as measured now, or how long (ns) it cannot be used for (not trusted,
    /// or being measured).
    fn current_rate() -> Result<f64, i64> {
        let mut c = CALIBRATION.lock().unwrap_or_else(|p| p.into_inner());
        let mono = read(libc::CLOCK_MONOTONIC);
        if c.checked_at
            .is_none_or(|t| mono.saturating_sub(t) >= CHECK_EVERY_NS)
        {
            c.checked_at = Some(mono);
            c.trusted = on_counter();
            if !c.trusted {
                c.origin = None;
                c.rate = None;
            }
        }
        if !c.trusted {
            return Err(CHECK_EVERY_NS);
        }
        let Some(origin) = c.origin else {
            c.origin = Some(together(libc::CLOCK_MONOTONIC));
            return Err(CALIBRATION_NS);
        };
        let measuring = mono - origin.1;
        if (0..CALIBRATION_NS).contains(&measuring) {
            return Err(CALIBRATION_NS - measuring);
        }
        let now = together(libc::CLOCK_MONOTONIC);
        match measure(origin, now, c.rate) {
            Measured::Rate(r) => {
                c.rate = Some(r);
                Ok(r)
            }
            Measured::Wait => Err(CALIBRATION_NS - (now.1 - origin.1)),
            Measured::Again => {
                c.origin = Some(now);
                c.rate = None;
                Err(CALIBRATION_NS)
            }
        }
    }

    /// Reads the clock, anchoring this thread there when the counter's rate is known.
    #[cold]
    fn anchor() -> i64 {
        let wall = read(libc::CLOCK_REALTIME);
        // (a wall clock stepped back leaves a wait longer than any given: looked at again)
        let left = READ_UNTIL.load(Ordering::Relaxed).saturating_sub(wall);
        if left > 0 && left <= CHECK_EVERY_NS {
            ANCHOR.with(|a| a.set(None));
            return wall;
        }
        match current_rate() {
            Ok(rate) => {
                let (ticks, ns) = together(libc::CLOCK_REALTIME);
                ANCHOR.with(|a| a.set(Anchor::new(ticks, ns, rate)));
                ns
            }
            Err(wait) => {
                READ_UNTIL.store(wall.saturating_add(wait), Ordering::Relaxed);
                ANCHOR.with(|a| a.set(None));
                wall
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_anchor_scales_the_counter_within_its_span_only() {
        // a 3 GHz counter: a third of a nanosecond a tick
        let a = Anchor::new(1_000, 5_000_000_000, 1.0 / 3.0).unwrap();
        assert_eq!(a.span, 30_000_000);
        assert_eq!(a.at(1_000), Some(5_000_000_000));
        assert_eq!(a.at(1_000 + 3_000), Some(5_000_001_000));
        assert_eq!(a.at(1_000 + 29_999_999), Some(5_009_999_999));
        // past the span, or behind the anchor: the clock is read
        assert_eq!(a.at(1_000 + 30_000_000), None);
        assert_eq!(a.at(999), None);
        assert_eq!(Anchor::new(0, 0, 0.0), None);
        assert_eq!(Anchor::new(0, 0, f64::NAN), None);
    }

    #[test]
    fn the_rate_is_measured_over_the_calibration_time_at_least() {
        assert_eq!(rate((0, 0), (300_000_000, 99_999_999)), None);
        assert_eq!(rate((0, 0), (300_000_000, 100_000_000)), Some(1.0 / 3.0));
        // a counter or a clock that went back gives no rate
        assert_eq!(rate((10, 0), (5, 200_000_000)), None);
        assert_eq!(rate((0, 200_000_000), (300_000_000, 0)), None);
    }

    #[test]
    fn a_rate_is_used_once_measured_long_enough_and_measured_again_after_a_jump() {
        let origin = (1_000, 0);
        // a 1 GHz counter, 50 ms in: wait
        assert_eq!(
            measure(origin, (1_000 + 50_000_000, 50_000_000), None),
            Measured::Wait
        );
        let at = |ns: i64, ticks: u64| (1_000 + ticks, ns);
        assert_eq!(
            measure(origin, at(200_000_000, 200_000_000), None),
            Measured::Rate(1.0)
        );
        // slewed by 500 ppm: still the counter's rate
        assert_eq!(
            measure(origin, at(200_100_000, 200_000_000), Some(1.0)),
            Measured::Rate(1.0005)
        );
        // 2 % off the last measurement: the counter jumped
        assert_eq!(
            measure(origin, at(204_000_000, 200_000_000), Some(1.0)),
            Measured::Again
        );
        // behind the origin (a counter reset by a resumed host), or a rate no counter has
        assert_eq!(
            measure(origin, (500, 300_000_000), Some(1.0)),
            Measured::Again
        );
        assert_eq!(measure(origin, (500, 10), None), Measured::Again);
        assert_eq!(
            measure(origin, at(200_000_000, 2_000), None),
            Measured::Again
        );
    }

    #[test]
    fn a_stamp_follows_the_system_clock() {
        // 300 ms of stamps on one thread, past the calibration and several anchors, each between
        // two readings of the system clock (with room for the counter read out of order)
        let slack = 20_000;
        let start = read(libc::CLOCK_MONOTONIC);
        let mut previous = i64::MIN;
        let mut stamps = 0u64;
        while read(libc::CLOCK_MONOTONIC) - start < 300_000_000 && stamps < 80_000_000 {
            let before = read(libc::CLOCK_REALTIME);
            let stamp = now_ns();
            let after = read(libc::CLOCK_REALTIME);
            assert!(
                (before - slack..=after + slack).contains(&stamp),
                "stamp {stamp} not between {before} and {after}"
            );
            assert!(
                stamp >= previous.saturating_sub(slack),
                "{stamp} went back from {previous}"
            );
            previous = stamp;
            stamps += 1;
        }
        assert!(stamps > 1_000);
        // where the kernel keeps time on the counter, the stamps were scaled from it
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        if counter::on_counter() {
            assert!(counter::ANCHOR.with(std::cell::Cell::get).is_some());
        }
    }
}
