//! A layout against a system ([`Layout::check`], `seabus layout check LAYOUT SYSTEM`, and
//! [`Layout::check_on`] for each console `seabus check` and `seabus run` read): what puts each
//! topic on the console's medium ([`producers`]), what accepts each command, directly or through a
//! bridge route, whether the command carries the fields those modules require, and whether the
//! input widgets' ranges fit the fields' limits.

use super::model::{Binding, CommandDecl, Layout, Node};
use seabus_medium::xml::{FileError, Pos};
use seabus_medium::{Capabilities, Kind, Pattern};
use seabus_modules::datasets::Dataset;
use seabus_modules::system::RouteSpec;
use seabus_modules::{Catalogue, Registry, SystemSpec};
use std::collections::BTreeSet;

/// What puts a topic on the console's medium: a module's declaration or a bridge route into it.
#[derive(Debug, Clone)]
pub struct Producer {
    /// The topics.
    pub pattern: Pattern,
    /// The fields it declares; `None` when unknown.
    pub fields: Option<BTreeSet<String>>,
}

/// A command topic a module of the system accepts.
struct Accepting<'a> {
    /// The medium it accepts it on.
    medium: &'a str,
    /// The topics.
    pattern: Pattern,
    /// The module.
    module: &'a str,
    /// The standard dataset it takes, when it names one.
    dataset: Option<&'a Dataset>,
}

/// A module that accepts a layout's command, and the bridge route the command crosses to reach
/// it (`None`: it accepts it on the console's medium).
struct Acceptor<'a> {
    /// The module.
    module: &'a str,
    /// The standard dataset it takes, when it names one.
    dataset: Option<&'a Dataset>,
    /// The route crossed, whose field renames apply.
    route: Option<&'a RouteSpec>,
}

impl Acceptor<'_> {
    /// The name field `field` of the command has when it reaches the module; `None` when the route
    /// leaves it out (`keep="false"` without it).
    fn arrives_as<'f>(&'f self, field: &'f str) -> Option<&'f str> {
        let Some(route) = self.route else {
            return Some(field);
        };
        match route.fields.iter().find(|(from, _)| from == field) {
            Some((_, to)) => Some(to),
            None => route.keep.then_some(field),
        }
    }
}

impl Layout {
    /// Compares the layout with a system (see [`Layout::check_on`]) for the console of the system:
    /// on the medium of its first `<console>`, or its first medium.
    pub fn check(
        &self,
        spec: &SystemSpec,
        registry: &Registry,
        catalogue: &Catalogue,
    ) -> Vec<FileError> {
        self.check_on(spec, registry, catalogue, console_medium(spec))
    }

    /// Compares the layout with a system for a console on `medium`: a warning (`warning: …`) for
    /// each binding whose topic no module produces on the medium (directly, or through a bridge
    /// route into it) or whose field no producer declares; for each command no module accepts (on
    /// that medium, or one route away); for each widget or input sending a command that lacks a
    /// field the accepting module's dataset requires (the command declares no such field, so no
    /// control can set it); and for each slider or number whose range goes beyond the `min.F` and
    /// `max.F` of its command or the limits of the accepting module's dataset.
    pub fn check_on(
        &self,
        spec: &SystemSpec,
        registry: &Registry,
        catalogue: &Catalogue,
        medium: &str,
    ) -> Vec<FileError> {
        let produced = producers(spec, registry, catalogue, medium);
        let accepted = accepted(spec, registry, catalogue);
        let mut warnings: Vec<FileError> = self
            .bindings()
            .iter()
            .filter_map(|b| binding_warning(b, &produced, spec, medium))
            .collect();
        let mut ranges = Vec::new();
        for c in self.commands.values() {
            let acceptors = acceptors(c.topic.as_str(), &accepted, spec, medium);
            if acceptors.is_empty()
                && sent_beyond(c.topic.as_str(), spec, registry, medium).is_none()
            {
                warnings.push(c.pos.error(format!(
                    "warning: no module of {} accepts command `{}` on `{}`",
                    spec.file,
                    c.name,
                    c.topic.as_str()
                )));
            }
            for a in &acceptors {
                warnings.extend(self.missing_fields(c, a));
            }
            ranges.extend(self.range_warnings(c, &acceptors));
        }
        warnings.extend(ranges);
        warnings
    }
}

