//! The model of a PGN database and the decoding of a PGN's data into a datamap.
//!
//! A [`Database`] holds [`PgnDef`]s — one or more per PGN number — each an ordered list of
//! [`Field`]s with their bit length, resolution, offset, signedness, unit and type, as canboat's
//! database describes them. [`PgnDef::decode`] reads a PGN's data (a single frame's, or a whole
//! fast-packet or transport-protocol message) into a datamap:
//!
//! - fields are read one after the other, little-endian, from bit 0 of the data; a field's
//!   physical value is `(raw + offset) × resolution`;
//! - numbers (and dates, times, durations, PGN numbers) whose raw value is one of the codes the
//!   standard keeps — all ones ("not available"), and for fields of 8 bits or more the two below
//!   it ("out of range", "reserved"); for fields of 4 to 7 bits the one below it; for signed
//!   fields the same codes at the top of the positive range — are left out of the datamap, never
//!   given as numbers; so are values outside the field's range (canboat's `RangeMin`/`RangeMax`,
//!   or the range the codes leave);
//! - units are those of seabus's datasets: angles in degrees (canboat's `rad` → `deg`), angular
//!   rates in degrees per second (`rad/s` → `deg/s`), temperatures in degrees Celsius (`K` →
//!   `degC`; a signed field in kelvin is a difference, kept in `K`); every other unit is canboat's (m, m/s, Pa, V, A, s, d, %, rpm, L/h, …);
//! - a lookup gives its name (`"Magnetic"`), or its number when the enumeration has no name for
//!   it (and nothing for the kept codes); a bit lookup the list of the names of the bits set;
//! - strings: fixed-length ones trimmed of the fill bytes (0xFF, 0x00, `@`, space), length-prefixed
//!   ones (`STRING_LZ`, `STRING_LAU`, ASCII/UTF-8 or UTF-16); empty strings are left out;
//! - reserved and spare bits are skipped;
//! - repeating field sets become lists of datamaps under `list` (the first set) and `list2`;
//! - a field the data ends before is left out, and so is every field after it.

use seabus_medium::{DataMap, Key, Value};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::sync::Arc;

/// How a PGN travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Packet {
    /// In one frame of up to 8 bytes.
    Single,
    /// In a fast-packet sequence of up to 32 frames (223 bytes).
    Fast,
    /// Through the ISO transport protocol (TP.CM / TP.DT), up to 1785 bytes.
    Iso,
}

impl Packet {
    /// The name canboat's database gives it.
    pub fn name(self) -> &'static str {
        match self {
            Packet::Single => "Single",
            Packet::Fast => "Fast",
            Packet::Iso => "ISO",
        }
    }
}

/// An enumeration: names of values.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Lookup {
    /// Its name (`DIRECTION_REFERENCE`).
    pub name: Key,
    /// Value → name.
    pub values: BTreeMap<u64, Key>,
}

/// An enumeration of bits: names of the bits of a bit field.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BitLookup {
    /// Its name.
    pub name: Key,
    /// Bit number (0 = least significant) → name.
    pub bits: BTreeMap<u32, Key>,
}

/// An enumeration whose names depend on the value of another field as well.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct IndirectLookup {
    /// Its name.
    pub name: Key,
    /// (the other field's value, this field's value) → name.
    pub values: BTreeMap<(u64, u64), Key>,
}

