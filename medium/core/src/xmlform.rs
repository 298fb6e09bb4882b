//! The XML form of a datamap (documented in `docs/wire-formats.md`).
//!
//! ```xml
//! <datamap>
//!   <float name="yaw">90.5</float>
//!   <int name="n">-2</int>
//!   <bool name="ok">true</bool>
//!   <string name="id">a</string>
//!   <bytes name="raw">AQI=</bytes>
//!   <list name="xs"><int>1</int><string>two</string></list>
//!   <map name="pose"><float name="x">1.5</float><map name="empty"></map></map>
//! </datamap>
//! ```
//! A `<map>` holds named entries as `<datamap>` does; lists and maps nest at most [`MAX_DEPTH`] deep
//! (counted together).
//! The form is lossless: floats are written in the shortest form that reads back to the same bits
//! (a NaN with a payload as `NaN:0x…`), carriage returns and attribute whitespace as character
//! references, and a string or name holding a character XML 1.0 cannot carry (C0 controls other than
//! tab, newline and carriage return; U+FFFE; U+FFFF) is written in base64 with `encoding="base64"` /
//! `name-base64="…"`. Readers accept any whitespace between elements and around numbers.

use crate::datamap::{DataMap, MAX_DEPTH, TooDeep, Value};
use base64::Engine as _;
use base64::engine::general_purpose::STANDARD as B64;
use quick_xml::events::Event;
use quick_xml::reader::Reader;
use std::borrow::Cow;
use std::fmt::Write as _;
use thiserror::Error;

/// Why XML text could not be read as a datamap; `offset` is the byte offset into the text.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{kind} at byte {offset}")]
pub struct XmlFormError {
    /// Byte offset into the XML text.
    pub offset: usize,
    /// What was wrong.
    pub kind: XmlFormErrorKind,
}

/// The kinds of [`XmlFormError`].
#[derive(Debug, Clone, PartialEq, Error)]
pub enum XmlFormErrorKind {
    /// The text is not well-formed XML.
    #[error("XML syntax: {0}")]
    Syntax(String),
    /// The text ended inside the document.
    #[error("document ends early (incomplete)")]
    Incomplete,
    /// The root element is not `<datamap>`.
    #[error("root element is <{0}>, expected <datamap>")]
    NotADataMap(String),
    /// An element that is not a value element.
    #[error("unexpected element <{0}>, expected one of bool, int, float, string, bytes, list, map")]
    UnknownElement(String),
    /// A datamap entry without a `name` attribute.
    #[error("<{0}> has no name attribute")]
    MissingName(String),
    /// Text that does not read as the element's type.
    #[error("{text:?} is not a valid {ty}")]
    BadValue {
        /// The element's type name.
        ty: &'static str,
        /// The offending text.
        text: String,
    },
    /// Text directly inside `<datamap>`, `<list>` or `<map>`.
    #[error("unexpected text {0:?} between elements")]
    StrayText(String),
    /// Content after the root element.
    #[error("content after </datamap>")]
    Trailing,
    /// Lists and maps nested deeper than [`MAX_DEPTH`].
    #[error("lists and maps nested deeper than {MAX_DEPTH}")]
    TooDeep,
}

impl XmlFormError {
    /// True when the text was cut short rather than malformed.
    pub fn is_incomplete(&self) -> bool {
        self.kind == XmlFormErrorKind::Incomplete
    }
}

/// Writes `map` in the XML form.
pub fn to_xml(map: &DataMap) -> Result<String, TooDeep> {
    let mut out = String::with_capacity(32 + map.len() * 40);
    out.push_str("<datamap>");
    for (k, v) in map.iter() {
        write_value(&mut out, Some(k), v, 0)?;
    }
    out.push_str("</datamap>");
    Ok(out)
}

