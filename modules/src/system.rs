//! System files: the XML that names a system's media, the modules on them and the bridges between
//! them.
//!
//! ```xml
//! <seabus node="auv1">
//!   <medium name="bus" url="inproc://"/>
//!   <medium name="net" url="udp://239.255.42.1:47800?ttl=0"/>
//!   <module name="sim" type="vehicle-sim" medium="bus" tick="10Hz"/>
//!   <bridge name="uplink" media="bus net" hops="8">
//!     <route from="bus" to="net" topics="nav.**" rename="auv1.nav.**" rate="5"/>
//!     <route from="net" to="bus" topics="cmd.**"/>
//!   </bridge>
//! </seabus>
//! ```
//! [`SystemSpec::parse`] reads the structure; [`check`] validates it against a [`Registry`]
//! (medium URLs, module types and parameters, bridge routes) and reports route cycles as warnings.
//! Every error names file, line and column.

use crate::datasets::Catalogue;
use crate::params::{Param, Params};
use crate::registry::{ModuleConfig, Registry};
use seabus_medium::parse::parse_rate;
use seabus_medium::qos::{Congestion, Priority, Qos};
use seabus_medium::xml::{self, Element, FileError, Pos};
use seabus_medium::{Format, Kind, Pattern};
use std::collections::BTreeMap;
use std::path::Path;

/// Default hop limit of a bridge.
pub const DEFAULT_HOPS: u8 = 8;

/// A medium as placed in a system file.
#[derive(Debug, Clone, PartialEq)]
pub struct MediumSpec {
    /// Its name.
    pub name: String,
    /// Its URL.
    pub url: String,
    /// Where it is written.
    pub pos: Pos,
}

/// One route of a bridge.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteSpec {
    /// The medium messages come from; `None` with `to` also `None` means both directions.
    pub from: Option<String>,
    /// The medium messages go to.
    pub to: Option<String>,
    /// Which topics.
    pub topics: Pattern,
    /// New topic on the far side, filled from the pattern's wildcards.
    pub rename: Option<Pattern>,
    /// The period of the route's `rate` (data only): one message of a topic per period, on
    /// average, from a faster source.
    pub min_interval: Option<std::time::Duration>,
    /// Payload format on the far side.
    pub format: Option<Format>,
    /// Only data or only commands.
    pub kind: Option<Kind>,
    /// Field renames (datamap payloads), `from → to`.
    pub fields: Vec<(String, String)>,
    /// Whether fields not listed in `fields` cross too (`keep="false"`: only the listed ones).
    pub keep: bool,
    /// The LCM type (`package.name_t`) messages have on the route's LCM side.
    pub lcm: Option<String>,
    /// The quality of service of what the route delivers, from its `priority`, `congestion` and
    /// `express` attributes, when it has any.
    pub qos: Option<RouteQos>,
    /// Where it is written.
    pub pos: Pos,
}

/// A route's `priority`, `congestion` and `express`: the quality of service of what it delivers,
/// on a medium that carries priorities ([`seabus_medium::Capabilities::qos`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RouteQos {
    /// The attributes' values.
    pub qos: Qos,
    /// The first of these attributes as written, which an error about the route's quality of
    /// service names.
    pub attr: xml::Attr,
}

impl RouteSpec {
    /// The directed legs of this route over a bridge between `a` and `b`: `(from, to)` pairs.
    pub fn legs<'a>(&'a self, a: &'a str, b: &'a str) -> Vec<(&'a str, &'a str)> {
        match (self.from.as_deref(), self.to.as_deref()) {
            (Some(f), Some(t)) => vec![(f, t)],
            (Some(f), None) => vec![(f, if f == a { b } else { a })],
            (None, Some(t)) => vec![(if t == a { b } else { a }, t)],
            (None, None) => vec![(a, b), (b, a)],
        }
    }

    /// The pattern of topics as they leave the route.
    pub fn out_pattern(&self) -> &Pattern {
        self.rename.as_ref().unwrap_or(&self.topics)
    }
}

