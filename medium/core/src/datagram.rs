//! The seabus datagram: one whole message with its provenance, as the UDP and Zenoh media carry it
//! (documented byte by byte in `docs/wire-formats.md`).
//!
//! ```text
//! off  size  field
//!   0     2  magic "SB" (0x53 0x42)
//!   2     1  version, 1
//!   3     1  flags: bit 0 kind (0 data, 1 command); bits 1–2 payload format
//!            (0 bytes, 1 datamap, 2 XML); bits 3–7 zero
//!   4     1  hops
//!   5     1  N, length of the origin node name (1–255)
//!   6     1  M, length of the origin medium name (1–255)
//!   7     1  T, length of the topic (1–255)
//!   8     8  sender: id of the transmitting medium instance, u64 little-endian
//!  16     4  origin boot number, u32 little-endian
//!  20     8  sequence number, u64 little-endian
//!  28     8  timestamp, i64 little-endian, nanoseconds since the Unix epoch
//!  36     N  origin node name, UTF-8
//!        M  origin medium name, UTF-8
//!        T  topic, UTF-8
//!        …  payload to the end of the datagram: raw bytes, a binary datamap, or UTF-8 XML
//! ```

use crate::binary;
use crate::{Kind, Message, Origin, Payload, Provenance, Stamp, Topic, WireError};
use bytes::{BufMut, Bytes, BytesMut};
use std::collections::HashMap;
use std::sync::Arc;

/// Magic bytes that open a seabus datagram.
pub const MAGIC: [u8; 2] = *b"SB";
/// The version this code writes and reads.
pub const VERSION: u8 = 1;
/// Size of the fixed header.
pub const FIXED: usize = 36;

fn fmt_code(p: &Payload) -> u8 {
    match p {
        Payload::Bytes(_) => 0,
        Payload::Map(_) => 1,
        Payload::Xml(_) => 2,
    }
}

/// Encodes `msg`; `sender` identifies the transmitting medium instance.
pub fn encode(msg: &Message, sender: u64) -> Result<Bytes, &'static str> {
    let o = &msg.provenance.origin;
    let (node, medium, topic) = (o.node.as_bytes(), o.medium.as_bytes(), msg.topic.as_bytes());
    if node.is_empty() || node.len() > 255 {
        return Err("origin node name must be 1 to 255 bytes");
    }
    if medium.is_empty() || medium.len() > 255 {
        return Err("origin medium name must be 1 to 255 bytes");
    }
    let payload_len = match &msg.payload {
        Payload::Bytes(b) => b.len(),
        Payload::Xml(x) => x.len(),
        Payload::Map(m) => binary::encoded_len(m),
    };
    let mut buf =
        BytesMut::with_capacity(FIXED + node.len() + medium.len() + topic.len() + payload_len);
    buf.put_slice(&MAGIC);
    buf.put_u8(VERSION);
    let kind = match msg.kind {
        Kind::Data => 0,
        Kind::Command => 1,
    };
    buf.put_u8(kind | (fmt_code(&msg.payload) << 1));
    buf.put_u8(msg.provenance.hops);
    buf.put_u8(node.len() as u8);
    buf.put_u8(medium.len() as u8);
    buf.put_u8(topic.len() as u8);
    buf.put_u64_le(sender);
    buf.put_u32_le(o.boot);
    buf.put_u64_le(msg.provenance.seq);
    buf.put_i64_le(msg.stamp.0);
    buf.put_slice(node);
    buf.put_slice(medium);
    buf.put_slice(topic);
    match &msg.payload {
        Payload::Bytes(b) => buf.put_slice(b),
        Payload::Xml(x) => buf.put_slice(x.as_bytes()),
        Payload::Map(m) => binary::encode_into(m, &mut buf)
            .map_err(|_| "datamap lists and maps nest deeper than receivers read")?,
    }
    Ok(buf.freeze())
}

/// The header fields of a datagram, read without copying.
#[derive(Debug)]
pub struct Header<'a> {
    /// The transmitting medium instance.
    pub sender: u64,
    /// Data or command.
    pub kind: Kind,
    /// Payload format code (0 bytes, 1 datamap, 2 XML).
    pub format: u8,
    /// Hops so far.
    pub hops: u8,
    /// Origin boot number.
    pub boot: u32,
    /// Sequence number.
    pub seq: u64,
    /// Timestamp.
    pub stamp: i64,
    /// Origin node name.
    pub node: &'a str,
    /// Origin medium name.
    pub medium: &'a str,
    /// Topic.
    pub topic: &'a str,
    /// Offset of the payload.
    pub payload_at: usize,
}

fn le<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&b[at..at + N]);
    out
}

fn truncated(at: usize) -> WireError {
    WireError::at(at, "truncated", "datagram is truncated")
}

