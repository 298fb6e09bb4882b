//! MAVLink messages as datamaps and back, through the messages' own serde form (the `mavlink`
//! crate derives it for every message of its dialects).
//!
//! A message becomes a datamap of its fields, by their MAVLink names (`type`, which Rust spells
//! `mavtype`, is `type` again), in the order the crate declares them (the order on the wire):
//!
//! | MAVLink field | datamap value |
//! |---|---|
//! | integer (`uint8_t` … `int64_t`) | integer (a `uint64_t` above 2⁶³−1 as its decimal text) |
//! | `float`, `double` | float (a `float` as the shortest decimal that reads back to it: 0.1, not 0.10000000149) |
//! | enum | the value's name (`MAV_TYPE_SUBMARINE`) |
//! | bitmask enum | the names of the bits set joined by ` \| ` (`MAV_MODE_FLAG_SAFETY_ARMED \| MAV_MODE_FLAG_CUSTOM_MODE_ENABLED`), bits without a name as hex (`0x100`), no bit as empty text |
//! | `char[N]` | text (up to its first NUL) |
//! | other array | list |
//!
//! A datamap becomes a message the same way back, each field checked against the message's
//! definition: a field the message does not have is refused naming it and the fields it has, a
//! missing field is refused naming it (MAVLink 2 extension fields may be left out: they are 0), a
//! value of the wrong kind is refused naming the field and what it takes. Besides the forms above a
//! bitmask takes a number, an integer field a float without a fraction or decimal text, a float
//! field an integer or text (`nan`), a list may be shorter than the array (the rest is 0) and a
//! byte string fills an array of bytes.

use mavlink::Message;
use seabus_medium::datamap::{DataMap, Text, Value};
use serde::de::value::{MapDeserializer, SeqDeserializer};
use serde::de::{DeserializeOwned, IntoDeserializer, Visitor};
use serde::ser::{
    SerializeMap, SerializeSeq, SerializeStruct, SerializeStructVariant, SerializeTuple,
    SerializeTupleStruct, SerializeTupleVariant,
};
use serde::{Serialize, Serializer};
use std::borrow::Cow;
use std::fmt;

/// The fields a received message's datamap carries besides the message's own: who sent it
/// (`sysid`, `compid`). They are ignored when a datamap is sent (seabus sends with its own ids).
pub const HEADER_FIELDS: [&str; 2] = ["sysid", "compid"];

/// A message's value as serde gives it, before it becomes a datamap value.
#[derive(Debug, Clone, PartialEq)]
enum Node {
    Null,
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f64),
    Str(Text),
    /// Text a bitmask wrote of itself (`A | B`): told apart from a `char[N]` field's text.
    Flags(String),
    Seq(Vec<Node>),
    Map(Vec<(Text, Node)>),
}

/// Why a value could not be converted (serde's errors, in words).
#[derive(Debug)]
struct Error(String);

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Error {}

impl serde::ser::Error for Error {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Error(msg.to_string())
    }
}

impl serde::de::Error for Error {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Error(msg.to_string())
    }
}

/// A `float` as the shortest decimal that reads back to the same `float`.
fn widen(v: f32) -> f64 {
    if v.is_finite() {
        // written to a buffer on the stack: no allocation for each float of each message
        ryu::Buffer::new()
            .format_finite(v)
            .parse()
            .unwrap_or(f64::from(v))
    } else {
        f64::from(v)
    }
}

/// Serializes a value into a [`Node`].
struct Ser;

struct SeqSer(Vec<Node>);

struct MapSer {
    entries: Vec<(Text, Node)>,
    key: Option<Text>,
}

impl Serializer for Ser {
    type Ok = Node;
    type Error = Error;
    type SerializeSeq = SeqSer;
    type SerializeTuple = SeqSer;
    type SerializeTupleStruct = SeqSer;
    type SerializeTupleVariant = SeqSer;
    type SerializeMap = MapSer;
    type SerializeStruct = MapSer;
    type SerializeStructVariant = MapSer;

