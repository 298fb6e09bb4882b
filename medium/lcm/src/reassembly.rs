//! Reassembly of fragmented LCM messages.
//!
//! Partial messages are keyed by sender and sequence number, so several senders and several
//! messages of one sender can be in flight at once, and fragments are placed by offset in any order.
//! Unlike liblcm, a fragment seen twice is ignored, a message completes only when its fragments
//! cover every byte exactly once (overlapping fragments cannot "complete" it with a hole), and a
//! partial message is dropped when its fragments stop coming for the timeout.
//!
//! What partial messages hold is bounded: their bytes (payload buffer, fragment bookkeeping and
//! [`PARTIAL_OVERHEAD`] each) are capped, and so is their number, overall ([`MAX_PARTIALS`]) and
//! per sender ([`MAX_PARTIALS_PER_SENDER`]). A new message that does not fit is refused, unless
//! room can be made by dropping partial messages that have stalled (no fragment for a quarter of
//! the timeout, longest idle first): a message still receiving fragments is never dropped for a
//! newcomer, so two large messages over the cap cannot keep dropping each other, and one of them
//! completes. Every message given up (timed out, dropped, refused, inconsistent) is reported once,
//! with its reason, for the medium to count; its later fragments are dropped quietly.
//!
//! Deadlines are kept in a heap, so expiring partial messages costs in proportion to those that
//! expire, not to those held.

use super::wire::Fragment;
use bytes::Bytes;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, VecDeque};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// Default time a partial message waits for its next fragment.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(2);
/// Default cap on the bytes held by partial messages (room for the largest LCM message).
pub const DEFAULT_MEMORY: usize = 300 << 20;
/// Most partial messages held at once, from all senders.
pub const MAX_PARTIALS: usize = 4096;
/// Most partial messages held at once from one sender.
pub const MAX_PARTIALS_PER_SENDER: usize = 256;
/// Bytes counted for each partial message besides its buffers: its table entry, its deadline and
/// what it remembers of the message.
pub const PARTIAL_OVERHEAD: usize = 256;
/// Messages completed or given up that are remembered, so that their later fragments are known.
const REMEMBER: usize = 4096;

/// A partial message that was given up, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Dropped {
    /// The reason, the key it is counted under.
    pub reason: &'static str,
    /// Who sent it.
    pub sender: SocketAddr,
    /// Its sequence number.
    pub seq: u32,
    /// Its channel, when fragment 0 had come.
    pub channel: Option<String>,
    /// Fragments received, of how many.
    pub fragments: (u16, u16),
}

impl std::fmt::Display for Dropped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "partial message {} from {} on {} dropped ({}): {} of {} fragments",
            self.seq,
            self.sender,
            self.channel.as_deref().unwrap_or("an unknown channel"),
            self.reason,
            self.fragments.0,
            self.fragments.1
        )
    }
}

/// What a fragment led to.
#[derive(Debug, PartialEq, Eq)]
pub enum Step {
    /// The message is complete.
    Complete {
        /// Its sequence number.
        seq: u32,
        /// Its channel.
        channel: String,
        /// Its bytes.
        payload: Bytes,
    },
    /// More fragments are needed.
    Pending,
    /// The fragment was seen before and is ignored.
    Duplicate,
    /// The fragment's message was given up, and reported when it was (possibly just now, for the
    /// fragment that would have started it); the fragment is dropped.
    GivenUp,
}

/// A partial message's key: who sent it and its sequence number.
type Key = (SocketAddr, u32);

struct Partial {
    /// Tells this partial message from an earlier one under the same key.
    id: u64,
    channel: Option<String>,
    msg_size: u32,
    count: u16,
    /// One bit per fragment received.
    have: Vec<u64>,
    /// Where each fragment received goes: offset and length.
    pieces: Vec<(u32, u32)>,
    buf: Vec<u8>,
    /// Bytes counted against the cap.
    cost: usize,
    last: Instant,
}

impl Partial {
    fn has(&self, no: u16) -> bool {
        self.have
            .get(usize::from(no / 64))
            .is_some_and(|w| w & (1 << (no % 64)) != 0)
    }