fn bad_text(at: usize, what: &str) -> WireError {
    WireError::at(at, "bad-text", format!("bad {what}"))
}

/// Reads and checks a datagram's header. Never panics.
pub fn header(d: &[u8]) -> Result<Header<'_>, WireError> {
    // what is there is checked before what is missing: a short datagram that is not seabus's is
    // "bad magic", one of another version "bad version"
    if let Some(i) = d.iter().take(2).zip(MAGIC).position(|(a, b)| *a != b) {
        return Err(WireError::at(
            i,
            "bad-magic",
            "bad magic (not a seabus datagram)",
        ));
    }
    match d.get(2) {
        Some(&v) if v != VERSION => {
            return Err(WireError::at(
                2,
                "bad-version",
                format!("unsupported version {v}"),
            ));
        }
        _ => {}
    }
    if d.len() < FIXED {
        return Err(truncated(d.len()));
    }
    let flags = d[3];
    let format = (flags >> 1) & 0b11;
    if flags & !0b111 != 0 || format == 3 {
        return Err(WireError::at(
            3,
            "bad-flags",
            format!("bad flags 0x{flags:02x}"),
        ));
    }
    let kind = if flags & 1 == 1 {
        Kind::Command
    } else {
        Kind::Data
    };
    let (n, m, t) = (d[5] as usize, d[6] as usize, d[7] as usize);
    let end = FIXED + n + m + t;
    if d.len() < end {
        return Err(truncated(d.len()));
    }
    let text = |at: usize, len: usize, what: &'static str| -> Result<&str, WireError> {
        if len == 0 {
            return Err(bad_text(at, what));
        }
        std::str::from_utf8(&d[at..at + len]).map_err(|e| bad_text(at + e.valid_up_to(), what))
    };
    let node = text(FIXED, n, "origin node name")?;
    let medium = text(FIXED + n, m, "origin medium name")?;
    let topic = text(FIXED + n + m, t, "topic")?;
    Ok(Header {
        sender: u64::from_le_bytes(le(d, 8)),
        kind,
        format,
        hops: d[4],
        boot: u32::from_le_bytes(le(d, 16)),
        seq: u64::from_le_bytes(le(d, 20)),
        stamp: i64::from_le_bytes(le(d, 28)),
        node,
        medium,
        topic,
        payload_at: end,
    })
}

/// Keeps one shared [`Origin`] per (node, medium, boot) seen, so that received messages do not
/// allocate their origin. Bounded: it is cleared when full.
#[derive(Default)]
pub struct Origins {
    map: HashMap<u64, Arc<Origin>>,
}

const MAX_CACHED_ORIGINS: usize = 1024;

impl Origins {
    /// The shared origin for these fields.
    pub fn get(&mut self, node: &str, medium: &str, boot: u32) -> Arc<Origin> {
        let id = Origin::id_of(node, medium, boot);
        if let Some(o) = self.map.get(&id)
            && o.boot == boot
            && &*o.node == node
            && &*o.medium == medium
        {
            return o.clone();
        }
        if self.map.len() >= MAX_CACHED_ORIGINS {
            self.map.clear();
        }
        let o = Origin::new(node, medium, boot);
        self.map.insert(id, o.clone());
        o
    }
}