    fn serialize_bool(self, v: bool) -> Result<Node, Error> {
        Ok(Node::Bool(v))
    }
    fn serialize_i8(self, v: i8) -> Result<Node, Error> {
        Ok(Node::Int(v.into()))
    }
    fn serialize_i16(self, v: i16) -> Result<Node, Error> {
        Ok(Node::Int(v.into()))
    }
    fn serialize_i32(self, v: i32) -> Result<Node, Error> {
        Ok(Node::Int(v.into()))
    }
    fn serialize_i64(self, v: i64) -> Result<Node, Error> {
        Ok(Node::Int(v))
    }
    fn serialize_u8(self, v: u8) -> Result<Node, Error> {
        Ok(Node::Int(v.into()))
    }
    fn serialize_u16(self, v: u16) -> Result<Node, Error> {
        Ok(Node::Int(v.into()))
    }
    fn serialize_u32(self, v: u32) -> Result<Node, Error> {
        Ok(Node::Int(v.into()))
    }
    fn serialize_u64(self, v: u64) -> Result<Node, Error> {
        Ok(i64::try_from(v).map_or(Node::UInt(v), Node::Int))
    }
    fn serialize_f32(self, v: f32) -> Result<Node, Error> {
        Ok(Node::Float(widen(v)))
    }
    fn serialize_f64(self, v: f64) -> Result<Node, Error> {
        Ok(Node::Float(v))
    }
    fn serialize_char(self, v: char) -> Result<Node, Error> {
        Ok(Node::Str(Cow::Owned(v.to_string())))
    }
    fn serialize_str(self, v: &str) -> Result<Node, Error> {
        Ok(Node::Str(Cow::Owned(v.to_owned())))
    }
    fn serialize_bytes(self, v: &[u8]) -> Result<Node, Error> {
        Ok(Node::Seq(
            v.iter().map(|b| Node::Int((*b).into())).collect(),
        ))
    }
    fn serialize_none(self) -> Result<Node, Error> {
        Ok(Node::Null)
    }
    fn serialize_some<T: ?Sized + Serialize>(self, v: &T) -> Result<Node, Error> {
        v.serialize(Ser)
    }
    fn serialize_unit(self) -> Result<Node, Error> {
        Ok(Node::Null)
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<Node, Error> {
        Ok(Node::Null)
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
    ) -> Result<Node, Error> {
        Ok(Node::Str(Cow::Borrowed(variant)))
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        v: &T,
    ) -> Result<Node, Error> {
        v.serialize(Ser)
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        v: &T,
    ) -> Result<Node, Error> {
        Ok(Node::Map(vec![(Cow::Borrowed(variant), v.serialize(Ser)?)]))
    }
    fn serialize_seq(self, len: Option<usize>) -> Result<SeqSer, Error> {
        Ok(SeqSer(Vec::with_capacity(len.unwrap_or(0))))
    }
    fn serialize_tuple(self, len: usize) -> Result<SeqSer, Error> {
        Ok(SeqSer(Vec::with_capacity(len)))
    }
    fn serialize_tuple_struct(self, _: &'static str, len: usize) -> Result<SeqSer, Error> {
        Ok(SeqSer(Vec::with_capacity(len)))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        len: usize,
    ) -> Result<SeqSer, Error> {
        Ok(SeqSer(Vec::with_capacity(len)))
    }
    fn serialize_map(self, len: Option<usize>) -> Result<MapSer, Error> {
        Ok(MapSer {
            entries: Vec::with_capacity(len.unwrap_or(0)),
            key: None,
        })
    }
    fn serialize_struct(self, _: &'static str, len: usize) -> Result<MapSer, Error> {
        self.serialize_map(Some(len))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        len: usize,
    ) -> Result<MapSer, Error> {
        self.serialize_map(Some(len))
    }
    // bitmasks write themselves with this (`A | B`), `char[N]` fields with `serialize_str`
    fn collect_str<T: ?Sized + fmt::Display>(self, v: &T) -> Result<Node, Error> {
        Ok(Node::Flags(v.to_string()))
    }
}

impl SerializeSeq for SeqSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        self.0.push(v.serialize(Ser)?);
        Ok(())
    }
    fn end(self) -> Result<Node, Error> {
        Ok(Node::Seq(self.0))
    }
}

impl SerializeTuple for SeqSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        SerializeSeq::serialize_element(self, v)
    }
    fn end(self) -> Result<Node, Error> {
        SerializeSeq::end(self)
    }
}

impl SerializeTupleStruct for SeqSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        SerializeSeq::serialize_element(self, v)
    }
    fn end(self) -> Result<Node, Error> {
        SerializeSeq::end(self)
    }
}

impl SerializeTupleVariant for SeqSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        SerializeSeq::serialize_element(self, v)
    }
    fn end(self) -> Result<Node, Error> {
        SerializeSeq::end(self)
    }
}

impl SerializeMap for MapSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_key<T: ?Sized + Serialize>(&mut self, key: &T) -> Result<(), Error> {
        match key.serialize(Ser)? {
            Node::Str(k) => {
                self.key = Some(k);
                Ok(())
            }
            Node::Flags(k) => {
                self.key = Some(Cow::Owned(k));
                Ok(())
            }
            other => Err(Error(format!("a map key that is not text: {other:?}"))),
        }
    }
    fn serialize_value<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        let key = self
            .key
            .take()
            .ok_or_else(|| Error("a map value without its key".into()))?;
        self.entries.push((key, v.serialize(Ser)?));
        Ok(())
    }
    fn end(self) -> Result<Node, Error> {
        Ok(Node::Map(self.entries))
    }
}

