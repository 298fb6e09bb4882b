//! The compact binary form of a datamap (documented byte by byte in `docs/wire-formats.md`).
//!
//! ```text
//! 0x53 0x4D 0x01          magic "SM", version 1
//! varint count            number of entries
//! per entry: varint key length, key (UTF-8), value
//! value: tag byte, then
//!   0x00 / 0x01           false / true (no body)
//!   0x02 varint           integer, zig-zag encoded
//!   0x03 8 bytes          float, IEEE 754 binary64, little-endian
//!   0x04 varint len, UTF-8   string
//!   0x05 varint len, bytes   byte string
//!   0x06 varint count, values  list
//!   0x07 varint count, entries nested map (entries as above)
//! ```
//! Varints are unsigned LEB128, at most 10 bytes, no over-long encodings. Lists and maps nest at
//! most [`MAX_DEPTH`] deep (counted together): the encoder refuses a deeper map, the decoder deeper
//! input. The decoder never panics and tells a truncated input apart from a malformed one.

use crate::datamap::{DataMap, MAX_DEPTH, TooDeep, Value};
use bytes::BufMut;
use thiserror::Error;

/// Magic bytes that open a binary datamap.
pub const MAGIC: [u8; 2] = [0x53, 0x4D];
/// The version byte this codec writes and reads.
pub const VERSION: u8 = 1;

const TAG_FALSE: u8 = 0;
const TAG_TRUE: u8 = 1;
const TAG_INT: u8 = 2;
const TAG_FLOAT: u8 = 3;
const TAG_STR: u8 = 4;
const TAG_BYTES: u8 = 5;
const TAG_LIST: u8 = 6;
const TAG_MAP: u8 = 7;

/// Why bytes could not be read as a binary datamap; `offset` is the byte where reading stopped.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{kind} at byte {offset}")]
pub struct DecodeError {
    /// Byte offset into the input where the problem was found.
    pub offset: usize,
    /// What was wrong.
    pub kind: DecodeErrorKind,
}

/// The kinds of [`DecodeError`].
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum DecodeErrorKind {
    /// The input ended before the value did: more bytes would be needed.
    #[error("input ends early (incomplete)")]
    Incomplete,
    /// The input does not start with the datamap magic.
    #[error("not a binary datamap (no \"SM\" magic)")]
    BadMagic,
    /// A version this codec does not read.
    #[error("unsupported binary datamap version {0}")]
    Version(u8),
    /// An unknown value tag.
    #[error("unknown value tag 0x{0:02x}")]
    BadTag(u8),
    /// A varint longer than 10 bytes, over 64 bits, or over-long.
    #[error("malformed varint")]
    BadVarint,
    /// A key or string that is not UTF-8.
    #[error("text is not UTF-8")]
    BadUtf8,
    /// Lists and maps nested deeper than [`MAX_DEPTH`].
    #[error("lists and maps nested deeper than {MAX_DEPTH}")]
    TooDeep,
    /// Bytes left over after the datamap.
    #[error("{0} trailing bytes after the datamap")]
    Trailing(usize),
}

impl DecodeError {
    /// True when the input was cut short rather than malformed.
    pub fn is_incomplete(&self) -> bool {
        self.kind == DecodeErrorKind::Incomplete
    }
}

/// Encodes `map` in the compact binary form.
pub fn encode(map: &DataMap) -> Result<Vec<u8>, TooDeep> {
    let mut out = Vec::with_capacity(encoded_len(map));
    encode_into(map, &mut out)?;
    Ok(out)
}

/// Appends the compact binary form of `map` to `out`; on error `out` holds a partial map.
pub fn encode_into(map: &DataMap, out: &mut impl BufMut) -> Result<(), TooDeep> {
    out.put_slice(&MAGIC);
    out.put_u8(VERSION);
    put_varint(out, map.len() as u64);
    for (k, v) in map.iter() {
        put_varint(out, k.len() as u64);
        out.put_slice(k.as_bytes());
        put_value(out, v, 0)?;
    }
    Ok(())
}

/// Writes the entry count and entries of a nested map whose values are found inside `depth` lists
/// and maps (the top-level loop of [`encode_into`] stays apart, so that it inlines).
#[inline(never)]
fn put_entries(out: &mut impl BufMut, map: &DataMap, depth: usize) -> Result<(), TooDeep> {
    put_varint(out, map.len() as u64);
    for (k, v) in map.iter() {
        put_varint(out, k.len() as u64);
        out.put_slice(k.as_bytes());
        put_value(out, v, depth)?;
    }
    Ok(())
}

