//! The encoding of a datamap into a PGN's data: the inverse of [`PgnDef::decode`].
//!
//! The datamap holds fields by canboat's identifiers, in seabus's units (the units the decoder
//! gives: degrees, degrees per second, degrees Celsius, and canboat's others):
//!
//! - a number is converted to the database's unit, divided by the resolution, less the offset,
//!   and rounded to the nearest raw value; a value the field cannot hold — outside its range, or
//!   on one of the codes the standard keeps ("not available", "out of range", "reserved") — is
//!   refused, never clamped. A bearing of 0° to 360° that rounds up to a full turn is sent as 0;
//! - a lookup takes its name (`"Magnetic"`) or its number; a name the enumeration does not have
//!   is refused; a bit lookup takes the list of the names of its bits set;
//! - strings are written as their kind says (fixed length filled with 0xFF, `STRING_LZ` with its
//!   length and ending zero, `STRING_LAU` with its length and the ASCII/UTF-8 encoding byte);
//! - a field the datamap lacks is sent as "not available": all bits set (for a signed number the
//!   largest positive value); a match field (a manufacturer code of a proprietary PGN) gets the
//!   definition's value;
//! - reserved bits are sent as ones, spare bits as zeros, as the standard says;
//! - repeating sets come from the lists `list` and `list2`; a count field the datamap lacks is
//!   the list's length;
//! - `header` is not a field (the driver reads the priority and destination from it); any other
//!   key that is not a field of the PGN is refused, so that a misspelt field is not silently sent
//!   as "not available".
//!
//! A PGN of fixed length is padded with ones to it; a single-frame PGN to 8 bytes.

use super::pgn::{Field, Kind, Packet, PgnDef, raw_limits};
use seabus_medium::{DataMap, Value};
use std::fmt;

/// Why a datamap cannot be a PGN's data.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodeError {
    /// The counter's name (`n2k-send-out-of-range`).
    pub reason: &'static str,
    /// What was wrong, naming the PGN and field.
    pub detail: String,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.detail)
    }
}

impl std::error::Error for EncodeError {}

/// Writes little-endian bit fields.
struct Writer {
    data: Vec<u8>,
    pos: u64,
}

impl Writer {
    fn put(&mut self, value: u64, len: u32) {
        let mut left = len;
        let mut v = value;
        while left > 0 {
            let byte = (self.pos / 8) as usize;
            if self.data.len() <= byte {
                self.data.push(0);
            }
            let shift = (self.pos % 8) as u32;
            let take = (8 - shift).min(left);
            let mask = ((1u16 << take) - 1) as u8;
            self.data[byte] |= ((v as u8) & mask) << shift;
            v = if take >= 64 { 0 } else { v >> take };
            left -= take;
            self.pos += u64::from(take);
        }
    }

    fn bytes(&mut self, b: &[u8]) {
        for x in b {
            self.put(u64::from(*x), 8);
        }
    }
}

/// All ones of `bits` bits.
fn ones(bits: u32) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

impl Field {
    /// A value in seabus's unit in the database's unit (the inverse of [`Field::to_seabus`]).
    pub fn from_seabus(&self, value: f64) -> f64 {
        match &*self.unit {
            "rad" | "rad/s" => value.to_radians(),
            "K" if self.is_temperature() => value + 273.15,
            _ => value,
        }
    }

    /// The raw bits "not available" is for this field.
    pub fn not_available(&self) -> u64 {
        let bits = self.bits.unwrap_or(0).min(64);
        if self.signed && self.offset == 0 && self.kind_is_number() {
            ones(bits.saturating_sub(1))
        } else {
            ones(bits)
        }
    }

    fn kind_is_number(&self) -> bool {
        !matches!(
            self.kind,
            Kind::Lookup(_)
                | Kind::IndirectLookup { .. }
                | Kind::BitLookup(_)
                | Kind::Reserved
                | Kind::Spare
        )
    }

