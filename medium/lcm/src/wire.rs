//! LCM's UDP multicast packets, byte for byte as liblcm writes and reads them.
//!
//! ```text
//! short (LC02):      u32 magic 0x4C433032 | u32 seq | channel | 0 | payload
//! fragment (LC03):   u32 magic 0x4C433033 | u32 seq | u32 msg_size | u32 offset
//!                    | u16 fragment_no | u16 n_fragments | [channel | 0, fragment 0 only] | data
//! ```
//! Big-endian. A message goes in one short packet when `channel + 1 + payload ≤ 65499` bytes;
//! otherwise in fragments of at most 65487 bytes after the 20-byte header, fragment 0's budget
//! including the channel. Fragments are placed by their offset, so they may arrive in any order.

use super::MAX_CHANNEL_LEN;
use seabus_medium::WireError;
use std::fmt;

/// Magic of a short, unfragmented message ("LC02").
pub const MAGIC_SHORT: u32 = 0x4C43_3032;
/// Magic of a fragment ("LC03").
pub const MAGIC_FRAGMENT: u32 = 0x4C43_3033;
/// Size of a short message's header.
pub const SHORT_HEADER: usize = 8;
/// Size of a fragment's header.
pub const FRAGMENT_HEADER: usize = 20;
/// Largest `channel + 1 + payload` sent in one short packet.
pub const MAX_SHORT_BODY: usize = 65_499;
/// Bytes after the header in a full fragment (fragment 0 counts its channel in them).
pub const FRAGMENT_BODY: usize = 65_487;
/// Largest message payload LCM carries.
pub const MAX_MESSAGE: usize = 256 << 20;
/// The channel liblcm publishes its start-up self-test on.
pub const SELF_TEST_CHANNEL: &str = "LCM_SELF_TEST";

/// One packet read from the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Packet<'a> {
    /// A whole message.
    Short {
        /// The sender's sequence number.
        seq: u32,
        /// The channel.
        channel: &'a str,
        /// The message bytes.
        payload: &'a [u8],
    },
    /// One fragment of a large message.
    Fragment(Fragment<'a>),
}

/// One fragment of a message too large for one packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fragment<'a> {
    /// The sender's sequence number, shared by every fragment of the message.
    pub seq: u32,
    /// Size of the whole message payload.
    pub msg_size: u32,
    /// Where this fragment's data goes in the payload.
    pub offset: u32,
    /// This fragment's number, from 0.
    pub no: u16,
    /// How many fragments the message has.
    pub count: u16,
    /// The channel: carried by fragment 0 only.
    pub channel: Option<&'a str>,
    /// This fragment's part of the payload.
    pub data: &'a [u8],
}

fn error(reason: &'static str, offset: usize, detail: impl Into<String>) -> WireError {
    WireError::at(offset, reason, detail)
}

fn too_short(d: &[u8], header: &str) -> WireError {
    error(
        "lcm-short-packet",
        d.len(),
        format!("{} bytes, shorter than {header}", d.len()),
    )
}

fn u32_at(d: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([d[at], d[at + 1], d[at + 2], d[at + 3]])
}

fn u16_at(d: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([d[at], d[at + 1]])
}

/// Reads a NUL-terminated channel starting at `at`; returns it and the offset after the NUL.
fn channel_at(d: &[u8], at: usize) -> Result<(&str, usize), WireError> {
    let rest = &d[at..];
    let Some(len) = memchr::memchr(0, rest) else {
        return Err(error(
            "lcm-no-channel-end",
            d.len(),
            "channel name has no terminating NUL",
        ));
    };
    if len == 0 {
        return Err(error("lcm-empty-channel", at, "empty channel name"));
    }
    if len > MAX_CHANNEL_LEN {
        return Err(error(
            "lcm-channel-too-long",
            at,
            format!("channel name is {len} bytes, LCM allows {MAX_CHANNEL_LEN}"),
        ));
    }
    let channel = std::str::from_utf8(&rest[..len]).map_err(|e| {
        error(
            "lcm-channel-not-utf8",
            at + e.valid_up_to(),
            "channel name is not UTF-8",
        )
    })?;
    Ok((channel, at + len + 1))
}

