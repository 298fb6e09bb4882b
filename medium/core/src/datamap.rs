//! The named datamap: an ordered list of `key → value` pairs, the structured payload format.
//!
//! Keys keep the order they were inserted in (a dataset's fields read in the order a driver wrote them).
//! Values are booleans, 64-bit integers, 64-bit floats, UTF-8 strings, byte strings, lists of values,
//! and nested datamaps (a structure inside a dataset: `pose.position.x`).

use std::borrow::Cow;
use std::fmt;
use thiserror::Error;

/// Deepest nesting of lists and maps (counted together) a datamap can be carried with: every
/// payload form writes and reads values inside this many lists and maps, and refuses deeper ones.
pub const MAX_DEPTH: usize = 32;

/// Why a datamap has no binary, XML or JSON form: its lists and maps nest deeper than [`MAX_DEPTH`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[error("lists and maps nested deeper than {MAX_DEPTH}")]
pub struct TooDeep;

/// One value in a [`DataMap`].
#[derive(Debug, Clone)]
pub enum Value {
    /// A boolean.
    Bool(bool),
    /// A signed 64-bit integer.
    Int(i64),
    /// A 64-bit IEEE float.
    Float(f64),
    /// A UTF-8 string (a constant written in code costs no allocation: [`Value::label`]).
    Str(Text),
    /// A byte string.
    Bytes(Vec<u8>),
    /// A list of values.
    List(Vec<Value>),
    /// A nested datamap (a structure inside the payload).
    Map(DataMap),
}

impl Value {
    /// The value's type name as used in the XML form and in error messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Bool(_) => "bool",
            Value::Int(_) => "int",
            Value::Float(_) => "float",
            Value::Str(_) => "string",
            Value::Bytes(_) => "bytes",
            Value::List(_) => "list",
            Value::Map(_) => "map",
        }
    }

    /// The value as a float, when it is numeric (an integer converts).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(f) => Some(*f),
            Value::Int(i) => Some(*i as f64),
            _ => None,
        }
    }

    /// The value as an integer, when it is an integer.
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }

    /// The value as a boolean, when it is one.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }

    /// The value as a string slice, when it is a string.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The items, when the value is a list.
    pub fn as_list(&self) -> Option<&[Value]> {
        match self {
            Value::List(items) => Some(items),
            _ => None,
        }
    }

    /// The nested datamap, when the value is one.
    pub fn as_map(&self) -> Option<&DataMap> {
        match self {
            Value::Map(m) => Some(m),
            _ => None,
        }
    }

    /// Parses a value typed on a command line or in a file: `true`/`false`, an integer, a float, or
    /// else a string. A value in double quotes is always a string.
    pub fn parse_loose(text: &str) -> Value {
        if let Some(inner) = text.strip_prefix('"').and_then(|t| t.strip_suffix('"')) {
            return Value::from(inner);
        }
        match text {
            "true" => return Value::Bool(true),
            "false" => return Value::Bool(false),
            _ => {}
        }
        if let Ok(i) = text.parse::<i64>() {
            return Value::Int(i);
        }
        if looks_numeric(text)
            && let Ok(f) = text.parse::<f64>()
        {
            return Value::Float(f);
        }
        Value::from(text)
    }

    /// A string value that is a constant in code (a unit, a mode, a reference frame).
    pub const fn label(text: &'static str) -> Value {
        Value::Str(Cow::Borrowed(text))
    }
}

/// True for text that reads as a decimal number (so `inf` or `nan` typed as words stay strings).
fn looks_numeric(text: &str) -> bool {
    let t = text.strip_prefix(['-', '+']).unwrap_or(text);
    t.starts_with(|c: char| c.is_ascii_digit() || c == '.')
}

/// Values compare equal when they have the same type and content; floats compare by bit pattern so
/// that NaN equals itself and `-0.0` differs from `0.0` (conversions must preserve both).
impl PartialEq for Value {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Value::Bool(a), Value::Bool(b)) => a == b,
            (Value::Int(a), Value::Int(b)) => a == b,
            (Value::Float(a), Value::Float(b)) => a.to_bits() == b.to_bits(),
            (Value::Str(a), Value::Str(b)) => a == b,
            (Value::Bytes(a), Value::Bytes(b)) => a == b,
            (Value::List(a), Value::List(b)) => a == b,
            (Value::Map(a), Value::Map(b)) => a == b,
            _ => false,
        }
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::Float(x) => write!(f, "{x}"),
            Value::Str(s) => write!(f, "{s:?}"),
            Value::Bytes(b) => {
                write!(f, "0x")?;
                for byte in b.iter().take(32) {
                    write!(f, "{byte:02x}")?;
                }
                if b.len() > 32 {
                    write!(f, "…({} bytes)", b.len())?;
                }
                Ok(())
            }
            Value::List(items) => {
                write!(f, "[")?;
                for (i, item) in items.iter().enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{item}")?;
                }
                write!(f, "]")
            }
            Value::Map(m) => {
                write!(f, "{{")?;
                for (i, (k, v)) in m.iter().enumerate() {
                    if i > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{k}={v}")?;
                }
                write!(f, "}}")
            }
        }
    }
}

