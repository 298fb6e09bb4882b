//! MAVLink frames on a wire: where each starts and ends, and why what is not a good frame is
//! refused.
//!
//! The `mavlink` crate's own readers skip whatever is not a good frame without saying what it was;
//! seabus counts every refusal by its reason, so it walks the bytes itself, one candidate at a
//! time, and asks the crate about each: a candidate starts at a MAVLink 1 or 2 start marker, its
//! length follows from its header ([`mavlink::consts`]), and the crate's raw message types give
//! its fields and check its checksum with the dialect's CRC_EXTRA ([`Dialect`]). Refusals, each a
//! [`WireError`] counted under its kind:
//!
//! | kind | what |
//! |---|---|
//! | `garbage` | bytes before a start marker, or a marker whose candidate is no frame |
//! | `truncated` | a frame cut off by the end of its datagram (skipped up to the next marker) |
//! | `bad-crc` | a whole frame whose checksum does not hold |
//! | `unknown-message` | a whole frame of a message id the dialect does not have (its checksum cannot be checked) |
//!
//! A bad candidate counts as a whole frame (skipped as one) when it ends where the next frame
//! starts or where its datagram ends; otherwise its marker is taken for garbage and the search
//! goes on from the next byte, so a good frame inside or just behind it is still found. On a byte
//! stream that means waiting for the byte after a bad candidate before judging it; a good frame is
//! delivered at once. A frame cut off on a stream cannot be told from garbage and is counted as
//! that. MAVLink 2 signatures are carried over, not checked; a MAVLink 2 header with a 32-bit
//! system id (incompatibility flag `0x02`) is three bytes longer.

use crate::dialect::{Dialect, raw};
use mavlink::consts::{self, v1, v2};
use mavlink::{MAV_STX, MAV_STX_V2, MAVLinkMessageRaw, MavlinkVersion};
use seabus_medium::WireError;

/// The longest frame: a signed MAVLink 2 frame with 255 payload bytes.
pub const MAX_FRAME: usize = consts::MAX_FRAME_SIZE;

/// What follows the bytes read so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    /// A byte stream (TCP, a serial line): more may come.
    Stream,
    /// A datagram: nothing follows.
    Datagram,
}

/// One good frame: its checksum holds for a message of the dialect.
pub struct Frame {
    /// The frame as the crate's raw message: header fields and payload.
    pub raw: MAVLinkMessageRaw,
    /// Its length in bytes on the wire.
    pub len: usize,
}

impl Frame {
    /// The frame's bytes, as they were on the wire.
    pub fn bytes(&self) -> &[u8] {
        match &self.raw {
            MAVLinkMessageRaw::V1(r) => r.raw_bytes(),
            MAVLinkMessageRaw::V2(r) => r.raw_bytes(),
        }
    }
}

/// What [`read`] found at a place in the bytes.
// a frame is handed on at once, on the stack: boxing it would cost an allocation per frame
#[allow(clippy::large_enum_variant)]
pub enum Read {
    /// A good frame.
    Frame(Frame),
    /// Bytes refused: the reason (its offset is where they start) and how many to skip.
    Rejected(WireError, usize),
    /// The bytes there may be the start of a frame: read again when more have come.
    Incomplete,
}

fn is_marker(b: u8) -> bool {
    b == MAV_STX || b == MAV_STX_V2
}

/// Garbage from `from` (inside `rest`, which starts at `at` in the input) up to the next marker.
fn garbage(rest: &[u8], at: usize, from: usize) -> Read {
    let n = from + memchr::memchr2(MAV_STX, MAV_STX_V2, &rest[from..]).unwrap_or(rest.len() - from);
    Read::Rejected(
        WireError::at(
            at,
            "garbage",
            format!("{n} bytes that are no MAVLink frame"),
        ),
        n,
    )
}

/// A candidate longer than the bytes there: on a stream, wait for more; in a datagram, a frame
/// cut off (skipped up to the next marker, where a frame may still start).
fn short(rest: &[u8], at: usize, end: End, len: usize) -> Read {
    match end {
        End::Stream => Read::Incomplete,
        End::Datagram => {
            let n = 1 + memchr::memchr2(MAV_STX, MAV_STX_V2, &rest[1..]).unwrap_or(rest.len() - 1);
            Read::Rejected(
                WireError::at(
                    at,
                    "truncated",
                    format!(
                        "a frame cut off after {} of its {len} bytes by the end of the datagram",
                        rest.len()
                    ),
                ),
                n,
            )
        }
    }
}

