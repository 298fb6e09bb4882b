//! A small XML tree for the files users write (system files, datasets, layouts, health rules), in
//! which every element and attribute remembers its file, line and column, so that every error can
//! say `FILE:LINE:COL: what was expected`.

use crate::xmlform::resolve_ref;
use quick_xml::events::{BytesStart, Event};
use quick_xml::reader::Reader;
use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use thiserror::Error;

/// Deepest element nesting a file may have.
pub const MAX_DEPTH: usize = 256;

/// A place in a file: 1-based line and column (in characters).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pos {
    /// The file's name as the user gave it.
    pub file: Arc<str>,
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1, in characters.
    pub col: u32,
}

impl Pos {
    /// An error at this place.
    pub fn error(&self, message: impl Into<String>) -> FileError {
        FileError {
            pos: self.clone(),
            message: message.into(),
        }
    }
}

impl fmt::Display for Pos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file, self.line, self.col)
    }
}

/// An error in a file, printed as `FILE:LINE:COL: message`.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{pos}: {message}")]
pub struct FileError {
    /// Where.
    pub pos: Pos,
    /// What was wrong, and what was expected.
    pub message: String,
}

/// An attribute and where it was written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Attr {
    /// Its name.
    pub name: String,
    /// Its value, with references resolved.
    pub value: String,
    /// Where the attribute starts.
    pub pos: Pos,
}

impl Attr {
    /// An error about this attribute's value.
    pub fn error(&self, message: impl fmt::Display) -> FileError {
        self.pos
            .error(format!("attribute `{}`: {message}", self.name))
    }

    /// Parses the value, naming the expected form on failure.
    pub fn parse<T: FromStr>(&self, expected: &str) -> Result<T, FileError> {
        self.value
            .trim()
            .parse()
            .map_err(|_| self.error(format!("`{}` is not {expected}", self.value)))
    }
}

/// An element with its attributes, children, text and place.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Element {
    /// The tag name.
    pub name: String,
    /// Attributes in order.
    pub attrs: Vec<Attr>,
    /// Child elements in order.
    pub children: Vec<Element>,
    /// The text directly inside, references resolved.
    pub text: String,
    /// Where the element starts (its `<`).
    pub pos: Pos,
}

impl Element {
    /// The attribute called `name`.
    pub fn attr(&self, name: &str) -> Option<&Attr> {
        self.attrs.iter().find(|a| a.name == name)
    }

    /// The value of attribute `name`.
    pub fn get(&self, name: &str) -> Option<&str> {
        self.attr(name).map(|a| a.value.as_str())
    }

    /// The attribute called `name`, or an error saying it is missing.
    pub fn required(&self, name: &str) -> Result<&Attr, FileError> {
        self.attr(name).ok_or_else(|| {
            self.pos
                .error(format!("<{}> is missing attribute `{name}`", self.name))
        })
    }

    /// Parses attribute `name` when present.
    pub fn parsed<T: FromStr>(&self, name: &str, expected: &str) -> Result<Option<T>, FileError> {
        self.attr(name).map(|a| a.parse(expected)).transpose()
    }

    /// Reads a boolean attribute (`true`/`false`, `yes`/`no`, `1`/`0`).
    pub fn flag(&self, name: &str) -> Result<Option<bool>, FileError> {
        match self.attr(name) {
            None => Ok(None),
            Some(a) => crate::parse::parse_bool(&a.value)
                .map(Some)
                .ok_or_else(|| a.error(format!("`{}` is not true or false", a.value.trim()))),
        }
    }

    /// Children with tag `name`.
    pub fn children_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Element> + 'a {
        self.children.iter().filter(move |c| c.name == name)
    }

    /// Fails on the first attribute not in `known`.
    pub fn only_attrs(&self, known: &[&str]) -> Result<(), FileError> {
        match self
            .attrs
            .iter()
            .find(|a| !known.contains(&a.name.as_str()))
        {
            None => Ok(()),
            Some(a) => Err(a.pos.error(format!(
                "unknown attribute `{}` on <{}>; expected one of: {}",
                a.name,
                self.name,
                known.join(", ")
            ))),
        }
    }

    /// Fails on the first child element not in `known`.
    pub fn only_children(&self, known: &[&str]) -> Result<(), FileError> {
        match self
            .children
            .iter()
            .find(|c| !known.contains(&c.name.as_str()))
        {
            None => Ok(()),
            Some(c) => Err(c.pos.error(format!(
                "unexpected element <{}> inside <{}>; expected {}",
                c.name,
                self.name,
                if known.is_empty() {
                    "no elements".to_string()
                } else {
                    known
                        .iter()
                        .map(|k| format!("<{k}>"))
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ))),
        }
    }

    /// An error at this element.
    pub fn error(&self, message: impl Into<String>) -> FileError {
        self.pos.error(message)
    }
}

/// Maps byte offsets to lines and columns.
struct Lines<'a> {
    text: &'a str,
    starts: Vec<usize>,
}

impl<'a> Lines<'a> {
    fn new(text: &'a str) -> Self {
        let mut starts = vec![0];
        starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Lines { text, starts }
    }

