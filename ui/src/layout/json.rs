//! The JSON form of a layout that the page reads ([`Layout::to_json`]): commands, the widget
//! tree with its attributes typed (numbers, bindings, durations in milliseconds, lists) and the
//! defaults filled in, and the keyboard and gamepad bindings.

use super::model::{
    AxisBinding, CONTAINERS, CommandDecl, Confirm, DEFAULT_FRESH, DEFAULT_HEALTH,
    DEFAULT_LOG_TOPICS, KeyBinding, Layout, Node, OUTPUTS, Offset,
};
use super::values::{field_list, field_value, list, list_items};
use seabus_medium::parse::parse_duration;
use seabus_medium::{DataMap, Value};
use serde_json::{Map, Value as Json, json};
use std::collections::BTreeMap;

impl Layout {
    /// The layout as the page reads it (the JSON form in `docs/console.md`).
    pub fn to_json(&self) -> Json {
        let commands: Map<String, Json> = self
            .commands
            .values()
            .map(|c| (c.name.clone(), command_json(c)))
            .collect();
        let keys: Vec<Json> = self.keys.iter().map(key_json).collect();
        let axes: Vec<Json> = self.axes.iter().map(axis_json).collect();
        let buttons: Vec<Json> = self
            .buttons
            .iter()
            .map(|b| json!({"index": b.index, "command": b.command}))
            .collect();
        json!({
            "name": self.name,
            "title": self.title,
            "roles": self.roles,
            "vehicle": self.vehicle,
            "vars": self.vars,
            "commands": commands,
            "root": node_json(&self.root),
            "keys": keys,
            "gamepad": {"axes": axes, "buttons": buttons},
        })
    }
}

fn command_json(c: &CommandDecl) -> Json {
    let (confirm, hold) = match c.confirm {
        Confirm::None => ("none", None),
        Confirm::Dialog => ("dialog", None),
        Confirm::Hold(d) => ("hold", Some(d.as_millis() as u64)),
    };
    let bounds = |m: &BTreeMap<String, f64>| -> Map<String, Json> {
        m.iter().map(|(k, v)| (k.clone(), number(*v))).collect()
    };
    json!({
        "topic": c.topic.as_str(),
        "fields": map_json(&c.fields),
        "role": c.role,
        "confirm": confirm,
        "hold_ms": hold,
        "rate_hz": c.rate_hz,
        "neutral": map_json(&c.neutral),
        "lease": c.lease,
        "min": bounds(&c.min),
        "max": bounds(&c.max),
        "from": c.from.iter().map(|(k, (t, f))| (k.clone(), json!({"topic": t.as_str(), "field": f}))).collect::<Map<String, Json>>(),
        "keep_ms": c.keep.map(|d| d.as_millis() as u64),
        "resume": c.resume,
        "safe": c.safe,
    })
}

fn key_json(k: &KeyBinding) -> Json {
    json!({
        "key": k.key,
        "command": k.command,
        "field": k.field,
        "value": k.value.as_ref().map(value_json),
        "step": k.step,
    })
}

fn axis_json(a: &AxisBinding) -> Json {
    let offset = match &a.offset {
        Offset::Number(n) => number(*n),
        Offset::Binding(topic, field) => json!({"topic": topic, "field": field}),
    };
    json!({
        "index": a.index,
        "command": a.command,
        "field": a.field,
        "deadband": a.deadband,
        "expo": a.expo,
        "gain": a.gain,
        "offset": offset,
    })
}

/// A number as JSON: an integer when it is whole and small, `null` when it is not finite.
fn number(x: f64) -> Json {
    if x.fract() == 0.0 && x.abs() < 9.0e15 {
        Json::from(x as i64)
    } else {
        serde_json::Number::from_f64(x).map_or(Json::Null, Json::Number)
    }
}

/// A number written in a file, as JSON (integers stay integers).
fn number_text(text: &str) -> Json {
    let t = text.trim();
    match t.parse::<i64>() {
        Ok(i) => Json::from(i),
        Err(_) => t
            .parse::<f64>()
            .ok()
            .and_then(serde_json::Number::from_f64)
            .map_or_else(|| Json::String(t.to_string()), Json::Number),
    }
}