/// The length of the binary form of `map` (counted as if lists and maps could nest without limit).
pub fn encoded_len(map: &DataMap) -> usize {
    MAGIC.len()
        + 1
        + varint_len(map.len() as u64)
        + map
            .iter()
            .map(|(k, v)| varint_len(k.len() as u64) + k.len() + value_len(v))
            .sum::<usize>()
}

/// The length of the entry count and entries of a nested map (apart from [`encoded_len`], so that
/// its loop inlines).
#[inline(never)]
fn entries_len(map: &DataMap) -> usize {
    varint_len(map.len() as u64)
        + map
            .iter()
            .map(|(k, v)| varint_len(k.len() as u64) + k.len() + value_len(v))
            .sum::<usize>()
}

fn value_len(v: &Value) -> usize {
    1 + match v {
        Value::Bool(_) => 0,
        Value::Int(i) => varint_len(zigzag(*i)),
        Value::Float(_) => 8,
        Value::Str(s) => varint_len(s.len() as u64) + s.len(),
        Value::Bytes(b) => varint_len(b.len() as u64) + b.len(),
        Value::List(items) => {
            varint_len(items.len() as u64) + items.iter().map(value_len).sum::<usize>()
        }
        Value::Map(m) => entries_len(m),
    }
}

fn varint_len(v: u64) -> usize {
    // one byte per started group of 7 significant bits, and one byte for zero
    1 + (63 - (v | 1).leading_zeros() as usize) / 7
}

/// Writes `v`, found inside `depth` lists and maps; a list or map is refused where the decoder would
/// refuse it.
fn put_value(out: &mut impl BufMut, v: &Value, depth: usize) -> Result<(), TooDeep> {
    match v {
        Value::Bool(false) => out.put_u8(TAG_FALSE),
        Value::Bool(true) => out.put_u8(TAG_TRUE),
        Value::Int(i) => {
            out.put_u8(TAG_INT);
            put_varint(out, zigzag(*i));
        }
        Value::Float(f) => {
            out.put_u8(TAG_FLOAT);
            out.put_f64_le(*f);
        }
        Value::Str(s) => {
            out.put_u8(TAG_STR);
            put_varint(out, s.len() as u64);
            out.put_slice(s.as_bytes());
        }
        Value::Bytes(b) => {
            out.put_u8(TAG_BYTES);
            put_varint(out, b.len() as u64);
            out.put_slice(b);
        }
        Value::List(items) => {
            if depth >= MAX_DEPTH {
                return Err(TooDeep);
            }
            out.put_u8(TAG_LIST);
            put_varint(out, items.len() as u64);
            for item in items {
                put_value(out, item, depth + 1)?;
            }
        }
        Value::Map(m) => {
            if depth >= MAX_DEPTH {
                return Err(TooDeep);
            }
            out.put_u8(TAG_MAP);
            put_entries(out, m, depth + 1)?;
        }
    }
    Ok(())
}

/// Appends `v` as an unsigned LEB128 varint.
pub fn put_varint(out: &mut impl BufMut, mut v: u64) {
    while v >= 0x80 {
        out.put_u8((v as u8) | 0x80);
        v >>= 7;
    }
    out.put_u8(v as u8);
}

fn zigzag(i: i64) -> u64 {
    ((i << 1) ^ (i >> 63)) as u64
}

fn unzigzag(u: u64) -> i64 {
    ((u >> 1) as i64) ^ -((u & 1) as i64)
}

