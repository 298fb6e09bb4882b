//! Template expansion: `${name}` substituted in every attribute (from the `<use>`'s attributes
//! out to the layout's `<var>`s) and each `<use template="…">` replaced by its template's elements,
//! within bounds on size, depth and recursion.

use seabus_medium::xml::{self, Attr, Element, FileError};
use std::collections::BTreeMap;

/// Most elements a layout may have once its templates are expanded.
pub const MAX_ELEMENTS: usize = 10_000;

/// Most characters of attribute text a layout may have once its variables are substituted.
pub const MAX_TEXT: usize = 1 << 20;

/// Deepest chain of templates using templates.
pub const MAX_TEMPLATE_DEPTH: usize = 32;

/// The parameters in scope: the attributes of the `<use>`s being expanded, innermost first.
type Params<'p> = [&'p BTreeMap<String, String>];

/// Substitutes variables and expands templates.
pub(super) struct Expander<'a> {
    vars: &'a BTreeMap<String, String>,
    templates: BTreeMap<String, &'a Element>,
    /// The templates being expanded, outermost first.
    stack: Vec<String>,
    elements: usize,
    text: usize,
}

impl<'a> Expander<'a> {
    /// An expander with the layout's variables (their values) and templates (by name).
    pub(super) fn new(
        vars: &'a BTreeMap<String, String>,
        templates: BTreeMap<String, &'a Element>,
    ) -> Self {
        Expander {
            vars,
            templates,
            stack: Vec::new(),
            elements: 0,
            text: 0,
        }
    }

    /// `a`'s value with every `${name}` replaced: from the innermost `<use>`'s attributes out,
    /// then the layout's variables.
    fn substitute(&mut self, a: &Attr, params: &Params) -> Result<String, FileError> {
        let mut out = String::new();
        let mut rest = a.value.as_str();
        while let Some(i) = rest.find("${") {
            out.push_str(&rest[..i]);
            let after = &rest[i + 2..];
            let Some(j) = after.find('}') else {
                return Err(a.error("`${` is not closed by `}`"));
            };
            out.push_str(self.variable(a, after[..j].trim(), params)?);
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

    /// The value of variable `name` in `a`.
    fn variable<'v>(
        &'v self,
        a: &Attr,
        name: &str,
        params: &Params<'v>,
    ) -> Result<&'v String, FileError> {
        params
            .iter()
            .find_map(|p| p.get(name))
            .or_else(|| self.vars.get(name))
            .ok_or_else(|| {
                a.error(format!(
                    "undefined variable `{name}`: declare it with <var name=\"{name}\" default=\"…\"/>{}",
                    if self.stack.is_empty() { "" } else { " or give it on the <use>" }
                ))
            })
    }

    /// `el`'s attributes with their variables substituted.
    pub(super) fn attrs(&mut self, el: &Element, params: &Params) -> Result<Vec<Attr>, FileError> {
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
    pub(super) fn expand(
        &mut self,
        el: &Element,
        params: &Params,
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
            return self.use_template(el, attrs, params, depth);
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

    /// The elements a `<use>` (with its attributes substituted) stands for.
    fn use_template(
        &mut self,
        el: &Element,
        attrs: Vec<Attr>,
        params: &Params,
        depth: usize,
    ) -> Result<Vec<Element>, FileError> {
        el.only_children(&[])?;
        let Some(name_at) = attrs.iter().find(|a| a.name == "template").cloned() else {
            return Err(el.error("<use> is missing attribute `template`"));
        };
        let name = name_at.value.trim();
        let template = self.template(&name_at, name)?;
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
        Ok(out)
    }

    /// Template `name`, which `at` uses: one that is defined and not already being expanded.
    fn template(&self, at: &Attr, name: &str) -> Result<&'a Element, FileError> {
        let Some(template) = self.templates.get(name).copied() else {
            let known: Vec<&str> = self.templates.keys().map(String::as_str).collect();
            return Err(at.error(format!(
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
            return Err(at.error(format!(
                "template `{name}` uses itself: {}",
                chain.join(" → ")
            )));
        }
        if self.stack.len() >= MAX_TEMPLATE_DEPTH {
            return Err(at.error(format!(
                "templates used inside templates deeper than {MAX_TEMPLATE_DEPTH}"
            )));
        }
        Ok(template)
    }
}

#[cfg(test)]
mod tests {
    use super::super::Layout;
    use super::super::testing::{EXAMPLE, error, parse, wrong_errors};
    use std::collections::BTreeMap;

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
    fn unknown_templates_and_variables_are_placed_and_explained() {
        let cases = [
            (
                "<layout name=\"t\">\n  <use template=\"nope\"/>\n</layout>",
                "2:8: attribute `template`: no template called `nope`; templates: none",
            ),
            (
                "<layout name=\"t\" title=\"${x}\"/>",
                "1:18: attribute `title`: undefined variable `x`: declare it with <var name=\"x\" default=\"…\"/>",
            ),
        ];
        let wrong = wrong_errors(&cases, |text| text.to_string());
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
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
}