/// Writes `v`, found inside `depth` lists and maps; a list or map is refused where the reader would
/// refuse it.
fn write_value(
    out: &mut String,
    name: Option<&str>,
    v: &Value,
    depth: usize,
) -> Result<(), TooDeep> {
    if matches!(v, Value::List(_) | Value::Map(_)) && depth >= MAX_DEPTH {
        return Err(TooDeep);
    }
    let tag = v.type_name();
    out.push('<');
    out.push_str(tag);
    if let Some(name) = name {
        if xml_safe(name) {
            out.push_str(" name=\"");
            escape_attr(out, name);
        } else {
            out.push_str(" name-base64=\"");
            out.push_str(&B64.encode(name));
        }
        out.push('"');
    }
    match v {
        Value::Bool(b) => {
            out.push('>');
            out.push_str(if *b { "true" } else { "false" });
        }
        Value::Int(i) => {
            out.push('>');
            out.push_str(itoa::Buffer::new().format(*i));
        }
        Value::Float(f) => {
            out.push('>');
            write_float(out, *f);
        }
        Value::Str(s) => {
            if xml_safe(s) {
                out.push('>');
                escape_text(out, s);
            } else {
                out.push_str(" encoding=\"base64\">");
                out.push_str(&B64.encode(s.as_bytes()));
            }
        }
        Value::Bytes(b) => {
            out.push('>');
            out.push_str(&B64.encode(b));
        }
        Value::List(items) => {
            out.push('>');
            for item in items {
                write_value(out, None, item, depth + 1)?;
            }
        }
        Value::Map(m) => {
            out.push('>');
            for (k, item) in m.iter() {
                write_value(out, Some(k), item, depth + 1)?;
            }
        }
    }
    out.push_str("</");
    out.push_str(tag);
    out.push('>');
    Ok(())
}

fn write_float(out: &mut String, f: f64) {
    if f.is_finite() {
        // the shortest text that parses back to the same bits ("1.0", "1e300", "-0.0")
        out.push_str(zmij::Buffer::new().format_finite(f));
    } else if f.is_nan() && f.to_bits() != f64::NAN.to_bits() {
        let _ = write!(out, "NaN:0x{:016x}", f.to_bits());
    } else if f.is_nan() {
        out.push_str("NaN");
    } else if f > 0.0 {
        out.push_str("inf");
    } else {
        out.push_str("-inf");
    }
}

/// True when every character of `s` can appear in XML 1.0 text.
fn xml_safe(s: &str) -> bool {
    !s.chars().any(|c| {
        (c < ' ' && !matches!(c, '\t' | '\n' | '\r')) || c == '\u{FFFE}' || c == '\u{FFFF}'
    })
}

fn escape_text(out: &mut String, s: &str) {
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '\r' => out.push_str("&#13;"),
            c => out.push(c),
        }
    }
}

fn escape_attr(out: &mut String, s: &str) {
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\t' => out.push_str("&#9;"),
            '\n' => out.push_str("&#10;"),
            '\r' => out.push_str("&#13;"),
            c => out.push(c),
        }
    }
}

/// Reads a datamap from its XML form.
pub fn from_xml(text: &str) -> Result<DataMap, XmlFormError> {
    let mut p = Parser::new(text);
    // prolog: declaration, comments, processing instructions, whitespace
    let (root, empty, root_at) = loop {
        let at = p.pos();
        match p.next()? {
            Event::Start(e) => break (e, false, at),
            Event::Empty(e) => break (e, true, at),
            Event::Decl(_) | Event::Comment(_) | Event::PI(_) | Event::DocType(_) => {}
            Event::Text(t) if is_blank(&t) => {}
            Event::Eof => return Err(p.err(at, XmlFormErrorKind::Incomplete)),
            _ => return Err(p.err(at, XmlFormErrorKind::NotADataMap("text".into()))),
        }
    };
    if root.name().as_ref() != "datamap" {
        return Err(p.err(
            root_at,
            XmlFormErrorKind::NotADataMap(root.name().as_ref().to_string()),
        ));
    }
    let mut map = DataMap::with_capacity(16);
    if !empty {
        while let Some((name, value)) = p.child(Some("datamap"), 0)? {
            map.push(name.unwrap_or_default(), value);
        }
    }
    loop {
        let at = p.pos();
        match p.next()? {
            Event::Eof => return Ok(map),
            Event::Comment(_) | Event::PI(_) => {}
            Event::Text(t) if is_blank(&t) => {}
            _ => return Err(p.err(at, XmlFormErrorKind::Trailing)),
        }
    }
}

