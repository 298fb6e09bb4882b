//! DSAAV IComms frames: one message of numbered key-value pairs with its addresses, id, type and
//! reference id, the same bytes on every backbone (raw Ethernet, UDP, in-process).
//!
//! ```text
//! offset  size  field
//!  0      1     magic 0x44 ('D')
//!  1      1     version, 1
//!  2      2     length of the whole frame in bytes (so Ethernet padding after it is ignored)
//!  4      1     flags: bit 0 = channel broadcast; other bits 0
//!  5      1     reserved, 0
//!  6      2     source node          8  2  source port
//! 10      2     destination node     12 2  destination port, or the channel of a broadcast
//! 14      4     message id
//! 18      2     message type
//! 20      4     reference id (the message this one answers; 0 for none)
//! 24      2     number of parameters
//! 26      …     parameters: u16 key, u8 type, value
//!                 type 1 int32 (4 bytes), 2 float32 (4), 3 float64 (8),
//!                 4 string (u16 length, then that many bytes of UTF-8 without NUL)
//! ```
//! Big-endian. A frame is at most [`MAX_FRAME`] bytes, the payload of one Ethernet frame, so a
//! component runs unchanged over every backbone. In a broadcast the destination node is 0xFFFF.

use seabus_medium::WireError;
use std::fmt;

/// The first byte of every frame.
pub const MAGIC: u8 = 0x44;
/// The version written and read.
pub const VERSION: u8 = 1;
/// Bytes before the parameters.
pub const HEADER: usize = 26;
/// Largest frame: an Ethernet frame's payload.
pub const MAX_FRAME: usize = 1500;
/// Longest string value, in bytes.
pub const MAX_STRING: usize = 1024;
/// The destination node of a channel broadcast.
pub const BROADCAST_NODE: u16 = 0xFFFF;

/// A node and logical port: `4:0` is port 0 on node 4.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Address {
    /// The hardware node.
    pub node: u16,
    /// The logical port: several services may run on one node.
    pub port: u16,
}

impl Address {
    /// The address as text, `NODE:PORT`, written by hand (every message's header has addresses):
    /// a buffer, and where the text starts in it.
    fn digits(&self) -> ([u8; 11], usize) {
        let mut text = [0u8; 11];
        let mut at = text.len();
        for (i, mut n) in [self.port, self.node].into_iter().enumerate() {
            if i == 1 {
                at -= 1;
                text[at] = b':';
            }
            loop {
                at -= 1;
                text[at] = b'0' + (n % 10) as u8;
                n /= 10;
                if n == 0 {
                    break;
                }
            }
        }
        (text, at)
    }

    /// The address as text, as [`fmt::Display`] writes it, made in one allocation.
    pub(crate) fn text(&self) -> String {
        let (text, at) = self.digits();
        // only ASCII digits and a colon were written
        text[at..].iter().map(|b| char::from(*b)).collect()
    }
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (text, at) = self.digits();
        // only ASCII digits and a colon were written
        f.write_str(std::str::from_utf8(&text[at..]).map_err(|_| fmt::Error)?)
    }
}

/// Text that is not an address.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AddressError {
    /// Not of the form `node:port`.
    #[error("`{0}` is not an address: expected `node:port`, e.g. `4:0`")]
    Form(String),
    /// The node or the port is not a number in its range.
    #[error("`{text}` is not an address: {part} `{value}` is not a number from 0 to {max}")]
    Number {
        /// The whole text (its first 40 characters).
        text: String,
        /// `node` or `port`.
        part: &'static str,
        /// The part's text.
        value: String,
        /// The largest the part may be (node 65535 is the broadcast node).
        max: u16,
    },
}

/// The first 40 characters of `text`, control characters escaped, for an error message.
fn shown(text: &str) -> String {
    let mut out: String = text
        .chars()
        .take(40)
        .flat_map(|c| {
            if c.is_control() {
                c.escape_default().collect::<Vec<_>>()
            } else {
                vec![c]
            }
        })
        .collect();
    if text.chars().nth(40).is_some() {
        out.push('…');
    }
    out
}

impl std::str::FromStr for Address {
    type Err = AddressError;

    fn from_str(text: &str) -> Result<Address, AddressError> {
        let Some((node, port)) = text.split_once(':') else {
            return Err(AddressError::Form(shown(text)));
        };
        let number = |part: &'static str, value: &str, max: u16| {
            let digits = !value.is_empty() && value.bytes().all(|b| b.is_ascii_digit());
            digits
                .then(|| value.parse::<u16>().ok())
                .flatten()
                .filter(|n| *n <= max)
                .ok_or_else(|| AddressError::Number {
                    text: shown(text),
                    part,
                    value: shown(value),
                    max,
                })
        };
        Ok(Address {
            node: number("node", node, BROADCAST_NODE - 1)?,
            port: number("port", port, u16::MAX)?,
        })
    }
}