/// What a field holds, after canboat's `FieldType`.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    /// A number with a resolution and an offset (`NUMBER`).
    Number,
    /// A 32-bit IEEE float (`FLOAT`).
    Float,
    /// Binary-coded decimal digits (`DECIMAL`).
    Decimal,
    /// A value named by an enumeration (`LOOKUP`).
    Lookup(Arc<Lookup>),
    /// A value named by an enumeration together with another field (`INDIRECT_LOOKUP`).
    IndirectLookup {
        /// The enumeration.
        lookup: Arc<IndirectLookup>,
        /// The index of the other field among the definition's fields.
        by: usize,
    },
    /// A bit field whose bits are named (`BITLOOKUP`).
    BitLookup(Arc<BitLookup>),
    /// Seconds since midnight (`TIME`).
    Time,
    /// A duration in seconds (`DURATION`).
    Duration,
    /// Days since 1970-01-01 (`DATE`).
    Date,
    /// A PGN number (`PGN`).
    Pgn,
    /// A vessel's MMSI, given as its nine digits (`MMSI`).
    Mmsi,
    /// A 64-bit ISO NAME, given in hex (`ISO_NAME`).
    IsoName,
    /// The index of a field of another PGN (`FIELD_INDEX`).
    FieldIndex,
    /// A fixed-length string (`STRING_FIX`).
    StringFix,
    /// A string after its length byte, ended by a zero byte (`STRING_LZ`).
    StringLz,
    /// A string after its length and encoding bytes (`STRING_LAU`).
    StringLau,
    /// Bytes (`BINARY`); without a bit length, as long as another field says (in bits).
    Binary {
        /// The index of the field that gives the length, when the length is not fixed.
        length_from: Option<usize>,
    },
    /// Reserved bits (`RESERVED`), skipped.
    Reserved,
    /// Spare bits (`SPARE`), skipped.
    Spare,
    /// The key of a key-value pair (`DYNAMIC_FIELD_KEY`, `DYNAMIC_FIELD_LENGTH`): a number.
    DynamicKey(&'static str),
    /// A field whose layout depends on another PGN (`VARIABLE`, `DYNAMIC_FIELD_VALUE`): decoding
    /// stops before it.
    Unsupported(&'static str),
}

impl Kind {
    /// canboat's name of the field type.
    pub fn name(&self) -> &'static str {
        match self {
            Kind::Number => "NUMBER",
            Kind::Float => "FLOAT",
            Kind::Decimal => "DECIMAL",
            Kind::Lookup(_) => "LOOKUP",
            Kind::IndirectLookup { .. } => "INDIRECT_LOOKUP",
            Kind::BitLookup(_) => "BITLOOKUP",
            Kind::Time => "TIME",
            Kind::Duration => "DURATION",
            Kind::Date => "DATE",
            Kind::Pgn => "PGN",
            Kind::Mmsi => "MMSI",
            Kind::IsoName => "ISO_NAME",
            Kind::FieldIndex => "FIELD_INDEX",
            Kind::StringFix => "STRING_FIX",
            Kind::StringLz => "STRING_LZ",
            Kind::StringLau => "STRING_LAU",
            Kind::Binary { .. } => "BINARY",
            Kind::Reserved => "RESERVED",
            Kind::Spare => "SPARE",
            Kind::DynamicKey(n) | Kind::Unsupported(n) => n,
        }
    }

    /// Whether the field is read as a number (its raw value checked against the kept codes).
    fn numeric(&self) -> bool {
        matches!(
            self,
            Kind::Number
                | Kind::Time
                | Kind::Duration
                | Kind::Date
                | Kind::Pgn
                | Kind::Mmsi
                | Kind::FieldIndex
                | Kind::DynamicKey(_)
        )
    }

    /// Whether the field's length is its own (a length byte) rather than a bit length.
    pub fn self_delimited(&self) -> bool {
        matches!(self, Kind::StringLz | Kind::StringLau)
    }
}

/// One field of a PGN.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// canboat's identifier (`heading`): the datamap key.
    pub id: Key,
    /// The name people read (`Heading`).
    pub name: Key,
    /// Its length in bits; `None` for strings that carry their length, and bytes whose length
    /// another field gives.
    pub bits: Option<u32>,
    /// Its first bit, when every field before it has a fixed length.
    pub bit_offset: Option<u32>,
    /// Physical value = (raw + offset) × resolution.
    pub resolution: f64,
    /// Added to the raw value before the resolution is applied.
    pub offset: i64,
    /// Two's complement.
    pub signed: bool,
    /// The unit as the database gives it (`rad`, `K`, `m/s`), empty when none.
    pub unit: Key,
    /// What it holds.
    pub kind: Kind,
    /// The physical range the database gives, in its unit; `None`: the range the kept codes
    /// leave.
    pub range: Option<(f64, f64)>,
    /// The raw value this field has in this definition, when the PGN has several definitions told
    /// apart by it (a manufacturer code, a function code).
    pub matches: Option<u64>,
}

/// How many codes at the top of a field's raw range the standard keeps: "not available", and for
/// longer fields "out of range" and "reserved".
pub fn kept_codes(bits: u32) -> u64 {
    match bits {
        0 | 1 => 0,
        2 | 3 => 1,
        4..=7 => 2,
        _ => 3,
    }
}

/// The raw values a number field of `bits` bits may have: all but the kept codes (for a signed
/// field without an offset, from −max to max, the most negative code left out as canboat does).
pub fn raw_limits(bits: u32, signed: bool, offset: i64) -> (i128, i128) {
    let bits = bits.clamp(1, 64);
    let high = if signed && offset == 0 {
        bits - 1
    } else {
        bits
    };
    let all = (1i128 << high) - 1;
    let max = all - i128::from(kept_codes(bits));
    let min = if signed && offset == 0 { -all } else { 0 };
    (min, max)
}

impl Field {
    /// The physical range of the field, in the database's unit: the database's, or the range the
    /// kept codes leave.
    pub fn effective_range(&self) -> Option<(f64, f64)> {
        if let Some(r) = self.range {
            return Some(r);
        }
        let bits = self.bits?;
        if !self.kind.numeric() && !matches!(self.kind, Kind::Lookup(_)) {
            return None;
        }
        let (min, mut max) = raw_limits(bits, self.signed, self.offset);
        // a lookup's named values are values, kept codes or not
        if let Kind::Lookup(l) = &self.kind
            && let Some((&top, _)) = l.values.last_key_value()
        {
            max = max.max(i128::from(top));
        }
        let phys = |raw: i128| (raw + i128::from(self.offset)) as f64 * self.resolution;
        Some((phys(min), phys(max)))
    }

