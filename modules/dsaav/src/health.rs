//! The DSAAV health monitor's core: the rules file and the state machine that turns component
//! health updates into a vehicle severity. It keeps no clock of its own: every call is given the
//! time, so the same calls always give the same answers.
//!
//! # The rules file
//!
//! ```xml
//! <health publish="vehicle.health" period="1s" timeout="3s" poll="1s"
//!         emergency-action='cmd.emergency ballast=drop sos=true reason="health emergency"'>
//!   <!-- vehicle-wide defaults, for every component that does not say otherwise -->
//!   <severity state="UNAVAILABLE" level="WARN"/>
//!   <component name="DepthSensor" mode="active" timeout="2s">
//!     <severity state="MALFUNCTION" level="ABORT"/>
//!     <severity state="OFFLINE" level="EMERGENCY"/>
//!   </component>
//!   <component name="GPS" mode="passive" poll="1s" timeout="3s"/>
//!   <component name="Frontseat" mode="link" medium="serial"/>
//! </health>
//! ```
//!
//! - `<health>` (the root) may have `publish` (the topic of the health snapshot, default
//!   `vehicle.health`), `period` (how often the snapshot is published, default 1 s), `timeout`
//!   and `poll` (the defaults of its components, 3 s and 1 s), and `emergency-action`: a command
//!   published once each time the vehicle enters EMERGENCY, written as a topic followed by
//!   `key=value` fields typed as `seabus pub` types them (`1` an integer, `2.5` a float, `true` a
//!   boolean, `"7"` or anything else a string; a double-quoted value keeps its blanks).
//! - `<component>` names one component (`name`: letters, digits, `_` and `-`; each once) and how
//!   its health is learnt (`mode`): `active` (the default) — the component sends updates itself and
//!   is OFFLINE once it has sent none for `timeout`; `passive` — the monitor polls it every `poll`
//!   and it is OFFLINE once it has not answered for `timeout`, which must be longer than `poll`;
//!   `link` — the component is the link of medium `medium`: HEALTHY while the link is up, OFFLINE
//!   while it is down, no timeout; `data` — the component is the data it publishes: each of its
//!   `<data topic="…" period="…"/>` children names a topic and the expected time between two
//!   messages on it; a topic silent for `unavailable-after` (default four periods) makes the
//!   component UNAVAILABLE, silent for `timeout` OFFLINE, and a message on it makes it HEALTHY
//!   again. `period`, `unavailable-after` and `timeout` on the component are defaults for its
//!   topics.
//! - `<severity state="…" level="…"/>` maps a component state (HEALTHY, UNAVAILABLE, MALFUNCTION,
//!   OFFLINE) to a severity level (NONE, WARN, ABORT, EMERGENCY); names are read in any case. Inside
//!   `<component>` it holds for that component; directly inside `<health>` for every component.
//!   A state is given at most once per element; HEALTHY is always NONE.
//! - Unless the file says otherwise UNAVAILABLE is WARN, MALFUNCTION is ABORT and OFFLINE is ABORT.
//!   EMERGENCY, which triggers the emergency action, is only ever chosen in the file.
//! - Durations are `250ms`, `2s`, `1min` or a bare number of milliseconds, above zero.
//!
//! Every error names file, line and column and what was expected:
//!
//! ```text
//! health.xml:2:23: attribute `mode`: `sleepy` is not a mode: active, passive, link or data
//! health.xml:4:5: state OFFLINE already has a severity at line 3
//! ```
//!
//! # The state machine
//!
//! A [`Monitor`] starts with every component HEALTHY, each given one timeout to send its first
//! update, and the severity NONE. [`Monitor::report`] takes an update (sent by an active component
//! or a poll's answer), [`Monitor::link`] a medium's link state, [`Monitor::data`] a message on a
//! watched topic, and [`Monitor::tick`] marks OFFLINE every timed component silent for its timeout,
//! UNAVAILABLE or OFFLINE every data component whose topics have fallen silent, and asks for the
//! polls that are due (the first at once, then one each `poll`). The vehicle severity is the
//! highest severity of the components' states. Each call returns what changed as [`Event`]s:
//! component states, the severity, the emergency action (once per entry into EMERGENCY) and polls.
//! Updates from components the rules do not name are ignored and counted. [`Monitor::snapshot`] is
//! the datamap the monitor publishes, with the reason of every component that is not HEALTHY
//! (`nav.position silent for 4.2 s`).

use seabus_medium::parse::{parse_duration, parse_field, split_words};
use seabus_medium::xml::{self, Attr, Element, FileError, Pos};
use seabus_medium::{DataMap, LinkState, Topic, Value};
use std::collections::HashMap;
use std::fmt;
use std::path::Path;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
/// The time a monitor is given (tokio's, so that a paused test clock drives it too).
pub use tokio::time::Instant;

/// The topic of the health snapshot when the file names none.
pub const DEFAULT_PUBLISH: &str = "vehicle.health";
/// How often the snapshot is published when the file does not say.
pub const DEFAULT_PERIOD: Duration = Duration::from_secs(1);
/// A timed component's timeout when the file does not say.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(3);
/// A passive component's poll period when the file does not say.
pub const DEFAULT_POLL: Duration = Duration::from_secs(1);
/// Longest component or medium name, in bytes.
pub const MAX_NAME: usize = seabus_modules::system::MAX_NAME;

/// The health of one component, in increasing order of trouble; the number is the DSAAV
/// dictionary's `state` value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ComponentState {
    /// Working as expected.
    Healthy = 0,
    /// Responding, but no data is available (no GPS fix, no bottom lock).
    Unavailable = 1,
    /// Responding, but it has detected a malfunction in software or hardware.
    Malfunction = 2,
    /// Not responding, or no update for its timeout.
    Offline = 3,
}

impl ComponentState {
    /// Every state, in order.
    pub const ALL: [ComponentState; 4] = [
        ComponentState::Healthy,
        ComponentState::Unavailable,
        ComponentState::Malfunction,
        ComponentState::Offline,
    ];

    /// The state's name as the paper writes it (`HEALTHY`).
    pub fn name(self) -> &'static str {
        match self {
            ComponentState::Healthy => "HEALTHY",
            ComponentState::Unavailable => "UNAVAILABLE",
            ComponentState::Malfunction => "MALFUNCTION",
            ComponentState::Offline => "OFFLINE",
        }
    }

    /// The state's number on the wire (0 HEALTHY … 3 OFFLINE).
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The state with number `code`.
    pub fn from_code(code: i64) -> Option<ComponentState> {
        usize::try_from(code)
            .ok()
            .and_then(|i| ComponentState::ALL.get(i).copied())
    }
}

impl fmt::Display for ComponentState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ComponentState {
    type Err = ();

    /// Reads a state's name in any case.
    fn from_str(s: &str) -> Result<Self, ()> {
        ComponentState::ALL
            .into_iter()
            .find(|st| st.name().eq_ignore_ascii_case(s.trim()))
            .ok_or(())
    }
}

/// How serious the vehicle's problems are, in increasing order; the number is the DSAAV
/// dictionary's `severity` value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub enum Severity {
    /// Normal operation.
    #[default]
    None = 0,
    /// A problem that is not a show-stopper: the mission can continue.
    Warn = 1,
    /// The mission must be aborted: the vehicle returns to the recovery point.
    Abort = 2,
    /// The mission must be aborted and the emergency action taken.
    Emergency = 3,
}

impl Severity {
    /// Every level, in order.
    pub const ALL: [Severity; 4] = [
        Severity::None,
        Severity::Warn,
        Severity::Abort,
        Severity::Emergency,
    ];

    /// The level's name as the paper writes it (`NONE`).
    pub fn name(self) -> &'static str {
        match self {
            Severity::None => "NONE",
            Severity::Warn => "WARN",
            Severity::Abort => "ABORT",
            Severity::Emergency => "EMERGENCY",
        }
    }

    /// The level's number on the wire (0 NONE … 3 EMERGENCY).
    pub fn code(self) -> u8 {
        self as u8
    }
}

impl fmt::Display for Severity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Severity {
    type Err = ();

    /// Reads a level's name in any case.
    fn from_str(s: &str) -> Result<Self, ()> {
        Severity::ALL
            .into_iter()
            .find(|l| l.name().eq_ignore_ascii_case(s.trim()))
            .ok_or(())
    }
}

/// The severity of each component state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Levels([Severity; 4]);

impl Default for Levels {
    /// HEALTHY is NONE, UNAVAILABLE is WARN, MALFUNCTION is ABORT, OFFLINE is ABORT.
    fn default() -> Self {
        Levels([
            Severity::None,
            Severity::Warn,
            Severity::Abort,
            Severity::Abort,
        ])
    }
}

impl Levels {
    /// The severity of `state`.
    pub fn get(&self, state: ComponentState) -> Severity {
        self.0[state as usize]
    }

    /// Sets the severity of `state`; HEALTHY stays NONE whatever is asked.
    pub fn set(&mut self, state: ComponentState, level: Severity) {
        if state != ComponentState::Healthy {
            self.0[state as usize] = level;
        }
    }
}

/// A command to publish: a topic and its fields.
#[derive(Debug, Clone, PartialEq)]
pub struct Action {
    /// Where the command goes.
    pub topic: Topic,
    /// What it says.
    pub fields: DataMap,
}

impl Action {
    /// Reads `TOPIC key=value …`: a topic, then fields typed as `seabus pub` types them, each key
    /// once.
    pub fn parse(text: &str) -> Result<Action, String> {
        let words = split_words(text)?;
        let Some((topic, fields)) = words.split_first() else {
            return Err("expected a topic and then `key=value` fields".to_string());
        };
        let topic = Topic::new(topic).map_err(|e| format!("topic `{topic}`: {e}"))?;
        let mut map = DataMap::new();
        for f in fields {
            let (key, value) = parse_field(f)?;
            if map.get(key).is_some() {
                return Err(format!("field `{key}` is given twice"));
            }
            map.insert(key.to_string(), value);
        }
        Ok(Action { topic, fields: map })
    }
}