/// What starts at byte `at` of `buf`, for `dialect`. Every answer but [`Read::Incomplete`] skips at
/// least one byte, and none past the end of `buf`.
pub fn read(dialect: Dialect, buf: &[u8], at: usize, end: End) -> Read {
    let rest = &buf[at.min(buf.len())..];
    let Some(&start) = rest.first() else {
        return Read::Incomplete;
    };
    let version = match start {
        MAV_STX_V2 => MavlinkVersion::V2,
        MAV_STX => MavlinkVersion::V1,
        _ => return garbage(rest, at, 0),
    };
    // a MAVLink 2 header is longer when its system id takes 32 bits
    let (header, signed) = match version {
        MavlinkVersion::V2 => match rest.get(v2::INCOMPAT_FLAGS_OFFSET) {
            None => return short(rest, at, end, consts::STX_SIZE + v2::MIN_HEADER_SIZE),
            Some(flags) if flags & !v2::SUPPORTED_IFLAGS != 0 => return garbage(rest, at, 1),
            Some(flags) => (
                consts::STX_SIZE
                    + v2::MIN_HEADER_SIZE
                    + if flags & v2::IFLAG_SYSID32 != 0 {
                        v2::SYSID32_EXTRA_HEADER_SIZE
                    } else {
                        0
                    },
                flags & v2::IFLAG_SIGNED != 0,
            ),
        },
        MavlinkVersion::V1 => (consts::STX_SIZE + v1::HEADER_SIZE, false),
    };
    let Some(&payload) = rest.get(consts::PAYLOAD_LEN_OFFSET) else {
        return short(rest, at, end, header);
    };
    let len = header
        + usize::from(payload)
        + consts::CHECKSUM_SIZE
        + if signed { v2::SIGNATURE_SIZE } else { 0 };
    if rest.len() < len {
        return short(rest, at, end, len);
    }
    let raw = raw(version, &rest[..len]);
    let id = raw.message_id();
    let problem = if !dialect.knows(id) {
        Some((
            "unknown-message",
            format!("a frame of message id {id}, which the {dialect} dialect does not have"),
        ))
    } else if !dialect.checksum_holds(&raw) {
        Some((
            "bad-crc",
            format!(
                "a frame of {} whose checksum does not hold",
                dialect.message_name(id).unwrap_or("?")
            ),
        ))
    } else {
        None
    };
    match problem {
        None => Read::Frame(Frame { raw, len }),
        // a whole frame, if the next one starts right behind it
        Some((kind, detail)) => match rest.get(len) {
            Some(&next) if is_marker(next) => Read::Rejected(WireError::at(at, kind, detail), len),
            None if end == End::Datagram => Read::Rejected(WireError::at(at, kind, detail), len),
            None => Read::Incomplete,
            Some(_) => garbage(rest, at, 1),
        },
    }
}

/// Reads every frame of a byte stream as it comes, and what is not one.
#[derive(Debug, Default)]
pub struct StreamReader {
    buf: Vec<u8>,
    /// the last refusal was garbage, so that more of it is not counted again
    in_garbage: bool,
}

/// What a reader hands on.
#[allow(clippy::large_enum_variant)]
pub enum Item {
    /// A good frame.
    Frame(Frame),
    /// Bytes refused: the reason and their count; `count` is false for more of a run of garbage
    /// already counted.
    Rejected(WireError, usize, bool),
}

impl StreamReader {
    /// Takes `bytes` read from the stream and hands on each frame and refusal that is complete.
    pub fn push(&mut self, dialect: Dialect, bytes: &[u8], mut each: impl FnMut(Item)) {
        self.buf.extend_from_slice(bytes);
        let mut at = 0;
        loop {
            match read(dialect, &self.buf, at, End::Stream) {
                Read::Incomplete => break,
                Read::Frame(f) => {
                    at += f.len;
                    self.in_garbage = false;
                    each(Item::Frame(f));
                }
                Read::Rejected(e, n) => {
                    at += n;
                    let garbage = e.kind() == "garbage";
                    let count = !(garbage && self.in_garbage);
                    self.in_garbage = garbage;
                    each(Item::Rejected(e, n, count));
                }
            }
        }
        self.buf.drain(..at);
    }