    /// The raw bits of a number given in seabus's unit, or why it cannot be sent.
    pub fn raw_of(&self, value: f64) -> Result<u64, String> {
        let bits = self.bits.unwrap_or(64).min(64);
        let unit = self.seabus_unit();
        if !value.is_finite() {
            return Err(format!("{value} is not a number"));
        }
        let phys = self.from_seabus(value);
        let mut raw = (phys / self.resolution).round() as i128 - i128::from(self.offset);
        let (min, max) = raw_limits(bits, self.signed, self.offset);
        let step = |raw: i128| (raw + i128::from(self.offset)) as f64 * self.resolution;
        // a bearing below a full turn that rounds up to it is north
        if let Some((lo, hi)) = self.range
            && unit == "deg"
            && lo == 0.0
            && (hi - std::f64::consts::TAU).abs() < 1e-4
            && (0.0..360.0).contains(&value)
            && step(raw) > hi
        {
            raw = -i128::from(self.offset);
        }
        let (plo, phi) = self.effective_range().unwrap_or((step(min), step(max)));
        let shown = |p: f64| {
            let v = self.to_seabus(p);
            format!("{}", (v * 1e6).round() / 1e6)
        };
        let outside = || {
            format!(
                "{value} {unit} is outside {} to {} {unit}",
                shown(plo),
                shown(phi)
            )
        };
        if raw < min || raw > max {
            return Err(outside());
        }
        if let Some((lo, hi)) = self.range {
            let tol = 1e-9 * lo.abs().max(hi.abs()).max(1.0);
            let p = step(raw);
            if p < lo - tol || p > hi + tol {
                return Err(outside());
            }
        }
        Ok((raw as i64 as u64) & ones(bits))
    }
}

/// A key of a repeating set's list.
fn list_key(k: usize) -> &'static str {
    if k == 0 { "list" } else { "list2" }
}

impl PgnDef {
    fn error(&self, reason: &'static str, field: &str, what: impl fmt::Display) -> EncodeError {
        EncodeError {
            reason,
            detail: format!("PGN {} ({}): field `{field}`: {what}", self.pgn, self.id),
        }
    }

    /// The data of this PGN holding the fields of `map` (see the module's documentation).
    pub fn encode(&self, map: &DataMap) -> Result<Vec<u8>, EncodeError> {
        for (key, _) in map.iter() {
            let in_set = |i: usize| {
                self.repeating
                    .iter()
                    .any(|s| (s.start..s.start + s.size).contains(&i))
            };
            let known = key == "header"
                || self
                    .fields
                    .iter()
                    .enumerate()
                    .any(|(i, f)| f.id == key && !in_set(i))
                || (0..self.repeating.len()).any(|k| list_key(k) == key);
            if !known {
                let what = if self.fields.iter().any(|f| f.id == key) {
                    "a field of a repeating set: give it in `list` (or `list2`), one map per set"
                } else {
                    "the PGN has no such field"
                };
                return Err(self.error("n2k-send-unknown-field", key, what));
            }
        }
        let mut w = Writer {
            data: Vec::with_capacity(self.length.unwrap_or(8)),
            pos: 0,
        };
        let mut raws: Vec<Option<u64>> = vec![None; self.fields.len()];
        let mut i = 0;
        while i < self.fields.len() {
            if let Some((k, set)) = self
                .repeating
                .iter()
                .enumerate()
                .find(|(_, s)| s.start == i && s.size > 0)
            {
                let end = (set.start + set.size).min(self.fields.len());
                let key = list_key(k);
                let items: &[Value] = match map.get(key) {
                    None => &[],
                    Some(v) => v.as_list().ok_or_else(|| {
                        self.error("n2k-send-bad-value", key, "expected a list of datamaps")
                    })?,
                };
                if let Some(c) = set.count
                    && let Some(n) = raws.get(c).copied().flatten()
                    && n != items.len() as u64
                {
                    return Err(self.error(
                        "n2k-send-bad-value",
                        key,
                        format_args!(
                            "{} items where `{}` says {n}",
                            items.len(),
                            self.fields[c].id
                        ),
                    ));
                }
                for item in items {
                    let item = item.as_map().ok_or_else(|| {
                        self.error("n2k-send-bad-value", key, "expected a list of datamaps")
                    })?;
                    for (ik, _) in item.iter() {
                        if !self.fields[set.start..end].iter().any(|f| f.id == ik) {
                            return Err(self.error(
                                "n2k-send-unknown-field",
                                &format!("{key}.{ik}"),
                                "the repeating set has no such field",
                            ));
                        }
                    }
                    for j in set.start..end {
                        raws[j] = self.put_field(&mut w, j, item.get(&self.fields[j].id), &raws)?;
                    }
                }
                i = end;
                continue;
            }
            let f = &self.fields[i];
            let mut value = map.get(&f.id).cloned();
            // a count the datamap lacks is its list's length
            if value.is_none()
                && let Some((k, _)) = self
                    .repeating
                    .iter()
                    .enumerate()
                    .find(|(_, s)| s.count == Some(i))
            {
                let n = map
                    .get(list_key(k))
                    .and_then(Value::as_list)
                    .map_or(0, <[Value]>::len);
                value = Some(Value::Int(n as i64));
            }
            if value.is_none()
                && let Some(m) = f.matches
            {
                value = Some(Value::Int(m as i64));
                if let Kind::Lookup(_) | Kind::IndirectLookup { .. } = f.kind {
                    w.put(m, f.bits.unwrap_or(0).min(64));
                    raws[i] = Some(m);
                    i += 1;
                    continue;
                }
            }
            raws[i] = self.put_field(&mut w, i, value.as_ref(), &raws)?;
            i += 1;
        }
        let mut data = w.data;
        let want = match (self.length, self.packet) {
            (Some(n), _) => n,
            (None, Packet::Single) => 8,
            (None, _) => data.len(),
        };
        if data.len() < want {
            data.resize(want, 0xFF);
        }
        let most = match self.packet {
            Packet::Single => 8,
            Packet::Fast => super::frame::FAST_MAX,
            Packet::Iso => super::frame::TP_MAX,
        };
        if data.len() > most {
            return Err(EncodeError {
                reason: "n2k-send-too-long",
                detail: format!(
                    "PGN {} ({}): {} bytes; a {} PGN carries at most {most}",
                    self.pgn,
                    self.id,
                    data.len(),
                    self.packet.name()
                ),
            });
        }
        Ok(data)
    }