/// How the monitor learns a component's health.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mode {
    /// The component sends updates itself; OFFLINE after `timeout` without one.
    Active {
        /// Longest silence before the component is OFFLINE.
        timeout: Duration,
    },
    /// The monitor polls the component every `poll`; OFFLINE after `timeout` without an answer.
    Passive {
        /// Time between two polls.
        poll: Duration,
        /// Longest silence before the component is OFFLINE (longer than `poll`).
        timeout: Duration,
    },
    /// The component is a medium's link: HEALTHY while it is up, OFFLINE while it is down.
    Link {
        /// The medium's name.
        medium: String,
    },
    /// The component is the data it publishes: UNAVAILABLE or OFFLINE while a topic is silent.
    Data {
        /// The topics it publishes, in file order, each once.
        topics: Vec<DataTopic>,
    },
}

/// A topic a data component publishes, and how long it may be silent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataTopic {
    /// The topic.
    pub topic: Topic,
    /// The expected time between two messages.
    pub period: Duration,
    /// The silence that makes the component UNAVAILABLE (longer than `period`).
    pub unavailable_after: Duration,
    /// The silence that makes the component OFFLINE (longer than `unavailable_after`).
    pub timeout: Duration,
}

impl DataTopic {
    /// The state a silence of `silent` on this topic puts its component in.
    pub fn state_after(&self, silent: Duration) -> ComponentState {
        if silent >= self.timeout {
            ComponentState::Offline
        } else if silent >= self.unavailable_after {
            ComponentState::Unavailable
        } else {
            ComponentState::Healthy
        }
    }
}

impl Mode {
    /// The longest silence the component is allowed, if it is timed: for a data component, the
    /// shortest timeout of its topics (any one of them silent that long makes it OFFLINE).
    pub fn timeout(&self) -> Option<Duration> {
        match self {
            Mode::Active { timeout } | Mode::Passive { timeout, .. } => Some(*timeout),
            Mode::Link { .. } => None,
            Mode::Data { topics } => topics.iter().map(|t| t.timeout).min(),
        }
    }

    /// The mode's name in the file.
    pub fn name(&self) -> &'static str {
        match self {
            Mode::Active { .. } => "active",
            Mode::Passive { .. } => "passive",
            Mode::Link { .. } => "link",
            Mode::Data { .. } => "data",
        }
    }
}

/// One component the rules name.
#[derive(Debug, Clone, PartialEq)]
pub struct ComponentRule {
    /// Its name.
    pub name: Arc<str>,
    /// How its health is learnt.
    pub mode: Mode,
    /// The severity of each of its states.
    pub levels: Levels,
    /// Where it is written.
    pub pos: Pos,
}

/// A health rules file, read.
#[derive(Debug, Clone, PartialEq)]
pub struct Rules {
    /// The topic of the health snapshot.
    pub publish: Topic,
    /// How often the snapshot is published.
    pub period: Duration,
    /// The command published on each entry into EMERGENCY, if any.
    pub emergency_action: Option<Action>,
    /// The components, in file order.
    pub components: Vec<ComponentRule>,
    /// Where the root element is.
    pub pos: Pos,
}

const STATES: &str = "a component state: HEALTHY, UNAVAILABLE, MALFUNCTION or OFFLINE";
const LEVELS: &str = "a severity: NONE, WARN, ABORT or EMERGENCY";

fn check_name(attr: &Attr, what: &str) -> Result<Arc<str>, FileError> {
    seabus_modules::system::check_name_of(attr, what, "").map(Arc::from)
}

/// Attribute `name` of `el` as a duration above zero, when present.
fn duration<'a>(el: &'a Element, name: &str) -> Result<Option<(Duration, &'a Attr)>, FileError> {
    let Some(a) = el.attr(name) else {
        return Ok(None);
    };
    match parse_duration(&a.value).filter(|d| !d.is_zero()) {
        Some(d) => Ok(Some((d, a))),
        None => Err(a.error(format!(
            "`{}` is not a duration above zero (250ms, 2s, 1min; a bare number is milliseconds)",
            a.value.trim()
        ))),
    }
}

/// `base` changed by the `<severity>` children of `el`.
fn levels(el: &Element, base: Levels) -> Result<Levels, FileError> {
    let mut levels = base;
    let mut seen: [Option<u32>; 4] = [None; 4];
    for s in el.children_named("severity") {
        s.only_attrs(&["state", "level"])?;
        s.only_children(&[])?;
        let state_attr = s.required("state")?;
        let state: ComponentState = state_attr.parse(STATES)?;
        let level_attr = s.required("level")?;
        let level: Severity = level_attr.parse(LEVELS)?;
        if let Some(line) = seen[state as usize] {
            return Err(s.error(format!(
                "state {state} already has a severity at line {line}"
            )));
        }
        seen[state as usize] = Some(s.pos.line);
        if state == ComponentState::Healthy && level != Severity::None {
            return Err(level_attr.error("a HEALTHY component has severity NONE, always"));
        }
        levels.set(state, level);
    }
    Ok(levels)
}

/// What every component inherits from the root.
struct Defaults {
    levels: Levels,
    timeout: Duration,
    poll: Duration,
}

impl Rules {
    /// Reads and parses a rules file.
    pub fn load(path: &Path) -> Result<Rules, FileError> {
        Rules::from_element(&xml::parse_file(path)?)
    }

    /// Parses a rules file's text; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<Rules, FileError> {
        Rules::from_element(&xml::parse(file, text)?)
    }

    /// Reads rules from a `<health>` element (a rules file's root, or a system file's section).
    pub fn from_element(root: &Element) -> Result<Rules, FileError> {
        if root.name != "health" {
            return Err(root.error(format!(
                "root element is <{}>, expected <health>",
                root.name
            )));
        }
        root.only_attrs(&["publish", "period", "timeout", "poll", "emergency-action"])?;
        root.only_children(&["component", "severity"])?;
        let publish = match root.attr("publish") {
            None => Topic::new(DEFAULT_PUBLISH).map_err(|e| root.error(e.to_string()))?,
            Some(a) => Topic::new(a.value.trim()).map_err(|e| a.error(e))?,
        };
        let period = duration(root, "period")?.map_or(DEFAULT_PERIOD, |(d, _)| d);
        let emergency_action = root
            .attr("emergency-action")
            .map(|a| Action::parse(&a.value).map_err(|e| a.error(e)))
            .transpose()?;
        let defaults = Defaults {
            levels: levels(root, Levels::default())?,
            timeout: duration(root, "timeout")?.map_or(DEFAULT_TIMEOUT, |(d, _)| d),
            poll: duration(root, "poll")?.map_or(DEFAULT_POLL, |(d, _)| d),
        };
        let mut names: HashMap<Arc<str>, u32> = HashMap::new();
        let mut components = Vec::new();
        for el in root.children_named("component") {
            let rule = component(el, &defaults)?;
            if let Some(line) = names.get(&rule.name) {
                return Err(el.required("name")?.error(format!(
                    "a component `{}` is already defined at line {line}",
                    rule.name
                )));
            }
            names.insert(rule.name.clone(), el.pos.line);
            components.push(rule);
        }
        if components.is_empty() {
            return Err(root.error("health rules need at least one <component>"));
        }
        Ok(Rules {
            publish,
            period,
            emergency_action,
            components,
            pos: root.pos.clone(),
        })
    }

    /// The component called `name`.
    pub fn component(&self, name: &str) -> Option<&ComponentRule> {
        self.components.iter().find(|c| &*c.name == name)
    }
}

fn component(el: &Element, defaults: &Defaults) -> Result<ComponentRule, FileError> {
    el.only_attrs(&[
        "name",
        "mode",
        "timeout",
        "poll",
        "medium",
        "period",
        "unavailable-after",
    ])?;
    el.only_children(&["severity", "data"])?;
    let name = check_name(el.required("name")?, "component")?;
    let timeout = duration(el, "timeout")?;
    let poll = duration(el, "poll")?;
    let kind = match el.attr("mode") {
        None => "active",
        Some(a) => match a.value.trim() {
            m @ ("active" | "passive" | "link" | "data") => m,
            other => {
                return Err(a.error(format!(
                    "`{other}` is not a mode: active, passive, link or data"
                )));
            }
        },
    };
    if let Some(m) = el.attr("medium")
        && kind != "link"
    {
        return Err(m.error(format!(
            "only a `link` component follows a medium; this one is {kind}"
        )));
    }
    if kind != "data" {
        let why = format!("only a `data` component watches topics; this one is {kind}");
        if let Some(a) = ["period", "unavailable-after"]
            .into_iter()
            .find_map(|a| el.attr(a))
        {
            return Err(a.error(why));
        }
        if let Some(d) = el.children_named("data").next() {
            return Err(d.error(format!("<data>: {why}")));
        }
    }
    if let Some((_, a)) = poll
        && matches!(kind, "active" | "data")
    {
        return Err(a.error(format!(
            "only a passive component is polled; this one is {kind}"
        )));
    }
    let mode = match kind {
        "data" => Mode::Data {
            topics: data_topics(el, timeout, defaults)?,
        },
        "active" => Mode::Active {
            timeout: timeout.map_or(defaults.timeout, |(d, _)| d),
        },
        "passive" => {
            let p = poll.map_or(defaults.poll, |(d, _)| d);
            let t = timeout.map_or(defaults.timeout, |(d, _)| d);
            if t <= p {
                let (at, which) = match (timeout, poll) {
                    (Some((_, a)), _) => (&a.pos, "timeout"),
                    (None, Some((_, a))) => (&a.pos, "timeout (the default)"),
                    (None, None) => (&el.pos, "timeout (the default)"),
                };
                return Err(at.error(format!(
                    "the {which} {t:?} must be longer than the poll period {p:?}, or the component \
                     goes OFFLINE between polls"
                )));
            }
            Mode::Passive {
                poll: p,
                timeout: t,
            }
        }
        _ => {
            if let Some((_, a)) = timeout.or(poll) {
                return Err(a.error(
                    "a link component has no timeout and is not polled: it follows its medium",
                ));
            }
            Mode::Link {
                medium: check_name(el.required("medium")?, "medium")?.to_string(),
            }
        }
    };
    Ok(ComponentRule {
        name,
        mode,
        levels: levels(el, defaults.levels)?,
        pos: el.pos.clone(),
    })
}