    fn received(&self) -> u16 {
        // at most `count` fragments are placed, and count is a u16
        u16::try_from(self.pieces.len()).unwrap_or(u16::MAX)
    }

    fn dropped(&self, reason: &'static str, (sender, seq): Key) -> Dropped {
        Dropped {
            reason,
            sender,
            seq,
            channel: self.channel.clone(),
            fragments: (self.received(), self.count),
        }
    }

    /// True when the pieces cover the message exactly once.
    fn covered(&mut self) -> bool {
        self.pieces.sort_unstable();
        let mut end = 0u64;
        for &(offset, len) in &self.pieces {
            if u64::from(offset) != end {
                return false;
            }
            end += u64::from(len);
        }
        end == u64::from(self.msg_size)
    }
}

/// Bytes a partial message of `msg_size` bytes in `count` fragments is counted for.
fn cost(msg_size: u32, count: u16) -> usize {
    let count = usize::from(count);
    msg_size as usize
        + count.div_ceil(64) * std::mem::size_of::<u64>()
        + count * std::mem::size_of::<(u32, u32)>()
        + PARTIAL_OVERHEAD
}

/// How a message remembered ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Completed,
    GivenUp,
}

/// A message completed or given up lately.
struct Remembered {
    outcome: Outcome,
    msg_size: u32,
    count: u16,
    /// When one of its fragments last came.
    last: Instant,
    id: u64,
}

/// Partial messages being put together.
pub struct Reassembler {
    partials: HashMap<Key, Partial>,
    /// Partial messages held per sender.
    per_sender: HashMap<SocketAddr, usize>,
    /// Each partial message's deadline as it was when pushed (earlier than or at its true one),
    /// with its id; entries of partial messages gone stay until they come to the top.
    deadlines: BinaryHeap<Reverse<(Instant, u64, Key)>>,
    held: usize,
    memory: usize,
    timeout: Duration,
    next_id: u64,
    /// Messages completed or given up lately, so that their later fragments are known.
    recent: HashMap<Key, Remembered>,
    /// The keys of `recent`, oldest first, with the time they were last seen as pushed and their
    /// id; entries of keys forgotten or remembered again stay until they come to the front.
    recent_order: VecDeque<(Instant, Key, u64)>,
}

impl Reassembler {
    /// A reassembler holding at most `memory` bytes of partial messages, each waiting at most
    /// `timeout` for its next fragment.
    pub fn new(timeout: Duration, memory: usize) -> Reassembler {
        Reassembler {
            partials: HashMap::new(),
            per_sender: HashMap::new(),
            deadlines: BinaryHeap::new(),
            held: 0,
            memory,
            timeout,
            next_id: 0,
            recent: HashMap::new(),
            recent_order: VecDeque::new(),
        }
    }

    /// Partial messages held now.
    pub fn pending(&self) -> usize {
        self.partials.len()
    }

    /// Bytes held by partial messages now, as counted against the cap.
    pub fn held_bytes(&self) -> usize {
        self.held
    }

    /// When the partial message idle longest times out, or a little earlier; `None` when none is
    /// held.
    pub fn next_deadline(&self) -> Option<Instant> {
        if self.partials.is_empty() {
            return None;
        }
        self.deadlines.peek().map(|Reverse((at, _, _))| *at)
    }

