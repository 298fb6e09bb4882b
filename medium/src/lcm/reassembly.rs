//! Reassembly of fragmented LCM messages.
//!
//! Partial messages are keyed by sender and sequence number, so several senders and several
//! messages of one sender can be in flight at once, and fragments are placed by offset in any order.
//! Unlike liblcm, a fragment seen twice is ignored (it cannot "complete" a message with a hole), a
//! partial message is dropped when its fragments stop coming for the timeout, and the bytes held by
//! partial messages are capped: the oldest partial is dropped to make room. Every dropped partial
//! message is reported with its reason, for the medium to count.

use super::wire::Fragment;
use bytes::Bytes;
use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// Default time a partial message waits for its next fragment.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(2);
/// Default cap on the bytes held by partial messages (room for the largest LCM message).
pub const DEFAULT_MEMORY: usize = 300 << 20;

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
}

struct Partial {
    channel: Option<String>,
    msg_size: u32,
    count: u16,
    have: Vec<u64>,
    received: u16,
    bytes: usize,
    buf: Vec<u8>,
    started: u64,
    last: Instant,
}

impl Partial {
    fn has(&self, no: u16) -> bool {
        self.have[usize::from(no / 64)] & (1 << (no % 64)) != 0
    }

    fn dropped(&self, reason: &'static str, sender: SocketAddr, seq: u32) -> Dropped {
        Dropped {
            reason,
            sender,
            seq,
            channel: self.channel.clone(),
            fragments: (self.received, self.count),
        }
    }
}

/// Partial messages being put together.
pub struct Reassembler {
    partials: HashMap<(SocketAddr, u32), Partial>,
    held: usize,
    memory: usize,
    timeout: Duration,
    started: u64,
    /// Messages completed lately, so a fragment repeated after completion is known as a repeat.
    completed: VecDeque<(SocketAddr, u32)>,
}

/// Completed messages remembered, to recognise their repeated fragments.
const REMEMBER_COMPLETED: usize = 256;

impl Reassembler {
    /// A reassembler holding at most `memory` bytes of partial messages, each waiting at most
    /// `timeout` for its next fragment.
    pub fn new(timeout: Duration, memory: usize) -> Reassembler {
        Reassembler {
            partials: HashMap::new(),
            held: 0,
            memory,
            timeout,
            started: 0,
            completed: VecDeque::new(),
        }
    }

    /// Partial messages held now.
    pub fn pending(&self) -> usize {
        self.partials.len()
    }

    /// Bytes held by partial messages now.
    pub fn held_bytes(&self) -> usize {
        self.held
    }

    /// When the oldest-waiting partial message times out, if there is one.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.partials
            .values()
            .map(|p| p.last)
            .min()
            .map(|t| t + self.timeout)
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
            dropped.push(p.dropped("lcm-inconsistent-fragments", sender, f.seq));
        }
        if !self.partials.contains_key(&key) {
            if self.completed.contains(&key) {
                return Step::Duplicate;
            }
            let size = f.msg_size as usize;
            if size > self.memory {
                dropped.push(Dropped {
                    reason: "lcm-over-memory-cap",
                    sender,
                    seq: f.seq,
                    channel: f.channel.map(str::to_string),
                    fragments: (1, f.count),
                });
                return Step::Pending;
            }
            while self.held + size > self.memory {
                let Some(oldest) = self
                    .partials
                    .iter()
                    .min_by_key(|(_, p)| p.started)
                    .map(|(k, _)| *k)
                else {
                    break;
                };
                let p = self.remove(&oldest);
                dropped.push(p.dropped("lcm-over-memory-cap", oldest.0, oldest.1));
            }
            self.started += 1;
            self.held += size;
            self.partials.insert(
                key,
                Partial {
                    channel: None,
                    msg_size: f.msg_size,
                    count: f.count,
                    have: vec![0; usize::from(f.count).div_ceil(64)],
                    received: 0,
                    bytes: 0,
                    buf: vec![0; size],
                    started: self.started,
                    last: now,
                },
            );
        }
        let Some(p) = self.partials.get_mut(&key) else {
            return Step::Pending;
        };
        if p.has(f.no) {
            return Step::Duplicate;
        }
        p.have[usize::from(f.no / 64)] |= 1 << (f.no % 64);
        p.received += 1;
        p.last = now;
        let at = f.offset as usize;
        // the packet parser checked that the data lies inside the message
        p.buf[at..at + f.data.len()].copy_from_slice(f.data);
        p.bytes += f.data.len();
        if let Some(c) = f.channel {
            p.channel = Some(c.to_string());
        }
        if p.received < p.count {
            return Step::Pending;
        }
        let p = self.remove(&key);
        if self.completed.len() == REMEMBER_COMPLETED {
            self.completed.pop_front();
        }
        self.completed.push_back(key);
        let Some(channel) = p.channel.clone() else {
            dropped.push(p.dropped("lcm-fragments-overlap", sender, f.seq));
            return Step::Pending;
        };
        if p.bytes != p.msg_size as usize {
            // every fragment came but they overlap, leaving a hole
            dropped.push(p.dropped("lcm-fragments-overlap", sender, f.seq));
            return Step::Pending;
        }
        Step::Complete {
            seq: f.seq,
            channel,
            payload: Bytes::from(p.buf),
        }
    }

    /// Drops the partial messages whose next fragment is overdue at `now`.
    pub fn expire(&mut self, now: Instant, dropped: &mut Vec<Dropped>) {
        let timeout = self.timeout;
        let overdue: Vec<_> = self
            .partials
            .iter()
            .filter(|(_, p)| now.duration_since(p.last) >= timeout)
            .map(|(k, _)| *k)
            .collect();
        for key in overdue {
            let p = self.remove(&key);
            dropped.push(p.dropped("lcm-fragment-timeout", key.0, key.1));
        }
    }

    fn remove(&mut self, key: &(SocketAddr, u32)) -> Partial {
        match self.partials.remove(key) {
            Some(p) => {
                self.held -= p.buf.len();
                p
            }
            None => unreachable!("removing a partial message that is held"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lcm::wire::{self, Packet};

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
    fn missing_fragments_time_out_and_are_reported() {
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
        // a late fragment starts a new partial, which never completes without the others
        assert_eq!(feed(&mut r, t0, addr(1), &f[1]).0, Step::Pending);
    }

    #[test]
    fn memory_cap_drops_the_oldest_partial() {
        let now = Instant::now();
        let mut r = Reassembler::new(DEFAULT_TIMEOUT, 250_000);
        let one = frags(1, "X", &payload(140_000, 4));
        let two = frags(2, "X", &payload(140_000, 5));
        feed(&mut r, now, addr(1), &one[0]);
        let (_, dropped) = feed(&mut r, now, addr(1), &two[0]);
        assert_eq!(dropped.len(), 1);
        assert_eq!(
            (dropped[0].reason, dropped[0].seq),
            ("lcm-over-memory-cap", 1)
        );
        // the second still completes
        feed(&mut r, now, addr(1), &two[1]);
        assert!(matches!(
            feed(&mut r, now, addr(1), &two[2]).0,
            Step::Complete { seq: 2, .. }
        ));
        // a message larger than the cap is refused outright
        let big = frags(3, "X", &payload(300_000, 6));
        let (_, dropped) = feed(&mut r, now, addr(1), &big[0]);
        assert_eq!(dropped[0].reason, "lcm-over-memory-cap");
        assert_eq!(r.held_bytes(), 0);
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
    }
}