impl SerializeStruct for MapSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        key: &'static str,
        v: &T,
    ) -> Result<(), Error> {
        self.entries.push((Cow::Borrowed(key), v.serialize(Ser)?));
        Ok(())
    }
    fn end(self) -> Result<Node, Error> {
        Ok(Node::Map(self.entries))
    }
}

impl SerializeStructVariant for MapSer {
    type Ok = Node;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        key: &'static str,
        v: &T,
    ) -> Result<(), Error> {
        SerializeStruct::serialize_field(self, key, v)
    }
    fn end(self) -> Result<Node, Error> {
        Ok(Node::Map(self.entries))
    }
}

impl<'de> serde::Deserializer<'de> for Node {
    type Error = Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Error> {
        match self {
            Node::Null => visitor.visit_unit(),
            Node::Bool(b) => visitor.visit_bool(b),
            Node::Int(i) => visitor.visit_i64(i),
            Node::UInt(u) => visitor.visit_u64(u),
            Node::Float(f) => visitor.visit_f64(f),
            Node::Str(Cow::Borrowed(s)) => visitor.visit_str(s),
            Node::Str(Cow::Owned(s)) | Node::Flags(s) => visitor.visit_string(s),
            Node::Seq(items) => {
                let mut seq = SeqDeserializer::new(items.into_iter());
                let out = visitor.visit_seq(&mut seq)?;
                seq.end()?;
                Ok(out)
            }
            Node::Map(entries) => {
                let mut map = MapDeserializer::new(entries.into_iter());
                let out = visitor.visit_map(&mut map)?;
                map.end()?;
                Ok(out)
            }
        }
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map struct enum identifier
        ignored_any
    }
}

impl IntoDeserializer<'_, Error> for Node {
    type Deserializer = Node;
    fn into_deserializer(self) -> Node {
        self
    }
}

/// The MAVLink name of a field the crate names `rust` (`mavtype` is MAVLink's `type`).
fn mavlink_name(rust: &str) -> &str {
    if rust == "mavtype" { "type" } else { rust }
}

/// The crate's name of MAVLink field `name`.
fn rust_name(name: &str) -> &str {
    if name == "type" { "mavtype" } else { name }
}

/// An enum's value as serde writes it for the crate's enums (tagged: `{"type": NAME}`): its name.
fn enum_name(entries: &[(Text, Node)]) -> Option<&str> {
    match entries {
        [(tag, Node::Str(name))] if tag == "type" => Some(name),
        _ => None,
    }
}

/// The fields of `msg` as serde gives them, without the message's own tag.
fn fields<M: Serialize>(msg: &M) -> Result<Vec<(Text, Node)>, String> {
    match msg.serialize(Ser) {
        Ok(Node::Map(mut entries)) => {
            if entries.first().is_some_and(|(k, _)| k.as_ref() == "type") {
                entries.remove(0);
            }
            Ok(entries)
        }
        Ok(other) => Err(format!("a message that is no set of fields: {other:?}")),
        Err(e) => Err(e.0),
    }
}

/// A message's fields as a datamap (see the [module](self) for the forms).
pub fn to_map<M: Message + Serialize>(msg: &M) -> Result<DataMap, String> {
    match msg.serialize(ValueSer { top: true }) {
        Ok(Value::Map(map)) => Ok(map),
        Ok(other) => Err(format!("a message that is no set of fields: {other:?}")),
        Err(e) => Err(e.0),
    }
}

/// Message `name` of dialect `M` from the fields of `map` (see the [module](self) for the forms);
/// the error names the message and the field.
pub fn from_map<M: Message + Serialize + DeserializeOwned>(
    name: &str,
    map: &DataMap,
) -> Result<M, String> {
    let template = M::message_id_from_name(name)
        .and_then(M::default_message_from_id)
        .ok_or_else(|| format!("there is no MAVLink message `{name}` in this dialect"))?;
    let fields = fields(&template)?;
    for (key, _) in map.iter() {
        let known = fields.iter().any(|(k, _)| k.as_ref() == rust_name(key));
        if !known && !HEADER_FIELDS.contains(&key) {
            let names: Vec<&str> = fields
                .iter()
                .map(|(k, _)| mavlink_name(k.as_ref()))
                .collect();
            return Err(format!(
                "{name} has no field `{key}`; its fields are {}",
                names.join(", ")
            ));
        }
    }
    let mut input = Vec::with_capacity(fields.len() + 1);
    input.push((
        Cow::Borrowed("type"),
        Node::Str(Cow::Owned(name.to_string())),
    ));
    for (rust, template) in fields {
        if let Some(v) = map.get(mavlink_name(rust.as_ref())) {
            let node = fit(v, &template)
                .map_err(|e| format!("{name}: field `{}`: {e}", mavlink_name(rust.as_ref())))?;
            input.push((rust, node));
        }
    }
    M::deserialize(Node::Map(input)).map_err(|e| format!("{name}: {}", tidy(&e.0)))
}

