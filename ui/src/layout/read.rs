//! Reading a layout file into the model: the `<layout>` element, its `<var>`s and `<template>`s,
//! then (templates expanded) its commands, widget tree and input bindings, and the ids of widgets
//! the file leaves unnamed. Every error names file, line and column; a file with several errors
//! has them all reported ([`Layout::load_all`]): an element in error is left out and the reading
//! goes on with the next one.

use super::commands::read_command;
use super::expand::Expander;
use super::model::{
    AxisBinding, CommandDecl, KeyBinding, Layout, Node, PadButton, TOP, widget_kinds,
};
use super::values::{name_attr, no_children, roles};
use seabus_medium::xml::{self, Attr, Element, FileError, Pos};
use std::collections::BTreeMap;
use std::path::Path;

impl Layout {
    /// Parses layout text; `vars` override the `<var>` defaults (unknown names are ignored).
    /// `${name}` is substituted in every attribute, and `<use>` replaced by its template's
    /// widgets, with the `<use>`'s attributes as the template's parameters.
    pub fn parse(
        file: &str,
        text: &str,
        vars: &BTreeMap<String, String>,
    ) -> Result<Layout, FileError> {
        Layout::parse_all(file, text, vars).map_err(first)
    }

    /// Reads and parses a layout file.
    pub fn load(path: &Path, vars: &BTreeMap<String, String>) -> Result<Layout, FileError> {
        Layout::load_all(path, vars).map_err(first)
    }

    /// As [`Layout::parse`], with every error the file has, in document order (an XML syntax
    /// error, a wrong `<layout>` element, variable or template stops the reading there).
    pub fn parse_all(
        file: &str,
        text: &str,
        vars: &BTreeMap<String, String>,
    ) -> Result<Layout, Vec<FileError>> {
        let root = xml::parse(file, text).map_err(|e| vec![e])?;
        Reader::layout(&root, vars)
    }

    /// As [`Layout::load`], with every error the file has (see [`Layout::parse_all`]).
    pub fn load_all(
        path: &Path,
        vars: &BTreeMap<String, String>,
    ) -> Result<Layout, Vec<FileError>> {
        let root = xml::parse_file(path).map_err(|e| vec![e])?;
        Reader::layout(&root, vars)
    }
}

/// The first of a file's errors.
fn first(mut errors: Vec<FileError>) -> FileError {
    errors.swap_remove(0)
}

/// Reads an expanded layout.
pub(super) struct Reader {
    /// The commands declared so far, by name.
    pub(super) commands: BTreeMap<String, CommandDecl>,
    /// Ids the file gives, and where.
    pub(super) ids: BTreeMap<String, Pos>,
    /// Commands whose declaration is in error, and where.
    pub(super) broken: BTreeMap<String, Pos>,
    /// The errors found so far (the elements in error are left out).
    pub(super) errors: Vec<FileError>,
}

/// The `<layout>` element's own attributes.
struct Header {
    name: String,
    title: String,
    roles: Vec<String>,
    vehicle: Option<String>,
}

/// What the elements inside `<layout>` give besides commands.
#[derive(Default)]
struct Body {
    widgets: Vec<Node>,
    keys: Vec<KeyBinding>,
    axes: Vec<AxisBinding>,
    buttons: Vec<PadButton>,
}

/// A layout's variables with their values, and its templates by name.
type Declarations<'a> = (BTreeMap<String, String>, BTreeMap<String, &'a Element>);

/// Every element `<layout>` may hold.
fn top_elements() -> Vec<&'static str> {
    TOP.iter().copied().chain(widget_kinds()).collect()
}

impl Reader {
    /// Reads the `<layout>` element `root`, with `given` overriding its variables' defaults.
    fn layout(root: &Element, given: &BTreeMap<String, String>) -> Result<Layout, Vec<FileError>> {
        let (vars, templates) = Reader::head(root, given).map_err(|e| vec![e])?;
        let mut ex = Expander::new(&vars, templates);
        let header = ex
            .attrs(root, &[])
            .and_then(|attrs| header(root, &attrs))
            .map_err(|e| vec![e])?;
        let mut reader = Reader {
            commands: BTreeMap::new(),
            ids: BTreeMap::new(),
            broken: BTreeMap::new(),
            errors: Vec::new(),
        };
        let mut children = Vec::new();
        for el in &root.children {
            if el.name != "var" && el.name != "template" {
                match ex.expand(el, &[], 1) {
                    Ok(els) => children.extend(els),
                    Err(e) => reader.errors.push(e),
                }
            }
        }
        reader.commands(&children);
        for c in reader.commands.values_mut() {
            c.vehicle.clone_from(&header.vehicle);
        }
        let body = reader.body(&children);
        if !reader.errors.is_empty() {
            let mut errors = reader.errors;
            errors.sort_by_key(|e| (e.pos.line, e.pos.col));
            errors.dedup();
            return Err(errors);
        }
        let mut root_node = root_node(body.widgets, &root.pos);
        reader.assign_ids(&mut root_node);
        Ok(Layout {
            name: header.name,
            title: header.title,
            roles: header.roles,
            vehicle: header.vehicle,
            vars,
            commands: reader.commands,
            root: root_node,
            keys: body.keys,
            axes: body.axes,
            buttons: body.buttons,
            file: root.pos.file.to_string(),
        })
    }