/// Reads one datagram.
pub fn parse(d: &[u8]) -> Result<Packet<'_>, WireError> {
    if d.len() < SHORT_HEADER {
        return Err(too_short(d, "any LCM header"));
    }
    let seq = u32_at(d, 4);
    match u32_at(d, 0) {
        MAGIC_SHORT => {
            let (channel, body) = channel_at(d, SHORT_HEADER)?;
            Ok(Packet::Short {
                seq,
                channel,
                payload: &d[body..],
            })
        }
        MAGIC_FRAGMENT => {
            if d.len() < FRAGMENT_HEADER {
                return Err(too_short(d, "a fragment header"));
            }
            let msg_size = u32_at(d, 8);
            let offset = u32_at(d, 12);
            let no = u16_at(d, 16);
            let count = u16_at(d, 18);
            if msg_size as usize > MAX_MESSAGE {
                return Err(error(
                    "lcm-too-large",
                    8,
                    format!("message of {msg_size} bytes, LCM carries at most {MAX_MESSAGE}"),
                ));
            }
            if no >= count {
                return Err(error(
                    "lcm-bad-fragment",
                    16,
                    format!("fragment {no} of {count}"),
                ));
            }
            // every fragment but the last carries at least one byte of the message
            if u32::from(count) - 1 > msg_size {
                return Err(error(
                    "lcm-bad-fragment",
                    18,
                    format!("{count} fragments cannot carry a {msg_size}-byte message"),
                ));
            }
            let (channel, body) = if no == 0 {
                let (c, b) = channel_at(d, FRAGMENT_HEADER)?;
                (Some(c), b)
            } else {
                (None, FRAGMENT_HEADER)
            };
            let data = &d[body..];
            if u64::from(offset) + data.len() as u64 > u64::from(msg_size) {
                return Err(error(
                    "lcm-bad-fragment",
                    12,
                    format!(
                        "fragment {no} puts {} bytes at offset {offset} of a {msg_size}-byte message",
                        data.len()
                    ),
                ));
            }
            Ok(Packet::Fragment(Fragment {
                seq,
                msg_size,
                offset,
                no,
                count,
                channel,
                data,
            }))
        }
        magic => Err(error(
            "lcm-bad-magic",
            0,
            format!("magic {magic:#010x} is neither LC02 nor LC03"),
        )),
    }
}

/// Why a message cannot be sent over LCM.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EncodeError {
    /// The channel name is longer than LCM allows.
    ChannelTooLong(usize),
    /// The message is larger than LCM carries.
    TooLarge(usize),
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::ChannelTooLong(n) => {
                write!(f, "channel name is {n} bytes, LCM allows {MAX_CHANNEL_LEN}")
            }
            EncodeError::TooLarge(n) => {
                write!(f, "message is {n} bytes, LCM carries at most {MAX_MESSAGE}")
            }
        }
    }
}

impl std::error::Error for EncodeError {}

/// Checks that a channel and payload size can go over LCM.
pub fn check(channel: &str, payload_len: usize) -> Result<(), EncodeError> {
    if channel.len() > MAX_CHANNEL_LEN {
        return Err(EncodeError::ChannelTooLong(channel.len()));
    }
    if payload_len > MAX_MESSAGE {
        return Err(EncodeError::TooLarge(payload_len));
    }
    Ok(())
}

/// True when the message goes in one short packet.
pub fn is_short(channel: &str, payload_len: usize) -> bool {
    channel.len() + 1 + payload_len <= MAX_SHORT_BODY
}

/// The header of a short packet.
pub fn short_header(seq: u32) -> [u8; SHORT_HEADER] {
    let mut h = [0u8; SHORT_HEADER];
    h[..4].copy_from_slice(&MAGIC_SHORT.to_be_bytes());
    h[4..].copy_from_slice(&seq.to_be_bytes());
    h
}

/// The fragments of a message too large for one packet: `(header, range of the payload)` per
/// fragment; fragment 0 also carries the channel and its NUL between header and data.
pub fn fragments(
    seq: u32,
    channel: &str,
    payload_len: usize,
) -> impl Iterator<Item = ([u8; FRAGMENT_HEADER], std::ops::Range<usize>)> {
    let first = FRAGMENT_BODY.saturating_sub(channel.len() + 1);
    let rest = payload_len.saturating_sub(first);
    let count = 1 + rest.div_ceil(FRAGMENT_BODY);
    (0..count).map(move |no| {
        let start = if no == 0 {
            0
        } else {
            first + (no - 1) * FRAGMENT_BODY
        };
        let end = if no == 0 {
            first.min(payload_len)
        } else {
            (start + FRAGMENT_BODY).min(payload_len)
        };
        let mut h = [0u8; FRAGMENT_HEADER];
        h[..4].copy_from_slice(&MAGIC_FRAGMENT.to_be_bytes());
        h[4..8].copy_from_slice(&seq.to_be_bytes());
        h[8..12].copy_from_slice(&(payload_len as u32).to_be_bytes());
        h[12..16].copy_from_slice(&(start as u32).to_be_bytes());
        h[16..18].copy_from_slice(&(no as u16).to_be_bytes());
        h[18..20].copy_from_slice(&(count as u16).to_be_bytes());
        (h, start..end)
    })
}