fn value_json(v: &Value) -> Json {
    match v {
        Value::Bool(b) => Json::Bool(*b),
        Value::Int(i) => Json::from(*i),
        Value::Float(f) => serde_json::Number::from_f64(*f).map_or(Json::Null, Json::Number),
        Value::Str(s) => Json::String(s.to_string()),
        other => Json::String(other.to_string()),
    }
}

fn map_json(map: &DataMap) -> Json {
    Json::Object(
        map.iter()
            .map(|(k, v)| (k.to_string(), value_json(v)))
            .collect(),
    )
}

/// `topic.field` as `{topic, field}`.
fn bind_json(text: &str) -> Json {
    match text.trim().rsplit_once('.') {
        Some((topic, field)) => json!({"topic": topic, "field": field}),
        None => json!({"topic": text.trim(), "field": null}),
    }
}

fn duration_json(text: &str) -> Json {
    parse_duration(text).map_or(Json::Null, |d| json!(d.as_millis() as u64))
}

/// `ranges="FROM:TO:COLOUR, …"` as `[{from, to, colour}]`.
fn ranges_json(text: &str) -> Json {
    Json::Array(
        list_items(text, ',')
            .filter_map(|r| {
                let mut p = r.splitn(3, ':');
                let (from, to, colour) = (p.next()?, p.next()?, p.next()?);
                Some(json!({"from": number_text(from), "to": number_text(to), "colour": colour.trim()}))
            })
            .collect(),
    )
}

/// `waypoints="LAT,LON; …"` as `[[lat, lon]]`.
fn waypoints_json(text: &str) -> Json {
    Json::Array(
        list_items(text, ';')
            .filter_map(|w| {
                let (lat, lon) = w.split_once(',')?;
                Some(json!([number_text(lat), number_text(lon)]))
            })
            .collect(),
    )
}

/// Attribute `name` of a node of `kind` as the page reads it: its key and value.
fn attr_json<'a>(kind: &str, name: &'a str, value: &str) -> (&'a str, Json) {
    match name {
        "bind" if kind == "health" => ("bind", json!({"topic": value.trim()})),
        "bind" | "heading" => (name, bind_json(value)),
        "fresh" => ("fresh_ms", duration_json(value)),
        "window" => ("window_ms", duration_json(value)),
        "min" | "max" | "step" | "precision" | "trail" | "lines" | "columns" => {
            (name, number_text(value))
        }
        "sizes" => (
            "sizes",
            Json::Array(value.split_whitespace().map(number_text).collect()),
        ),
        "ranges" => ("ranges", ranges_json(value)),
        "waypoints" => ("waypoints", waypoints_json(value)),
        "grid" if value.trim() == "auto" => ("grid", Json::from("auto")),
        "grid" => ("grid", number_text(value)),
        "topics" => ("topics", json!(list(value))),
        "set" => (
            "set",
            field_list(value).map_or(Json::Null, |m| map_json(&m)),
        ),
        "on" | "off" => (name, value_json(&field_value(value.trim()))),
        _ => (name, Json::from(value)),
    }
}

/// What the page assumes for a node of `kind` whose file leaves it out.
fn defaults(kind: &str) -> Vec<(&'static str, Json)> {
    let mut out = match kind {
        "health" => vec![("bind", json!({"topic": DEFAULT_HEALTH}))],
        "log" => vec![
            ("topics", json!(list(DEFAULT_LOG_TOPICS))),
            ("lines", json!(200)),
        ],
        "history" => vec![("lines", json!(200))],
        "plot" => vec![("window_ms", json!(60_000))],
        _ => Vec::new(),
    };
    if OUTPUTS.contains(&kind) {
        out.push(("fresh_ms", json!(DEFAULT_FRESH.as_millis() as u64)));
    }
    out
}

