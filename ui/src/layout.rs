//! Console layouts: the XML files that place widgets on a page, bind them to `topic.field`
//! variables and declare the commands the page may send (see `docs/console.md`).
//!
//! [`Layout::parse`] reads a layout: it substitutes `${name}` variables, expands `<template>`s
//! where they are `<use>`d, checks every element and attribute, and gives ids to the widgets that
//! have none. Every error names file, line and column. A parsed layout answers what the console
//! needs: its JSON form for the page ([`Layout::to_json`]), the variables it displays
//! ([`Layout::bindings`]), who sees it ([`Layout::visible_to`]) and whether a command the page
//! proposes is one it declares, with fields of the right types and in range ([`CommandDecl::build`]).
//! [`Layout::check`] compares it with a system: bindings whose topic no module produces and commands
//! no module accepts are warnings.

use seabus_medium::parse::{parse_duration, parse_rate};
use seabus_medium::xml::{self, Attr, Element, FileError, Pos};
use seabus_medium::{DataMap, Kind, Pattern, Topic, Value};
use seabus_modules::system::RouteSpec;
use seabus_modules::{Catalogue, Registry, SystemSpec};
use serde_json::{Map, Value as Json, json};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::Duration;

/// How old a displayed value may be before it is shown as stale, when a widget gives no `fresh`.
pub const DEFAULT_FRESH: Duration = Duration::from_secs(2);

/// The time a `confirm="hold"` button is held, when the command gives no `hold`.
pub const DEFAULT_HOLD: Duration = Duration::from_secs(1);

/// The topic a `<health>` table shows when it gives no `bind`.
pub const DEFAULT_HEALTH: &str = "vehicle.health";

/// The topics a `<log>` shows when it gives no `topics`.
pub const DEFAULT_LOG_TOPICS: &str = "cmd.status, vehicle.state";

/// Most elements a layout may have once its templates are expanded.
pub const MAX_ELEMENTS: usize = 10_000;

/// Most characters of attribute text a layout may have once its variables are substituted.
pub const MAX_TEXT: usize = 1 << 20;

/// Deepest chain of templates using templates.
pub const MAX_TEMPLATE_DEPTH: usize = 32;

/// Elements directly inside `<layout>` other than widgets.
const TOP: [&str; 6] = ["var", "command", "template", "use", "keys", "gamepad"];

/// Widgets that hold other widgets.
const CONTAINERS: [&str; 4] = ["row", "column", "tabs", "grid"];

/// Every widget kind an element may name, containers first.
const WIDGETS: [&str; 16] = [
    "row", "column", "tabs", "grid", "readout", "gauge", "plot", "track", "health", "log",
    "history", "button", "slider", "number", "text", "toggle",
];

/// Widgets that display variables and take `fresh`.
const OUTPUTS: [&str; 6] = ["readout", "gauge", "plot", "track", "health", "log"];

/// Colour names a layout may use besides `#rgb` and `#rrggbb`.
pub const COLOURS: [&str; 18] = [
    "black", "white", "gray", "grey", "red", "orange", "yellow", "green", "lime", "teal", "cyan",
    "blue", "navy", "purple", "magenta", "pink", "brown", "olive",
];

/// The attributes of a node of `kind` besides `id`, `label` and `role`; `None` for an unknown kind.
fn kind_attrs(kind: &str) -> Option<&'static [&'static str]> {
    Some(match kind {
        "row" | "column" => &["sizes"],
        "tabs" => &[],
        "tab" => &["title"],
        "grid" => &["columns"],
        "readout" => &["bind", "unit", "precision", "fresh"],
        "gauge" => &["bind", "min", "max", "unit", "precision", "ranges", "fresh"],
        "plot" => &["window", "min", "max", "fresh"],
        "series" => &["bind", "colour"],
        "track" => &["position", "heading", "trail", "waypoints", "grid", "fresh"],
        "health" => &["bind", "fresh"],
        "log" => &["topics", "lines", "fresh"],
        "history" => &["lines"],
        "button" => &["command", "set"],
        "slider" | "number" => &["command", "min", "max", "step"],
        "text" => &["command"],
        "toggle" => &["command", "on", "off"],
        _ => return None,
    })
}

/// Every widget kind.
fn widget_kinds() -> Vec<&'static str> {
    WIDGETS.to_vec()
}

/// How a command is confirmed before it is sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Confirm {
    /// Sent at once.
    None,
    /// The page asks before sending.
    Dialog,
    /// The button must be held this long.
    Hold(Duration),
}

/// A `<command>`: a topic and the fields it is sent with.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandDecl {
    /// Its name in the layout.
    pub name: String,
    /// The topic it is sent on.
    pub topic: Topic,
    /// Its fields with their initial values (which also fix their types).
    pub fields: DataMap,
    /// The role needed to send it (`None`: the console's lease role).
    pub role: Option<String>,
    /// How it is confirmed.
    pub confirm: Confirm,
    /// The rate of a dead-man command, per second.
    pub rate_hz: Option<f64>,
    /// Fields sent once when a dead-man command stops.
    pub neutral: DataMap,
    /// Whether control is needed to send it.
    pub lease: bool,
    /// Lowest values of fields.
    pub min: BTreeMap<String, f64>,
    /// Highest values of fields.
    pub max: BTreeMap<String, f64>,
    /// Where it is declared.
    pub pos: Pos,
}

impl CommandDecl {
    /// Checks a proposed set of field values (types as the defaults', ranges) and returns the full
    /// datamap to send: the defaults, overridden by `current` (the values last set, where they
    /// fit) and then by `set`; or the reason it cannot be sent.
    pub fn build(&self, current: &DataMap, set: &DataMap) -> Result<DataMap, String> {
        let mut out = self.fields.clone();
        for (name, value) in current.iter() {
            if let Ok(v) = self.fit(name, value) {
                out.insert(name.to_string(), v);
            }
        }
        for (name, value) in set.iter() {
            let v = self.fit(name, value)?;
            out.insert(name.to_string(), v);
        }
        Ok(out)
    }

    /// `value` for field `name`, converted to the field's type and within its range.
    fn fit(&self, name: &str, value: &Value) -> Result<Value, String> {
        let Some(default) = self.fields.get(name) else {
            return Err(format!(
                "command `{}` has no field `{name}`; fields: {}",
                self.name,
                field_names(&self.fields)
            ));
        };
        let v = same_type(name, default, value)?;
        if let Some(x) = v.as_f64() {
            if let Some(min) = self.min.get(name).filter(|&&m| x < m) {
                return Err(format!("field `{name}`: {x} is below the minimum {min}"));
            }
            if let Some(max) = self.max.get(name).filter(|&&m| x > m) {
                return Err(format!("field `{name}`: {x} is above the maximum {max}"));
            }
        }
        Ok(v)
    }
}

/// `value` as the type of `default`. Numbers are one type: a field whose initial value is written
/// without a point takes any number (kept an integer when whole), one with a point a float.
fn same_type(name: &str, default: &Value, value: &Value) -> Result<Value, String> {
    let v = match (default, value) {
        (Value::Float(_), Value::Float(x)) if x.is_finite() => Some(Value::Float(*x)),
        (Value::Float(_), Value::Int(i)) => Some(Value::Float(*i as f64)),
        (Value::Int(_), Value::Int(i)) => Some(Value::Int(*i)),
        (Value::Int(_), Value::Float(x)) if x.fract() == 0.0 && x.abs() < 9.0e15 => {
            Some(Value::Int(*x as i64))
        }
        (Value::Int(_), Value::Float(x)) if x.is_finite() => Some(Value::Float(*x)),
        (Value::Bool(_), Value::Bool(b)) => Some(Value::Bool(*b)),
        (Value::Str(_), Value::Str(s)) => Some(Value::Str(s.clone())),
        _ => None,
    };
    v.ok_or_else(|| {
        format!(
            "field `{name}` is {}, not {} `{value}`",
            article(default.type_name()),
            article(value.type_name())
        )
    })
}

fn article(type_name: &str) -> String {
    match type_name {
        "int" => "an int".to_string(),
        t => format!("a {t}"),
    }
}

fn field_names(map: &DataMap) -> String {
    let names: Vec<&str> = map.iter().map(|(k, _)| k).collect();
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}

/// A displayed variable: a topic (or, for a log, a pattern) and the field shown.
#[derive(Debug, Clone, PartialEq)]
pub struct Binding {
    /// The topic, or a pattern of topics.
    pub topic: String,
    /// The field, when one field is shown.
    pub field: Option<String>,
    /// How old a value may be before it is stale.
    pub fresh: Duration,
    /// The id of the widget that shows it (`axis-N` for a gamepad axis's offset).
    pub widget: String,
    /// Where the widget is written.
    pub pos: Pos,
}

/// A widget or container, with its attributes as written (variables substituted) and its children.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// The element name: `row`, `readout`, `series`, …
    pub kind: String,
    /// Its id, unique in the layout (`KIND-N` in document order when the file gives none).
    pub id: String,
    /// Its label.
    pub label: Option<String>,
    /// The role a user needs to see it.
    pub role: Option<String>,
    /// Its other attributes.
    pub attrs: BTreeMap<String, String>,
    /// Widgets inside it (tabs of `<tabs>`, series of `<plot>`).
    pub children: Vec<Node>,
    /// Where it is written.
    pub pos: Pos,
}

impl Node {
    /// The command a sending widget names, and the field it sets.
    pub fn command(&self) -> Option<(&str, Option<&str>)> {
        let c = self.attrs.get("command")?;
        Some(match c.split_once('.') {
            Some((name, field)) => (name, Some(field)),
            None => (c.as_str(), None),
        })
    }

    /// This node and every node inside it, in document order.
    pub fn walk(&self) -> Vec<&Node> {
        let mut out = Vec::new();
        let mut stack = vec![self];
        while let Some(n) = stack.pop() {
            out.push(n);
            stack.extend(n.children.iter().rev());
        }
        out
    }

    /// How old a displayed value may be before it is stale.
    fn fresh(&self) -> Duration {
        self.attrs
            .get("fresh")
            .and_then(|f| parse_duration(f))
            .unwrap_or(DEFAULT_FRESH)
    }
}

