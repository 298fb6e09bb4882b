//! seabus-medium-moos, MOOS: [`wire`] is the V10 message and packet format, [`client`] the `moos://` medium (an
//! asynchronous client of a MOOSDB), [`db`] a small MOOSDB.
//!
//! Values and payloads:
//!
//! | MOOS value | payload |
//! |---|---|
//! | double | datamap `{value = 12.5}` |
//! | string of `key=value` pairs (`NAME=auv1, X = 10.5,MODE=A=B`) | datamap of those fields |
//! | other string | datamap `{value = "text"}` |
//! | binary | bytes |
//!
//! and back: a datamap with a single numeric `value` is a double, with a single string `value`
//! that string as it is, any other datamap a string of `key=value` pairs; bytes are binary; XML
//! text a string. Pairs are read and written as MOOS apps read them with libMOOS's
//! `MOOSValFromString` ([`parse_pairs`], [`to_pairs`]): a value ends at the next comma, so a value
//! holding one, or blanks at its ends, has no pair form and is refused with the field's name, as
//! are nested maps and lists. MOOS strings carry no types: a value that reads as a number is a
//! number, `true`/`false` a boolean, so the text `"12"` sent as a field reads back as 12.
//!
//! Who may depend on it: the program (to register `moos://`, and to run [`db::MoosDb`] for tests).
//! It depends on the core only.

pub mod client;
pub mod db;
pub mod wire;

use seabus_medium::datamap::{DataMap, Value};
use seabus_medium::payload::Payload;
use wire::{MoosRef, data};

pub use client::MoosConfig;

use seabus_medium::{Opened, Scheme, Schemes};

/// Adds `moos://`.
pub fn register(schemes: &mut Schemes) {
    schemes.add(Scheme {
        name: "moos",
        family: "moos",
        summary: "a client of a MOOSDB",
        check: |url| Ok(MoosConfig::from_url(url)?.capabilities()),
        open: |o| Ok(Opened::from(client::open(o)?)),
    });
}

/// A registry with `moos://` and the in-process medium, for a program or test that uses only these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}

/// The blanks MOOS trims from a value, and from between a key and its `=`
/// (`MOOSTrimWhiteSpace`).
const BLANKS: &[char] = &[' ', '\t', '\n', '\r'];

/// Writes a datamap as MOOS `key=value` pairs, as MOOS apps read them (`MOOSValFromString`): a
/// key or value MOOS would read otherwise is refused with the field's name — a comma (it ends a
/// value), blanks at a value's ends (MOOS trims them), a key with `=` or blanks at its ends.
pub fn to_pairs(map: &DataMap) -> Result<String, String> {
    let mut out = String::new();
    for (i, (key, v)) in map.iter().enumerate() {
        if key.is_empty() || key.contains([',', '=']) || key.trim_matches(BLANKS) != key {
            return Err(format!(
                "field `{key}` cannot be a MOOS key (no `,` or `=`, no blanks at its ends)"
            ));
        }
        if i > 0 {
            out.push(',');
        }
        out.push_str(key);
        out.push('=');
        match v {
            Value::Str(s) => {
                if s.contains(',') {
                    return Err(format!(
                        "field `{key}`: a MOOS value cannot hold a comma (it ends the value)"
                    ));
                }
                if s.trim_matches(BLANKS) != &**s {
                    return Err(format!(
                        "field `{key}`: MOOS trims the blanks at a value's ends"
                    ));
                }
                out.push_str(s);
            }
            Value::Int(n) => out.push_str(&n.to_string()),
            Value::Float(f) if f.is_finite() => out.push_str(&format!("{f:?}")),
            Value::Float(f) => {
                return Err(format!(
                    "field `{key}` is {f}, which MOOS apps do not read as a number"
                ));
            }
            Value::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            other => {
                return Err(format!(
                    "field `{key}` is a {}; MOOS key=value pairs carry numbers, booleans and text",
                    other.type_name()
                ));
            }
        }
    }
    Ok(out)
}