/// Writes a whole message as datagrams (for tests and tools; the medium sends without copying).
pub fn encode(seq: u32, channel: &str, payload: &[u8]) -> Result<Vec<Vec<u8>>, EncodeError> {
    check(channel, payload.len())?;
    if is_short(channel, payload.len()) {
        let mut d = Vec::with_capacity(SHORT_HEADER + channel.len() + 1 + payload.len());
        d.extend_from_slice(&short_header(seq));
        d.extend_from_slice(channel.as_bytes());
        d.push(0);
        d.extend_from_slice(payload);
        return Ok(vec![d]);
    }
    Ok(fragments(seq, channel, payload.len())
        .map(|(h, range)| {
            let mut d = Vec::with_capacity(FRAGMENT_HEADER + channel.len() + 1 + range.len());
            d.extend_from_slice(&h);
            if range.start == 0 {
                d.extend_from_slice(channel.as_bytes());
                d.push(0);
            }
            d.extend_from_slice(&payload[range]);
            d
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_packet_matches_the_protocol_example() {
        let d = encode(0, "CH", b"hello").unwrap();
        assert_eq!(d.len(), 1);
        assert_eq!(
            d[0],
            [
                0x4c, 0x43, 0x30, 0x32, 0, 0, 0, 0, 0x43, 0x48, 0, 0x68, 0x65, 0x6c, 0x6c, 0x6f
            ]
        );
        assert_eq!(
            parse(&d[0]).unwrap(),
            Packet::Short {
                seq: 0,
                channel: "CH",
                payload: b"hello"
            }
        );
    }

    #[test]
    fn large_messages_fragment_as_liblcm_does() {
        let payload: Vec<u8> = (0..300_000u32).map(|i| i as u8).collect();
        let d = encode(7, "BIG", &payload).unwrap();
        // fragment 0 holds 65487 - 4 bytes of payload, then 65487 each
        assert_eq!(d.len(), 5);
        assert_eq!(d[0].len(), FRAGMENT_HEADER + 4 + 65_483);
        assert!(d[..4].iter().all(|x| x.len() <= 65_507));
        let mut rebuilt = vec![0u8; payload.len()];
        for x in &d {
            let Packet::Fragment(f) = parse(x).unwrap() else {
                panic!("not a fragment")
            };
            assert_eq!((f.seq, f.msg_size, f.count), (7, 300_000, 5));
            assert_eq!(f.channel.is_some(), f.no == 0);
            rebuilt[f.offset as usize..f.offset as usize + f.data.len()].copy_from_slice(f.data);
        }
        assert_eq!(rebuilt, payload);
        // the boundary: exactly 65499 bytes of channel + NUL + payload is one short packet
        assert_eq!(encode(1, "CH", &vec![0; 65_496]).unwrap().len(), 1);
        assert_eq!(encode(1, "CH", &vec![0; 65_497]).unwrap().len(), 2);
    }

    #[test]
    fn bad_packets_say_what_and_where() {
        assert_eq!(parse(b"LC02").unwrap_err().kind(), "lcm-short-packet");
        assert_eq!(parse(b"XXXX\0\0\0\0CH\0").unwrap_err().offset(), Some(0));
        let e = parse(b"LC02\0\0\0\0CH").unwrap_err();
        assert_eq!((e.kind(), e.offset()), ("lcm-no-channel-end", Some(10)));
        let long = format!("LC02\0\0\0\0{}\0", "x".repeat(64));
        assert_eq!(
            parse(long.as_bytes()).unwrap_err().kind(),
            "lcm-channel-too-long"
        );
        let mut f = encode(1, "C", &vec![1; 70_000]).unwrap().remove(1);
        f[18..20].copy_from_slice(&1u16.to_be_bytes()); // fragment 1 of 1
        assert_eq!(parse(&f).unwrap_err().kind(), "lcm-bad-fragment");
        let mut f = encode(1, "C", &vec![1; 70_000]).unwrap().remove(1);
        f[8..12].copy_from_slice(&100u32.to_be_bytes()); // data beyond the message
        assert_eq!(parse(&f).unwrap_err().kind(), "lcm-bad-fragment");
        // more fragments than the message has bytes: nothing liblcm sends, only a cost
        let mut f = b"LC03\0\0\0\x07\0\0\0\0\0\0\0\0\xff\xfe\xff\xff".to_vec();
        let e = parse(&f).unwrap_err();
        assert_eq!((e.kind(), e.offset()), ("lcm-bad-fragment", Some(18)));
        f[8..12].copy_from_slice(&65_534u32.to_be_bytes());
        assert!(matches!(parse(&f), Ok(Packet::Fragment(_))));
        assert_eq!(
            encode(1, &"x".repeat(64), b"").unwrap_err(),
            EncodeError::ChannelTooLong(64)
        );
    }
}
