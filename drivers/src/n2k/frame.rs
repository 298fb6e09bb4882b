//! NMEA 2000 frames: the 29-bit identifier ([`Header`]) and the reassembly of messages longer
//! than a frame ([`Assembler`]).
//!
//! An identifier holds, from the top: the priority (3 bits), the extended data page (1 bit, 0 in
//! NMEA 2000), the data page (1 bit), the PDU format PF (8 bits), the PDU specific PS (8 bits)
//! and the source address (8 bits). With PF below 240 (PDU1) the message is addressed: PS is the
//! destination and the PGN's low byte is 0; from 240 (PDU2) it goes to everyone (destination
//! 255) and PS is the PGN's low byte.
//!
//! **Fast packets** carry up to 223 bytes in up to 32 frames: the first byte of each frame holds
//! a sequence number (3 bits) and the frame's number (5 bits); the first frame gives the length,
//! then 6 bytes; every other frame 7. The assembler keeps one message under way for each sender,
//! PGN and destination, so that senders (and one sender's PGNs) interleave freely. A message is
//! dropped, never stitched wrong, when a frame is missing (`n2k-fast-packet-lost-frame`), comes
//! out of order (`n2k-fast-packet-out-of-order`), belongs to another sequence
//! (`n2k-fast-packet-sequence`), is short (`n2k-fast-packet-short-frame`), or when no frame comes
//! for [`Limits::timeout`] (`n2k-fast-packet-timeout`, default 750 ms); a first frame while a
//! message is under way starts the new one (`n2k-fast-packet-interrupted` for the old); a frame
//! whose first frame was never seen is counted once for its message (`n2k-fast-packet-no-start`).
//! At most [`Limits::max_partial`] messages are under way: past that the one heard from longest
//! ago is dropped (`n2k-fast-packet-overflow`).
//!
//! **ISO transport protocol**: a broadcast announce (TP.CM BAM) or a request to send (TP.CM RTS)
//! opens a session between a sender and a destination; its data frames (TP.DT, numbered from 1)
//! carry 7 bytes each, up to 1785 bytes. A session is dropped when a frame is missing or out of
//! order (`n2k-tp-lost-frame`), on an abort (`n2k-tp-aborted`), a new announce
//! (`n2k-tp-interrupted`) or a time-out (`n2k-tp-timeout`); data without a session is
//! `n2k-tp-no-start`.
//!
//! Frames that are not NMEA 2000 are counted too: 11-bit identifiers (`n2k-standard-id`), remote
//! frames (`n2k-remote-frame`), more than 8 bytes (`n2k-long-frame`), the extended data page set
//! (`n2k-extended-data-page`).

use super::pgn::Packet;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::time::Duration;
use tokio::time::Instant;

/// The PGN of the transport protocol's connection management (TP.CM).
pub const TP_CM: u32 = 60416;
/// The PGN of the transport protocol's data transfer (TP.DT).
pub const TP_DT: u32 = 60160;
/// The destination meaning everyone.
pub const GLOBAL: u8 = 255;
/// The longest fast-packet message.
pub const FAST_MAX: usize = 223;
/// The longest transport-protocol message.
pub const TP_MAX: usize = 1785;

/// What a 29-bit identifier says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// 0 (highest) to 7.
    pub priority: u8,
    /// The parameter group number.
    pub pgn: u32,
    /// The sender's address.
    pub source: u8,
    /// The addressee ([`GLOBAL`] for everyone).
    pub destination: u8,
}

impl Header {
    /// Reads an identifier (its bits above 29 are ignored).
    pub fn from_id(id: u32) -> Header {
        let pf = (id >> 16) & 0xFF;
        let ps = ((id >> 8) & 0xFF) as u8;
        let page = (id >> 24) & 0x3;
        let (pgn, destination) = if pf < 240 {
            ((page << 16) | (pf << 8), ps)
        } else {
            ((page << 16) | (pf << 8) | u32::from(ps), GLOBAL)
        };
        Header {
            priority: ((id >> 26) & 0x7) as u8,
            pgn,
            source: (id & 0xFF) as u8,
            destination,
        }
    }

    /// The identifier of this header (the destination is in it only for PDU1 PGNs).
    pub fn id(&self) -> u32 {
        let pf = (self.pgn >> 8) & 0xFF;
        let ps = if pf < 240 {
            u32::from(self.destination)
        } else {
            self.pgn & 0xFF
        };
        (u32::from(self.priority & 7) << 26)
            | ((self.pgn >> 16 & 0x3) << 24)
            | (pf << 16)
            | (ps << 8)
            | u32::from(self.source)
    }
}

