//! JSON Schemas of topics, for the tools that show or store messages by their fields (MCAP files,
//! Foxglove): a standard dataset's schema from the catalogue (field names, types, units, ranges and
//! what each field means), or, for a topic no dataset describes, one read off a datamap's values.
//!
//! A schema describes the JSON form of a datamap ([`seabus_medium::json`]): floats are numbers
//! (non-finite ones `{"float": "NaN"}`), integers integers, bytes `{"base64": "…"}`, nested maps
//! objects, lists arrays.

use crate::datasets::{Catalogue, Dataset, Field, FieldType};
use seabus_medium::{DataMap, Value};
use serde_json::{Map, Value as Json, json};

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
    let properties: Map<String, Json> = d
        .fields
        .iter()
        .map(|f| (f.name.clone(), field_schema(f)))
        .collect();
    let required: Vec<&str> = d.required().map(|f| f.name.as_str()).collect();
    let schema = json!({
        "$schema": DIALECT,
        "title": format!("seabus.{}", d.name),
        "description": d.summary,
        "type": "object",
        "properties": properties,
        "required": required,
    });
    Schema {
        name: format!("seabus.{}", d.name),
        text: schema.to_string(),
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
        let required: Vec<&str> = j["required"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        let ds = cat.get("attitude").unwrap();
        assert_eq!(
            required,
            ds.required().map(|f| f.name.as_str()).collect::<Vec<_>>()
        );
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
}
