//! Widgets: the attributes each kind takes, and the checks that read a widget element into a
//! [`Node`]: ids and roles, bindings, numbers and ranges, colours, track waypoints, and the
//! command and field an input widget sets.

use super::commands::article;
use super::model::{Node, widget_kinds};
use super::read::Reader;
use super::values::{
    bind, bind_pattern, colour, count, duration, field_list, field_value, finite, list, list_items,
    name_attr, no_children, pattern, topic,
};
use seabus_medium::xml::{Attr, Element, FileError};
use seabus_medium::{Pattern, Value};
use std::collections::BTreeMap;

/// The attributes of a node of `kind` besides `id`, `label` and `role`; `None` for an unknown kind.
fn kind_attrs(kind: &str) -> Option<&'static [&'static str]> {
    Some(match kind {
        "row" | "column" => &["sizes"],
        "tabs" => &[],
        "tab" => &["title"],
        "grid" => &["columns"],
        "readout" => &[
            "bind",
            "unit",
            "precision",
            "angle",
            "true",
            "false",
            "fresh",
        ],
        "gauge" => &[
            "bind",
            "min",
            "max",
            "unit",
            "precision",
            "ranges",
            "angle",
            "fresh",
        ],
        "plot" => &["window", "min", "max", "fresh"],
        "series" => &["bind", "colour", "unit", "angle"],
        "track" => &["position", "heading", "trail", "waypoints", "grid", "fresh"],
        "fleet" => &[
            "bind", "open", "var", "mode", "battery", "severity", "position", "fresh",
        ],
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

/// A flag: `true` or `false`.
fn flag(a: &Attr) -> Result<bool, FileError> {
    match a.value.trim() {
        "true" => Ok(true),
        "false" => Ok(false),
        v => Err(a.error(format!("`{v}` is not true or false"))),
    }
}

/// A finite number in a list item, as `ranges` and `waypoints` write them.
fn item_number(s: &str) -> Option<f64> {
    s.trim().parse::<f64>().ok().filter(|x| x.is_finite())
}

/// Checks `min` < `max` when both are given.
fn min_max(el: &Element) -> Result<(Option<f64>, Option<f64>), FileError> {
    let min = el.attr("min").map(finite).transpose()?;
    let max = el.attr("max").map(finite).transpose()?;
    if let (Some(lo), Some(hi), Some(a)) = (min, max, el.attr("max"))
        && lo >= hi
    {
        return Err(a.error(format!("the maximum {hi} is not above the minimum {lo}")));
    }
    Ok((min, max))
}

/// A container's `sizes`: one size above 0 for each of its `children` children.
fn sizes(a: &Attr, children: usize) -> Result<(), FileError> {
    let mut n = 0;
    for s in a.value.split_whitespace() {
        n += 1;
        if !s.parse::<f64>().is_ok_and(|x| x.is_finite() && x > 0.0) {
            return Err(a.error(format!("`{s}` is not a size (a number above 0)")));
        }
    }
    if n != children {
        return Err(a.error(format!(
            "{n} sizes for {children} children; give one size per child"
        )));
    }
    Ok(())
}

/// A gauge's `ranges="FROM:TO:COLOUR, …"`, each within `min`–`max` when they are given.
fn ranges(a: &Attr, min: Option<f64>, max: Option<f64>) -> Result<(), FileError> {
    for r in list_items(&a.value, ',') {
        let parts: Vec<&str> = r.splitn(3, ':').collect();
        let [from, to, c] = parts[..] else {
            return Err(a.error(format!("`{r}` is not FROM:TO:COLOUR")));
        };
        let (Some(from), Some(to)) = (item_number(from), item_number(to)) else {
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
    Ok(())
}

/// A track's `waypoints="LAT,LON; …"` in degrees.
fn waypoints(a: &Attr) -> Result<(), FileError> {
    for w in list_items(&a.value, ';') {
        let ll = w.split_once(',').and_then(|(lat, lon)| {
            let lat = item_number(lat).filter(|x| (-90.0..=90.0).contains(x))?;
            let lon = item_number(lon).filter(|x| (-180.0..=180.0).contains(x))?;
            Some((lat, lon))
        });
        if ll.is_none() {
            return Err(a.error(format!(
                "`{w}` is not LAT,LON (degrees, latitude −90 to 90, longitude −180 to 180)"
            )));
        }
    }
    Ok(())
}

/// A track's `grid`: a spacing in metres above 0, or `auto`.
fn grid(a: &Attr) -> Result<(), FileError> {
    let g = a.value.trim();
    if g != "auto" && !g.parse::<f64>().is_ok_and(|x| x.is_finite() && x > 0.0) {
        return Err(a.error(format!(
            "`{g}` is not a grid spacing in metres (above 0) or `auto`"
        )));
    }
    Ok(())
}

impl Reader {
    /// Reads a widget element (and the widgets inside it).
    pub(super) fn node(&mut self, el: &Element) -> Result<Node, FileError> {
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
            node.id = self.id(a)?;
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
        node.children = self.kind(el)?;
        Ok(node)
    }

    /// A widget's own id: unique in the layout.
    fn id(&mut self, a: &Attr) -> Result<String, FileError> {
        let id = a.value.trim();
        if id.is_empty() || id.len() > 64 || id.chars().any(|c| c.is_whitespace() || c.is_control())
        {
            return Err(a.error(format!(
                "`{id}` is not an id: no blanks, at most 64 characters"
            )));
        }
        if let Some(prev) = self.ids.get(id) {
            return Err(a.error(format!("id `{id}` is already used at line {}", prev.line)));
        }
        self.ids.insert(id.to_string(), a.pos.clone());
        Ok(id.to_string())
    }

    /// Checks what is particular to `el`'s kind; returns the nodes inside it.
    fn kind(&mut self, el: &Element) -> Result<Vec<Node>, FileError> {
        match el.name.as_str() {
            "row" | "column" | "grid" | "tab" => return self.container(el),
            "tabs" => {
                el.only_children(&["tab"])?;
                return self.children(el);
            }
            "plot" => return self.plot(el),
            "readout" | "gauge" => readout(el)?,
            "series" => series(el)?,
            "track" => track(el)?,
            "fleet" => fleet(el)?,
            "health" => health(el)?,
            "log" | "history" => log(el)?,
            "button" => self.button(el)?,
            "slider" | "number" => self.slider(el)?,
            "text" => self.text(el)?,
            "toggle" => self.toggle(el)?,
            kind => return Err(el.error(format!("unknown widget <{kind}>"))),
        }
        Ok(Vec::new())
    }

    /// The nodes inside `el`; those in error are left out, their errors kept.
    fn children(&mut self, el: &Element) -> Result<Vec<Node>, FileError> {
        let mut nodes = Vec::new();
        for c in &el.children {
            let node = self.node(c);
            nodes.extend(self.keep(node));
        }
        Ok(nodes)
    }

    /// `<row>`, `<column>`, `<grid>` and `<tab>`: any widgets, with their sizes or columns.
    fn container(&mut self, el: &Element) -> Result<Vec<Node>, FileError> {
        el.only_children(&widget_kinds())?;
        let children = self.children(el)?;
        if let Some(a) = el.attr("sizes") {
            sizes(a, el.children.len())?;
        }
        if let Some(a) = el.attr("columns") {
            count(a, 1, 64)?;
        }
        if el.name == "tab" {
            el.required("title")?;
        }
        Ok(children)
    }

    /// `<plot>`: one or more `<series>`.
    fn plot(&mut self, el: &Element) -> Result<Vec<Node>, FileError> {
        el.only_children(&["series"])?;
        if el.children.is_empty() {
            return Err(el.error("a <plot> needs at least one <series bind=\"topic.field\"/>"));
        }
        let children = self.children(el)?;
        if let Some(a) = el.attr("window") {
            duration(a)?;
        }
        min_max(el)?;
        Ok(children)
    }

    /// `<button>`: a whole command, with the fields it sets fitting the command.
    fn button(&self, el: &Element) -> Result<(), FileError> {
        no_children(el)?;
        let (name, _) = self.command_ref(el.required("command")?, Some(false))?;
        if let Some(a) = el.attr("set") {
            let set = field_list(&a.value).map_err(|e| a.error(e))?;
            if let Some(c) = self.commands.get(&name) {
                for (f, v) in set.iter() {
                    c.fit(f, v).map_err(|e| a.error(e))?;
                }
            }
        }
        Ok(())
    }

    /// `<slider>` and `<number>`: a numeric field, its range and step.
    fn slider(&self, el: &Element) -> Result<(), FileError> {
        no_children(el)?;
        let a = el.required("command")?;
        let (name, field) = self.command_ref(a, Some(true))?;
        self.numeric_field(a, &name, field.as_deref().unwrap_or_default())?;
        min_max(el)?;
        if let Some(a) = el.attr("step")
            && !finite(a).is_ok_and(|s| s > 0.0)
        {
            return Err(a.error(format!(
                "`{}` is not a step (a number above 0)",
                a.value.trim()
            )));
        }
        Ok(())
    }

    /// `<text>`: a text field.
    fn text(&self, el: &Element) -> Result<(), FileError> {
        no_children(el)?;
        let a = el.required("command")?;
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
        Ok(())
    }

    /// `<toggle>`: a field whose `on` and `off` values fit it.
    fn toggle(&self, el: &Element) -> Result<(), FileError> {
        no_children(el)?;
        let a = el.required("command")?;
        let (name, field) = self.command_ref(a, Some(true))?;
        let field = field.unwrap_or_default();
        if let Some(c) = self.commands.get(&name) {
            for (which, default) in [("on", "true"), ("off", "false")] {
                let at = el.attr(which).unwrap_or(a);
                let v = field_value(el.get(which).map_or(default, str::trim));
                c.fit(&field, &v).map_err(|e| at.error(e))?;
            }
        }
        Ok(())
    }
}

/// `<readout>` and `<gauge>`: a binding, precision, range and coloured ranges; whether the value
/// is an angle (a gauge of an angle is a compass dial over 0–360°, with no `min` or `max`).
fn readout(el: &Element) -> Result<(), FileError> {
    no_children(el)?;
    bind(el.required("bind")?)?;
    if let Some(a) = el.attr("precision") {
        count(a, 0, 15)?;
    }
    let angle = el.attr("angle").map(flag).transpose()?.unwrap_or(false);
    if angle && el.name == "gauge" {
        if let Some(a) = el.attr("min").or_else(|| el.attr("max")) {
            return Err(a.error(
                "a gauge of an angle is a compass dial over 0–360°: leave out `min` and `max`",
            ));
        }
        if let Some(a) = el.attr("ranges") {
            return ranges(a, Some(0.0), Some(360.0));
        }
    }
    let (min, max) = min_max(el)?;
    if let Some(a) = el.attr("ranges") {
        ranges(a, min, max)?;
    }
    Ok(())
}

/// `<series>` of a plot: a binding, a colour, and whether its values are angles.
fn series(el: &Element) -> Result<(), FileError> {
    no_children(el)?;
    bind(el.required("bind")?)?;
    if let Some(a) = el.attr("colour") {
        colour(a, &a.value)?;
    }
    if let Some(a) = el.attr("angle") {
        flag(a)?;
    }
    Ok(())
}

/// `<track>`: a position topic (or a pattern: one trail per vehicle, `*.nav.position`), a
/// heading binding, the trail, waypoints and grid.
fn track(el: &Element) -> Result<(), FileError> {
    no_children(el)?;
    let a = el.required("position")?;
    pattern(a, &a.value)?;
    if let Some(a) = el.attr("heading") {
        bind_pattern(a)?;
    }
    if let Some(a) = el.attr("trail") {
        count(a, 1, 1_000_000)?;
    }
    if let Some(a) = el.attr("waypoints") {
        waypoints(a)?;
    }
    if let Some(a) = el.attr("grid") {
        grid(a)?;
    }
    Ok(())
}

/// `<fleet>`: the fleet's topic, the layout each vehicle opens with and its variable, and where
/// each vehicle's mode, battery, severity and position are (topics under the vehicle's name).
fn fleet(el: &Element) -> Result<(), FileError> {
    no_children(el)?;
    if let Some(a) = el.attr("bind") {
        topic(a, &a.value)?;
    }
    if let Some(a) = el.attr("open") {
        name_attr(a, "a layout")?;
    }
    if let Some(a) = el.attr("var") {
        name_attr(a, "a variable")?;
    }
    for name in ["mode", "battery", "severity"] {
        if let Some(a) = el.attr(name) {
            bind(a)?;
        }
    }
    if let Some(a) = el.attr("position") {
        topic(a, &a.value)?;
    }
    Ok(())
}

/// `<health>`: the topic of a health table.
fn health(el: &Element) -> Result<(), FileError> {
    no_children(el)?;
    if let Some(a) = el.attr("bind") {
        topic(a, &a.value)?;
    }
    Ok(())
}

/// `<log>` and `<history>`: topic patterns and a number of lines.
fn log(el: &Element) -> Result<(), FileError> {
    no_children(el)?;
    if let Some(a) = el.attr("topics") {
        for t in list(&a.value) {
            Pattern::new(t).map_err(|e| a.error(format!("`{t}` is not a topic pattern: {e}")))?;
        }
    }
    if let Some(a) = el.attr("lines") {
        count(a, 1, 100_000)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::testing::{parse, with, wrong_errors};

    #[test]
    fn widget_errors_are_placed_and_explained() {
        let cases = [
            (
                "<layout name=\"t\">\n  <readout bind=\"a.b\" colour=\"red\"/>\n</layout>",
                "2:23: unknown attribute `colour` on <readout>; expected one of: id, label, role, bind, unit, precision, angle, true, false, fresh",
            ),
            (
                "<layout name=\"t\">\n  <column><dial/></column>\n</layout>",
                "2:11: unexpected element <dial> inside <column>; expected <row>, <column>, <tabs>, <grid>, <readout>, <gauge>, <plot>, <track>, <fleet>, <health>, <log>, <history>, <button>, <slider>, <number>, <text>, <toggle>",
            ),
            (
                "<layout name=\"t\">\n  <fleet mode=\"vehicle-state\"/>\n</layout>",
                "2:10: attribute `mode`: `vehicle-state` is not topic.field (the field is after the last dot: nav.depth.depth)",
            ),
            (
                "<layout name=\"t\">\n  <fleet open=\"a b\"/>\n</layout>",
                "2:10: attribute `open`: `a b` is not a layout name: use letters, digits, `_` and `-` (at most 64)",
            ),
            (
                "<layout name=\"t\">\n  <track position=\"*.nav..position\"/>\n</layout>",
                "2:10: attribute `position`: `*.nav..position` is not a topic pattern: empty segment in \"*.nav..position\" (two dots in a row, or a dot at an end)",
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
                "<layout name=\"t\">\n  <readout bind=\"a.b\" angle=\"yes\"/>\n</layout>",
                "2:23: attribute `angle`: `yes` is not true or false",
            ),
            (
                "<layout name=\"t\">\n  <gauge bind=\"a.b\" angle=\"true\" max=\"180\"/>\n</layout>",
                "2:34: attribute `max`: a gauge of an angle is a compass dial over 0–360°: leave out `min` and `max`",
            ),
            (
                "<layout name=\"t\">\n  <gauge bind=\"a.b\" angle=\"true\" ranges=\"350:370:red\"/>\n</layout>",
                "2:34: attribute `ranges`: range `350:370:red` is outside min–max",
            ),
            (
                "<layout name=\"t\">\n  <plot><series bind=\"a.b\" angle=\"1\"/></plot>\n</layout>",
                "2:28: attribute `angle`: `1` is not true or false",
            ),
            (
                "<layout name=\"t\">\n  <plot/>\n</layout>",
                "2:3: a <plot> needs at least one <series bind=\"topic.field\"/>",
            ),
        ];
        let wrong = wrong_errors(&cases, |text| text.to_string());
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }

    #[test]
    fn widgets_name_commands_and_fields_that_exist_and_fit() {
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
                "<toggle on=\"yes\" command=\"course.on\"/>",
                "4:9: attribute `on`: field `on` is a bool, not a string `\"yes\"`",
            ),
        ];
        let wrong = wrong_errors(&cases, with);
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
        parse(&with(
            "<toggle command=\"course.on\"/><text command=\"course.name\"/>",
        ))
        .unwrap();
    }
}