/// A keyboard binding.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyBinding {
    /// The `KeyboardEvent.key` it reacts to.
    pub key: String,
    /// The command it sends.
    pub command: String,
    /// The field it sets, when it sets one.
    pub field: Option<String>,
    /// The field's value while the key is held.
    pub value: Option<Value>,
    /// What each press adds to the field.
    pub step: Option<f64>,
    /// Where it is written.
    pub pos: Pos,
}

/// What a gamepad axis adds to its shaped value.
#[derive(Debug, Clone, PartialEq)]
pub enum Offset {
    /// A constant.
    Number(f64),
    /// The current value of a field of a topic: `(topic, field)`.
    Binding(String, String),
}

/// A gamepad axis driving a command's field.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisBinding {
    /// The axis index in the Gamepad API.
    pub index: usize,
    /// The command it drives.
    pub command: String,
    /// The field it sets.
    pub field: String,
    /// Readings below this magnitude count as 0 (0 to 1).
    pub deadband: f64,
    /// How cubic the response is (0 to 1).
    pub expo: f64,
    /// The factor after shaping.
    pub gain: f64,
    /// What is added after the gain.
    pub offset: Offset,
    /// Where it is written.
    pub pos: Pos,
}

/// A gamepad button sending a command once per press.
#[derive(Debug, Clone, PartialEq)]
pub struct PadButton {
    /// The button index in the Gamepad API.
    pub index: usize,
    /// The command it sends.
    pub command: String,
    /// Where it is written.
    pub pos: Pos,
}

/// A parsed layout: one page of the console.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Its name.
    pub name: String,
    /// Its title (the name when the file gives none).
    pub title: String,
    /// The roles it is shown to (empty: everyone).
    pub roles: Vec<String>,
    /// Its variables with the values used.
    pub vars: BTreeMap<String, String>,
    /// Its commands by name.
    pub commands: BTreeMap<String, CommandDecl>,
    /// The widget tree (a `column` around them when the layout has several top-level widgets).
    pub root: Node,
    /// Keyboard bindings.
    pub keys: Vec<KeyBinding>,
    /// Gamepad axes.
    pub axes: Vec<AxisBinding>,
    /// Gamepad buttons.
    pub buttons: Vec<PadButton>,
    /// The file it was read from.
    pub file: String,
}

impl Layout {
    /// Parses layout text; `vars` override the `<var>` defaults (unknown names are ignored).
    /// `${name}` is substituted in every attribute, and `<use>` replaced by its template's
    /// widgets, with the `<use>`'s attributes as the template's parameters.
    pub fn parse(
        file: &str,
        text: &str,
        vars: &BTreeMap<String, String>,
    ) -> Result<Layout, FileError> {
        let root = xml::parse(file, text)?;
        Reader::layout(&root, vars)
    }

    /// Reads and parses a layout file.
    pub fn load(path: &Path, vars: &BTreeMap<String, String>) -> Result<Layout, FileError> {
        let root = xml::parse_file(path)?;
        Reader::layout(&root, vars)
    }

    /// The widget with id `id`.
    pub fn widget(&self, id: &str) -> Option<&Node> {
        self.root.walk().into_iter().find(|n| n.id == id)
    }

    /// Whether a user with `roles` sees this layout.
    pub fn visible_to(&self, roles: &[String]) -> bool {
        self.roles.is_empty() || roles.iter().any(|r| self.roles.contains(r))
    }

    /// Number of widgets (containers and plot series not counted).
    pub fn widget_count(&self) -> usize {
        self.root
            .walk()
            .iter()
            .filter(|n| !CONTAINERS.contains(&n.kind.as_str()) && n.kind != "tab")
            .filter(|n| n.kind != "series")
            .count()
    }

    /// Every displayed variable: readouts, gauges, plot series, the track's position and heading,
    /// health tables, log topics (as patterns) and gamepad axis offsets.
    pub fn bindings(&self) -> Vec<Binding> {
        let mut out = Vec::new();
        let mut add = |topic: &str, field: Option<&str>, fresh: Duration, node: &Node| {
            out.push(Binding {
                topic: topic.to_string(),
                field: field.map(str::to_string),
                fresh,
                widget: node.id.clone(),
                pos: node.pos.clone(),
            });
        };
        for node in self.root.walk() {
            let fresh = node.fresh();
            match node.kind.as_str() {
                "readout" | "gauge" => {
                    if let Some((t, f)) = node.attrs.get("bind").and_then(|b| b.rsplit_once('.')) {
                        add(t, Some(f), fresh, node);
                    }
                }
                "plot" => {
                    for s in &node.children {
                        if let Some((t, f)) = s.attrs.get("bind").and_then(|b| b.rsplit_once('.')) {
                            add(t, Some(f), fresh, s);
                        }
                    }
                }
                "track" => {
                    if let Some(p) = node.attrs.get("position") {
                        add(p.trim(), None, fresh, node);
                    }
                    if let Some((t, f)) = node.attrs.get("heading").and_then(|b| b.rsplit_once('.'))
                    {
                        add(t, Some(f), fresh, node);
                    }
                }
                "health" => {
                    let topic = node.attrs.get("bind").map_or(DEFAULT_HEALTH, |b| b.trim());
                    add(topic, None, fresh, node);
                }
                "log" => {
                    let topics = node
                        .attrs
                        .get("topics")
                        .map_or(DEFAULT_LOG_TOPICS, String::as_str);
                    for t in list(topics) {
                        add(t, None, fresh, node);
                    }
                }
                _ => {}
            }
        }
        for a in &self.axes {
            if let Offset::Binding(topic, field) = &a.offset {
                out.push(Binding {
                    topic: topic.clone(),
                    field: Some(field.clone()),
                    fresh: DEFAULT_FRESH,
                    widget: format!("axis-{}", a.index),
                    pos: a.pos.clone(),
                });
            }
        }
        out
    }

    /// Compares the layout with a system: a warning (`warning: …`) for each binding whose topic no
    /// module produces on the console's medium (directly, or through a bridge route into it) or
    /// whose field no producer declares, and for each command no module accepts (on that medium,
    /// or one route away). The console's medium is the `<console medium>` of the system, or its
    /// first medium.
    pub fn check(
        &self,
        spec: &SystemSpec,
        registry: &Registry,
        catalogue: &Catalogue,
    ) -> Vec<FileError> {
        let console = spec
            .sections("console")
            .find_map(|e| e.get("medium"))
            .map(str::trim)
            .or_else(|| spec.media.first().map(|m| m.name.as_str()))
            .unwrap_or_default();
        let produced = producers(spec, registry, catalogue, console);
        let mut accepted: Vec<(&str, Pattern)> = Vec::new();
        for m in &spec.modules {
            let Ok(built) = registry.build_module(m, catalogue) else {
                continue;
            };
            for t in &built.decl.accepts {
                if let (Some(medium), Ok(p)) = (m.media.get(t.port), Pattern::new(&t.topic)) {
                    accepted.push((medium.as_str(), p));
                }
            }
        }
        let legs = || route_legs(spec);
        let mut warnings = Vec::new();
        for b in self.bindings() {
            let Ok(pattern) = Pattern::new(&b.topic) else {
                continue;
            };
            let matching: Vec<&Producer> = produced
                .iter()
                .filter(|p| p.pattern.overlaps(&pattern))
                .collect();
            if matching.is_empty() {
                warnings.push(b.pos.error(format!(
                    "warning: no module of {} produces `{}` on medium `{console}` (widget `{}`)",
                    spec.file, b.topic, b.widget
                )));
                continue;
            }
            let Some(field) = &b.field else { continue };
            let declared: Option<BTreeSet<&String>> = matching
                .iter()
                .map(|p| p.fields.as_ref())
                .try_fold(BTreeSet::new(), |mut all, f| {
                    all.extend(f?);
                    Some(all)
                });
            if let Some(declared) = declared.filter(|d| !d.contains(field)) {
                let names: Vec<&str> = declared.iter().map(|s| s.as_str()).collect();
                warnings.push(b.pos.error(format!(
                    "warning: `{}` has no field `{field}` (widget `{}`); its fields: {}",
                    b.topic,
                    b.widget,
                    names.join(", ")
                )));
            }
        }
        let accepts = |medium: &str, topic: &str| {
            accepted
                .iter()
                .any(|(m, p)| *m == medium && p.matches(topic))
        };
        for c in self.commands.values() {
            let topic = c.topic.as_str();
            let through_bridge = legs().any(|(from, to, r)| {
                if from != console || r.kind == Some(Kind::Data) || !r.topics.matches(topic) {
                    return false;
                }
                let out = match &r.rename {
                    Some(rename) => r.topics.captures(topic).and_then(|c| rename.fill(&c)),
                    None => Some(topic.to_string()),
                };
                out.is_some_and(|t| accepts(to, &t))
            });
            if !accepts(console, topic) && !through_bridge {
                warnings.push(c.pos.error(format!(
                    "warning: no module of {} accepts command `{}` on `{topic}`",
                    spec.file, c.name
                )));
            }
        }
        warnings
    }

    /// The layout as the page reads it (the JSON form in `docs/console.md`).
    pub fn to_json(&self) -> Json {
        let commands: Map<String, Json> = self
            .commands
            .values()
            .map(|c| {
                let (confirm, hold) = match c.confirm {
                    Confirm::None => ("none", None),
                    Confirm::Dialog => ("dialog", None),
                    Confirm::Hold(d) => ("hold", Some(d.as_millis() as u64)),
                };
                let bounds = |m: &BTreeMap<String, f64>| -> Map<String, Json> {
                    m.iter().map(|(k, v)| (k.clone(), number(*v))).collect()
                };
                let body = json!({
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
                });
                (c.name.clone(), body)
            })
            .collect();
        let keys: Vec<Json> = self
            .keys
            .iter()
            .map(|k| {
                json!({
                    "key": k.key,
                    "command": k.command,
                    "field": k.field,
                    "value": k.value.as_ref().map(value_json),
                    "step": k.step,
                })
            })
            .collect();
        let axes: Vec<Json> = self
            .axes
            .iter()
            .map(|a| {
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
            })
            .collect();
        let buttons: Vec<Json> = self
            .buttons
            .iter()
            .map(|b| json!({"index": b.index, "command": b.command}))
            .collect();
        json!({
            "name": self.name,
            "title": self.title,
            "roles": self.roles,
            "vars": self.vars,
            "commands": commands,
            "root": node_json(&self.root),
            "keys": keys,
            "gamepad": {"axes": axes, "buttons": buttons},
        })
    }
}

