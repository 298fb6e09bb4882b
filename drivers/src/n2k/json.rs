//! Reading canboat's PGN database (`canboat.json`) into a [`Database`].
//!
//! The file is a JSON object; what is read of it:
//!
//! - `PGNs`: the definitions, each with `PGN`, `Id`, `Description`, `Type` (`Single`, `Fast`,
//!   `ISO`; `Mixed` is read as `Single`), `Length`, `Priority`, `Fallback`, `Fields` and
//!   `RepeatingFieldSet1Size` / `…StartField` / `…CountField` (and the same for set 2);
//! - each field's `Id`, `Name`, `BitLength`, `BitOffset`, `Resolution`, `Offset`, `Signed`,
//!   `Unit`, `FieldType`, `RangeMin`/`RangeMax`, `Match`, `BitLengthField`, and the enumeration it
//!   names: `LookupEnumeration`, `LookupBitEnumeration`, or `LookupIndirectEnumeration` with
//!   `LookupIndirectEnumerationFieldOrder`;
//! - `LookupEnumerations` (`Name`, `EnumValues` of `Name` and `Value`),
//!   `LookupBitEnumerations` (`Name`, `EnumBitValues` of `Name` and `Bit`) and
//!   `LookupIndirectEnumerations` (`Name`, `EnumValues` of `Name`, `Value1`, `Value2`).
//!
//! Other keys are ignored. Every error names the file, line and column, and the path to what is
//! wrong: `canboat.json:214:9: PGNs[3] (127250 vesselHeading).Fields[1] (heading).BitLength:
//! expected a whole number, found "16"`.

use super::pgn::{
    BitLookup, Database, Field, IndirectLookup, Kind, Lookup, Packet, PgnDef, Repeating,
};
use seabus_medium::Key;
use seabus_medium::xml::{FileError, Pos};
use serde_json::Value;
use serde_json::value::RawValue;
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

/// Reads a canboat database file.
pub fn load(path: &Path) -> Result<Database, FileError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| FileError {
        pos: Pos {
            file: Arc::from(name.as_str()),
            line: 1,
            col: 1,
        },
        message: format!("cannot read: {e}"),
    })?;
    parse(&name, &text)
}

/// Reads a canboat database from `text`, naming `file` in errors.
pub fn parse(file: &str, text: &str) -> Result<Database, FileError> {
    let r = Reader {
        file: Arc::from(file),
        text,
    };
    let top: BTreeMap<String, &RawValue> =
        serde_json::from_str(text).map_err(|e| r.json_error(text, "", &e))?;
    let list = |key: &str| -> Result<Vec<&RawValue>, FileError> {
        match top.get(key) {
            None => Ok(Vec::new()),
            Some(raw) => serde_json::from_str(raw.get())
                .map_err(|_| r.at(raw.get(), None, key, "expected a list".to_string())),
        }
    };
    let Some(pgns) = top.get("PGNs") else {
        return Err(r.at(text, None, "", "no `PGNs`: not a canboat database".into()));
    };
    let mut lookups = HashMap::new();
    for (i, raw) in list("LookupEnumerations")?.into_iter().enumerate() {
        let o = r.object(raw, format!("LookupEnumerations[{i}]"))?;
        let name = &*o.required_str("Name")?;
        let mut values = BTreeMap::new();
        for (j, v) in o.items("EnumValues")?.into_iter().enumerate() {
            let e = r.object(v, format!("{}.EnumValues[{j}]", o.path))?;
            values.insert(e.required_u64("Value")?, key(&e.required_str("Name")?));
        }
        lookups.insert(
            name.to_string(),
            Arc::new(Lookup {
                name: key(name),
                values,
            }),
        );
    }
    let mut bit_lookups = HashMap::new();
    for (i, raw) in list("LookupBitEnumerations")?.into_iter().enumerate() {
        let o = r.object(raw, format!("LookupBitEnumerations[{i}]"))?;
        let name = &*o.required_str("Name")?;
        let mut bits = BTreeMap::new();
        for (j, v) in o.items("EnumBitValues")?.into_iter().enumerate() {
            let e = r.object(v, format!("{}.EnumBitValues[{j}]", o.path))?;
            let bit = e.required_u64("Bit")?;
            if bit > 63 {
                return Err(e.error("Bit", format!("bit {bit}: a bit field has at most 64")));
            }
            bits.insert(bit as u32, key(&e.required_str("Name")?));
        }
        bit_lookups.insert(
            name.to_string(),
            Arc::new(BitLookup {
                name: key(name),
                bits,
            }),
        );
    }
    let mut indirect = HashMap::new();
    for (i, raw) in list("LookupIndirectEnumerations")?.into_iter().enumerate() {
        let o = r.object(raw, format!("LookupIndirectEnumerations[{i}]"))?;
        let name = &*o.required_str("Name")?;
        let mut values = BTreeMap::new();
        for (j, v) in o.items("EnumValues")?.into_iter().enumerate() {
            let e = r.object(v, format!("{}.EnumValues[{j}]", o.path))?;
            values.insert(
                (e.required_u64("Value1")?, e.required_u64("Value2")?),
                key(&e.required_str("Name")?),
            );
        }
        indirect.insert(
            name.to_string(),
            Arc::new(IndirectLookup {
                name: key(name),
                values,
            }),
        );
    }
    let tables = Tables {
        lookups,
        bit_lookups,
        indirect,
    };
    let mut db = Database::new(file);
    let items: Vec<&RawValue> = serde_json::from_str(pgns.get())
        .map_err(|_| r.at(pgns.get(), None, "PGNs", "expected a list".to_string()))?;
    for (i, raw) in items.into_iter().enumerate() {
        db.add(r.pgn(raw, i, &tables)?);
    }
    Ok(db)
}

