//! seabus-medium-moos, MOOS: [`wire`] is the V10 message and packet format, [`client`] the `moos://` medium (an
//! asynchronous client of a MOOSDB), [`db`] a small MOOSDB.
//!
//! Values and payloads:
//!
//! | MOOS value | payload |
//! |---|---|
//! | double | datamap `{value = 12.5}` |
//! | string of `key=value` pairs (`NAME=auv1,X=10.5,MODE="A,B"`) | datamap of those fields |
//! | other string | datamap `{value = "text"}` |
//! | binary | bytes |
//!
//! and back: a datamap with a single numeric `value` is a double, with a single string `value` a
//! string (unless that string reads as `key=value` pairs: then it is the pair `value="…"`, so that
//! it reads back as the same string rather than as a datamap of its pairs), any other datamap a
//! string of `key=value` pairs; bytes are binary; XML text a string.
//! In the pairs a value holding `,`, `=`, `"` or `\`, blanks at its ends, or text that would read
//! as a number or boolean is written in double quotes with `\"` and `\\` escapes; numbers and
//! booleans are written plain, so they read back as they were (`seabus pub` types them the same
//! way). Nested maps and lists have no pair form and are refused with the field's name.
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

/// Writes a datamap as MOOS `key=value` pairs.
pub fn to_pairs(map: &DataMap) -> Result<String, String> {
    let mut out = String::new();
    for (i, (key, v)) in map.iter().enumerate() {
        if key.is_empty() || key.contains([',', '=', '"', '\\']) || key.trim() != key {
            return Err(format!(
                "field `{key}` cannot be a MOOS key (no `,`, `=`, `\"`, `\\` or blanks at its ends)"
            ));
        }
        if i > 0 {
            out.push(',');
        }
        out.push_str(key);
        out.push('=');
        match v {
            Value::Str(s) => {
                let plain = Value::parse_loose(s) == Value::from(&**s)
                    && !s.contains([',', '=', '"', '\\'])
                    && s.trim() == &**s
                    && !s.is_empty();
                if plain {
                    out.push_str(s);
                } else {
                    out.push('"');
                    for c in s.chars() {
                        if c == '"' || c == '\\' {
                            out.push('\\');
                        }
                        out.push(c);
                    }
                    out.push('"');
                }
            }
            Value::Int(n) => out.push_str(&n.to_string()),
            Value::Float(f) => out.push_str(&format!("{f:?}")),
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

/// Reads MOOS `key=value` pairs; `None` when the text is not such pairs.
pub fn parse_pairs(text: &str) -> Option<DataMap> {
    let mut map = DataMap::new();
    let mut chars = text.chars().peekable();
    loop {
        let mut key = String::new();
        let mut equals = false;
        for c in chars.by_ref() {
            if c == '=' {
                equals = true;
                break;
            }
            if c == ',' || c == '"' {
                return None;
            }
            key.push(c);
        }
        if key.is_empty() || !equals {
            return None;
        }
        let value = if chars.peek() == Some(&'"') {
            chars.next();
            let mut s = String::new();
            loop {
                match chars.next()? {
                    '\\' => s.push(chars.next()?),
                    '"' => break,
                    c => s.push(c),
                }
            }
            match chars.peek() {
                None | Some(',') => {}
                Some(_) => return None,
            }
            Value::from(s)
        } else {
            let mut raw = String::new();
            while let Some(&c) = chars.peek() {
                if c == ',' {
                    break;
                }
                if c == '=' || c == '"' {
                    return None;
                }
                raw.push(c);
                chars.next();
            }
            Value::parse_loose(&raw)
        };
        map.insert(key, value);
        match chars.next() {
            None => return Some(map),
            Some(',') => {}
            Some(_) => return None,
        }
    }
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
                    // text shaped like pairs goes as the pair `value="…"`, so it reads back whole
                    Value::Str(s) if parse_pairs(s).is_none() => {
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
    fn pairs_survive_commas_equals_and_quotes() {
        let map = DataMap::new()
            .with("NAME", "auv1")
            .with("X", 10.5)
            .with("N", 3i64)
            .with("OK", true)
            .with("MODE", "A,B=C")
            .with("Q", "say \"hi\" \\ bye")
            .with("CODE", "12")
            .with("EMPTY", "")
            .with("WHOLE", 2.0);
        let text = to_pairs(&map).unwrap();
        assert_eq!(
            text,
            r#"NAME=auv1,X=10.5,N=3,OK=true,MODE="A,B=C",Q="say \"hi\" \\ bye",CODE="12",EMPTY="",WHOLE=2.0"#
        );
        assert_eq!(parse_pairs(&text), Some(map));
    }

    #[test]
    fn what_is_not_pairs_stays_a_string() {
        assert_eq!(parse_pairs("hello world"), None);
        assert_eq!(parse_pairs("a=1,,b=2"), None);
        assert_eq!(parse_pairs("=1"), None);
        assert_eq!(parse_pairs("a=\"open"), None);
        assert_eq!(
            parse_pairs("NAME=auv1,SPD=1.5"),
            Some(DataMap::new().with("NAME", "auv1").with("SPD", 1.5))
        );
    }

    #[test]
    fn payloads_travel_as_moos_values() {
        let d = to_moos(&Payload::from(DataMap::new().with("value", 12.5))).unwrap();
        assert_eq!((d.0, d.1), (data::DOUBLE, 12.5));
        let s = to_moos(&Payload::from(DataMap::new().with("value", "survey"))).unwrap();
        assert_eq!((s.0, s.2), (data::STRING, b"survey".to_vec()));
        // a string shaped like pairs reads back as that string
        let pairs = Payload::from(DataMap::new().with("value", "x=1"));
        let s = to_moos(&pairs).unwrap();
        assert_eq!((s.0, &s.2[..]), (data::STRING, &br#"value="x=1""#[..]));
        let back = from_moos(
            &MoosMsg {
                data_type: s.0,
                string: s.2,
                ..MoosMsg::default()
            }
            .borrowed(),
        );
        assert_eq!(back.unwrap(), pairs);
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