/// The medium the system's console reads: its `<console medium>`, or the system's first medium.
fn console_medium(spec: &SystemSpec) -> &str {
    spec.sections("console")
        .find_map(|e| e.get("medium"))
        .map(str::trim)
        .or_else(|| spec.media.first().map(|m| m.name.as_str()))
        .unwrap_or_default()
}

/// The command topics each module of the system accepts, with the medium it accepts them on.
fn accepted<'a>(
    spec: &'a SystemSpec,
    registry: &Registry,
    catalogue: &'a Catalogue,
) -> Vec<Accepting<'a>> {
    let mut accepted = Vec::new();
    for m in &spec.modules {
        let Ok(built) = registry.build_module(m, catalogue) else {
            continue;
        };
        for t in &built.decl.accepts {
            if let (Some(medium), Ok(pattern)) = (m.media.get(t.port), Pattern::new(&t.topic)) {
                accepted.push(Accepting {
                    medium: medium.as_str(),
                    pattern,
                    module: m.name.as_str(),
                    dataset: t.dataset.as_deref().and_then(|d| catalogue.get(d)),
                });
            }
        }
    }
    accepted
}
/// The warning for a binding whose topic nothing produces on `console`, or whose field no
/// producer declares (when they all say what they declare).
fn binding_warning(
    b: &Binding,
    produced: &[Producer],
    spec: &SystemSpec,
    console: &str,
) -> Option<FileError> {
    let pattern = Pattern::new(&b.topic).ok()?;
    let matching: Vec<&Producer> = produced
        .iter()
        .filter(|p| p.pattern.overlaps(&pattern))
        .collect();
    if matching.is_empty() {
        return Some(b.pos.error(format!(
            "warning: no module of {} produces `{}` on medium `{console}` (widget `{}`)",
            spec.file, b.topic, b.widget
        )));
    }
    let field = b.field.as_ref()?;
    let declared: BTreeSet<&String> =
        matching
            .iter()
            .map(|p| p.fields.as_ref())
            .try_fold(BTreeSet::new(), |mut all, f| {
                all.extend(f?);
                Some(all)
            })?;
    if declared.contains(field) {
        return None;
    }
    let names: Vec<&str> = declared.iter().map(|s| s.as_str()).collect();
    Some(b.pos.error(format!(
        "warning: `{}` has no field `{field}` (widget `{}`); its fields: {}",
        b.topic,
        b.widget,
        names.join(", ")
    )))
}

/// The modules that accept command `c` sent on `console`: there, or through a bridge route that
/// carries commands from `console` to the module's medium.
fn acceptors<'a>(
    topic: &str,
    accepted: &[Accepting<'a>],
    spec: &'a SystemSpec,
    console: &str,
) -> Vec<Acceptor<'a>> {
    let on = |medium: &str, topic: &str, route: Option<&'a RouteSpec>| -> Vec<Acceptor<'a>> {
        accepted
            .iter()
            .filter(|a| a.medium == medium && a.pattern.matches(topic))
            .map(|a| Acceptor {
                module: a.module,
                dataset: a.dataset,
                route,
            })
            .collect()
    };
    let mut out = on(console, topic, None);
    for (from, to, r) in route_legs(spec) {
        if from != console || r.kind == Some(Kind::Data) || !r.topics.matches(topic) {
            continue;
        }
        let crossed = match &r.rename {
            Some(rename) => r.topics.captures(topic).and_then(|c| rename.fill(&c)),
            None => Some(topic.to_string()),
        };
        if let Some(t) = crossed {
            out.extend(on(to, &t, Some(r)));
        }
    }
    out
}

/// The medium beyond this system a command is carried to, if a bridge route takes it from the
/// console's medium onto a medium that reaches other systems (one with a wire: its capabilities
/// are not the in-process medium's): a fleet console's `auv2.cmd.course` goes out to the vehicle,
/// whose own system accepts it.
fn sent_beyond<'a>(
    topic: &str,
    spec: &'a SystemSpec,
    registry: &Registry,
    console: &str,
) -> Option<&'a str> {
    route_legs(spec)
        .filter(|(from, _, r)| {
            *from == console && r.kind != Some(Kind::Data) && r.topics.matches(topic)
        })
        .map(|(_, to, _)| to)
        .find(|to| {
            spec.medium(to).is_some_and(|m| {
                registry
                    .capabilities(&m.url, &m.pos)
                    .is_ok_and(|caps| caps != Capabilities::IN_PROCESS)
            })
        })
}

