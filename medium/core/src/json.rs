//! The JSON form of a datamap, for tools and programs that speak JSON (`seabus spy --json`, external
//! program modules, the console).
//!
//! A datamap is a JSON object with its keys in order. Booleans, strings and lists map directly;
//! integers are JSON integers; floats are JSON numbers written with a decimal point or exponent
//! (`2.0`, so they read back as floats); a non-finite float is `{"float": "NaN"}` (`"inf"`,
//! `"-inf"`); bytes are `{"base64": "…"}`; a nested map is a JSON object (`{}` when empty).
//!
//! An object whose first key is `float`, `base64` or `map` is one of the one-key forms, so a nested
//! map whose first key is one of those words is written inside `{"map": {…}}`. Lists and maps nest at
//! most [`MAX_DEPTH`] deep (counted together), writing and reading alike.

use crate::datamap::{DataMap, MAX_DEPTH, TooDeep, Value};
use base64::Engine as _;
use base64::engine::general_purpose::STANDARD as B64;
use serde::de::{self, DeserializeSeed, MapAccess, SeqAccess, Visitor};
use serde::ser::{self, SerializeMap, SerializeSeq};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// The keys that open a one-key form rather than a nested map.
const FORM_KEYS: [&str; 3] = ["float", "base64", "map"];

/// A value found inside `.1` lists and maps, written with the depth limit.
struct Nested<'a>(&'a Value, usize);

/// The entries of a map found inside `.1` lists and maps, written as one JSON object.
struct Entries<'a>(&'a DataMap, usize);

impl Serialize for Nested<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let Nested(v, depth) = *self;
        match v {
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
                if depth >= MAX_DEPTH {
                    return Err(ser::Error::custom(TooDeep));
                }
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for item in items {
                    seq.serialize_element(&Nested(item, depth + 1))?;
                }
                seq.end()
            }
            Value::Map(map) => {
                if depth >= MAX_DEPTH {
                    return Err(ser::Error::custom(TooDeep));
                }
                let first = map.iter().next().map(|(k, _)| k);
                if first.is_some_and(|k| FORM_KEYS.contains(&k)) {
                    let mut m = s.serialize_map(Some(1))?;
                    m.serialize_entry("map", &Entries(map, depth + 1))?;
                    m.end()
                } else {
                    Entries(map, depth + 1).serialize(s)
                }
            }
        }
    }
}

impl Serialize for Entries<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let Entries(map, depth) = *self;
        let mut m = s.serialize_map(Some(map.len()))?;
        for (k, v) in map.iter() {
            m.serialize_entry(k, &Nested(v, depth))?;
        }
        m.end()
    }
}

/// A value on its own is written as if it were an entry of a datamap.
impl Serialize for Value {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        Nested(self, 0).serialize(s)
    }
}

impl Serialize for DataMap {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        Entries(self, 0).serialize(s)
    }
}

/// Reads a value found inside `depth` lists and maps.
#[derive(Clone, Copy)]
struct ValueSeed {
    depth: usize,
}

impl<'de> DeserializeSeed<'de> for ValueSeed {
    type Value = Value;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        d.deserialize_any(self)
    }
}

/// The error for a list or map that would nest deeper than [`MAX_DEPTH`].
fn too_deep<E: de::Error>() -> E {
    E::custom(TooDeep)
}