/// Decodes a whole binary datamap; trailing bytes are an error.
pub fn decode(bytes: &[u8]) -> Result<DataMap, DecodeError> {
    let mut r = Reader { buf: bytes, pos: 0 };
    if bytes.len() < 2 {
        return Err(r.err(if MAGIC.starts_with(bytes) {
            DecodeErrorKind::Incomplete
        } else {
            DecodeErrorKind::BadMagic
        }));
    }
    if bytes[..2] != MAGIC {
        return Err(r.err(DecodeErrorKind::BadMagic));
    }
    r.pos = 2;
    let version = r.byte()?;
    if version != VERSION {
        r.pos -= 1;
        return Err(r.err(DecodeErrorKind::Version(version)));
    }
    let count = r.varint()?;
    // every entry takes at least two bytes: never reserve more than the input could hold
    let mut map = DataMap::with_capacity((count as usize).min(r.remaining() / 2));
    for _ in 0..count {
        let key = r.text()?;
        let value = r.value(0)?;
        map.push(key, value);
    }
    if r.remaining() > 0 {
        return Err(r.err(DecodeErrorKind::Trailing(r.remaining())));
    }
    Ok(map)
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn err(&self, kind: DecodeErrorKind) -> DecodeError {
        DecodeError {
            offset: self.pos,
            kind,
        }
    }

    fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn byte(&mut self) -> Result<u8, DecodeError> {
        let b = *self
            .buf
            .get(self.pos)
            .ok_or_else(|| self.err(DecodeErrorKind::Incomplete))?;
        self.pos += 1;
        Ok(b)
    }

    fn take(&mut self, n: u64) -> Result<&[u8], DecodeError> {
        if n > self.remaining() as u64 {
            return Err(self.err(DecodeErrorKind::Incomplete));
        }
        let n = n as usize;
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn varint(&mut self) -> Result<u64, DecodeError> {
        let start = self.pos;
        let mut v: u64 = 0;
        for i in 0..10 {
            let b = self.byte()?;
            if i == 9 && b > 1 {
                self.pos = start;
                return Err(self.err(DecodeErrorKind::BadVarint));
            }
            v |= u64::from(b & 0x7f) << (7 * i);
            if b & 0x80 == 0 {
                if b == 0 && i > 0 {
                    // over-long: a trailing zero group
                    self.pos = start;
                    return Err(self.err(DecodeErrorKind::BadVarint));
                }
                return Ok(v);
            }
        }
        self.pos = start;
        Err(self.err(DecodeErrorKind::BadVarint))
    }

    fn text(&mut self) -> Result<String, DecodeError> {
        let len = self.varint()?;
        let start = self.pos;
        let raw = self.take(len)?;
        match std::str::from_utf8(raw) {
            Ok(s) => Ok(s.to_string()),
            Err(e) => Err(DecodeError {
                offset: start + e.valid_up_to(),
                kind: DecodeErrorKind::BadUtf8,
            }),
        }
    }

    /// Reads the count and entries of a nested map whose values are found inside `depth` lists and
    /// maps (the top-level loop of [`decode`] stays apart, so that it inlines).
    #[inline(never)]
    fn entries(&mut self, depth: usize) -> Result<DataMap, DecodeError> {
        let count = self.varint()?;
        // every entry takes at least two bytes; reserve modestly, the map grows as it is read
        let mut map = DataMap::with_capacity((count as usize).min(self.remaining() / 2).min(64));
        for _ in 0..count {
            let key = self.text()?;
            let value = self.value(depth)?;
            map.push(key, value);
        }
        Ok(map)
    }

    /// Reads one value found inside `depth` lists and maps.
    fn value(&mut self, depth: usize) -> Result<Value, DecodeError> {
        let tag = self.byte()?;
        Ok(match tag {
            TAG_FALSE => Value::Bool(false),
            TAG_TRUE => Value::Bool(true),
            TAG_INT => Value::Int(unzigzag(self.varint()?)),
            TAG_FLOAT => {
                let raw = self.take(8)?;
                let mut b = [0u8; 8];
                b.copy_from_slice(raw);
                Value::Float(f64::from_le_bytes(b))
            }
            TAG_STR => Value::from(self.text()?),
            TAG_BYTES => {
                let len = self.varint()?;
                Value::Bytes(self.take(len)?.to_vec())
            }
            TAG_LIST => {
                if depth >= MAX_DEPTH {
                    self.pos -= 1;
                    return Err(self.err(DecodeErrorKind::TooDeep));
                }
                let count = self.varint()?;
                // every item takes at least one byte; reserve modestly, the list grows as it is read
                let mut items = Vec::with_capacity((count as usize).min(self.remaining()).min(64));
                for _ in 0..count {
                    items.push(self.value(depth + 1)?);
                }
                Value::List(items)
            }
            TAG_MAP => {
                if depth >= MAX_DEPTH {
                    self.pos -= 1;
                    return Err(self.err(DecodeErrorKind::TooDeep));
                }
                Value::Map(self.entries(depth + 1)?)
            }
            other => {
                self.pos -= 1;
                return Err(self.err(DecodeErrorKind::BadTag(other)));
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datamap::nested_maps;

    #[test]
    fn documented_example_bytes() {
        // the example in docs/wire-formats.md
        let map = DataMap::new()
            .with("yaw", 90.5f64)
            .with("n", -2i64)
            .with("ok", true)
            .with("id", "a");
        let bytes = encode(&map).unwrap();
        let mut expected = vec![0x53, 0x4D, 0x01, 0x04];
        expected.extend_from_slice(&[0x03, b'y', b'a', b'w', 0x03]);
        expected.extend_from_slice(&90.5f64.to_le_bytes());
        expected.extend_from_slice(&[0x01, b'n', 0x02, 0x03]);
        expected.extend_from_slice(&[0x02, b'o', b'k', 0x01]);
        expected.extend_from_slice(&[0x02, b'i', b'd', 0x04, 0x01, b'a']);
        assert_eq!(bytes, expected);
        assert_eq!(decode(&bytes).unwrap(), map);
    }

    #[test]
    fn documented_nested_map_bytes() {
        // the nested-map example in docs/wire-formats.md
        let map = DataMap::new().with(
            "pose",
            DataMap::new()
                .with("x", 1i64)
                .with("tags", Value::List(vec![DataMap::new().into()])),
        );
        let bytes = encode(&map).unwrap();
        let expected = [
            0x53, 0x4D, 0x01, 0x01, // magic, version, 1 entry
            0x04, b'p', b'o', b's', b'e', 0x07, 0x02, // "pose": map of 2 entries
            0x01, b'x', 0x02, 0x02, // "x": int 1
            0x04, b't', b'a', b'g', b's', 0x06, 0x01, 0x07, 0x00, // "tags": [ {} ]
        ];
        assert_eq!(bytes, expected);
        assert_eq!(decode(&bytes).unwrap(), map);
        assert_eq!(encoded_len(&map), bytes.len());
    }

    #[test]
    fn every_prefix_is_incomplete_not_malformed() {
        let map = DataMap::new()
            .with(
                "list",
                Value::List(vec![1i64.into(), "x".into(), vec![1u8, 2].into()]),
            )
            .with(
                "pose",
                DataMap::new()
                    .with("x", 2.5f64)
                    .with("frame", "utm")
                    .with("empty", DataMap::new()),
            )
            .with("f", 1.0f64);
        let bytes = encode(&map).unwrap();
        for cut in 0..bytes.len() {
            let err = decode(&bytes[..cut]).unwrap_err();
            assert!(err.is_incomplete(), "prefix {cut}: {err}");
            assert!(err.offset <= cut);
        }
    }

    #[test]
    fn malformed_inputs_name_their_offset() {
        assert_eq!(
            decode(b"XY\x01\x00").unwrap_err(),
            DecodeError {
                offset: 0,
                kind: DecodeErrorKind::BadMagic
            }
        );
        assert_eq!(
            decode(b"SM\x02\x00").unwrap_err().kind,
            DecodeErrorKind::Version(2)
        );
        let e = decode(b"SM\x01\x01\x01k\x09").unwrap_err();
        assert_eq!((e.offset, e.kind), (6, DecodeErrorKind::BadTag(9)));
        let e = decode(b"SM\x01\x01\x01\xff").unwrap_err();
        assert_eq!((e.offset, e.kind), (5, DecodeErrorKind::BadUtf8));
        let e = decode(b"SM\x01\x00\x00").unwrap_err();
        assert_eq!(e.kind, DecodeErrorKind::Trailing(1));
        let e = decode(b"SM\x01\x80\x00").unwrap_err();
        assert_eq!((e.offset, e.kind), (3, DecodeErrorKind::BadVarint));
        // inside a nested map: a key that is not UTF-8, an unknown tag, an over-long count
        let e = decode(b"SM\x01\x01\x01m\x07\x01\x02k\xff\x01").unwrap_err();
        assert_eq!((e.offset, e.kind), (10, DecodeErrorKind::BadUtf8));
        let e = decode(b"SM\x01\x01\x01m\x07\x01\x01k\x08").unwrap_err();
        assert_eq!((e.offset, e.kind), (10, DecodeErrorKind::BadTag(8)));
        let e = decode(b"SM\x01\x01\x01m\x07\x81\x00").unwrap_err();
        assert_eq!((e.offset, e.kind), (7, DecodeErrorKind::BadVarint));
        let e = decode(b"SM\x01\x01\x01m\x07\x00\x00").unwrap_err();
        assert_eq!(e.kind, DecodeErrorKind::Trailing(1));
    }

    #[test]
    fn deep_nesting_is_refused() {
        let mut bytes = b"SM\x01\x01\x01k".to_vec();
        for _ in 0..(MAX_DEPTH + 1) {
            bytes.extend_from_slice(&[TAG_LIST, 1]);
        }
        bytes.push(TAG_TRUE);
        assert_eq!(decode(&bytes).unwrap_err().kind, DecodeErrorKind::TooDeep);
    }

    #[test]
    fn deep_maps_and_mixed_nesting_are_refused_where_they_pass_the_limit() {
        // maps only: each `0x07 0x01 0x01 'k'` opens a map of one entry named "k"
        let mut bytes = b"SM\x01\x01\x01k".to_vec();
        for _ in 0..(MAX_DEPTH + 1) {
            bytes.extend_from_slice(&[TAG_MAP, 1, 1, b'k']);
        }
        bytes.push(TAG_TRUE);
        let e = decode(&bytes).unwrap_err();
        assert_eq!(e.kind, DecodeErrorKind::TooDeep);
        assert_eq!(
            e.offset,
            6 + 4 * MAX_DEPTH,
            "the offset of the map too many"
        );
        // lists and maps alternating count together
        let mut bytes = b"SM\x01\x01\x01k".to_vec();
        for i in 0..(MAX_DEPTH + 1) {
            if i % 2 == 0 {
                bytes.extend_from_slice(&[TAG_LIST, 1]);
            } else {
                bytes.extend_from_slice(&[TAG_MAP, 1, 1, b'k']);
            }
        }
        bytes.push(TAG_TRUE);
        assert_eq!(decode(&bytes).unwrap_err().kind, DecodeErrorKind::TooDeep);
    }

    /// A map whose one entry holds `lists` lists, each inside the one before.
    fn nested(lists: usize) -> DataMap {
        let mut v = Value::Int(1);
        for _ in 0..lists {
            v = Value::List(vec![v]);
        }
        DataMap::new().with("k", v)
    }

    #[test]
    fn the_encoder_nests_exactly_as_deep_as_the_decoder() {
        for build in [nested, nested_maps] {
            let deepest = build(MAX_DEPTH);
            assert_eq!(decode(&encode(&deepest).unwrap()).unwrap(), deepest);
            let mut out = Vec::new();
            assert_eq!(encode_into(&build(MAX_DEPTH + 1), &mut out), Err(TooDeep));
        }
    }

    #[test]
    fn encoded_len_is_exact() {
        let ints = [0, 63, -64, 64, -65, 8191, i64::MAX, i64::MIN];
        let map = DataMap::new()
            .with(
                "list",
                Value::List(ints.iter().map(|&i| Value::Int(i)).collect()),
            )
            .with("s", "x".repeat(200))
            .with("b", vec![7u8; 128])
            .with("f", -0.0f64)
            .with("t", true)
            .with("k".repeat(130), Value::List(vec![]))
            .with(
                "m",
                DataMap::new()
                    .with("i", 300i64)
                    .with("inner", DataMap::new().with("s", "é".repeat(70))),
            );
        for m in [
            DataMap::new(),
            map,
            nested(MAX_DEPTH),
            nested_maps(MAX_DEPTH),
        ] {
            assert_eq!(encoded_len(&m), encode(&m).unwrap().len(), "{m}");
        }
        // a map too deep for the binary form still has a length: that of the form without the limit
        assert_eq!(
            encoded_len(&nested(MAX_DEPTH + 1)),
            encoded_len(&nested(MAX_DEPTH)) + 2
        );
    }

    #[test]
    fn huge_counts_do_not_allocate() {
        // a count of 2^63 with nothing behind it: incomplete, and no giant reservation first
        let mut bytes = b"SM\x01".to_vec();
        put_varint(&mut bytes, 1 << 62);
        assert!(decode(&bytes).unwrap_err().is_incomplete());
    }

    #[test]
    fn zigzag_round_trips_extremes() {
        for i in [0, 1, -1, i64::MAX, i64::MIN, 63, -64] {
            assert_eq!(unzigzag(zigzag(i)), i);
        }
    }
}
