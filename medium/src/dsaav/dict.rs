//! The DSAAV key dictionary: message-type and parameter-key numbers, with the names seabus uses for
//! them and each key's value type. Built in (`configs/dsaav-dictionary.xml`), extended by a user's
//! file in the same form.

use crate::xml::{self, FileError};
use std::collections::HashMap;

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

/// Message types and keys by number and by name.
#[derive(Debug, Clone, Default)]
pub struct Dictionary {
    types: HashMap<u16, String>,
    type_ids: HashMap<String, u16>,
    keys: HashMap<u16, (String, ValueType)>,
    key_ids: HashMap<String, (u16, ValueType)>,
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
            let name = name_attr.value.trim().to_string();
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
                if next.types.contains_key(&id) || next.type_ids.contains_key(&name) {
                    return Err(el.error(format!("message type {id} or `{name}` is defined twice")));
                }
                next.types.insert(id, name.clone());
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
                if next.keys.contains_key(&id) || next.key_ids.contains_key(&name) {
                    return Err(el.error(format!("key {id} or `{name}` is defined twice")));
                }
                next.keys.insert(id, (name.clone(), ty));
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
    pub fn key_name(&self, id: u16) -> Option<(&str, ValueType)> {
        self.keys.get(&id).map(|(n, t)| (n.as_str(), *t))
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
        self.types
            .get(&id)
            .cloned()
            .unwrap_or_else(|| id.to_string())
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