    /// Writes field `i` with `value` (absent: "not available"); returns its raw value when it is
    /// a number.
    fn put_field(
        &self,
        w: &mut Writer,
        i: usize,
        value: Option<&Value>,
        raws: &[Option<u64>],
    ) -> Result<Option<u64>, EncodeError> {
        let f = &self.fields[i];
        let bad = |what: String| self.error("n2k-send-bad-value", &f.id, what);
        let range = |what: String| self.error("n2k-send-out-of-range", &f.id, what);
        let fixed = || {
            f.bits
                .filter(|b| *b <= 64)
                .ok_or_else(|| bad(format!("a {} field of no fixed length", f.kind.name())))
        };
        match &f.kind {
            Kind::Reserved => {
                let b = fixed()?;
                w.put(ones(b), b);
                Ok(None)
            }
            Kind::Spare => {
                w.put(0, fixed()?);
                Ok(None)
            }
            Kind::Unsupported(n) => Err(bad(format!(
                "a {n} field (its layout depends on another PGN) cannot be sent"
            ))),
            Kind::Number
            | Kind::Time
            | Kind::Duration
            | Kind::Date
            | Kind::Pgn
            | Kind::FieldIndex
            | Kind::DynamicKey(_) => {
                let b = fixed()?;
                let raw = match value {
                    None => f.not_available(),
                    Some(v) => {
                        let x = v.as_f64().ok_or_else(|| {
                            bad(format!("expected a number, found a {}", v.type_name()))
                        })?;
                        f.raw_of(x).map_err(range)?
                    }
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::Mmsi => {
                let b = fixed()?;
                let raw = match value {
                    None => f.not_available(),
                    Some(v) => {
                        let n = match v {
                            Value::Str(s) => s.trim().parse::<f64>().ok(),
                            other => other.as_f64(),
                        }
                        .ok_or_else(|| bad(format!("`{v:?}` is not an MMSI")))?;
                        f.raw_of(n).map_err(range)?
                    }
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::IsoName => {
                let b = fixed()?;
                let raw = match value {
                    None => ones(b),
                    Some(Value::Str(s)) => u64::from_str_radix(s.trim(), 16)
                        .map_err(|_| bad(format!("`{s}` is not a NAME in hex")))?,
                    Some(Value::Int(n)) => *n as u64,
                    Some(v) => return Err(bad(format!("`{v:?}` is not a NAME"))),
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::Float => {
                let b = fixed()?;
                let raw = match value {
                    None => u64::from(f32::NAN.to_bits()),
                    Some(v) => {
                        let x = v.as_f64().ok_or_else(|| {
                            bad(format!("expected a number, found a {}", v.type_name()))
                        })?;
                        let phys = f.from_seabus(x) / f.resolution;
                        if !phys.is_finite() || phys.abs() > f64::from(f32::MAX) {
                            return Err(range(format!("{x} does not fit a 32-bit float")));
                        }
                        u64::from((phys as f32).to_bits())
                    }
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::Decimal => {
                let b = fixed()?;
                let digits = (b.div_ceil(8) * 2) as usize;
                match value {
                    None => {
                        for _ in 0..b.div_ceil(8) {
                            w.put(0xFF, 8);
                        }
                        Ok(None)
                    }
                    Some(v) => {
                        let n = v.as_i64().filter(|n| *n >= 0).ok_or_else(|| {
                            bad(format!("`{v:?}` is not a whole number of 0 or more"))
                        })?;
                        let text = format!("{n:0digits$}");
                        if text.len() > digits {
                            return Err(range(format!("{n} has more than {digits} digits")));
                        }
                        for pair in text.as_bytes().chunks(2) {
                            w.put(u64::from((pair[0] - b'0') << 4 | (pair[1] - b'0')), 8);
                        }
                        Ok(Some(n as u64))
                    }
                }
            }
            Kind::Lookup(l) => {
                let b = fixed()?;
                let raw = match value {
                    None => ones(b),
                    Some(Value::Str(s)) => *l
                        .values
                        .iter()
                        .find(|(_, n)| **n == **s)
                        .map(|(v, _)| v)
                        .ok_or_else(|| {
                            self.error(
                                "n2k-send-unknown-lookup",
                                &f.id,
                                format_args!("`{s}` is not a name of {}", l.name),
                            )
                        })?,
                    Some(v) => self.lookup_number(f, v, b)?,
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::IndirectLookup { lookup, by } => {
                let b = fixed()?;
                let raw = match value {
                    None => ones(b),
                    Some(Value::Str(s)) => {
                        let other = raws.get(*by).copied().flatten();
                        *lookup
                            .values
                            .iter()
                            .find(|((k, _), n)| **n == **s && other.is_none_or(|o| o == *k))
                            .map(|((_, v), _)| v)
                            .ok_or_else(|| {
                                self.error(
                                    "n2k-send-unknown-lookup",
                                    &f.id,
                                    format_args!("`{s}` is not a name of {}", lookup.name),
                                )
                            })?
                    }
                    Some(v) => self.lookup_number(f, v, b)?,
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::BitLookup(l) => {
                let b = fixed()?;
                let raw = match value {
                    None => 0,
                    Some(Value::List(names)) => {
                        let mut raw = 0u64;
                        for n in names {
                            let bit = match n {
                                Value::Str(s) => l
                                    .bits
                                    .iter()
                                    .find(|(_, name)| **name == **s)
                                    .map(|(bit, _)| *bit)
                                    .or_else(|| {
                                        s.strip_prefix("bit ").and_then(|d| d.parse().ok())
                                    }),
                                other => other.as_i64().and_then(|i| u32::try_from(i).ok()),
                            }
                            .filter(|bit| *bit < b)
                            .ok_or_else(|| {
                                self.error(
                                    "n2k-send-unknown-lookup",
                                    &f.id,
                                    format_args!("`{n:?}` is not a bit of {}", l.name),
                                )
                            })?;
                            raw |= 1 << bit;
                        }
                        raw
                    }
                    Some(v) => return Err(bad(format!("expected a list of names, found {v:?}"))),
                };
                w.put(raw, b);
                Ok(Some(raw))
            }
            Kind::StringFix => {
                let b = fixed()?;
                let n = (b / 8) as usize;
                let text = self.text(f, value)?;
                if text.len() > n {
                    return Err(range(format!("{} bytes; the field holds {n}", text.len())));
                }
                let mut bytes = text.to_vec();
                bytes.resize(n, 0xFF);
                w.bytes(&bytes);
                Ok(None)
            }
            Kind::StringLz => {
                let text = self.text(f, value)?;
                if text.len() > 254 {
                    return Err(range(format!("{} bytes; at most 254", text.len())));
                }
                w.put(text.len() as u64, 8);
                w.bytes(text);
                w.put(0, 8);
                Ok(None)
            }
            Kind::StringLau => {
                let text = self.text(f, value)?;
                if text.len() > 253 {
                    return Err(range(format!("{} bytes; at most 253", text.len())));
                }
                w.put(text.len() as u64 + 2, 8);
                w.put(1, 8);
                w.bytes(text);
                Ok(None)
            }
            Kind::Binary { length_from } => {
                let bytes: &[u8] = match value {
                    None => &[],
                    Some(Value::Bytes(b)) => b,
                    Some(v) => {
                        return Err(bad(format!("expected bytes, found a {}", v.type_name())));
                    }
                };
                match (f.bits, length_from) {
                    (Some(bits), _) => {
                        if value.is_none() {
                            let mut left = bits;
                            while left > 0 {
                                let n = left.min(64);
                                w.put(ones(n), n);
                                left -= n;
                            }
                            return Ok(None);
                        }
                        if bytes.len() as u64 * 8 < u64::from(bits) {
                            return Err(range(format!(
                                "{} bytes; the field holds {bits} bits",
                                bytes.len()
                            )));
                        }
                        let mut left = bits;
                        for byte in bytes {
                            if left == 0 {
                                break;
                            }
                            let n = left.min(8);
                            w.put(u64::from(*byte), n);
                            left -= n;
                        }
                        Ok(None)
                    }
                    (None, Some(len)) => {
                        let want = raws.get(*len).copied().flatten().unwrap_or(0);
                        if want != bytes.len() as u64 * 8 {
                            return Err(bad(format!(
                                "{} bytes where `{}` says {want} bits",
                                bytes.len(),
                                self.fields[*len].id
                            )));
                        }
                        w.bytes(bytes);
                        Ok(None)
                    }
                    (None, None) => Err(bad("bytes of no known length".into())),
                }
            }
        }
    }

    /// A lookup given as a number: any raw value but the kept codes.
    fn lookup_number(&self, f: &Field, v: &Value, bits: u32) -> Result<u64, EncodeError> {
        let (_, max) = raw_limits(bits, false, 0);
        match v.as_i64() {
            Some(n) if n >= 0 && i128::from(n) <= max => Ok(n as u64),
            Some(n) => Err(self.error(
                "n2k-send-out-of-range",
                &f.id,
                format_args!("{n} is outside 0 to {max}"),
            )),
            None => Err(self.error(
                "n2k-send-bad-value",
                &f.id,
                format_args!("expected a name or a number, found {v:?}"),
            )),
        }
    }

    fn text<'v>(&self, f: &Field, value: Option<&'v Value>) -> Result<&'v [u8], EncodeError> {
        match value {
            None => Ok(&[]),
            Some(Value::Str(s)) => Ok(s.as_bytes()),
            Some(v) => Err(self.error(
                "n2k-send-bad-value",
                &f.id,
                format_args!("expected a string, found a {}", v.type_name()),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::builtin;
    use super::*;

    fn def(pgn: u32) -> std::sync::Arc<PgnDef> {
        builtin::database().definitions(pgn)[0].clone()
    }

    #[test]
    fn a_heading_is_the_bytes_the_standard_gives() {
        let m = DataMap::new()
            .and("sid", Value::Int(1))
            .and("heading", Value::Float(15708.0e-4f64.to_degrees()))
            .and("reference", Value::from("True"));
        // the frame of configs/nmea2000.xml: deviation and variation not available
        assert_eq!(
            def(127250).encode(&m).unwrap(),
            [1, 0x5C, 0x3D, 0xFF, 0x7F, 0xFF, 0x7F, 0xFC]
        );
    }

    #[test]
    fn every_built_in_pgn_decodes_to_what_was_encoded() {
        let db = builtin::database();
        let heading = DataMap::new()
            .and("sid", Value::Int(7))
            .and("heading", Value::Float(70.0))
            .and("deviation", Value::Float(-0.5))
            .and("variation", Value::Float(2.5))
            .and("reference", Value::from("Magnetic"));
        let engine = DataMap::new()
            .and("instance", Value::from("Dual Engine Starboard"))
            .and("oilTemperature", Value::Float(90.05))
            .and(
                "discreteStatus1",
                Value::List(vec![Value::from("Check Engine"), Value::from("Water Flow")]),
            )
            .and("engineLoad", Value::Int(50));
        let gnss = DataMap::new()
            .and("sid", Value::Int(9))
            .and("latitude", Value::Float(43.5))
            .and("longitude", Value::Float(-16.25))
            .and("method", Value::from("RTK Fixed Integer"))
            .and(
                "list",
                Value::List(vec![Value::Map(
                    DataMap::new()
                        .and("referenceStationType", Value::from("GPS"))
                        .and("referenceStationId", Value::Int(100)),
                )]),
            );
        for (pgn, m) in [(127250, heading), (127489, engine), (129029, gnss)] {
            let d = &db.definitions(pgn)[0];
            let data = d.encode(&m).unwrap();
            let back = d.decode(&data);
            assert!(!back.short, "{pgn}");
            for (k, v) in m.iter() {
                let got = back
                    .map
                    .get(k)
                    .unwrap_or_else(|| panic!("{pgn} {k}: {back:?}"));
                match (v, got) {
                    (Value::Float(a), _) => {
                        let b = got.as_f64().unwrap();
                        assert!((a - b).abs() < 0.01, "{pgn} {k}: {a} vs {b}");
                    }
                    (Value::List(a), Value::List(b)) if k == "list" => {
                        assert_eq!(a.len(), b.len());
                        assert_eq!(
                            b[0].as_map().unwrap().get_str("referenceStationType"),
                            Some("GPS")
                        );
                    }
                    _ => assert_eq!(v, got, "{pgn} {k}"),
                }
            }
        }
    }

    #[test]
    fn values_it_cannot_hold_are_refused_never_clamped() {
        let d = def(127250);
        let e = d
            .encode(&DataMap::new().and("heading", Value::Float(400.0)))
            .unwrap_err();
        assert_eq!(e.reason, "n2k-send-out-of-range");
        assert!(
            e.detail
                .contains("`heading`: 400 deg is outside 0 to 359.999994 deg"),
            "{e}"
        );
        let e = d
            .encode(&DataMap::new().and("reference", Value::from("Northish")))
            .unwrap_err();
        assert_eq!(e.reason, "n2k-send-unknown-lookup");
        assert!(
            e.detail
                .contains("`reference`: `Northish` is not a name of DIRECTION_REFERENCE"),
            "{e}"
        );
        let e = d
            .encode(&DataMap::new().and("headng", Value::Float(1.0)))
            .unwrap_err();
        assert_eq!(e.reason, "n2k-send-unknown-field");
        let e = def(129029)
            .encode(&DataMap::new().and("referenceStationId", Value::Int(5)))
            .unwrap_err();
        assert!(e.detail.contains("give it in `list`"), "{e}");
        let e = d
            .encode(&DataMap::new().and("heading", Value::from("north")))
            .unwrap_err();
        assert_eq!(e.reason, "n2k-send-bad-value");
        // the kept codes are not values: a sid of 255 is "not available"
        assert_eq!(
            d.encode(&DataMap::new().and("sid", Value::Int(253)))
                .unwrap_err()
                .reason,
            "n2k-send-out-of-range"
        );
        // a negative rate is fine, a NaN is not
        let r = def(127251);
        assert!(
            r.encode(&DataMap::new().and("rate", Value::Float(-3.0)))
                .is_ok()
        );
        assert!(
            r.encode(&DataMap::new().and("rate", Value::Float(f64::NAN)))
                .is_err()
        );
        // 359.999° rounds to a full turn: north
        let data = d
            .encode(&DataMap::new().and("heading", Value::Float(359.999)))
            .unwrap();
        assert_eq!(&data[1..3], &[0, 0]);
    }

    #[test]
    fn absent_fields_are_not_available_and_reserved_bits_ones() {
        let d = def(127250);
        let data = d.encode(&DataMap::new()).unwrap();
        // sid, heading all ones; deviation, variation 0x7FFF; reference 3, reserved ones
        assert_eq!(data, [0xFF, 0xFF, 0xFF, 0xFF, 0x7F, 0xFF, 0x7F, 0xFF]);
        assert!(d.decode(&data).map.is_empty());
    }
}