    /// Takes one fragment from `sender`; messages given up on the way are pushed on `dropped`.
    pub fn fragment(
        &mut self,
        now: Instant,
        sender: SocketAddr,
        f: &Fragment<'_>,
        dropped: &mut Vec<Dropped>,
    ) -> Step {
        let key = (sender, f.seq);
        if let Some(p) = self.partials.get(&key)
            && (p.msg_size != f.msg_size || p.count != f.count)
        {
            // the sequence number was reused for another message: the old one cannot complete
            let p = self.remove(&key);
            dropped.push(p.dropped("lcm-inconsistent-fragments", key));
        }
        if !self.partials.contains_key(&key) {
            if let Some(r) = self.recent.get_mut(&key) {
                if r.msg_size == f.msg_size && r.count == f.count {
                    r.last = now;
                    return match r.outcome {
                        Outcome::Completed => Step::Duplicate,
                        Outcome::GivenUp => Step::GivenUp,
                    };
                }
                // another message under the same key
                self.recent.remove(&key);
            }
            if let Err(reason) = self.admit(now, key, f, dropped) {
                dropped.push(Dropped {
                    reason,
                    sender,
                    seq: f.seq,
                    channel: f.channel.map(str::to_string),
                    fragments: (1, f.count),
                });
                self.remember(now, key, f.msg_size, f.count, Outcome::GivenUp);
                return Step::GivenUp;
            }
        }
        let Some(p) = self.partials.get_mut(&key) else {
            return Step::Pending;
        };
        if p.has(f.no) {
            return Step::Duplicate;
        }
        if let Some(w) = p.have.get_mut(usize::from(f.no / 64)) {
            *w |= 1 << (f.no % 64);
        }
        p.last = now;
        let at = f.offset as usize;
        // the packet parser checked that the data lies inside the message
        if let Some(dest) = p.buf.get_mut(at..at + f.data.len()) {
            dest.copy_from_slice(f.data);
        }
        // the data fits the message, whose size is a u32
        p.pieces.push((f.offset, f.data.len() as u32));
        if let Some(c) = f.channel {
            p.channel = Some(c.to_string());
        }
        if p.pieces.len() < usize::from(p.count) {
            return Step::Pending;
        }
        let mut p = self.remove(&key);
        let whole = p.covered();
        match p.channel.take() {
            Some(channel) if whole => {
                self.remember(now, key, p.msg_size, p.count, Outcome::Completed);
                Step::Complete {
                    seq: f.seq,
                    channel,
                    payload: Bytes::from(p.buf),
                }
            }
            channel => {
                // every fragment came, but they overlap, leaving a hole (fragment 0 brings the
                // channel, so by now there is one)
                p.channel = channel;
                self.remember(now, key, p.msg_size, p.count, Outcome::GivenUp);
                dropped.push(p.dropped("lcm-fragments-overlap", key));
                Step::GivenUp
            }
        }
    }