/// Where a frame goes: one address, or everyone listening to a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Destination {
    /// One service.
    To(Address),
    /// A channel broadcast.
    Channel(u16),
}

/// A parameter value.
#[derive(Debug, Clone, PartialEq)]
pub enum Param {
    /// A 32-bit integer.
    Int(i32),
    /// A single-precision float.
    Float(f32),
    /// A double-precision float.
    Double(f64),
    /// A string.
    Str(String),
}

impl Param {
    fn code(&self) -> u8 {
        match self {
            Param::Int(_) => 1,
            Param::Float(_) => 2,
            Param::Double(_) => 3,
            Param::Str(_) => 4,
        }
    }

    fn size(&self) -> usize {
        match self {
            Param::Int(_) | Param::Float(_) => 4,
            Param::Double(_) => 8,
            Param::Str(s) => 2 + s.len(),
        }
    }
}

/// One IComms message.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Who sent it.
    pub src: Address,
    /// Where it goes.
    pub dst: Destination,
    /// The sender's number for it.
    pub id: u32,
    /// What kind of message it is.
    pub kind: u16,
    /// The message it refers to (a reply or acknowledgement), 0 for none.
    pub reference: u32,
    /// Its key-value pairs, in order.
    pub params: Vec<(u16, Param)>,
}

fn error(reason: &'static str, offset: usize, detail: impl Into<String>) -> WireError {
    WireError::at(offset, reason, detail)
}

impl Frame {
    /// Its size on the wire.
    pub fn encoded_len(&self) -> usize {
        HEADER + self.params.iter().map(|(_, p)| 3 + p.size()).sum::<usize>()
    }

    /// Writes the frame.
    pub fn encode(&self) -> Result<Vec<u8>, WireError> {
        let len = self.encoded_len();
        if len > MAX_FRAME {
            return Err(error(
                "dsaav-too-large",
                MAX_FRAME,
                format!("frame of {len} bytes, at most {MAX_FRAME} fit"),
            ));
        }
        let mut out = Vec::with_capacity(len);
        out.extend_from_slice(&[MAGIC, VERSION]);
        out.extend_from_slice(&(len as u16).to_be_bytes());
        let (flags, node, port) = match self.dst {
            Destination::To(a) => (0u8, a.node, a.port),
            Destination::Channel(c) => (1u8, BROADCAST_NODE, c),
        };
        out.extend_from_slice(&[flags, 0]);
        for v in [self.src.node, self.src.port, node, port] {
            out.extend_from_slice(&v.to_be_bytes());
        }
        out.extend_from_slice(&self.id.to_be_bytes());
        out.extend_from_slice(&self.kind.to_be_bytes());
        out.extend_from_slice(&self.reference.to_be_bytes());
        out.extend_from_slice(&(self.params.len() as u16).to_be_bytes());
        for (key, p) in &self.params {
            let at = out.len();
            out.extend_from_slice(&key.to_be_bytes());
            out.push(p.code());
            match p {
                Param::Int(v) => out.extend_from_slice(&v.to_be_bytes()),
                Param::Float(v) => out.extend_from_slice(&v.to_be_bytes()),
                Param::Double(v) => out.extend_from_slice(&v.to_be_bytes()),
                Param::Str(s) => {
                    if s.len() > MAX_STRING || s.contains('\0') {
                        return Err(error(
                            "dsaav-bad-string",
                            at,
                            format!(
                                "key {key}: a string is at most {MAX_STRING} bytes without NUL, \
                                 this one has {} bytes",
                                s.len()
                            ),
                        ));
                    }
                    out.extend_from_slice(&(s.len() as u16).to_be_bytes());
                    out.extend_from_slice(s.as_bytes());
                }
            }
        }
        Ok(out)
    }