fn is_blank(t: &str) -> bool {
    t.bytes().all(|b| b.is_ascii_whitespace())
}

/// The value elements.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Tag {
    Bool,
    Int,
    Float,
    Str,
    Bytes,
    List,
    Map,
}

impl Tag {
    fn parse(name: &str) -> Option<Tag> {
        Some(match name {
            "bool" => Tag::Bool,
            "int" => Tag::Int,
            "float" => Tag::Float,
            "string" => Tag::Str,
            "bytes" => Tag::Bytes,
            "list" => Tag::List,
            "map" => Tag::Map,
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            Tag::Bool => "bool",
            Tag::Int => "int",
            Tag::Float => "float",
            Tag::Str => "string",
            Tag::Bytes => "bytes",
            Tag::List => "list",
            Tag::Map => "map",
        }
    }
}

struct Parser<'a> {
    reader: Reader<&'a [u8]>,
    len: usize,
}

impl<'a> Parser<'a> {
    fn new(text: &'a str) -> Self {
        let mut reader = Reader::from_str(text);
        // end tags are matched here, against the element each one closes
        reader.config_mut().check_end_names = false;
        Parser {
            reader,
            len: text.len(),
        }
    }

    fn pos(&self) -> usize {
        self.reader.buffer_position() as usize
    }

    fn err(&self, offset: usize, kind: XmlFormErrorKind) -> XmlFormError {
        XmlFormError { offset, kind }
    }