fn node_json(node: &Node) -> Json {
    let mut o = Map::new();
    o.insert("kind".into(), Json::from(node.kind.as_str()));
    o.insert("id".into(), Json::from(node.id.as_str()));
    if let Some(l) = &node.label {
        o.insert("label".into(), Json::from(l.as_str()));
    }
    if let Some(r) = &node.role {
        o.insert("role".into(), Json::from(r.as_str()));
    }
    for (name, value) in &node.attrs {
        if name == "command" {
            let (command, field) = node.command().unwrap_or_default();
            o.insert("field".into(), json!(field));
            o.insert("command".into(), Json::from(command));
            continue;
        }
        let (key, v) = attr_json(&node.kind, name, value);
        o.insert(key.to_string(), v);
    }
    for (key, v) in defaults(&node.kind) {
        o.entry(key).or_insert(v);
    }
    let kind = node.kind.as_str();
    if CONTAINERS.contains(&kind) || kind == "tab" || kind == "plot" {
        o.insert(
            "children".into(),
            Json::Array(node.children.iter().map(node_json).collect()),
        );
    }
    if kind == "tabs" {
        let titles: Vec<&str> = node
            .children
            .iter()
            .map(|t| t.attrs.get("title").map_or("", String::as_str))
            .collect();
        o.insert("titles".into(), json!(titles));
    }
    Json::Object(o)
}

#[cfg(test)]
mod tests {
    use super::super::testing::{example, parse};
    use serde_json::json;

    #[test]
    fn json_has_the_documented_shape() {
        let j = example().to_json();
        assert_eq!(j["name"], "pilot");
        assert_eq!(j["title"], "Pilot — iver");
        assert_eq!(j["vars"], json!({"vehicle": "iver"}));
        assert_eq!(
            j["commands"]["course"],
            json!({
                "topic": "cmd.course",
                "fields": {"heading": 0, "depth": 0, "speed": 0.0},
                "role": null,
                "confirm": "none",
                "hold_ms": null,
                "rate_hz": 5.0,
                "neutral": {"speed": 0.0},
                "lease": true,
                "min": {},
                "max": {"speed": 2.5},
                "from": {},
                "keep_ms": null,
                "resume": null,
                "safe": false,
            })
        );
        assert_eq!(j["commands"]["start"]["confirm"], "hold");
        assert_eq!(j["commands"]["start"]["hold_ms"], 1000);
        let root = &j["root"];
        assert_eq!(root["kind"], "row");
        assert_eq!(root["sizes"], json!([2, 1]));
        let track = &root["children"][0];
        assert_eq!(
            track["heading"],
            json!({"topic": "nav.attitude", "field": "yaw"})
        );
        assert_eq!(track["waypoints"], json!([[43.5, 16.4], [43.6, 16.5]]));
        assert_eq!(track["grid"], 50);
        assert_eq!(track["fresh_ms"], 2000);
        let column = &root["children"][1];
        let gauge = &column["children"][1];
        assert_eq!(
            gauge,
            &json!({
                "kind": "gauge", "id": "speed",
                "bind": {"topic": "nav.velocity", "field": "speed"},
                "min": 0, "max": 3, "fresh_ms": 5000,
                "ranges": [{"from": 0, "to": 2, "colour": "green"}, {"from": 2, "to": 3, "colour": "#f00"}],
            })
        );
        let slider = &column["children"][3];
        assert_eq!(slider["command"], "course");
        assert_eq!(slider["field"], "speed");
        assert_eq!(slider["step"], 0.1);
        assert_eq!(column["children"][5]["set"], json!({"action": "stop"}));
        assert_eq!(
            column["children"][6]["topics"],
            json!(["cmd.status", "vehicle.state"])
        );
        assert_eq!(
            j["keys"][1],
            json!({"key": "w", "command": "course", "field": "speed", "value": 1.5, "step": null})
        );
        assert_eq!(
            j["gamepad"]["axes"][1],
            json!({"index": 0, "command": "course", "field": "heading", "deadband": 0.15, "expo": 0.0,
                   "gain": 30.0, "offset": {"topic": "nav.attitude", "field": "yaw"}})
        );
        assert_eq!(
            j["gamepad"]["buttons"],
            json!([{"index": 0, "command": "start"}])
        );
        let tabs = parse("<layout name=\"t\"><tabs><tab title=\"A\"><log/></tab><tab title=\"B\"><history/></tab></tabs></layout>")
            .unwrap()
            .to_json();
        assert_eq!(tabs["root"]["titles"], json!(["A", "B"]));
        assert_eq!(tabs["root"]["children"][1]["children"][0]["lines"], 200);
    }
}