/// What puts a topic on the console's medium: a module's declaration or a bridge route into it.
#[derive(Debug, Clone)]
pub struct Producer {
    /// The topics.
    pub pattern: Pattern,
    /// The fields it declares; `None` when unknown.
    pub fields: Option<BTreeSet<String>>,
}

/// Every route leg of a system's bridges: (from medium, to medium, route).
fn route_legs(spec: &SystemSpec) -> impl Iterator<Item = (&str, &str, &RouteSpec)> {
    spec.bridges.iter().flat_map(|b| {
        b.routes.iter().flat_map(move |r| {
            r.legs(&b.media[0], &b.media[1])
                .into_iter()
                .map(move |(from, to)| (from, to, r))
        })
    })
}

/// What produces topics on `medium`: the modules that declare them there, and the bridge routes
/// that bring data into it.
pub fn producers(
    spec: &SystemSpec,
    registry: &Registry,
    catalogue: &Catalogue,
    medium: &str,
) -> Vec<Producer> {
    let mut produced = Vec::new();
    for m in &spec.modules {
        let Ok(built) = registry.build_module(m, catalogue) else {
            continue;
        };
        for t in &built.decl.produces {
            if m.media.get(t.port).map(String::as_str) != Some(medium) {
                continue;
            }
            let Ok(pattern) = Pattern::new(&t.topic) else {
                continue;
            };
            let dataset = t.dataset.as_deref().and_then(|d| catalogue.get(d));
            let fields = (dataset.is_some() || !t.fields.is_empty()).then(|| {
                dataset
                    .iter()
                    .flat_map(|d| d.fields.iter().map(|f| f.name.clone()))
                    .chain(t.fields.iter().map(|f| f.name.clone()))
                    .collect()
            });
            produced.push(Producer { pattern, fields });
        }
    }
    for (_, to, r) in route_legs(spec) {
        if to == medium && r.kind != Some(Kind::Command) {
            produced.push(Producer {
                pattern: r.out_pattern().clone(),
                fields: None,
            });
        }
    }
    produced
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
        let (key, v) = match name.as_str() {
            "bind" if node.kind == "health" => ("bind", json!({"topic": value.trim()})),
            "bind" | "heading" => (name.as_str(), bind_json(value)),
            "fresh" => ("fresh_ms", duration_json(value)),
            "window" => ("window_ms", duration_json(value)),
            "min" | "max" | "step" | "precision" | "trail" | "lines" | "columns" => {
                (name.as_str(), number_text(value))
            }
            "sizes" => (
                "sizes",
                Json::Array(value.split_whitespace().map(number_text).collect()),
            ),
            "ranges" => (
                "ranges",
                Json::Array(
                    list_items(value, ',')
                        .filter_map(|r| {
                            let mut p = r.splitn(3, ':');
                            let (from, to, colour) = (p.next()?, p.next()?, p.next()?);
                            Some(json!({"from": number_text(from), "to": number_text(to), "colour": colour.trim()}))
                        })
                        .collect(),
                ),
            ),
            "waypoints" => (
                "waypoints",
                Json::Array(
                    list_items(value, ';')
                        .filter_map(|w| {
                            let (lat, lon) = w.split_once(',')?;
                            Some(json!([number_text(lat), number_text(lon)]))
                        })
                        .collect(),
                ),
            ),
            "grid" if value.trim() == "auto" => ("grid", Json::from("auto")),
            "grid" => ("grid", number_text(value)),
            "topics" => ("topics", json!(list(value))),
            "set" => (
                "set",
                field_list(value).map_or(Json::Null, |m| map_json(&m)),
            ),
            "on" | "off" => (name.as_str(), value_json(&field_value(value.trim()))),
            "command" => {
                let (command, field) = node.command().unwrap_or_default();
                o.insert("field".into(), json!(field));
                ("command", Json::from(command))
            }
            _ => (name.as_str(), Json::from(value.as_str())),
        };
        o.insert(key.to_string(), v);
    }
    let defaults: &[(&str, Json)] = match node.kind.as_str() {
        "health" => &[("bind", json!({"topic": DEFAULT_HEALTH}))],
        "log" => &[
            ("topics", json!(list(DEFAULT_LOG_TOPICS))),
            ("lines", json!(200)),
        ],
        "history" => &[("lines", json!(200))],
        "plot" => &[("window_ms", json!(60_000))],
        _ => &[],
    };
    for (key, v) in defaults {
        o.entry(*key).or_insert_with(|| v.clone());
    }
    if OUTPUTS.contains(&node.kind.as_str()) {
        o.entry("fresh_ms")
            .or_insert_with(|| json!(DEFAULT_FRESH.as_millis() as u64));
    }
    if CONTAINERS.contains(&node.kind.as_str()) || node.kind == "tab" || node.kind == "plot" {
        o.insert(
            "children".into(),
            Json::Array(node.children.iter().map(node_json).collect()),
        );
    }
    if node.kind == "tabs" {
        let titles: Vec<&str> = node
            .children
            .iter()
            .map(|t| t.attrs.get("title").map_or("", String::as_str))
            .collect();
        o.insert("titles".into(), json!(titles));
    }
    Json::Object(o)
}

fn duration_json(text: &str) -> Json {
    parse_duration(text).map_or(Json::Null, |d| json!(d.as_millis() as u64))
}

/// The items of a list separated by `sep`, trimmed, empty ones left out.
fn list_items(text: &str, sep: char) -> impl Iterator<Item = &str> {
    text.split(sep).map(str::trim).filter(|s| !s.is_empty())
}

/// The words of a list separated by commas or blanks.
fn list(text: &str) -> Vec<&str> {
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .collect()
}

/// A field value as written: `true`/`false`, an integer (no point), a number, or text.
fn field_value(text: &str) -> Value {
    match text {
        "true" => return Value::Bool(true),
        "false" => return Value::Bool(false),
        _ => {}
    }
    let numeric = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '+' | '-' | '.' | 'e' | 'E'))
        && text.chars().any(|c| c.is_ascii_digit());
    if numeric {
        if let Ok(i) = text.parse::<i64>() {
            return Value::Int(i);
        }
        if let Some(f) = text.parse::<f64>().ok().filter(|f| f.is_finite()) {
            return Value::Float(f);
        }
    }
    Value::from(text)
}

/// `F=V, …` as a datamap in order, or the reason it does not read.
fn field_list(text: &str) -> Result<DataMap, String> {
    let mut items = Vec::new();
    let mut start = 0;
    let mut quoted = false;
    for (i, c) in text.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => {
                items.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    if quoted {
        return Err("a double quote `\"` is not closed".to_string());
    }
    items.push(&text[start..]);
    let mut map = DataMap::new();
    for item in items.into_iter().map(str::trim).filter(|s| !s.is_empty()) {
        let Some((name, value)) = item.split_once('=') else {
            return Err(format!("`{item}` is not FIELD=VALUE"));
        };
        let name = name.trim();
        if !is_name(name) {
            return Err(format!(
                "`{name}` is not a field name: use letters, digits, `_` and `-`"
            ));
        }
        if map.get(name).is_some() {
            return Err(format!("field `{name}` is given twice"));
        }
        let value = value.trim();
        let value = match value.strip_prefix('"') {
            Some(rest) => match rest.strip_suffix('"') {
                Some(inner) if !inner.contains('"') => Value::from(inner),
                _ => return Err(format!("`{value}` is not a quoted text (\"…\")")),
            },
            None if value.contains('"') => {
                return Err(format!("`{value}`: quote the whole value (\"…\")"));
            }
            None => field_value(value),
        };
        map.insert(name.to_string(), value);
    }
    Ok(map)
}

/// Letters, digits, `_` and `-`, not empty.
fn is_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

fn name_attr(a: &Attr, what: &str) -> Result<String, FileError> {
    let v = a.value.trim();
    if is_name(v) {
        Ok(v.to_string())
    } else {
        Err(a.error(format!(
            "`{v}` is not {what} name: use letters, digits, `_` and `-` (at most 64)"
        )))
    }
}

/// A finite number.
fn finite(a: &Attr) -> Result<f64, FileError> {
    a.value
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| a.error(format!("`{}` is not a number", a.value.trim())))
}

/// A whole number from `min` to `max`.
fn count(a: &Attr, min: u64, max: u64) -> Result<u64, FileError> {
    a.value
        .trim()
        .parse::<u64>()
        .ok()
        .filter(|n| (min..=max).contains(n))
        .ok_or_else(|| {
            a.error(format!(
                "`{}` is not a whole number from {min} to {max}",
                a.value.trim()
            ))
        })
}

/// A duration above zero.
fn duration(a: &Attr) -> Result<Duration, FileError> {
    parse_duration(&a.value)
        .filter(|d| !d.is_zero())
        .ok_or_else(|| {
            a.error(format!(
                "`{}` is not a duration (250ms, 2s, 1min)",
                a.value.trim()
            ))
        })
}

fn topic(a: &Attr, text: &str) -> Result<Topic, FileError> {
    Topic::new(text.trim()).map_err(|e| a.error(format!("`{}` is not a topic: {e}", text.trim())))
}

/// `topic.field`, split at the last dot.
fn bind(a: &Attr) -> Result<(Topic, String), FileError> {
    let text = a.value.trim();
    let Some((t, field)) = text.rsplit_once('.') else {
        return Err(a.error(format!(
            "`{text}` is not topic.field (the field is after the last dot: nav.depth.depth)"
        )));
    };
    if !is_name(field) {
        return Err(a.error(format!("`{field}` is not a field name in `{text}`")));
    }
    Ok((topic(a, t)?, field.to_string()))
}

fn colour(a: &Attr, text: &str) -> Result<(), FileError> {
    let t = text.trim();
    let hex = t.strip_prefix('#').is_some_and(|h| {
        (h.len() == 3 || h.len() == 6) && h.chars().all(|c| c.is_ascii_hexdigit())
    });
    if hex || COLOURS.contains(&t) {
        Ok(())
    } else {
        Err(a.error(format!(
            "`{t}` is not a colour: #rgb, #rrggbb or one of {}",
            COLOURS.join(", ")
        )))
    }
}