/// Whether a command on `topic` sent on `medium` reaches a module of the system that accepts it:
/// there, one bridge route away, or carried by a route onto a medium that reaches other systems.
pub fn command_accepted(
    spec: &SystemSpec,
    registry: &Registry,
    catalogue: &Catalogue,
    medium: &str,
    topic: &str,
) -> bool {
    let accepted = accepted(spec, registry, catalogue);
    !acceptors(topic, &accepted, spec, medium).is_empty()
        || sent_beyond(topic, spec, registry, medium).is_some()
}

/// A widget or input that sends a command: what it is called in a warning, and where it is.
struct Sender<'a> {
    what: String,
    pos: &'a Pos,
}

impl Layout {
    /// Every widget and input that sends command `name`.
    fn senders(&self, name: &str) -> Vec<Sender<'_>> {
        let mut out: Vec<Sender> = self
            .root
            .walk()
            .into_iter()
            .filter(|n| n.command().is_some_and(|(c, _)| c == name))
            .map(|n| Sender {
                what: format!("{} `{}`", n.kind, n.id),
                pos: &n.pos,
            })
            .collect();
        let keys = self.keys.iter().filter(|k| k.command == name);
        out.extend(keys.map(|k| Sender {
            what: format!("key `{}`", k.key),
            pos: &k.pos,
        }));
        let axes = self.axes.iter().filter(|a| a.command == name);
        out.extend(axes.map(|a| Sender {
            what: format!("gamepad axis {}", a.index),
            pos: &a.pos,
        }));
        let buttons = self.buttons.iter().filter(|b| b.command == name);
        out.extend(buttons.map(|b| Sender {
            what: format!("gamepad button {}", b.index),
            pos: &b.pos,
        }));
        out
    }

    /// A warning at each widget and input sending `c` when `a` requires fields `c` does not carry
    /// to it: a field the command does not declare is one no control can set, and the command is
    /// sent without it.
    fn missing_fields(&self, c: &CommandDecl, a: &Acceptor) -> Vec<FileError> {
        let Some(dataset) = a.dataset else {
            return Vec::new();
        };
        let carried: BTreeSet<&str> = c
            .fields
            .iter()
            .filter_map(|(f, _)| a.arrives_as(f))
            .collect();
        let missing: Vec<String> = dataset
            .required()
            .filter(|f| !carried.contains(f.name.as_str()))
            .map(|f| format!("`{}`", f.name))
            .collect();
        if missing.is_empty() {
            return Vec::new();
        }
        let them = if missing.len() == 1 { "it" } else { "them" };
        let (crossing, carry) = match a.route {
            None => (String::new(), String::new()),
            Some(r) => (
                format!(" once it crosses the route at {}", r.pos),
                format!(" or let the route carry {them}"),
            ),
        };
        self.senders(&c.name)
            .into_iter()
            .map(|s| {
                s.pos.error(format!(
                    "warning: {} sends command `{}` without {}{crossing}, which module `{}` \
                     requires (dataset `{}`); declare {them} in the command's `fields`{carry}",
                    s.what,
                    c.name,
                    missing.join(", "),
                    a.module,
                    dataset.name,
                ))
            })
            .collect()
    }

    /// A warning for each slider or number setting a field of `c` whose range goes beyond the
    /// field's `min.F`/`max.F` or the limits of an accepting module's dataset.
    fn range_warnings(&self, c: &CommandDecl, acceptors: &[Acceptor]) -> Vec<FileError> {
        let mut out = Vec::new();
        for node in self.root.walk() {
            let Some((name, Some(field))) = node.command() else {
                continue;
            };
            if name != c.name || !matches!(node.kind.as_str(), "slider" | "number") {
                continue;
            }
            let mut limits = vec![Limits {
                min: c.min.get(field).copied(),
                max: c.max.get(field).copied(),
                of: format!("`{}.{field}`", c.name),
                consequence: "the server refuses values beyond them".to_string(),
            }];
            for a in acceptors {
                let declared = a
                    .dataset
                    .zip(a.arrives_as(field))
                    .and_then(|(d, f)| d.field(f).map(|f| (d, f)));
                if let Some((d, f)) = declared {
                    limits.push(Limits {
                        min: f.min,
                        max: f.max,
                        of: format!("field `{}` of dataset `{}`", f.name, d.name),
                        consequence: format!(
                            "values beyond them are not valid for module `{}`",
                            a.module
                        ),
                    });
                }
            }
            let range = Range::of(node);
            out.extend(limits.iter().filter_map(|l| range.beyond(node, l)));
        }
        out
    }
}