    fn next(&mut self) -> Result<Event<'a>, XmlFormError> {
        self.reader.read_event().map_err(|e| {
            let offset = self.reader.error_position() as usize;
            use quick_xml::errors::{IllFormedError as I, SyntaxError as S};
            let at_end = offset + 3 >= self.len;
            let kind = match &e {
                quick_xml::Error::Syntax(
                    S::UnclosedTag
                    | S::UnclosedComment
                    | S::UnclosedCData
                    | S::UnclosedDoctype
                    | S::UnclosedPI
                    | S::UnclosedXmlDecl
                    | S::UnclosedSingleQuotedAttributeValue
                    | S::UnclosedDoubleQuotedAttributeValue,
                )
                | quick_xml::Error::IllFormed(I::UnclosedReference | I::MissingEndTag(_)) => {
                    XmlFormErrorKind::Incomplete
                }
                // `<!` with nothing after it yet
                quick_xml::Error::Syntax(S::InvalidBangMarkup) if at_end => {
                    XmlFormErrorKind::Incomplete
                }
                _ => XmlFormErrorKind::Syntax(e.to_string()),
            };
            XmlFormError { offset, kind }
        })
    }

    fn check_end(&self, at: usize, end: &str, open: &str) -> Result<(), XmlFormError> {
        if end == open {
            Ok(())
        } else {
            Err(self.err(
                at,
                XmlFormErrorKind::Syntax(format!("expected `</{open}>`, found `</{end}>`")),
            ))
        }
    }

    /// Reads the next child value of `<datamap>` or `<map>` (`parent` names it: its children are
    /// named) or of a `<list>` (`parent` is `None`), found inside `depth` lists and maps; `None` at
    /// the parent's end tag.
    fn child(
        &mut self,
        parent: Option<&str>,
        depth: usize,
    ) -> Result<Option<(Option<String>, Value)>, XmlFormError> {
        loop {
            let at = self.pos();
            let (start, empty) = match self.next()? {
                Event::Start(e) => (e, false),
                Event::Empty(e) => (e, true),
                Event::End(e) => {
                    self.check_end(at, e.name().as_ref(), parent.unwrap_or("list"))?;
                    return Ok(None);
                }
                Event::Comment(_) | Event::PI(_) => continue,
                Event::Text(t) if is_blank(&t) => continue,
                Event::Text(t) => {
                    let text = t.trim().to_string();
                    return Err(self.err(at, XmlFormErrorKind::StrayText(text)));
                }
                Event::GeneralRef(r) => {
                    let text = format!("&{};", &*r);
                    return Err(self.err(at, XmlFormErrorKind::StrayText(text)));
                }
                Event::CData(_) => {
                    return Err(self.err(at, XmlFormErrorKind::StrayText("CDATA".into())));
                }
                Event::Eof => return Err(self.err(at, XmlFormErrorKind::Incomplete)),
                Event::Decl(_) | Event::DocType(_) => {
                    return Err(
                        self.err(at, XmlFormErrorKind::Syntax("misplaced declaration".into()))
                    );
                }
            };
            let tag = Tag::parse(start.name().as_ref()).ok_or_else(|| {
                self.err(
                    at,
                    XmlFormErrorKind::UnknownElement(start.name().as_ref().to_string()),
                )
            })?;
            let (name, base64) = self.value_attributes(&start, at)?;
            if parent.is_some() && name.is_none() {
                return Err(self.err(at, XmlFormErrorKind::MissingName(tag.name().to_string())));
            }
            if matches!(tag, Tag::List | Tag::Map) && depth >= MAX_DEPTH {
                return Err(self.err(at, XmlFormErrorKind::TooDeep));
            }
            let value = match tag {
                Tag::List => {
                    let mut items = Vec::new();
                    if !empty {
                        while let Some((_, v)) = self.child(None, depth + 1)? {
                            items.push(v);
                        }
                    }
                    Value::List(items)
                }
                Tag::Map => {
                    let mut entries = DataMap::new();
                    if !empty {
                        while let Some((name, v)) = self.child(Some("map"), depth + 1)? {
                            entries.push(name.unwrap_or_default(), v);
                        }
                    }
                    Value::Map(entries)
                }
                _ => {
                    let text = if empty {
                        Cow::Borrowed("")
                    } else {
                        self.text(tag)?
                    };
                    self.scalar(tag, text, base64, at)?
                }
            };
            return Ok(Some((name, value)));
        }
    }

    /// The `name` (plain or `name-base64`) and whether the text is base64 (`encoding`), of a value
    /// element starting at byte `at`.
    fn value_attributes(
        &self,
        start: &quick_xml::events::BytesStart<'_>,
        at: usize,
    ) -> Result<(Option<String>, bool), XmlFormError> {
        let mut name = None;
        let mut base64 = false;
        // the form seabus writes, ` name="plain text"`, is read without the attribute parser
        let raw = start.attributes_raw();
        if let Some(plain) = raw
            .strip_prefix(" name=\"")
            .and_then(|r| r.strip_suffix('"'))
            .filter(|v| !v.contains(['"', '&', '<', '\t', '\n', '\r']))
        {
            name = Some(plain.to_string());
        }
        let mut attrs = start.attributes();
        attrs.with_checks(false);
        for attr in attrs.take(if name.is_some() { 0 } else { usize::MAX }) {
            let attr = attr.map_err(|e| self.err(at, XmlFormErrorKind::Syntax(e.to_string())))?;
            // a value with no reference and no whitespace to normalise is used as written
            let value = if attr.value.contains(['&', '\t', '\n', '\r']) {
                attr.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                    .map_err(|e| self.err(at, XmlFormErrorKind::Syntax(e.to_string())))?
            } else {
                attr.value.clone()
            };
            match attr.key.as_ref() {
                "name" => name = Some(value.into_owned()),
                "name-base64" => {
                    let raw = B64
                        .decode(value.as_bytes())
                        .ok()
                        .and_then(|b| String::from_utf8(b).ok());
                    match raw {
                        Some(n) => name = Some(n),
                        None => {
                            return Err(self.err(
                                at,
                                XmlFormErrorKind::BadValue {
                                    ty: "base64 name",
                                    text: value.into_owned(),
                                },
                            ));
                        }
                    }
                }
                "encoding" => base64 = value == "base64",
                _ => {}
            }
        }
        Ok((name, base64))
    }

    /// Collects the text of a `tag` element up to its end tag, resolving references; borrowed
    /// from the input when it is one plain run of text.
    fn text(&mut self, tag: Tag) -> Result<Cow<'a, str>, XmlFormError> {
        let mut out: Option<Cow<'a, str>> = None;
        loop {
            let at = self.pos();
            let piece: Cow<'a, str> = match self.next()? {
                Event::Text(t) => t.xml10_content(),
                Event::CData(c) => c.into_inner(),
                Event::GeneralRef(r) => match resolve_ref(&r) {
                    Some(c) => Cow::Owned(c.to_string()),
                    None => {
                        return Err(self.err(
                            at,
                            XmlFormErrorKind::Syntax(format!("unknown entity &{};", &*r)),
                        ));
                    }
                },
                Event::End(e) => {
                    self.check_end(at, e.name().as_ref(), tag.name())?;
                    return Ok(out.unwrap_or(Cow::Borrowed("")));
                }
                Event::Comment(_) | Event::PI(_) => continue,
                Event::Eof => return Err(self.err(at, XmlFormErrorKind::Incomplete)),
                Event::Start(e) | Event::Empty(e) => {
                    return Err(self.err(
                        at,
                        XmlFormErrorKind::UnknownElement(e.name().as_ref().to_string()),
                    ));
                }
                Event::Decl(_) | Event::DocType(_) => {
                    return Err(
                        self.err(at, XmlFormErrorKind::Syntax("misplaced declaration".into()))
                    );
                }
            };
            out = Some(match out {
                None => piece,
                Some(prev) => Cow::Owned(prev.into_owned() + &piece),
            });
        }
    }

    fn scalar(
        &self,
        tag: Tag,
        text: Cow<'_, str>,
        base64: bool,
        at: usize,
    ) -> Result<Value, XmlFormError> {
        let bad = |ty: &'static str, text: &str| {
            self.err(
                at,
                XmlFormErrorKind::BadValue {
                    ty,
                    text: text.to_string(),
                },
            )
        };
        Ok(match tag {
            Tag::Bool => match text.trim() {
                "true" | "1" => Value::Bool(true),
                "false" | "0" => Value::Bool(false),
                t => return Err(bad("bool", t)),
            },
            Tag::Int => Value::Int(text.trim().parse().map_err(|_| bad("int", &text))?),
            Tag::Float => {
                Value::Float(parse_float(text.trim()).ok_or_else(|| bad("float", &text))?)
            }
            Tag::Str if base64 => {
                let raw = B64
                    .decode(strip_ws(&text))
                    .ok()
                    .and_then(|b| String::from_utf8(b).ok());
                Value::from(raw.ok_or_else(|| bad("base64 string", &text))?)
            }
            Tag::Str => Value::from(text.into_owned()),
            Tag::Bytes => Value::Bytes(
                B64.decode(strip_ws(&text))
                    .map_err(|_| bad("base64 bytes", &text))?,
            ),
            Tag::List | Tag::Map => return Err(bad(tag.name(), &text)),
        })
    }
}