    /// The unit the decoded value is given in: the database's, with angles in degrees and
    /// temperatures in degrees Celsius.
    pub fn seabus_unit(&self) -> &str {
        match &*self.unit {
            "rad" => "deg",
            "rad/s" => "deg/s",
            "K" if self.is_temperature() => "degC",
            u => u,
        }
    }

    /// Whether the field is a temperature (in kelvin, unsigned, as canboat's analyzer tells them
    /// apart), given in degrees Celsius; a signed field in kelvin is a temperature difference
    /// (an offset, a calibration), the same number in kelvin and in degrees Celsius.
    pub fn is_temperature(&self) -> bool {
        &*self.unit == "K" && !self.signed
    }
}

/// Where a repeating field set is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Repeating {
    /// The index of its first field.
    pub start: usize,
    /// How many fields it has.
    pub size: usize,
    /// The index of the field that counts the repetitions; `None`: it repeats to the data's end.
    pub count: Option<usize>,
}

/// One definition of a PGN.
#[derive(Debug, Clone, PartialEq)]
pub struct PgnDef {
    /// The PGN number.
    pub pgn: u32,
    /// canboat's identifier (`vesselHeading`): the last segment of its topic.
    pub id: Key,
    /// Its description (`Vessel Heading`).
    pub description: Key,
    /// How it travels.
    pub packet: Packet,
    /// Its length in bytes, when fixed.
    pub length: Option<usize>,
    /// Its default priority.
    pub priority: Option<u8>,
    /// Its fields, in order (repeating sets at the end, once each).
    pub fields: Vec<Field>,
    /// Its repeating field sets (at most two).
    pub repeating: Vec<Repeating>,
    /// Used only when no other definition of the PGN matches the data.
    pub fallback: bool,
}

/// A decoded PGN: its fields, and whether the data was shorter than the definition.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// The fields, by identifier (absent ones left out).
    pub map: DataMap,
    /// The data ended before a field the definition has (those fields are left out).
    pub short: bool,
}

/// Reads little-endian bit fields of a message.
struct Bits<'a> {
    data: &'a [u8],
    /// the next bit to read
    pos: u64,
}

/// The `len` bits (at most 64) of `data` from bit `start`, least significant first; `None` when
/// the data ends before them.
pub fn extract(data: &[u8], start: u64, len: u32) -> Option<u64> {
    if len > 64 || start + u64::from(len) > 8 * data.len() as u64 {
        return None;
    }
    let mut value = 0u64;
    let mut got = 0u32;
    let mut pos = start;
    while got < len {
        let byte = data[(pos / 8) as usize];
        let shift = (pos % 8) as u32;
        let take = (8 - shift).min(len - got);
        let chunk = (u64::from(byte) >> shift) & ((1u64 << take) - 1);
        value |= chunk << got;
        got += take;
        pos += u64::from(take);
    }
    Some(value)
}

impl Bits<'_> {
    fn left(&self) -> u64 {
        (8 * self.data.len() as u64).saturating_sub(self.pos)
    }

    fn take(&mut self, len: u32) -> Option<u64> {
        let v = extract(self.data, self.pos, len)?;
        self.pos += u64::from(len);
        Some(v)
    }

    /// `n` whole bytes (read bit by bit, so any alignment works).
    fn bytes(&mut self, n: u64) -> Option<Vec<u8>> {
        if n * 8 > self.left() {
            return None;
        }
        let out = (0..n)
            .filter_map(|_| self.take(8).map(|b| b as u8))
            .collect();
        Some(out)
    }
}

/// Sign-extends the `bits`-bit two's complement `raw`.
pub fn sign_extend(raw: u64, bits: u32) -> i64 {
    if bits == 0 || bits >= 64 {
        return raw as i64;
    }
    let shift = 64 - bits;
    ((raw << shift) as i64) >> shift
}

const RAD_TO_DEG: f64 = 180.0 / std::f64::consts::PI;

/// Trims the fill bytes of a fixed string (0xFF, 0x00, `@`, space) from its end.
fn trim_fill(bytes: &[u8]) -> &[u8] {
    let end = bytes
        .iter()
        .rposition(|b| !matches!(b, 0xFF | 0x00 | b'@' | b' '))
        .map_or(0, |i| i + 1);
    &bytes[..end]
}

/// The text of string bytes: UTF-8 (invalid sequences replaced), `None` when empty.
fn text(bytes: &[u8]) -> Option<Value> {
    let t = trim_fill(bytes);
    (!t.is_empty()).then(|| Value::from(String::from_utf8_lossy(t).into_owned()))
}

/// What reading one field gave.
enum Read {
    /// A value (or `None`: absent), and its raw bits when it is a number.
    Value(Option<Value>, Option<u64>),
    /// The data ended before the field.
    Short,
    /// The field cannot be read (its layout is unknown): stop.
    Stop,
}