fn no_children(el: &Element) -> Result<(), FileError> {
    el.only_children(&[])
}

/// Checks `min` < `max` when both are given.
fn min_max(el: &Element) -> Result<(Option<f64>, Option<f64>), FileError> {
    let min = el.attr("min").map(finite).transpose()?;
    let max = el.attr("max").map(finite).transpose()?;
    if let (Some(lo), Some(hi), Some(a)) = (min, max, el.attr("max")) {
        if lo >= hi {
            return Err(a.error(format!("the maximum {hi} is not above the minimum {lo}")));
        }
    }
    Ok((min, max))
}

/// Substitutes variables and expands templates.
struct Expander<'a> {
    vars: &'a BTreeMap<String, String>,
    templates: BTreeMap<String, &'a Element>,
    /// The templates being expanded, outermost first.
    stack: Vec<String>,
    elements: usize,
    text: usize,
}

impl<'a> Expander<'a> {
    /// `a`'s value with every `${name}` replaced: from the innermost `<use>`'s attributes out,
    /// then the layout's variables.
    fn substitute(
        &mut self,
        a: &Attr,
        params: &[&BTreeMap<String, String>],
    ) -> Result<String, FileError> {
        let mut out = String::new();
        let mut rest = a.value.as_str();
        while let Some(i) = rest.find("${") {
            out.push_str(&rest[..i]);
            let after = &rest[i + 2..];
            let Some(j) = after.find('}') else {
                return Err(a.error("`${` is not closed by `}`"));
            };
            let name = after[..j].trim();
            let value = params
                .iter()
                .find_map(|p| p.get(name))
                .or_else(|| self.vars.get(name))
                .ok_or_else(|| {
                    a.error(format!(
                        "undefined variable `{name}`: declare it with <var name=\"{name}\" default=\"…\"/>{}",
                        if self.stack.is_empty() { "" } else { " or give it on the <use>" }
                    ))
                })?;
            out.push_str(value);
            rest = &after[j + 1..];
        }
        out.push_str(rest);
        self.text += out.len();
        if self.text > MAX_TEXT {
            return Err(a.error(format!(
                "the layout's attributes come to more than {MAX_TEXT} characters with variables substituted"
            )));
        }
        Ok(out)
    }

    fn attrs(
        &mut self,
        el: &Element,
        params: &[&BTreeMap<String, String>],
    ) -> Result<Vec<Attr>, FileError> {
        el.attrs
            .iter()
            .map(|a| {
                Ok(Attr {
                    name: a.name.clone(),
                    value: self.substitute(a, params)?,
                    pos: a.pos.clone(),
                })
            })
            .collect()
    }

    /// `el` with its attributes substituted and the templates inside expanded; a `<use>` becomes
    /// its template's elements.
    fn expand(
        &mut self,
        el: &Element,
        params: &[&BTreeMap<String, String>],
        depth: usize,
    ) -> Result<Vec<Element>, FileError> {
        if depth > xml::MAX_DEPTH {
            return Err(el.error(format!(
                "elements nested deeper than {} with the templates expanded",
                xml::MAX_DEPTH
            )));
        }
        self.elements += 1;
        if self.elements > MAX_ELEMENTS {
            return Err(el.error(format!(
                "the layout has more than {MAX_ELEMENTS} elements with the templates expanded"
            )));
        }
        let attrs = self.attrs(el, params)?;
        if el.name == "use" {
            el.only_children(&[])?;
            let Some(name_at) = attrs.iter().find(|a| a.name == "template").cloned() else {
                return Err(el.error("<use> is missing attribute `template`"));
            };
            let name = name_at.value.trim();
            let Some(template) = self.templates.get(name).copied() else {
                let known: Vec<&str> = self.templates.keys().map(String::as_str).collect();
                return Err(name_at.error(format!(
                    "no template called `{name}`; templates: {}",
                    if known.is_empty() {
                        "none".to_string()
                    } else {
                        known.join(", ")
                    }
                )));
            };
            if self.stack.iter().any(|t| t == name) {
                let chain: Vec<&str> = self
                    .stack
                    .iter()
                    .map(String::as_str)
                    .skip_while(|t| *t != name)
                    .chain([name])
                    .collect();
                return Err(name_at.error(format!(
                    "template `{name}` uses itself: {}",
                    chain.join(" → ")
                )));
            }
            if self.stack.len() >= MAX_TEMPLATE_DEPTH {
                return Err(name_at.error(format!(
                    "templates used inside templates deeper than {MAX_TEMPLATE_DEPTH}"
                )));
            }
            let own: BTreeMap<String, String> = attrs
                .into_iter()
                .filter(|a| a.name != "template")
                .map(|a| (a.name, a.value))
                .collect();
            let mut scope = vec![&own];
            scope.extend(params.iter().copied());
            self.stack.push(name.to_string());
            let mut out = Vec::new();
            for c in &template.children {
                out.extend(self.expand(c, &scope, depth)?);
            }
            self.stack.pop();
            return Ok(out);
        }
        let mut children = Vec::new();
        for c in &el.children {
            children.extend(self.expand(c, params, depth + 1)?);
        }
        Ok(vec![Element {
            name: el.name.clone(),
            attrs,
            children,
            text: String::new(),
            pos: el.pos.clone(),
        }])
    }
}

/// Reads an expanded layout.
struct Reader {
    commands: BTreeMap<String, CommandDecl>,
    /// Ids the file gives, and where.
    ids: BTreeMap<String, Pos>,
}

