//! JSON Schemas of topics, for the tools that show or store messages by their fields (MCAP files,
//! Foxglove): a standard dataset's schema from the catalogue (field names, types, units, ranges and
//! what each field means), or, for a topic no dataset describes, one read off a datamap's values.
//!
//! A schema describes the JSON message of a datamap ([`write_message`]): seabus's JSON form
//! ([`seabus_medium::json`]), floats numbers, integers integers, bytes `{"base64": "…"}`, nested
//! maps objects, lists arrays. JSON has no number for a float that is not finite (NaN, ±inf), and
//! a reader that takes `"type": "number"` at its word (Foxglove, Lichtblick, a JSON Schema
//! validator) must not meet another form in its place: such a value is left out of its place and
//! given, in seabus's JSON form (`{"float": "NaN"}`), under the message's [`NONFINITE`] object,
//! nested as it was (a list holding one moves whole). Every schema admits that object, and a
//! required field may be there instead of in its place. [`read_message`] puts the values back.

use crate::datasets::{Catalogue, Dataset, Field, FieldType};
use seabus_medium::{DataMap, Value};
use serde_json::{Map, Value as Json, json};

/// The key of a message's object that holds its non-finite floats, nested as in the message.
pub const NONFINITE: &str = "$nonfinite";

/// Why a datamap has no JSON message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MessageError {
    /// Lists and maps nest deeper than any payload form allows.
    #[error("the datamap nests deeper than 32 lists and maps")]
    TooDeep,
    /// The datamap has a field of [`NONFINITE`]'s name, which a reader could not tell apart.
    #[error("the datamap has a field `{NONFINITE}`, the name its non-finite floats go under")]
    Reserved,
}

/// Whether `v` is, or holds, a float that is not finite.
fn holds_nonfinite(v: &Value) -> bool {
    match v {
        Value::Float(f) => !f.is_finite(),
        Value::List(items) => items.iter().any(holds_nonfinite),
        Value::Map(m) => m.iter().any(|(_, v)| holds_nonfinite(v)),
        _ => false,
    }
}

/// `map` parted into what stays in place and what holds a non-finite float, nested alike: maps
/// are walked, anything else holding one moves whole.
fn part(map: &DataMap) -> (DataMap, DataMap) {
    let (mut kept, mut moved) = (DataMap::new(), DataMap::new());
    for (k, v) in map.entries() {
        match v {
            Value::Map(inner) if holds_nonfinite(v) => {
                let (inner_kept, inner_moved) = part(inner);
                kept.push(k.clone(), Value::Map(inner_kept));
                moved.push(k.clone(), Value::Map(inner_moved));
            }
            v if holds_nonfinite(v) => moved.push(k.clone(), v.clone()),
            v => kept.push(k.clone(), v.clone()),
        }
    }
    (kept, moved)
}

/// Writes `map` as the JSON message its schema describes (see the module's documentation) onto
/// `out`.
pub fn write_message(map: &DataMap, out: &mut Vec<u8>) -> Result<(), MessageError> {
    if map.get(NONFINITE).is_some() {
        return Err(MessageError::Reserved);
    }
    let written = if map.iter().any(|(_, v)| holds_nonfinite(v)) {
        let (mut kept, moved) = part(map);
        kept.push(NONFINITE, Value::Map(moved));
        serde_json::to_writer(out, &kept)
    } else {
        serde_json::to_writer(out, map)
    };
    // writing to memory fails only where the depth limit refuses a value
    written.map_err(|_| MessageError::TooDeep)
}

/// Puts `moved` back into `map`, where its nesting says.
fn put_back(map: &mut DataMap, moved: DataMap) {
    for (k, v) in moved.entries() {
        match (map.remove(k), v) {
            (Some(Value::Map(mut inner)), Value::Map(m)) => {
                put_back(&mut inner, m.clone());
                map.push(k.clone(), Value::Map(inner));
            }
            (_, v) => map.push(k.clone(), v.clone()),
        }
    }
}

/// Reads a JSON message ([`write_message`]'s, or any JSON object in seabus's JSON form) as a
/// datamap, its non-finite floats back in their places; the error names line and column.
pub fn read_message(text: &str) -> Result<DataMap, serde_json::Error> {
    let mut map = seabus_medium::json::from_json(text)?;
    // another tool's field of that name that is no object stays as it came
    if matches!(map.get(NONFINITE), Some(Value::Map(_)))
        && let Some(Value::Map(moved)) = map.remove(NONFINITE)
    {
        put_back(&mut map, moved);
    }
    Ok(map)
}

/// The schema of the [`NONFINITE`] object: any object (Foxglove shows it as a field with none).
fn nonfinite_schema() -> Json {
    json!({
        "type": "object",
        "properties": {},
        "description": "fields whose float value JSON has no number for (NaN, inf, -inf), \
            left out of their place and given here as {\"float\": \"NaN\"}, \
            {\"float\": \"inf\"} or {\"float\": \"-inf\"}, nested as in the message",
    })
}

