//! The DSAAV key dictionary: message-type and parameter-key numbers, with the names seabus uses for
//! them and each key's value type. Built in (`configs/dsaav-dictionary.xml`), extended by a user's
//! file in the same form.

use seabus_medium::xml::{self, FileError};
use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::{Mutex, OnceLock};

/// The built-in dictionary's text.
pub const BUILT_IN: &str = include_str!("../../../configs/dsaav-dictionary.xml");
/// The name the built-in dictionary is known by in messages.
pub const BUILT_IN_FILE: &str = "configs/dsaav-dictionary.xml";

/// A parameter's value type on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    /// 32-bit integer.
    Int,
    /// 32-bit float.
    Float,
    /// 64-bit float.
    Double,
    /// String.
    Str,
}

impl ValueType {
    /// Its name in the dictionary file.
    pub fn name(self) -> &'static str {
        match self {
            ValueType::Int => "int",
            ValueType::Float => "float",
            ValueType::Double => "double",
            ValueType::Str => "string",
        }
    }
}

/// A quick hash for the dictionary's numbers and names (FNV-1a, then mixed so that every bit of
/// the result depends on the input): the dictionary is looked up for every key of every message.
#[derive(Default)]
pub(crate) struct QuickHasher(u64);

impl Hasher for QuickHasher {
    fn finish(&self) -> u64 {
        (self.0 ^ (self.0 >> 29)).wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }

    fn write(&mut self, bytes: &[u8]) {
        let mut h = if self.0 == 0 {
            0xcbf2_9ce4_8422_2325
        } else {
            self.0
        };
        for b in bytes {
            h = (h ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
        self.0 = h;
    }

    fn write_u16(&mut self, n: u16) {
        self.0 = (self.0 ^ u64::from(n)).wrapping_mul(0x0100_0000_01b3);
    }
}

/// A map with [`QuickHasher`].
pub(crate) type QuickMap<K, V> = HashMap<K, V, BuildHasherDefault<QuickHasher>>;

/// The one copy of `name` kept for the program's life, so that datamaps built from received
/// frames name their keys without copying them. Each distinct name is kept once, however many
/// dictionaries name it.
fn intern(name: &str) -> &'static str {
    static NAMES: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut names = NAMES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    match names.get(name) {
        Some(n) => n,
        None => {
            let n: &'static str = Box::leak(name.into());
            names.insert(n);
            n
        }
    }
}

/// Message types and keys by number and by name.
#[derive(Debug, Clone, Default)]
pub struct Dictionary {
    types: QuickMap<u16, &'static str>,
    type_ids: QuickMap<&'static str, u16>,
    keys: QuickMap<u16, (&'static str, ValueType)>,
    key_ids: QuickMap<&'static str, (u16, ValueType)>,
}

impl Dictionary {
    /// The built-in dictionary.
    pub fn built_in() -> Dictionary {
        let mut d = Dictionary::default();
        // the built-in file is part of the program and checked by the tests
        if let Err(e) = d.add(BUILT_IN_FILE, BUILT_IN) {
            tracing::error!("built-in DSAAV dictionary: {e}");
        }
        d
    }

    /// Adds the types and keys of a dictionary file; a number or name already taken is an error.
    pub fn add(&mut self, file: &str, text: &str) -> Result<(), FileError> {
        let root = xml::parse(file, text)?;
        if root.name != "dsaav-dictionary" {
            return Err(root.error(format!(
                "root element is <{}>, expected <dsaav-dictionary>",
                root.name
            )));
        }
        root.only_children(&["type", "key"])?;
        let mut next = self.clone();
        for el in &root.children {
            let id_attr = el.required("id")?;
            let id: u16 = id_attr.parse("a number 0–65535")?;
            let name_attr = el.required("name")?;
            let name = name_attr.value.trim();
            if name.is_empty()
                || !name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
                || name.starts_with(|c: char| c.is_ascii_digit())
            {
                return Err(name_attr
                    .error("a name is letters, digits, `_` and `-`, not starting with a digit"));
            }
            if el.name == "type" {
                el.only_attrs(&["id", "name", "summary"])?;
                if next.types.contains_key(&id) || next.type_ids.contains_key(name) {
                    return Err(el.error(format!("message type {id} or `{name}` is defined twice")));
                }
                let name = intern(name);
                next.types.insert(id, name);
                next.type_ids.insert(name, id);
            } else {
                el.only_attrs(&["id", "name", "type", "unit", "summary"])?;
                let ty_attr = el.required("type")?;
                let ty = match ty_attr.value.trim() {
                    "int" => ValueType::Int,
                    "float" => ValueType::Float,
                    "double" => ValueType::Double,
                    "string" => ValueType::Str,
                    _ => return Err(ty_attr.error("expected int, float, double or string")),
                };
                if next.keys.contains_key(&id) || next.key_ids.contains_key(name) {
                    return Err(el.error(format!("key {id} or `{name}` is defined twice")));
                }
                let name = intern(name);
                next.keys.insert(id, (name, ty));
                next.key_ids.insert(name, (id, ty));
            }
        }
        *self = next;
        Ok(())
    }

    /// The number and value type of the key called `name`.
    pub fn key(&self, name: &str) -> Option<(u16, ValueType)> {
        self.key_ids.get(name).copied()
    }

    /// The name and value type of key `id`.
    pub fn key_name(&self, id: u16) -> Option<(&'static str, ValueType)> {
        self.keys.get(&id).copied()
    }

    /// The number of the message type called `name` (or written as a number).
    pub fn type_id(&self, name: &str) -> Option<u16> {
        self.type_ids
            .get(name)
            .copied()
            .or_else(|| name.parse().ok())
    }

    /// The name of message type `id`, or its number as text when it has none.
    pub fn type_name(&self, id: u16) -> String {
        match self.types.get(&id) {
            Some(name) => name.to_string(),
            None => id.to_string(),
        }
    }

    /// The name of message type `id`, when it has one.
    pub fn named_type(&self, id: u16) -> Option<&'static str> {
        self.types.get(&id).copied()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_dictionary_reads_and_looks_up_both_ways() {
        let mut d = Dictionary::default();
        d.add(BUILT_IN_FILE, BUILT_IN).unwrap();
        assert_eq!(d.key("depth"), Some((102, ValueType::Double)));
        assert_eq!(d.key_name(1), Some(("op", ValueType::Int)));
        assert_eq!(d.type_id("rpc-request"), Some(2));
        assert_eq!(d.type_id("77"), Some(77));
        assert_eq!(d.type_name(5), "notify");
        assert_eq!(d.type_name(900), "900");
    }

    #[test]
    fn clashes_and_bad_entries_are_placed() {
        let mut d = Dictionary::built_in();
        let e = d
            .add(
                "mine.xml",
                "<dsaav-dictionary>\n<key id=\"102\" name=\"x\" type=\"int\"/></dsaav-dictionary>",
            )
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "mine.xml:2:1: key 102 or `x` is defined twice"
        );
        let e = d
            .add(
                "mine.xml",
                "<dsaav-dictionary><key id=\"900\" name=\"x\" type=\"long\"/></dsaav-dictionary>",
            )
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("expected int, float, double or string"),
            "{e}"
        );
        // nothing of a refused file is kept
        assert_eq!(d.key("x"), None);
        d.add(
            "mine.xml",
            "<dsaav-dictionary><key id=\"900\" name=\"salinity\" type=\"double\"/></dsaav-dictionary>",
        )
        .unwrap();
        assert_eq!(d.key("salinity"), Some((900, ValueType::Double)));
    }
}