    /// Reads a frame; bytes after its stated length (Ethernet padding) are ignored.
    pub fn decode(d: &[u8]) -> Result<Frame, WireError> {
        let len = checked_length(d)?;
        let d = &d[..len];
        let flags = d[4];
        if flags & !1 != 0 || d[5] != 0 {
            return Err(error(
                "dsaav-bad-flags",
                4,
                format!("flags {flags:#04x} and reserved {:#04x}", d[5]),
            ));
        }
        let src = Address {
            node: u16_at(d, 6),
            port: u16_at(d, 8),
        };
        if (flags & 1 != 0) != (u16_at(d, 10) == BROADCAST_NODE) {
            return Err(error(
                "dsaav-bad-address",
                10,
                format!(
                    "destination node {} with the broadcast flag {}: node {BROADCAST_NODE} goes with broadcasts only",
                    u16_at(d, 10),
                    if flags & 1 != 0 { "set" } else { "clear" }
                ),
            ));
        }
        let dst = if flags & 1 != 0 {
            Destination::Channel(u16_at(d, 12))
        } else {
            Destination::To(Address {
                node: u16_at(d, 10),
                port: u16_at(d, 12),
            })
        };
        let count = usize::from(u16_at(d, 24));
        let mut params = Vec::with_capacity(count.min((len - HEADER) / 7));
        let mut at = HEADER;
        for i in 0..count {
            let (param, next) = decode_param(d, at, i, count)?;
            params.push(param);
            at = next;
        }
        if at != len {
            return Err(error(
                "dsaav-bad-length",
                at,
                format!("{} bytes after the last parameter", len - at),
            ));
        }
        Ok(Frame {
            src,
            dst,
            id: u32_at(d, 14),
            kind: u16_at(d, 18),
            reference: u32_at(d, 20),
            params,
        })
    }
}

fn u16_at(d: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([d[at], d[at + 1]])
}

fn u32_at(d: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([d[at], d[at + 1], d[at + 2], d[at + 3]])
}

/// The length a frame states, checked against its header and the bytes there are.
fn checked_length(d: &[u8]) -> Result<usize, WireError> {
    if d.len() < HEADER {
        return Err(error(
            "dsaav-short-frame",
            d.len(),
            format!("{} bytes, shorter than the {HEADER}-byte header", d.len()),
        ));
    }
    if d[0] != MAGIC {
        return Err(error(
            "dsaav-bad-magic",
            0,
            format!("first byte {:#04x} is not {MAGIC:#04x}", d[0]),
        ));
    }
    if d[1] != VERSION {
        return Err(error(
            "dsaav-bad-version",
            1,
            format!("version {} (this reads {VERSION})", d[1]),
        ));
    }
    let len = usize::from(u16_at(d, 2));
    if len < HEADER || len > d.len() || len > MAX_FRAME {
        return Err(error(
            "dsaav-bad-length",
            2,
            format!(
                "stated length {len} does not fit a {}-byte datagram (header {HEADER}, at most {MAX_FRAME})",
                d.len()
            ),
        ));
    }
    Ok(len)
}

/// Reads parameter `i` of `count` at byte `at` of frame `d`; returns it and where the next starts.
fn decode_param(
    d: &[u8],
    at: usize,
    i: usize,
    count: usize,
) -> Result<((u16, Param), usize), WireError> {
    let len = d.len();
    let truncated = || {
        error(
            "dsaav-truncated",
            at,
            format!("parameter {i} of {count} runs past the frame's end"),
        )
    };
    if at + 3 > len {
        return Err(truncated());
    }
    let key = u16_at(d, at);
    let code = d[at + 2];
    let value_at = at + 3;
    let need = match code {
        1 | 2 => 4,
        3 => 8,
        4 => {
            if value_at + 2 > len {
                return Err(truncated());
            }
            2 + usize::from(u16_at(d, value_at))
        }
        c => {
            return Err(error(
                "dsaav-bad-type",
                at + 2,
                format!("key {key}: value type {c} is not 1–4"),
            ));
        }
    };
    if value_at + need > len {
        return Err(truncated());
    }
    let v = &d[value_at..value_at + need];
    let value = match code {
        1 => Param::Int(i32::from_be_bytes([v[0], v[1], v[2], v[3]])),
        2 => Param::Float(f32::from_be_bytes([v[0], v[1], v[2], v[3]])),
        3 => Param::Double(f64::from_be_bytes([
            v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7],
        ])),
        _ => Param::Str(string_param(key, &v[2..], value_at)?),
    };
    Ok(((key, value), value_at + need))
}