/// A whole message: a single frame's data, or a reassembled one's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Message {
    /// Its header (a reassembled message's is its first frame's).
    pub header: Header,
    /// Its data.
    pub data: Vec<u8>,
}

/// A frame or message refused, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rejection {
    /// The reason, a counter's name (`n2k-fast-packet-lost-frame`).
    pub reason: &'static str,
    /// What was wrong, for the log.
    pub detail: String,
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.reason, self.detail)
    }
}

/// How long and how many messages the assembler keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// A message under way is dropped when no frame of it comes for this long.
    pub timeout: Duration,
    /// Most messages under way at once.
    pub max_partial: usize,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            timeout: Duration::from_millis(750),
            max_partial: 128,
        }
    }
}

/// A message under way.
#[derive(Debug)]
struct Partial {
    header: Header,
    /// fast packet: the sequence number; transport protocol: unused
    seq: u8,
    /// the number of the frame expected next
    next: u8,
    total: usize,
    data: Vec<u8>,
    last: Instant,
    /// the message was dropped: its other frames are taken quietly
    dropping: bool,
    /// fast packet, dropped: the sequences whose frames are taken quietly (a bit each)
    quiet: u8,
}

/// Which kind of message is under way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Key {
    /// A fast packet from a sender, of a PGN, to a destination.
    Fast(u8, u32, u8),
    /// A transport-protocol session from a sender to a destination.
    Tp(u8, u8),
}

/// Turns frames into whole messages (see the module's documentation), counting what it drops.
#[derive(Debug)]
pub struct Assembler {
    limits: Limits,
    partial: HashMap<Key, Partial>,
    counts: BTreeMap<&'static str, u64>,
    rejected: Vec<Rejection>,
}

impl Assembler {
    /// An assembler with these limits.
    pub fn new(limits: Limits) -> Assembler {
        Assembler {
            limits,
            partial: HashMap::new(),
            counts: BTreeMap::new(),
            rejected: Vec::new(),
        }
    }

