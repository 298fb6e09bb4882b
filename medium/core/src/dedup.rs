//! Duplicate detection by provenance: one sliding window of sequence numbers per origin.
//!
//! Every interface and every bridge keeps a [`Dedup`]. A message whose (origin, sequence number)
//! was already seen inside the window is a duplicate; one older than the whole window is late.
//! Both are dropped and counted. A node that restarts draws a new boot number, hence a new origin, so
//! its fresh sequence numbers are never mistaken for old ones.

use crate::message::Message;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Sequence numbers remembered per origin.
pub const WINDOW: u64 = 1024;
/// Origins remembered at once; the least recently seen is forgotten first.
pub const MAX_ORIGINS: usize = 4096;

const WORDS: usize = (WINDOW / 64) as usize;

/// The verdict on one message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seen {
    /// First time seen.
    New,
    /// Seen before, inside the window.
    Duplicate,
    /// Older than the window: cannot be told apart from a duplicate, so it is dropped.
    Late,
}

#[derive(Clone)]
struct Window {
    highest: u64,
    /// ring of seen flags: bit `seq % WINDOW` for the sequence numbers in `(highest - WINDOW, highest]`
    bits: [u64; WORDS],
    last_use: u64,
}

impl Window {
    fn new(seq: u64, now: u64) -> Window {
        let mut w = Window {
            highest: seq,
            bits: [0u64; WORDS],
            last_use: now,
        };
        w.set(seq);
        w
    }

    fn slot(seq: u64) -> (usize, u64) {
        let i = seq % WINDOW;
        ((i / 64) as usize, 1 << (i % 64))
    }

    fn set(&mut self, seq: u64) {
        let (w, b) = Window::slot(seq);
        self.bits[w] |= b;
    }

    /// The verdict on `seq` without recording it.
    fn peek(&self, seq: u64) -> Seen {
        if seq > self.highest {
            return Seen::New;
        }
        if self.highest - seq >= WINDOW {
            return Seen::Late;
        }
        let (w, b) = Window::slot(seq);
        if self.bits[w] & b != 0 {
            Seen::Duplicate
        } else {
            Seen::New
        }
    }

    fn check(&mut self, seq: u64) -> Seen {
        let verdict = self.peek(seq);
        if verdict != Seen::New {
            return verdict;
        }
        if seq > self.highest {
            self.advance(seq);
        }
        self.set(seq);
        Seen::New
    }

    /// Moves the window's top to `seq`, forgetting the flags of the numbers that fall out of it.
    fn advance(&mut self, seq: u64) {
        let n = seq - self.highest;
        if n >= WINDOW {
            self.bits = [0; WORDS];
        } else {
            // clear ring positions highest+1 ..= seq, a word at a time
            let mut from = (self.highest + 1) % WINDOW;
            let mut left = n;
            while left > 0 {
                let (w, bit) = ((from / 64) as usize, from % 64);
                let span = (64 - bit).min(left);
                let mask = if span == 64 {
                    u64::MAX
                } else {
                    ((1u64 << span) - 1) << bit
                };
                self.bits[w] &= !mask;
                left -= span;
                from = (from + span) % WINDOW;
            }
        }
        self.highest = seq;
    }
}

/// A hasher for keys that are already hashes (origin ids).
#[derive(Default)]
struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = self.0.rotate_left(8) ^ u64::from(*b);
        }
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = n;
    }
}

/// Per-origin duplicate detection.
#[derive(Default)]
pub struct Dedup {
    windows: HashMap<u64, Window, BuildHasherDefault<IdHasher>>,
    clock: u64,
}

impl Dedup {
    /// An empty table.
    pub fn new() -> Dedup {
        Dedup::default()
    }

    /// Records `msg` and says whether it is new.
    pub fn check(&mut self, msg: &Message) -> Seen {
        self.check_raw(msg.provenance.origin.id, msg.provenance.seq)
    }

    /// Records (origin id, sequence number) and says whether it is new.
    pub fn check_raw(&mut self, origin: u64, seq: u64) -> Seen {
        self.clock += 1;
        let now = self.clock;
        if let Some(w) = self.windows.get_mut(&origin) {
            w.last_use = now;
            return w.check(seq);
        }
        if self.windows.len() >= MAX_ORIGINS {
            self.forget_oldest_half();
        }
        self.windows.insert(origin, Window::new(seq, now));
        Seen::New
    }

    /// The verdict on (origin id, sequence number) without recording it.
    pub fn peek_raw(&self, origin: u64, seq: u64) -> Seen {
        self.windows.get(&origin).map_or(Seen::New, |w| w.peek(seq))
    }

    /// Forgets the least recently seen half of the origins at once, so that a stream of new origins
    /// costs a scan only every [`MAX_ORIGINS`]` / 2` of them.
    fn forget_oldest_half(&mut self) {
        let mut uses: Vec<u64> = self.windows.values().map(|w| w.last_use).collect();
        let mid = uses.len() / 2;
        let (_, median, _) = uses.select_nth_unstable(mid);
        let cut = *median;
        self.windows.retain(|_, w| w.last_use > cut);
    }

    /// Origins currently remembered.
    pub fn origins(&self) -> usize {
        self.windows.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicates_inside_the_window_are_caught_in_any_order() {
        let mut d = Dedup::new();
        let order = [5u64, 3, 4, 1, 2, 7, 6, 900, 10, 8, 9];
        for s in order {
            assert_eq!(d.check_raw(1, s), Seen::New, "{s}");
        }
        for s in order {
            assert_eq!(d.check_raw(1, s), Seen::Duplicate, "{s}");
        }
        assert_eq!(
            d.check_raw(2, 5),
            Seen::New,
            "another origin is independent"
        );
    }

    #[test]
    fn the_window_slides() {
        let mut d = Dedup::new();
        assert_eq!(d.check_raw(1, 1), Seen::New);
        assert_eq!(d.check_raw(1, 1 + WINDOW), Seen::New);
        assert_eq!(d.check_raw(1, 1), Seen::Late);
        assert_eq!(d.check_raw(1, 2), Seen::New);
        assert_eq!(d.check_raw(1, 2), Seen::Duplicate);
        // a big jump clears everything
        assert_eq!(d.check_raw(1, 10 * WINDOW), Seen::New);
        assert_eq!(d.check_raw(1, 10 * WINDOW - 1), Seen::New);
    }

    #[test]
    fn shifting_across_word_boundaries_keeps_bits() {
        let mut d = Dedup::new();
        for s in 1..=200u64 {
            assert_eq!(d.check_raw(9, s), Seen::New);
        }
        for jump in [63u64, 64, 65, 130] {
            let top = 200 + jump;
            assert_eq!(d.check_raw(9, top), Seen::New);
            for s in (top.saturating_sub(WINDOW - 1)).max(1)..=200 {
                assert_eq!(d.check_raw(9, s), Seen::Duplicate, "jump {jump} seq {s}");
            }
            d = Dedup::new();
            for s in 1..=200u64 {
                d.check_raw(9, s);
            }
        }
    }

    #[test]
    fn origins_are_bounded() {
        let mut d = Dedup::new();
        for o in 0..(MAX_ORIGINS as u64 + 10) {
            d.check_raw(o, 1);
        }
        assert!(
            d.origins() <= MAX_ORIGINS && d.origins() > MAX_ORIGINS / 2 - 10,
            "{}",
            d.origins()
        );
        // the most recent ones are remembered
        assert_eq!(d.check_raw(MAX_ORIGINS as u64 + 9, 1), Seen::Duplicate);
        assert_eq!(d.peek_raw(MAX_ORIGINS as u64 + 9, 2), Seen::New);
    }
}