    /// The `<layout>` element's checks, its variables and its templates: an error here stops
    /// the reading.
    fn head<'a>(
        root: &'a Element,
        given: &BTreeMap<String, String>,
    ) -> Result<Declarations<'a>, FileError> {
        if root.name != "layout" {
            return Err(root.error(format!(
                "root element is <{}>, expected <layout>",
                root.name
            )));
        }
        root.only_attrs(&["name", "title", "roles", "vehicle"])?;
        let (vars, templates) = declarations(root, given)?;
        root.only_children(&top_elements())?;
        Ok((vars, templates))
    }

    /// Keeps `r`'s value, or its error among the file's errors.
    pub(super) fn keep<T>(&mut self, r: Result<T, FileError>) -> Option<T> {
        r.map_err(|e| self.errors.push(e)).ok()
    }

    /// Reads the `<command>`s among `children`; a name is declared once.
    fn commands(&mut self, children: &[Element]) {
        for el in children.iter().filter(|e| e.name == "command") {
            let c = match read_command(el) {
                Ok(c) => c,
                Err(e) => {
                    if let Some(name) = el.get("name") {
                        self.broken.insert(name.trim().to_string(), el.pos.clone());
                    }
                    self.errors.push(e);
                    continue;
                }
            };
            if let Some(prev) = self.commands.get(&c.name) {
                let e = el.error(format!(
                    "command `{}` is already declared at line {}",
                    c.name, prev.pos.line
                ));
                self.errors.push(e);
                continue;
            }
            self.commands.insert(c.name.clone(), c);
        }
        for el in children.iter().filter(|e| e.name == "command") {
            if let Some(a) = el.attr("resume") {
                let r = self.command_ref(a, Some(false));
                self.keep(r);
            }
        }
    }

    /// Reads the widgets, `<keys>` and `<gamepad>` among `children` (commands already read).
    fn body(&mut self, children: &[Element]) -> Body {
        let mut body = Body::default();
        let kinds = widget_kinds();
        for el in children {
            match el.name.as_str() {
                "command" => {}
                "keys" => {
                    let keys = self.keys(el);
                    body.keys.extend(self.keep(keys).unwrap_or_default());
                }
                "gamepad" => {
                    let pad = self.gamepad(el);
                    if let Some((axes, buttons)) = self.keep(pad) {
                        body.axes.extend(axes);
                        body.buttons.extend(buttons);
                    }
                }
                k if kinds.contains(&k) => {
                    let node = self.node(el);
                    body.widgets.extend(self.keep(node));
                }
                _ => {
                    let e = el.error(format!(
                        "unexpected element <{}> inside <layout>; expected {}",
                        el.name,
                        top_elements()
                            .iter()
                            .map(|k| format!("<{k}>"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ));
                    self.errors.push(e);
                }
            }
        }
        body
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
}

/// The layout's `<var>`s with their values (given, or their defaults) and its `<template>`s by
/// name, read in document order.
fn declarations<'a>(
    root: &'a Element,
    given: &BTreeMap<String, String>,
) -> Result<Declarations<'a>, FileError> {
    let mut vars = BTreeMap::new();
    let mut templates = BTreeMap::new();
    for el in &root.children {
        match el.name.as_str() {
            "var" => {
                let (name, value) = variable(el, given)?;
                if vars.contains_key(&name) {
                    let at = el.required("name")?;
                    return Err(at.error(format!("variable `{name}` is declared twice")));
                }
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
    Ok((vars, templates))
}

/// A `<var>`'s name and value: given, or its default.
fn variable(el: &Element, given: &BTreeMap<String, String>) -> Result<(String, String), FileError> {
    el.only_attrs(&["name", "default"])?;
    no_children(el)?;
    let name = name_attr(el.required("name")?, "a variable")?;
    let value = given
        .get(&name)
        .cloned()
        .unwrap_or_else(|| el.get("default").unwrap_or_default().to_string());
    Ok((name, value))
}

/// The name, title, roles and vehicle of `<layout>` (`attrs`: its attributes, variables
/// substituted).
fn header(root: &Element, attrs: &[Attr]) -> Result<Header, FileError> {
    let get = |n: &str| attrs.iter().find(|a| a.name == n);
    let name = match get("name") {
        Some(a) => name_attr(a, "a layout")?,
        None => return Err(root.error("<layout> is missing attribute `name`")),
    };
    let title = get("title").map_or_else(|| name.clone(), |a| a.value.trim().to_string());
    let roles = match get("roles") {
        Some(a) => roles(a)?,
        None => Vec::new(),
    };
    let vehicle = get("vehicle")
        .map(|a| name_attr(a, "a vehicle"))
        .transpose()?;
    Ok(Header {
        name,
        title,
        roles,
        vehicle,
    })
}

/// The root of the widget tree: the only top-level widget, or a `column` around them.
fn root_node(mut widgets: Vec<Node>, pos: &Pos) -> Node {
    if widgets.len() == 1 {
        widgets.remove(0)
    } else {
        Node {
            kind: "column".to_string(),
            id: String::new(),
            label: None,
            role: None,
            attrs: BTreeMap::new(),
            children: widgets,
            pos: pos.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::model::{Confirm, DEFAULT_HOLD, Node, Offset};
    use super::super::testing::{example, wrong_errors};
    use seabus_medium::Value;

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
    fn the_layout_element_is_checked() {
        let cases = [
            (
                "<page name=\"x\"/>",
                "1:1: root element is <page>, expected <layout>",
            ),
            ("<layout/>", "1:1: <layout> is missing attribute `name`"),
            (
                "<layout name=\"t\" vehicle=\"auv 1\"/>",
                "1:18: attribute `vehicle`: `auv 1` is not a vehicle name: use letters, digits, `_` and `-` (at most 64)",
            ),
            (
                "<layout name=\"t\" roles=\"pilot s!\"/>",
                "1:18: attribute `roles`: `s!` is not a role name: use letters, digits, `_` and `-`",
            ),
        ];
        let wrong = wrong_errors(&cases, |text| text.to_string());
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }
}