impl Field {
    /// The physical value of a raw number, in the database's unit, or `None` when it is a kept
    /// code or outside the field's range.
    pub fn physical(&self, raw: u64) -> Option<f64> {
        let bits = self.bits.unwrap_or(64);
        let (min, max) = raw_limits(bits, self.signed, self.offset);
        let value: i128 = if self.signed && self.offset == 0 {
            i128::from(sign_extend(raw, bits))
        } else {
            i128::from(raw)
        };
        if value < min || value > max {
            return None;
        }
        let phys = (value + i128::from(self.offset)) as f64 * self.resolution;
        if let Some((lo, hi)) = self.range {
            let tol = 1e-9 * lo.abs().max(hi.abs()).max(1.0);
            if phys < lo - tol || phys > hi + tol {
                return None;
            }
        }
        Some(phys)
    }

    /// A physical value (in the database's unit) in seabus's unit.
    pub fn to_seabus(&self, phys: f64) -> f64 {
        match &*self.unit {
            "rad" | "rad/s" => phys * RAD_TO_DEG,
            "K" if self.is_temperature() => phys - 273.15,
            _ => phys,
        }
    }

    /// Whether a number of this field is given as an integer.
    fn integral(&self) -> bool {
        self.resolution.fract() == 0.0 && self.seabus_unit() == &*self.unit
    }

    /// The value of a number field's raw bits.
    fn number(&self, raw: u64) -> Option<Value> {
        let phys = self.physical(raw)?;
        if self.integral() && phys.abs() < 9.0e15 {
            return Some(Value::Int(phys as i64));
        }
        Some(Value::Float(self.to_seabus(phys)))
    }

    /// A lookup's value: its name, or its number when unnamed (nothing for the kept codes).
    fn named(&self, raw: u64, name: Option<&Key>) -> Option<Value> {
        if let Some(n) = name {
            return Some(Value::Str(n.clone()));
        }
        let (_, max) = raw_limits(self.bits.unwrap_or(8), false, 0);
        (i128::from(raw) <= max).then_some(Value::Int(raw as i64))
    }

    fn read(&self, r: &mut Bits<'_>, raws: &[Option<u64>]) -> Read {
        let fixed = |r: &mut Bits<'_>| match self.bits {
            Some(b) if b <= 64 => r.take(b),
            _ => None,
        };
        match &self.kind {
            Kind::Reserved | Kind::Spare => match self.bits {
                Some(b) if u64::from(b) <= r.left() => {
                    r.pos += u64::from(b);
                    Read::Value(None, None)
                }
                _ => Read::Short,
            },
            Kind::Unsupported(_) => Read::Stop,
            Kind::Number
            | Kind::Time
            | Kind::Duration
            | Kind::Date
            | Kind::Pgn
            | Kind::FieldIndex
            | Kind::DynamicKey(_) => match fixed(r) {
                Some(raw) => Read::Value(self.number(raw), Some(raw)),
                None => Read::Short,
            },
            Kind::Mmsi => match fixed(r) {
                Some(raw) => Read::Value(
                    self.physical(raw)
                        .map(|v| Value::from(format!("{:09}", v as u64))),
                    Some(raw),
                ),
                None => Read::Short,
            },
            Kind::IsoName => match fixed(r) {
                Some(raw) => Read::Value(Some(Value::from(format!("{raw:016x}"))), Some(raw)),
                None => Read::Short,
            },
            Kind::Float => match fixed(r) {
                Some(raw) => {
                    let f = f64::from(f32::from_bits(raw as u32)) * self.resolution;
                    let v = f.is_finite().then(|| Value::Float(self.to_seabus(f)));
                    Read::Value(v, Some(raw))
                }
                None => Read::Short,
            },
            Kind::Decimal => {
                let Some(bits) = self.bits else {
                    return Read::Stop;
                };
                match r.bytes(u64::from(bits.div_ceil(8))) {
                    Some(bytes) => {
                        let mut n: u64 = 0;
                        let mut ok = !bytes.iter().all(|b| *b == 0xFF);
                        for b in &bytes {
                            let (hi, lo) = (u64::from(b >> 4), u64::from(b & 0xF));
                            ok &= hi < 10 && lo < 10;
                            n = n.saturating_mul(100).saturating_add(hi * 10 + lo);
                        }
                        Read::Value(ok.then_some(Value::Int(n as i64)), Some(n))
                    }
                    None => Read::Short,
                }
            }
            Kind::Lookup(l) => match fixed(r) {
                Some(raw) => Read::Value(self.named(raw, l.values.get(&raw)), Some(raw)),
                None => Read::Short,
            },
            Kind::IndirectLookup { lookup, by } => match fixed(r) {
                Some(raw) => {
                    let name = raws
                        .get(*by)
                        .copied()
                        .flatten()
                        .and_then(|k| lookup.values.get(&(k, raw)));
                    Read::Value(self.named(raw, name), Some(raw))
                }
                None => Read::Short,
            },
            Kind::BitLookup(l) => match fixed(r) {
                Some(raw) => {
                    let names: Vec<Value> = (0..self.bits.unwrap_or(0).min(64))
                        .filter(|b| (raw >> b) & 1 == 1)
                        .map(|b| match l.bits.get(&b) {
                            Some(n) => Value::Str(n.clone()),
                            None => Value::from(format!("bit {b}")),
                        })
                        .collect();
                    Read::Value(Some(Value::List(names)), Some(raw))
                }
                None => Read::Short,
            },
            Kind::StringFix => {
                let Some(bits) = self.bits else {
                    return Read::Stop;
                };
                match r.bytes(u64::from(bits / 8)) {
                    Some(b) => Read::Value(text(&b), None),
                    None => Read::Short,
                }
            }
            Kind::StringLz => {
                let Some(len) = r.take(8) else {
                    return Read::Short;
                };
                let Some(chars) = r.bytes(len) else {
                    return Read::Short;
                };
                // the terminating zero byte, when it is there
                if r.left() >= 8 && extract(r.data, r.pos, 8) == Some(0) {
                    r.pos += 8;
                }
                Read::Value(text(&chars), None)
            }
            Kind::StringLau => {
                let Some(len) = r.take(8) else {
                    return Read::Short;
                };
                if len < 2 {
                    // no room for its own two bytes: the rest cannot be placed
                    return Read::Stop;
                }
                let Some(encoding) = r.take(8) else {
                    return Read::Short;
                };
                let Some(chars) = r.bytes(len - 2) else {
                    return Read::Short;
                };
                let v = if encoding == 0 {
                    let units: Vec<u16> = chars
                        .chunks_exact(2)
                        .map(|c| u16::from_le_bytes([c[0], c[1]]))
                        .take_while(|u| *u != 0 && *u != 0xFFFF)
                        .collect();
                    let s = String::from_utf16_lossy(&units);
                    (!s.is_empty()).then(|| Value::from(s))
                } else {
                    text(&chars)
                };
                Read::Value(v, None)
            }
            Kind::Binary { length_from } => {
                let bits = match (self.bits, length_from) {
                    (Some(b), _) => u64::from(b),
                    (None, Some(i)) => match raws.get(*i).copied().flatten() {
                        Some(n) => n,
                        None => return Read::Stop,
                    },
                    (None, None) => return Read::Stop,
                };
                // a message that ends inside it keeps what it has (a proprietary payload shorter
                // than the most the definition allows); the fields after it are short
                let bits = if bits > r.left() {
                    match r.left() / 8 * 8 {
                        0 => return Read::Short,
                        whole => whole,
                    }
                } else {
                    bits
                };
                let mut out = Vec::with_capacity(bits.div_ceil(8) as usize);
                let mut left = bits;
                while left > 0 {
                    let n = left.min(8) as u32;
                    out.push(r.take(n).unwrap_or(0) as u8);
                    left -= u64::from(n);
                }
                Read::Value(Some(Value::Bytes(out)), None)
            }
        }
    }
}

