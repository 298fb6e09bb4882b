//! Commands: reading and checking a `<command>` (its fields, bounds, confirmation, dead-man rate
//! and neutral), the references widgets and inputs make to commands, and
//! [`CommandDecl::build`], which checks the fields a page proposes before they are sent.

use super::model::{CommandDecl, Confirm, DEFAULT_HOLD};
use super::read::Reader;
use super::values::{bind, duration, field_list, finite, name_attr, no_children, topic};
use seabus_medium::parse::parse_rate;
use seabus_medium::xml::{Attr, Element, FileError};
use seabus_medium::{DataMap, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

/// The attributes of `<command>` besides `min.FIELD`, `max.FIELD` and `from.FIELD`.
const KNOWN: [&str; 12] = [
    "name", "topic", "fields", "role", "confirm", "hold", "rate", "neutral", "lease", "keep",
    "resume", "safe",
];

/// The shortest and longest `keep` period.
const KEEP_RANGE: (Duration, Duration) = (Duration::from_millis(100), Duration::from_secs(60));

impl CommandDecl {
    /// The vehicle whose control it needs (`""`: the console's one control).
    pub fn vehicle(&self) -> &str {
        self.vehicle.as_deref().unwrap_or("")
    }

    /// Checks a proposed set of field values (types as the declared values', ranges) and returns
    /// the full datamap to send, or the reason it cannot be sent. A field in `chosen` (one the
    /// layout's controls let the pilot choose) is the value in `set`, else its current value in
    /// `current` (last commanded or measured): never the value the layout declares, which for
    /// such a field only gives its type. Any other field is the layout's: the value in `set`
    /// (already checked against what the controls offer), else the declared value.
    pub fn build(
        &self,
        current: &DataMap,
        set: &DataMap,
        chosen: &BTreeSet<String>,
    ) -> Result<DataMap, String> {
        let mut out = DataMap::new();
        let mut unknown = Vec::new();
        for (name, declared) in self.fields.iter() {
            let value = match set.get(name) {
                Some(v) => self.fit(name, v)?,
                None if chosen.contains(name) => {
                    match current.get(name).and_then(|v| self.fit(name, v).ok()) {
                        Some(v) => v,
                        None => {
                            unknown.push(name);
                            continue;
                        }
                    }
                }
                None => declared.clone(),
            };
            out.insert(name.to_string(), value);
        }
        for (name, value) in set.iter() {
            self.fit(name, value)?;
        }
        if !unknown.is_empty() {
            return Err(format!(
                "{} no known value (nothing commanded{} yet): set {}",
                match unknown.as_slice() {
                    [one] => format!("`{one}` has"),
                    many => format!(
                        "{} have",
                        many.iter()
                            .map(|f| format!("`{f}`"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                },
                if self.from.is_empty() {
                    ""
                } else {
                    " or measured"
                },
                if unknown.len() == 1 { "it" } else { "them" }
            ));
        }
        Ok(out)
    }

    /// `value` for field `name`, converted to the field's type and within its range.
    pub fn fit(&self, name: &str, value: &Value) -> Result<Value, String> {
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

/// A type's name with its article: `an int`, `a float`.
pub(super) fn article(type_name: &str) -> String {
    match type_name {
        "int" => "an int".to_string(),
        t => format!("a {t}"),
    }
}

/// The names of a command's fields, for messages.
pub(super) fn field_names(map: &DataMap) -> String {
    let names: Vec<&str> = map.iter().map(|(k, _)| k).collect();
    if names.is_empty() {
        "none".to_string()
    } else {
        names.join(", ")
    }
}

/// Reads a `<command>`.
pub(super) fn read_command(el: &Element) -> Result<CommandDecl, FileError> {
    no_children(el)?;
    known_attrs(el)?;
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
    let confirm = confirmation(el)?;
    let rate_hz = el.attr("rate").map(rate).transpose()?;
    let mut decl = CommandDecl {
        name,
        topic,
        fields,
        role,
        confirm,
        rate_hz,
        neutral: DataMap::new(),
        lease: el.flag("lease")?.unwrap_or(true),
        vehicle: None,
        min: BTreeMap::new(),
        max: BTreeMap::new(),
        from: BTreeMap::new(),
        keep: el.attr("keep").map(keep).transpose()?,
        resume: el.attr("resume").map(|a| a.value.trim().to_string()),
        safe: el.flag("safe")?.unwrap_or(false),
        pos: el.pos.clone(),
    };
    bounds(&mut decl, el)?;
    measured(&mut decl, el)?;
    if let (Some(_), false, Some(a)) = (decl.keep, decl.lease, el.attr("keep")) {
        return Err(a.error(
            "a kept command is sent again while its sender holds control: it needs control \
             (remove lease=\"false\")",
        ));
    }
    if let (true, false, Some(a)) = (
        decl.safe,
        matches!(decl.confirm, Confirm::None),
        el.attr("confirm"),
    ) {
        return Err(a.error(
            "the safe action goes at once, from every state of the page (Escape, the header's \
             stop): it takes no confirmation (remove confirm)",
        ));
    }
    // where a contradiction between attributes is shown when the one to blame is not written
    let fallback = el.attrs.first().unwrap_or(t);
    bounds_ordered(&decl, el, fallback)?;
    initial_values_fit(&decl, el.attr("fields").unwrap_or(t))?;
    if let Some(a) = el.attr("neutral") {
        decl.neutral = neutral(&decl, a)?;
    }
    Ok(decl)
}

/// Refuses an attribute `<command>` does not take.
fn known_attrs(el: &Element) -> Result<(), FileError> {
    for a in &el.attrs {
        let bound = ["min.", "max.", "from."]
            .iter()
            .any(|p| a.name.starts_with(p));
        if !bound && !KNOWN.contains(&a.name.as_str()) {
            return Err(a.pos.error(format!(
                "unknown attribute `{}` on <command>; expected one of: {}, min.FIELD, max.FIELD, \
                 from.FIELD",
                a.name,
                KNOWN.join(", ")
            )));
        }
    }
    Ok(())
}

/// How the command is confirmed: `confirm`, with `hold` only for `confirm="hold"`.
fn confirmation(el: &Element) -> Result<Confirm, FileError> {
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
    Ok(confirm)
}

/// A dead-man rate, per second: `rate` as a rate (5Hz, 5) or a period (200ms).
fn rate(a: &Attr) -> Result<f64, FileError> {
    parse_rate(&a.value)
        .map(|p| 1.0 / p.as_secs_f64())
        .filter(|hz| hz.is_finite())
        .ok_or_else(|| {
            a.error(format!(
                "`{}` is not a rate (5Hz, 5) or a period (200ms)",
                a.value.trim()
            ))
        })
}

/// Reads the `min.FIELD` and `max.FIELD` attributes: each names a numeric field.
fn bounds(decl: &mut CommandDecl, el: &Element) -> Result<(), FileError> {
    for a in &el.attrs {
        let (is_min, field) = if let Some(f) = a.name.strip_prefix("min.") {
            (true, f)
        } else if let Some(f) = a.name.strip_prefix("max.") {
            (false, f)
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
        let value = finite(a)?;
        let bounds = if is_min { &mut decl.min } else { &mut decl.max };
        bounds.insert(field.to_string(), value);
    }
    Ok(())
}

/// How often a kept command is sent again: a period within [`KEEP_RANGE`].
fn keep(a: &Attr) -> Result<Duration, FileError> {
    let d = duration(a)?;
    let (lo, hi) = KEEP_RANGE;
    if d < lo || d > hi {
        return Err(a.error(format!(
            "`keep` is how often the command is sent again while control is held: from {} ms \
             to {} s",
            lo.as_millis(),
            hi.as_secs()
        )));
    }
    Ok(d)
}

/// Reads the `from.FIELD="topic.field"` attributes: the variable a field's current value is
/// measured by.
fn measured(decl: &mut CommandDecl, el: &Element) -> Result<(), FileError> {
    for a in &el.attrs {
        let Some(field) = a.name.strip_prefix("from.") else {
            continue;
        };
        if decl.fields.get(field).is_none() {
            return Err(a.error(format!(
                "command `{}` has no field `{field}`; fields: {}",
                decl.name,
                field_names(&decl.fields)
            )));
        }
        let (topic, f) = bind(a)?;
        decl.from.insert(field.to_string(), (topic, f));
    }
    Ok(())
}

/// Refuses a field whose maximum is not above its minimum.
fn bounds_ordered(decl: &CommandDecl, el: &Element, fallback: &Attr) -> Result<(), FileError> {
    for (f, lo) in &decl.min {
        if let Some(hi) = decl.max.get(f).filter(|hi| *hi <= lo) {
            let at = el.attr(&format!("max.{f}")).unwrap_or(fallback);
            return Err(at.error(format!(
                "the maximum {hi} of `{f}` is not above its minimum {lo}"
            )));
        }
    }
    Ok(())
}

/// Refuses an initial field value outside the field's bounds (shown at `at`).
fn initial_values_fit(decl: &CommandDecl, at: &Attr) -> Result<(), FileError> {
    for (f, v) in decl.fields.iter() {
        if let Err(e) = decl.fit(f, v) {
            return Err(at.error(format!("{e} (the initial value)")));
        }
    }
    Ok(())
}

/// The `neutral` fields of a dead-man command, each fitting its field.
fn neutral(decl: &CommandDecl, a: &Attr) -> Result<DataMap, FileError> {
    if decl.rate_hz.is_none() && decl.keep.is_none() {
        return Err(a.error(
            "`neutral` is sent when a dead-man or kept command stops; give the command a `rate` \
             or `keep`",
        ));
    }
    let mut out = DataMap::new();
    for (f, v) in field_list(&a.value).map_err(|e| a.error(e))?.iter() {
        let v = decl.fit(f, v).map_err(|e| a.error(e))?;
        out.insert(f.to_string(), v);
    }
    Ok(out)
}

impl Reader {
    /// The command a `command` attribute names, and its field; `field` says whether one is needed.
    pub(super) fn command_ref(
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
            if let Some(at) = self.broken.get(name) {
                return Err(a.error(format!(
                    "command `{name}` is in error where it is declared (line {})",
                    at.line
                )));
            }
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
    pub(super) fn default_of(&self, name: &str, field: &str) -> Option<&Value> {
        self.commands.get(name)?.fields.get(field)
    }

    /// Refuses a field that is not a number (`a` names it).
    pub(super) fn numeric_field(&self, a: &Attr, name: &str, field: &str) -> Result<(), FileError> {
        match self.default_of(name, field) {
            Some(Value::Int(_) | Value::Float(_)) | None => Ok(()),
            Some(v) => Err(a.error(format!(
                "field `{field}` of command `{name}` is {}, not a number",
                article(v.type_name())
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{example, with, wrong_errors};
    use seabus_medium::{DataMap, Value};
    use std::collections::BTreeSet;

    #[test]
    fn build_checks_types_ranges_and_names() {
        let l = example();
        let course = &l.commands["course"];
        let none = BTreeSet::new();
        let set = DataMap::new().with("heading", 90.0);
        let sent = course.build(&DataMap::new(), &set, &none).unwrap();
        assert_eq!(sent.get("heading"), Some(&Value::Int(90)));
        assert_eq!(sent.get("depth"), Some(&Value::Int(0)));
        assert_eq!(sent.len(), 3);
        // fields the pilot chooses come from the current values, never the declared ones
        let chosen: BTreeSet<String> = ["heading", "depth", "speed"].map(String::from).into();
        let current = DataMap::new()
            .with("depth", 12)
            .with("heading", 45)
            .with("bogus", 1);
        let sent = course
            .build(&current, &DataMap::new().with("speed", 2), &chosen)
            .unwrap();
        assert_eq!(sent.get("heading"), Some(&Value::Int(45)));
        assert_eq!(sent.get("depth"), Some(&Value::Int(12)));
        assert_eq!(sent.get("speed"), Some(&Value::Float(2.0)));
        assert_eq!(sent.get("bogus"), None);
        assert_eq!(
            course.build(&DataMap::new().with("depth", 3), &set, &chosen),
            Err("`speed` has no known value (nothing commanded yet): set it".to_string())
        );
        assert_eq!(
            course.build(&DataMap::new(), &set, &chosen),
            Err(
                "`depth`, `speed` have no known value (nothing commanded yet): set them"
                    .to_string()
            )
        );
        let build = |set: DataMap| course.build(&DataMap::new(), &set, &none);
        assert_eq!(
            build(DataMap::new().with("speed", 3.0)),
            Err("field `speed`: 3 is above the maximum 2.5".to_string())
        );
        assert_eq!(
            build(DataMap::new().with("speed", "fast")),
            Err("field `speed` is a float, not a string `\"fast\"`".to_string())
        );
        assert_eq!(
            build(DataMap::new().with("hdg", 1)),
            Err("command `course` has no field `hdg`; fields: heading, depth, speed".to_string())
        );
        assert_eq!(
            build(DataMap::new().with("heading", f64::NAN)),
            Err("field `heading` is an int, not a float `NaN`".to_string())
        );
        let start = &l.commands["start"];
        assert!(
            start
                .build(&DataMap::new(), &DataMap::new().with("name", true), &none)
                .is_err()
        );
    }

    #[test]
    fn command_declarations_are_checked() {
        let cases = [
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
                "4:42: attribute `neutral`: `neutral` is sent when a dead-man or kept command stops; give the command a `rate` or `keep`",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" keep=\"10ms\"/>",
                "4:42: attribute `keep`: `keep` is how often the command is sent again while control is held: from 100 ms to 60 s",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" lease=\"false\" keep=\"1s\"/>",
                "4:56: attribute `keep`: a kept command is sent again while its sender holds control: it needs control (remove lease=\"false\")",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" from.y=\"nav.depth.depth\"/>",
                "4:42: attribute `from.y`: command `c` has no field `y`; fields: x",
            ),
            (
                "<command name=\"c\" topic=\"a\" fields=\"x=1\" from.x=\"depth\"/>",
                "4:42: attribute `from.x`: `depth` is not topic.field (the field is after the last dot: nav.depth.depth)",
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
                "4:29: unknown attribute `colour` on <command>; expected one of: name, topic, fields, role, confirm, hold, rate, neutral, lease, keep, resume, safe, min.FIELD, max.FIELD, from.FIELD",
            ),
            (
                "<command name=\"stop\" topic=\"a\"/>",
                "4:1: command `stop` is already declared at line 3",
            ),
        ];
        let wrong = wrong_errors(&cases, with);
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }
}