impl Reader {
    fn layout(root: &Element, given: &BTreeMap<String, String>) -> Result<Layout, FileError> {
        if root.name != "layout" {
            return Err(root.error(format!(
                "root element is <{}>, expected <layout>",
                root.name
            )));
        }
        root.only_attrs(&["name", "title", "roles"])?;
        let mut vars = BTreeMap::new();
        let mut templates = BTreeMap::new();
        for el in &root.children {
            match el.name.as_str() {
                "var" => {
                    el.only_attrs(&["name", "default"])?;
                    no_children(el)?;
                    let at = el.required("name")?;
                    let name = name_attr(at, "a variable")?;
                    if vars.contains_key(&name) {
                        return Err(at.error(format!("variable `{name}` is declared twice")));
                    }
                    let value = given
                        .get(&name)
                        .cloned()
                        .unwrap_or_else(|| el.get("default").unwrap_or_default().to_string());
                    vars.insert(name, value);
                }
                "template" => {
                    el.only_attrs(&["name"])?;
                    let at = el.required("name")?;
                    let name = name_attr(at, "a template")?;
                    if templates.insert(name.clone(), el).is_some() {
                        return Err(at.error(format!("template `{name}` is defined twice")));
                    }
                }
                _ => {}
            }
        }
        let known: Vec<&str> = TOP.iter().copied().chain(widget_kinds()).collect();
        root.only_children(&known)?;
        let mut ex = Expander {
            vars: &vars,
            templates,
            stack: Vec::new(),
            elements: 0,
            text: 0,
        };
        let top = ex.attrs(root, &[])?;
        let get = |n: &str| top.iter().find(|a| a.name == n);
        let name = match get("name") {
            Some(a) => name_attr(a, "a layout")?,
            None => return Err(root.error("<layout> is missing attribute `name`")),
        };
        let title = get("title").map_or_else(|| name.clone(), |a| a.value.trim().to_string());
        let roles = match get("roles") {
            Some(a) => roles(a)?,
            None => Vec::new(),
        };
        let mut children = Vec::new();
        for el in &root.children {
            if el.name != "var" && el.name != "template" {
                children.extend(ex.expand(el, &[], 1)?);
            }
        }
        let mut reader = Reader {
            commands: BTreeMap::new(),
            ids: BTreeMap::new(),
        };
        for el in children.iter().filter(|e| e.name == "command") {
            let c = command(el)?;
            if let Some(prev) = reader.commands.get(&c.name) {
                return Err(el.error(format!(
                    "command `{}` is already declared at line {}",
                    c.name, prev.pos.line
                )));
            }
            reader.commands.insert(c.name.clone(), c);
        }
        let mut widgets = Vec::new();
        let mut keys = Vec::new();
        let mut axes = Vec::new();
        let mut buttons = Vec::new();
        let kinds = widget_kinds();
        for el in &children {
            match el.name.as_str() {
                "command" => {}
                "keys" => {
                    el.only_attrs(&[])?;
                    el.only_children(&["key"])?;
                    for k in &el.children {
                        keys.push(reader.key(k)?);
                    }
                }
                "gamepad" => {
                    el.only_attrs(&[])?;
                    el.only_children(&["axis", "button"])?;
                    for c in &el.children {
                        if c.name == "axis" {
                            axes.push(reader.axis(c)?);
                        } else {
                            buttons.push(reader.pad_button(c)?);
                        }
                    }
                }
                k if kinds.contains(&k) => widgets.push(reader.node(el)?),
                _ => {
                    return Err(el.error(format!(
                        "unexpected element <{}> inside <layout>; expected {}",
                        el.name,
                        known
                            .iter()
                            .map(|k| format!("<{k}>"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )));
                }
            }
        }
        let mut root_node = if widgets.len() == 1 {
            widgets.remove(0)
        } else {
            Node {
                kind: "column".to_string(),
                id: String::new(),
                label: None,
                role: None,
                attrs: BTreeMap::new(),
                children: widgets,
                pos: root.pos.clone(),
            }
        };
        reader.assign_ids(&mut root_node);
        Ok(Layout {
            name,
            title,
            roles,
            vars,
            commands: reader.commands,
            root: root_node,
            keys,
            axes,
            buttons,
            file: root.pos.file.to_string(),
        })
    }

    /// Gives every node without an id `KIND-N`, N counting nodes of that kind in document order
    /// and skipping ids the file gives.
    fn assign_ids(&mut self, root: &mut Node) {
        let mut counters: BTreeMap<String, usize> = BTreeMap::new();
        let mut stack = vec![root];
        while let Some(node) = stack.pop() {
            if node.id.is_empty() {
                let n = counters.entry(node.kind.clone()).or_insert(0);
                loop {
                    *n += 1;
                    let id = format!("{}-{n}", node.kind);
                    if !self.ids.contains_key(&id) {
                        self.ids.insert(id.clone(), node.pos.clone());
                        node.id = id;
                        break;
                    }
                }
            }
            stack.extend(node.children.iter_mut().rev());
        }
    }

    /// The command a `command` attribute names, and its field; `field` says whether one is needed.
    fn command_ref(
        &self,
        a: &Attr,
        field: Option<bool>,
    ) -> Result<(String, Option<String>), FileError> {
        let text = a.value.trim();
        let (name, f) = match text.split_once('.') {
            Some((n, f)) => (n, Some(f)),
            None => (text, None),
        };
        let Some(c) = self.commands.get(name) else {
            let known: Vec<&str> = self.commands.keys().map(String::as_str).collect();
            return Err(a.error(format!(
                "no command called `{name}`; commands: {}",
                if known.is_empty() {
                    "none (declare one with <command>)".to_string()
                } else {
                    known.join(", ")
                }
            )));
        };
        match (f, field) {
            (Some(f), Some(false)) => Err(a.error(format!(
                "sends command `{name}` as a whole: write `{name}`, not `{name}.{f}`"
            ))),
            (None, Some(true)) => Err(a.error(format!(
                "sets a field: write `{name}.FIELD`; fields of `{name}`: {}",
                field_names(&c.fields)
            ))),
            (Some(f), _) if c.fields.get(f).is_none() => Err(a.error(format!(
                "command `{name}` has no field `{f}`; fields: {}",
                field_names(&c.fields)
            ))),
            _ => Ok((name.to_string(), f.map(str::to_string))),
        }
    }

    /// The default value of field `field` of command `name`.
    fn default_of(&self, name: &str, field: &str) -> Option<&Value> {
        self.commands.get(name)?.fields.get(field)
    }

    fn numeric_field(&self, a: &Attr, name: &str, field: &str) -> Result<(), FileError> {
        match self.default_of(name, field) {
            Some(Value::Int(_) | Value::Float(_)) | None => Ok(()),
            Some(v) => Err(a.error(format!(
                "field `{field}` of command `{name}` is {}, not a number",
                article(v.type_name())
            ))),
        }
    }

    fn node(&mut self, el: &Element) -> Result<Node, FileError> {
        let kind = el.name.as_str();
        let Some(own) = kind_attrs(kind) else {
            return Err(el.error(format!("unknown widget <{kind}>")));
        };
        let common: &[&str] = if kind == "series" {
            &["id", "label"]
        } else {
            &["id", "label", "role"]
        };
        let known: Vec<&str> = common.iter().chain(own).copied().collect();
        el.only_attrs(&known)?;
        let mut node = Node {
            kind: kind.to_string(),
            id: String::new(),
            label: el.get("label").map(str::to_string),
            role: None,
            attrs: BTreeMap::new(),
            children: Vec::new(),
            pos: el.pos.clone(),
        };
        if let Some(a) = el.attr("id") {
            let id = a.value.trim();
            if id.is_empty()
                || id.len() > 64
                || id.chars().any(|c| c.is_whitespace() || c.is_control())
            {
                return Err(a.error(format!(
                    "`{id}` is not an id: no blanks, at most 64 characters"
                )));
            }
            if let Some(prev) = self.ids.get(id) {
                return Err(a.error(format!("id `{id}` is already used at line {}", prev.line)));
            }
            self.ids.insert(id.to_string(), a.pos.clone());
            node.id = id.to_string();
        }
        if let Some(a) = el.attr("role") {
            node.role = Some(name_attr(a, "a role")?);
        }
        for a in &el.attrs {
            if !common.contains(&a.name.as_str()) {
                node.attrs.insert(a.name.clone(), a.value.clone());
            }
        }
        if let Some(a) = el.attr("fresh") {
            duration(a)?;
        }
        let required = |name: &str| el.required(name);
        match kind {
            "row" | "column" | "grid" | "tab" => {
                el.only_children(&widget_kinds())?;
                for c in &el.children {
                    node.children.push(self.node(c)?);
                }
                if let Some(a) = el.attr("sizes") {
                    let mut n = 0;
                    for s in a.value.split_whitespace() {
                        n += 1;
                        if !s.parse::<f64>().is_ok_and(|x| x.is_finite() && x > 0.0) {
                            return Err(a.error(format!("`{s}` is not a size (a number above 0)")));
                        }
                    }
                    if n != el.children.len() {
                        return Err(a.error(format!(
                            "{n} sizes for {} children; give one size per child",
                            el.children.len()
                        )));
                    }
                }
                if let Some(a) = el.attr("columns") {
                    count(a, 1, 64)?;
                }
                if kind == "tab" {
                    required("title")?;
                }
            }
            "tabs" => {
                el.only_children(&["tab"])?;
                for c in &el.children {
                    node.children.push(self.node(c)?);
                }
            }
            "readout" | "gauge" => {
                no_children(el)?;
                bind(required("bind")?)?;
                if let Some(a) = el.attr("precision") {
                    count(a, 0, 15)?;
                }
                let (min, max) = min_max(el)?;
                if let Some(a) = el.attr("ranges") {
                    for r in list_items(&a.value, ',') {
                        let parts: Vec<&str> = r.splitn(3, ':').collect();
                        let [from, to, c] = parts[..] else {
                            return Err(a.error(format!("`{r}` is not FROM:TO:COLOUR")));
                        };
                        let num = |s: &str| s.trim().parse::<f64>().ok().filter(|x| x.is_finite());
                        let (Some(from), Some(to)) = (num(from), num(to)) else {
                            return Err(a.error(format!(
                                "`{r}` is not FROM:TO:COLOUR with numbers FROM and TO"
                            )));
                        };
                        if from >= to {
                            return Err(a.error(format!("range `{r}`: {to} is not above {from}")));
                        }
                        if min.is_some_and(|m| from < m) || max.is_some_and(|m| to > m) {
                            return Err(a.error(format!("range `{r}` is outside min–max")));
                        }
                        colour(a, c)?;
                    }
                }
            }
            "plot" => {
                el.only_children(&["series"])?;
                if el.children.is_empty() {
                    return Err(
                        el.error("a <plot> needs at least one <series bind=\"topic.field\"/>")
                    );
                }
                for c in &el.children {
                    node.children.push(self.node(c)?);
                }
                if let Some(a) = el.attr("window") {
                    duration(a)?;
                }
                min_max(el)?;
            }
            "series" => {
                no_children(el)?;
                bind(required("bind")?)?;
                if let Some(a) = el.attr("colour") {
                    colour(a, &a.value)?;
                }
            }
            "track" => {
                no_children(el)?;
                let a = required("position")?;
                topic(a, &a.value)?;
                if let Some(a) = el.attr("heading") {
                    bind(a)?;
                }
                if let Some(a) = el.attr("trail") {
                    count(a, 1, 1_000_000)?;
                }
                if let Some(a) = el.attr("waypoints") {
                    for w in list_items(&a.value, ';') {
                        let ll = w.split_once(',').and_then(|(lat, lon)| {
                            let lat = lat
                                .trim()
                                .parse::<f64>()
                                .ok()
                                .filter(|x| (-90.0..=90.0).contains(x))?;
                            let lon = lon
                                .trim()
                                .parse::<f64>()
                                .ok()
                                .filter(|x| (-180.0..=180.0).contains(x))?;
                            Some((lat, lon))
                        });
                        if ll.is_none() {
                            return Err(a.error(format!(
                                "`{w}` is not LAT,LON (degrees, latitude −90 to 90, longitude −180 to 180)"
                            )));
                        }
                    }
                }
                if let Some(a) = el.attr("grid") {
                    let g = a.value.trim();
                    if g != "auto" && !g.parse::<f64>().is_ok_and(|x| x.is_finite() && x > 0.0) {
                        return Err(a.error(format!(
                            "`{g}` is not a grid spacing in metres (above 0) or `auto`"
                        )));
                    }
                }
            }
            "health" => {
                no_children(el)?;
                if let Some(a) = el.attr("bind") {
                    topic(a, &a.value)?;
                }
            }
            "log" | "history" => {
                no_children(el)?;
                if let Some(a) = el.attr("topics") {
                    for t in list(&a.value) {
                        Pattern::new(t)
                            .map_err(|e| a.error(format!("`{t}` is not a topic pattern: {e}")))?;
                    }
                }
                if let Some(a) = el.attr("lines") {
                    count(a, 1, 100_000)?;
                }
            }
            "button" => {
                no_children(el)?;
                let (name, _) = self.command_ref(required("command")?, Some(false))?;
                if let Some(a) = el.attr("set") {
                    let set = field_list(&a.value).map_err(|e| a.error(e))?;
                    if let Some(c) = self.commands.get(&name) {
                        for (f, v) in set.iter() {
                            c.fit(f, v).map_err(|e| a.error(e))?;
                        }
                    }
                }
            }
            "slider" | "number" => {
                no_children(el)?;
                let a = required("command")?;
                let (name, field) = self.command_ref(a, Some(true))?;
                self.numeric_field(a, &name, field.as_deref().unwrap_or_default())?;
                min_max(el)?;
                if let Some(a) = el.attr("step") {
                    if !finite(a).is_ok_and(|s| s > 0.0) {
                        return Err(a.error(format!(
                            "`{}` is not a step (a number above 0)",
                            a.value.trim()
                        )));
                    }
                }
            }
            "text" => {
                no_children(el)?;
                let a = required("command")?;
                let (name, field) = self.command_ref(a, Some(true))?;
                let field = field.unwrap_or_default();
                if let Some(v) = self
                    .default_of(&name, &field)
                    .filter(|v| !matches!(v, Value::Str(_)))
                {
                    return Err(a.error(format!(
                        "<text> sets text; field `{field}` of command `{name}` is {}",
                        article(v.type_name())
                    )));
                }
            }
            "toggle" => {
                no_children(el)?;
                let a = required("command")?;
                let (name, field) = self.command_ref(a, Some(true))?;
                let field = field.unwrap_or_default();
                if let Some(c) = self.commands.get(&name) {
                    for (which, default) in [("on", "true"), ("off", "false")] {
                        let at = el.attr(which).unwrap_or(a);
                        let v = field_value(el.get(which).map_or(default, str::trim));
                        c.fit(&field, &v).map_err(|e| at.error(e))?;
                    }
                }
            }
            _ => return Err(el.error(format!("unknown widget <{kind}>"))),
        }
        Ok(node)
    }

    fn key(&self, el: &Element) -> Result<KeyBinding, FileError> {
        el.only_attrs(&["key", "command", "value", "step"])?;
        no_children(el)?;
        let k = el.required("key")?;
        if k.value.is_empty() {
            return Err(k.error("empty; give a KeyboardEvent.key such as `w`, `ArrowLeft` or ` `"));
        }
        let a = el.required("command")?;
        let (command, field) = self.command_ref(a, None)?;
        let value_at = el.attr("value");
        let step_at = el.attr("step");
        let mut value = None;
        let mut step = None;
        match (&field, value_at, step_at) {
            (_, Some(v), Some(_)) => {
                return Err(v.error("give `value` (held) or `step` (each press), not both"));
            }
            (None, Some(x), _) | (None, _, Some(x)) => {
                return Err(x.error(format!(
                    "`{}` needs a field: write command=\"{command}.FIELD\"",
                    x.name
                )));
            }
            (Some(f), None, None) => {
                return Err(el.error(format!(
                    "<key> setting `{command}.{f}` needs `value` (held) or `step` (each press)"
                )));
            }
            (Some(f), Some(v), None) => {
                let parsed = field_value(v.value.trim());
                if let Some(c) = self.commands.get(&command) {
                    value = Some(c.fit(f, &parsed).map_err(|e| v.error(e))?);
                }
            }
            (Some(f), None, Some(s)) => {
                self.numeric_field(s, &command, f)?;
                step = Some(finite(s)?);
            }
            (None, None, None) => {}
        }
        Ok(KeyBinding {
            key: k.value.clone(),
            command,
            field,
            value,
            step,
            pos: el.pos.clone(),
        })
    }

    fn axis(&self, el: &Element) -> Result<AxisBinding, FileError> {
        el.only_attrs(&["index", "command", "deadband", "expo", "gain", "offset"])?;
        no_children(el)?;
        let index = count(el.required("index")?, 0, 255)? as usize;
        let a = el.required("command")?;
        let (command, field) = self.command_ref(a, Some(true))?;
        let field = field.unwrap_or_default();
        self.numeric_field(a, &command, &field)?;
        let unit = |name: &str, default: f64| -> Result<f64, FileError> {
            match el.attr(name) {
                None => Ok(default),
                Some(a) => {
                    let x = finite(a)?;
                    if (0.0..1.0).contains(&x) {
                        Ok(x)
                    } else {
                        Err(a.error(format!(
                            "`{}` is not from 0 up to (not including) 1",
                            a.value.trim()
                        )))
                    }
                }
            }
        };
        let deadband = unit("deadband", 0.1)?;
        let expo = unit("expo", 0.0)?;
        let gain = el.attr("gain").map(finite).transpose()?.unwrap_or(1.0);
        let offset = match el.attr("offset") {
            None => Offset::Number(0.0),
            Some(a) => match a.value.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Offset::Number(x),
                _ => {
                    let (t, f) = bind(a)?;
                    Offset::Binding(t.as_str().to_string(), f)
                }
            },
        };
        Ok(AxisBinding {
            index,
            command,
            field,
            deadband,
            expo,
            gain,
            offset,
            pos: el.pos.clone(),
        })
    }

    fn pad_button(&self, el: &Element) -> Result<PadButton, FileError> {
        el.only_attrs(&["index", "command"])?;
        no_children(el)?;
        let index = count(el.required("index")?, 0, 255)? as usize;
        let (command, _) = self.command_ref(el.required("command")?, Some(false))?;
        Ok(PadButton {
            index,
            command,
            pos: el.pos.clone(),
        })
    }
}

fn roles(a: &Attr) -> Result<Vec<String>, FileError> {
    let mut out: Vec<String> = Vec::new();
    for r in a.value.split_whitespace() {
        if !is_name(r) {
            return Err(a.error(format!(
                "`{r}` is not a role name: use letters, digits, `_` and `-`"
            )));
        }
        if !out.iter().any(|x| x == r) {
            out.push(r.to_string());
        }
    }
    Ok(out)
}

/// Reads a `<command>`.
fn command(el: &Element) -> Result<CommandDecl, FileError> {
    const KNOWN: [&str; 9] = [
        "name", "topic", "fields", "role", "confirm", "hold", "rate", "neutral", "lease",
    ];
    no_children(el)?;
    for a in &el.attrs {
        let bound = a
            .name
            .strip_prefix("min.")
            .or_else(|| a.name.strip_prefix("max."))
            .is_some();
        if !bound && !KNOWN.contains(&a.name.as_str()) {
            return Err(a.pos.error(format!(
                "unknown attribute `{}` on <command>; expected one of: {}, min.FIELD, max.FIELD",
                a.name,
                KNOWN.join(", ")
            )));
        }
    }
    let name = name_attr(el.required("name")?, "a command")?;
    let t = el.required("topic")?;
    let topic = topic(t, &t.value)?;
    let fields = match el.attr("fields") {
        Some(a) => field_list(&a.value).map_err(|e| a.error(e))?,
        None => DataMap::new(),
    };
    let role = el
        .attr("role")
        .map(|a| name_attr(a, "a role"))
        .transpose()?;
    let hold = el.attr("hold").map(duration).transpose()?;
    let confirm = match el.attr("confirm") {
        None => Confirm::None,
        Some(a) => match a.value.trim() {
            "none" => Confirm::None,
            "dialog" => Confirm::Dialog,
            "hold" => Confirm::Hold(hold.unwrap_or(DEFAULT_HOLD)),
            other => {
                return Err(a.error(format!(
                    "`{other}` is not a confirmation: none, dialog or hold"
                )));
            }
        },
    };
    if let (Some(a), false) = (el.attr("hold"), matches!(confirm, Confirm::Hold(_))) {
        return Err(
            a.error("`hold` is how long a confirm=\"hold\" button is held; add confirm=\"hold\"")
        );
    }
    let rate_hz = match el.attr("rate") {
        None => None,
        Some(a) => Some(
            parse_rate(&a.value)
                .map(|p| 1.0 / p.as_secs_f64())
                .filter(|hz| hz.is_finite())
                .ok_or_else(|| {
                    a.error(format!(
                        "`{}` is not a rate (5Hz, 5) or a period (200ms)",
                        a.value.trim()
                    ))
                })?,
        ),
    };
    let mut decl = CommandDecl {
        name,
        topic,
        fields,
        role,
        confirm,
        rate_hz,
        neutral: DataMap::new(),
        lease: el.flag("lease")?.unwrap_or(true),
        min: BTreeMap::new(),
        max: BTreeMap::new(),
        pos: el.pos.clone(),
    };
    for a in &el.attrs {
        let (bounds, field) = if let Some(f) = a.name.strip_prefix("min.") {
            (&mut decl.min, f)
        } else if let Some(f) = a.name.strip_prefix("max.") {
            (&mut decl.max, f)
        } else {
            continue;
        };
        match decl.fields.get(field) {
            None => {
                return Err(a.error(format!(
                    "command `{}` has no field `{field}`; fields: {}",
                    decl.name,
                    field_names(&decl.fields)
                )));
            }
            Some(Value::Int(_) | Value::Float(_)) => {}
            Some(v) => {
                return Err(a.error(format!(
                    "field `{field}` is {}, not a number",
                    article(v.type_name())
                )));
            }
        }
        bounds.insert(field.to_string(), finite(a)?);
    }
    for (f, lo) in &decl.min {
        if let Some(hi) = decl.max.get(f).filter(|hi| *hi <= lo) {
            let at = el
                .attr(&format!("max.{f}"))
                .unwrap_or(el.attrs.first().unwrap_or(t));
            return Err(at.error(format!(
                "the maximum {hi} of `{f}` is not above its minimum {lo}"
            )));
        }
    }
    for (f, v) in decl.fields.iter() {
        if let Err(e) = decl.fit(f, v) {
            let at = el.attr("fields").unwrap_or(t);
            return Err(at.error(format!("{e} (the initial value)")));
        }
    }
    if let Some(a) = el.attr("neutral") {
        if decl.rate_hz.is_none() {
            return Err(a.error(
                "`neutral` is sent when a dead-man command stops; give the command a `rate`",
            ));
        }
        let neutral = field_list(&a.value).map_err(|e| a.error(e))?;
        for (f, v) in neutral.iter() {
            let v = decl.fit(f, v).map_err(|e| a.error(e))?;
            decl.neutral.insert(f.to_string(), v);
        }
    }
    Ok(decl)
}

#[cfg(test)]
mod tests {
    use super::*;

