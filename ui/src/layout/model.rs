//! The layout model: a parsed layout, its commands, widget tree and input bindings, and what it
//! displays ([`Layout::bindings`]) and to whom ([`Layout::visible_to`]).

use super::values::{field_list, list};
use seabus_medium::parse::parse_duration;
use seabus_medium::xml::Pos;
use seabus_medium::{DataMap, Topic, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

/// How old a displayed value may be before it is shown as stale, when a widget gives no `fresh`.
pub const DEFAULT_FRESH: Duration = Duration::from_secs(2);

/// The time a `confirm="hold"` button is held, when the command gives no `hold`.
pub const DEFAULT_HOLD: Duration = Duration::from_secs(1);

/// The topic a `<health>` table shows when it gives no `bind`.
pub const DEFAULT_HEALTH: &str = "vehicle.health";

/// The topics a `<log>` shows when it gives no `topics`.
pub const DEFAULT_LOG_TOPICS: &str = "cmd.status, vehicle.state";

/// Elements directly inside `<layout>` other than widgets.
pub(super) const TOP: [&str; 6] = ["var", "command", "template", "use", "keys", "gamepad"];

/// Widgets that hold other widgets.
pub(super) const CONTAINERS: [&str; 4] = ["row", "column", "tabs", "grid"];

/// Every widget kind an element may name, containers first.
pub(super) const WIDGETS: [&str; 17] = [
    "row", "column", "tabs", "grid", "readout", "gauge", "plot", "track", "fleet", "health", "log",
    "history", "button", "slider", "number", "text", "toggle",
];

/// Widgets that display variables and take `fresh`.
pub(super) const OUTPUTS: [&str; 7] = [
    "readout", "gauge", "plot", "track", "fleet", "health", "log",
];

/// What a `<fleet>` table shows of each vehicle when it does not say: its own attribute, and
/// where under the vehicle's name (`auv1.vehicle.state`) the value is.
pub const FLEET_COLUMNS: [(&str, &str); 4] = [
    ("mode", "vehicle.state.mode"),
    ("battery", "power.battery.percent"),
    ("severity", "vehicle.health.severity"),
    ("position", "nav.position"),
];

/// Every widget kind.
pub(super) fn widget_kinds() -> Vec<&'static str> {
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
    /// The vehicle whose control it needs (its layout's `vehicle`; `None`: the console's one
    /// control).
    pub vehicle: Option<String>,
    /// Lowest values of fields.
    pub min: BTreeMap<String, f64>,
    /// Highest values of fields.
    pub max: BTreeMap<String, f64>,
    /// The variables that give fields their current value while nothing has been commanded on
    /// the command's topic (`from.FIELD="topic.field"`).
    pub from: BTreeMap<String, (Topic, String)>,
    /// How often the console sends the command again while its sender holds control
    /// (`keep`): the vehicle holds it until another is sent, control ends or the vehicle
    /// refuses it.
    pub keep: Option<Duration>,
    /// The command a page offers when the vehicle refuses this one (`resume`: a mission's start
    /// after the vehicle stopped).
    pub resume: Option<String>,
    /// Whether it is the layout's safe action (`safe`: a stop): sending it first ends every
    /// kept command.
    pub safe: bool,
    /// Where it is declared.
    pub pos: Pos,
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

    /// An attribute written `topic.field`, split at the last dot.
    fn bound(&self, attr: &str) -> Option<(&str, &str)> {
        self.attrs.get(attr).and_then(|b| b.rsplit_once('.'))
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
    /// The vehicle it commands (`vehicle`, usually `${vehicle}`): its commands need control of
    /// that vehicle, each vehicle's control taken on its own. `None`: the console's one control.
    pub vehicle: Option<String>,
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
        for node in self.root.walk() {
            node_bindings(node, &mut out);
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
        for c in self.commands.values() {
            for (topic, field) in c.from.values() {
                out.push(Binding {
                    topic: topic.to_string(),
                    field: Some(field.clone()),
                    fresh: DEFAULT_FRESH,
                    widget: format!("command-{}", c.name),
                    pos: c.pos.clone(),
                });
            }
        }
        out
    }
}

/// How much of a variable's past a plot or track draws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Horizon {
    /// A plot: its window, in seconds.
    Seconds(f64),
    /// A track: its trail, in points.
    Points(usize),
}

/// What a plot or track binds: a topic (or pattern), the fields it draws and how far back.
#[derive(Debug, Clone, PartialEq)]
pub struct Plotted {
    /// The topic or pattern.
    pub topic: String,
    /// The fields drawn (a track's position: `lat` and `lon`).
    pub fields: Vec<String>,
    /// How far back, the widest of the widgets drawing it.
    pub horizons: Vec<Horizon>,
}

/// A plot's window when it gives none, as the page draws it.
const PLOT_WINDOW: f64 = 60.0;
/// A track's trail when it gives none, as the page draws it.
const TRAIL: usize = 600;

