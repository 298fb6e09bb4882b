//! A layout against a system ([`Layout::check`], `seabus layout check LAYOUT SYSTEM`): what puts
//! each topic on the console's medium ([`producers`]) and what accepts each command, directly or
//! through a bridge route.

use super::model::{Binding, CommandDecl, Layout};
use seabus_medium::xml::FileError;
use seabus_medium::{Kind, Pattern};
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

/// What a system's modules accept: (medium, topics).
type Accepted<'a> = Vec<(&'a str, Pattern)>;

impl Layout {
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
        let console = console_medium(spec);
        let produced = producers(spec, registry, catalogue, console);
        let accepted = accepted(spec, registry, catalogue);
        let mut warnings: Vec<FileError> = self
            .bindings()
            .iter()
            .filter_map(|b| binding_warning(b, &produced, spec, console))
            .collect();
        for c in self.commands.values() {
            if !accepted_from(c, &accepted, spec, console) {
                warnings.push(c.pos.error(format!(
                    "warning: no module of {} accepts command `{}` on `{}`",
                    spec.file,
                    c.name,
                    c.topic.as_str()
                )));
            }
        }
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

/// The topics each module of the system accepts, with the medium it accepts them on.
fn accepted<'a>(spec: &'a SystemSpec, registry: &Registry, catalogue: &Catalogue) -> Accepted<'a> {
    let mut accepted = Vec::new();
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

/// Whether a module accepts command `c` sent on `console`: there, or through a bridge route that
/// carries commands from `console` to the module's medium.
fn accepted_from(c: &CommandDecl, accepted: &Accepted, spec: &SystemSpec, console: &str) -> bool {
    let accepts = |medium: &str, topic: &str| {
        accepted
            .iter()
            .any(|(m, p)| *m == medium && p.matches(topic))
    };
    let topic = c.topic.as_str();
    if accepts(console, topic) {
        return true;
    }
    route_legs(spec).any(|(from, to, r)| {
        if from != console || r.kind == Some(Kind::Data) || !r.topics.matches(topic) {
            return false;
        }
        let out = match &r.rename {
            Some(rename) => r.topics.captures(topic).and_then(|c| rename.fill(&c)),
            None => Some(topic.to_string()),
        };
        out.is_some_and(|t| accepts(to, &t))
    })
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

#[cfg(test)]
mod tests {
    use super::super::testing::{parse, with};
    use seabus_modules::{Catalogue, SystemSpec};

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