/// The `<data>` children of data component `el`: each a topic, unique in the component, with its
/// `period`, `unavailable-after` (default four periods) and `timeout` (`timeout_attr`, the
/// component's, or the root's); the component's `period` and `unavailable-after` fill what a
/// child leaves out.
fn data_topics(
    el: &Element,
    timeout_attr: Option<(Duration, &Attr)>,
    defaults: &Defaults,
) -> Result<Vec<DataTopic>, FileError> {
    let period = duration(el, "period")?;
    let unavailable = duration(el, "unavailable-after")?;
    let mut topics: Vec<DataTopic> = Vec::new();
    let mut lines: HashMap<String, u32> = HashMap::new();
    for d in el.children_named("data") {
        d.only_attrs(&["topic", "period", "unavailable-after", "timeout"])?;
        d.only_children(&[])?;
        let at = d.required("topic")?;
        let topic = Topic::new(at.value.trim()).map_err(|e| at.error(e))?;
        if let Some(line) = lines.get(topic.as_str()) {
            return Err(at.error(format!(
                "topic `{topic}` is already watched by this component at line {line}"
            )));
        }
        lines.insert(topic.to_string(), d.pos.line);
        let Some((p, p_attr)) = duration(d, "period")?.or(period) else {
            return Err(d.error(
                "<data> needs `period`, the expected time between two messages on its topic \
                 (on it or on its <component>)",
            ));
        };
        let ua = duration(d, "unavailable-after")?.or(unavailable);
        let u = ua.map_or(p.saturating_mul(4), |(v, _)| v);
        if let Some((_, a)) = ua
            && u <= p
        {
            return Err(a.pos.error(format!(
                "unavailable-after {u:?} must be longer than the period {p:?}, or the component \
                 is UNAVAILABLE between two messages"
            )));
        }
        let to = duration(d, "timeout")?.or(timeout_attr);
        let t = to.map_or(defaults.timeout, |(v, _)| v);
        if t <= u {
            let (at, which) = match (to, ua) {
                (Some((_, a)), _) => (&a.pos, "timeout"),
                (None, Some((_, a))) => (&a.pos, "timeout (the default)"),
                (None, None) => (&p_attr.pos, "timeout (the default)"),
            };
            let four = if ua.is_none() { " (four periods)" } else { "" };
            return Err(at.error(format!(
                "the {which} {t:?} must be longer than unavailable-after{four} {u:?}, or the \
                 component goes OFFLINE before it is UNAVAILABLE"
            )));
        }
        topics.push(DataTopic {
            topic,
            period: p,
            unavailable_after: u,
            timeout: t,
        });
    }
    if topics.is_empty() {
        return Err(el.error(
            "a data component needs at least one <data topic=\"…\" period=\"…\"/>: the topics \
             it publishes",
        ));
    }
    Ok(topics)
}

/// Why a component's state changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cause {
    /// The component (or a poll's answer) said so.
    Report,
    /// It was silent for its timeout.
    Timeout,
    /// Its medium's link went up or down.
    Link,
    /// A message arrived on one of its topics (a data component).
    Data,
}

/// Something the monitor's owner should act on.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A component's state changed.
    State {
        /// The component.
        component: Arc<str>,
        /// Its state before.
        from: ComponentState,
        /// Its state now.
        to: ComponentState,
        /// Why.
        cause: Cause,
    },
    /// The vehicle severity changed.
    Severity {
        /// The severity before.
        from: Severity,
        /// The severity now.
        to: Severity,
    },
    /// The vehicle has just entered EMERGENCY: publish the action (when the rules give one).
    Emergency {
        /// The command to publish.
        action: Option<Action>,
    },
    /// A passive component is due a poll.
    Poll {
        /// The component.
        component: Arc<str>,
    },
}

/// What the monitor knows about one component.
#[derive(Debug, Clone)]
struct Entry {
    state: ComponentState,
    /// The last update, or the monitor's start.
    last: Instant,
    /// When the next poll is due (passive components).
    next_poll: Option<Instant>,
    /// Why its link is down (link components, while it is).
    link_down: Option<String>,
    /// Each of its topics (data components), in file order.
    heard: Vec<Heard>,
}

/// One topic of a data component: when it was last heard and the state its silence gives.
#[derive(Debug, Clone, Copy)]
struct Heard {
    last: Option<Instant>,
    state: ComponentState,
}

/// The health monitor's state machine: component states, the vehicle severity, and what changes.
#[derive(Debug, Clone)]
pub struct Monitor {
    rules: Rules,
    entries: Vec<Entry>,
    index: HashMap<Arc<str>, usize>,
    /// Each watched topic's (component, topic) places.
    watchers: HashMap<String, Vec<(usize, usize)>>,
    severity: Severity,
    unknown: u64,
    started: Instant,
    /// The latest time the monitor has been given.
    now: Instant,
}

/// Seconds with one decimal, as reasons give them.
fn tenths(d: Duration) -> String {
    format!("{:.1} s", d.as_secs_f64())
}

impl Monitor {
    /// A monitor starting at `now`: every component HEALTHY with one timeout to send its first
    /// update (a data component: each topic silent since `now`), every passive component due a
    /// poll at once, the severity NONE.
    pub fn new(rules: Rules, now: Instant) -> Monitor {
        let entries = rules
            .components
            .iter()
            .map(|c| Entry {
                state: ComponentState::Healthy,
                last: now,
                next_poll: matches!(c.mode, Mode::Passive { .. }).then_some(now),
                link_down: None,
                heard: match &c.mode {
                    Mode::Data { topics } => vec![
                        Heard {
                            last: None,
                            state: ComponentState::Healthy,
                        };
                        topics.len()
                    ],
                    _ => Vec::new(),
                },
            })
            .collect();
        let index = rules
            .components
            .iter()
            .enumerate()
            .map(|(i, c)| (c.name.clone(), i))
            .collect();
        let mut watchers: HashMap<String, Vec<(usize, usize)>> = HashMap::new();
        for (i, c) in rules.components.iter().enumerate() {
            if let Mode::Data { topics } = &c.mode {
                for (j, t) in topics.iter().enumerate() {
                    watchers
                        .entry(t.topic.to_string())
                        .or_default()
                        .push((i, j));
                }
            }
        }
        Monitor {
            rules,
            entries,
            index,
            watchers,
            severity: Severity::None,
            unknown: 0,
            started: now,
            now,
        }
    }

    /// The rules it follows.
    pub fn rules(&self) -> &Rules {
        &self.rules
    }

    /// The vehicle severity: the highest severity of the components' states.
    pub fn severity(&self) -> Severity {
        self.severity
    }

    /// The state of component `name`, if the rules name it.
    pub fn state(&self, name: &str) -> Option<ComponentState> {
        self.index.get(name).map(|&i| self.entries[i].state)
    }