/// A field's limits, whose they are and what becomes of values beyond them (for the warning).
struct Limits {
    min: Option<f64>,
    max: Option<f64>,
    of: String,
    consequence: String,
}

impl Limits {
    /// The limits as words: `0 to 360`, `at least 0`, `at most 2.5`.
    fn describe(&self) -> String {
        match (self.min, self.max) {
            (Some(lo), Some(hi)) => format!("{lo} to {hi}"),
            (Some(lo), None) => format!("at least {lo}"),
            (None, Some(hi)) => format!("at most {hi}"),
            (None, None) => "none".to_string(),
        }
    }
}

/// The values a slider or number lets the user pick: its `min` and `max`, or where they are not
/// written a slider's 0 and 100 (as the page draws it) and no limit for a number.
struct Range {
    min: Option<f64>,
    max: Option<f64>,
}

impl Range {
    /// The range of `node`.
    fn of(node: &Node) -> Range {
        let written = |name: &str| {
            node.attrs
                .get(name)
                .and_then(|v| v.trim().parse::<f64>().ok())
        };
        let slider = node.kind == "slider";
        Range {
            min: written("min").or(slider.then_some(SLIDER_MIN)),
            max: written("max").or(slider.then_some(SLIDER_MAX)),
        }
    }

    /// The warning when this range goes below `l.min` or above `l.max`.
    fn beyond(&self, node: &Node, l: &Limits) -> Option<FileError> {
        let below = l.min.is_some_and(|m| self.min.is_none_or(|lo| lo < m));
        let above = l.max.is_some_and(|m| self.max.is_none_or(|hi| hi > m));
        if !below && !above {
            return None;
        }
        let end = |value: Option<f64>, attr: &str| {
            let value = value.map_or_else(|| "no limit".to_string(), |v| v.to_string());
            if node.attrs.contains_key(attr) {
                value
            } else {
                format!("{value} (no `{attr}`)")
            }
        };
        Some(node.pos.error(format!(
            "warning: {} `{}` goes from {} to {}, beyond the limits of {} ({}): {}",
            node.kind,
            node.id,
            end(self.min, "min"),
            end(self.max, "max"),
            l.of,
            l.describe(),
            l.consequence
        )))
    }
}

/// The range a slider without `min` or `max` has on the page.
const SLIDER_MIN: f64 = 0.0;
/// See [`SLIDER_MIN`].
const SLIDER_MAX: f64 = 100.0;

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

#[cfg(test)]
mod tests {
    use super::super::testing::{parse, with};
    use seabus_modules::{
        Built, Catalogue, Declaration, Module, ModuleKind, ModuleType, SystemSpec, TopicDecl,
    };

    /// A module that accepts course commands (dataset `course-command`) and does nothing.
    struct Helm;
    impl Module for Helm {}

    const HELM: ModuleType = ModuleType {
        name: "helm",
        kind: ModuleKind::Driver,
        summary: "accepts course commands",
        build: |_, _| {
            Ok(Built {
                decl: Declaration::new(ModuleKind::Driver)
                    .accepts(TopicDecl::dataset("cmd.course", "course-command")),
                module: Box::new(Helm),
            })
        },
    };