macro_rules! value_from {
    ($($t:ty => $variant:ident $(as $cast:ty)?),* $(,)?) => {
        $(impl From<$t> for Value {
            fn from(v: $t) -> Self {
                Value::$variant(v $(as $cast)?)
            }
        })*
    };
}

value_from! {
    bool => Bool,
    i64 => Int,
    i32 => Int as i64,
    u32 => Int as i64,
    u8 => Int as i64,
    f64 => Float,
    f32 => Float as f64,
    Vec<u8> => Bytes,
    Vec<Value> => List,
    DataMap => Map,
}

impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::Str(Cow::Owned(v.to_string()))
    }
}

impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::Str(Cow::Owned(v))
    }
}

/// Text that is either a constant in code or owned: datamap keys and string values.
pub type Text = Cow<'static, str>;

/// A datamap key: a field name written in code costs no allocation.
pub type Key = Text;

/// An ordered map of named values: the "named datamap" payload format.
///
/// Lookups are linear: datamaps hold a dataset's handful of fields, where a scan beats hashing.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DataMap {
    entries: Vec<(Key, Value)>,
}

impl DataMap {
    /// An empty datamap.
    pub fn new() -> Self {
        DataMap {
            entries: Vec::new(),
        }
    }

    /// An empty datamap with room for `n` entries.
    pub fn with_capacity(n: usize) -> Self {
        DataMap {
            entries: Vec::with_capacity(n),
        }
    }

    /// A datamap of these entries, in this order, taken as they are (like [`DataMap::push`], a
    /// repeated key stays repeated): the quickest way to build a dataset whose fields are known.
    pub fn from_entries(entries: Vec<(Key, Value)>) -> Self {
        DataMap { entries }
    }

    /// Sets `key` to `value`: replaces the value in place when the key exists, appends otherwise.
    pub fn insert(&mut self, key: impl Into<Key>, value: impl Into<Value>) {
        let key = key.into();
        let value = value.into();
        match self.entries.iter_mut().find(|(k, _)| *k == key) {
            Some(slot) => slot.1 = value,
            None => self.entries.push((key, value)),
        }
    }

    /// Appends an entry without looking for an existing key: for building a map whose keys are
    /// known to differ (a repeated key would stay repeated, as decoders keep them).
    pub fn push(&mut self, key: impl Into<Key>, value: impl Into<Value>) {
        self.entries.push((key.into(), value.into()));
    }

    /// Builder form of [`DataMap::push`].
    pub fn and(mut self, key: impl Into<Key>, value: impl Into<Value>) -> Self {
        self.push(key, value);
        self
    }

    /// Builder form of [`DataMap::insert`].
    pub fn with(mut self, key: impl Into<Key>, value: impl Into<Value>) -> Self {
        self.insert(key, value);
        self
    }