fn key(s: &str) -> Key {
    Cow::Owned(s.to_string())
}

/// The enumerations fields may name.
struct Tables {
    lookups: HashMap<String, Arc<Lookup>>,
    bit_lookups: HashMap<String, Arc<BitLookup>>,
    indirect: HashMap<String, Arc<IndirectLookup>>,
}

/// The file being read.
struct Reader<'t> {
    file: Arc<str>,
    text: &'t str,
}

/// One JSON object of the file: its keys with their text (slices of the file's), its own text
/// and its path.
struct Obj<'r, 't> {
    reader: &'r Reader<'t>,
    map: BTreeMap<String, &'t RawValue>,
    raw: &'t str,
    path: String,
}

impl<'t> Reader<'t> {
    /// Line and column (from 1, in characters) of byte `at` of the file.
    fn pos(&self, at: usize) -> Pos {
        let at = at.min(self.text.len());
        let before = &self.text[..at];
        let line = before.matches('\n').count() as u32 + 1;
        let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) as u32 + 1;
        Pos {
            file: self.file.clone(),
            line,
            col,
        }
    }

    /// An error placed at `key` within `slice` (a slice of the file's text), or at its start.
    fn at(&self, slice: &str, key: Option<&str>, path: &str, message: String) -> FileError {
        let base = (slice.as_ptr() as usize).saturating_sub(self.text.as_ptr() as usize);
        let inner = key
            .and_then(|k| slice.find(&format!("\"{k}\"")))
            .unwrap_or(0);
        let message = if path.is_empty() {
            message
        } else {
            format!("{path}: {message}")
        };
        FileError {
            pos: self.pos(base + inner),
            message,
        }
    }

    /// A JSON error of serde's in `slice`, placed by its line and column.
    fn json_error(&self, slice: &str, path: &str, e: &serde_json::Error) -> FileError {
        let base = (slice.as_ptr() as usize).saturating_sub(self.text.as_ptr() as usize);
        // serde counts lines and columns (bytes) within the slice
        let offset: usize = slice
            .split_inclusive('\n')
            .take(e.line().saturating_sub(1))
            .map(str::len)
            .sum::<usize>()
            + e.column().saturating_sub(1);
        let shown = e.to_string();
        let what = shown
            .rsplit_once(" at line ")
            .map_or(shown.as_str(), |(w, _)| w)
            .to_string();
        let message = if path.is_empty() {
            format!("not JSON: {what}")
        } else {
            format!("{path}: {what}")
        };
        FileError {
            pos: self.pos(base + offset),
            message,
        }
    }

    fn object<'r>(&'r self, raw: &'t RawValue, path: String) -> Result<Obj<'r, 't>, FileError> {
        let map: BTreeMap<String, &'t RawValue> = serde_json::from_str(raw.get())
            .map_err(|_| self.at(raw.get(), None, &path, "expected an object".to_string()))?;
        Ok(Obj {
            reader: self,
            map,
            raw: raw.get(),
            path,
        })
    }

    /// The definition `raw`, the `i`-th of `PGNs`.
    fn pgn(&self, raw: &'t RawValue, i: usize, t: &Tables) -> Result<PgnDef, FileError> {
        let mut o = self.object(raw, format!("PGNs[{i}]"))?;
        let pgn = o.required_u64("PGN")?;
        if pgn > 0x3FFFF {
            return Err(o.error("PGN", format!("{pgn} is past the largest PGN 262143")));
        }
        let id = o.required_str("Id")?.to_string();
        if id.is_empty() || id.contains(|c: char| c == '.' || c == '*' || c.is_whitespace()) {
            return Err(o.error(
                "Id",
                format!("`{id}` cannot be a topic segment (no dots, `*` or spaces)"),
            ));
        }
        o.path = format!("PGNs[{i}] ({pgn} {id})");
        let packet = match o.str("Type")?.as_deref() {
            None | Some("Single") | Some("Mixed") => Packet::Single,
            Some("Fast") => Packet::Fast,
            Some("ISO") => Packet::Iso,
            Some(other) => {
                return Err(o.error(
                    "Type",
                    format!("`{other}`: expected Single, Fast, ISO or Mixed"),
                ));
            }
        };
        let length = o.u64("Length")?.map(|l| l as usize);
        if length.is_some_and(|l| l > 1785) {
            return Err(o.error(
                "Length",
                "longer than 1785 bytes, the most a PGN can carry".into(),
            ));
        }
        let priority = match o.u64("Priority")? {
            Some(p) if p > 7 => return Err(o.error("Priority", format!("{p}: expected 0 to 7"))),
            p => p.map(|p| p as u8),
        };
        let mut fields: Vec<Field> = Vec::new();
        let mut at: Option<u32> = Some(0);
        for (j, raw) in o.items("Fields")?.into_iter().enumerate() {
            let f = self.field(raw, format!("{}.Fields[{j}]", o.path), &fields, at, t)?;
            at = match (at, f.bits, f.kind.self_delimited()) {
                (Some(a), Some(b), false) => a.checked_add(b),
                _ => None,
            };
            fields.push(f);
        }
        for (j, f) in fields.iter().enumerate() {
            if let Kind::IndirectLookup { by, .. } = f.kind
                && by >= fields.len()
            {
                return Err(self.at(
                    o.raw,
                    Some(&f.id),
                    &format!(
                        "{}.Fields[{j}] ({}).LookupIndirectEnumerationFieldOrder",
                        o.path, f.id
                    ),
                    format!("field {} is not among its {} fields", by + 1, fields.len()),
                ));
            }
        }
        let mut repeating = Vec::new();
        for set in [1, 2] {
            let size = o.u64(&format!("RepeatingFieldSet{set}Size"))?;
            let start = o.u64(&format!("RepeatingFieldSet{set}StartField"))?;
            let count = o.u64(&format!("RepeatingFieldSet{set}CountField"))?;
            let (Some(size), Some(start)) = (size, start) else {
                continue;
            };
            let key = format!("RepeatingFieldSet{set}StartField");
            let (size, start) = (size as usize, start as usize);
            if start == 0 || start - 1 + size > fields.len() {
                return Err(o.error(
                    &key,
                    format!(
                        "fields {start} to {} are not among its {} fields",
                        start + size.saturating_sub(1),
                        fields.len()
                    ),
                ));
            }
            let count = match count {
                None => None,
                Some(c) if c >= 1 && (c as usize) < start => Some(c as usize - 1),
                Some(c) => {
                    return Err(o.error(
                        &format!("RepeatingFieldSet{set}CountField"),
                        format!("field {c} is not a field before the set (from field {start})"),
                    ));
                }
            };
            repeating.push(Repeating {
                start: start - 1,
                size,
                count,
            });
        }
        Ok(PgnDef {
            pgn: pgn as u32,
            id: key(&id),
            description: key(o.str("Description")?.as_deref().unwrap_or(&id)),
            packet,
            length,
            priority,
            fields,
            repeating,
            fallback: o.bool("Fallback")?.unwrap_or(false),
        })
    }

    /// A field; `before` are the fields before it, `at` the bit it starts at when known.
    fn field(
        &self,
        raw: &'t RawValue,
        path: String,
        before: &[Field],
        at: Option<u32>,
        t: &Tables,
    ) -> Result<Field, FileError> {
        let mut o = self.object(raw, path)?;
        let id = o.required_str("Id")?.to_string();
        o.path = format!("{} ({id})", o.path);
        let field_at = |o: &Obj<'_, '_>, k: &str| -> Result<Option<usize>, FileError> {
            match o.u64(k)? {
                None => Ok(None),
                Some(n) if n >= 1 && (n as usize) <= before.len() => Ok(Some(n as usize - 1)),
                Some(n) => Err(o.error(
                    k,
                    format!(
                        "field {n} is not a field before this one (it is field {})",
                        before.len() + 1
                    ),
                )),
            }
        };
        let type_name = o.required_str("FieldType")?;
        let type_name = &*type_name;
        let kind = match type_name {
            "NUMBER" => Kind::Number,
            "FLOAT" => Kind::Float,
            "DECIMAL" => Kind::Decimal,
            "LOOKUP" => {
                let name = &*o.required_str("LookupEnumeration")?;
                Kind::Lookup(t.lookups.get(name).cloned().ok_or_else(|| {
                    o.error(
                        "LookupEnumeration",
                        format!("no enumeration `{name}` in LookupEnumerations"),
                    )
                })?)
            }
            "BITLOOKUP" => {
                let name = &*o.required_str("LookupBitEnumeration")?;
                match (t.bit_lookups.get(name), t.lookups.get(name)) {
                    (Some(b), _) => Kind::BitLookup(b.clone()),
                    // a bit field named after a value enumeration (canboat has one) reads as one
                    (None, Some(l)) => Kind::Lookup(l.clone()),
                    (None, None) => {
                        return Err(o.error(
                            "LookupBitEnumeration",
                            format!("no enumeration `{name}` in LookupBitEnumerations"),
                        ));
                    }
                }
            }
            "INDIRECT_LOOKUP" => {
                let name = &*o.required_str("LookupIndirectEnumeration")?;
                let lookup = t.indirect.get(name).cloned().ok_or_else(|| {
                    o.error(
                        "LookupIndirectEnumeration",
                        format!("no enumeration `{name}` in LookupIndirectEnumerations"),
                    )
                })?;
                // the other field may come after this one (an ISO name's device class does):
                // checked once every field is read
                let by = match o.u64("LookupIndirectEnumerationFieldOrder")? {
                    Some(n) if n >= 1 && n as usize != before.len() + 1 => n as usize - 1,
                    _ => {
                        return Err(o.error(
                            "LookupIndirectEnumerationFieldOrder",
                            "an indirect lookup needs the order of another field it depends on"
                                .into(),
                        ));
                    }
                };
                Kind::IndirectLookup { lookup, by }
            }
            "TIME" => Kind::Time,
            "DURATION" => Kind::Duration,
            "DATE" => Kind::Date,
            "PGN" => Kind::Pgn,
            "MMSI" => Kind::Mmsi,
            "ISO_NAME" => Kind::IsoName,
            "FIELD_INDEX" => Kind::FieldIndex,
            "STRING_FIX" => Kind::StringFix,
            "STRING_LZ" => Kind::StringLz,
            "STRING_LAU" => Kind::StringLau,
            "BINARY" => Kind::Binary {
                length_from: field_at(&o, "BitLengthField")?,
            },
            "RESERVED" => Kind::Reserved,
            "SPARE" => Kind::Spare,
            "DYNAMIC_FIELD_KEY" => Kind::DynamicKey("DYNAMIC_FIELD_KEY"),
            "DYNAMIC_FIELD_LENGTH" => Kind::DynamicKey("DYNAMIC_FIELD_LENGTH"),
            "DYNAMIC_FIELD_VALUE" => Kind::Unsupported("DYNAMIC_FIELD_VALUE"),
            "VARIABLE" => Kind::Unsupported("VARIABLE"),
            other => {
                return Err(o.error(
                    "FieldType",
                    format!(
                        "`{other}` is not a field type (NUMBER, FLOAT, DECIMAL, LOOKUP, INDIRECT_LOOKUP, \
                         BITLOOKUP, TIME, DURATION, DATE, PGN, MMSI, ISO_NAME, FIELD_INDEX, STRING_FIX, \
                         STRING_LZ, STRING_LAU, BINARY, RESERVED, SPARE, VARIABLE, DYNAMIC_FIELD_KEY, \
                         DYNAMIC_FIELD_LENGTH, DYNAMIC_FIELD_VALUE)"
                    ),
                ));
            }
        };
        let bits = o.u64("BitLength")?;
        let bits = match bits {
            Some(0) => return Err(o.error("BitLength", "a field of 0 bits".into())),
            Some(b) if b > 1785 * 8 => {
                return Err(o.error("BitLength", format!("{b} bits: longer than any PGN")));
            }
            b => b.map(|b| b as u32),
        };
        let needs_word = match &kind {
            Kind::Float => Some((32, 32)),
            Kind::IsoName => Some((64, 64)),
            Kind::Number
            | Kind::Time
            | Kind::Duration
            | Kind::Date
            | Kind::Pgn
            | Kind::Mmsi
            | Kind::FieldIndex
            | Kind::DynamicKey(_)
            | Kind::Lookup(_)
            | Kind::IndirectLookup { .. }
            | Kind::BitLookup(_) => Some((1, 64)),
            _ => None,
        };
        match (needs_word, bits) {
            (Some((lo, hi)), Some(b)) if b < lo || b > hi => {
                return Err(o.error(
                    "BitLength",
                    format!("{b} bits: a {type_name} field has {lo} to {hi}"),
                ));
            }
            (Some(_), None) => {
                return Err(o.error(
                    "BitLength",
                    format!("a {type_name} field needs a bit length"),
                ));
            }
            _ => {}
        }
        let delimited = kind.self_delimited()
            || matches!(
                kind,
                Kind::Unsupported(_)
                    | Kind::Binary {
                        length_from: Some(_)
                    }
            );
        if bits.is_none() && !delimited {
            return Err(o.error(
                "BitLength",
                format!("a {type_name} field needs a bit length"),
            ));
        }
        if matches!(kind, Kind::StringFix) && bits.is_some_and(|b| b % 8 != 0) {
            return Err(o.error("BitLength", "a fixed string is whole bytes".into()));
        }
        let bit_offset = o.u64("BitOffset")?.map(|b| b as u32);
        if let (Some(said), Some(is)) = (bit_offset, at)
            && said != is
        {
            return Err(o.error(
                "BitOffset",
                format!("{said}, but the fields before it end at bit {is}"),
            ));
        }
        let resolution = o.f64("Resolution")?.unwrap_or(1.0);
        if resolution == 0.0 || !resolution.is_finite() {
            return Err(o.error("Resolution", format!("{resolution} gives no value")));
        }
        let range = match (o.f64("RangeMin")?, o.f64("RangeMax")?) {
            (Some(lo), Some(hi)) if lo <= hi => Some((lo, hi)),
            (Some(lo), Some(hi)) => {
                return Err(o.error("RangeMax", format!("{hi} is below RangeMin {lo}")));
            }
            _ => None,
        };
        let matches = o.u64("Match")?;
        if let (Some(m), Some(b)) = (matches, bits)
            && b < 64
            && m >> b != 0
        {
            return Err(o.error("Match", format!("{m} does not fit in {b} bits")));
        }
        let offset = o.i64("Offset")?.unwrap_or(0);
        Ok(Field {
            id: key(&id),
            name: key(o.str("Name")?.as_deref().unwrap_or(&id)),
            bits,
            bit_offset: bit_offset.or(at.filter(|_| bits.is_some())),
            resolution,
            offset,
            signed: o.bool("Signed")?.unwrap_or(false),
            unit: key(o.str("Unit")?.as_deref().unwrap_or("")),
            kind,
            range: range.filter(|_| needs_word.is_some()),
            matches,
        })
    }
}