/// Most repetitions of a repeating field set read from one message.
const MAX_REPEATS: usize = 1024;

impl PgnDef {
    /// Whether `data` matches this definition's match fields.
    pub fn matches(&self, data: &[u8]) -> bool {
        let mut pos = 0u64;
        for f in &self.fields {
            let Some(bits) = f.bits else {
                // match fields come first; past a field of unknown length nothing is checked
                return true;
            };
            if let Some(want) = f.matches
                && extract(data, pos, bits.min(64)) != Some(want)
            {
                return false;
            }
            pos += u64::from(bits);
        }
        true
    }

    /// The datamap of a message of this PGN (see the module's documentation).
    pub fn decode(&self, data: &[u8]) -> Decoded {
        let mut r = Bits { data, pos: 0 };
        let mut raws: Vec<Option<u64>> = vec![None; self.fields.len()];
        let mut map = DataMap::with_capacity(self.fields.len());
        let mut short = false;
        let mut i = 0;
        while i < self.fields.len() {
            if let Some((k, set)) = self
                .repeating
                .iter()
                .enumerate()
                .find(|(_, s)| s.start == i && s.size > 0)
            {
                // a count that is not available counts none
                let count = set.count.map(|c| {
                    raws.get(c)
                        .copied()
                        .flatten()
                        .filter(|r| self.fields[c].physical(*r).is_some())
                        .unwrap_or(0)
                });
                let mut list = Vec::new();
                let end = (set.start + set.size).min(self.fields.len());
                let mut stop = false;
                while list.len() < MAX_REPEATS {
                    match count {
                        Some(n) if list.len() as u64 >= n => break,
                        None if r.left() < 8 => break,
                        _ => {}
                    }
                    let before = r.pos;
                    let mut item = DataMap::with_capacity(set.size);
                    for j in set.start..end {
                        match self.fields[j].read(&mut r, &raws) {
                            Read::Value(v, raw) => {
                                raws[j] = raw;
                                if let Some(v) = v {
                                    item.push(self.fields[j].id.clone(), v);
                                }
                            }
                            Read::Short => {
                                short |= count.is_some();
                                stop = true;
                                break;
                            }
                            Read::Stop => {
                                stop = true;
                                break;
                            }
                        }
                    }
                    if stop || r.pos == before {
                        if !item.is_empty() && !stop {
                            list.push(Value::Map(item));
                        }
                        break;
                    }
                    list.push(Value::Map(item));
                }
                let key: Key = if k == 0 {
                    Cow::Borrowed("list")
                } else {
                    Cow::Borrowed("list2")
                };
                // a list cut short of its count (a field it could not read) is not the list:
                // left out rather than given with sets missing
                let incomplete = stop && count.is_some_and(|n| (list.len() as u64) < n);
                if !incomplete {
                    map.push(key, Value::List(list));
                }
                if stop {
                    break;
                }
                i = end;
                continue;
            }
            let f = &self.fields[i];
            match f.read(&mut r, &raws) {
                Read::Value(v, raw) => {
                    raws[i] = raw;
                    if let Some(v) = v {
                        map.push(f.id.clone(), v);
                    }
                }
                Read::Short => {
                    // reserved bits at the end may be left off by a sender
                    short |= !matches!(f.kind, Kind::Reserved | Kind::Spare);
                    break;
                }
                Read::Stop => break,
            }
            i += 1;
        }
        // an indirect lookup may depend on a field after it (an ISO name's device function on
        // its device class)
        for (i, f) in self.fields.iter().enumerate() {
            if let Kind::IndirectLookup { lookup, by } = &f.kind
                && *by > i
                && let (Some(raw), Some(k)) = (raws[i], raws.get(*by).copied().flatten())
                && let Some(name) = lookup.values.get(&(k, raw))
            {
                map.insert(f.id.clone(), Value::Str(name.clone()));
            }
        }
        Decoded { map, short }
    }
}