/// Serde's words about a message, in MAVLink's names and of a readable length.
fn tidy(text: &str) -> String {
    let text = text.replace("`mavtype`", "`type`");
    // an unknown enum name lists every name there is (hundreds for MAV_CMD)
    match text.find(", expected one of ") {
        Some(i) => {
            let (head, list) = text.split_at(i);
            let names: Vec<&str> = list
                .trim_start_matches(", expected one of ")
                .split(", ")
                .collect();
            if names.len() > 6 {
                format!(
                    "{head}, expected one of {}, … ({} names)",
                    names[..6].join(", "),
                    names.len()
                )
            } else {
                text
            }
        }
        None => text,
    }
}

/// `v` in the form serde takes for a field whose default value is `template`.
fn fit(v: &Value, template: &Node) -> Result<Node, String> {
    match template {
        Node::Map(entries) => match (enum_name(entries), v) {
            (Some(_), Value::Str(s)) => Ok(Node::Map(vec![(
                Cow::Borrowed("type"),
                Node::Str(Cow::Owned(s.to_string())),
            )])),
            (Some(example), other) => Err(format!(
                "expected a name such as {example}, not the {} {other}",
                other.type_name()
            )),
            (None, _) => Err("a field of a kind this medium cannot fill".to_string()),
        },
        Node::Flags(example) => match v {
            Value::Str(s) => Ok(Node::Flags(s.to_string())),
            Value::Int(n) if *n >= 0 => Ok(Node::Flags(format!("{n:#x}"))),
            other => Err(format!(
                "expected flags such as `{example}` (names joined by ` | `) or a number, not the {} {other}",
                other.type_name()
            )),
        },
        Node::Str(_) => match v {
            Value::Str(s) => Ok(Node::Str(Cow::Owned(s.to_string()))),
            Value::Int(_) | Value::Float(_) | Value::Bool(_) => {
                Ok(Node::Str(Cow::Owned(v.to_string())))
            }
            other => Err(format!("expected text, not a {}", other.type_name())),
        },
        Node::Int(_) | Node::UInt(_) => match v {
            Value::Int(i) => Ok(Node::Int(*i)),
            Value::Float(f) if f.is_finite() && f.fract() == 0.0 => {
                if *f >= 0.0 {
                    Ok(Node::UInt(*f as u64))
                } else {
                    Ok(Node::Int(*f as i64))
                }
            }
            Value::Str(s) => {
                let s = s.trim();
                s.parse::<i64>()
                    .map(Node::Int)
                    .or_else(|_| s.parse::<u64>().map(Node::UInt))
                    .map_err(|_| format!("expected an integer, not the text {s:?}"))
            }
            other => Err(format!(
                "expected an integer, not the {} {other}",
                other.type_name()
            )),
        },
        Node::Float(_) => match v {
            Value::Float(f) => Ok(Node::Float(*f)),
            Value::Int(i) => Ok(Node::Float(*i as f64)),
            Value::Str(s) => s
                .trim()
                .parse::<f64>()
                .map(Node::Float)
                .map_err(|_| format!("expected a number, not the text {s:?}")),
            other => Err(format!(
                "expected a number, not the {} {other}",
                other.type_name()
            )),
        },
        Node::Seq(items) => {
            let given: Vec<Value> = match v {
                Value::List(l) => l.clone(),
                Value::Bytes(b) => b.iter().map(|x| Value::Int((*x).into())).collect(),
                other => {
                    return Err(format!(
                        "expected a list of up to {} items, not the {} {other}",
                        items.len(),
                        other.type_name()
                    ));
                }
            };
            if given.len() > items.len() {
                return Err(format!(
                    "expected a list of up to {} items, not {}",
                    items.len(),
                    given.len()
                ));
            }
            let mut out = Vec::with_capacity(items.len());
            for (i, g) in given.iter().enumerate() {
                out.push(fit(g, &items[i]).map_err(|e| format!("item {i}: {e}"))?);
            }
            out.extend(items[given.len()..].iter().cloned());
            Ok(Node::Seq(out))
        }
        Node::Bool(_) => match v {
            Value::Bool(b) => Ok(Node::Bool(*b)),
            other => Err(format!(
                "expected true or false, not a {}",
                other.type_name()
            )),
        },
        Node::Null => Ok(Node::Null),
    }
}

/// Serializes a received message's value straight into a datamap [`Value`] (no [`Node`] tree in
/// between, field names borrowed from the crate). With `top`, the value is the message itself:
/// its fields without the message's own tag, room left for [`HEADER_FIELDS`].
#[derive(Clone, Copy)]
struct ValueSer {
    top: bool,
}

const INNER: ValueSer = ValueSer { top: false };

/// The items of a list as they are serialized.
struct ListSer(Vec<Value>);

/// The fields of a struct as they are serialized; an enum of the crate (tagged: `{"type": NAME}`)
/// has only the tag, and is its name.
struct FieldsSer {
    entries: Vec<(Text, Value)>,
    tag: Option<Value>,
    top: bool,
}