    fn pos(&self, file: &Arc<str>, offset: usize) -> Pos {
        let offset = offset.min(self.text.len());
        let line = self.starts.partition_point(|&s| s <= offset);
        let start = self.starts[line - 1];
        let col = self
            .text
            .get(start..offset)
            .map_or(offset - start, |s| s.chars().count())
            + 1;
        Pos {
            file: file.clone(),
            line: line as u32,
            col: col as u32,
        }
    }
}

/// Parses `text` (from a file called `file`) into its root element.
pub fn parse(file: &str, text: &str) -> Result<Element, FileError> {
    let file: Arc<str> = Arc::from(file);
    let lines = Lines::new(text);
    let mut reader = Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut stack: Vec<Element> = Vec::new();
    let mut root: Option<Element> = None;
    loop {
        let at = reader.buffer_position() as usize;
        let event = reader.read_event().map_err(|e| {
            let p = lines.pos(&file, reader.error_position() as usize);
            p.error(format!("XML syntax error: {e}"))
        })?;
        match event {
            Event::Start(_) | Event::Empty(_) if root.is_some() => {
                return Err(lines
                    .pos(&file, at)
                    .error("a second root element; a file has one root"));
            }
            Event::Start(_) if stack.len() >= MAX_DEPTH => {
                return Err(lines
                    .pos(&file, at)
                    .error(format!("elements nested deeper than {MAX_DEPTH}")));
            }
            Event::Start(e) => {
                let el = element(&e, at, &lines, &file)?;
                stack.push(el);
            }
            Event::Empty(e) => {
                let el = element(&e, at, &lines, &file)?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(el),
                    None => root = Some(el),
                }
            }
            Event::End(_) => {
                let Some(el) = stack.pop() else {
                    return Err(lines
                        .pos(&file, at)
                        .error("closing tag without an opening tag"));
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(el),
                    None => root = Some(el),
                }
            }
            Event::Text(t) => {
                let s = t.xml10_content();
                match stack.last_mut() {
                    Some(el) => el.text.push_str(&s),
                    None if s.trim().is_empty() => {}
                    None => {
                        return Err(lines.pos(&file, at).error("text outside the root element"));
                    }
                }
            }
            Event::GeneralRef(r) => {
                let c = resolve_ref(&r).ok_or_else(|| {
                    lines
                        .pos(&file, at)
                        .error(format!("unknown entity `&{};`", &*r))
                })?;
                match stack.last_mut() {
                    Some(el) => el.text.push(c),
                    None => {
                        return Err(lines.pos(&file, at).error("text outside the root element"));
                    }
                }
            }
            Event::CData(c) => {
                if let Some(el) = stack.last_mut() {
                    el.text.push_str(&c);
                }
            }
            Event::Eof => break,
            Event::Decl(_) | Event::Comment(_) | Event::PI(_) | Event::DocType(_) => {}
        }
    }
    if let Some(open) = stack.last() {
        return Err(lines.pos(&file, text.len()).error(format!(
            "file ends inside <{}> opened at line {}",
            open.name, open.pos.line
        )));
    }
    root.ok_or_else(|| {
        lines
            .pos(&file, text.len())
            .error("no root element: the file is empty")
    })
}

/// Where attribute `key` starts in an element's raw attribute text, searching from `from`, and
/// where its value ends: a name standing on its own (not inside an earlier attribute's value), so
/// `<t command="course.on" on="1">` places `on` at the second one.
fn find_attr(raw: &[u8], from: usize, key: &[u8]) -> Option<(usize, usize)> {
    let mut i = from;
    while i < raw.len() {
        let c = raw[i];
        if c == b'"' || c == b'\'' {
            // a value: skip to its closing quote
            i = raw[i + 1..]
                .iter()
                .position(|x| *x == c)
                .map_or(raw.len(), |p| i + 1 + p + 1);
            continue;
        }
        let boundary = i == 0 || raw[i - 1].is_ascii_whitespace();
        if boundary && raw[i..].starts_with(key) {
            let after = raw.get(i + key.len()).copied();
            if matches!(after, None | Some(b'=')) || after.is_some_and(|b| b.is_ascii_whitespace())
            {
                // past its value
                let mut j = i + key.len();
                while j < raw.len() && raw[j] != b'"' && raw[j] != b'\'' {
                    j += 1;
                }
                let end = match raw.get(j) {
                    Some(q) => raw[j + 1..]
                        .iter()
                        .position(|x| x == q)
                        .map_or(raw.len(), |p| j + 1 + p + 1),
                    None => raw.len(),
                };
                return Some((i, end));
            }
        }
        i += 1;
    }
    None
}

/// Reads and parses a file.
pub fn parse_file(path: &std::path::Path) -> Result<Element, FileError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| {
        Pos {
            file: Arc::from(name.as_str()),
            line: 1,
            col: 1,
        }
        .error(format!("cannot read: {e}"))
    })?;
    parse(&name, &text)
}