impl<'t> Obj<'_, 't> {
    fn error(&self, key: &str, message: String) -> FileError {
        self.reader.at(
            self.raw,
            Some(key),
            &format!("{}.{key}", self.path),
            message,
        )
    }

    fn wrong(&self, key: &str, expected: &str, found: &Value) -> FileError {
        let mut shown = found.to_string();
        if shown.len() > 40 {
            shown.truncate(40);
            shown.push('…');
        }
        self.error(key, format!("expected {expected}, found {shown}"))
    }

    /// The value of `key`, when it is there and not null.
    fn get(&self, key: &str) -> Result<Option<Value>, FileError> {
        let Some(raw) = self.map.get(key) else {
            return Ok(None);
        };
        match serde_json::from_str::<Value>(raw.get()) {
            Ok(Value::Null) => Ok(None),
            Ok(v) => Ok(Some(v)),
            Err(e) => Err(self.reader.json_error(raw.get(), &self.path, &e)),
        }
    }

    fn str(&self, key: &str) -> Result<Option<Cow<'t, str>>, FileError> {
        let Some(raw) = self.map.get(key) else {
            return Ok(None);
        };
        // a string without escapes is borrowed from the file
        match serde_json::from_str::<&str>(raw.get()) {
            Ok(s) => Ok(Some(Cow::Borrowed(s))),
            Err(_) => match self.get(key)? {
                None => Ok(None),
                Some(Value::String(s)) => Ok(Some(Cow::Owned(s))),
                Some(v) => Err(self.wrong(key, "a string", &v)),
            },
        }
    }

    fn required_str(&self, key: &str) -> Result<Cow<'t, str>, FileError> {
        self.str(key)?
            .ok_or_else(|| self.error(key, "missing".into()))
    }

    fn u64(&self, key: &str) -> Result<Option<u64>, FileError> {
        match self.get(key)? {
            None => Ok(None),
            Some(v) => v
                .as_u64()
                .map(Some)
                .ok_or_else(|| self.wrong(key, "a whole number of 0 or more", &v)),
        }
    }

    fn required_u64(&self, key: &str) -> Result<u64, FileError> {
        self.u64(key)?
            .ok_or_else(|| self.error(key, "missing".into()))
    }

    fn i64(&self, key: &str) -> Result<Option<i64>, FileError> {
        match self.get(key)? {
            None => Ok(None),
            Some(v) => v
                .as_i64()
                .map(Some)
                .ok_or_else(|| self.wrong(key, "a whole number", &v)),
        }
    }

    fn f64(&self, key: &str) -> Result<Option<f64>, FileError> {
        match self.get(key)? {
            None => Ok(None),
            Some(v) => v
                .as_f64()
                .map(Some)
                .ok_or_else(|| self.wrong(key, "a number", &v)),
        }
    }

    fn bool(&self, key: &str) -> Result<Option<bool>, FileError> {
        match self.get(key)? {
            None => Ok(None),
            Some(Value::Bool(b)) => Ok(Some(b)),
            Some(v) => Err(self.wrong(key, "true or false", &v)),
        }
    }

    /// The objects of list `key` (none when it is missing), as slices of the file's text.
    fn items(&self, key: &str) -> Result<Vec<&'t RawValue>, FileError> {
        let Some(list) = self.map.get(key) else {
            return Ok(Vec::new());
        };
        serde_json::from_str(list.get()).map_err(|_| {
            self.reader.at(
                list.get(),
                None,
                &format!("{}.{key}", self.path),
                "expected a list".into(),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = r#"{
  "LookupEnumerations": [
    {"Name": "DIRECTION_REFERENCE", "MaxValue": 3,
     "EnumValues": [{"Name": "True", "Value": 0}, {"Name": "Magnetic", "Value": 1}]}
  ],
  "PGNs": [
    {"PGN": 127250, "Id": "vesselHeading", "Description": "Vessel Heading", "Type": "Single",
     "Length": 8, "Priority": 2,
     "Fields": [
       {"Order": 1, "Id": "sid", "Name": "SID", "BitLength": 8, "BitOffset": 0,
        "Resolution": 1, "Signed": false, "FieldType": "NUMBER"},
       {"Order": 2, "Id": "heading", "Name": "Heading", "BitLength": 16, "BitOffset": 8,
        "Unit": "rad", "Resolution": 0.0001, "Signed": false, "RangeMin": 0,
        "RangeMax": 6.2831852, "FieldType": "NUMBER"},
       {"Order": 3, "Id": "reference", "Name": "Reference", "BitLength": 2, "BitOffset": 24,
        "FieldType": "LOOKUP", "LookupEnumeration": "DIRECTION_REFERENCE"}
     ]}
  ]
}"#;

    #[test]
    fn a_small_database_reads() {
        let db = parse("small.json", SMALL).unwrap();
        let d = &db.definitions(127250)[0];
        assert_eq!(
            (&*d.id, d.packet, d.length),
            ("vesselHeading", Packet::Single, Some(8))
        );
        let ids: Vec<&str> = d.fields.iter().map(|f| &*f.id).collect();
        assert_eq!(ids, ["sid", "heading", "reference"]);
        assert_eq!(d.fields[1].range, Some((0.0, 6.2831852)));
        let m = d.decode(&[7, 0x5C, 0x3D, 0x01]).map;
        assert_eq!(m.get_i64("sid"), Some(7));
        assert!((m.get_f64("heading").unwrap() - 90.0).abs() < 0.01);
        assert_eq!(m.get_str("reference"), Some("Magnetic"));
    }

    #[test]
    fn errors_name_the_place_and_the_path() {
        let err = |text: &str| parse("db.json", text).unwrap_err().to_string();
        // a JSON syntax error
        let e = err("{\n  \"PGNs\": [\n    {\"PGN\": 1,,}\n  ]\n}");
        assert!(
            e.starts_with("db.json:3:15: not JSON: key must be a string"),
            "{e}"
        );
        // a wrong type
        let bad = SMALL.replace("\"BitLength\": 16", "\"BitLength\": \"16\"");
        let e = err(&bad);
        assert_eq!(
            e,
            "db.json:12:57: PGNs[0] (127250 vesselHeading).Fields[1] (heading).BitLength: \
             expected a whole number of 0 or more, found \"16\""
        );
        // an enumeration that is not there
        let bad = SMALL.replace(
            "\"LookupEnumeration\": \"DIRECTION",
            "\"LookupEnumeration\": \"DIRECTIONS",
        );
        let e = err(&bad);
        assert!(
            e.starts_with("db.json:16:32: PGNs[0] (127250 vesselHeading).Fields[2] (reference).LookupEnumeration: no enumeration `DIRECTIONS_REFERENCE`"),
            "{e}"
        );
        // a bit offset the fields before it do not give
        let bad = SMALL.replace("\"BitOffset\": 24", "\"BitOffset\": 25");
        let e = err(&bad);
        assert!(
            e.ends_with(
                "Fields[2] (reference).BitOffset: 25, but the fields before it end at bit 24"
            ),
            "{e}"
        );
        let bad = SMALL.replace("\"Type\": \"Single\"", "\"Type\": \"Slow\"");
        assert!(err(&bad).contains(
            "PGNs[0] (127250 vesselHeading).Type: `Slow`: expected Single, Fast, ISO or Mixed"
        ));
        let bad = SMALL.replace("\"FieldType\": \"NUMBER\"}", "\"FieldType\": \"NUMBR\"}");
        assert!(err(&bad).contains("Fields[0] (sid).FieldType: `NUMBR` is not a field type"));
        assert!(err("{}").contains("no `PGNs`"));
        assert!(err("[1]").starts_with("db.json:1:1: not JSON: "));
    }
}