    /// Every component and its state, in file order.
    pub fn components(&self) -> impl Iterator<Item = (&str, ComponentState)> + '_ {
        self.rules
            .components
            .iter()
            .zip(&self.entries)
            .map(|(c, e)| (&*c.name, e.state))
    }

    /// Every topic the data components watch, each once.
    pub fn watched_topics(&self) -> impl Iterator<Item = &str> + '_ {
        self.watchers.keys().map(String::as_str)
    }

    /// How many updates came from components the rules do not name.
    pub fn unknown_reports(&self) -> u64 {
        self.unknown
    }

    /// Takes an update: component `name` is in `state` at `now` (sent by the component itself or
    /// answering a poll). An update from a component the rules do not name is counted and
    /// otherwise ignored; a data component takes none (its data tells its state).
    pub fn report(&mut self, name: &str, state: ComponentState, now: Instant) -> Vec<Event> {
        self.now = self.now.max(now);
        let Some(&i) = self.index.get(name) else {
            self.unknown = self.unknown.saturating_add(1);
            return Vec::new();
        };
        if matches!(self.rules.components[i].mode, Mode::Data { .. }) {
            return Vec::new();
        }
        let entry = &mut self.entries[i];
        entry.last = entry.last.max(now);
        let mut events = Vec::new();
        self.set(i, state, Cause::Report, &mut events);
        self.update_severity(&mut events);
        events
    }

    /// Takes the link state of medium `medium`: its link components become HEALTHY when it is up
    /// and OFFLINE when it is down.
    pub fn link(&mut self, medium: &str, link: &LinkState, now: Instant) -> Vec<Event> {
        self.now = self.now.max(now);
        let state = match link {
            LinkState::Up => ComponentState::Healthy,
            LinkState::Down(_) => ComponentState::Offline,
        };
        let mut events = Vec::new();
        for i in 0..self.entries.len() {
            if matches!(&self.rules.components[i].mode, Mode::Link { medium: m } if m == medium) {
                let entry = &mut self.entries[i];
                entry.last = entry.last.max(now);
                entry.link_down = match link {
                    LinkState::Up => None,
                    LinkState::Down(why) => Some(why.to_string()),
                };
                self.set(i, state, Cause::Link, &mut events);
            }
        }
        self.update_severity(&mut events);
        events
    }

    /// Takes a message on `topic` at `now`: every data component watching it has heard it, and
    /// is HEALTHY again unless another of its topics is still silent. A topic no component
    /// watches changes nothing.
    pub fn data(&mut self, topic: &str, now: Instant) -> Vec<Event> {
        self.now = self.now.max(now);
        let mut events = Vec::new();
        let Some(places) = self.watchers.get(topic) else {
            return events;
        };
        let mut touched = Vec::with_capacity(places.len());
        for &(i, j) in places {
            let heard = &mut self.entries[i].heard[j];
            heard.last = Some(heard.last.map_or(now, |l| l.max(now)));
            heard.state = ComponentState::Healthy;
            touched.push(i);
        }
        for i in touched {
            let worst = self.entries[i].heard.iter().map(|h| h.state).max();
            self.set(
                i,
                worst.unwrap_or(ComponentState::Healthy),
                Cause::Data,
                &mut events,
            );
        }
        self.update_severity(&mut events);
        events
    }

    /// Advances to `now`: every timed component silent for its timeout or longer becomes
    /// OFFLINE, every data component takes the state of its most silent topic (UNAVAILABLE after
    /// `unavailable-after`, OFFLINE after `timeout`), and every passive component whose poll is
    /// due is asked for (at most one poll each per call; a late call does not catch up on missed
    /// polls).
    pub fn tick(&mut self, now: Instant) -> Vec<Event> {
        self.now = self.now.max(now);
        let mut events = Vec::new();
        let mut polls = Vec::new();
        for i in 0..self.entries.len() {
            let rule = &self.rules.components[i];
            let entry = &mut self.entries[i];
            let to = match &rule.mode {
                Mode::Passive { poll, timeout } => {
                    if let Some(due) = entry.next_poll
                        && now >= due
                    {
                        polls.push(Event::Poll {
                            component: rule.name.clone(),
                        });
                        let next = due.checked_add(*poll).filter(|&n| n > now);
                        entry.next_poll = next.or_else(|| now.checked_add(*poll));
                    }
                    expired(entry.last, *timeout, now).then_some(ComponentState::Offline)
                }
                Mode::Active { timeout } => {
                    expired(entry.last, *timeout, now).then_some(ComponentState::Offline)
                }
                Mode::Link { .. } => None,
                Mode::Data { topics } => {
                    for (t, h) in topics.iter().zip(&mut entry.heard) {
                        let since = h.last.unwrap_or(self.started);
                        h.state = t.state_after(now.saturating_duration_since(since));
                    }
                    entry.heard.iter().map(|h| h.state).max()
                }
            };
            if let Some(to) = to {
                let cause = if to > entry.state {
                    Cause::Timeout
                } else {
                    Cause::Data
                };
                self.set(i, to, cause, &mut events);
            }
        }
        self.update_severity(&mut events);
        events.append(&mut polls);
        events
    }

    /// The earliest time at which [`Monitor::tick`] would change something, if any: a timed
    /// component not yet OFFLINE reaching its timeout, a data component's topic reaching its next
    /// limit, or a poll falling due.
    pub fn next_due(&self) -> Option<Instant> {
        let data = |rule: &ComponentRule, entry: &Entry| -> Option<Instant> {
            let Mode::Data { topics } = &rule.mode else {
                return None;
            };
            topics
                .iter()
                .zip(&entry.heard)
                .filter_map(|(t, h)| {
                    let since = h.last.unwrap_or(self.started);
                    match h.state {
                        ComponentState::Healthy => since.checked_add(t.unavailable_after),
                        ComponentState::Offline => None,
                        _ => since.checked_add(t.timeout),
                    }
                })
                .min()
        };
        self.rules
            .components
            .iter()
            .zip(&self.entries)
            .flat_map(|(rule, entry)| {
                let deadline = match rule.mode {
                    Mode::Active { timeout } | Mode::Passive { timeout, .. } => (entry.state
                        != ComponentState::Offline)
                        .then(|| entry.last.checked_add(timeout))
                        .flatten(),
                    _ => data(rule, entry),
                };
                [deadline, entry.next_poll]
            })
            .flatten()
            .min()
    }

    /// Why component `name` is not HEALTHY, as of the latest time the monitor was given: the
    /// topics a data component has not heard for too long (`nav.position silent for 4.2 s`,
    /// `nav.attitude never received`), a link component's medium that is down, a timed
    /// component's silence. `None` for a HEALTHY component, and for a state its component reported
    /// itself (the report gives no reason).
    pub fn reason(&self, name: &str) -> Option<String> {
        let i = *self.index.get(name)?;
        let entry = &self.entries[i];
        if entry.state == ComponentState::Healthy {
            return None;
        }
        match &self.rules.components[i].mode {
            Mode::Data { topics } => {
                let silent: Vec<String> = topics
                    .iter()
                    .zip(&entry.heard)
                    .filter(|(_, h)| h.state != ComponentState::Healthy)
                    .map(|(t, h)| match h.last {
                        None => format!("{} never received", t.topic),
                        Some(at) => format!(
                            "{} silent for {}",
                            t.topic,
                            tenths(self.now.saturating_duration_since(at))
                        ),
                    })
                    .collect();
                (!silent.is_empty()).then(|| silent.join("; "))
            }
            Mode::Link { medium } => entry.link_down.as_ref().map(|why| match why.trim() {
                "" => format!("link {medium} down"),
                why => format!("link {medium} down: {why}"),
            }),
            Mode::Active { timeout } | Mode::Passive { timeout, .. } => {
                let silent = self.now.saturating_duration_since(entry.last);
                (entry.state == ComponentState::Offline && silent >= *timeout)
                    .then(|| format!("no update for {}", tenths(silent)))
            }
        }
    }

    /// The health snapshot to publish: `severity` (its name), `components` (a map of each
    /// component's name to its state's name, in file order), `reasons` (a map of each component
    /// that has a [reason](Monitor::reason) to it, in file order; empty when there is none) and
    /// `unknown` (updates from components the rules do not name).
    pub fn snapshot(&self) -> DataMap {
        let mut components = DataMap::with_capacity(self.entries.len());
        let mut reasons = DataMap::new();
        for (name, state) in self.components() {
            components.push(name.to_string(), Value::label(state.name()));
            if let Some(why) = self.reason(name) {
                reasons.push(name.to_string(), Value::from(why));
            }
        }
        DataMap::new()
            .and("severity", Value::label(self.severity.name()))
            .and("components", Value::Map(components))
            .and("reasons", Value::Map(reasons))
            .and(
                "unknown",
                Value::Int(i64::try_from(self.unknown).unwrap_or(i64::MAX)),
            )
    }

    fn set(&mut self, i: usize, to: ComponentState, cause: Cause, events: &mut Vec<Event>) {
        let entry = &mut self.entries[i];
        let from = entry.state;
        if from != to {
            entry.state = to;
            events.push(Event::State {
                component: self.rules.components[i].name.clone(),
                from,
                to,
                cause,
            });
        }
    }

    fn update_severity(&mut self, events: &mut Vec<Event>) {
        let to = self
            .rules
            .components
            .iter()
            .zip(&self.entries)
            .map(|(rule, entry)| rule.levels.get(entry.state))
            .max()
            .unwrap_or_default();
        let from = self.severity;
        if to == from {
            return;
        }
        self.severity = to;
        events.push(Event::Severity { from, to });
        if to == Severity::Emergency {
            events.push(Event::Emergency {
                action: self.rules.emergency_action.clone(),
            });
        }
    }
}