fn element(
    e: &BytesStart<'_>,
    at: usize,
    lines: &Lines<'_>,
    file: &Arc<str>,
) -> Result<Element, FileError> {
    let name = e.name().as_ref().to_string();
    let raw_start = at + 1 + name.len();
    let raw = e.attributes_raw();
    let mut attrs = Vec::new();
    let mut search_from = 0;
    for a in e.attributes() {
        let a = a.map_err(|err| {
            use quick_xml::events::attributes::AttrError;
            match err {
                AttrError::Duplicated(p, _) => lines
                    .pos(file, at + 1 + p)
                    .error(format!("attribute given twice on <{name}>")),
                AttrError::ExpectedEq(p)
                | AttrError::ExpectedValue(p)
                | AttrError::UnquotedValue(p)
                | AttrError::ExpectedQuote(p, _) => lines
                    .pos(file, at + 1 + p)
                    .error(format!("bad attribute on <{name}>: {err}")),
            }
        })?;
        let key = a.key.as_ref().to_string();
        let rel = find_attr(raw.as_bytes(), search_from, key.as_bytes());
        let attr_at = rel.map_or(at, |(r, _)| raw_start + r);
        if let Some((_, end)) = rel {
            search_from = end;
        }
        let value = a
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|err| {
                lines
                    .pos(file, attr_at)
                    .error(format!("bad value of attribute `{key}`: {err}"))
            })?
            .into_owned();
        if attrs.iter().any(|x: &Attr| x.name == key) {
            return Err(lines
                .pos(file, attr_at)
                .error(format!("attribute `{key}` given twice")));
        }
        attrs.push(Attr {
            name: key,
            value,
            pos: lines.pos(file, attr_at),
        });
    }
    Ok(Element {
        name,
        attrs,
        children: Vec::new(),
        text: String::new(),
        pos: lines.pos(file, at),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_attribute_is_placed_at_its_name_not_inside_an_earlier_value() {
        let root = parse(
            "t.xml",
            "<toggle command=\"course.on\" on=\"yes\" off='on'/>",
        )
        .unwrap();
        assert_eq!(root.attr("command").unwrap().pos.col, 9);
        assert_eq!(root.attr("on").unwrap().pos.col, 29);
        assert_eq!(root.attr("off").unwrap().pos.col, 38);
    }

    #[test]
    fn positions_are_lines_and_columns() {
        let text = "<?xml version=\"1.0\"?>\n<seabus node=\"a\">\n  <medium name=\"bus\"\n          url=\"inproc://\"/>\n</seabus>\n";
        let root = parse("sys.xml", text).unwrap();
        assert_eq!((root.pos.line, root.pos.col), (2, 1));
        assert_eq!(root.attr("node").unwrap().pos.col, 9);
        let m = &root.children[0];
        assert_eq!((m.pos.line, m.pos.col), (3, 3));
        let url = m.attr("url").unwrap();
        assert_eq!((url.pos.line, url.pos.col), (4, 11));
        assert_eq!(url.value, "inproc://");
    }

    #[test]
    fn syntax_errors_name_the_place() {
        let e = parse("f.xml", "<a>\n  <b>\n</a>\n").unwrap_err();
        assert_eq!(e.pos.line, 3, "{e}");
        assert!(e.to_string().starts_with("f.xml:3:"), "{e}");
        let e = parse("f.xml", "").unwrap_err();
        assert!(e.message.contains("empty"));
        let e = parse("f.xml", "<a x=\"1\" x=\"2\"/>").unwrap_err();
        assert!(e.message.contains("given twice"), "{e}");
        assert_eq!(e.pos.col, 10, "{e}");
        let e = parse("f.xml", "<a>\n<b>").unwrap_err();
        assert!(e.message.contains("ends inside <b>"), "{e}");
    }

    #[test]
    fn helpers_explain_what_is_missing() {
        let root = parse("f.xml", "<m type=\"x\" rate=\"fast\" bogus=\"1\"><p/></m>").unwrap();
        assert_eq!(
            root.required("name").unwrap_err().to_string(),
            "f.xml:1:1: <m> is missing attribute `name`"
        );
        let e = root.parsed::<f64>("rate", "a number").unwrap_err();
        assert_eq!(
            e.to_string(),
            "f.xml:1:13: attribute `rate`: `fast` is not a number"
        );
        let e = root.only_attrs(&["type", "rate"]).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("f.xml:1:25: unknown attribute `bogus`"),
            "{e}"
        );
        let e = root.only_children(&["param"]).unwrap_err();
        assert!(e.message.contains("unexpected element <p>"), "{e}");
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_crash() {
        let text = "<a>".repeat(30_000);
        let e = parse("f.xml", &text).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "f.xml:1:{}: elements nested deeper than {MAX_DEPTH}",
                3 * MAX_DEPTH + 1
            )
        );
    }

    #[test]
    fn entities_and_text_are_resolved() {
        let root = parse("f.xml", "<a v=\"x &amp; y\">1 &lt; 2 &#x41;</a>").unwrap();
        assert_eq!(root.get("v"), Some("x & y"));
        assert_eq!(root.text, "1 < 2 A");
    }
}