    /// Counts of what was refused, by reason.
    pub fn counts(&self) -> &BTreeMap<&'static str, u64> {
        &self.counts
    }

    /// The rejections since the last call, oldest first.
    pub fn take_rejections(&mut self) -> Vec<Rejection> {
        std::mem::take(&mut self.rejected)
    }

    /// How many messages are under way (dropped ones whose frames are still taken included).
    pub fn under_way(&self) -> usize {
        self.partial.len()
    }

    fn reject(&mut self, reason: &'static str, detail: String) {
        *self.counts.entry(reason).or_default() += 1;
        // kept for the caller to log; a caller that never takes them keeps only the latest
        if self.rejected.len() >= 256 {
            self.rejected.remove(0);
        }
        self.rejected.push(Rejection { reason, detail });
    }

    /// Takes one frame: its identifier (`extended`: 29-bit), data and whether it is a remote
    /// frame; `packet` says how a PGN travels. Returns the message it completes, if any.
    pub fn push(
        &mut self,
        id: u32,
        extended: bool,
        remote: bool,
        data: &[u8],
        packet: impl Fn(u32) -> Packet,
        now: Instant,
    ) -> Option<Message> {
        if !extended {
            self.reject(
                "n2k-standard-id",
                format!("an 11-bit identifier {id:03x}: NMEA 2000 frames have 29"),
            );
            return None;
        }
        if remote {
            self.reject("n2k-remote-frame", format!("a remote frame {id:08x}"));
            return None;
        }
        if data.len() > 8 {
            self.reject(
                "n2k-long-frame",
                format!(
                    "{id:08x}: {} bytes; an NMEA 2000 frame has at most 8",
                    data.len()
                ),
            );
            return None;
        }
        if id & 0x0200_0000 != 0 {
            self.reject(
                "n2k-extended-data-page",
                format!("{id:08x}: the extended data page bit is set"),
            );
            return None;
        }
        let header = Header::from_id(id);
        match header.pgn {
            TP_CM => self.tp_cm(header, data, now),
            TP_DT => self.tp_dt(header, data, now),
            pgn if packet(pgn) == Packet::Fast => self.fast(header, data, now),
            _ => Some(Message {
                header,
                data: data.to_vec(),
            }),
        }
    }

    /// Drops the messages no frame came for within the time-out, counting them.
    pub fn expire(&mut self, now: Instant) {
        let timeout = self.limits.timeout;
        let stale: Vec<Key> = self
            .partial
            .iter()
            .filter(|(_, p)| now.saturating_duration_since(p.last) > timeout)
            .map(|(k, _)| *k)
            .collect();
        for k in stale {
            if let Some(p) = self.partial.remove(&k)
                && !p.dropping
            {
                let (reason, what) = match k {
                    Key::Fast(..) => ("n2k-fast-packet-timeout", "fast packet"),
                    Key::Tp(..) => ("n2k-tp-timeout", "transport session"),
                };
                self.reject(
                    reason,
                    format!(
                        "{what} of PGN {} from {}: {} of {} bytes, then nothing for {} ms",
                        p.header.pgn,
                        p.header.source,
                        p.data.len(),
                        p.total,
                        timeout.as_millis()
                    ),
                );
            }
        }
    }

    /// Drops the message under way for `key` (if it times out first, that is counted), so
    /// that the frames after it are taken quietly.
    fn drop_message(&mut self, key: Key, now: Instant) {
        if let Some(p) = self.partial.get_mut(&key) {
            p.dropping = true;
            p.quiet |= 1 << (p.seq & 7);
            p.last = now;
        }
    }

    /// Makes room for one more message under way.
    fn room(&mut self, now: Instant) {
        self.expire(now);
        while self.partial.len() >= self.limits.max_partial.max(1) {
            let Some(oldest) = self
                .partial
                .iter()
                .min_by_key(|(_, p)| (!p.dropping, p.last))
                .map(|(k, _)| *k)
            else {
                return;
            };
            if let Some(p) = self.partial.remove(&oldest)
                && !p.dropping
            {
                self.reject(
                    "n2k-fast-packet-overflow",
                    format!(
                        "{} messages under way: PGN {} from {} dropped for a new one",
                        self.limits.max_partial, p.header.pgn, p.header.source
                    ),
                );
            }
        }
    }

    /// A message under way whose time is up is counted and dropped before its key is used.
    fn expire_one(&mut self, key: Key, now: Instant) {
        if self
            .partial
            .get(&key)
            .is_some_and(|p| now.saturating_duration_since(p.last) > self.limits.timeout)
        {
            self.expire(now);
        }
    }

    fn fast(&mut self, header: Header, data: &[u8], now: Instant) -> Option<Message> {
        let from = |h: &Header| format!("PGN {} from {}", h.pgn, h.source);
        let Some(&first) = data.first() else {
            self.reject(
                "n2k-fast-packet-short-frame",
                format!("{}: an empty frame", from(&header)),
            );
            return None;
        };
        let (seq, frame) = (first >> 5, first & 0x1F);
        let key = Key::Fast(header.source, header.pgn, header.destination);
        self.expire_one(key, now);
        if frame == 0 {
            let Some(&total) = data.get(1) else {
                self.reject(
                    "n2k-fast-packet-short-frame",
                    format!("{}: a first frame without the length", from(&header)),
                );
                return None;
            };
            let total = usize::from(total);
            if let Some(p) = self.partial.remove(&key)
                && !p.dropping
            {
                self.reject(
                    "n2k-fast-packet-interrupted",
                    format!(
                        "{}: a new message began with {} of {} bytes of sequence {} received",
                        from(&header),
                        p.data.len(),
                        p.total,
                        p.seq
                    ),
                );
            }
            if total == 0 || total > FAST_MAX {
                self.reject(
                    "n2k-fast-packet-bad-length",
                    format!("{}: a length of {total} bytes (1 to 223)", from(&header)),
                );
                return None;
            }
            let chunk = &data[2..];
            if chunk.len() >= total {
                return Some(Message {
                    header,
                    data: chunk[..total].to_vec(),
                });
            }
            if data.len() < 8 {
                self.reject(
                    "n2k-fast-packet-short-frame",
                    format!(
                        "{}: a first frame of {} bytes with more to come",
                        from(&header),
                        data.len()
                    ),
                );
                return None;
            }
            self.room(now);
            let mut buf = Vec::with_capacity(total);
            buf.extend_from_slice(chunk);
            self.partial.insert(
                key,
                Partial {
                    header,
                    seq,
                    next: 1,
                    total,
                    data: buf,
                    last: now,
                    dropping: false,
                    quiet: 0,
                },
            );
            return None;
        }
        let Some(p) = self.partial.get_mut(&key) else {
            // the first frame was not heard: count the message once, take its other frames quietly
            self.reject(
                "n2k-fast-packet-no-start",
                format!(
                    "{}: frame {frame} of sequence {seq} without its first frame",
                    from(&header)
                ),
            );
            self.room(now);
            self.partial.insert(
                key,
                Partial {
                    header,
                    seq,
                    next: frame.wrapping_add(1),
                    total: 0,
                    data: Vec::new(),
                    last: now,
                    dropping: true,
                    quiet: 1 << (seq & 7),
                },
            );
            return None;
        };
        if p.dropping {
            p.last = now;
            if p.quiet & (1 << seq) != 0 {
                return None;
            }
            // another message whose first frame was not heard
            p.quiet |= 1 << seq;
            self.reject(
                "n2k-fast-packet-no-start",
                format!(
                    "{}: frame {frame} of sequence {seq} without its first frame",
                    from(&header)
                ),
            );
            return None;
        }
        if p.seq != seq {
            let detail = format!(
                "{}: frame {frame} of sequence {seq} while sequence {} was at frame {} \
                 ({} of {} bytes): dropped",
                from(&header),
                p.seq,
                p.next,
                p.data.len(),
                p.total
            );
            // the old message is lost, and the new one's start was not heard
            p.quiet |= 1 << seq;
            self.reject("n2k-fast-packet-sequence", detail);
            self.drop_message(key, now);
            return None;
        }
        if frame != p.next {
            let reason = if frame > p.next {
                "n2k-fast-packet-lost-frame"
            } else {
                "n2k-fast-packet-out-of-order"
            };
            let detail = format!(
                "{}: frame {frame} where frame {} was due ({} of {} bytes): dropped",
                from(&header),
                p.next,
                p.data.len(),
                p.total
            );
            self.reject(reason, detail);
            self.drop_message(key, now);
            return None;
        }
        let left = p.total - p.data.len();
        let chunk = &data[1..];
        if chunk.len() < left.min(7) {
            let detail = format!(
                "{}: frame {frame} of {} bytes where {} were due: dropped",
                from(&header),
                data.len(),
                left.min(7) + 1
            );
            self.reject("n2k-fast-packet-short-frame", detail);
            self.drop_message(key, now);
            return None;
        }
        p.data.extend_from_slice(&chunk[..left.min(7)]);
        p.next = p.next.wrapping_add(1);
        p.last = now;
        if p.data.len() < p.total {
            return None;
        }
        let p = self.partial.remove(&key)?;
        Some(Message {
            header: p.header,
            data: p.data,
        })
    }

    fn tp_cm(&mut self, header: Header, data: &[u8], now: Instant) -> Option<Message> {
        if data.len() < 8 {
            self.reject(
                "n2k-tp-short-frame",
                format!(
                    "a connection frame of {} bytes from {}",
                    data.len(),
                    header.source
                ),
            );
            return None;
        }
        let control = data[0];
        let pgn = u32::from(data[5]) | u32::from(data[6]) << 8 | u32::from(data[7]) << 16;
        let key = Key::Tp(header.source, header.destination);
        match control {
            // RTS and BAM open a session; CTS and end-of-message come from the receiver
            16 | 32 => {
                self.expire_one(key, now);
                let size = usize::from(u16::from_le_bytes([data[1], data[2]]));
                let packets = usize::from(data[3]);
                if let Some(p) = self.partial.remove(&key)
                    && !p.dropping
                {
                    self.reject(
                        "n2k-tp-interrupted",
                        format!(
                            "PGN {} from {} to {}: a new session began with {} of {} bytes received",
                            p.header.pgn,
                            header.source,
                            header.destination,
                            p.data.len(),
                            p.total
                        ),
                    );
                }
                if !(9..=TP_MAX).contains(&size) || packets != size.div_ceil(7) {
                    self.reject(
                        "n2k-tp-bad-announce",
                        format!(
                            "PGN {pgn} from {}: {size} bytes in {packets} packets",
                            header.source
                        ),
                    );
                    return None;
                }
                self.room(now);
                self.partial.insert(
                    key,
                    Partial {
                        header: Header { pgn, ..header },
                        seq: 0,
                        next: 1,
                        total: size,
                        data: Vec::with_capacity(size),
                        last: now,
                        dropping: false,
                        quiet: 0,
                    },
                );
            }
            255 => {
                // either side may abort
                for k in [key, Key::Tp(header.destination, header.source)] {
                    if let Some(p) = self.partial.remove(&k)
                        && !p.dropping
                    {
                        self.reject(
                            "n2k-tp-aborted",
                            format!(
                                "PGN {} between {} and {}: aborted with reason {}",
                                p.header.pgn, header.source, header.destination, data[1]
                            ),
                        );
                    }
                }
            }
            _ => {}
        }
        None
    }

    fn tp_dt(&mut self, header: Header, data: &[u8], now: Instant) -> Option<Message> {
        let key = Key::Tp(header.source, header.destination);
        self.expire_one(key, now);
        let Some(p) = self.partial.get_mut(&key) else {
            self.reject(
                "n2k-tp-no-start",
                format!(
                    "data from {} to {} without a session",
                    header.source, header.destination
                ),
            );
            self.room(now);
            self.partial.insert(
                key,
                Partial {
                    header,
                    seq: 0,
                    next: 0,
                    total: 0,
                    data: Vec::new(),
                    last: now,
                    dropping: true,
                    quiet: 0,
                },
            );
            return None;
        };
        if p.dropping {
            p.last = now;
            return None;
        }
        let at = data.first().copied().unwrap_or(0);
        if data.len() < 8 || at != p.next {
            let detail = format!(
                "PGN {} from {} to {}: packet {at} ({} bytes) where packet {} was due: dropped",
                p.header.pgn,
                header.source,
                header.destination,
                data.len(),
                p.next
            );
            self.reject("n2k-tp-lost-frame", detail);
            self.drop_message(key, now);
            return None;
        }
        let left = p.total - p.data.len();
        p.data.extend_from_slice(&data[1..1 + left.min(7)]);
        p.next = p.next.wrapping_add(1);
        p.last = now;
        if p.data.len() < p.total {
            return None;
        }
        let p = self.partial.remove(&key)?;
        Some(Message {
            header: p.header,
            data: p.data,
        })
    }
}