/// Whether a component last heard at `last` has been silent for `timeout` at `now`.
fn expired(last: Instant, timeout: Duration, now: Instant) -> bool {
    last.checked_add(timeout)
        .is_some_and(|deadline| now >= deadline)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks that each rules file is refused with its message ("accepted" when it is not).
    fn assert_refused_as<T: AsRef<str>>(cases: &[(T, &str)]) {
        let wrong: Vec<String> = cases
            .iter()
            .filter_map(|(text, expected)| {
                let text = text.as_ref();
                let got = match Rules::parse("health.xml", text) {
                    Ok(_) => "accepted".to_string(),
                    Err(e) => e.to_string(),
                };
                (got != *expected)
                    .then(|| format!("{text}\n  got:      {got}\n  expected: {expected}"))
            })
            .collect();
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }

    const STARFISH: &str = include_str!("../../../configs/starfish-health.xml");

    fn rules(text: &str) -> Rules {
        Rules::parse("health.xml", text).unwrap_or_else(|e| panic!("{e}"))
    }

    fn secs(s: f64) -> Duration {
        Duration::from_secs_f64(s)
    }

    fn state(component: &str, from: ComponentState, to: ComponentState, cause: Cause) -> Event {
        Event::State {
            component: Arc::from(component),
            from,
            to,
            cause,
        }
    }

    fn severity(from: Severity, to: Severity) -> Event {
        Event::Severity { from, to }
    }

    fn poll(component: &str) -> Event {
        Event::Poll {
            component: Arc::from(component),
        }
    }

    use ComponentState::{Healthy, Malfunction, Offline, Unavailable};

    #[test]
    fn errors_name_the_place_and_what_was_expected() {
        let cases = [
            (
                "<rules/>",
                "health.xml:1:1: root element is <rules>, expected <health>",
            ),
            (
                "<health>\n</health>",
                "health.xml:1:1: health rules need at least one <component>",
            ),
            (
                "<health colour=\"red\"><component name=\"A\"/></health>",
                "health.xml:1:9: unknown attribute `colour` on <health>; expected one of: publish, \
                 period, timeout, poll, emergency-action",
            ),
            (
                "<health>\n  <module name=\"A\"/>\n</health>",
                "health.xml:2:3: unexpected element <module> inside <health>; expected <component>, \
                 <severity>",
            ),
            (
                "<health>\n  <component mode=\"active\"/>\n</health>",
                "health.xml:2:3: <component> is missing attribute `name`",
            ),
            (
                "<health>\n  <component name=\"Depth Sensor\"/>\n</health>",
                "health.xml:2:14: attribute `name`: `Depth Sensor` is not a component name: use \
                 letters, digits, `_` and `-`",
            ),
            (
                "<health>\n  <component name=\"A\"/>\n  <component name=\"A\"/>\n</health>",
                "health.xml:3:14: attribute `name`: a component `A` is already defined at line 2",
            ),
            (
                "<health>\n  <component name=\"A\" mode=\"sleepy\"/>\n</health>",
                "health.xml:2:23: attribute `mode`: `sleepy` is not a mode: active, passive, link \
                 or data",
            ),
            (
                "<health>\n  <component name=\"A\" timeout=\"soon\"/>\n</health>",
                "health.xml:2:23: attribute `timeout`: `soon` is not a duration above zero (250ms, \
                 2s, 1min; a bare number is milliseconds)",
            ),
            (
                "<health>\n  <component name=\"A\" timeout=\"0s\"/>\n</health>",
                "health.xml:2:23: attribute `timeout`: `0s` is not a duration above zero (250ms, \
                 2s, 1min; a bare number is milliseconds)",
            ),
            (
                "<health>\n  <component name=\"A\" poll=\"1s\"/>\n</health>",
                "health.xml:2:23: attribute `poll`: only a passive component is polled; this one is \
                 active",
            ),
            (
                "<health>\n  <component name=\"A\" mode=\"passive\" poll=\"2s\" timeout=\"2s\"/>\n</health>",
                "health.xml:2:48: the timeout 2s must be longer than the poll period 2s, or the \
                 component goes OFFLINE between polls",
            ),
            (
                "<health>\n  <component name=\"A\" mode=\"passive\" poll=\"5s\"/>\n</health>",
                "health.xml:2:38: the timeout (the default) 3s must be longer than the poll period \
                 5s, or the component goes OFFLINE between polls",
            ),
            (
                "<health poll=\"4s\">\n  <component name=\"A\" mode=\"passive\"/>\n</health>",
                "health.xml:2:3: the timeout (the default) 3s must be longer than the poll period \
                 4s, or the component goes OFFLINE between polls",
            ),
            (
                "<health>\n  <component name=\"A\" medium=\"serial\"/>\n</health>",
                "health.xml:2:23: attribute `medium`: only a `link` component follows a medium; \
                 this one is active",
            ),
            (
                "<health>\n  <component name=\"A\" mode=\"link\"/>\n</health>",
                "health.xml:2:3: <component> is missing attribute `medium`",
            ),
            (
                "<health>\n  <component name=\"A\" mode=\"link\" medium=\"s\" timeout=\"1s\"/>\n</health>",
                "health.xml:2:46: attribute `timeout`: a link component has no timeout and is not \
                 polled: it follows its medium",
            ),
            (
                "<health>\n  <component name=\"A\">\n    <severity state=\"SICK\" level=\"WARN\"/>\n  </component>\n</health>",
                "health.xml:3:15: attribute `state`: `SICK` is not a component state: HEALTHY, \
                 UNAVAILABLE, MALFUNCTION or OFFLINE",
            ),
            (
                "<health>\n  <component name=\"A\">\n    <severity state=\"OFFLINE\" level=\"PANIC\"/>\n  </component>\n</health>",
                "health.xml:3:31: attribute `level`: `PANIC` is not a severity: NONE, WARN, ABORT \
                 or EMERGENCY",
            ),
            (
                "<health>\n  <component name=\"A\">\n    <severity state=\"OFFLINE\"/>\n  </component>\n</health>",
                "health.xml:3:5: <severity> is missing attribute `level`",
            ),
            (
                "<health>\n  <component name=\"A\">\n    <severity state=\"OFFLINE\" level=\"WARN\"/>\n    <severity state=\"offline\" level=\"ABORT\"/>\n  </component>\n</health>",
                "health.xml:4:5: state OFFLINE already has a severity at line 3",
            ),
            (
                "<health>\n  <severity state=\"HEALTHY\" level=\"WARN\"/>\n  <component name=\"A\"/>\n</health>",
                "health.xml:2:29: attribute `level`: a HEALTHY component has severity NONE, always",
            ),
            (
                "<health>\n  <component name=\"A\">\n    <severity state=\"OFFLINE\" level=\"WARN\"><x/></severity>\n  </component>\n</health>",
                "health.xml:3:44: unexpected element <x> inside <severity>; expected no elements",
            ),
            (
                "<health publish=\"vehicle..health\"><component name=\"A\"/></health>",
                "health.xml:1:9: attribute `publish`: empty segment in \"vehicle..health\" (two dots in a \
                 row, or a dot at an end)",
            ),
            (
                "<health emergency-action=\"\"><component name=\"A\"/></health>",
                "health.xml:1:9: attribute `emergency-action`: expected a topic and then \
                 `key=value` fields",
            ),
            (
                "<health emergency-action=\"cmd.stop now\"><component name=\"A\"/></health>",
                "health.xml:1:9: attribute `emergency-action`: `now` is not key=value",
            ),
            (
                "<health emergency-action=\"cmd.stop a=1 a=2\"><component name=\"A\"/></health>",
                "health.xml:1:9: attribute `emergency-action`: field `a` is given twice",
            ),
            (
                "<health emergency-action='cmd.stop why=\"no depth'><component name=\"A\"/></health>",
                "health.xml:1:9: attribute `emergency-action`: a double quote `\"` is not closed",
            ),
            (
                "<health>\n  <component name=\"A\">",
                "health.xml:2:23: file ends inside <component> opened at line 2",
            ),
        ];
        assert_refused_as(&cases);
    }

    #[test]
    fn defaults_fill_what_the_file_leaves_out() {
        let r = rules(
            r#"<health>
  <component name="A"/>
  <component name="B" mode="passive"/>
  <component name="C" mode="link" medium="serial"/>
</health>"#,
        );
        assert_eq!(r.publish.as_str(), DEFAULT_PUBLISH);
        assert_eq!(r.period, DEFAULT_PERIOD);
        assert_eq!(r.emergency_action, None);
        assert_eq!(
            r.components.iter().map(|c| &c.mode).collect::<Vec<_>>(),
            [
                &Mode::Active {
                    timeout: DEFAULT_TIMEOUT
                },
                &Mode::Passive {
                    poll: DEFAULT_POLL,
                    timeout: DEFAULT_TIMEOUT
                },
                &Mode::Link {
                    medium: "serial".to_string()
                },
            ]
        );
        let a = r.component("A").unwrap();
        let levels: Vec<Severity> = ComponentState::ALL
            .iter()
            .map(|&s| a.levels.get(s))
            .collect();
        assert_eq!(
            levels,
            [
                Severity::None,
                Severity::Warn,
                Severity::Abort,
                Severity::Abort
            ]
        );
        assert_eq!((a.pos.line, a.pos.col), (2, 3));
    }

    #[test]
    fn the_root_sets_defaults_and_components_override_them() {
        let r = rules(
            r#"<health publish="auv1.health" period="250ms" timeout="5s" poll="2s"
        emergency-action='cmd.emergency ballast=drop depth=0 hold=2.5 sos=true why="no depth" code="7"'>
  <severity state="unavailable" level="none"/>
  <severity state="OFFLINE" level="EMERGENCY"/>
  <component name="A" mode="passive"/>
  <component name="B" timeout="1s">
    <severity state="OFFLINE" level="WARN"/>
    <severity state="HEALTHY" level="NONE"/>
  </component>
</health>"#,
        );
        assert_eq!(r.publish.as_str(), "auv1.health");
        assert_eq!(r.period, Duration::from_millis(250));
        let action = r.emergency_action.as_ref().unwrap();
        assert_eq!(action.topic.as_str(), "cmd.emergency");
        let fields: Vec<(&str, &Value)> = action.fields.iter().collect();
        assert_eq!(
            fields,
            [
                ("ballast", &Value::from("drop")),
                ("depth", &Value::Int(0)),
                ("hold", &Value::Float(2.5)),
                ("sos", &Value::Bool(true)),
                ("why", &Value::from("no depth")),
                ("code", &Value::from("7")),
            ]
        );
        let a = r.component("A").unwrap();
        assert_eq!(
            a.mode,
            Mode::Passive {
                poll: secs(2.0),
                timeout: secs(5.0)
            }
        );
        assert_eq!(a.levels.get(Unavailable), Severity::None);
        assert_eq!(a.levels.get(Malfunction), Severity::Abort);
        assert_eq!(a.levels.get(Offline), Severity::Emergency);
        let b = r.component("B").unwrap();
        assert_eq!(b.mode, Mode::Active { timeout: secs(1.0) });
        assert_eq!(b.levels.get(Unavailable), Severity::None);
        assert_eq!(b.levels.get(Offline), Severity::Warn);
    }

    #[test]
    fn names_and_codes_read_back() {
        for (i, s) in ComponentState::ALL.into_iter().enumerate() {
            assert_eq!(s.code() as usize, i);
            assert_eq!(ComponentState::from_code(i as i64), Some(s));
            assert_eq!(s.name().to_lowercase().parse(), Ok(s));
            assert_eq!(s.to_string(), s.name());
        }
        assert_eq!(ComponentState::from_code(4), None);
        assert_eq!(ComponentState::from_code(-1), None);
        for (i, l) in Severity::ALL.into_iter().enumerate() {
            assert_eq!(l.code() as usize, i);
            assert_eq!(l.name().parse(), Ok(l));
        }
        assert!(Healthy < Unavailable && Unavailable < Malfunction && Malfunction < Offline);
        assert!(Severity::None < Severity::Warn && Severity::Abort < Severity::Emergency);
    }

    const SENSOR: &str = r#"<health>
  <component name="DepthSensor" timeout="2s">
    <severity state="OFFLINE" level="ABORT"/>
  </component>
  <component name="Logging" timeout="10s"/>
</health>"#;

    #[test]
    fn a_silent_component_goes_offline_exactly_at_its_timeout() {
        let t0 = Instant::now();
        let mut m = Monitor::new(rules(SENSOR), t0);
        assert_eq!(m.severity(), Severity::None);
        assert_eq!(m.report("DepthSensor", Healthy, t0 + secs(1.0)), []);
        assert_eq!(m.next_due(), Some(t0 + secs(3.0)));
        assert_eq!(m.tick(t0 + secs(2.999)), []);
        assert_eq!(m.state("DepthSensor"), Some(Healthy));
        assert_eq!(
            m.tick(t0 + secs(3.0)),
            [
                state("DepthSensor", Healthy, Offline, Cause::Timeout),
                severity(Severity::None, Severity::Abort),
            ]
        );
        assert_eq!(m.state("DepthSensor"), Some(Offline));
        assert_eq!(m.severity(), Severity::Abort);
        // it stays OFFLINE without saying so again
        assert_eq!(m.tick(t0 + secs(4.0)), []);
        assert_eq!(m.next_due(), Some(t0 + secs(10.0)), "only Logging is timed");

        // it speaks again: HEALTHY, and the severity comes back down
        assert_eq!(
            m.report("DepthSensor", Healthy, t0 + secs(5.0)),
            [
                state("DepthSensor", Offline, Healthy, Cause::Report),
                severity(Severity::Abort, Severity::None),
            ]
        );
        assert_eq!(m.tick(t0 + secs(6.999)), []);
        assert_eq!(m.severity(), Severity::None);
        assert_eq!(
            m.tick(t0 + secs(7.0)).len(),
            2,
            "a fresh timeout from t=5 s"
        );
    }

    #[test]
    fn the_severity_is_the_worst_of_the_components() {
        let t0 = Instant::now();
        let mut m = Monitor::new(rules(SENSOR), t0);
        assert_eq!(
            m.report("Logging", Unavailable, t0),
            [
                state("Logging", Healthy, Unavailable, Cause::Report),
                severity(Severity::None, Severity::Warn),
            ]
        );
        assert_eq!(
            m.report("DepthSensor", Malfunction, t0),
            [
                state("DepthSensor", Healthy, Malfunction, Cause::Report),
                severity(Severity::Warn, Severity::Abort),
            ]
        );
        // the same state again is no change
        assert_eq!(m.report("DepthSensor", Malfunction, t0 + secs(1.0)), []);
        assert_eq!(
            m.report("DepthSensor", Healthy, t0 + secs(1.0)),
            [
                state("DepthSensor", Malfunction, Healthy, Cause::Report),
                severity(Severity::Abort, Severity::Warn),
            ]
        );
        assert_eq!(
            m.report("Logging", Healthy, t0 + secs(1.0)),
            [
                state("Logging", Unavailable, Healthy, Cause::Report),
                severity(Severity::Warn, Severity::None),
            ]
        );
    }

    #[test]
    fn unknown_components_are_ignored_and_counted() {
        let t0 = Instant::now();
        let mut m = Monitor::new(rules(SENSOR), t0);
        assert_eq!(m.report("Sonar", Offline, t0), []);
        assert_eq!(m.report("depthsensor", Malfunction, t0), []);
        assert_eq!(m.unknown_reports(), 2);
        assert_eq!(m.severity(), Severity::None);
        assert_eq!(
            m.components().collect::<Vec<_>>(),
            [("DepthSensor", Healthy), ("Logging", Healthy)]
        );
        assert_eq!(m.state("Sonar"), None);
    }

    const CRITICAL: &str = r#"<health emergency-action="cmd.emergency ballast=drop">
  <component name="Elevators" timeout="1s">
    <severity state="OFFLINE" level="EMERGENCY"/>
    <severity state="MALFUNCTION" level="EMERGENCY"/>
  </component>
  <component name="Filter" timeout="1s">
    <severity state="OFFLINE" level="EMERGENCY"/>
  </component>
</health>"#;

    fn emergencies(events: &[Event]) -> usize {
        events
            .iter()
            .filter(|e| matches!(e, Event::Emergency { .. }))
            .count()
    }

    #[test]
    fn the_emergency_action_fires_once_per_entry() {
        let t0 = Instant::now();
        let r = rules(CRITICAL);
        let action = r.emergency_action.clone();
        assert!(action.is_some());
        let mut m = Monitor::new(r, t0);
        m.report("Filter", Healthy, t0 + secs(0.5));
        let events = m.tick(t0 + secs(1.0));
        assert_eq!(
            events,
            [
                state("Elevators", Healthy, Offline, Cause::Timeout),
                severity(Severity::None, Severity::Emergency),
                Event::Emergency {
                    action: action.clone()
                },
            ]
        );
        // later ticks and a second component in trouble keep EMERGENCY without a second action
        let mut later = Vec::new();
        for ms in (1100..5000).step_by(100) {
            later.extend(m.tick(t0 + Duration::from_millis(ms)));
        }
        assert_eq!(
            later,
            [state("Filter", Healthy, Offline, Cause::Timeout)],
            "the filter times out at 1.5 s; the severity was EMERGENCY already"
        );
        // one recovers: still EMERGENCY, nothing fires
        let events = m.report("Elevators", Healthy, t0 + secs(5.0));
        assert_eq!(
            events,
            [state("Elevators", Offline, Healthy, Cause::Report)]
        );
        // both recover: the severity leaves EMERGENCY
        let events = m.report("Filter", Healthy, t0 + secs(5.0));
        assert_eq!(emergencies(&events), 0);
        assert_eq!(m.severity(), Severity::None);
        // and the next entry fires again, once
        let events = m.report("Elevators", Malfunction, t0 + secs(5.5));
        assert_eq!(emergencies(&events), 1);
        assert_eq!(
            emergencies(&m.report("Elevators", Malfunction, t0 + secs(5.6))),
            0
        );
        assert_eq!(emergencies(&m.tick(t0 + secs(10.0))), 0);
    }

    #[test]
    fn an_emergency_without_an_action_still_says_so() {
        let t0 = Instant::now();
        let text = CRITICAL.replace(" emergency-action=\"cmd.emergency ballast=drop\"", "");
        let mut m = Monitor::new(rules(&text), t0);
        let events = m.report("Filter", Offline, t0);
        assert_eq!(events.last(), Some(&Event::Emergency { action: None }));
    }

    #[test]
    fn passive_components_are_polled_at_their_period() {
        let t0 = Instant::now();
        let mut m = Monitor::new(
            rules(
                r#"<health>
  <component name="GPS" mode="passive" poll="1s" timeout="3s"/>
  <component name="Compass" mode="passive" poll="400ms" timeout="1s"/>
  <component name="Thruster"/>
</health>"#,
            ),
            t0,
        );
        assert_eq!(m.next_due(), Some(t0), "the first polls are due at once");
        assert_eq!(m.tick(t0), [poll("GPS"), poll("Compass")]);
        assert_eq!(m.next_due(), Some(t0 + secs(0.4)));
        let mut asked: Vec<(u64, String)> = Vec::new();
        for ms in (100..=2000).step_by(100) {
            let now = t0 + Duration::from_millis(ms);
            for e in m.tick(now) {
                if let Event::Poll { component } = e {
                    m.report(&component, Healthy, now);
                    asked.push((ms, component.to_string()));
                }
            }
        }
        let asked: Vec<(u64, &str)> = asked.iter().map(|(t, c)| (*t, c.as_str())).collect();
        assert_eq!(
            asked,
            [
                (400, "Compass"),
                (800, "Compass"),
                (1000, "GPS"),
                (1200, "Compass"),
                (1600, "Compass"),
                (2000, "GPS"),
                (2000, "Compass"),
            ]
        );
        assert_eq!(m.severity(), Severity::None, "every poll was answered");

        // a late tick asks once and does not catch up on the polls it missed
        let events = m.tick(t0 + secs(10.0));
        let polls: Vec<&Event> = events
            .iter()
            .filter(|e| matches!(e, Event::Poll { .. }))
            .collect();
        assert_eq!(polls, [&poll("GPS"), &poll("Compass")]);
        assert_eq!(m.next_due(), Some(t0 + secs(10.4)));
        // unanswered, the polled components went OFFLINE
        assert_eq!(m.state("GPS"), Some(Offline));
        assert_eq!(m.state("Thruster"), Some(Offline));
    }

    #[test]
    fn an_unanswered_poll_leaves_the_component_offline_after_its_timeout() {
        let t0 = Instant::now();
        let mut m = Monitor::new(
            rules(
                r#"<health><component name="GPS" mode="passive" poll="1s" timeout="3s"/></health>"#,
            ),
            t0,
        );
        m.report("GPS", Healthy, t0);
        let mut offline_at = None;
        for ms in (0..=4000).step_by(250) {
            let now = t0 + Duration::from_millis(ms);
            for e in m.tick(now) {
                if let Event::State { to: Offline, .. } = e {
                    offline_at = Some(ms);
                }
            }
        }
        assert_eq!(offline_at, Some(3000));
        assert_eq!(m.severity(), Severity::Abort);
    }

    #[test]
    fn link_components_follow_their_medium() {
        let t0 = Instant::now();
        let mut m = Monitor::new(
            rules(
                r#"<health>
  <component name="Frontseat" mode="link" medium="serial">
    <severity state="OFFLINE" level="WARN"/>
  </component>
  <component name="Modem" mode="link" medium="acoustic"/>
</health>"#,
            ),
            t0,
        );
        assert_eq!(m.next_due(), None, "nothing is timed");
        assert_eq!(m.tick(t0 + secs(1000.0)), []);
        let down = LinkState::Down("no such device".into());
        assert_eq!(
            m.link("serial", &down, t0),
            [
                state("Frontseat", Healthy, Offline, Cause::Link),
                severity(Severity::None, Severity::Warn),
            ]
        );
        assert_eq!(m.link("other", &down, t0), []);
        assert_eq!(m.state("Modem"), Some(Healthy));
        assert_eq!(
            m.link("serial", &LinkState::Up, t0),
            [
                state("Frontseat", Offline, Healthy, Cause::Link),
                severity(Severity::Warn, Severity::None),
            ]
        );
    }

    #[test]
    fn the_snapshot_names_the_severity_and_every_state() {
        let t0 = Instant::now();
        let mut m = Monitor::new(rules(SENSOR), t0);
        m.report("DepthSensor", Unavailable, t0);
        m.report("Ghost", Healthy, t0);
        let snap = m.snapshot();
        assert_eq!(snap.get_str("severity"), Some("WARN"));
        assert_eq!(snap.get_i64("unknown"), Some(1));
        let components = snap.get("components").and_then(Value::as_map).unwrap();
        let states: Vec<(&str, Option<&str>)> =
            components.iter().map(|(k, v)| (k, v.as_str())).collect();
        assert_eq!(
            states,
            [
                ("DepthSensor", Some("UNAVAILABLE")),
                ("Logging", Some("HEALTHY"))
            ]
        );
        assert_eq!(
            snap.get_path("components.DepthSensor")
                .and_then(Value::as_str),
            Some("UNAVAILABLE")
        );
    }

    #[test]
    fn the_starfish_example_loads_and_reacts() {
        let r = rules(STARFISH);
        let names: Vec<(&str, &str)> = r
            .components
            .iter()
            .map(|c| (&*c.name, c.mode.name()))
            .collect();
        assert_eq!(
            names,
            [
                ("Logging", "passive"),
                ("Elevators", "active"),
                ("DepthSensor", "active"),
                ("DepthFilter", "active"),
                ("MyDepthController", "passive"),
            ]
        );
        let action = r.emergency_action.clone().unwrap();
        assert_eq!(action.topic.as_str(), "cmd.emergency");
        assert_eq!(action.fields.get_bool("sos"), Some(true));
        assert_eq!(action.fields.get_str("reason"), Some("health emergency"));

        // the depth sensor falls silent at 0.9 s; the filter coasts, then has no depth from 2 s
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut m = Monitor::new(r, t0);
        assert_eq!(m.tick(t0), [poll("Logging"), poll("MyDepthController")]);
        let others = ["Logging", "Elevators", "MyDepthController"];
        for ms in (0..=2800).step_by(100) {
            for c in others {
                m.report(c, Healthy, at(ms));
            }
            if ms <= 900 {
                m.report("DepthSensor", Healthy, at(ms));
            }
            let filter = if ms < 2000 { Healthy } else { Unavailable };
            m.report("DepthFilter", filter, at(ms));
            m.tick(at(ms));
            let expected = if ms < 2000 {
                Severity::None
            } else {
                Severity::Abort
            };
            assert_eq!(m.severity(), expected, "at {ms} ms");
        }
        // the sensor's 2 s run out: OFFLINE is ABORT, no worse than what the filter says
        assert_eq!(
            m.tick(at(2900)),
            [state("DepthSensor", Healthy, Offline, Cause::Timeout)]
        );
        // the filter falls silent too: OFFLINE is EMERGENCY, and the action goes out once
        for ms in (3000..=4700).step_by(100) {
            for c in others {
                m.report(c, Healthy, at(ms));
            }
            assert_eq!(emergencies(&m.tick(at(ms))), 0);
        }
        for c in others {
            m.report(c, Healthy, at(4800));
        }
        assert_eq!(
            m.tick(at(4800)),
            [
                state("DepthFilter", Unavailable, Offline, Cause::Timeout),
                severity(Severity::Abort, Severity::Emergency),
                Event::Emergency {
                    action: Some(action)
                },
            ]
        );
        assert_eq!(
            m.snapshot()
                .get_path("components.DepthFilter")
                .and_then(Value::as_str),
            Some("OFFLINE")
        );
    }

    #[test]
    fn data_rule_errors_name_the_place_and_what_was_expected() {
        let comp = |inner: &str| format!("<health>\n  {inner}\n</health>");
        let cases = [
            (
                comp(r#"<component name="Nav" mode="data"/>"#),
                "health.xml:2:3: a data component needs at least one <data topic=\"…\" \
                 period=\"…\"/>: the topics it publishes",
            ),
            (
                comp(r#"<component name="Nav" period="1s"/>"#),
                "health.xml:2:25: attribute `period`: only a `data` component watches topics; \
                 this one is active",
            ),
            (
                comp(r#"<component name="Nav" mode="passive" unavailable-after="1s"/>"#),
                "health.xml:2:40: attribute `unavailable-after`: only a `data` component watches \
                 topics; this one is passive",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"link\" medium=\"serial\">\n    \
                     <data topic=\"nav.position\" period=\"1s\"/>\n  </component>",
                ),
                "health.xml:3:5: <data>: only a `data` component watches topics; this one is link",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\" poll=\"1s\">\n    \
                     <data topic=\"nav.position\" period=\"1s\"/>\n  </component>",
                ),
                "health.xml:2:37: attribute `poll`: only a passive component is polled; this one \
                 is data",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\">\n    \
                     <data topic=\"nav.position\"/>\n  </component>",
                ),
                "health.xml:3:5: <data> needs `period`, the expected time between two messages on \
                 its topic (on it or on its <component>)",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\">\n    \
                     <data topic=\"nav.position\" period=\"often\"/>\n  </component>",
                ),
                "health.xml:3:32: attribute `period`: `often` is not a duration above zero (250ms, \
                 2s, 1min; a bare number is milliseconds)",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\">\n    \
                     <data topic=\"nav.*\" period=\"1s\"/>\n  </component>",
                ),
                "health.xml:3:11: attribute `topic`: character '*' not allowed in \"nav.*\"",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\">\n    \
                     <data topic=\"nav.position\" rate=\"4Hz\"/>\n  </component>",
                ),
                "health.xml:3:32: unknown attribute `rate` on <data>; expected one of: topic, \
                 period, unavailable-after, timeout",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\" period=\"250ms\">\n    \
                     <data topic=\"nav.position\"/>\n    <data topic=\"nav.position\"/>\n  \
                     </component>",
                ),
                "health.xml:4:11: attribute `topic`: topic `nav.position` is already watched by \
                 this component at line 3",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\">\n    \
                     <data topic=\"nav.position\" period=\"1s\" unavailable-after=\"1s\"/>\n  \
                     </component>",
                ),
                "health.xml:3:44: unavailable-after 1s must be longer than the period 1s, or the \
                 component is UNAVAILABLE between two messages",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\">\n    \
                     <data topic=\"vehicle.state\" period=\"1s\"/>\n  </component>",
                ),
                "health.xml:3:33: the timeout (the default) 3s must be longer than \
                 unavailable-after (four periods) 4s, or the component goes OFFLINE before it is \
                 UNAVAILABLE",
            ),
            (
                comp(
                    "<component name=\"Nav\" mode=\"data\" timeout=\"2s\">\n    \
                     <data topic=\"nav.position\" period=\"250ms\" unavailable-after=\"2s\"/>\n  \
                     </component>",
                ),
                "health.xml:2:37: the timeout 2s must be longer than unavailable-after 2s, or the \
                 component goes OFFLINE before it is UNAVAILABLE",
            ),
        ];
        assert_refused_as(&cases);
    }

    const NAV: &str = r#"<health timeout="5s">
  <component name="Navigation" mode="data" period="250ms" timeout="3s">
    <data topic="nav.position"/>
    <data topic="nav.attitude" unavailable-after="1500ms"/>
  </component>
  <component name="VehicleState" mode="data">
    <data topic="vehicle.state" period="1s" unavailable-after="2s"/>
  </component>
  <component name="DVL" mode="data">
    <data topic="nav.dvl" period="200ms" timeout="2s"/>
    <severity state="OFFLINE" level="WARN"/>
  </component>