/// Decodes a whole datagram into a message, sharing `datagram`'s bytes for byte payloads.
pub fn decode(datagram: &Bytes, origins: &mut Origins) -> Result<(u64, Message), WireError> {
    let h = header(datagram)?;
    let topic = Topic::new(h.topic).map_err(|_| bad_text(h.payload_at - h.topic.len(), "topic"))?;
    let body = &datagram[h.payload_at..];
    let payload = match h.format {
        0 => Payload::Bytes(datagram.slice(h.payload_at..)),
        1 => Payload::from(binary::decode(body).map_err(|e| {
            WireError::at(
                h.payload_at + e.offset,
                "bad-payload",
                format!("bad datamap payload: {}", e.kind),
            )
        })?),
        _ => {
            Payload::Xml(Arc::from(std::str::from_utf8(body).map_err(|e| {
                bad_text(h.payload_at + e.valid_up_to(), "XML payload")
            })?))
        }
    };
    let origin = origins.get(h.node, h.medium, h.boot);
    Ok((
        h.sender,
        Message {
            topic,
            kind: h.kind,
            provenance: Provenance {
                origin,
                seq: h.seq,
                hops: h.hops,
            },
            stamp: Stamp(h.stamp),
            payload,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datamap::{DataMap, Value};

    fn msg(payload: Payload) -> Message {
        Message {
            topic: Topic::new("nav.depth").unwrap(),
            kind: Kind::Command,
            provenance: Provenance {
                origin: Origin::new("auv", "bus", 7),
                seq: 42,
                hops: 2,
            },
            stamp: Stamp(1_700_000_000_000_000_000),
            payload,
        }
    }

    #[test]
    fn documented_layout() {
        let m = msg(Payload::from(b"hi".as_slice()));
        let d = encode(&m, 0x0102030405060708).unwrap();
        let mut expected = vec![b'S', b'B', 1, 0b001, 2, 3, 3, 9];
        expected.extend_from_slice(&0x0102030405060708u64.to_le_bytes());
        expected.extend_from_slice(&7u32.to_le_bytes());
        expected.extend_from_slice(&42u64.to_le_bytes());
        expected.extend_from_slice(&1_700_000_000_000_000_000i64.to_le_bytes());
        expected.extend_from_slice(b"auvbusnav.depthhi");
        assert_eq!(&d[..], &expected[..]);
    }

    #[test]
    fn lists_and_maps_too_deep_for_receivers_are_refused_at_send() {
        for maps in [false, true] {
            let mut v = Value::Int(1);
            for _ in 0..=crate::datamap::MAX_DEPTH {
                v = if maps {
                    Value::Map(DataMap::new().with("k", v))
                } else {
                    Value::List(vec![v])
                };
            }
            let m = msg(Payload::from(DataMap::new().with("deep", v)));
            assert!(encode(&m, 1).is_err());
        }
    }

    #[test]
    fn round_trips_every_format() {
        let mut origins = Origins::default();
        for p in [
            Payload::from(vec![0u8, 255, 3]),
            Payload::from(DataMap::new().with("depth", 12.5f64)),
            Payload::from(
                DataMap::new().with(
                    "pose",
                    DataMap::new()
                        .with("x", 1.0f64)
                        .with("tags", Value::List(vec![DataMap::new().into()])),
                ),
            ),
            crate::payload::xml("<a>é</a>"),
        ] {
            let m = msg(p);
            let d = encode(&m, 9).unwrap();
            let (sender, back) = decode(&d, &mut origins).unwrap();
            assert_eq!(sender, 9);
            assert_eq!(back.topic, m.topic);
            assert_eq!(back.kind, m.kind);
            assert_eq!(back.provenance, m.provenance);
            assert_eq!(back.stamp, m.stamp);
            assert_eq!(back.payload, m.payload);
        }
    }

    #[test]
    fn every_truncation_and_corruption_is_an_error_not_a_panic() {
        let m = msg(Payload::from(
            DataMap::new().with("x", 1i64).with("s", "text"),
        ));
        let d = encode(&m, 1).unwrap();
        let mut origins = Origins::default();
        for cut in 0..d.len() {
            assert!(
                decode(&d.slice(..cut), &mut origins).is_err(),
                "cut at {cut}"
            );
        }
        for i in 0..d.len() {
            for flip in [0x01u8, 0x80, 0xff] {
                let mut bad = d.to_vec();
                bad[i] ^= flip;
                let _ = decode(&Bytes::from(bad), &mut origins);
            }
        }
    }

    #[test]
    fn rejections_name_their_place() {
        let mut origins = Origins::default();
        let e = decode(&Bytes::from_static(b"XX\x01"), &mut origins).unwrap_err();
        assert_eq!((e.offset(), e.kind()), (Some(0), "bad-magic"));
        let e = decode(&Bytes::from_static(b"X"), &mut origins).unwrap_err();
        assert_eq!((e.offset(), e.kind()), (Some(0), "bad-magic"));
        let e = decode(&Bytes::from_static(b"SB\x07"), &mut origins).unwrap_err();
        assert_eq!((e.offset(), e.kind()), (Some(2), "bad-version"));
        let e = decode(&Bytes::from_static(b"SB"), &mut origins).unwrap_err();
        assert_eq!((e.offset(), e.kind()), (Some(2), "truncated"));
        let m = msg(Payload::from(b"".as_slice()));
        let mut d = encode(&m, 1).unwrap().to_vec();
        d[2] = 9;
        let e = decode(&Bytes::from(d.clone()), &mut origins).unwrap_err();
        assert_eq!((e.offset(), e.kind()), (Some(2), "bad-version"));
        assert_eq!(e.to_string(), "byte 2: unsupported version 9");
        d[2] = 1;
        d[3] = 0b110;
        let e = decode(&Bytes::from(d.clone()), &mut origins).unwrap_err();
        assert_eq!(e.to_string(), "byte 3: bad flags 0x06");
        d[3] = 0;
        d[FIXED] = 0xff;
        let e = decode(&Bytes::from(d), &mut origins).unwrap_err();
        assert_eq!(e.to_string(), format!("byte {FIXED}: bad origin node name"));
    }
}