    const EXAMPLE: &str = r#"<layout name="pilot" title="Pilot — ${vehicle}" roles="pilot designer">
  <var name="vehicle" default="iver"/>
  <command name="course" topic="cmd.course" fields="heading=0, depth=0, speed=0.0"
           rate="5Hz" neutral="speed=0" max.speed="2.5"/>
  <command name="start" topic="cmd.mission" fields="action=start, name=&quot;survey, north&quot;" confirm="hold"/>
  <command name="stop" topic="cmd.mission" fields="action=stop" confirm="dialog" lease="false"/>
  <template name="nav">
    <readout bind="nav.depth.depth" label="${what}" unit="m" precision="1"/>
  </template>
  <row sizes="2 1">
    <track position="nav.position" heading="nav.attitude.yaw" waypoints="43.5,16.4; 43.6,16.5" grid="50"/>
    <column>
      <use template="nav" what="Depth of ${vehicle}"/>
      <gauge id="speed" bind="nav.velocity.speed" min="0" max="3" ranges="0:2:green, 2:3:#f00" fresh="5s"/>
      <slider command="course.heading" min="0" max="359" step="1"/>
      <slider command="course.speed" min="0" max="2.5" step="0.1"/>
      <button command="start" label="Start"/>
      <button command="stop" set="action=stop"/>
      <log/>
    </column>
  </row>
  <keys>
    <key key="ArrowLeft" command="course.heading" step="-5"/>
    <key key="w" command="course.speed" value="1.5"/>
    <key key=" " command="stop"/>
  </keys>
  <gamepad>
    <axis index="1" command="course.speed" expo="0.5" gain="-2.5"/>
    <axis index="0" command="course.heading" deadband="0.15" gain="30" offset="nav.attitude.yaw"/>
    <button index="0" command="start"/>
  </gamepad>
</layout>
"#;