/// Properties `required` of an object schema, where a field that may hold a float may be in the
/// [`NONFINITE`] object instead: those as `allOf` alternatives, the others as `required`.
fn required_of(schema: &mut Map<String, Json>, required: Vec<(&str, FieldType)>) {
    let (floats, others): (Vec<_>, Vec<_>) = required
        .into_iter()
        .partition(|(_, ty)| matches!(ty, FieldType::Float | FieldType::List | FieldType::Map));
    let others: Vec<&str> = others.into_iter().map(|(name, _)| name).collect();
    schema.insert("required".into(), json!(others));
    if !floats.is_empty() {
        let either: Vec<Json> = floats
            .into_iter()
            .map(|(name, _)| {
                json!({"anyOf": [
                    {"required": [name]},
                    {"required": [NONFINITE], "properties": {NONFINITE: {"required": [name]}}},
                ]})
            })
            .collect();
        schema.insert("allOf".into(), Json::Array(either));
    }
}

/// The JSON Schema dialect every schema here declares.
pub const DIALECT: &str = "https://json-schema.org/draft/2020-12/schema";

/// A topic's schema: its name (`seabus.attitude` for a dataset, the topic otherwise) and the
/// JSON Schema text.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    /// The schema's name.
    pub name: String,
    /// The JSON Schema, as text.
    pub text: String,
}

/// The schema of a field of type `ty`.
fn of_type(ty: FieldType) -> Map<String, Json> {
    let mut m = Map::new();
    match ty {
        FieldType::Float => m.insert("type".into(), json!("number")),
        FieldType::Int => m.insert("type".into(), json!("integer")),
        FieldType::Bool => m.insert("type".into(), json!("boolean")),
        FieldType::Str => m.insert("type".into(), json!("string")),
        FieldType::List => m.insert("type".into(), json!("array")),
        FieldType::Map => m.insert("type".into(), json!("object")),
        FieldType::Bytes => {
            m.insert("type".into(), json!("object"));
            m.insert(
                "properties".into(),
                json!({"base64": {"type": "string", "contentEncoding": "base64"}}),
            )
        }
    };
    m
}

fn field_schema(f: &Field) -> Json {
    let mut m = of_type(f.ty);
    let description = match (f.summary.is_empty(), f.unit.is_empty()) {
        (false, false) => format!("{} ({})", f.summary, f.unit),
        (false, true) => f.summary.clone(),
        (true, false) => f.unit.clone(),
        (true, true) => String::new(),
    };
    if !description.is_empty() {
        m.insert("description".into(), json!(description));
    }
    if let Some(min) = f.min {
        m.insert("minimum".into(), json!(min));
    }
    if let Some(max) = f.max {
        m.insert("maximum".into(), json!(max));
    }
    Json::Object(m)
}

/// The schema of dataset `d`: every field it names, the required ones required; fields it does
/// not name are allowed (a device may publish more).
pub fn of_dataset(d: &Dataset) -> Schema {
    let mut properties: Map<String, Json> = d
        .fields
        .iter()
        .map(|f| (f.name.clone(), field_schema(f)))
        .collect();
    properties.insert(NONFINITE.into(), nonfinite_schema());
    let Json::Object(mut schema) = json!({
        "$schema": DIALECT,
        "title": format!("seabus.{}", d.name),
        "description": d.summary,
        "type": "object",
        "properties": properties,
    }) else {
        unreachable!("an object")
    };
    required_of(
        &mut schema,
        d.required().map(|f| (f.name.as_str(), f.ty)).collect(),
    );
    Schema {
        name: format!("seabus.{}", d.name),
        text: Json::Object(schema).to_string(),
    }
}

/// The JSON Schema of one value, read off the value itself.
fn of_value(v: &Value) -> Json {
    match v {
        Value::Bool(_) => Json::Object(of_type(FieldType::Bool)),
        Value::Int(_) => Json::Object(of_type(FieldType::Int)),
        Value::Float(_) => Json::Object(of_type(FieldType::Float)),
        Value::Str(_) => Json::Object(of_type(FieldType::Str)),
        Value::Bytes(_) => Json::Object(of_type(FieldType::Bytes)),
        Value::List(items) => match items.first() {
            Some(first) => json!({"type": "array", "items": of_value(first)}),
            None => Json::Object(of_type(FieldType::List)),
        },
        Value::Map(m) => of_map(m),
    }
}

fn of_map(map: &DataMap) -> Json {
    let properties: Map<String, Json> = map
        .iter()
        .map(|(k, v)| (k.to_string(), of_value(v)))
        .collect();
    json!({"type": "object", "properties": properties})
}

/// A schema for `topic`, whose messages no dataset describes, read off one of its datamaps: each
/// field with the type of its value there.
pub fn inferred(topic: &str, sample: &DataMap) -> Schema {
    let Json::Object(mut schema) = of_map(sample) else {
        unreachable!("a map's schema is an object")
    };
    if let Some(Json::Object(properties)) = schema.get_mut("properties") {
        properties.insert(NONFINITE.into(), nonfinite_schema());
    }
    schema.insert("$schema".into(), json!(DIALECT));
    schema.insert("title".into(), json!(topic));
    Schema {
        name: topic.to_string(),
        text: Json::Object(schema).to_string(),
    }
}