/// The frames of a fast-packet message of sequence `seq` (0–7), as canboat and the standard
/// write them: the first with the length and 6 bytes, the others with 7, the last padded with
/// 0xFF.
pub fn fast_frames(seq: u8, data: &[u8]) -> Vec<Vec<u8>> {
    let data = &data[..data.len().min(FAST_MAX)];
    let mut out = Vec::new();
    let mut first = vec![(seq & 7) << 5, data.len() as u8];
    first.extend_from_slice(&data[..data.len().min(6)]);
    first.resize(8, 0xFF);
    out.push(first);
    for (i, chunk) in data.get(6..).unwrap_or(&[]).chunks(7).enumerate() {
        let mut f = vec![((seq & 7) << 5) | ((i + 1) as u8 & 0x1F)];
        f.extend_from_slice(chunk);
        f.resize(8, 0xFF);
        out.push(f);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fast(_: u32) -> Packet {
        Packet::Fast
    }

    /// An identifier: priority 3, `pgn` from `src` (PDU2, or PDU1 to `dst`).
    fn id(pgn: u32, src: u8, dst: u8) -> u32 {
        Header {
            priority: 3,
            pgn,
            source: src,
            destination: dst,
        }
        .id()
    }

    fn message(len: usize, salt: u8) -> Vec<u8> {
        (0..len).map(|i| (i as u8).wrapping_mul(7) ^ salt).collect()
    }

    #[test]
    fn identifiers_give_priority_pgn_source_and_destination() {
        // PDU2: vessel heading from 35, priority 2
        let h = Header::from_id(0x09F1_1223);
        assert_eq!(
            h,
            Header {
                priority: 2,
                pgn: 127250,
                source: 0x23,
                destination: GLOBAL
            }
        );
        assert_eq!(h.id(), 0x09F1_1223);
        // PDU1: ISO request (59904 = 0xEA00) to 0x42 from 0x05
        let h = Header::from_id(0x18EA_4205);
        assert_eq!(
            (h.priority, h.pgn, h.source, h.destination),
            (6, 59904, 5, 0x42)
        );
        assert_eq!(h.id(), 0x18EA_4205);
        // PDU1 on data page 1: 126208 (0x1ED00) to 0x10
        let h = Header::from_id(0x0DED_1001);
        assert_eq!((h.pgn, h.destination), (126208, 0x10));
        assert_eq!(h.id(), 0x0DED_1001);
        // ISO address claim to everyone
        assert_eq!(Header::from_id(0x18EE_FF19).pgn, 60928);
    }

    #[test]
    fn frames_that_are_not_nmea_2000_are_counted() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        assert!(a.push(0x123, false, false, &[1], fast, now).is_none());
        assert!(a.push(0x09F1_1223, true, true, &[], fast, now).is_none());
        assert!(
            a.push(0x09F1_1223, true, false, &[0; 12], fast, now)
                .is_none()
        );
        assert!(
            a.push(0x0BF1_1223, true, false, &[0; 8], fast, now)
                .is_none()
        );
        let counts: Vec<(&str, u64)> = a.counts().iter().map(|(k, v)| (*k, *v)).collect();
        assert_eq!(
            counts,
            [
                ("n2k-extended-data-page", 1),
                ("n2k-long-frame", 1),
                ("n2k-remote-frame", 1),
                ("n2k-standard-id", 1)
            ]
        );
        // a single-frame PGN is its frame
        let single = |_| Packet::Single;
        let m = a
            .push(0x09F1_1223, true, false, &[1, 2, 3], single, now)
            .unwrap();
        assert_eq!((m.header.pgn, m.data), (127250, vec![1, 2, 3]));
    }

    #[test]
    fn a_fast_packet_is_reassembled() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let data = message(43, 0);
        let frames = fast_frames(2, &data);
        assert_eq!(frames.len(), 7);
        assert_eq!(frames[0][..2], [0x40, 43]);
        assert_eq!(frames[6][0], 0x46);
        let mut got = None;
        for f in &frames {
            assert!(got.is_none(), "complete before the last frame");
            got = a.push(id(129029, 7, 255), true, false, f, fast, now);
        }
        let m = got.expect("the message");
        assert_eq!((m.header.pgn, m.header.source, m.data), (129029, 7, data));
        assert!(a.counts().is_empty());
        assert_eq!(a.under_way(), 0);
        // a message that fits the first frame
        let m = a
            .push(
                id(127489, 7, 255),
                true,
                false,
                &[0x20, 3, 9, 8, 7, 0xFF, 0xFF, 0xFF],
                fast,
                now,
            )
            .unwrap();
        assert_eq!(m.data, [9, 8, 7]);
    }

    #[test]
    fn two_senders_interleave() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let (d1, d2) = (message(40, 1), message(26, 2));
        let (f1, f2) = (fast_frames(1, &d1), fast_frames(5, &d2));
        let mut done = Vec::new();
        for i in 0..f1.len().max(f2.len()) {
            for (src, frames) in [(10u8, &f1), (11u8, &f2)] {
                if let Some(f) = frames.get(i)
                    && let Some(m) = a.push(id(129029, src, 255), true, false, f, fast, now)
                {
                    done.push((m.header.source, m.data));
                }
            }
        }
        assert_eq!(done, [(11, d2), (10, d1)]);
        assert!(a.counts().is_empty(), "{:?}", a.counts());
        // one sender's two PGNs interleave as well
        let (g1, g2) = (
            fast_frames(0, &message(20, 3)),
            fast_frames(0, &message(20, 4)),
        );
        let mut n = 0;
        for (x, y) in g1.iter().zip(&g2) {
            n += usize::from(
                a.push(id(129029, 10, 255), true, false, x, fast, now)
                    .is_some(),
            );
            n += usize::from(
                a.push(id(127489, 10, 255), true, false, y, fast, now)
                    .is_some(),
            );
        }
        assert_eq!(n, 2);
    }

    #[test]
    fn a_lost_frame_drops_the_message_and_is_counted_once() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let frames = fast_frames(3, &message(43, 0));
        for (i, f) in frames.iter().enumerate() {
            if i == 2 {
                continue;
            }
            assert!(
                a.push(id(129029, 7, 255), true, false, f, fast, now)
                    .is_none()
            );
        }
        assert_eq!(a.counts().get("n2k-fast-packet-lost-frame"), Some(&1));
        assert_eq!(a.counts().len(), 1, "{:?}", a.counts());
        let r = a.take_rejections();
        assert!(
            r[0].detail.contains("frame 3 where frame 2 was due"),
            "{}",
            r[0]
        );
        // the next message from the same sender arrives whole
        let data = message(43, 9);
        let got: Vec<Message> = fast_frames(4, &data)
            .iter()
            .filter_map(|f| a.push(id(129029, 7, 255), true, false, f, fast, now))
            .collect();
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].data, data);
        assert_eq!(a.counts().values().sum::<u64>(), 1);
    }

    #[test]
    fn out_of_order_and_foreign_sequences_are_never_stitched() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let frames = fast_frames(1, &message(30, 0));
        let push =
            |a: &mut Assembler, f: &[u8]| a.push(id(129029, 7, 255), true, false, f, fast, now);
        // frames 0, 2, 1, 3, 4: dropped at frame 2
        for i in [0, 2, 1, 3, 4] {
            assert!(push(&mut a, &frames[i]).is_none());
        }
        assert_eq!(a.counts().get("n2k-fast-packet-lost-frame"), Some(&1));
        // frame 0, 1, 1 again: a repeated frame is out of order
        let frames = fast_frames(2, &message(30, 1));
        for i in [0, 1, 1, 2, 3, 4] {
            assert!(push(&mut a, &frames[i]).is_none());
        }
        assert_eq!(a.counts().get("n2k-fast-packet-out-of-order"), Some(&1));
        // a frame of another sequence in the middle
        let (x, y) = (
            fast_frames(3, &message(30, 2)),
            fast_frames(4, &message(30, 3)),
        );
        assert!(push(&mut a, &x[0]).is_none());
        assert!(push(&mut a, &x[1]).is_none());
        assert!(push(&mut a, &y[2]).is_none());
        assert!(push(&mut a, &x[2]).is_none());
        assert_eq!(a.counts().get("n2k-fast-packet-sequence"), Some(&1));
        // continuation frames without a first frame: one count per message
        let z = fast_frames(5, &message(30, 4));
        for f in &z[1..] {
            assert!(push(&mut a, f).is_none());
        }
        assert_eq!(a.counts().get("n2k-fast-packet-no-start"), Some(&1));
        let total: u64 = a.counts().values().sum();
        assert_eq!(total, 4, "{:?}", a.counts());
    }

    #[test]
    fn a_new_sequence_restarts_cleanly() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let push =
            |a: &mut Assembler, f: &[u8]| a.push(id(129029, 7, 255), true, false, f, fast, now);
        let old = fast_frames(6, &message(43, 0));
        assert!(push(&mut a, &old[0]).is_none());
        assert!(push(&mut a, &old[1]).is_none());
        // the sender starts again (a new sequence) before finishing
        let data = message(43, 5);
        let new = fast_frames(7, &data);
        let got: Vec<Message> = new.iter().filter_map(|f| push(&mut a, f)).collect();
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].data, data);
        assert_eq!(a.counts().get("n2k-fast-packet-interrupted"), Some(&1));
        // the sequence counter wraps from 7 to 0
        let data = message(43, 6);
        let got: Vec<Message> = fast_frames(0, &data)
            .iter()
            .filter_map(|f| push(&mut a, f))
            .collect();
        assert_eq!(got[0].data, data);
        assert_eq!(a.counts().values().sum::<u64>(), 1);
    }

    #[test]
    fn a_silent_sender_times_out() {
        let mut a = Assembler::new(Limits::default());
        let t0 = Instant::now();
        let frames = fast_frames(1, &message(43, 0));
        let push = |a: &mut Assembler, f: &[u8], ms: u64| {
            a.push(
                id(129029, 7, 255),
                true,
                false,
                f,
                fast,
                t0 + Duration::from_millis(ms),
            )
        };
        assert!(push(&mut a, &frames[0], 0).is_none());
        assert!(push(&mut a, &frames[1], 700).is_none());
        // 700 ms between frames is within the time-out
        assert!(a.counts().is_empty());
        a.expire(t0 + Duration::from_millis(1400));
        assert!(a.counts().is_empty());
        a.expire(t0 + Duration::from_millis(1451));
        assert_eq!(a.counts().get("n2k-fast-packet-timeout"), Some(&1));
        assert_eq!(a.under_way(), 0);
        // the rest of the message comes too late: its first frame was not heard (for this message)
        assert!(push(&mut a, &frames[2], 1500).is_none());
        assert_eq!(a.counts().get("n2k-fast-packet-no-start"), Some(&1));
        // a frame after a long silence, without expire being called, counts the time-out first
        let mut b = Assembler::new(Limits::default());
        let push = |b: &mut Assembler, f: &[u8], ms: u64| {
            b.push(
                id(129029, 8, 255),
                true,
                false,
                f,
                fast,
                t0 + Duration::from_millis(ms),
            )
        };
        assert!(push(&mut b, &frames[0], 0).is_none());
        assert!(push(&mut b, &frames[1], 800).is_none());
        assert_eq!(b.counts().get("n2k-fast-packet-timeout"), Some(&1));
    }

    #[test]
    fn partial_messages_are_bounded() {
        let mut a = Assembler::new(Limits {
            max_partial: 4,
            ..Limits::default()
        });
        let t0 = Instant::now();
        let first = &fast_frames(0, &message(43, 0))[0];
        for src in 0..10u8 {
            let t = t0 + Duration::from_millis(u64::from(src));
            assert!(
                a.push(id(129029, src, 255), true, false, first, fast, t)
                    .is_none()
            );
            assert!(a.under_way() <= 4);
        }
        assert_eq!(a.counts().get("n2k-fast-packet-overflow"), Some(&6));
        // the newest are the ones kept: sender 9 completes
        let rest = fast_frames(0, &message(43, 0));
        let got: Vec<Message> = rest[1..]
            .iter()
            .filter_map(|f| a.push(id(129029, 9, 255), true, false, f, fast, t0))
            .collect();
        assert_eq!(got.len(), 1);
    }

    #[test]
    fn bad_lengths_and_short_frames_are_counted() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let push =
            |a: &mut Assembler, f: &[u8]| a.push(id(129029, 7, 255), true, false, f, fast, now);
        assert!(push(&mut a, &[]).is_none());
        assert!(push(&mut a, &[0x00]).is_none());
        assert!(push(&mut a, &[0x00, 0, 1, 2, 3, 4, 5, 6]).is_none());
        assert!(push(&mut a, &[0x00, 224, 1, 2, 3, 4, 5, 6]).is_none());
        assert!(push(&mut a, &[0x00, 20, 1, 2]).is_none());
        assert_eq!(a.counts().get("n2k-fast-packet-short-frame"), Some(&3));
        assert_eq!(a.counts().get("n2k-fast-packet-bad-length"), Some(&2));
        // a middle frame cut short
        assert!(push(&mut a, &[0x20, 20, 1, 2, 3, 4, 5, 6]).is_none());
        assert!(push(&mut a, &[0x21, 1, 2]).is_none());
        assert_eq!(a.counts().get("n2k-fast-packet-short-frame"), Some(&4));
    }

    #[test]
    fn transport_protocol_sessions_are_reassembled() {
        let mut a = Assembler::new(Limits::default());
        let now = Instant::now();
        let single = |_| Packet::Single;
        let data = message(20, 7);
        // BAM of PGN 126464 (0x1EE00), 20 bytes in 3 packets, from 9 to everyone
        let cm = [32, 20, 0, 3, 0xFF, 0x00, 0xEE, 0x01];
        assert!(
            a.push(id(TP_CM, 9, 255), true, false, &cm, single, now)
                .is_none()
        );
        let mut got = None;
        for (i, chunk) in data.chunks(7).enumerate() {
            let mut f = vec![i as u8 + 1];
            f.extend_from_slice(chunk);
            f.resize(8, 0xFF);
            got = a.push(id(TP_DT, 9, 255), true, false, &f, single, now);
        }
        let m = got.expect("the message");
        assert_eq!(
            (m.header.pgn, m.header.source, m.data),
            (126464, 9, data.clone())
        );
        // a lost packet drops the session
        assert!(
            a.push(id(TP_CM, 9, 255), true, false, &cm, single, now)
                .is_none()
        );
        let mut f = vec![2];
        f.extend_from_slice(&data[7..14]);
        assert!(
            a.push(id(TP_DT, 9, 255), true, false, &f, single, now)
                .is_none()
        );
        assert_eq!(a.counts().get("n2k-tp-lost-frame"), Some(&1));
        // an abort, and data without a session
        let rts = [16, 20, 0, 3, 3, 0x00, 0xEE, 0x01];
        assert!(
            a.push(id(TP_CM, 9, 4), true, false, &rts, single, now)
                .is_none()
        );
        let abort = [255, 1, 0xFF, 0xFF, 0xFF, 0x00, 0xEE, 0x01];
        assert!(
            a.push(id(TP_CM, 4, 9), true, false, &abort, single, now)
                .is_none()
        );
        assert_eq!(a.counts().get("n2k-tp-aborted"), Some(&1));
        assert!(
            a.push(id(TP_DT, 9, 4), true, false, &f, single, now)
                .is_none()
        );
        assert_eq!(a.counts().get("n2k-tp-no-start"), Some(&1));
        let bad = [32, 20, 0, 9, 0xFF, 0x00, 0xEE, 0x01];
        assert!(
            a.push(id(TP_CM, 9, 255), true, false, &bad, single, now)
                .is_none()
        );
        assert_eq!(a.counts().get("n2k-tp-bad-announce"), Some(&1));
    }
}