    /// Bytes waiting for the rest of their frame.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Forgets what waits (the stream was lost); returns how many bytes that was.
    pub fn clear(&mut self) -> usize {
        self.in_garbage = false;
        std::mem::take(&mut self.buf).len()
    }
}

/// Hands on each frame of a datagram and each refusal (all counted).
pub fn datagram(dialect: Dialect, bytes: &[u8], mut each: impl FnMut(Item)) {
    let mut at = 0;
    while at < bytes.len() {
        match read(dialect, bytes, at, End::Datagram) {
            // a datagram's end decides every candidate
            Read::Incomplete => break,
            Read::Frame(f) => {
                at += f.len;
                each(Item::Frame(f));
            }
            Read::Rejected(e, n) => {
                at += n;
                each(Item::Rejected(e, n, true));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::MavHeader;
    use seabus_medium::DataMap;

    fn attitude(seq: u8, version: MavlinkVersion) -> Vec<u8> {
        let map = DataMap::new()
            .with("time_boot_ms", i64::from(seq))
            .with("roll", 0.1)
            .with("pitch", 0.2)
            .with("yaw", 0.3)
            .with("rollspeed", 0.0)
            .with("pitchspeed", 0.0)
            .with("yawspeed", 0.0);
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        };
        Dialect::ArduPilotMega
            .encode(version, header, "ATTITUDE", &map)
            .unwrap()
    }

    /// The frames' sequence numbers and the refusals' kinds and counts, in order.
    fn walk(bytes: &[u8], chunk: Option<usize>) -> (Vec<u8>, Vec<(String, usize)>) {
        let mut seqs = Vec::new();
        let mut refused = Vec::new();
        let mut each = |item: Item| match item {
            Item::Frame(f) => seqs.push(f.raw.sequence()),
            Item::Rejected(e, n, counted) => {
                if counted {
                    refused.push((e.kind().to_string(), n));
                } else if let Some(last) = refused.last_mut() {
                    last.1 += n;
                }
            }
        };
        match chunk {
            None => datagram(Dialect::ArduPilotMega, bytes, &mut each),
            Some(size) => {
                let mut r = StreamReader::default();
                for c in bytes.chunks(size) {
                    r.push(Dialect::ArduPilotMega, c, &mut each);
                }
                assert!(r.pending() <= MAX_FRAME);
            }
        }
        (seqs, refused)
    }

    #[test]
    fn good_frames_of_both_versions_read_whole_or_in_pieces() {
        let mut bytes = attitude(1, MavlinkVersion::V2);
        bytes.extend(attitude(2, MavlinkVersion::V1));
        bytes.extend(attitude(3, MavlinkVersion::V2));
        assert_eq!(walk(&bytes, None), (vec![1, 2, 3], vec![]));
        for size in [1, 2, 7, 64] {
            assert_eq!(walk(&bytes, Some(size)), (vec![1, 2, 3], vec![]), "{size}");
        }
    }

    #[test]
    fn each_kind_of_bad_input_is_told_and_the_next_frame_still_reads() {
        let good = attitude(1, MavlinkVersion::V2);
        let mut bad_crc = attitude(2, MavlinkVersion::V2);
        let n = bad_crc.len();
        bad_crc[n - 1] ^= 0xFF;
        // message id 16000000 is in no dialect
        let mut unknown = attitude(3, MavlinkVersion::V2);
        unknown[7..10].copy_from_slice(&16_000_000u32.to_le_bytes()[..3]);
        let garbage = b"hello, not mavlink".to_vec();
        let mut stream = Vec::new();
        for part in [&garbage, &bad_crc, &good, &unknown, &good] {
            stream.extend_from_slice(part);
        }
        let expected = (
            vec![1, 1],
            vec![
                ("garbage".to_string(), garbage.len()),
                ("bad-crc".to_string(), bad_crc.len()),
                ("unknown-message".to_string(), unknown.len()),
            ],
        );
        assert_eq!(walk(&stream, None), expected);
        for size in [1, 3, 50] {
            assert_eq!(walk(&stream, Some(size)), expected, "chunks of {size}");
        }
        // a datagram cut short
        let cut = &good[..good.len() - 5];
        assert_eq!(
            walk(cut, None),
            (vec![], vec![("truncated".to_string(), cut.len())])
        );
        // on a stream, a frame cut off by the next one is garbage, and the next one reads
        let mut stream = good[..10].to_vec();
        stream.extend(attitude(7, MavlinkVersion::V2));
        assert_eq!(
            walk(&stream, Some(4)),
            (vec![7], vec![("garbage".to_string(), 10)])
        );
    }

    #[test]
    fn a_marker_inside_garbage_does_not_swallow_the_frame_behind_it() {
        // 0xFD followed by bytes that make a long candidate overlapping the good frame
        let mut bytes = vec![0xFD, 40, 0, 0, 0, 1, 1, 30, 0, 0];
        bytes.extend(attitude(5, MavlinkVersion::V2));
        // in a datagram it runs past the end: cut off, up to the next marker
        assert_eq!(
            walk(&bytes, None),
            (vec![5], vec![("truncated".to_string(), 10)])
        );
        // on a stream it is judged once its bytes are there
        bytes.extend(attitude(6, MavlinkVersion::V2));
        for size in [1, 9, 100] {
            assert_eq!(
                walk(&bytes, Some(size)),
                (vec![5, 6], vec![("garbage".to_string(), 10)]),
                "chunks of {size}"
            );
        }
        // unsupported incompatibility flags: not a frame
        let mut flagged = attitude(6, MavlinkVersion::V2);
        flagged[2] = 0x80;
        assert_eq!(walk(&flagged, None).0, Vec::<u8>::new());
    }

    #[test]
    fn a_frame_with_a_32_bit_system_id_reads_whole() {
        let map = DataMap::new()
            .with("time_boot_ms", 1i64)
            .with("roll", 0.1)
            .with("pitch", 0.2)
            .with("yaw", 0.3)
            .with("rollspeed", 0.0)
            .with("pitchspeed", 0.0)
            .with("yawspeed", 0.0);
        let header = MavHeader {
            system_id: 70_000,
            component_id: 1,
            sequence: 4,
        };
        let mut bytes = Dialect::ArduPilotMega
            .encode(MavlinkVersion::V2, header, "ATTITUDE", &map)
            .unwrap();
        assert_eq!(bytes[2] & v2::IFLAG_SYSID32, v2::IFLAG_SYSID32);
        bytes.extend(attitude(5, MavlinkVersion::V2));
        let mut ids = Vec::new();
        datagram(Dialect::ArduPilotMega, &bytes, |i| match i {
            Item::Frame(f) => ids.push((f.raw.system_id(), f.raw.sequence())),
            Item::Rejected(e, _, _) => panic!("{e}"),
        });
        assert_eq!(ids, [(70_000, 4), (1, 5)]);
    }

    #[test]
    fn errors_say_where_in_a_datagram() {
        let mut bytes = attitude(1, MavlinkVersion::V2);
        let at = bytes.len();
        bytes.extend_from_slice(b"xyz");
        let mut errors = Vec::new();
        datagram(Dialect::Common, &bytes, |i| {
            if let Item::Rejected(e, _, _) = i {
                errors.push(e.to_string());
            }
        });
        assert_eq!(
            errors,
            [format!("byte {at}: 3 bytes that are no MAVLink frame")]
        );
    }

    #[test]
    fn every_answer_makes_progress() {
        // short random-ish inputs: every step skips at least a byte or waits
        let mut state = 0x2545_f491_u32;
        for _ in 0..2000 {
            let len = (state % 64) as usize;
            let mut bytes = Vec::with_capacity(len);
            for _ in 0..len {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                bytes.push(match state % 5 {
                    0 => MAV_STX_V2,
                    1 => MAV_STX,
                    _ => (state >> 8) as u8,
                });
            }
            let mut at = 0;
            loop {
                match read(Dialect::ArduPilotMega, &bytes, at, End::Datagram) {
                    Read::Incomplete => break,
                    Read::Frame(f) => at += f.len,
                    Read::Rejected(_, n) => {
                        assert!(n >= 1);
                        at += n;
                    }
                }
                assert!(at <= bytes.len());
            }
            assert_eq!(at, bytes.len());
        }
    }
}