/// PGN definitions, by number.
#[derive(Debug, Clone, Default)]
pub struct Database {
    defs: BTreeMap<u32, Vec<Arc<PgnDef>>>,
    /// Where the definitions came from (a file, or `built-in`).
    pub source: Arc<str>,
}

impl Database {
    /// An empty database said to come from `source`.
    pub fn new(source: &str) -> Database {
        Database {
            defs: BTreeMap::new(),
            source: Arc::from(source),
        }
    }

    /// Adds a definition (after those of its PGN already there).
    pub fn add(&mut self, def: PgnDef) {
        self.defs.entry(def.pgn).or_default().push(Arc::new(def));
    }

    /// Adds `other`'s definitions of the PGNs this database has none of.
    pub fn fill_from(&mut self, other: &Database) {
        for (pgn, defs) in &other.defs {
            self.defs.entry(*pgn).or_insert_with(|| defs.clone());
        }
    }

    /// The definitions of `pgn`.
    pub fn definitions(&self, pgn: u32) -> &[Arc<PgnDef>] {
        self.defs.get(&pgn).map_or(&[], Vec::as_slice)
    }

    /// Every definition, by PGN.
    pub fn iter(&self) -> impl Iterator<Item = &Arc<PgnDef>> {
        self.defs.values().flatten()
    }

    /// How many PGNs it defines.
    pub fn len(&self) -> usize {
        self.defs.len()
    }

    /// Whether it defines none.
    pub fn is_empty(&self) -> bool {
        self.defs.is_empty()
    }

    /// The definition of `pgn` that `data` is: the first whose match fields match (one with no
    /// match fields matches anything), else its fallback, else the fallback of the proprietary
    /// range it is in (canboat's generic definitions at 65280 for 65280–65535 and at 130816 for
    /// 130816–131071); none when nothing fits: another manufacturer's definition is never used.
    pub fn select(&self, pgn: u32, data: &[u8]) -> Option<&Arc<PgnDef>> {
        let fallback_of = |p: u32| self.defs.get(&p)?.iter().find(|d| d.fallback);
        let defs = self.defs.get(&pgn);
        defs.and_then(|defs| defs.iter().find(|d| !d.fallback && d.matches(data)))
            .or_else(|| fallback_of(pgn))
            .or_else(|| match pgn {
                0xFF00..=0xFFFF => fallback_of(0xFF00),
                0x1FF00..=0x1FFFF => fallback_of(0x1FF00),
                _ => None,
            })
    }