/// Reads MOOS `key=value` pairs as MOOS apps read them (libMOOS's `MOOSValFromString`): the text
/// is split at its commas; in each part the key is what comes before the first `=` (blanks and
/// tabs before it, and blanks between it and the `=`, not its own), the value all after it to the
/// comma, blanks at its ends trimmed (a value may hold `=` and quotes, which are its own); the
/// first of two parts with one key is the one MOOS finds. `None` when the text is not such pairs:
/// a part (other than blanks) without `=` or with nothing before it — MOOS would find some keys
/// of such a text, and no datamap would say which part was meant.
///
/// A value that reads as a number (an integer, a decimal) is a number and `true`/`false` a
/// boolean; any other value is text, as it is.
pub fn parse_pairs(text: &str) -> Option<DataMap> {
    let mut map = DataMap::new();
    for part in text.split(',') {
        let Some((key, value)) = part.split_once('=') else {
            if part.trim_matches(BLANKS).is_empty() {
                continue;
            }
            return None;
        };
        let key = key.trim_start_matches([' ', '\t']).trim_end_matches(BLANKS);
        if key.is_empty() {
            return None;
        }
        if map.get(key).is_some() {
            continue;
        }
        let value = value.trim_matches(BLANKS);
        let value = if value.starts_with('"') {
            Value::from(value)
        } else {
            Value::parse_loose(value)
        };
        map.insert(key.to_string(), value);
    }
    (!map.is_empty()).then_some(map)
}

/// What a payload is on MOOS: its data type, double and string fields.
pub fn to_moos(p: &Payload) -> Result<(u8, f64, Vec<u8>), String> {
    match p {
        Payload::Bytes(b) => Ok((data::BINARY, 0.0, b.to_vec())),
        Payload::Xml(x) => Ok((data::STRING, 0.0, x.as_bytes().to_vec())),
        Payload::Map(m) => {
            if m.len() == 1
                && let Some(v) = m.get("value")
            {
                match v {
                    Value::Int(_) | Value::Float(_) => {
                        return Ok((data::DOUBLE, v.as_f64().unwrap_or(0.0), Vec::new()));
                    }
                    // text goes as it is, whatever it looks like (MOOS strings carry no types)
                    Value::Str(s) => {
                        return Ok((data::STRING, 0.0, s.as_bytes().to_vec()));
                    }
                    _ => {}
                }
            }
            Ok((data::STRING, 0.0, to_pairs(m)?.into_bytes()))
        }
    }
}