/// The schema of `topic`: its dataset's, when the catalogue has a dataset published on that topic,
/// else one read off `sample`.
pub fn for_topic(catalogue: &Catalogue, topic: &str, sample: &DataMap) -> Schema {
    match catalogue.iter().find(|d| d.topic == topic) {
        Some(d) => of_dataset(d),
        None => inferred(topic, sample),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dataset_schema_names_its_fields_types_units_and_ranges() {
        let cat = Catalogue::built_in();
        let s = for_topic(&cat, "nav.attitude", &DataMap::new());
        assert_eq!(s.name, "seabus.attitude");
        let j: Json = serde_json::from_str(&s.text).unwrap();
        assert_eq!(j["type"], "object");
        assert_eq!(j["$schema"], DIALECT);
        let roll = &j["properties"]["roll"];
        assert_eq!(roll["type"], "number");
        assert!(
            roll["description"].as_str().unwrap().ends_with("(deg)"),
            "{roll}"
        );
        // required: in place, or a float's (NaN, ±inf) under `$nonfinite` instead
        let mut required: Vec<&str> = j["required"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        for either in j["allOf"].as_array().unwrap() {
            let name = either["anyOf"][0]["required"][0].as_str().unwrap();
            assert_eq!(
                either["anyOf"][1],
                json!({"required": [NONFINITE], "properties": {NONFINITE: {"required": [name]}}})
            );
            required.push(name);
        }
        required.sort_unstable();
        let ds = cat.get("attitude").unwrap();
        let mut wanted: Vec<&str> = ds.required().map(|f| f.name.as_str()).collect();
        wanted.sort_unstable();
        assert_eq!(required, wanted);
        assert!(j["properties"][NONFINITE]["properties"].is_object());
    }

    #[test]
    fn a_topic_without_dataset_gets_the_types_of_its_values() {
        let cat = Catalogue::built_in();
        let sample = DataMap::new()
            .with("n", 3i64)
            .with("x", 1.5)
            .with("ok", true)
            .with("name", "a")
            .with("raw", Value::Bytes(vec![1, 2]))
            .with("inner", DataMap::new().with("y", 2.0));
        let s = for_topic(&cat, "lab.thing", &sample);
        assert_eq!(s.name, "lab.thing");
        let j: Json = serde_json::from_str(&s.text).unwrap();
        let p = &j["properties"];
        assert_eq!(
            [
                &p["n"]["type"],
                &p["x"]["type"],
                &p["ok"]["type"],
                &p["name"]["type"],
                &p["raw"]["type"],
                &p["inner"]["properties"]["y"]["type"],
            ],
            ["integer", "number", "boolean", "string", "object", "number"]
        );
        assert_eq!(p["raw"]["properties"]["base64"]["type"], "string");
    }

    #[test]
    fn non_finite_floats_go_under_nonfinite_and_come_back() {
        let map = DataMap::new()
            .with("depth", f64::NAN)
            .with("ok", 1.5)
            .with(
                "pos",
                DataMap::new().with("x", f64::INFINITY).with("y", 2.0),
            )
            .with(
                "ranges",
                Value::List(vec![Value::Float(1.0), Value::Float(f64::NEG_INFINITY)]),
            )
            .with("n", 3i64);
        let mut out = Vec::new();
        write_message(&map, &mut out).unwrap();
        let j: Json = serde_json::from_slice(&out).unwrap();
        assert_eq!(
            j,
            json!({
                "ok": 1.5,
                "pos": {"y": 2.0},
                "n": 3,
                NONFINITE: {
                    "depth": {"float": "NaN"},
                    "pos": {"x": {"float": "inf"}},
                    "ranges": [1.0, {"float": "-inf"}],
                },
            })
        );
        let back = read_message(std::str::from_utf8(&out).unwrap()).unwrap();
        assert!(back.get_f64("depth").unwrap().is_nan());
        assert_eq!(back.get_f64("ok"), Some(1.5));
        let Some(Value::Map(pos)) = back.get("pos") else {
            panic!("pos is a map: {back:?}")
        };
        assert_eq!(
            (pos.get_f64("x"), pos.get_f64("y")),
            (Some(f64::INFINITY), Some(2.0))
        );
        assert_eq!(back.get("ranges"), map.get("ranges"));
        // all finite: the message is the datamap's JSON form
        let mut plain = Vec::new();
        write_message(&DataMap::new().with("a", 1.0), &mut plain).unwrap();
        assert_eq!(plain, br#"{"a":1.0}"#);
        // a field of the reserved name is refused, not misread later
        let reserved = DataMap::new().with(NONFINITE, 1i64);
        assert_eq!(
            write_message(&reserved, &mut Vec::new()),
            Err(MessageError::Reserved)
        );
    }
}