fn strip_ws(s: &str) -> Vec<u8> {
    s.bytes().filter(|b| !b.is_ascii_whitespace()).collect()
}

/// Resolves a predefined entity or character reference (without `&` and `;`).
pub(crate) fn resolve_ref(r: &str) -> Option<char> {
    match r {
        "lt" => Some('<'),
        "gt" => Some('>'),
        "amp" => Some('&'),
        "apos" => Some('\''),
        "quot" => Some('"'),
        _ => {
            let s = r.strip_prefix('#')?;
            let n = match s.strip_prefix('x') {
                Some(hex) => u32::from_str_radix(hex, 16).ok()?,
                None => s.parse().ok()?,
            };
            char::from_u32(n).filter(|c| *c != '\0')
        }
    }
}

fn parse_float(t: &str) -> Option<f64> {
    if let Some(hex) = t.strip_prefix("NaN:0x") {
        let bits = u64::from_str_radix(hex, 16).ok()?;
        let f = f64::from_bits(bits);
        return f.is_nan().then_some(f);
    }
    t.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datamap::nested_maps;

    fn sample() -> DataMap {
        DataMap::new()
            .with("yaw", 90.5f64)
            .with("n", -2i64)
            .with("ok", true)
            .with("id", "a<b & \"c\"\r\n\t")
            .with("raw", vec![1u8, 2])
            .with("xs", Value::List(vec![1i64.into(), "two".into()]))
            .with(
                "pose",
                DataMap::new()
                    .with("x", 1.5f64)
                    .with("k\u{1}ey", "a<b")
                    .with(
                        "wps",
                        Value::List(vec![DataMap::new().with("n", 1i64).into()]),
                    )
                    .with("empty", DataMap::new()),
            )
    }

    #[test]
    fn documented_example() {
        let map = DataMap::new()
            .with("yaw", 90.5f64)
            .with("n", -2i64)
            .with("ok", true)
            .with("id", "a")
            .with("raw", vec![1u8, 2])
            .with("xs", Value::List(vec![1i64.into(), "two".into()]));
        assert_eq!(
            to_xml(&map).unwrap(),
            "<datamap><float name=\"yaw\">90.5</float><int name=\"n\">-2</int>\
             <bool name=\"ok\">true</bool><string name=\"id\">a</string>\
             <bytes name=\"raw\">AQI=</bytes><list name=\"xs\"><int>1</int><string>two</string></list></datamap>"
        );
    }

    #[test]
    fn documented_nested_map() {
        let map = DataMap::new().with(
            "pose",
            DataMap::new()
                .with("x", 1.5f64)
                .with("empty", DataMap::new())
                .with(
                    "wps",
                    Value::List(vec![DataMap::new().with("n", 1i64).into()]),
                ),
        );
        let xml = to_xml(&map).unwrap();
        assert_eq!(
            xml,
            "<datamap><map name=\"pose\"><float name=\"x\">1.5</float><map name=\"empty\"></map>\
             <list name=\"wps\"><map><int name=\"n\">1</int></map></list></map></datamap>"
        );
        assert_eq!(from_xml(&xml).unwrap(), map);
    }

    #[test]
    fn nested_maps_read_as_written_by_hand() {
        let text = "<datamap>\n  <map name=\"pose\">\n    <int name=\"x\">1</int>\n    \
                    <map name=\"e\"/>\n  </map>\n  <list name=\"l\"><map/><map></map></list>\n</datamap>";
        let m = from_xml(text).unwrap();
        assert_eq!(m.get_path("pose.x"), Some(&Value::Int(1)));
        assert_eq!(m.get_path("pose.e"), Some(&Value::Map(DataMap::new())));
        let empty = Value::Map(DataMap::new());
        assert_eq!(m.get("l"), Some(&Value::List(vec![empty.clone(), empty])));
        // entries of a map are named; a map ends with </map>
        let e = from_xml("<datamap><map name=\"m\"><int>1</int></map></datamap>").unwrap_err();
        assert_eq!(
            (e.offset, e.kind),
            (23, XmlFormErrorKind::MissingName("int".into()))
        );
        let e = from_xml("<datamap><map name=\"m\"></list></datamap>").unwrap_err();
        assert_eq!(e.offset, 23);
        assert!(matches!(e.kind, XmlFormErrorKind::Syntax(_)), "{e}");
        let e = from_xml("<datamap><map name=\"m\">1</map></datamap>").unwrap_err();
        assert_eq!(e.kind, XmlFormErrorKind::StrayText("1".into()));
    }

    #[test]
    fn round_trip_with_awkward_text() {
        let m = sample();
        assert_eq!(from_xml(&to_xml(&m).unwrap()).unwrap(), m);
        let odd = DataMap::new()
            .with("k\u{1}ey", "nul\0here")
            .with("tab\tkey", "\u{FFFF}")
            .with("neg0", -0.0f64)
            .with("nan", f64::from_bits(0x7ff8_0000_dead_beef))
            .with("inf", f64::NEG_INFINITY)
            .with("empty", "")
            .with("space", "  ");
        let xml = to_xml(&odd).unwrap();
        assert!(xml.contains("name-base64"), "{xml}");
        assert_eq!(from_xml(&xml).unwrap(), odd);
    }

    #[test]
    fn hand_written_documents_are_accepted() {
        let text = "<?xml version=\"1.0\"?>\n<!-- a sensor -->\n<datamap>\n  <float name=\"yaw\"> 12 </float>\n  \
                    <bool name=\"ok\">1</bool>\n  <string name=\"e\"/>\n  <list name=\"l\">\n    <int> 3 </int>\n  </list>\n</datamap>\n";
        let m = from_xml(text).unwrap();
        assert_eq!(m.get_f64("yaw"), Some(12.0));
        assert_eq!(m.get_bool("ok"), Some(true));
        assert_eq!(m.get_str("e"), Some(""));
        assert_eq!(m.get("l"), Some(&Value::List(vec![Value::Int(3)])));
    }

    #[test]
    fn errors_are_typed_and_placed() {
        let e = from_xml("<?xml version=\"1.0\"?>\n<other/>").unwrap_err();
        assert_eq!(
            (e.offset, e.kind),
            (22, XmlFormErrorKind::NotADataMap("other".into()))
        );
        let e = from_xml("<datamap><int>1</int></datamap>").unwrap_err();
        assert_eq!(
            (e.offset, e.kind),
            (9, XmlFormErrorKind::MissingName("int".into()))
        );
        let e = from_xml("<datamap><int name=\"a\">x</int></datamap>").unwrap_err();
        assert!(matches!(
            e.kind,
            XmlFormErrorKind::BadValue { ty: "int", .. }
        ));
        let e = from_xml("<datamap><date name=\"a\"/></datamap>").unwrap_err();
        assert_eq!(e.kind, XmlFormErrorKind::UnknownElement("date".into()));
        let e = from_xml("<datamap></datamap><x/>").unwrap_err();
        assert_eq!(e.kind, XmlFormErrorKind::Trailing);
        let e = from_xml("<datamap>hello</datamap>").unwrap_err();
        assert_eq!(e.kind, XmlFormErrorKind::StrayText("hello".into()));
        let e = from_xml("<datamap><int name=\"a\">1</float></datamap>").unwrap_err();
        assert!(matches!(e.kind, XmlFormErrorKind::Syntax(_)));
    }

    #[test]
    fn every_truncation_is_incomplete() {
        let hand = "<?xml version=\"1.0\"?><!-- c --><datamap><string name=\"a&amp;b\">x &lt; y<![CDATA[z]]></string></datamap>";
        for xml in [to_xml(&sample()).unwrap(), hand.to_string()] {
            for cut in (0..xml.len()).filter(|c| xml.is_char_boundary(*c)) {
                let e = from_xml(&xml[..cut]).unwrap_err();
                assert!(e.is_incomplete(), "cut {cut} of {xml}: {e}");
            }
        }
    }

    #[test]
    fn deep_lists_are_refused() {
        let mut xml = String::from("<datamap><list name=\"l\">");
        for _ in 0..MAX_DEPTH + 1 {
            xml.push_str("<list>");
        }
        for _ in 0..MAX_DEPTH + 1 {
            xml.push_str("</list>");
        }
        xml.push_str("</list></datamap>");
        assert_eq!(from_xml(&xml).unwrap_err().kind, XmlFormErrorKind::TooDeep);
    }

    #[test]
    fn deep_maps_are_refused_by_writer_and_reader_alike() {
        let deepest = nested_maps(MAX_DEPTH);
        assert_eq!(from_xml(&to_xml(&deepest).unwrap()).unwrap(), deepest);
        assert_eq!(to_xml(&nested_maps(MAX_DEPTH + 1)), Err(TooDeep));
        // maps only, one level too many: refused at the start tag of the map too many
        let mut xml = String::from("<datamap>");
        for _ in 0..=MAX_DEPTH {
            xml.push_str("<map name=\"m\">");
        }
        let too_many = xml.len() - "<map name=\"m\">".len();
        for _ in 0..=MAX_DEPTH {
            xml.push_str("</map>");
        }
        xml.push_str("</datamap>");
        let e = from_xml(&xml).unwrap_err();
        assert_eq!((e.offset, e.kind), (too_many, XmlFormErrorKind::TooDeep));
    }
}