/// The payload of a MOOS notification.
pub fn from_moos(m: &MoosRef<'_>) -> Result<Payload, String> {
    match m.data_type {
        data::DOUBLE => Ok(Payload::from(DataMap::new().with("value", m.value))),
        data::BINARY => Ok(Payload::from(m.string.to_vec())),
        data::STRING => {
            let text = std::str::from_utf8(m.string)
                .map_err(|e| format!("a string value that is not UTF-8 ({e})"))?;
            Ok(Payload::from(
                parse_pairs(text).unwrap_or_else(|| DataMap::new().with("value", text)),
            ))
        }
        t => Err(format!("data type `{}` is not D, S or B", t as char)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wire::MoosMsg;

    #[test]
    fn pairs_are_written_as_moos_reads_them() {
        let map = DataMap::new()
            .with("NAME", "auv1")
            .with("X", 10.5)
            .with("N", 3i64)
            .with("OK", true)
            .with("MODE", "A=B")
            .with("Q", "say \"hi\" \\ bye")
            .with("EMPTY", "")
            .with("WHOLE", 2.0);
        let text = to_pairs(&map).unwrap();
        assert_eq!(
            text,
            r#"NAME=auv1,X=10.5,N=3,OK=true,MODE=A=B,Q=say "hi" \ bye,EMPTY=,WHOLE=2.0"#
        );
        assert_eq!(parse_pairs(&text), Some(map));
        let refused =
            |k: &str, v: Value| to_pairs(&DataMap::new().with(k.to_string(), v)).unwrap_err();
        assert_eq!(
            refused("MODE", Value::from("A,B")),
            "field `MODE`: a MOOS value cannot hold a comma (it ends the value)"
        );
        assert_eq!(
            refused("P", Value::from(" x")),
            "field `P`: MOOS trims the blanks at a value's ends"
        );
        assert_eq!(
            refused("a b ", Value::from(1i64)),
            "field `a b ` cannot be a MOOS key (no `,` or `=`, no blanks at its ends)"
        );
        assert_eq!(
            refused("F", Value::Float(f64::NAN)),
            "field `F` is NaN, which MOOS apps do not read as a number"
        );
    }

    #[test]
    fn pairs_are_read_as_moos_reads_them() {
        let pairs = |t: &str| parse_pairs(t);
        assert_eq!(
            pairs("a = b , c = d"),
            Some(DataMap::new().with("a", "b").with("c", "d"))
        );
        assert_eq!(pairs("k=v=w"), Some(DataMap::new().with("k", "v=w")));
        assert_eq!(pairs("a=1\nb=2"), Some(DataMap::new().with("a", "1\nb=2")));
        assert_eq!(pairs("x=1,x=2"), Some(DataMap::new().with("x", 1i64)));
        assert_eq!(pairs("M=\"A\""), Some(DataMap::new().with("M", "\"A\"")));
        assert_eq!(
            pairs("my key=1,"),
            Some(DataMap::new().with("my key", 1i64))
        );
        assert_eq!(
            pairs("a=,b=2"),
            Some(DataMap::new().with("a", "").with("b", 2i64))
        );
        assert_eq!(pairs("hello world"), None);
        assert_eq!(pairs("=1"), None);
        assert_eq!(pairs("pts={0,0:10,10},label=a"), None);
        assert_eq!(pairs(""), None);
        assert_eq!(
            pairs("NAME=auv1,SPD=1.5"),
            Some(DataMap::new().with("NAME", "auv1").with("SPD", 1.5))
        );
    }

    #[test]
    fn payloads_travel_as_moos_values() {
        let d = to_moos(&Payload::from(DataMap::new().with("value", 12.5))).unwrap();
        assert_eq!((d.0, d.1), (data::DOUBLE, 12.5));
        let s = to_moos(&Payload::from(DataMap::new().with("value", "survey"))).unwrap();
        assert_eq!((s.0, s.2), (data::STRING, b"survey".to_vec()));
        // a string goes as it is, whatever it looks like
        let pairs = Payload::from(DataMap::new().with("value", "x=1"));
        let s = to_moos(&pairs).unwrap();
        assert_eq!((s.0, &s.2[..]), (data::STRING, &b"x=1"[..]));
        let p = to_moos(&Payload::from(
            DataMap::new().with("x", 1i64).with("y", 2i64),
        ))
        .unwrap();
        assert_eq!((p.0, p.2), (data::STRING, b"x=1,y=2".to_vec()));
        let b = to_moos(&Payload::from(vec![0u8, 255])).unwrap();
        assert_eq!((b.0, b.2), (data::BINARY, vec![0, 255]));
        assert_eq!(
            to_moos(&Payload::from(
                DataMap::new().with("l", Value::List(vec![]))
            ))
            .unwrap_err(),
            "field `l` is a list; MOOS key=value pairs carry numbers, booleans and text"
        );
        let back = |dt: u8, v: f64, s: &[u8]| {
            from_moos(
                &MoosMsg {
                    data_type: dt,
                    value: v,
                    string: s.to_vec(),
                    ..MoosMsg::default()
                }
                .borrowed(),
            )
        };
        assert_eq!(
            back(data::DOUBLE, 3.5, b"").unwrap(),
            Payload::from(DataMap::new().with("value", 3.5))
        );
        assert_eq!(
            back(data::STRING, 0.0, b"hello").unwrap(),
            Payload::from(DataMap::new().with("value", "hello"))
        );
        assert!(back(data::STRING, 0.0, &[0xFF]).is_err());
        assert!(back(b'X', 0.0, b"").is_err());
    }
}
