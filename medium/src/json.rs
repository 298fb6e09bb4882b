//! The JSON form of a datamap, for tools and programs that speak JSON (`seabus spy --json`, external
//! program modules, the console).
//!
//! A datamap is a JSON object with its keys in order. Booleans, strings and lists map directly;
//! integers are JSON integers; floats are JSON numbers written with a decimal point or exponent
//! (`2.0`, so they read back as floats); a non-finite float is `{"float": "NaN"}` (`"inf"`,
//! `"-inf"`); bytes are `{"base64": "…"}`.

use crate::datamap::{DataMap, Value};
use base64::Engine as _;
use base64::engine::general_purpose::STANDARD as B64;
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::ser::{SerializeMap, SerializeSeq};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

impl Serialize for Value {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Value::Bool(b) => s.serialize_bool(*b),
            Value::Int(i) => s.serialize_i64(*i),
            Value::Float(f) if f.is_finite() => s.serialize_f64(*f),
            Value::Float(f) => {
                let mut m = s.serialize_map(Some(1))?;
                let text = if f.is_nan() {
                    "NaN"
                } else if *f > 0.0 {
                    "inf"
                } else {
                    "-inf"
                };
                m.serialize_entry("float", text)?;
                m.end()
            }
            Value::Str(t) => s.serialize_str(t),
            Value::Bytes(b) => {
                let mut m = s.serialize_map(Some(1))?;
                m.serialize_entry("base64", &B64.encode(b))?;
                m.end()
            }
            Value::List(items) => {
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for item in items {
                    seq.serialize_element(item)?;
                }
                seq.end()
            }
        }
    }
}

impl Serialize for DataMap {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.len()))?;
        for (k, v) in self.iter() {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

struct ValueVisitor;

impl<'de> Visitor<'de> for ValueVisitor {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a boolean, number, string, list, {\"base64\": …} or {\"float\": …}")
    }

    fn visit_bool<E: de::Error>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }

    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Value, E> {
        Ok(Value::Int(v))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Value, E> {
        i64::try_from(v)
            .map(Value::Int)
            .map_err(|_| E::custom(format!("integer {v} is larger than 64-bit signed")))
    }

    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Value, E> {
        Ok(Value::Float(v))
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<Value, E> {
        Ok(Value::from(v))
    }

    fn visit_string<E: de::Error>(self, v: String) -> Result<Value, E> {
        Ok(Value::from(v))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Value, E> {
        Err(E::custom("null is not a datamap value"))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1024));
        while let Some(v) = seq.next_element::<Value>()? {
            items.push(v);
        }
        Ok(Value::List(items))
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let Some(key) = map.next_key::<String>()? else {
            return Err(de::Error::custom("an empty object is not a datamap value"));
        };
        let text: String = map.next_value()?;
        if map.next_key::<String>()?.is_some() {
            return Err(de::Error::custom(
                "objects inside a datamap have one key, `base64` or `float`",
            ));
        }
        match key.as_str() {
            "base64" => B64
                .decode(text.as_bytes())
                .map(Value::Bytes)
                .map_err(|e| de::Error::custom(format!("bad base64: {e}"))),
            "float" => match text.as_str() {
                "NaN" | "nan" => Ok(Value::Float(f64::NAN)),
                "inf" | "Infinity" => Ok(Value::Float(f64::INFINITY)),
                "-inf" | "-Infinity" => Ok(Value::Float(f64::NEG_INFINITY)),
                other => other
                    .parse()
                    .map(Value::Float)
                    .map_err(|_| de::Error::custom(format!("`{other}` is not a float"))),
            },
            other => Err(de::Error::custom(format!(
                "unexpected object key `{other}`: objects inside a datamap are {{\"base64\": …}} or {{\"float\": …}}"
            ))),
        }
    }
}

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Value, D::Error> {
        d.deserialize_any(ValueVisitor)
    }
}

struct MapVisitor;

impl<'de> Visitor<'de> for MapVisitor {
    type Value = DataMap;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a JSON object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<DataMap, A::Error> {
        let mut out = DataMap::with_capacity(map.size_hint().unwrap_or(0).min(256));
        // entries are kept as written, a repeated key included, as the other forms do
        while let Some((k, v)) = map.next_entry::<String, Value>()? {
            out.push(k, v);
        }
        Ok(out)
    }
}

impl<'de> Deserialize<'de> for DataMap {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<DataMap, D::Error> {
        d.deserialize_map(MapVisitor)
    }
}

/// Writes `map` as JSON text.
pub fn to_json(map: &DataMap) -> String {
    serde_json::to_string(map).unwrap_or_else(|e| format!("{{\"error\":{:?}}}", e.to_string()))
}

/// Reads a datamap from JSON text; the error names line and column.
pub fn from_json(text: &str) -> Result<DataMap, serde_json::Error> {
    serde_json::from_str(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_round_trips_every_value() {
        let m = DataMap::new()
            .with("b", true)
            .with("i", -3i64)
            .with("f", 2.0f64)
            .with("nan", f64::NAN)
            .with("inf", f64::NEG_INFINITY)
            .with("s", "x\"y")
            .with("raw", vec![1u8, 2])
            .with("l", Value::List(vec![1i64.into(), 0.5f64.into()]));
        let text = to_json(&m);
        assert_eq!(
            text,
            r#"{"b":true,"i":-3,"f":2.0,"nan":{"float":"NaN"},"inf":{"float":"-inf"},"s":"x\"y","raw":{"base64":"AQI="},"l":[1,0.5]}"#
        );
        assert_eq!(from_json(&text).unwrap(), m);
    }

    #[test]
    fn regression_floats_read_back_to_the_same_bits() {
        // found by the datamap_json fuzz target: JSON's shortest text for these read back one bit off
        for x in [
            -9.223372306852233e29,
            123332221.33333333,
            1.1999999944444445e35,
            1.1111111111111111e110,
        ] {
            let m = DataMap::new().with("x", x);
            assert_eq!(from_json(&to_json(&m)).unwrap(), m, "{x:e}");
        }
        let m = from_json(r#"{"min":-922337230685223372063854775807}"#).unwrap();
        assert_eq!(from_json(&to_json(&m)).unwrap(), m);
    }

    #[test]
    fn bad_json_is_explained() {
        let e = from_json("{\"a\": null}").unwrap_err();
        assert!(e.to_string().contains("null is not a datamap value"), "{e}");
        let e = from_json("{\"a\": {\"x\": \"1\"}}").unwrap_err();
        assert!(e.to_string().contains("unexpected object key `x`"), "{e}");
        let e = from_json("[1]").unwrap_err();
        assert!(e.to_string().contains("a JSON object"), "{e}");
        let e = from_json("{\"a\": 1").unwrap_err();
        assert!(e.is_eof());
    }
}