impl Layout {
    /// What the plots and tracks bind.
    pub fn plotted(&self) -> Vec<Plotted> {
        let mut out: Vec<Plotted> = Vec::new();
        let mut add = |topic: &str, field: &str, horizon: Horizon| {
            let i = match out.iter().position(|p| p.topic == topic) {
                Some(i) => i,
                None => {
                    out.push(Plotted {
                        topic: topic.to_string(),
                        fields: Vec::new(),
                        horizons: Vec::new(),
                    });
                    out.len() - 1
                }
            };
            let p = &mut out[i];
            if !p.fields.iter().any(|f| f == field) {
                p.fields.push(field.to_string());
            }
            if !p.horizons.contains(&horizon) {
                p.horizons.push(horizon);
            }
        };
        for node in self.root.walk() {
            match node.kind.as_str() {
                "plot" => {
                    let window = node
                        .attrs
                        .get("window")
                        .and_then(|w| parse_duration(w))
                        .map_or(PLOT_WINDOW, |d| d.as_secs_f64());
                    for (t, f) in node.children.iter().filter_map(|s| s.bound("bind")) {
                        add(t, f, Horizon::Seconds(window));
                    }
                }
                "track" => {
                    let trail = node
                        .attrs
                        .get("trail")
                        .and_then(|t| t.trim().parse().ok())
                        .unwrap_or(TRAIL);
                    if let Some(p) = node.attrs.get("position") {
                        add(p.trim(), "lat", Horizon::Points(trail));
                        add(p.trim(), "lon", Horizon::Points(trail));
                    }
                    if let Some((t, f)) = node.bound("heading") {
                        add(t, f, Horizon::Points(trail));
                    }
                }
                _ => {}
            }
        }
        out
    }
}

/// What a layout's controls let a page put in one command: the fields some control sets to a value
/// the user chooses, and for the others the values its buttons and keys fix. A value no control
/// could send is not the user's choice: the server refuses it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Offers {
    /// Fields a control sets freely: sliders, numbers, texts, toggles, gamepad axes, stepping keys.
    pub free: BTreeSet<String>,
    /// Fields buttons and keys set to values of their own, with those values.
    pub fixed: BTreeMap<String, Vec<Value>>,
}

impl Offers {
    /// Whether some control of the layout sends `value` in `field`; `same` compares two values of
    /// the field as the command takes them.
    pub fn allows(
        &self,
        field: &str,
        value: &Value,
        same: impl Fn(&Value, &Value) -> bool,
    ) -> bool {
        self.free.contains(field)
            || self
                .fixed
                .get(field)
                .is_some_and(|vs| vs.iter().any(|v| same(v, value)))
    }
}

impl Layout {
    /// What the layout's controls let a page put in command `name` (see [`Offers`]).
    pub fn offers(&self, name: &str) -> Offers {
        let mut out = Offers::default();
        let mut fix =
            |field: &str, value: Value| out.fixed.entry(field.to_string()).or_default().push(value);
        let mut free = BTreeSet::new();
        for node in self.root.walk() {
            let Some((command, field)) = node.command() else {
                continue;
            };
            if command != name {
                continue;
            }
            match (node.kind.as_str(), field) {
                ("button", _) => {
                    let set = node
                        .attrs
                        .get("set")
                        .and_then(|s| field_list(s).ok())
                        .unwrap_or_default();
                    for (f, v) in set.iter() {
                        fix(f, v.clone());
                    }
                }
                (_, Some(f)) => {
                    free.insert(f.to_string());
                }
                _ => {}
            }
        }
        for k in self.keys.iter().filter(|k| k.command == name) {
            match (&k.field, &k.value, k.step) {
                (Some(f), Some(v), _) => fix(f, v.clone()),
                (Some(f), None, Some(_)) => {
                    free.insert(f.clone());
                }
                _ => {}
            }
        }
        for a in self.axes.iter().filter(|a| a.command == name) {
            free.insert(a.field.clone());
        }
        out.free = free;
        out
    }
}

/// The variables one node displays (a plot's are its series'), added to `out`.
fn node_bindings(node: &Node, out: &mut Vec<Binding>) {
    let fresh = node.fresh();
    let mut add = |topic: &str, field: Option<&str>, node: &Node| {
        out.push(Binding {
            topic: topic.to_string(),
            field: field.map(str::to_string),
            fresh,
            widget: node.id.clone(),
            pos: node.pos.clone(),
        });
    };
    match node.kind.as_str() {
        "readout" | "gauge" => {
            if let Some((t, f)) = node.bound("bind") {
                add(t, Some(f), node);
            }
        }
        "plot" => {
            for s in &node.children {
                if let Some((t, f)) = s.bound("bind") {
                    add(t, Some(f), s);
                }
            }
        }
        "track" => {
            if let Some(p) = node.attrs.get("position") {
                add(p.trim(), None, node);
            }
            if let Some((t, f)) = node.bound("heading") {
                add(t, Some(f), node);
            }
        }
        "health" => {
            let topic = node.attrs.get("bind").map_or(DEFAULT_HEALTH, |b| b.trim());
            add(topic, None, node);
        }
        "fleet" => {
            let fleet = node
                .attrs
                .get("bind")
                .map_or(seabus_medium::topic::FLEET, |b| b.trim());
            add(fleet, None, node);
            for (attr, default) in FLEET_COLUMNS {
                let at = node.attrs.get(attr).map_or(default, |v| v.trim());
                // every vehicle's: `*.vehicle.state` with field `mode`; a position's any field
                let (topic, field) = match at.rsplit_once('.') {
                    Some((t, f)) if attr != "position" => (t, Some(f)),
                    _ => (at, None),
                };
                add(&format!("*.{topic}"), field, node);
            }
        }
        "log" => {
            let topics = node
                .attrs
                .get("topics")
                .map_or(DEFAULT_LOG_TOPICS, String::as_str);
            for t in list(topics) {
                add(t, None, node);
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{example, parse};

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
    fn visibility_follows_roles() {
        let l = example();
        assert!(l.visible_to(&["designer".to_string()]));
        assert!(!l.visible_to(&["scientist".to_string()]));
        assert!(!l.visible_to(&[]));
        let open = parse("<layout name=\"t\"/>").unwrap();
        assert!(open.visible_to(&[]));
        assert_eq!(open.root.kind, "column");
    }
}