    /// How `pgn` travels: as its definitions say; for a PGN it does not define, fast-packet in the
    /// ranges the standard keeps for fast-packet PGNs (126208–126975 and 130816–131071), else
    /// single frame.
    pub fn packet(&self, pgn: u32) -> Packet {
        match self.defs.get(&pgn).and_then(|d| d.first()) {
            Some(d) => d.packet,
            None if (0x1ED00..=0x1EFFF).contains(&pgn) || (0x1FF00..=0x1FFFF).contains(&pgn) => {
                Packet::Fast
            }
            None => Packet::Single,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(bits: u32, signed: bool, resolution: f64, unit: &'static str) -> Field {
        Field {
            id: Cow::Borrowed("x"),
            name: Cow::Borrowed("X"),
            bits: Some(bits),
            bit_offset: Some(0),
            resolution,
            offset: 0,
            signed,
            unit: Cow::Borrowed(unit),
            kind: Kind::Number,
            range: None,
            matches: None,
        }
    }

    #[test]
    fn bits_are_taken_little_endian_at_any_offset() {
        let data = [0b1010_1100, 0x34, 0x12, 0xFF];
        assert_eq!(extract(&data, 0, 8), Some(0xAC));
        assert_eq!(extract(&data, 2, 3), Some(0b011));
        assert_eq!(extract(&data, 4, 4), Some(0b1010));
        assert_eq!(extract(&data, 8, 16), Some(0x1234));
        // a field across a byte boundary: bits 6..14
        assert_eq!(extract(&data, 6, 8), Some((0x34 << 2 | 0b10) & 0xFF));
        assert_eq!(extract(&data, 0, 32), Some(0xFF12_34AC));
        assert_eq!(extract(&data, 25, 8), None, "past the end");
        assert_eq!(extract(&[0xFF; 9], 3, 64), Some(u64::MAX));
        assert_eq!(extract(&[], 0, 0), Some(0));
        assert_eq!(sign_extend(0xFFFE, 16), -2);
        assert_eq!(sign_extend(0x7FFF, 16), 0x7FFF);
        assert_eq!(sign_extend(0b100, 3), -4);
    }

    #[test]
    fn not_available_out_of_range_and_reserved_codes_are_absent() {
        let u8f = field(8, false, 1.0, "");
        assert_eq!(u8f.number(252), Some(Value::Int(252)));
        for code in [253, 254, 255] {
            assert_eq!(u8f.number(code), None, "{code}");
        }
        let u16f = field(16, false, 0.01, "m/s");
        assert_eq!(u16f.number(65532), Some(Value::Float(655.32)));
        for code in [0xFFFD, 0xFFFE, 0xFFFF] {
            assert_eq!(u16f.number(code), None);
        }
        // signed: the top of the positive range is kept, and the most negative code too
        let s16 = field(16, true, 1.0, "");
        assert_eq!(s16.number(0x7FFC), Some(Value::Int(32764)));
        for code in [0x7FFD, 0x7FFE, 0x7FFF, 0x8000] {
            assert_eq!(s16.number(code), None, "{code:#x}");
        }
        assert_eq!(s16.number(0x8001), Some(Value::Int(-32767)));
        // short fields keep fewer codes
        assert_eq!(field(4, false, 1.0, "").number(13), Some(Value::Int(13)));
        assert_eq!(field(4, false, 1.0, "").number(14), None);
        assert_eq!(field(2, false, 1.0, "").number(2), Some(Value::Int(2)));
        assert_eq!(field(2, false, 1.0, "").number(3), None);
        assert_eq!(field(1, false, 1.0, "").number(1), Some(Value::Int(1)));
        // 64 bits
        let s64 = field(64, true, 1e-16, "deg");
        assert_eq!(s64.number(0x7FFF_FFFF_FFFF_FFFF), None);
        assert!(s64.number(4_512_345_678_000_000_000).is_some());
        // a range of the database's: outside it is absent as well
        let mut heading = field(16, false, 1e-4, "rad");
        heading.range = Some((0.0, 6.2831852));
        assert!(heading.number(62831).is_some());
        assert_eq!(heading.number(62832), None);
        assert_eq!(heading.number(65000), None);
    }

    #[test]
    fn units_become_seabus_units() {
        let rad = field(16, false, 1e-4, "rad");
        let Some(Value::Float(deg)) = rad.number(15708) else {
            panic!()
        };
        assert!((deg - 90.0).abs() < 0.01, "{deg}");
        let k = field(16, false, 0.01, "K");
        assert_eq!(k.seabus_unit(), "degC");
        let Some(Value::Float(c)) = k.number(29815) else {
            panic!()
        };
        assert!((c - 25.0).abs() < 1e-9, "{c}");
        let rate = field(32, true, 3.125e-8, "rad/s");
        assert_eq!(rate.seabus_unit(), "deg/s");
        // whole resolutions without conversion stay integers
        assert_eq!(
            field(16, false, 100.0, "Pa").number(1013),
            Some(Value::Int(101300))
        );
    }

    #[test]
    fn strings_of_every_kind() {
        let mut f = field(64, false, 1.0, "");
        f.kind = Kind::StringFix;
        let mut r = Bits {
            data: b"ABC @\xff\xff\x00",
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Value(Some(Value::Str(s)), _) if s == "ABC"));
        let mut r = Bits {
            data: &[0xFF; 8],
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Value(None, _)));
        f.bits = None;
        f.kind = Kind::StringLz;
        let mut r = Bits {
            data: b"\x02hi\x00\x07",
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Value(Some(Value::Str(s)), _) if s == "hi"));
        assert_eq!(r.pos, 32, "the zero byte is taken");
        f.kind = Kind::StringLau;
        let mut r = Bits {
            data: b"\x05\x01abc",
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Value(Some(Value::Str(s)), _) if s == "abc"));
        let mut r = Bits {
            data: b"\x06\x00a\x00b\x00",
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Value(Some(Value::Str(s)), _) if s == "ab"));
        let mut r = Bits {
            data: b"\x09\x01ab",
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Short));
        let mut r = Bits {
            data: b"\x01\x01ab",
            pos: 0,
        };
        assert!(matches!(f.read(&mut r, &[]), Read::Stop));
    }

    fn named(id: &'static str, mut f: Field) -> Field {
        f.id = Cow::Borrowed(id);
        f
    }

    fn def(pgn: u32, id: &'static str, fields: Vec<Field>, fallback: bool) -> PgnDef {
        PgnDef {
            pgn,
            id: Cow::Borrowed(id),
            description: Cow::Borrowed(id),
            packet: Packet::Single,
            length: None,
            priority: None,
            fields,
            repeating: Vec::new(),
            fallback,
        }
    }

    #[test]
    fn a_signed_field_in_kelvin_is_a_difference_an_unsigned_one_a_temperature() {
        // Airmar's calibration offset of canboat's capture: −8333 × 0.001 K
        let offset = field(16, true, 0.001, "K");
        assert_eq!(offset.seabus_unit(), "K");
        let Some(Value::Float(v)) = offset.number((-8333i64 as u64) & 0xFFFF) else {
            panic!("a number")
        };
        assert!((v - -8.333).abs() < 1e-9, "{v}");
        assert!((offset.from_seabus(v) - v).abs() < 1e-12);
        let sea = field(16, false, 0.01, "K");
        assert_eq!(sea.seabus_unit(), "degC");
        let Some(Value::Float(t)) = sea.number(27926) else {
            panic!("a number")
        };
        assert!((t - 6.11).abs() < 1e-9, "{t}");
        assert!((sea.from_seabus(t) - 279.26).abs() < 1e-9);
    }

    #[test]
    fn another_manufacturer_s_proprietary_pgn_takes_the_generic_definition() {
        let maker = |m: u64| {
            let mut f = named("manufacturerCode", field(11, false, 1.0, ""));
            f.matches = Some(m);
            f
        };
        let mut db = Database::new("test");
        db.add(def(
            65306,
            "airmarThing",
            vec![maker(135), field(8, false, 1.0, "")],
            false,
        ));
        db.add(def(
            65280,
            "generic",
            vec![named("data", field(8, false, 1.0, ""))],
            true,
        ));
        db.add(def(61184, "proprietaryAddressed", vec![maker(229)], false));
        db.add(def(61184, "fallbackAddressed", vec![], true));
        db.add(def(
            130306,
            "windData",
            vec![field(8, false, 1.0, "")],
            false,
        ));
        let id = |pgn: u32, data: &[u8]| db.select(pgn, data).map(|d| d.id.to_string());
        // manufacturer 135 (Airmar) in the first 11 bits, industry 4
        assert_eq!(id(65306, &[0x87, 0x98, 1]).as_deref(), Some("airmarThing"));
        // Raymarine's (1851) frames on the same PGN: the range's generic definition
        assert_eq!(id(65306, &[0x3B, 0x9F, 1]).as_deref(), Some("generic"));
        assert_eq!(id(65400, &[0x3B, 0x9F, 1]).as_deref(), Some("generic"));
        // the PGN's own fallback first
        assert_eq!(
            id(61184, &[0x3B, 0x9F]).as_deref(),
            Some("fallbackAddressed")
        );
        assert_eq!(id(130306, &[1]).as_deref(), Some("windData"));
        // no generic definition for the range: nothing rather than another maker's
        let mut bare = Database::new("test");
        bare.add(def(65306, "airmarThing", vec![maker(135)], false));
        assert!(bare.select(65306, &[0x3B, 0x9F]).is_none());
    }

    #[test]
    fn a_payload_shorter_than_its_definition_keeps_the_bytes_it_has() {
        let mut data = named("data", field(8, false, 1.0, ""));
        data.bits = Some(48);
        data.kind = Kind::Binary { length_from: None };
        let d = def(61184, "p", vec![field(8, false, 1.0, ""), data], true);
        let got = d.decode(&[7, 0x90, 0x00, 0x04]);
        assert_eq!(
            got.map.get("data"),
            Some(&Value::Bytes(vec![0x90, 0x00, 0x04]))
        );
        // a whole field after a cut binary one is short
        let mut after = d.clone();
        after.fields.push(named("y", field(8, false, 1.0, "")));
        let got = after.decode(&[7, 0x90]);
        assert_eq!(got.map.get("data"), Some(&Value::Bytes(vec![0x90])));
        assert_eq!(got.map.get("y"), None);
        assert!(got.short);
    }

    #[test]
    fn a_list_cut_short_of_its_count_is_left_out() {
        let count = named("n", field(8, false, 1.0, ""));
        let mut value = named("value", field(8, false, 1.0, ""));
        value.kind = Kind::Unsupported("VARIABLE");
        let mut d = def(126208, "request", vec![count, value], false);
        d.repeating = vec![Repeating {
            start: 1,
            size: 1,
            count: Some(0),
        }];
        let got = d.decode(&[2, 1, 2]);
        assert_eq!(got.map.get("n"), Some(&Value::Int(2)));
        assert_eq!(got.map.get("list"), None, "{:?}", got.map);
        // a count of none is an empty list, which is the list
        let got = d.decode(&[0]);
        assert_eq!(got.map.get("list"), Some(&Value::List(vec![])));
    }
}