/// A string parameter's text; `at` is where its length starts.
fn string_param(key: u16, bytes: &[u8], at: usize) -> Result<String, WireError> {
    if bytes.len() > MAX_STRING || bytes.contains(&0) {
        return Err(error(
            "dsaav-bad-string",
            at,
            format!(
                "key {key}: a string is at most {MAX_STRING} bytes without NUL, this one has {}",
                bytes.len()
            ),
        ));
    }
    std::str::from_utf8(bytes).map(str::to_string).map_err(|e| {
        error(
            "dsaav-bad-string",
            at + 2 + e.valid_up_to(),
            format!("key {key}: string is not UTF-8"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Frame {
        Frame {
            src: Address { node: 3, port: 0 },
            dst: Destination::To(Address { node: 4, port: 1 }),
            id: 7,
            kind: 2,
            reference: 5,
            params: vec![
                (1, Param::Int(-2)),
                (2, Param::Float(1.5)),
                (3, Param::Double(-12.25)),
                (4, Param::Str("depth".into())),
            ],
        }
    }

    #[test]
    fn frames_are_the_documented_bytes_and_read_back() {
        let bytes = sample().encode().unwrap();
        #[rustfmt::skip]
        let expected: Vec<u8> = vec![
            0x44, 1, 0, 61, 0, 0,
            0, 3, 0, 0, 0, 4, 0, 1,
            0, 0, 0, 7, 0, 2, 0, 0, 0, 5, 0, 4,
            0, 1, 1, 0xff, 0xff, 0xff, 0xfe,
            0, 2, 2, 0x3f, 0xc0, 0, 0,
            0, 3, 3, 0xc0, 0x28, 0x80, 0, 0, 0, 0, 0,
            0, 4, 4, 0, 5, b'd', b'e', b'p', b't', b'h',
        ];
        assert_eq!(bytes, expected);
        assert_eq!(Frame::decode(&bytes).unwrap(), sample());
        // Ethernet padding after the frame is ignored
        let mut padded = bytes.clone();
        padded.extend_from_slice(&[0; 10]);
        assert_eq!(Frame::decode(&padded).unwrap(), sample());
        let mut b = sample();
        b.dst = Destination::Channel(9);
        let bytes = b.encode().unwrap();
        assert_eq!(bytes[4], 1);
        assert_eq!(&bytes[10..14], &[0xff, 0xff, 0, 9]);
        assert_eq!(Frame::decode(&bytes).unwrap(), b);
    }

    #[test]
    fn bad_frames_name_what_and_where() {
        let good = sample().encode().unwrap();
        let cases: Vec<(Vec<u8>, &str, usize)> = vec![
            (good[..10].to_vec(), "dsaav-short-frame", 10),
            ([&[0x45][..], &good[1..]].concat(), "dsaav-bad-magic", 0),
            (
                [&good[..1], &[2], &good[2..]].concat(),
                "dsaav-bad-version",
                1,
            ),
            (good[..good.len() - 1].to_vec(), "dsaav-bad-length", 2),
            (
                [&good[..28], &[9], &good[29..]].concat(),
                "dsaav-bad-type",
                28,
            ),
            (
                [&good[..4], &[2], &good[5..]].concat(),
                "dsaav-bad-flags",
                4,
            ),
            (
                [&good[..4], &[1], &good[5..]].concat(),
                "dsaav-bad-address",
                10,
            ),
        ];
        for (bytes, reason, offset) in cases {
            let e = Frame::decode(&bytes).unwrap_err();
            assert_eq!((e.kind(), e.offset()), (reason, Some(offset)), "{e}");
        }
        // a string length running past the end
        let mut long = good.clone();
        let n = long.len();
        long[n - 6] = 0xff;
        assert_eq!(Frame::decode(&long).unwrap_err().kind(), "dsaav-truncated");
        let mut f = sample();
        f.params = vec![(1, Param::Str("x".repeat(MAX_STRING + 1)))];
        assert_eq!(f.encode().unwrap_err().kind(), "dsaav-bad-string");
        f.params = (0..200).map(|k| (k, Param::Double(0.0))).collect();
        assert_eq!(f.encode().unwrap_err().kind(), "dsaav-too-large");
    }

    #[test]
    fn addresses_read_as_node_colon_port() {
        assert_eq!("4:0".parse::<Address>(), Ok(Address { node: 4, port: 0 }));
        assert!("4".parse::<Address>().is_err());
        assert_eq!(
            "65535:0".parse::<Address>().unwrap_err().to_string(),
            "`65535:0` is not an address: node `65535` is not a number from 0 to 65534"
        );
        assert_eq!(Address { node: 2, port: 3 }.to_string(), "2:3");
        assert_eq!(Address { node: 0, port: 0 }.to_string(), "0:0");
        let far = Address {
            node: 65534,
            port: 65535,
        };
        assert_eq!(far.to_string(), "65534:65535");
        assert_eq!(far.to_string().parse(), Ok(far));
        assert_eq!(far.text(), far.to_string());
    }
}