</health>"#;

    fn data_topic(topic: &str, period: f64, unavailable: f64, timeout: f64) -> DataTopic {
        DataTopic {
            topic: Topic::new(topic).unwrap(),
            period: secs(period),
            unavailable_after: secs(unavailable),
            timeout: secs(timeout),
        }
    }

    #[test]
    fn data_topics_take_their_component_s_limits_and_four_periods() {
        let r = rules(NAV);
        let modes: Vec<&Mode> = r.components.iter().map(|c| &c.mode).collect();
        assert_eq!(
            modes,
            [
                &Mode::Data {
                    topics: vec![
                        data_topic("nav.position", 0.25, 1.0, 3.0),
                        data_topic("nav.attitude", 0.25, 1.5, 3.0),
                    ]
                },
                &Mode::Data {
                    topics: vec![data_topic("vehicle.state", 1.0, 2.0, 5.0)]
                },
                &Mode::Data {
                    topics: vec![data_topic("nav.dvl", 0.2, 0.8, 2.0)]
                },
            ]
        );
        assert_eq!(r.components[0].mode.name(), "data");
        assert_eq!(r.components[0].mode.timeout(), Some(secs(3.0)));
        let m = Monitor::new(r, Instant::now());
        let mut watched: Vec<&str> = m.watched_topics().collect();
        watched.sort_unstable();
        assert_eq!(
            watched,
            ["nav.attitude", "nav.dvl", "nav.position", "vehicle.state"]
        );
    }

    /// Every watched topic heard at `at`.
    fn all_data(m: &mut Monitor, at: Instant) {
        for t in ["nav.position", "nav.attitude", "vehicle.state", "nav.dvl"] {
            m.data(t, at);
        }
    }

    fn reasons(m: &Monitor) -> Vec<(String, String)> {
        let snap = m.snapshot();
        let map = snap.get("reasons").and_then(Value::as_map).unwrap();
        map.iter()
            .map(|(k, v)| (k.to_string(), v.as_str().unwrap().to_string()))
            .collect()
    }

    /// The state and the DVL heard at `at`: only the navigation is watched for silence.
    fn others(m: &mut Monitor, at: Instant) {
        assert_eq!(m.data("vehicle.state", at), []);
        assert_eq!(m.data("nav.dvl", at), []);
    }

    #[test]
    fn a_silent_topic_makes_its_component_unavailable_then_offline_and_data_brings_it_back() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut m = Monitor::new(rules(NAV), t0);
        // everything flows for 2 s
        for ms in (0..=2000).step_by(250) {
            all_data(&mut m, at(ms));
            assert_eq!(m.tick(at(ms)), [], "at {ms} ms");
        }
        assert_eq!(reasons(&m), []);
        // the position stops at 2 s; the attitude goes on until 2.75 s
        for ms in (2250..=2750).step_by(250) {
            assert_eq!(m.data("nav.attitude", at(ms)), []);
            others(&mut m, at(ms));
        }
        assert_eq!(m.next_due(), Some(at(3000)), "position: 1 s after 2 s");
        assert_eq!(m.tick(at(2999)), []);
        others(&mut m, at(3000));
        assert_eq!(
            m.tick(at(3000)),
            [
                state("Navigation", Healthy, Unavailable, Cause::Timeout),
                severity(Severity::None, Severity::Warn),
            ]
        );
        assert_eq!(
            m.reason("Navigation").as_deref(),
            Some("nav.position silent for 1.0 s")
        );
        // the reason measures the silence up to the latest step
        others(&mut m, at(4000));
        assert_eq!(m.data("nav.attitude", at(4230)), []);
        assert_eq!(
            reasons(&m),
            [(
                "Navigation".to_string(),
                "nav.position silent for 2.2 s".to_string()
            )]
        );
        assert_eq!(m.next_due(), Some(at(4800)), "the DVL, heard at 4 s");
        others(&mut m, at(4900));
        assert_eq!(m.next_due(), Some(at(5000)), "position: 3 s after 2 s");
        assert_eq!(
            m.tick(at(5000)),
            [
                state("Navigation", Unavailable, Offline, Cause::Timeout),
                severity(Severity::Warn, Severity::Abort),
            ]
        );
        let snap = m.snapshot();
        assert_eq!(snap.get_str("severity"), Some("ABORT"));
        assert_eq!(
            snap.get_path("components.Navigation")
                .and_then(Value::as_str),
            Some("OFFLINE")
        );
        // the attitude stopped at 4.23 s: both are named, in file order
        others(&mut m, at(5700));
        assert_eq!(
            m.tick(at(5730)),
            [],
            "the attitude is UNAVAILABLE, the component already OFFLINE"
        );
        assert_eq!(
            m.reason("Navigation").as_deref(),
            Some("nav.position silent for 3.7 s; nav.attitude silent for 1.5 s")
        );
        // the position is back: the attitude still keeps the component UNAVAILABLE
        assert_eq!(
            m.data("nav.position", at(5800)),
            [
                state("Navigation", Offline, Unavailable, Cause::Data),
                severity(Severity::Abort, Severity::Warn),
            ]
        );
        assert_eq!(
            m.reason("Navigation").as_deref(),
            Some("nav.attitude silent for 1.6 s")
        );
        assert_eq!(
            m.data("nav.attitude", at(5900)),
            [
                state("Navigation", Unavailable, Healthy, Cause::Data),
                severity(Severity::Warn, Severity::None),
            ]
        );
        assert_eq!(reasons(&m), []);
        assert_eq!(m.reason("Navigation"), None);
        // a fresh limit from the new message
        others(&mut m, at(6500));
        assert_eq!(m.tick(at(6799)), []);
        assert_eq!(
            m.tick(at(6800)),
            [
                state("Navigation", Healthy, Unavailable, Cause::Timeout),
                severity(Severity::None, Severity::Warn),
            ],
            "position: 1 s after 5.8 s"
        );
    }

    #[test]
    fn a_topic_never_heard_is_silent_since_the_start() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut m = Monitor::new(rules(NAV), t0);
        assert_eq!(
            m.next_due(),
            Some(at(800)),
            "the DVL: four periods of 200 ms"
        );
        for ms in (0..=700).step_by(100) {
            assert_eq!(m.tick(at(ms)), [], "at {ms} ms");
        }
        assert_eq!(
            m.tick(at(800)),
            [
                state("DVL", Healthy, Unavailable, Cause::Timeout),
                severity(Severity::None, Severity::Warn),
            ]
        );
        assert_eq!(m.reason("DVL").as_deref(), Some("nav.dvl never received"));
        assert_eq!(
            m.tick(at(1000)),
            [state("Navigation", Healthy, Unavailable, Cause::Timeout)]
        );
        assert_eq!(
            m.reason("Navigation").as_deref(),
            Some("nav.position never received")
        );
        assert_eq!(
            m.tick(at(1500)),
            [],
            "the attitude too, the component already UNAVAILABLE"
        );
        assert_eq!(
            m.reason("Navigation").as_deref(),
            Some("nav.position never received; nav.attitude never received")
        );
        // the DVL's OFFLINE is only a warning; the navigation's is an abort
        assert_eq!(
            m.tick(at(2000)),
            [
                state("VehicleState", Healthy, Unavailable, Cause::Timeout),
                state("DVL", Unavailable, Offline, Cause::Timeout),
            ]
        );
        assert_eq!(m.severity(), Severity::Warn);
        assert_eq!(
            m.tick(at(3000)),
            [
                state("Navigation", Unavailable, Offline, Cause::Timeout),
                severity(Severity::Warn, Severity::Abort),
            ]
        );
        assert_eq!(
            reasons(&m),
            [
                (
                    "Navigation".to_string(),
                    "nav.position never received; nav.attitude never received".to_string()
                ),
                (
                    "VehicleState".to_string(),
                    "vehicle.state never received".to_string()
                ),
                ("DVL".to_string(), "nav.dvl never received".to_string()),
            ]
        );
        // the first message of a topic is enough for it
        assert_eq!(
            m.data("nav.dvl", at(3100)),
            [state("DVL", Offline, Healthy, Cause::Data)]
        );
    }

    #[test]
    fn a_data_component_takes_no_reports_and_topics_may_be_shared() {
        let t0 = Instant::now();
        let mut m = Monitor::new(
            rules(
                r#"<health>
  <component name="Navigation" mode="data">
    <data topic="nav.position" period="250ms"/>
  </component>
  <component name="Fix" mode="data">
    <data topic="nav.position" period="500ms" unavailable-after="1s" timeout="2s"/>
  </component>
</health>"#,
            ),
            t0,
        );
        assert_eq!(m.report("Navigation", Offline, t0), []);
        assert_eq!(m.state("Navigation"), Some(Healthy));
        assert_eq!(m.unknown_reports(), 0, "a named component is not unknown");
        assert_eq!(m.tick(t0 + secs(1.0)).len(), 3, "both UNAVAILABLE, WARN");
        assert_eq!(
            m.data("nav.position", t0 + secs(1.5)),
            [
                state("Navigation", Unavailable, Healthy, Cause::Data),
                state("Fix", Unavailable, Healthy, Cause::Data),
                severity(Severity::Warn, Severity::None),
            ]
        );
        assert_eq!(m.data("nav.velocity", t0 + secs(1.5)), [], "not watched");
    }

    #[test]
    fn links_and_timed_components_give_their_reasons_too() {
        let t0 = Instant::now();
        let mut m = Monitor::new(
            rules(
                r#"<health>
  <component name="Frontseat" mode="link" medium="serial"/>
  <component name="Sensors" mode="link" medium="sensors"/>
  <component name="Depth" timeout="2s"/>
  <component name="Sonar"/>
</health>"#,
            ),
            t0,
        );
        m.link("serial", &LinkState::Down("no such device".into()), t0);
        m.link("sensors", &LinkState::Down(String::new()), t0);
        m.report("Sonar", Malfunction, t0);
        m.tick(t0 + secs(2.34));
        assert_eq!(
            reasons(&m),
            [
                (
                    "Frontseat".to_string(),
                    "link serial down: no such device".to_string()
                ),
                ("Sensors".to_string(), "link sensors down".to_string()),
                ("Depth".to_string(), "no update for 2.3 s".to_string()),
            ],
            "a reported state has no reason"
        );
        m.link("serial", &LinkState::Up, t0 + secs(3.0));
        assert_eq!(m.reason("Frontseat"), None);
    }

    #[test]
    fn the_shipped_rules_watch_the_frontseat_s_data() {
        for (file, text, link) in [
            (
                "demo-health.xml",
                include_str!("../../../configs/demo-health.xml"),
                "serial",
            ),
            (
                "iver2-backseat-health.xml",
                include_str!("../../../configs/iver2-backseat-health.xml"),
                "frontseat",
            ),
        ] {
            let r = Rules::parse(file, text).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(
                r.component("Frontseat").map(|c| &c.mode),
                Some(&Mode::Link {
                    medium: link.to_string()
                }),
                "{file}"
            );
            let topics = |name: &str| -> Vec<(String, Duration)> {
                match r.component(name).map(|c| &c.mode) {
                    Some(Mode::Data { topics }) => topics
                        .iter()
                        .map(|t| (t.topic.to_string(), t.period))
                        .collect(),
                    other => panic!("{file}: {name} is {other:?}"),
                }
            };
            assert_eq!(
                topics("Navigation"),
                [
                    ("nav.position".to_string(), secs(0.25)),
                    ("nav.attitude".to_string(), secs(0.25))
                ],
                "{file}"
            );
            assert_eq!(
                topics("VehicleState"),
                [("vehicle.state".to_string(), secs(1.0))],
                "{file}"
            );
            // the driver asks every 250 ms: a second without navigation is a warning, three
            // an abort
            let nav = r.component("Navigation").unwrap();
            let Mode::Data { topics } = &nav.mode else {
                unreachable!()
            };
            assert!(
                topics
                    .iter()
                    .all(|t| t.unavailable_after == secs(1.0) && t.timeout == secs(3.0)),
                "{file}"
            );
            assert_eq!(nav.levels.get(Unavailable), Severity::Warn, "{file}");
            assert_eq!(nav.levels.get(Offline), Severity::Abort, "{file}");
        }
    }
}