    #[test]
    fn check_warns_of_fields_the_acceptor_requires_and_ranges_beyond_its_limits() {
        let spec = SystemSpec::parse(
            "sys.xml",
            r#"<seabus>
  <medium name="bus" url="inproc://"/>
  <medium name="vehicle" url="inproc://"/>
  <module name="helm" type="helm" medium="vehicle"/>
  <bridge name="b" media="bus vehicle">
    <route from="bus" to="vehicle" topics="ui.cmd.*" rename="cmd.*" kind="command" keep="false">
      <field name="hdg" rename="heading"/><field name="depth"/><field name="speed"/>
    </route>
  </bridge>
</seabus>"#,
        )
        .unwrap();
        let mut registry = seabus_support::registry();
        registry.add_module(HELM);
        let catalogue = Catalogue::built_in();
        let l = parse(
            r#"<layout name="t">
<command name="course" topic="ui.cmd.course" fields="hdg=0.0, depth=0.0, speed=0.0, x=1" max.hdg="400"/>
<command name="bare" topic="ui.cmd.course" fields="heading=0.0, depth=0.0, speed=0.0"/>
<command name="part" topic="ui.cmd.course" fields="hdg=0.0, speed=0.0" min.speed="0"/>
<slider command="course.hdg" min="0" max="400"/>
<number command="course.depth"/>
<button command="bare"/>
<slider command="part.speed" max="2"/>
<keys><key key="s" command="part.speed" value="1"/></keys>
</layout>"#,
        )
        .unwrap();
        let got: Vec<String> = l
            .check_on(&spec, &registry, &catalogue, "bus")
            .iter()
            .map(ToString::to_string)
            .collect();
        assert_eq!(
            got,
            [
                "l.xml:7:1: warning: button `button-1` sends command `bare` without `heading` once \
                 it crosses the route at sys.xml:6:5, which module `helm` requires (dataset \
                 `course-command`); declare it in the command's `fields` or let the route carry it",
                "l.xml:8:1: warning: slider `slider-2` sends command `part` without `depth` once \
                 it crosses the route at sys.xml:6:5, which module `helm` requires (dataset \
                 `course-command`); declare it in the command's `fields` or let the route carry it",
                "l.xml:9:7: warning: key `s` sends command `part` without `depth` once it crosses \
                 the route at sys.xml:6:5, which module `helm` requires (dataset \
                 `course-command`); declare it in the command's `fields` or let the route carry it",
                "l.xml:5:1: warning: slider `slider-1` goes from 0 to 400, beyond the limits of \
                 field `heading` of dataset `course-command` (0 to 360): values beyond them are \
                 not valid for module `helm`",
            ]
        );
        // the same layout straight on the vehicle's medium: no module accepts `ui.cmd.course`
        let direct = l.check_on(&spec, &registry, &catalogue, "vehicle");
        assert_eq!(direct.len(), 3, "{direct:?}");
        assert!(
            direct.iter().all(|w| w
                .message
                .starts_with("warning: no module of sys.xml accepts command")),
            "{direct:?}"
        );
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

    #[test]
    fn a_command_a_route_carries_out_to_other_systems_is_not_warned_of() {
        let spec = SystemSpec::parse(
            "sys.xml",
            r#"<seabus node="shore">
  <medium name="bus" url="inproc://"/>
  <medium name="fleet" url="udp://239.255.1.1:47000?ttl=0"/>
  <medium name="local" url="inproc://"/>
  <bridge name="b" media="bus fleet"><route from="bus" to="fleet" topics="*.cmd.**" kind="command"/></bridge>
  <bridge name="c" media="bus local"><route from="bus" to="local" topics="lab.**"/></bridge>
</seabus>"#,
        )
        .unwrap();
        // (the UDP medium has a wire: what goes onto it reaches other systems)
        let mut registry = seabus_support::registry();
        registry.set_schemes(seabus_medium_udp::schemes());
        let catalogue = Catalogue::built_in();
        let l = parse(
            r#"<layout name="t" vehicle="auv2">
<command name="course" topic="auv2.cmd.course" fields="heading=0.0"/>
<command name="lab" topic="lab.light" fields="on=true"/>
</layout>"#,
        )
        .unwrap();
        let got: Vec<String> = l
            .check_on(&spec, &registry, &catalogue, "bus")
            .iter()
            .map(ToString::to_string)
            .collect();
        // auv2's commands go out to auv2's own system; `lab.light` stays in this process,
        // where nothing takes it
        assert_eq!(
            got,
            ["l.xml:3:1: warning: no module of sys.xml accepts command `lab` on `lab.light`"]
        );
    }
}