impl<'de> Visitor<'de> for ValueSeed {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(
            "a boolean, number, string, list, object, {\"base64\": …}, {\"float\": …} or {\"map\": …}",
        )
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
        if self.depth >= MAX_DEPTH {
            return Err(too_deep());
        }
        let inner = ValueSeed {
            depth: self.depth + 1,
        };
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1024));
        while let Some(v) = seq.next_element_seed(inner)? {
            items.push(v);
        }
        Ok(Value::List(items))
    }

    /// An object: a one-key form when its first key is `float`, `base64` or `map`, a nested map
    /// otherwise.
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let Some(key) = map.next_key::<String>()? else {
            return self.nested(map, None);
        };
        let value = match key.as_str() {
            "base64" => {
                let text: String = map.next_value()?;
                B64.decode(text.as_bytes())
                    .map(Value::Bytes)
                    .map_err(|e| de::Error::custom(format!("bad base64: {e}")))?
            }
            "float" => {
                let text: String = map.next_value()?;
                match text.as_str() {
                    "NaN" | "nan" => Value::Float(f64::NAN),
                    "inf" | "Infinity" => Value::Float(f64::INFINITY),
                    "-inf" | "-Infinity" => Value::Float(f64::NEG_INFINITY),
                    other => other
                        .parse()
                        .map(Value::Float)
                        .map_err(|_| de::Error::custom(format!("`{other}` is not a float")))?,
                }
            }
            "map" => {
                if self.depth >= MAX_DEPTH {
                    return Err(too_deep());
                }
                Value::Map(map.next_value_seed(EntriesSeed {
                    depth: self.depth + 1,
                })?)
            }
            _ => return self.nested(map, Some(key)),
        };
        if let Some(other) = map.next_key::<String>()? {
            return Err(de::Error::custom(format!(
                "unexpected key `{other}` after `{key}`: an object whose first key is `{key}` has \
                 that one key (write a map starting with `{key}` as {{\"map\": {{…}}}})"
            )));
        }
        Ok(value)
    }
}

impl ValueSeed {
    /// Reads the rest of an object as a nested map whose first key, already read, is `first`.
    fn nested<'de, A: MapAccess<'de>>(
        self,
        mut map: A,
        first: Option<String>,
    ) -> Result<Value, A::Error> {
        if self.depth >= MAX_DEPTH {
            return Err(too_deep());
        }
        let inner = ValueSeed {
            depth: self.depth + 1,
        };
        let mut out = DataMap::with_capacity(map.size_hint().unwrap_or(0).min(256));
        if let Some(key) = first {
            let value = map.next_value_seed(inner)?;
            out.push(key, value);
        }
        read_entries(&mut out, map, inner)?;
        Ok(Value::Map(out))
    }
}

/// Reads the remaining entries of an object into `out`, each value with `seed`; entries are kept as
/// written, a repeated key included, as the other forms do.
fn read_entries<'de, A: MapAccess<'de>>(
    out: &mut DataMap,
    mut map: A,
    seed: ValueSeed,
) -> Result<(), A::Error> {
    while let Some(k) = map.next_key::<String>()? {
        let v = map.next_value_seed(seed)?;
        out.push(k, v);
    }
    Ok(())
}

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Value, D::Error> {
        ValueSeed { depth: 0 }.deserialize(d)
    }
}

/// Reads a JSON object as the entries of a map whose values are found inside `depth` lists and
/// maps.
#[derive(Clone, Copy)]
struct EntriesSeed {
    depth: usize,
}