/// A bridge as placed in a system file.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeSpec {
    /// Its name.
    pub name: String,
    /// Its type (`route` unless given).
    pub type_name: String,
    /// The two media it joins.
    pub media: [String; 2],
    /// The URLs of those media, as the system file gives them (empty for one not defined).
    pub urls: [String; 2],
    /// Hop limit: a message that crossed this many bridges is not forwarded.
    pub hops: u8,
    /// Routes in order; a message takes the first that matches.
    pub routes: Vec<RouteSpec>,
    /// Other attributes, for the bridge type.
    pub params: Params,
    /// Where it is written.
    pub pos: Pos,
}

/// A parsed system file.
#[derive(Debug, Clone)]
pub struct SystemSpec {
    /// The file it came from.
    pub file: String,
    /// The node name, when given.
    pub node: Option<String>,
    /// Media in order; the first is the default bus.
    pub media: Vec<MediumSpec>,
    /// Modules in order.
    pub modules: Vec<ModuleConfig>,
    /// Bridges in order.
    pub bridges: Vec<BridgeSpec>,
    /// Other top-level elements, for the services other crates provide (console, health, …);
    /// [`check`] refuses those no registered crate reads.
    pub sections: Vec<Element>,
    /// Where the root element is.
    pub pos: Pos,
}

const TOP_TAGS: [&str; 3] = ["medium", "module", "bridge"];

/// A path a file at `pos` gives, relative to that file's directory.
pub fn beside(pos: &Pos, relative: &str) -> std::path::PathBuf {
    std::path::Path::new(&*pos.file)
        .parent()
        .unwrap_or_else(|| std::path::Path::new(""))
        .join(relative.trim())
}

/// Longest name of a node, medium, module or bridge, in bytes.
pub const MAX_NAME: usize = 64;

fn check_name(attr: &xml::Attr) -> Result<String, FileError> {
    check_name_of(attr, "", " (it becomes part of topics)").map(str::to_string)
}

/// Checks the name an attribute gives (a `what` name: letters, digits, `_` and `-`, at most
/// [`MAX_NAME`] bytes); `why` ends the message when it is not one.
pub fn check_name_of<'a>(attr: &'a xml::Attr, what: &str, why: &str) -> Result<&'a str, FileError> {
    let v = attr.value.trim();
    let what = if what.is_empty() {
        String::new()
    } else {
        format!("{what} ")
    };
    if v.len() > MAX_NAME {
        return Err(attr.error(format!(
            "a {what}name is at most {MAX_NAME} characters, this one has {}",
            v.len()
        )));
    }
    if v.is_empty()
        || !v
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Err(attr.error(format!(
            "`{v}` is not a {what}name: use letters, digits, `_` and `-`{why}"
        )));
    }
    Ok(v)
}

fn split_list(s: &str) -> Vec<String> {
    s.split([' ', ',', '\t', '\n'])
        .filter(|x| !x.is_empty())
        .map(str::to_string)
        .collect()
}

impl SystemSpec {
    /// Reads and parses a system file.
    pub fn load(path: &Path) -> Result<SystemSpec, FileError> {
        SystemSpec::from_element(&xml::parse_file(path)?)
    }

    /// Parses a system file's text.
    pub fn parse(file: &str, text: &str) -> Result<SystemSpec, FileError> {
        SystemSpec::from_element(&xml::parse(file, text)?)
    }

    fn from_element(root: &Element) -> Result<SystemSpec, FileError> {
        if root.name != "seabus" {
            return Err(root.error(format!(
                "root element is <{}>, expected <seabus>",
                root.name
            )));
        }
        root.only_attrs(&["node"])?;
        let node = match root.attr("node") {
            Some(a) => Some(check_name(a)?),
            None => None,
        };
        let mut spec = SystemSpec {
            file: root.pos.file.to_string(),
            node,
            media: Vec::new(),
            modules: Vec::new(),
            bridges: Vec::new(),
            sections: Vec::new(),
            pos: root.pos.clone(),
        };
        let mut unit_names: BTreeMap<String, Pos> = BTreeMap::new();
        let claim = |attr: &xml::Attr,
                     what: &str,
                     names: &mut BTreeMap<String, Pos>|
         -> Result<String, FileError> {
            let name = check_name(attr)?;
            if let Some(prev) = names.get(&name) {
                return Err(attr.error(format!(
                    "{what} `{name}` is already defined at line {}",
                    prev.line
                )));
            }
            names.insert(name.clone(), attr.pos.clone());
            Ok(name)
        };
        let mut medium_names = BTreeMap::new();
        for el in &root.children {
            match el.name.as_str() {
                "medium" => {
                    el.only_attrs(&["name", "url"])?;
                    el.only_children(&[])?;
                    let name = claim(el.required("name")?, "a medium", &mut medium_names)?;
                    let url = el.required("url")?;
                    spec.media.push(MediumSpec {
                        name,
                        url: url.value.trim().to_string(),
                        pos: url.pos.clone(),
                    });
                }
                "module" => spec.modules.push(module_config(el, &mut |a| {
                    claim(a, "a module or bridge", &mut unit_names)
                })?),
                "bridge" => spec.bridges.push(bridge_spec(el, &mut |a| {
                    claim(a, "a module or bridge", &mut unit_names)
                })?),
                _ => spec.sections.push(el.clone()),
            }
        }
        if spec.media.is_empty() {
            return Err(root.error("a system needs at least one <medium>"));
        }
        for b in &mut spec.bridges {
            for (url, name) in b.urls.iter_mut().zip(&b.media) {
                if let Some(m) = spec.media.iter().find(|m| &m.name == name) {
                    url.clone_from(&m.url);
                }
            }
        }
        Ok(spec)
    }