    /// Makes room for a new partial message under `key` and adds it, or says why not.
    fn admit(
        &mut self,
        now: Instant,
        key: Key,
        f: &Fragment<'_>,
        dropped: &mut Vec<Dropped>,
    ) -> Result<(), &'static str> {
        let cost = cost(f.msg_size, f.count);
        if cost > self.memory {
            return Err("lcm-over-memory-cap");
        }
        if self.per_sender.get(&key.0).copied().unwrap_or(0) >= MAX_PARTIALS_PER_SENDER {
            return Err("lcm-too-many-partials");
        }
        loop {
            let reason = if self.held + cost > self.memory {
                "lcm-over-memory-cap"
            } else if self.partials.len() >= MAX_PARTIALS {
                "lcm-too-many-partials"
            } else {
                break;
            };
            let Some(stalled) = self.stalled(now) else {
                return Err(reason);
            };
            let p = self.remove(&stalled);
            dropped.push(p.dropped(reason, stalled));
            self.remember(now, stalled, p.msg_size, p.count, Outcome::GivenUp);
        }
        self.next_id += 1;
        let id = self.next_id;
        self.held += cost;
        *self.per_sender.entry(key.0).or_insert(0) += 1;
        self.deadlines.push(Reverse((now + self.timeout, id, key)));
        let count = usize::from(f.count);
        self.partials.insert(
            key,
            Partial {
                id,
                channel: None,
                msg_size: f.msg_size,
                count: f.count,
                have: vec![0; count.div_ceil(64)],
                pieces: Vec::with_capacity(count),
                buf: vec![0; f.msg_size as usize],
                cost,
                last: now,
            },
        );
        Ok(())
    }

    /// The partial message idle longest, if it has had no fragment for a quarter of the timeout.
    fn stalled(&mut self, now: Instant) -> Option<Key> {
        let key = self.settle()?;
        let last = self.partials.get(&key)?.last;
        (now.saturating_duration_since(last) >= self.timeout / 4).then_some(key)
    }

    /// Brings the partial message idle longest to the top of the deadlines with its true
    /// deadline, dropping entries of partial messages gone on the way; its key.
    fn settle(&mut self) -> Option<Key> {
        while let Some(&Reverse((at, id, key))) = self.deadlines.peek() {
            match self.partials.get(&key) {
                Some(p) if p.id == id => {
                    let due = p.last + self.timeout;
                    if due == at {
                        return Some(key);
                    }
                    self.deadlines.pop();
                    self.deadlines.push(Reverse((due, id, key)));
                }
                _ => {
                    self.deadlines.pop();
                }
            }
        }
        None
    }

    /// Drops the partial messages whose next fragment is overdue at `now`, and forgets messages
    /// whose fragments stopped coming long enough ago. Costs in proportion to what it drops.
    pub fn expire(&mut self, now: Instant, dropped: &mut Vec<Dropped>) {
        while let Some(&Reverse((at, _, _))) = self.deadlines.peek() {
            if at > now {
                break;
            }
            let Some(key) = self.settle() else {
                break;
            };
            let Some(p) = self.partials.get(&key) else {
                break;
            };
            if p.last + self.timeout > now {
                break;
            }
            let p = self.remove(&key);
            dropped.push(p.dropped("lcm-fragment-timeout", key));
            self.remember(now, key, p.msg_size, p.count, Outcome::GivenUp);
        }
        while let Some(&(at, key, id)) = self.recent_order.front() {
            if at + self.timeout > now {
                break;
            }
            self.recent_order.pop_front();
            let Some(r) = self.recent.get(&key).filter(|r| r.id == id) else {
                continue;
            };
            if r.last + self.timeout > now {
                // seen since: remembered from then
                self.recent_order.push_back((r.last, key, id));
            } else {
                self.recent.remove(&key);
            }
        }
    }

    /// Remembers how the message under `key` ended.
    fn remember(&mut self, now: Instant, key: Key, msg_size: u32, count: u16, outcome: Outcome) {
        self.next_id += 1;
        let id = self.next_id;
        self.recent.insert(
            key,
            Remembered {
                outcome,
                msg_size,
                count,
                last: now,
                id,
            },
        );
        self.recent_order.push_back((now, key, id));
        while self.recent.len() > REMEMBER || self.recent_order.len() > 2 * REMEMBER {
            let Some((_, key, id)) = self.recent_order.pop_front() else {
                break;
            };
            if self.recent.get(&key).is_some_and(|r| r.id == id) {
                self.recent.remove(&key);
            }
        }
    }

    fn remove(&mut self, key: &Key) -> Partial {
        let Some(p) = self.partials.remove(key) else {
            unreachable!("removing a partial message that is held")
        };
        self.held -= p.cost;
        if let Some(n) = self.per_sender.get_mut(&key.0) {
            *n -= 1;
            if *n == 0 {
                self.per_sender.remove(&key.0);
            }
        }
        if self.partials.is_empty() {
            self.deadlines.clear();
        } else if self.deadlines.len() > 2 * self.partials.len() + 1024 {
            // mostly entries of partial messages gone: keep only the live ones
            let live = self
                .partials
                .iter()
                .map(|(k, p)| Reverse((p.last + self.timeout, p.id, *k)));
            self.deadlines = live.collect();
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{self, Packet};

    fn frags(seq: u32, channel: &str, payload: &[u8]) -> Vec<Vec<u8>> {
        wire::encode(seq, channel, payload).unwrap()
    }

    fn feed(r: &mut Reassembler, now: Instant, from: SocketAddr, d: &[u8]) -> (Step, Vec<Dropped>) {
        let Packet::Fragment(f) = wire::parse(d).unwrap() else {
            panic!("not a fragment")
        };
        let mut dropped = Vec::new();
        (r.fragment(now, from, &f, &mut dropped), dropped)
    }

    fn addr(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    fn payload(n: usize, salt: u8) -> Vec<u8> {
        (0..n).map(|i| (i as u8).wrapping_mul(31) ^ salt).collect()
    }

    #[test]
    fn any_order_duplicates_and_two_senders_interleaved() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        let a = payload(200_000, 1);
        let b = payload(150_000, 2);
        let mut fa = frags(5, "A", &a);
        let fb = frags(5, "B", &b);
        fa.reverse();
        let mut done = Vec::new();
        let mut dups = 0;
        for (i, d) in fa.iter().enumerate() {
            for (from, d) in [(addr(1), d), (addr(1), d)]
                .into_iter()
                .chain(fb.get(i).map(|x| (addr(2), x)))
            {
                match feed(&mut r, now, from, d) {
                    (
                        Step::Complete {
                            channel, payload, ..
                        },
                        _,
                    ) => done.push((channel, payload)),
                    (Step::Duplicate, _) => dups += 1,
                    (Step::Pending, dropped) => assert!(dropped.is_empty()),
                    (Step::GivenUp, dropped) => panic!("given up: {dropped:?}"),
                }
            }
        }
        assert_eq!(
            dups,
            fa.len(),
            "every repeated fragment, also after completion"
        );
        done.sort();
        assert_eq!(
            done,
            vec![
                ("A".to_string(), Bytes::from(a)),
                ("B".to_string(), Bytes::from(b))
            ]
        );
        assert_eq!((r.pending(), r.held_bytes()), (0, 0));
    }

    #[test]
    fn missing_fragments_time_out_and_are_reported_once() {
        let t0 = Instant::now();
        let mut r = Reassembler::new(Duration::from_millis(100), DEFAULT_MEMORY);
        let f = frags(9, "CAM", &payload(140_000, 3));
        assert_eq!(feed(&mut r, t0, addr(1), &f[0]).0, Step::Pending);
        assert_eq!(feed(&mut r, t0, addr(1), &f[2]).0, Step::Pending);
        assert_eq!(r.next_deadline(), Some(t0 + Duration::from_millis(100)));
        let mut dropped = Vec::new();
        r.expire(t0 + Duration::from_millis(99), &mut dropped);
        assert!(dropped.is_empty());
        r.expire(t0 + Duration::from_millis(100), &mut dropped);
        assert_eq!(dropped.len(), 1);
        assert_eq!(dropped[0].reason, "lcm-fragment-timeout");
        assert_eq!(dropped[0].channel.as_deref(), Some("CAM"));
        assert_eq!(dropped[0].fragments, (2, 3));
        assert_eq!((r.pending(), r.held_bytes()), (0, 0));
        assert_eq!(r.next_deadline(), None);
        // a late fragment is dropped quietly: it starts nothing, and the message is not counted
        // again
        let late = t0 + Duration::from_millis(150);
        assert_eq!(feed(&mut r, late, addr(1), &f[1]), (Step::GivenUp, vec![]));
        assert_eq!((r.pending(), r.held_bytes()), (0, 0));
        // once its fragments have stopped for the timeout, the message is forgotten
        r.expire(late + Duration::from_millis(100), &mut dropped);
        assert_eq!(dropped.len(), 1);
        assert_eq!(r.recent.len(), 0);
    }

    #[test]
    fn the_deadline_follows_the_partial_idle_longest() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let timeout = ms(100);
        let mut r = Reassembler::new(timeout, DEFAULT_MEMORY);
        let a = frags(1, "A", &payload(140_000, 1));
        let b = frags(2, "B", &payload(140_000, 2));
        feed(&mut r, t0, addr(1), &a[0]);
        feed(&mut r, t0 + ms(10), addr(1), &b[0]);
        feed(&mut r, t0 + ms(50), addr(1), &a[1]);
        // A's first deadline passes without dropping it: it had a fragment since
        let mut dropped = Vec::new();
        r.expire(t0 + ms(100), &mut dropped);
        assert!(dropped.is_empty());
        assert_eq!(r.next_deadline(), Some(t0 + ms(110)), "B's");
        r.expire(t0 + ms(110), &mut dropped);
        assert_eq!(dropped.len(), 1);
        assert_eq!(dropped[0].seq, 2);
        assert_eq!(r.next_deadline(), Some(t0 + ms(150)), "A's");
        r.expire(t0 + ms(150), &mut dropped);
        assert_eq!(dropped.len(), 2);
        assert_eq!(r.next_deadline(), None);
    }

    #[test]
    fn a_message_in_progress_is_not_dropped_for_a_newcomer() {
        // two 700 kB messages under a 1 MB cap, their fragments interleaved: the first completes,
        // the second is refused and counted once
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, 1_000_000);
        let a = payload(700_000, 4);
        let fa = frags(1, "A", &a);
        let fb = frags(2, "B", &payload(700_000, 5));
        let mut done = Vec::new();
        let mut all_dropped = Vec::new();
        for (x, y) in fa.iter().zip(&fb) {
            for d in [x, y] {
                let (step, dropped) = feed(&mut r, now, addr(1), d);
                all_dropped.extend(dropped);
                if let Step::Complete { seq, payload, .. } = step {
                    done.push((seq, payload));
                }
            }
        }
        assert_eq!(done, vec![(1, Bytes::from(a))]);
        assert_eq!(all_dropped.len(), 1, "{all_dropped:?}");
        assert_eq!(
            (all_dropped[0].reason, all_dropped[0].seq),
            ("lcm-over-memory-cap", 2)
        );
        assert_eq!((r.pending(), r.held_bytes()), (0, 0));
    }

    #[test]
    fn a_stalled_partial_makes_room_for_a_newcomer() {
        let t0 = Instant::now();
        let timeout = Duration::from_millis(400);
        let mut r = Reassembler::new(timeout, 1_000_000);
        let fa = frags(1, "A", &payload(700_000, 6));
        let b = payload(700_000, 7);
        let fb = frags(2, "B", &b);
        feed(&mut r, t0, addr(1), &fa[0]);
        // A has had nothing for a quarter of the timeout: B takes its room
        let later = t0 + timeout / 4;
        let (step, dropped) = feed(&mut r, later, addr(1), &fb[0]);
        assert_eq!(step, Step::Pending);
        assert_eq!(dropped.len(), 1);
        assert_eq!(
            (dropped[0].reason, dropped[0].seq),
            ("lcm-over-memory-cap", 1)
        );
        let mut done = None;
        for (x, y) in fa.iter().zip(&fb).skip(1) {
            // A's late fragments are dropped quietly, without taking B's room back
            assert_eq!(feed(&mut r, later, addr(1), x), (Step::GivenUp, vec![]));
            let (step, dropped) = feed(&mut r, later, addr(1), y);
            assert!(dropped.is_empty());
            if let Step::Complete { payload, .. } = step {
                done = Some(payload);
            }
        }
        assert_eq!(done, Some(Bytes::from(b)));
    }

    #[test]
    fn a_message_over_the_cap_is_counted_once() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, 250_000);
        let big = frags(3, "X", &payload(300_000, 6));
        let mut all_dropped = Vec::new();
        for d in &big {
            let (step, dropped) = feed(&mut r, now, addr(1), d);
            assert_eq!(step, Step::GivenUp);
            all_dropped.extend(dropped);
        }
        assert_eq!(all_dropped.len(), 1, "{all_dropped:?}");
        assert_eq!(all_dropped[0].reason, "lcm-over-memory-cap");
        assert_eq!(r.held_bytes(), 0);
    }

    #[test]
    fn bookkeeping_counts_against_the_cap() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        let f = frags(1, "X", &payload(140_000, 1));
        feed(&mut r, now, addr(1), &f[0]);
        // the payload, one bitmap word, three pieces and the overhead
        assert_eq!(r.held_bytes(), 140_000 + 8 + 3 * 8 + PARTIAL_OVERHEAD);
    }

    /// A fragment of a message of `msg_size` bytes in `count` fragments that carries nothing.
    fn empty(seq: u32, msg_size: u32, count: u16) -> Fragment<'static> {
        Fragment {
            seq,
            msg_size,
            offset: 0,
            no: count - 1,
            count,
            channel: None,
            data: &[],
        }
    }

    #[test]
    fn cheap_fragments_cannot_pile_up_partials() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        let mut dropped = Vec::new();
        // one sender, a new sequence number each: at most its share
        for seq in 0..1000 {
            r.fragment(now, addr(1), &empty(seq, 65_534, 65_535), &mut dropped);
        }
        assert_eq!(r.pending(), MAX_PARTIALS_PER_SENDER);
        assert_eq!(dropped.len(), 1000 - MAX_PARTIALS_PER_SENDER);
        assert!(dropped.iter().all(|d| d.reason == "lcm-too-many-partials"));
        // bitmaps and pieces are counted: 8 kB and 512 kB a message
        assert_eq!(
            r.held_bytes(),
            MAX_PARTIALS_PER_SENDER * (65_534 + 1024 * 8 + 65_535 * 8 + PARTIAL_OVERHEAD)
        );
        // a refused message's later fragments are not counted again
        let again = dropped.len();
        r.fragment(now, addr(1), &empty(999, 65_534, 65_535), &mut dropped);
        assert_eq!(dropped.len(), again);
        // many senders: at most the overall number, and the memory cap
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        for port in 0..100u16 {
            for seq in 0..100 {
                r.fragment(now, addr(port), &empty(seq, 1000, 2), &mut dropped);
            }
        }
        assert_eq!(r.pending(), MAX_PARTIALS);
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, 10 << 20);
        for port in 0..100u16 {
            for seq in 0..10 {
                r.fragment(now, addr(port), &empty(seq, 65_534, 65_535), &mut dropped);
            }
        }
        assert!(r.held_bytes() <= 10 << 20);
        assert_eq!(r.pending(), (10 << 20) / cost(65_534, 65_535));
    }

    #[test]
    fn overlapping_fragments_do_not_complete_with_a_hole() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        let data = payload(300, 1);
        let piece = |no: u16, offset: u32| Fragment {
            seq: 1,
            msg_size: 300,
            offset,
            no,
            count: 3,
            channel: (no == 0).then_some("X"),
            data: &data[offset as usize..offset as usize + 100],
        };
        let mut dropped = Vec::new();
        // 0..100, 50..150 and 200..300: 300 bytes, but 150..200 never came
        for (no, offset) in [(0, 0), (1, 50)] {
            assert_eq!(
                r.fragment(now, addr(1), &piece(no, offset), &mut dropped),
                Step::Pending
            );
        }
        assert_eq!(
            r.fragment(now, addr(1), &piece(2, 200), &mut dropped),
            Step::GivenUp
        );
        assert_eq!(dropped.len(), 1);
        assert_eq!(dropped[0].reason, "lcm-fragments-overlap");
        // the same, tiling the message, completes
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        for (no, offset) in [(2, 200), (0, 0)] {
            assert_eq!(
                r.fragment(now, addr(1), &piece(no, offset), &mut dropped),
                Step::Pending
            );
        }
        assert_eq!(
            r.fragment(now, addr(1), &piece(1, 100), &mut dropped),
            Step::Complete {
                seq: 1,
                channel: "X".into(),
                payload: Bytes::from(data.clone())
            }
        );
    }

    #[test]
    fn a_reused_sequence_number_drops_the_old_partial() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, DEFAULT_MEMORY);
        let old = frags(4, "X", &payload(140_000, 7));
        let new = frags(4, "X", &payload(70_000, 8));
        feed(&mut r, now, addr(1), &old[0]);
        let (_, dropped) = feed(&mut r, now, addr(1), &new[0]);
        assert_eq!(dropped[0].reason, "lcm-inconsistent-fragments");
        assert!(matches!(
            feed(&mut r, now, addr(1), &new[1]).0,
            Step::Complete { .. }
        ));
        // and once complete, another message under the key is not taken for a repeat
        let third = frags(4, "X", &payload(140_000, 9));
        assert_eq!(feed(&mut r, now, addr(1), &third[0]).0, Step::Pending);
    }
}