    fn parse(text: &str) -> Result<Layout, FileError> {
        Layout::parse("l.xml", text, &BTreeMap::new())
    }

    fn example() -> Layout {
        parse(EXAMPLE).unwrap()
    }

    /// The error `text` gives, as `LINE:COL: message`.
    fn error(text: &str) -> String {
        let e = parse(text).map(|_| ()).unwrap_err();
        let s = e.to_string();
        s.strip_prefix("l.xml:").unwrap_or(&s).to_string()
    }

    /// A layout with `body` inside, after a `course` command (line 2) and a `stop` command (line 3).
    fn with(body: &str) -> String {
        format!(
            "<layout name=\"t\">\n<command name=\"course\" topic=\"cmd.course\" fields=\"heading=0, speed=0.0, name=x, on=true\" max.heading=\"360\"/>\n<command name=\"stop\" topic=\"cmd.mission\" fields=\"action=stop\"/>\n{body}\n</layout>"
        )
    }

    #[test]
    fn the_documented_example_reads() {
        let l = example();
        assert_eq!(
            (l.name.as_str(), l.title.as_str()),
            ("pilot", "Pilot — iver")
        );
        assert_eq!(l.roles, ["pilot", "designer"]);
        assert_eq!(l.commands.len(), 3);
        let course = &l.commands["course"];
        assert_eq!(course.rate_hz, Some(5.0));
        assert_eq!(course.neutral.get("speed"), Some(&Value::Float(0.0)));
        assert_eq!(course.fields.get("heading"), Some(&Value::Int(0)));
        assert_eq!(
            l.commands["start"].fields.get_str("name"),
            Some("survey, north")
        );
        assert_eq!(l.commands["start"].confirm, Confirm::Hold(DEFAULT_HOLD));
        assert_eq!(l.commands["stop"].confirm, Confirm::Dialog);
        assert!(!l.commands["stop"].lease);
        assert_eq!(l.root.kind, "row");
        let ids: Vec<&str> = l.root.walk().iter().map(|n| n.id.as_str()).collect();
        assert_eq!(
            ids,
            [
                "row-1",
                "track-1",
                "column-1",
                "readout-1",
                "speed",
                "slider-1",
                "slider-2",
                "button-1",
                "button-2",
                "log-1"
            ]
        );
        assert_eq!(
            l.widget("slider-2").and_then(Node::command),
            Some(("course", Some("speed")))
        );
        assert_eq!(
            l.widget("button-1").and_then(Node::command),
            Some(("start", None))
        );
        assert_eq!(
            l.widget("readout-1").and_then(|n| n.label.as_deref()),
            Some("Depth of iver")
        );
        assert_eq!(l.keys[0].step, Some(-5.0));
        assert_eq!(l.keys[1].value, Some(Value::Float(1.5)));
        assert_eq!(
            (l.keys[2].key.as_str(), l.keys[2].field.as_ref()),
            (" ", None)
        );
        assert_eq!(l.axes[0].deadband, 0.1);
        assert_eq!(
            l.axes[1].offset,
            Offset::Binding("nav.attitude".into(), "yaw".into())
        );
        assert_eq!(l.buttons[0].command, "start");
        assert_eq!(l.widget_count(), 8);
    }

    #[test]
    fn bindings_cover_every_displayed_variable() {
        let got: Vec<(String, Option<String>, u128, String)> = example()
            .bindings()
            .into_iter()
            .map(|b| (b.topic, b.field, b.fresh.as_millis(), b.widget))
            .collect();
        let want = [
            ("nav.position", None, 2000, "track-1"),
            ("nav.attitude", Some("yaw"), 2000, "track-1"),
            ("nav.depth", Some("depth"), 2000, "readout-1"),
            ("nav.velocity", Some("speed"), 5000, "speed"),
            ("cmd.status", None, 2000, "log-1"),
            ("vehicle.state", None, 2000, "log-1"),
            ("nav.attitude", Some("yaw"), 2000, "axis-0"),
        ];
        let want: Vec<(String, Option<String>, u128, String)> = want
            .iter()
            .map(|(t, f, ms, w)| (t.to_string(), f.map(str::to_string), *ms, w.to_string()))
            .collect();
        assert_eq!(got, want);
    }

    #[test]
    fn vars_are_overridden_and_unknown_ones_ignored() {
        let vars: BTreeMap<String, String> = [("vehicle", "auv2"), ("other", "x")]
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let l = Layout::parse("l.xml", EXAMPLE, &vars).unwrap();
        assert_eq!(l.title, "Pilot — auv2");
        assert_eq!(l.vars.len(), 1);
        assert_eq!(l.vars["vehicle"], "auv2");
        assert_eq!(
            l.widget("readout-1").and_then(|n| n.label.as_deref()),
            Some("Depth of auv2")
        );
    }

    #[test]
    fn templates_take_their_parameters_and_nest() {
        let l = parse(
            r#"<layout name="t">
  <var name="v" default="outer"/>
  <template name="a"><readout bind="${topic}.x" label="${v}"/><use template="b" label="in ${topic}"/></template>
  <template name="b"><readout bind="c.d" label="${label}"/></template>
  <column><use template="a" topic="p.q"/><use template="a" topic="r" v="mine"/></column>
</layout>"#,
        )
        .unwrap();
        let got: Vec<(&str, Option<&str>)> = l
            .root
            .children
            .iter()
            .map(|n| (n.attrs["bind"].as_str(), n.label.as_deref()))
            .collect();
        assert_eq!(
            got,
            [
                ("p.q.x", Some("outer")),
                ("c.d", Some("in p.q")),
                ("r.x", Some("mine")),
                ("c.d", Some("in r")),
            ]
        );
    }

    #[test]
    fn templates_using_themselves_are_refused() {
        assert_eq!(
            error(
                "<layout name=\"t\">\n<template name=\"a\"><use template=\"a\"/></template>\n<use template=\"a\"/>\n</layout>"
            ),
            "2:25: attribute `template`: template `a` uses itself: a → a"
        );
        assert_eq!(
            error(
                "<layout name=\"t\">\n<template name=\"a\"><use template=\"b\"/></template>\n<template name=\"b\">\n  <use template=\"a\"/></template>\n<use template=\"a\"/>\n</layout>"
            ),
            "4:8: attribute `template`: template `a` uses itself: a → b → a"
        );
    }

    #[test]
    fn structural_errors_are_placed_and_explained() {
        let cases = [
            (
                "<page name=\"x\"/>",
                "1:1: root element is <page>, expected <layout>",
            ),
            ("<layout/>", "1:1: <layout> is missing attribute `name`"),
            (
                "<layout name=\"t\">\n  <readout bind=\"a.b\" colour=\"red\"/>\n</layout>",
                "2:23: unknown attribute `colour` on <readout>; expected one of: id, label, role, bind, unit, precision, fresh",
            ),
            (
                "<layout name=\"t\">\n  <column><dial/></column>\n</layout>",
                "2:11: unexpected element <dial> inside <column>; expected <row>, <column>, <tabs>, <grid>, <readout>, <gauge>, <plot>, <track>, <health>, <log>, <history>, <button>, <slider>, <number>, <text>, <toggle>",
            ),
            (
                "<layout name=\"t\">\n  <tabs><column/></tabs>\n</layout>",
                "2:9: unexpected element <column> inside <tabs>; expected <tab>",
            ),
            (
                "<layout name=\"t\">\n  <tabs><tab/></tabs>\n</layout>",
                "2:9: <tab> is missing attribute `title`",
            ),
            (
                "<layout name=\"t\">\n  <use template=\"nope\"/>\n</layout>",
                "2:8: attribute `template`: no template called `nope`; templates: none",
            ),
            (
                "<layout name=\"t\" title=\"${x}\"/>",
                "1:18: attribute `title`: undefined variable `x`: declare it with <var name=\"x\" default=\"…\"/>",
            ),
            (
                "<layout name=\"t\">\n  <readout id=\"a\" bind=\"a.b\"/>\n  <readout id=\"a\" bind=\"a.b\"/>\n</layout>",
                "3:12: attribute `id`: id `a` is already used at line 2",
            ),
            (
                "<layout name=\"t\">\n  <row sizes=\"1 2 3\"><log/></row>\n</layout>",
                "2:8: attribute `sizes`: 3 sizes for 1 children; give one size per child",
            ),
            (
                "<layout name=\"t\">\n  <readout bind=\"depth\"/>\n</layout>",
                "2:12: attribute `bind`: `depth` is not topic.field (the field is after the last dot: nav.depth.depth)",
            ),
            (
                "<layout name=\"t\">\n  <readout bind=\"nav..x\"/>\n</layout>",
                "2:12: attribute `bind`: `nav.` is not a topic: empty segment in \"nav.\" (two dots in a row, or a dot at an end)",
            ),
            (
                "<layout name=\"t\">\n  <gauge bind=\"a.b\" min=\"3\" max=\"1\"/>\n</layout>",
                "2:29: attribute `max`: the maximum 1 is not above the minimum 3",
            ),
            (
                "<layout name=\"t\">\n  <gauge bind=\"a.b\" min=\"x\"/>\n</layout>",
                "2:21: attribute `min`: `x` is not a number",
            ),
            (
                "<layout name=\"t\">\n  <gauge bind=\"a.b\" ranges=\"0:1:plaid\"/>\n</layout>",
                "2:21: attribute `ranges`: `plaid` is not a colour: #rgb, #rrggbb or one of black, white, gray, grey, red, orange, yellow, green, lime, teal, cyan, blue, navy, purple, magenta, pink, brown, olive",
            ),
            (
                "<layout name=\"t\">\n  <readout bind=\"a.b\" fresh=\"soon\"/>\n</layout>",
                "2:23: attribute `fresh`: `soon` is not a duration (250ms, 2s, 1min)",
            ),
            (
                "<layout name=\"t\" roles=\"pilot s!\"/>",
                "1:18: attribute `roles`: `s!` is not a role name: use letters, digits, `_` and `-`",
            ),
            (
                "<layout name=\"t\">\n  <plot/>\n</layout>",
                "2:3: a <plot> needs at least one <series bind=\"topic.field\"/>",
            ),
        ];
        let wrong: Vec<String> = cases
            .iter()
            .filter(|(text, want)| error(text) != *want)
            .map(|(text, want)| format!("{text}\n  got  {}\n  want {want}", error(text)))
            .collect();
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }

    #[test]
    fn commands_are_checked_where_they_are_named() {
        let cases = [
            (
                "<slider command=\"cours.heading\"/>",
                "4:9: attribute `command`: no command called `cours`; commands: course, stop",
            ),
            (
                "<slider command=\"course.hdg\"/>",
                "4:9: attribute `command`: command `course` has no field `hdg`; fields: heading, speed, name, on",
            ),
            (
                "<slider command=\"course\"/>",
                "4:9: attribute `command`: sets a field: write `course.FIELD`; fields of `course`: heading, speed, name, on",
            ),
            (
                "<button command=\"course.speed\"/>",
                "4:9: attribute `command`: sends command `course` as a whole: write `course`, not `course.speed`",
            ),
            (
                "<slider command=\"course.name\"/>",
                "4:9: attribute `command`: field `name` of command `course` is a string, not a number",
            ),
            (
                "<slider command=\"course.speed\" step=\"0\"/>",
                "4:32: attribute `step`: `0` is not a step (a number above 0)",
            ),
            (
                "<button command=\"stop\" set=\"action=1\"/>",
                "4:24: attribute `set`: field `action` is a string, not an int `1`",
            ),
            (
                "<button command=\"course\" set=\"heading=400\"/>",
                "4:26: attribute `set`: field `heading`: 400 is above the maximum 360",
            ),
            (
                "<keys><key key=\"a\" command=\"course.speed\"/></keys>",
                "4:7: <key> setting `course.speed` needs `value` (held) or `step` (each press)",
            ),
            (
                "<keys><key key=\"a\" command=\"stop\" value=\"1\"/></keys>",
                "4:35: attribute `value`: `value` needs a field: write command=\"stop.FIELD\"",
            ),
            (
                "<gamepad><axis index=\"0\" command=\"course.speed\" deadband=\"1\"/></gamepad>",
                "4:49: attribute `deadband`: `1` is not from 0 up to (not including) 1",
            ),
            (
                "<gamepad><axis index=\"0\" command=\"course.speed\" expo=\"-0.1\"/></gamepad>",
                "4:49: attribute `expo`: `-0.1` is not from 0 up to (not including) 1",
            ),
            (
                "<gamepad><button index=\"x\" command=\"stop\"/></gamepad>",
                "4:18: attribute `index`: `x` is not a whole number from 0 to 255",
            ),
            (
                "<command name=\"c\" topic=\"a b\"/>",
                "4:19: attribute `topic`: `a b` is not a topic: character ' ' not allowed in \"a b\"",
            ),
            (
                "<command name=\"c\" topic=\"a\" rate=\"fast\"/>",
                "4:29: attribute `rate`: `fast` is not a rate (5Hz, 5) or a period (200ms)",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" neutral=\"x=0\"/>",
                "4:42: attribute `neutral`: `neutral` is sent when a dead-man command stops; give the command a `rate`",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" rate=\"5\" neutral=\"y=0\"/>",
                "4:51: attribute `neutral`: command `c` has no field `y`; fields: x",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" min.x=\"2\" max.x=\"1\"/>",
                "4:52: attribute `max.x`: the maximum 1 of `x` is not above its minimum 2",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" min.x=\"2\"/>",
                "4:29: attribute `fields`: field `x`: 1 is below the minimum 2 (the initial value)",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" max.y=\"2\"/>",
                "4:42: attribute `max.y`: command `c` has no field `y`; fields: x",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1, x=2\"/>",
                "4:29: attribute `fields`: field `x` is given twice",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x\"/>",
                "4:29: attribute `fields`: `x` is not FIELD=VALUE",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=&quot;open\"/>",
                "4:29: attribute `fields`: a double quote `\"` is not closed",
            ),
            (
                "<command name=\"c\" topic=\"a\" hold=\"2s\"/>",
                "4:29: attribute `hold`: `hold` is how long a confirm=\"hold\" button is held; add confirm=\"hold\"",
            ),
            (
                "<command name=\"c\" topic=\"a\" confirm=\"maybe\"/>",
                "4:29: attribute `confirm`: `maybe` is not a confirmation: none, dialog or hold",
            ),
            (
                "<command name=\"c\" topic=\"a\" colour=\"red\"/>",
                "4:29: unknown attribute `colour` on <command>; expected one of: name, topic, fields, role, confirm, hold, rate, neutral, lease, min.FIELD, max.FIELD",
            ),
            (
                "<command name=\"stop\" topic=\"a\"/>",
                "4:1: command `stop` is already declared at line 3",
            ),
            (
                "<toggle on=\"yes\" command=\"course.on\"/>",
                "4:9: attribute `on`: field `on` is a bool, not a string `\"yes\"`",
            ),
        ];
        let wrong: Vec<String> = cases
            .iter()
            .filter(|(body, want)| error(&with(body)) != *want)
            .map(|(body, want)| format!("{body}\n  got  {}\n  want {want}", error(&with(body))))
            .collect();
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
        parse(&with(
            "<toggle command=\"course.on\"/><text command=\"course.name\"/>",
        ))
        .unwrap();
    }

    #[test]
    fn expansion_is_bounded() {
        let mut text =
            String::from("<layout name=\"t\">\n<template name=\"t0\"><log/><log/></template>\n");
        for i in 1..20 {
            text.push_str(&format!(
                "<template name=\"t{i}\"><use template=\"t{p}\"/><use template=\"t{p}\"/></template>\n",
                p = i - 1
            ));
        }
        text.push_str("<use template=\"t19\"/>\n</layout>");
        assert!(
            error(&text).contains("more than 10000 elements"),
            "{}",
            error(&text)
        );
    }

    #[test]
    fn field_values_are_typed() {
        let m =
            field_list("a=1, b=1.5, c=-2, d=true, e=false, f=survey, g=\"x, y\", h=1e3").unwrap();
        let want = [
            ("a", Value::Int(1)),
            ("b", Value::Float(1.5)),
            ("c", Value::Int(-2)),
            ("d", Value::Bool(true)),
            ("e", Value::Bool(false)),
            ("f", Value::from("survey")),
            ("g", Value::from("x, y")),
            ("h", Value::Float(1000.0)),
        ];
        for (k, v) in want {
            assert_eq!(m.get(k), Some(&v), "{k}");
        }
        assert_eq!(field_value("nan"), Value::from("nan"));
        assert_eq!(field_value("1e999"), Value::from("1e999"));
    }

    #[test]
    fn build_checks_types_ranges_and_names() {
        let l = example();
        let course = &l.commands["course"];
        let set = DataMap::new().with("heading", 90.0);
        let sent = course.build(&DataMap::new(), &set).unwrap();
        assert_eq!(sent.get("heading"), Some(&Value::Int(90)));
        assert_eq!(sent.get("depth"), Some(&Value::Int(0)));
        assert_eq!(sent.len(), 3);
        let current = DataMap::new().with("depth", 12).with("bogus", 1);
        let sent = course
            .build(&current, &DataMap::new().with("speed", 2))
            .unwrap();
        assert_eq!(sent.get("depth"), Some(&Value::Int(12)));
        assert_eq!(sent.get("speed"), Some(&Value::Float(2.0)));
        assert_eq!(sent.get("bogus"), None);
        assert_eq!(
            course.build(&DataMap::new(), &DataMap::new().with("speed", 3.0)),
            Err("field `speed`: 3 is above the maximum 2.5".to_string())
        );
        assert_eq!(
            course.build(&DataMap::new(), &DataMap::new().with("speed", "fast")),
            Err("field `speed` is a float, not a string `\"fast\"`".to_string())
        );
        assert_eq!(
            course.build(&DataMap::new(), &DataMap::new().with("hdg", 1)),
            Err("command `course` has no field `hdg`; fields: heading, depth, speed".to_string())
        );
        assert_eq!(
            course.build(&DataMap::new(), &DataMap::new().with("heading", f64::NAN)),
            Err("field `heading` is an int, not a float `NaN`".to_string())
        );
        let start = &l.commands["start"];
        assert!(
            start
                .build(&DataMap::new(), &DataMap::new().with("name", true))
                .is_err()
        );
    }

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

    #[test]
    fn visibility_follows_roles() {
        let l = example();
        assert!(l.visible_to(&["designer".to_string()]));
        assert!(!l.visible_to(&["scientist".to_string()]));
        assert!(!l.visible_to(&[]));
        let open = parse("<layout name=\"t\"/>").unwrap();
        assert!(open.visible_to(&[]));
        assert_eq!(open.root.kind, "column");
    }

    #[test]
    fn check_warns_of_missing_producers_and_acceptors() {
        let spec = SystemSpec::parse(
            "sys.xml",
            r#"<seabus>
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="inproc://"/>
  <module name="g" type="generator" medium="bus" topic="nav.depth"/>
  <bridge name="b" media="bus net"><route from="net" to="bus" topics="remote.**"/></bridge>
</seabus>"#,
        )
        .unwrap();
        let registry = seabus_support::registry();
        let catalogue = Catalogue::built_in();
        let l = parse(&with(
            "<column><readout bind=\"nav.depth.value\"/><readout bind=\"remote.x.y\"/><readout bind=\"nav.velocity.speed\"/></column>",
        ))
        .unwrap();
        let got: Vec<String> = l
            .check(&spec, &registry, &catalogue)
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(
            got,
            [
                "l.xml:4:9: warning: `nav.depth` has no field `value` (widget `readout-1`); its fields: counter, sine, time",
                "l.xml:4:70: warning: no module of sys.xml produces `nav.velocity` on medium `bus` (widget `readout-3`)",
                "l.xml:2:1: warning: no module of sys.xml accepts command `course` on `cmd.course`",
                "l.xml:3:1: warning: no module of sys.xml accepts command `stop` on `cmd.mission`",
            ]
        );
    }
}