    /// The medium called `name` that an element at `pos` names, or an error there listing the
    /// media there are.
    pub fn medium_at(&self, name: &str, pos: &Pos) -> Result<&MediumSpec, FileError> {
        self.medium(name).ok_or_else(|| {
            pos.error(format!(
                "no medium called `{name}`; media: {}",
                self.media
                    .iter()
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
    }

    /// The medium called `name`.
    pub fn medium(&self, name: &str) -> Option<&MediumSpec> {
        self.media.iter().find(|m| m.name == name)
    }

    /// The name of the default medium (the first one).
    pub fn default_medium(&self) -> &str {
        &self.media[0].name
    }

    /// The top-level elements called `tag` that other crates read.
    pub fn sections(&self, tag: &str) -> impl Iterator<Item = &Element> {
        self.sections.iter().filter(move |e| e.name == tag)
    }
}

fn module_config(
    el: &Element,
    claim: &mut dyn FnMut(&xml::Attr) -> Result<String, FileError>,
) -> Result<ModuleConfig, FileError> {
    el.only_children(&["param"])?;
    let name = claim(el.required("name")?)?;
    let type_name = el.required("type")?.value.trim().to_string();
    let media = match (el.attr("medium"), el.attr("media")) {
        (Some(a), None) | (None, Some(a)) => {
            let list = split_list(&a.value);
            if list.is_empty() {
                return Err(a.error("names no medium"));
            }
            list
        }
        (Some(_), Some(b)) => return Err(b.error("give either `medium` or `media`, not both")),
        (None, None) => Vec::new(),
    };
    let tick = match el.attr("tick") {
        None => None,
        Some(a) => Some(parse_rate(&a.value).ok_or_else(|| {
            a.error(format!(
                "`{}` is not a rate (10, 10Hz) or a period (100ms, 2s)",
                a.value
            ))
        })?),
    };
    let mut params: Vec<Param> = el
        .attrs
        .iter()
        .filter(|a| !["name", "type", "medium", "media", "tick"].contains(&a.name.as_str()))
        .map(|a| Param {
            name: a.name.clone(),
            value: a.value.clone(),
            pos: a.pos.clone(),
        })
        .collect();
    for p in el.children_named("param") {
        p.only_attrs(&["name", "value"])?;
        let n = p.required("name")?;
        let v = match (p.attr("value"), p.text.trim()) {
            (Some(v), _) => v.value.clone(),
            (None, t) if !t.is_empty() => t.to_string(),
            (None, _) => return Err(p.error("<param> needs a `value` attribute or text")),
        };
        params.push(Param {
            name: n.value.clone(),
            value: v,
            pos: n.pos.clone(),
        });
    }
    Ok(ModuleConfig {
        name,
        type_name,
        media,
        tick,
        params: Params::new(params, el.pos.clone()),
        pos: el.pos.clone(),
    })
}

fn bridge_spec(
    el: &Element,
    claim: &mut dyn FnMut(&xml::Attr) -> Result<String, FileError>,
) -> Result<BridgeSpec, FileError> {
    el.only_children(&["route"])?;
    let name = claim(el.required("name")?)?;
    let media_attr = el.required("media")?;
    let media = split_list(&media_attr.value);
    let media: [String; 2] = match media.as_slice() {
        [a, b] if a != b => [a.clone(), b.clone()],
        [a, b] if a == b => {
            return Err(media_attr.error(format!(
                "a bridge joins two different media, `{a}` is given twice"
            )));
        }
        _ => {
            return Err(media_attr.error(format!(
                "a bridge joins exactly two media, `{}` names {}",
                media_attr.value,
                media.len()
            )));
        }
    };
    let hops = el
        .parsed::<u8>("hops", "a hop count 1–255")?
        .unwrap_or(DEFAULT_HOPS);
    if hops == 0 {
        return Err(el
            .required("hops")?
            .error("the hop limit must be at least 1"));
    }
    let routes = el
        .children_named("route")
        .map(|r| route_spec(r, &media))
        .collect::<Result<Vec<_>, _>>()?;
    let params: Vec<Param> = el
        .attrs
        .iter()
        .filter(|a| !["name", "type", "media", "hops"].contains(&a.name.as_str()))
        .map(|a| Param {
            name: a.name.clone(),
            value: a.value.clone(),
            pos: a.pos.clone(),
        })
        .collect();
    Ok(BridgeSpec {
        name,
        type_name: el.get("type").unwrap_or("route").trim().to_string(),
        media,
        urls: Default::default(),
        hops,
        routes,
        params: Params::new(params, el.pos.clone()),
        pos: el.pos.clone(),
    })
}

/// A `<route>` of a bridge between `media`.
fn route_spec(r: &Element, media: &[String; 2]) -> Result<RouteSpec, FileError> {
    r.only_children(&["field"])?;
    r.only_attrs(&[
        "from",
        "to",
        "topics",
        "rename",
        "rate",
        "format",
        "kind",
        "lcm",
        "keep",
        "priority",
        "congestion",
        "express",
    ])?;
    let medium_attr = |key: &str| -> Result<Option<String>, FileError> {
        match r.attr(key) {
            None => Ok(None),
            Some(a) if media.contains(&a.value) => Ok(Some(a.value.clone())),
            Some(a) => Err(a.error(format!(
                "`{}` is not one of this bridge's media ({} and {})",
                a.value, media[0], media[1]
            ))),
        }
    };
    let (from, to) = (medium_attr("from")?, medium_attr("to")?);
    if from.is_some() && from == to {
        return Err(r.error("a route's `from` and `to` must differ"));
    }
    let topics_attr = r.required("topics")?;
    let topics = Pattern::new(topics_attr.value.trim()).map_err(|e| topics_attr.error(e))?;
    let rename = match r.attr("rename") {
        None => None,
        Some(a) => {
            let p = Pattern::new(a.value.trim()).map_err(|e| a.error(e))?;
            if p.wildcards() != topics.wildcards() {
                return Err(a.error(format!(
                    "`{}` has {} wildcards, `{}` has {}: they are filled in order and must match",
                    p,
                    p.wildcards(),
                    topics,
                    topics.wildcards()
                )));
            }
            Some(p)
        }
    };
    let min_interval = match r.attr("rate") {
        None => None,
        Some(a) => Some(parse_rate(&a.value).ok_or_else(|| {
            a.error(format!(
                "`{}`: the rate must be above 0 and at most a million per second \
                 (5, 5Hz) or a period (200ms, 2s)",
                a.value
            ))
        })?),
    };
    let format = match r.attr("format") {
        None => None,
        Some(a) => Some(
            Format::parse(a.value.trim()).ok_or_else(|| a.error("expected bytes, map or xml"))?,
        ),
    };
    let kind = match r.get("kind") {
        None | Some("any") => None,
        Some("data") => Some(Kind::Data),
        Some("command") | Some("commands") => Some(Kind::Command),
        Some(_) => return Err(r.required("kind")?.error("expected data, command or any")),
    };
    let mut fields = Vec::new();
    for f in r.children_named("field") {
        f.only_attrs(&["name", "rename"])?;
        let name = f.required("name")?.value.clone();
        let rename = f.get("rename").map_or_else(|| name.clone(), str::to_string);
        fields.push((name, rename));
    }
    Ok(RouteSpec {
        from,
        to,
        topics,
        rename,
        min_interval,
        format,
        kind,
        fields,
        keep: r.flag("keep")?.unwrap_or(true),
        lcm: r.get("lcm").map(|t| t.trim().to_string()),
        qos: route_qos(r)?,
        pos: r.pos.clone(),
    })
}

/// A route's `priority`, `congestion` and `express`, each checked; `None` without any.
fn route_qos(r: &Element) -> Result<Option<RouteQos>, FileError> {
    let priority = match r.attr("priority") {
        None => None,
        Some(a) => Some(Priority::parse(&a.value).ok_or_else(|| {
            a.error(format!(
                "`{}` is not a priority; expected {}",
                a.value.trim(),
                Priority::expected()
            ))
        })?),
    };
    let congestion = match r.attr("congestion") {
        None => None,
        Some(a) => Some(Congestion::parse(&a.value).ok_or_else(|| {
            a.error(format!(
                "`{}` is not a congestion control; expected {}",
                a.value.trim(),
                Congestion::expected()
            ))
        })?),
    };
    let qos = Qos {
        priority,
        congestion,
        express: r.flag("express")?,
    };
    let first = r
        .attrs
        .iter()
        .find(|a| ["priority", "congestion", "express"].contains(&a.name.as_str()));
    Ok(first.map(|attr| RouteQos {
        qos,
        attr: attr.clone(),
    }))
}

/// A route cycle: messages could go round these media through these bridges.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    /// The media in order, the first repeated at the end.
    pub media: Vec<String>,
    /// The bridge of each leg.
    pub bridges: Vec<String>,
    /// Where the first route of the cycle is written.
    pub pos: Pos,
}

impl Cycle {
    /// A warning describing the cycle.
    pub fn warning(&self) -> FileError {
        self.pos.error(format!(
            "warning: route cycle {} through bridges {}; seabus drops the repeats, but every message crosses \
             each of these bridges",
            self.media.join(" -> "),
            self.bridges.join(", ")
        ))
    }
}

struct Leg<'a> {
    from: &'a str,
    to: &'a str,
    bridge: &'a str,
    inp: &'a Pattern,
    out: &'a Pattern,
    kind: Option<Kind>,
    pos: &'a Pos,
}

impl Leg<'_> {
    /// True when what leaves `self` can be taken by `next`: topics and kinds overlap.
    fn feeds(&self, next: &Leg<'_>) -> bool {
        let kinds = match (self.kind, next.kind) {
            (Some(a), Some(b)) => a == b,
            _ => true,
        };
        kinds && self.out.overlaps(next.inp)
    }
}

/// Finds route cycles: closed paths of routes through two or more bridges in which each leg passes
/// topics (after renames) and kinds on to the next. Legs are compared pairwise, so a path where no
/// single topic fits every leg may still be reported: the check errs on the side of warning. (A single bridge routing both ways is no cycle: a bridge never sends a
/// message back where it came from.)
pub fn route_cycles(spec: &SystemSpec) -> Vec<Cycle> {
    let legs: Vec<Leg<'_>> = spec
        .bridges
        .iter()
        .flat_map(|b| {
            b.routes.iter().flat_map(move |r| {
                r.legs(&b.media[0], &b.media[1])
                    .into_iter()
                    .map(move |(from, to)| Leg {
                        from,
                        to,
                        bridge: &b.name,
                        inp: &r.topics,
                        out: r.out_pattern(),
                        kind: r.kind,
                        pos: &r.pos,
                    })
            })
        })
        .collect();
    let mut found: Vec<Cycle> = Vec::new();
    let mut seen_sets: Vec<Vec<usize>> = Vec::new();
    for start in 0..legs.len() {
        let mut path = vec![start];
        walk(&legs, &mut path, &mut found, &mut seen_sets);
    }
    found
}

fn walk(
    legs: &[Leg<'_>],
    path: &mut Vec<usize>,
    found: &mut Vec<Cycle>,
    seen: &mut Vec<Vec<usize>>,
) {
    const MAX_LEN: usize = 12;
    let last = &legs[*path.last().expect("path is never empty")];
    let first = &legs[path[0]];
    // closing the loop: back at the start medium, topic still matching the first leg
    if path.len() >= 2 && last.to == first.from && last.feeds(first) {
        let bridges: Vec<&str> = path.iter().map(|&i| legs[i].bridge).collect();
        let distinct = bridges
            .iter()
            .collect::<std::collections::BTreeSet<_>>()
            .len();
        if distinct >= 2 {
            let mut key = path.clone();
            key.sort_unstable();
            if !seen.contains(&key) {
                seen.push(key);
                let mut media: Vec<String> =
                    path.iter().map(|&i| legs[i].from.to_string()).collect();
                media.push(first.from.to_string());
                found.push(Cycle {
                    media,
                    bridges: bridges.iter().map(|b| b.to_string()).collect(),
                    pos: first.pos.clone(),
                });
            }
        }
        return;
    }
    if path.len() >= MAX_LEN {
        return;
    }
    for (i, next) in legs.iter().enumerate() {
        if path.contains(&i) || next.from != last.to || !last.feeds(next) {
            continue;
        }
        // a bridge never forwards straight back to the medium it just took a message from
        if next.bridge == last.bridge && next.to == last.from {
            continue;
        }
        // visit each medium once, except for closing the loop
        if next.to != first.from && path.iter().any(|&j| legs[j].from == next.to) {
            continue;
        }
        path.push(i);
        walk(legs, path, found, seen);
        path.pop();
    }
}

/// What `seabus check` found in a valid system.
#[derive(Debug, Default)]
pub struct Report {
    /// Warnings (`FILE:LINE:COL: warning: …`).
    pub warnings: Vec<FileError>,
}

/// Checks a system against a registry: every medium URL, every module (built, so its parameters are
/// checked), every bridge and route. Returns warnings (route cycles) when valid.
pub fn check(
    spec: &SystemSpec,
    registry: &Registry,
    catalogue: &Catalogue,
) -> Result<Report, FileError> {
    if let Some(el) = spec
        .sections
        .iter()
        .find(|e| !registry.sections().any(|s| s == e.name))
    {
        let known: Vec<String> = TOP_TAGS
            .iter()
            .copied()
            .chain(registry.sections())
            .map(|t| format!("<{t}>"))
            .collect();
        return Err(el.error(format!(
            "unexpected element <{}> inside <seabus>; expected {}",
            el.name,
            known.join(", ")
        )));
    }
    for m in &spec.media {
        registry.capabilities(&m.url, &m.pos)?;
    }
    for el in &spec.sections {
        if let Some(t) = registry.service(&el.name) {
            (t.check)(el, spec, registry)?;
        }
    }
    for m in &spec.modules {
        for name in &m.media {
            spec.medium_at(name, &m.pos)?;
        }
        registry.build_module(m, catalogue)?;
    }
    for b in &spec.bridges {
        for name in &b.media {
            spec.medium_at(name, &b.pos)?;
        }
        registry.build_bridge(b, catalogue)?;
    }
    Ok(Report {
        warnings: route_cycles(spec).iter().map(Cycle::warning).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SystemSpec, FileError> {
        SystemSpec::parse("sys.xml", text)
    }

    #[test]
    fn a_full_system_parses() {
        let s = parse(
            r#"<seabus node="auv1">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="udp://239.255.42.1:47800?ttl=0"/>
  <module name="gen" type="generator" medium="bus" tick="5Hz" topic="a.b">
    <param name="amplitude" value="2"/>
  </module>
  <bridge name="up" media="bus net" hops="4">
    <route from="bus" topics="nav.*" rename="auv1.nav.*" rate="5" format="xml"/>
    <route topics="cmd.**" kind="command"><field name="hdg" rename="heading"/></route>
  </bridge>
</seabus>"#,
        )
        .unwrap();
        assert_eq!(s.node.as_deref(), Some("auv1"));
        assert_eq!(s.default_medium(), "bus");
        let m = &s.modules[0];
        assert_eq!(
            (m.type_name.as_str(), m.media.clone(), m.tick),
            (
                "generator",
                vec!["bus".to_string()],
                Some(std::time::Duration::from_millis(200))
            )
        );
        assert_eq!(m.params.str("topic"), Some("a.b"));
        assert_eq!(m.params.str("amplitude"), Some("2"));
        let b = &s.bridges[0];
        assert_eq!((b.hops, b.type_name.as_str()), (4, "route"));
        assert_eq!(b.routes[0].legs("bus", "net"), [("bus", "net")]);
        assert_eq!(
            b.routes[1].legs("bus", "net"),
            [("bus", "net"), ("net", "bus")]
        );
        assert_eq!(
            b.routes[1].fields,
            [("hdg".to_string(), "heading".to_string())]
        );
        assert_eq!(b.routes[0].format, Some(Format::Xml));
    }

    #[test]
    fn structural_errors_are_placed_and_explained() {
        let cases = [
            (
                "<system/>",
                "sys.xml:1:1: root element is <system>, expected <seabus>",
            ),
            (
                "<seabus>\n</seabus>",
                "sys.xml:1:1: a system needs at least one <medium>",
            ),
            (
                "<seabus>\n  <medium url=\"inproc://\"/>\n</seabus>",
                "sys.xml:2:3: <medium> is missing attribute `name`",
            ),
            (
                "<seabus><medium name=\"a\" url=\"inproc://\"/><medium name=\"a\" url=\"inproc://\"/></seabus>",
                "sys.xml:1:51: attribute `name`: a medium `a` is already defined at line 1",
            ),
            (
                "<seabus><medium name=\"bus\" url=\"inproc://\"/><bridge name=\"b\" media=\"bus\"/></seabus>",
                "sys.xml:1:62: attribute `media`: a bridge joins exactly two media, `bus` names 1",
            ),
            (
                "<seabus><medium name=\"a b\" url=\"inproc://\"/></seabus>",
                "sys.xml:1:17: attribute `name`: `a b` is not a name: use letters, digits, `_` and `-` (it becomes part of topics)",
            ),
        ];
        for (text, expected) in cases {
            let got = parse(text).map(|_| ()).unwrap_err().to_string();
            assert_eq!(got, expected, "for {text}");
        }
    }

    #[test]
    fn route_errors_are_placed() {
        let base = |route: &str| {
            format!(
                "<seabus><medium name=\"a\" url=\"inproc://\"/><medium name=\"b\" url=\"inproc://\"/>\n<bridge name=\"x\" media=\"a b\">\n{route}\n</bridge></seabus>"
            )
        };
        let e = parse(&base("<route from=\"c\" topics=\"**\"/>")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "sys.xml:3:8: attribute `from`: `c` is not one of this bridge's media (a and b)"
        );
        let e = parse(&base("<route topics=\"nav.*\" rename=\"x.*.*\"/>")).unwrap_err();
        assert!(e.message.contains("wildcards"), "{e}");
        let e = parse(&base("<route topics=\"nav..x\"/>")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("sys.xml:3:8: attribute `topics`: empty segment"),
            "{e}"
        );
        let e = parse(&base("<route topics=\"**\" rate=\"0\"/>")).unwrap_err();
        assert!(e.message.contains("above 0"), "{e}");
        let e = parse(&base("<route topics=\"**\" format=\"json\"/>")).unwrap_err();
        assert!(e.message.contains("bytes, map or xml"), "{e}");
    }

    #[test]
    fn a_route_reads_its_quality_of_service_attribute_by_attribute() {
        let route = |attrs: &str| {
            let text = format!(
                "<seabus><medium name=\"a\" url=\"inproc://\"/><medium name=\"b\" url=\"inproc://\"/>\n\
                 <bridge name=\"x\" media=\"a b\">\n<route to=\"b\" topics=\"**\" {attrs}/>\n</bridge></seabus>"
            );
            parse(&text).map(|s| s.bridges[0].routes[0].qos.clone())
        };
        assert_eq!(route("").unwrap(), None);
        let all = route(r#"express="true" priority="data-high" congestion="block""#)
            .unwrap()
            .unwrap();
        assert_eq!(
            all.qos,
            Qos {
                priority: Some(Priority::DataHigh),
                congestion: Some(Congestion::Block),
                express: Some(true),
            }
        );
        assert_eq!(
            (all.attr.name.as_str(), all.attr.pos.line, all.attr.pos.col),
            ("express", 3, 27),
            "the first of them as written"
        );
        let one = route(r#"priority="background""#).unwrap().unwrap();
        assert_eq!(
            one.qos,
            Qos {
                priority: Some(Priority::Background),
                ..Qos::default()
            },
            "what is not said stays the kind's"
        );
        let cases = [
            (
                r#"priority="urgent""#,
                "sys.xml:3:27: attribute `priority`: `urgent` is not a priority; expected realtime, \
                 interactive-high, interactive-low, data-high, data, data-low or background",
            ),
            (
                r#"congestion="wait""#,
                "sys.xml:3:27: attribute `congestion`: `wait` is not a congestion control; expected \
                 block or drop",
            ),
            (
                r#"express="often""#,
                "sys.xml:3:27: attribute `express`: `often` is not true or false",
            ),
        ];
        for (attrs, expected) in cases {
            assert_eq!(route(attrs).unwrap_err().to_string(), expected, "{attrs}");
        }
    }

    #[test]
    fn unknown_sections_are_refused_by_check() {
        let s = parse("<seabus><medium name=\"bus\" url=\"inproc://\"/><gizmo/></seabus>").unwrap();
        let e = check(&s, &Registry::new(), &Catalogue::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "sys.xml:1:45: unexpected element <gizmo> inside <seabus>; expected <medium>, <module>, <bridge>"
        );
    }

    fn cycles_of(text: &str) -> Vec<Cycle> {
        route_cycles(&parse(text).unwrap())
    }

    #[test]
    fn cycles_through_several_bridges_are_found() {
        let three = r#"<seabus>
 <medium name="a" url="inproc://"/><medium name="b" url="inproc://"/><medium name="c" url="inproc://"/>
 <bridge name="ab" media="a b"><route topics="**"/></bridge>
 <bridge name="bc" media="b c"><route topics="**"/></bridge>
 <bridge name="ca" media="c a"><route topics="**"/></bridge>
</seabus>"#;
        let cycles = cycles_of(three);
        assert_eq!(cycles.len(), 2, "one each way round: {cycles:?}");
        assert_eq!(cycles[0].media, ["a", "b", "c", "a"]);
        assert_eq!(cycles[0].bridges, ["ab", "bc", "ca"]);
        assert!(
            cycles[0]
                .warning()
                .to_string()
                .starts_with("sys.xml:3:32: warning: route cycle a -> b -> c -> a")
        );

        // one bridge both ways is not a cycle; two bridges between the same media are
        let one = r#"<seabus><medium name="a" url="inproc://"/><medium name="b" url="inproc://"/>
 <bridge name="ab" media="a b"><route topics="**"/></bridge></seabus>"#;
        assert!(cycles_of(one).is_empty());
        let two = r#"<seabus><medium name="a" url="inproc://"/><medium name="b" url="inproc://"/>
 <bridge name="x" media="a b"><route from="a" topics="nav.**"/></bridge>
 <bridge name="y" media="a b"><route from="b" topics="nav.*"/></bridge></seabus>"#;
        assert_eq!(cycles_of(two).len(), 1);
    }

    #[test]
    fn disjoint_or_renamed_topics_break_cycles() {
        let open = r#"<seabus>
 <medium name="a" url="inproc://"/><medium name="b" url="inproc://"/><medium name="c" url="inproc://"/>
 <bridge name="ab" media="a b"><route from="a" topics="nav.**"/></bridge>
 <bridge name="bc" media="b c"><route from="b" topics="nav.**"/></bridge>
 <bridge name="ca" media="c a"><route from="c" topics="cmd.**"/></bridge>
</seabus>"#;
        assert!(cycles_of(open).is_empty());
        let renamed = r#"<seabus>
 <medium name="a" url="inproc://"/><medium name="b" url="inproc://"/><medium name="c" url="inproc://"/>
 <bridge name="ab" media="a b"><route from="a" topics="nav.**" rename="remote.nav.**"/></bridge>
 <bridge name="bc" media="b c"><route from="b" topics="remote.**"/></bridge>
 <bridge name="ca" media="c a"><route from="c" topics="remote.**" rename="cmd.**"/></bridge>
</seabus>"#;
        assert!(cycles_of(renamed).is_empty(), "cmd.** never matches nav.**");
        let kinds = r#"<seabus><medium name="a" url="inproc://"/><medium name="b" url="inproc://"/>
 <bridge name="x" media="a b"><route from="a" topics="**" kind="data"/></bridge>
 <bridge name="y" media="a b"><route from="b" topics="**" kind="command"/></bridge></seabus>"#;
        assert!(cycles_of(kinds).is_empty(), "data never becomes a command");
        let renamed_back = renamed.replace("rename=\"cmd.**\"", "rename=\"nav.**\"");
        assert_eq!(cycles_of(&renamed_back).len(), 1);
    }
}