impl<'de> DeserializeSeed<'de> for EntriesSeed {
    type Value = DataMap;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<DataMap, D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for EntriesSeed {
    type Value = DataMap;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a JSON object")
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<DataMap, A::Error> {
        let mut out = DataMap::with_capacity(map.size_hint().unwrap_or(0).min(256));
        read_entries(&mut out, map, ValueSeed { depth: self.depth })?;
        Ok(out)
    }
}

impl<'de> Deserialize<'de> for DataMap {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<DataMap, D::Error> {
        EntriesSeed { depth: 0 }.deserialize(d)
    }
}

/// Writes `map` as JSON text; a map whose lists and maps nest deeper than [`MAX_DEPTH`] is refused.
pub fn to_json(map: &DataMap) -> Result<String, TooDeep> {
    // writing to memory fails only where the depth limit refuses a value
    serde_json::to_string(map).map_err(|_| TooDeep)
}

/// Reads a datamap from JSON text; the error names line and column.
pub fn from_json(text: &str) -> Result<DataMap, serde_json::Error> {
    serde_json::from_str(text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datamap::nested_maps;

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
            .with("l", Value::List(vec![1i64.into(), 0.5f64.into()]))
            .with(
                "m",
                DataMap::new().with("x", 1i64).with("e", DataMap::new()),
            );
        let text = to_json(&m).unwrap();
        assert_eq!(
            text,
            r#"{"b":true,"i":-3,"f":2.0,"nan":{"float":"NaN"},"inf":{"float":"-inf"},"s":"x\"y","raw":{"base64":"AQI="},"l":[1,0.5],"m":{"x":1,"e":{}}}"#
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
            assert_eq!(from_json(&to_json(&m).unwrap()).unwrap(), m, "{x:e}");
        }
        let m = from_json(r#"{"min":-922337230685223372063854775807}"#).unwrap();
        assert_eq!(from_json(&to_json(&m).unwrap()).unwrap(), m);
    }

    #[test]
    fn maps_that_start_like_a_one_key_form_are_wrapped() {
        let inner = |k: &'static str| DataMap::new().with(k, "AQI=").with("x", 1i64);
        let m = DataMap::new()
            .with("a", inner("base64"))
            .with("b", DataMap::new().with("float", "NaN"))
            .with(
                "c",
                DataMap::new().with("map", DataMap::new().with("y", 2i64)),
            )
            .with("d", inner("id"))
            // at the top level every key is just a key
            .with("float", "NaN");
        let text = to_json(&m).unwrap();
        assert_eq!(
            text,
            r#"{"a":{"map":{"base64":"AQI=","x":1}},"b":{"map":{"float":"NaN"}},"c":{"map":{"map":{"y":2}}},"d":{"id":"AQI=","x":1},"float":"NaN"}"#
        );
        assert_eq!(from_json(&text).unwrap(), m);
        // the one-key forms still read as before
        let m = from_json(r#"{"a":{"base64":"AQI="},"b":{"float":"inf"},"c":{"map":{}},"d":{}}"#)
            .unwrap();
        assert_eq!(m.get("a"), Some(&Value::Bytes(vec![1, 2])));
        assert_eq!(m.get_f64("b"), Some(f64::INFINITY));
        assert_eq!(m.get("c"), Some(&Value::Map(DataMap::new())));
        assert_eq!(m.get("d"), Some(&Value::Map(DataMap::new())));
    }

    #[test]
    fn deep_maps_are_refused_by_writer_and_reader_alike() {
        let deepest = nested_maps(MAX_DEPTH);
        assert_eq!(from_json(&to_json(&deepest).unwrap()).unwrap(), deepest);
        assert_eq!(to_json(&nested_maps(MAX_DEPTH + 1)), Err(TooDeep));
        // one map too many, wrapped or not, and one list too many
        for (open, close) in [(r#"{"k":"#, "}"), (r#"{"map":{"map":"#, "}}"), ("[", "]")] {
            let text = format!(
                "{{\"k\":{}1{}}}",
                open.repeat(MAX_DEPTH + 1),
                close.repeat(MAX_DEPTH + 1)
            );
            let e = from_json(&text).unwrap_err();
            assert!(
                e.to_string()
                    .contains("lists and maps nested deeper than 32"),
                "{e}"
            );
            let fits = format!(
                "{{\"k\":{}1{}}}",
                open.repeat(MAX_DEPTH),
                close.repeat(MAX_DEPTH)
            );
            assert!(from_json(&fits).is_ok(), "{fits}");
        }
    }

    #[test]
    fn bad_json_is_explained() {
        let e = from_json("{\"a\": null}").unwrap_err();
        assert!(e.to_string().contains("null is not a datamap value"), "{e}");
        let e = from_json("{\"a\": {\"base64\": \"AQI=\", \"x\": 1}}").unwrap_err();
        assert!(
            e.to_string().contains("unexpected key `x` after `base64`"),
            "{e}"
        );
        let e = from_json("{\"a\": {\"map\": 1}}").unwrap_err();
        assert!(e.to_string().contains("a JSON object"), "{e}");
        let e = from_json("{\"a\": {\"float\": 1.5}}").unwrap_err();
        assert!(e.to_string().contains("expected a string"), "{e}");
        let e = from_json("[1]").unwrap_err();
        assert!(e.to_string().contains("a JSON object"), "{e}");
        let e = from_json("{\"a\": 1").unwrap_err();
        assert!(e.is_eof());
    }
}