    /// The value under `key`.
    pub fn get(&self, key: &str) -> Option<&Value> {
        self.entries.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    /// The value at a dotted path of keys through nested maps (`pose.position.x`; lists not walked).
    pub fn get_path(&self, path: &str) -> Option<&Value> {
        let mut segments = path.split('.');
        let mut value = self.get(segments.next()?)?;
        for segment in segments {
            value = value.as_map()?.get(segment)?;
        }
        Some(value)
    }

    /// The numeric value under `key` as a float.
    pub fn get_f64(&self, key: &str) -> Option<f64> {
        self.get(key).and_then(Value::as_f64)
    }

    /// The integer under `key`.
    pub fn get_i64(&self, key: &str) -> Option<i64> {
        self.get(key).and_then(Value::as_i64)
    }

    /// The string under `key`.
    pub fn get_str(&self, key: &str) -> Option<&str> {
        self.get(key).and_then(Value::as_str)
    }

    /// The boolean under `key`.
    pub fn get_bool(&self, key: &str) -> Option<bool> {
        self.get(key).and_then(Value::as_bool)
    }

    /// Removes `key`, returning its value.
    pub fn remove(&mut self, key: &str) -> Option<Value> {
        let idx = self.entries.iter().position(|(k, _)| k == key)?;
        Some(self.entries.remove(idx).1)
    }

    /// Renames `from` to `to` in place, keeping the entry's position; any entry already called `to`
    /// is removed. Returns false when `from` is absent.
    ///
    /// Only this map's own (top-level) keys are renamed: `from` is a key, not a path, and the keys of
    /// nested maps are left as they are.
    pub fn rename(&mut self, from: &str, to: &str) -> bool {
        if from == to {
            return self.get(from).is_some();
        }
        let Some(idx) = self.entries.iter().position(|(k, _)| k == from) else {
            return false;
        };
        self.entries[idx].0 = Cow::Owned(to.to_string());
        let mut i = 0;
        self.entries.retain(|(k, _)| {
            let keep = i == idx || k != to;
            i += 1;
            keep
        });
        true
    }

    /// The map with each list field replaced by one field per element, named by the list's key and
    /// the element's index (`route_forwarded` = `[3, 5]` becomes `route_forwarded.0` = 3 and
    /// `route_forwarded.1` = 5), in place of the list; lists inside lists flatten the same way
    /// (`a.1.0`). An empty list leaves no field. Other values stay as they are: the form for a
    /// wire whose key-value messages carry no lists ([`crate::Capabilities::lists`]).
    pub fn flatten_lists(self) -> DataMap {
        fn put(out: &mut DataMap, key: Key, value: Value) {
            match value {
                Value::List(items) => {
                    for (i, v) in items.into_iter().enumerate() {
                        put(out, Cow::Owned(format!("{key}.{i}")), v);
                    }
                }
                v => out.push(key, v),
            }
        }
        if !self
            .entries
            .iter()
            .any(|(_, v)| matches!(v, Value::List(_)))
        {
            return self;
        }
        let mut out = DataMap::with_capacity(self.entries.len());
        for (k, v) in self.entries {
            put(&mut out, k, v);
        }
        out
    }

    /// The entries in order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Value)> {
        self.entries.iter().map(|(k, v)| (k.as_ref(), v))
    }

    /// The entries in order, keys as held: cloning a key written in code copies nothing.
    pub fn entries(&self) -> &[(Key, Value)] {
        &self.entries
    }

    /// The entries in order, taken out of the map.
    pub fn into_entries(self) -> Vec<(Key, Value)> {
        self.entries
    }

    /// The number of entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when the map has no entries.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

impl fmt::Display for DataMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, (k, v)) in self.entries.iter().enumerate() {
            if i > 0 {
                write!(f, " ")?;
            }
            write!(f, "{k}={v}")?;
        }
        Ok(())
    }
}

impl<K: Into<Key>, V: Into<Value>> FromIterator<(K, V)> for DataMap {
    fn from_iter<I: IntoIterator<Item = (K, V)>>(iter: I) -> Self {
        let mut map = DataMap::new();
        for (k, v) in iter {
            map.insert(k, v);
        }
        map
    }
}