/// The entries of a map as they are serialized.
struct EntriesSer {
    entries: Vec<(Text, Value)>,
    key: Option<Text>,
}

/// Text a value writes of itself ([`fmt::Display`]), in a string made at its first piece with
/// room for a bitmask's `A | B` (grown a byte at a time it would be reallocated several times);
/// no text, no string.
struct TextBuf(Option<String>);

impl fmt::Write for TextBuf {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        if !s.is_empty() {
            self.0
                .get_or_insert_with(|| String::with_capacity(s.len().max(64)))
                .push_str(s);
        }
        Ok(())
    }
}

impl TextBuf {
    /// The text of `v` as a datamap string (the empty text without an allocation).
    fn text<T: ?Sized + fmt::Display>(v: &T) -> Result<Value, Error> {
        let mut buf = TextBuf(None);
        fmt::write(&mut buf, format_args!("{v}")).map_err(|e| Error(e.to_string()))?;
        Ok(Value::Str(buf.0.map_or(Cow::Borrowed(""), Cow::Owned)))
    }
}

impl Serializer for ValueSer {
    type Ok = Value;
    type Error = Error;
    type SerializeSeq = ListSer;
    type SerializeTuple = ListSer;
    type SerializeTupleStruct = ListSer;
    type SerializeTupleVariant = ListSer;
    type SerializeMap = EntriesSer;
    type SerializeStruct = FieldsSer;
    type SerializeStructVariant = FieldsSer;

    fn serialize_bool(self, v: bool) -> Result<Value, Error> {
        Ok(Value::Bool(v))
    }
    fn serialize_i8(self, v: i8) -> Result<Value, Error> {
        Ok(Value::Int(v.into()))
    }
    fn serialize_i16(self, v: i16) -> Result<Value, Error> {
        Ok(Value::Int(v.into()))
    }
    fn serialize_i32(self, v: i32) -> Result<Value, Error> {
        Ok(Value::Int(v.into()))
    }
    fn serialize_i64(self, v: i64) -> Result<Value, Error> {
        Ok(Value::Int(v))
    }
    fn serialize_u8(self, v: u8) -> Result<Value, Error> {
        Ok(Value::Int(v.into()))
    }
    fn serialize_u16(self, v: u16) -> Result<Value, Error> {
        Ok(Value::Int(v.into()))
    }
    fn serialize_u32(self, v: u32) -> Result<Value, Error> {
        Ok(Value::Int(v.into()))
    }
    fn serialize_u64(self, v: u64) -> Result<Value, Error> {
        Ok(i64::try_from(v).map_or_else(|_| Value::from(v.to_string()), Value::Int))
    }
    fn serialize_f32(self, v: f32) -> Result<Value, Error> {
        Ok(Value::Float(widen(v)))
    }
    fn serialize_f64(self, v: f64) -> Result<Value, Error> {
        Ok(Value::Float(v))
    }
    fn serialize_char(self, v: char) -> Result<Value, Error> {
        Ok(Value::from(v.to_string()))
    }
    fn serialize_str(self, v: &str) -> Result<Value, Error> {
        Ok(Value::from(v))
    }
    fn serialize_bytes(self, v: &[u8]) -> Result<Value, Error> {
        Ok(Value::List(
            v.iter().map(|b| Value::Int((*b).into())).collect(),
        ))
    }
    fn serialize_none(self) -> Result<Value, Error> {
        Ok(Value::List(Vec::new()))
    }
    fn serialize_some<T: ?Sized + Serialize>(self, v: &T) -> Result<Value, Error> {
        v.serialize(INNER)
    }
    fn serialize_unit(self) -> Result<Value, Error> {
        Ok(Value::List(Vec::new()))
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<Value, Error> {
        Ok(Value::List(Vec::new()))
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
    ) -> Result<Value, Error> {
        Ok(Value::label(variant))
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        v: &T,
    ) -> Result<Value, Error> {
        v.serialize(INNER)
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        v: &T,
    ) -> Result<Value, Error> {
        Ok(Value::Map(DataMap::from_entries(vec![(
            Cow::Borrowed(variant),
            v.serialize(INNER)?,
        )])))
    }
    fn serialize_seq(self, len: Option<usize>) -> Result<ListSer, Error> {
        Ok(ListSer(Vec::with_capacity(len.unwrap_or(0))))
    }
    fn serialize_tuple(self, len: usize) -> Result<ListSer, Error> {
        Ok(ListSer(Vec::with_capacity(len)))
    }
    fn serialize_tuple_struct(self, _: &'static str, len: usize) -> Result<ListSer, Error> {
        Ok(ListSer(Vec::with_capacity(len)))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        len: usize,
    ) -> Result<ListSer, Error> {
        Ok(ListSer(Vec::with_capacity(len)))
    }
    fn serialize_map(self, len: Option<usize>) -> Result<EntriesSer, Error> {
        Ok(EntriesSer {
            entries: Vec::with_capacity(len.unwrap_or(0)),
            key: None,
        })
    }
    fn serialize_struct(self, _: &'static str, len: usize) -> Result<FieldsSer, Error> {
        // a message's `len` counts its tag, which it leaves out, and the header fields are to come;
        // an enum (one field, its tag) needs no list at all
        let room = match (self.top, len) {
            (true, _) => len + HEADER_FIELDS.len(),
            (false, 1) => 0,
            (false, _) => len,
        };
        Ok(FieldsSer {
            entries: Vec::with_capacity(room),
            tag: None,
            top: self.top,
        })
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        len: usize,
    ) -> Result<FieldsSer, Error> {
        self.serialize_struct("", len)
    }
    // bitmasks write themselves with this (`A | B`), `char[N]` fields with `serialize_str`
    fn collect_str<T: ?Sized + fmt::Display>(self, v: &T) -> Result<Value, Error> {
        TextBuf::text(v)
    }
}

impl SerializeSeq for ListSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        self.0.push(v.serialize(INNER)?);
        Ok(())
    }
    fn end(self) -> Result<Value, Error> {
        Ok(Value::List(self.0))
    }
}