/// A map whose one entry holds `levels` maps and lists, alternating, each inside the one before.
#[cfg(test)]
pub(crate) fn nested_maps(levels: usize) -> DataMap {
    let mut v = Value::Int(1);
    for i in 0..levels {
        v = if i % 2 == 0 {
            Value::Map(DataMap::new().with("k", v))
        } else {
            Value::List(vec![v])
        };
    }
    DataMap::new().with("k", v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn insert_keeps_order_and_replaces_in_place() {
        let mut m = DataMap::new().with("b", 1i64).with("a", 2i64);
        m.insert("b", 3i64);
        let keys: Vec<_> = m.iter().map(|(k, _)| k).collect();
        assert_eq!(keys, ["b", "a"]);
        assert_eq!(m.get_i64("b"), Some(3));
    }

    #[test]
    fn lists_flatten_into_one_field_per_element_in_place() {
        let m = DataMap::new()
            .with("n", 1i64)
            .with("l", Value::List(vec![Value::Int(3), Value::Float(0.5)]))
            .with("empty", Value::List(vec![]))
            .with(
                "nested",
                Value::List(vec![Value::List(vec![Value::Bool(true)])]),
            )
            .with("s", "x");
        assert_eq!(
            m.flatten_lists(),
            DataMap::new()
                .with("n", 1i64)
                .with("l.0", 3i64)
                .with("l.1", 0.5)
                .with("nested.0.0", true)
                .with("s", "x")
        );
    }

    #[test]
    fn rename_keeps_position_and_replaces_target() {
        let mut m = DataMap::new()
            .with("x", 1i64)
            .with("y", 2i64)
            .with("z", 3i64);
        assert!(m.rename("z", "x"));
        let keys: Vec<_> = m.iter().map(|(k, _)| k.to_string()).collect();
        assert_eq!(keys, ["y", "x"]);
        assert_eq!(m.get_i64("x"), Some(3));
        assert!(!m.rename("nope", "q"));
    }

    #[test]
    fn regression_rename_with_repeated_keys_from_the_wire() {
        // decoded maps may repeat a key; renaming onto it must neither panic nor pick the wrong entry
        let mut m = DataMap::new();
        m.push("heading", Value::Int(1));
        m.push("heading", Value::Int(2));
        m.push("hdg", Value::Int(3));
        assert!(m.rename("hdg", "heading"));
        assert_eq!(
            m.iter()
                .map(|(k, v)| (k.to_string(), v.clone()))
                .collect::<Vec<_>>(),
            [("heading".to_string(), Value::Int(3))]
        );
        let mut m = DataMap::new();
        m.push("b", Value::Int(1));
        m.push("a", Value::Int(2));
        m.push("a", Value::Int(3));
        assert!(m.rename("a", "b"));
        assert_eq!(
            m.iter()
                .map(|(k, v)| (k.to_string(), v.clone()))
                .collect::<Vec<_>>(),
            [
                ("b".to_string(), Value::Int(2)),
                ("a".to_string(), Value::Int(3))
            ]
        );
    }

    #[test]
    fn loose_parsing_picks_the_narrowest_type() {
        assert_eq!(Value::parse_loose("true"), Value::Bool(true));
        assert_eq!(Value::parse_loose("-12"), Value::Int(-12));
        assert_eq!(Value::parse_loose("1.5"), Value::Float(1.5));
        assert_eq!(Value::parse_loose("nan"), Value::label("nan"));
        assert_eq!(Value::parse_loose("\"12\""), Value::label("12"));
        assert_eq!(Value::parse_loose("N"), Value::label("N"));
    }

    #[test]
    fn paths_walk_nested_maps() {
        let m = DataMap::new().with("depth", 4.5f64).with(
            "pose",
            DataMap::new()
                .with("position", DataMap::new().with("x", 1i64).with("y", 2i64))
                .with(
                    "wps",
                    Value::List(vec![DataMap::new().with("x", 9i64).into()]),
                ),
        );
        assert_eq!(m.get_path("depth"), Some(&Value::Float(4.5)));
        assert_eq!(m.get_path("pose.position.y"), Some(&Value::Int(2)));
        assert_eq!(
            m.get_path("pose.position").and_then(Value::as_map),
            m.get("pose")
                .and_then(Value::as_map)
                .and_then(|p| p.get("position"))
                .and_then(Value::as_map)
        );
        // absent keys, a path through a scalar or a list, empty segments
        for missing in [
            "pose.position.z",
            "depth.x",
            "pose.wps.0.x",
            "pose..x",
            "",
            "nope",
        ] {
            assert_eq!(m.get_path(missing), None, "{missing}");
        }
        // a key holding a dot is one key to `get`, two segments to `get_path`
        let dotted = DataMap::new().with("a.b", 1i64);
        assert_eq!(dotted.get_path("a.b"), None);
        assert_eq!(dotted.get_i64("a.b"), Some(1));
    }

    #[test]
    fn rename_touches_top_level_keys_only() {
        let mut m = DataMap::new()
            .with("x", 1i64)
            .with("pose", DataMap::new().with("x", 2i64));
        assert!(m.rename("x", "east"));
        assert_eq!(m.get_i64("east"), Some(1));
        assert_eq!(m.get_path("pose.x"), Some(&Value::Int(2)));
        assert!(!m.rename("pose.x", "pose.east"));
        assert_eq!(m.get_path("pose.x"), Some(&Value::Int(2)));
    }

    #[test]
    fn nested_maps_print_in_braces() {
        let m = DataMap::new()
            .with("n", 3i64)
            .with(
                "pose",
                DataMap::new()
                    .with("x", 1i64)
                    .with("y", 2.5f64)
                    .with("frame", "utm"),
            )
            .with("wps", Value::List(vec![DataMap::new().into()]));
        assert_eq!(
            m.to_string(),
            "n=3 pose={x=1, y=2.5, frame=\"utm\"} wps=[{}]"
        );
        assert_eq!(m.get("pose").map(Value::type_name), Some("map"));
        assert_eq!(
            m.get("wps").and_then(Value::as_list).map(<[_]>::len),
            Some(1)
        );
        assert_eq!(Value::Int(1).as_map(), None);
    }

    #[test]
    fn maps_compare_by_entries_in_order() {
        let a = Value::from(DataMap::new().with("x", 1i64).with("y", f64::NAN));
        let b = Value::from(DataMap::new().with("x", 1i64).with("y", f64::NAN));
        let swapped = Value::from(DataMap::new().with("y", f64::NAN).with("x", 1i64));
        assert_eq!(a, b);
        assert_ne!(a, swapped);
        assert_ne!(Value::from(DataMap::new()), Value::List(vec![]));
    }

    #[test]
    fn float_equality_is_bitwise() {
        assert_eq!(Value::Float(f64::NAN), Value::Float(f64::NAN));
        assert_ne!(Value::Float(0.0), Value::Float(-0.0));
    }
}