impl SerializeTuple for ListSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        SerializeSeq::serialize_element(self, v)
    }
    fn end(self) -> Result<Value, Error> {
        SerializeSeq::end(self)
    }
}

impl SerializeTupleStruct for ListSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        SerializeSeq::serialize_element(self, v)
    }
    fn end(self) -> Result<Value, Error> {
        SerializeSeq::end(self)
    }
}

impl SerializeTupleVariant for ListSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        SerializeSeq::serialize_element(self, v)
    }
    fn end(self) -> Result<Value, Error> {
        SerializeSeq::end(self)
    }
}

impl SerializeMap for EntriesSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_key<T: ?Sized + Serialize>(&mut self, key: &T) -> Result<(), Error> {
        match key.serialize(INNER)? {
            Value::Str(k) => {
                self.key = Some(k);
                Ok(())
            }
            other => Err(Error(format!("a map key that is not text: {other:?}"))),
        }
    }
    fn serialize_value<T: ?Sized + Serialize>(&mut self, v: &T) -> Result<(), Error> {
        let key = self
            .key
            .take()
            .ok_or_else(|| Error("a map value without its key".into()))?;
        self.entries.push((key, v.serialize(INNER)?));
        Ok(())
    }
    fn end(self) -> Result<Value, Error> {
        Ok(Value::Map(DataMap::from_entries(self.entries)))
    }
}

impl SerializeStruct for FieldsSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        key: &'static str,
        v: &T,
    ) -> Result<(), Error> {
        // no field of the crate's is called `type` (Rust's `mavtype` is): this is a tag, the
        // message's own (left out) or an enum's (its name)
        if key == "type" {
            if !self.top {
                self.tag = Some(v.serialize(INNER)?);
            }
        } else {
            self.entries
                .push((Cow::Borrowed(mavlink_name(key)), v.serialize(INNER)?));
        }
        Ok(())
    }
    fn end(mut self) -> Result<Value, Error> {
        match self.tag {
            Some(name @ Value::Str(_)) if self.entries.is_empty() => Ok(name),
            Some(tag) => {
                self.entries.insert(0, (Cow::Borrowed("type"), tag));
                Ok(Value::Map(DataMap::from_entries(self.entries)))
            }
            None => Ok(Value::Map(DataMap::from_entries(self.entries))),
        }
    }
}

impl SerializeStructVariant for FieldsSer {
    type Ok = Value;
    type Error = Error;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        key: &'static str,
        v: &T,
    ) -> Result<(), Error> {
        SerializeStruct::serialize_field(self, key, v)
    }
    fn end(self) -> Result<Value, Error> {
        SerializeStruct::end(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::ardupilotmega as apm;
    use mavlink::dialects::common;

    fn heartbeat() -> apm::MavMessage {
        apm::MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
            custom_mode: 19,
            mavtype: apm::MavType::MAV_TYPE_SUBMARINE,
            autopilot: apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: apm::MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                | apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: apm::MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    }

    #[test]
    fn a_heartbeat_reads_with_mavlink_names_enums_and_flags_as_names() {
        let map = to_map(&heartbeat()).unwrap();
        assert_eq!(
            map,
            DataMap::new()
                .and("custom_mode", 19i64)
                .and("type", "MAV_TYPE_SUBMARINE")
                .and("autopilot", "MAV_AUTOPILOT_ARDUPILOTMEGA")
                .and(
                    "base_mode",
                    "MAV_MODE_FLAG_SAFETY_ARMED | MAV_MODE_FLAG_CUSTOM_MODE_ENABLED"
                )
                .and("system_status", "MAV_STATE_ACTIVE")
                .and("mavlink_version", 3i64)
        );
        let back: apm::MavMessage = from_map("HEARTBEAT", &map).unwrap();
        assert_eq!(back, heartbeat());
    }

    #[test]
    fn floats_read_as_the_decimal_sent_and_nan_stays_nan() {
        let att = apm::MavMessage::ATTITUDE(apm::ATTITUDE_DATA {
            time_boot_ms: 1234,
            roll: 0.1,
            pitch: -0.25,
            yaw: f32::NAN,
            rollspeed: 0.0,
            pitchspeed: -0.0,
            yawspeed: 3.0e-5,
        });
        let map = to_map(&att).unwrap();
        assert_eq!(map.get("time_boot_ms"), Some(&Value::Int(1234)));
        assert_eq!(map.get("roll"), Some(&Value::Float(0.1)));
        assert_eq!(map.get("pitch"), Some(&Value::Float(-0.25)));
        assert!(map.get_f64("yaw").unwrap().is_nan());
        assert_eq!(map.get("pitchspeed"), Some(&Value::Float(-0.0)));
        assert_eq!(map.get("yawspeed"), Some(&Value::Float(3.0e-5)));
        let back: apm::MavMessage = from_map("ATTITUDE", &map).unwrap();
        let apm::MavMessage::ATTITUDE(a) = back else {
            panic!("{back:?}")
        };
        assert_eq!((a.roll, a.pitch, a.yawspeed), (0.1, -0.25, 3.0e-5));
        assert!(a.yaw.is_nan());
        assert!(a.pitchspeed.is_sign_negative());
    }

    #[test]
    fn arrays_are_lists_and_char_arrays_text() {
        let st = common::STATUSTEXT_DATA {
            severity: common::MavSeverity::MAV_SEVERITY_WARNING,
            text: "Leak detected".into(),
            ..Default::default()
        };
        let map = to_map(&common::MavMessage::STATUSTEXT(st.clone())).unwrap();
        assert_eq!(map.get_str("text"), Some("Leak detected"));
        assert_eq!(map.get_str("severity"), Some("MAV_SEVERITY_WARNING"));
        let back: common::MavMessage = from_map("STATUSTEXT", &map).unwrap();
        assert_eq!(back, common::MavMessage::STATUSTEXT(st));

        let map = DataMap::new()
            .with("time_usec", 5i64)
            .with("port", 1i64)
            .with("servo1_raw", 1500i64);
        let e = from_map::<common::MavMessage>("SERVO_OUTPUT_RAW", &map).unwrap_err();
        assert_eq!(e, "SERVO_OUTPUT_RAW: missing field `servo2_raw`");

        // a list shorter than the array is filled with zeros; a byte string fills bytes
        let mut rtcm = DataMap::new()
            .with("flags", 0i64)
            .with("len", 3i64)
            .with("data", Value::Bytes(vec![1, 2, 3]));
        let back: common::MavMessage = from_map("GPS_RTCM_DATA", &rtcm).unwrap();
        let common::MavMessage::GPS_RTCM_DATA(d) = back else {
            panic!()
        };
        assert_eq!((&d.data[..4], d.data.len()), (&[1u8, 2, 3, 0][..], 180));
        let out = to_map(&common::MavMessage::GPS_RTCM_DATA(d)).unwrap();
        let list = out.get("data").and_then(Value::as_list).unwrap();
        assert_eq!(list.len(), 180);
        assert_eq!(&list[..3], &[Value::Int(1), Value::Int(2), Value::Int(3)]);
        rtcm.insert("data", Value::List(vec![Value::Int(0); 181]));
        assert_eq!(
            from_map::<common::MavMessage>("GPS_RTCM_DATA", &rtcm).unwrap_err(),
            "GPS_RTCM_DATA: field `data`: expected a list of up to 180 items, not 181"
        );
    }

    fn arm() -> DataMap {
        DataMap::new()
            .with("target_system", 1i64)
            .with("target_component", 1i64)
            .with("command", "MAV_CMD_COMPONENT_ARM_DISARM")
            .with("confirmation", 0i64)
            .with("param1", 1i64)
            .with("param2", 0.0)
            .with("param3", 0.0)
            .with("param4", 0.0)
            .with("param5", 0.0)
            .with("param6", 0.0)
            .with("param7", "nan")
    }

    #[test]
    fn a_command_is_made_of_its_fields_by_name() {
        let msg: apm::MavMessage = from_map("COMMAND_LONG", &arm()).unwrap();
        let apm::MavMessage::COMMAND_LONG(c) = msg else {
            panic!("{msg:?}")
        };
        assert_eq!(c.command, apm::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM);
        assert_eq!((c.target_system, c.target_component), (1, 1));
        assert_eq!(c.param1, 1.0);
        assert!(c.param7.is_nan());
    }

    #[test]
    fn what_a_message_cannot_take_is_refused_naming_the_field() {
        let mut m = arm();
        m.remove("param3");
        assert_eq!(
            from_map::<apm::MavMessage>("COMMAND_LONG", &m).unwrap_err(),
            "COMMAND_LONG: missing field `param3`"
        );
        let e =
            from_map::<apm::MavMessage>("COMMAND_LONG", &arm().with("parm1", 1i64)).unwrap_err();
        assert!(
            e.starts_with("COMMAND_LONG has no field `parm1`; its fields are param1, param2"),
            "{e}"
        );
        let e = from_map::<apm::MavMessage>("COMMAND_LONG", &arm().with("command", 400i64))
            .unwrap_err();
        assert_eq!(
            e,
            "COMMAND_LONG: field `command`: expected a name such as MAV_CMD_NAV_WAYPOINT, not the int 400"
        );
        let e =
            from_map::<apm::MavMessage>("COMMAND_LONG", &arm().with("command", "MAV_CMD_NO_SUCH"))
                .unwrap_err();
        assert!(
            e.starts_with("COMMAND_LONG: unknown variant `MAV_CMD_NO_SUCH`, expected one of `MAV_CMD_NAV_WAYPOINT`")
                && e.ends_with(" names)"),
            "{e}"
        );
        let e = from_map::<apm::MavMessage>("COMMAND_LONG", &arm().with("target_system", 300i64))
            .unwrap_err();
        assert_eq!(e, "COMMAND_LONG: invalid value: integer `300`, expected u8");
        let e =
            from_map::<apm::MavMessage>("COMMAND_LONG", &arm().with("param1", "one")).unwrap_err();
        assert_eq!(
            e,
            "COMMAND_LONG: field `param1`: expected a number, not the text \"one\""
        );
        assert_eq!(
            from_map::<apm::MavMessage>("NO_SUCH_MESSAGE", &arm()).unwrap_err(),
            "there is no MAVLink message `NO_SUCH_MESSAGE` in this dialect"
        );
        // an ArduPilot message is not in the common dialect
        assert!(from_map::<common::MavMessage>("RANGEFINDER", &DataMap::new()).is_err());
        assert!(
            from_map::<apm::MavMessage>(
                "RANGEFINDER",
                &DataMap::new().with("distance", 1.5).with("voltage", 0.1)
            )
            .is_ok()
        );
    }

    #[test]
    fn type_is_the_mavlink_name_and_header_fields_are_let_through() {
        let hb = to_map(&heartbeat())
            .unwrap()
            .with("sysid", 1i64)
            .with("compid", 1i64);
        let back: apm::MavMessage = from_map("HEARTBEAT", &hb).unwrap();
        assert_eq!(back, heartbeat());
        let mut no_type = hb.clone();
        no_type.remove("type");
        assert_eq!(
            from_map::<apm::MavMessage>("HEARTBEAT", &no_type).unwrap_err(),
            "HEARTBEAT: missing field `type`"
        );
    }

    #[test]
    fn bitmasks_take_names_or_numbers() {
        let mut hb = to_map(&heartbeat()).unwrap();
        hb.insert("base_mode", 0x81i64);
        let apm::MavMessage::HEARTBEAT(h) = from_map::<apm::MavMessage>("HEARTBEAT", &hb).unwrap()
        else {
            panic!()
        };
        assert_eq!(h.base_mode.bits(), 0x81);
        hb.insert("base_mode", "");
        let apm::MavMessage::HEARTBEAT(h) = from_map::<apm::MavMessage>("HEARTBEAT", &hb).unwrap()
        else {
            panic!()
        };
        assert_eq!(h.base_mode.bits(), 0);
        // bits without a name read as hex and go back as they were
        let sys = apm::MavMessage::SYS_STATUS(apm::SYS_STATUS_DATA {
            onboard_control_sensors_present: apm::MavSysStatusSensor::from_bits_retain(0x8000_0001),
            ..Default::default()
        });
        let map = to_map(&sys).unwrap();
        let present = map.get_str("onboard_control_sensors_present").unwrap();
        assert!(
            present.starts_with("MAV_SYS_STATUS_SENSOR_3D_GYRO"),
            "{present}"
        );
        assert_eq!(
            from_map::<apm::MavMessage>("SYS_STATUS", &map).unwrap(),
            sys
        );
    }

    #[test]
    fn a_mavlink2_extension_field_may_be_left_out() {
        let ack = DataMap::new()
            .with("command", "MAV_CMD_COMPONENT_ARM_DISARM")
            .with("result", "MAV_RESULT_ACCEPTED");
        let apm::MavMessage::COMMAND_ACK(a) =
            from_map::<apm::MavMessage>("COMMAND_ACK", &ack).unwrap()
        else {
            panic!()
        };
        assert_eq!((a.progress, a.target_system), (0, 0));
    }
}
