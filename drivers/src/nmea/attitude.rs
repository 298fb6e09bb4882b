//! Attitude from NMEA: pitch and roll combined across sentences, and the table of proprietary
//! attitude sentences.
//!
//! Devices give pitch and roll in many ways: one `XDR` with both, two `XDR`s, or a maker's own
//! sentence (`$PRDID`, `$PHTRO`, `$PSXN,23`, …). seabus keeps the latest pitch and the latest roll
//! with when and whence each came ([`Combined`]); an attitude is made when a heading arrives while
//! both are fresh, and says which sentence gave each angle.
//!
//! The proprietary sentences are read by a table ([`Table`]), an XML file users extend without
//! code (`configs/nmea-attitude.xml` is built in):
//!
//! ```xml
//! <attitude-sentences>
//!   <sentence address="PHTRO" summary="iXblue pitch and roll">
//!     <value name="pitch" field="1" negative-when="2=P"/>
//!     <value name="roll" field="3" negative-when="4=B"/>
//!   </sentence>
//!   <sentence address="PSXN" when="1=23">
//!     <value name="roll" field="2"/><value name="pitch" field="3"/><value name="heading" field="4"/>
//!   </sentence>
//! </attitude-sentences>
//! ```
//!
//! `field` counts the fields after the address from 1; `when="N=TEXT"` picks the sentence by a
//! field's text; `negative-when="N=LETTER"` negates the value when that field holds the letter;
//! `scale` multiplies it (a sentence in radians: `scale="57.29577951308232"`). Angles are degrees,
//! pitch bow up and roll starboard down positive, heading from true north unless the sentence
//! says `magnetic="true"`.

use seabus_medium::xml::{self, Element, FileError};
use std::time::Duration;
use tokio::time::Instant;

/// The built-in table.
pub const BUILT_IN: &str = include_str!("../../../configs/nmea-attitude.xml");

/// An angle a table entry reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Angle {
    /// Bow up positive.
    Pitch,
    /// Starboard down positive.
    Roll,
    /// From north, clockwise.
    Heading,
}

/// How one angle is read from a sentence's fields.
#[derive(Debug, Clone, PartialEq)]
struct Value {
    angle: Angle,
    /// Index into the fields after the address (0-based).
    field: usize,
    /// Negated when this field (0-based) holds this text.
    negative_when: Option<(usize, String)>,
    scale: f64,
}

/// One proprietary sentence the table reads.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// The address (`PHTRO`).
    pub address: String,
    /// Only when this field (0-based) holds this text.
    when: Option<(usize, String)>,
    values: Vec<Value>,
    /// Whether its heading is magnetic.
    pub magnetic: bool,
}

/// Angles read from one sentence.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Angles {
    /// Pitch, degrees.
    pub pitch: Option<f64>,
    /// Roll, degrees.
    pub roll: Option<f64>,
    /// Heading, degrees.
    pub heading: Option<f64>,
}

/// Why a proprietary sentence's value could not be read.
pub type FieldError = String;

impl Entry {
    /// Whether this entry reads a sentence with these fields.
    fn matches(&self, fields: &[Box<str>]) -> bool {
        self.when
            .as_ref()
            .is_none_or(|(i, text)| fields.get(*i).is_some_and(|f| f.trim() == text))
    }

    /// Reads the angles of a sentence's fields.
    fn read(&self, fields: &[Box<str>]) -> Result<Angles, FieldError> {
        let mut out = Angles::default();
        for v in &self.values {
            let text = fields.get(v.field).map_or("", |f| f.trim());
            if text.is_empty() {
                continue;
            }
            let Some(mut x) = text.parse::<f64>().ok().filter(|x| x.is_finite()) else {
                return Err(format!("field {} `{text}` is not a number", v.field + 1));
            };
            if let Some((i, letter)) = &v.negative_when
                && fields.get(*i).is_some_and(|f| f.trim() == letter)
            {
                x = -x;
            }
            x *= v.scale;
            if !x.is_finite() {
                return Err(format!(
                    "field {} `{text}` scaled is not finite",
                    v.field + 1
                ));
            }
            match v.angle {
                Angle::Pitch => out.pitch = Some(x),
                Angle::Roll => out.roll = Some(x),
                Angle::Heading => out.heading = Some(x),
            }
        }
        Ok(out)
    }
}

/// The proprietary attitude sentences read.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    entries: Vec<Entry>,
}

/// `N=TEXT`, with N a field number from 1.
fn field_is(a: &xml::Attr) -> Result<(usize, String), FileError> {
    let (n, text) = a
        .value
        .split_once('=')
        .ok_or_else(|| a.error("expected FIELD=TEXT, such as `2=P`"))?;
    let n: usize = n
        .trim()
        .parse()
        .ok()
        .filter(|n| (1..=64).contains(n))
        .ok_or_else(|| a.error(format!("`{n}` is not a field number from 1 to 64")))?;
    Ok((n - 1, text.trim().to_string()))
}

impl Table {
    /// The built-in table.
    pub fn built_in() -> Table {
        Table::parse("configs/nmea-attitude.xml", BUILT_IN).expect("the built-in table is valid")
    }

    /// Parses a table file's text; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<Table, FileError> {
        Table::from_element(&xml::parse(file, text)?)
    }

    fn from_element(root: &Element) -> Result<Table, FileError> {
        if root.name != "attitude-sentences" {
            return Err(root.error("expected <attitude-sentences>"));
        }
        root.only_children(&["sentence"])?;
        let mut table = Table::default();
        for s in root.children_named("sentence") {
            s.only_attrs(&["address", "when", "summary", "magnetic"])?;
            s.only_children(&["value"])?;
            let addr = s.required("address")?;
            let address = addr.value.trim().to_string();
            let standard = address.len() == 5 && !address.starts_with('P');
            if address.is_empty()
                || address.len() > super::sentence::MAX_ADDRESS
                || !address.bytes().all(|b| b.is_ascii_uppercase())
                || standard
            {
                return Err(addr.error(format!(
                    "`{address}` is not a proprietary address (P and up to {} capital letters)",
                    super::sentence::MAX_ADDRESS - 1
                )));
            }
            let mut values = Vec::new();
            for v in s.children_named("value") {
                v.only_attrs(&["name", "field", "negative-when", "scale"])?;
                let name = v.required("name")?;
                let angle = match name.value.trim() {
                    "pitch" => Angle::Pitch,
                    "roll" => Angle::Roll,
                    "heading" => Angle::Heading,
                    other => {
                        return Err(name.error(format!("`{other}` is not pitch, roll or heading")));
                    }
                };
                if values.iter().any(|x: &Value| x.angle == angle) {
                    return Err(name.error(format!("{} is read twice", name.value.trim())));
                }
                let field_attr = v.required("field")?;
                let field: usize = field_attr.parse("a field number from 1")?;
                if !(1..=64).contains(&field) {
                    return Err(field_attr.error(format!("{field} is not from 1 to 64")));
                }
                let scale = v.parsed::<f64>("scale", "a number")?.unwrap_or(1.0);
                if !scale.is_finite() || scale == 0.0 {
                    return Err(v.error("attribute `scale` must be a finite number other than 0"));
                }
                values.push(Value {
                    angle,
                    field: field - 1,
                    negative_when: v.attr("negative-when").map(field_is).transpose()?,
                    scale,
                });
            }
            if values.is_empty() {
                return Err(s.error("<sentence> reads no <value>"));
            }
            let entry = Entry {
                address,
                when: s.attr("when").map(field_is).transpose()?,
                values,
                magnetic: s.flag("magnetic")?.unwrap_or(false),
            };
            table.add(entry);
        }
        Ok(table)
    }

    /// Adds an entry; one for the same address and `when` is replaced.
    fn add(&mut self, entry: Entry) {
        self.entries
            .retain(|e| (&e.address, &e.when) != (&entry.address, &entry.when));
        self.entries.push(entry);
    }

    /// This table with `other`'s entries added (replacing this one's for the same sentence).
    pub fn extended(mut self, other: Table) -> Table {
        for e in other.entries {
            self.add(e);
        }
        self
    }

    /// The addresses read.
    pub fn addresses(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|e| e.address.as_str())
    }

    /// The angles of a proprietary sentence with this address and these fields: `None` when the
    /// table has no entry for it, an error naming the field that is not a number.
    pub fn read(
        &self,
        address: &str,
        fields: &[Box<str>],
    ) -> Option<Result<(Angles, &Entry), FieldError>> {
        let entry = self
            .entries
            .iter()
            .find(|e| e.address == address && e.matches(fields))?;
        Some(entry.read(fields).map(|a| (a, entry)))
    }
}

/// One angle kept: its value, when and from which sentence.
#[derive(Debug, Clone, Copy)]
struct Kept {
    value: f64,
    at: Instant,
    from: Source,
}

/// The sentence an angle came from (a formatter or a proprietary address, at most
/// [`super::sentence::MAX_ADDRESS`] letters).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Source([u8; super::sentence::MAX_ADDRESS], u8);

impl Source {
    /// The source named `name` (cut to the longest address).
    pub fn new(name: &str) -> Source {
        let mut b = [0; super::sentence::MAX_ADDRESS];
        let n = name.len().min(b.len());
        b[..n].copy_from_slice(&name.as_bytes()[..n]);
        Source(b, n as u8)
    }

    /// Its name.
    pub fn as_str(&self) -> &str {
        std::str::from_utf8(&self.0[..usize::from(self.1)]).unwrap_or_default()
    }
}

/// Pitch and roll combined across sentences within a window.
#[derive(Debug, Clone)]
pub struct Combined {
    window: Duration,
    pitch: Option<Kept>,
    roll: Option<Kept>,
}

/// An attitude made: the angles and the sentence each came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Made {
    /// Pitch, degrees.
    pub pitch: f64,
    /// Roll, degrees.
    pub roll: f64,
    /// Where the pitch came from.
    pub pitch_from: Source,
    /// Where the roll came from.
    pub roll_from: Source,
}

impl Combined {
    /// Pitch and roll stay usable for `window` after they came.
    pub fn new(window: Duration) -> Combined {
        Combined {
            window,
            pitch: None,
            roll: None,
        }
    }

    /// Keeps a pitch from `from` at `at`.
    pub fn pitch(&mut self, value: f64, from: Source, at: Instant) {
        self.pitch = Some(Kept { value, at, from });
    }

    /// Keeps a roll from `from` at `at`.
    pub fn roll(&mut self, value: f64, from: Source, at: Instant) {
        self.roll = Some(Kept { value, at, from });
    }

    /// The pitch and roll when both are fresh at `now`.
    pub fn fresh(&self, now: Instant) -> Option<Made> {
        let ok =
            |k: &Option<Kept>| k.filter(|k| now.saturating_duration_since(k.at) <= self.window);
        let (p, r) = (ok(&self.pitch)?, ok(&self.roll)?);
        Some(Made {
            pitch: p.value,
            roll: r.value,
            pitch_from: p.from,
            roll_from: r.from,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(fields: &[&str]) -> Vec<Box<str>> {
        fields.iter().map(|s| Box::from(*s)).collect()
    }

    #[test]
    fn the_built_in_table_reads_the_makers_sentences() {
        let t = Table::built_in();
        let (a, _) = t
            .read("PHTRO", &f(&["2.50", "P", "1.25", "B"]))
            .unwrap()
            .unwrap();
        assert_eq!(
            (a.pitch, a.roll, a.heading),
            (Some(-2.5), Some(-1.25), None)
        );
        let (a, _) = t
            .read("PHTRO", &f(&["2.50", "M", "1.25", "T"]))
            .unwrap()
            .unwrap();
        assert_eq!((a.pitch, a.roll), (Some(2.5), Some(1.25)));
        let (a, e) = t
            .read("PRDID", &f(&["-1.5", "2.0", "180.0"]))
            .unwrap()
            .unwrap();
        assert_eq!(
            (a.pitch, a.roll, a.heading),
            (Some(-1.5), Some(2.0), Some(180.0))
        );
        assert!(!e.magnetic);
        let (a, _) = t
            .read("PSXN", &f(&["23", "0.5", "-0.25", "90.0", "0.1"]))
            .unwrap()
            .unwrap();
        assert_eq!(
            (a.pitch, a.roll, a.heading),
            (Some(-0.25), Some(0.5), Some(90.0))
        );
        assert!(t.read("PSXN", &f(&["20", "0.5"])).is_none(), "another PSXN");
        assert!(t.read("PGRME", &f(&["1"])).is_none());
        let e = t
            .read("PRDID", &f(&["up", "2.0", "1"]))
            .unwrap()
            .unwrap_err();
        assert_eq!(e, "field 1 `up` is not a number");
    }

    #[test]
    fn users_extend_the_table_and_errors_are_placed() {
        let mine = Table::parse(
            "mine.xml",
            "<attitude-sentences>\n<sentence address=\"PXYZ\" magnetic=\"true\">\n\
             <value name=\"pitch\" field=\"2\" scale=\"57.29577951308232\"/>\n\
             <value name=\"heading\" field=\"1\"/></sentence></attitude-sentences>",
        )
        .unwrap();
        let t = Table::built_in().extended(mine);
        let (a, e) = t.read("PXYZ", &f(&["10", "0.1"])).unwrap().unwrap();
        assert!((a.pitch.unwrap() - 5.729_577_951).abs() < 1e-6);
        assert_eq!(a.heading, Some(10.0));
        assert!(e.magnetic);
        assert!(t.addresses().any(|a| a == "PHTRO"));
        for (text, want) in [
            (
                "<attitude-sentences><sentence address=\"GPGGA\"><value name=\"pitch\" field=\"1\"/></sentence></attitude-sentences>",
                "x.xml:1:31: attribute `address`: `GPGGA` is not a proprietary address",
            ),
            (
                "<attitude-sentences><sentence address=\"PX\"><value name=\"yaw\" field=\"1\"/></sentence></attitude-sentences>",
                "x.xml:1:51: attribute `name`: `yaw` is not pitch, roll or heading",
            ),
            (
                "<attitude-sentences><sentence address=\"PX\"><value name=\"roll\" field=\"0\"/></sentence></attitude-sentences>",
                "attribute `field`: 0 is not from 1 to 64",
            ),
            (
                "<attitude-sentences><sentence address=\"PX\" when=\"x\"><value name=\"roll\" field=\"1\"/></sentence></attitude-sentences>",
                "attribute `when`: expected FIELD=TEXT",
            ),
            (
                "<attitude-sentences><sentence address=\"PX\"/></attitude-sentences>",
                "reads no <value>",
            ),
        ] {
            let e = Table::parse("x.xml", text).unwrap_err().to_string();
            assert!(e.contains(want), "{e}");
        }
    }

    #[test]
    fn pitch_and_roll_combine_within_the_window() {
        let t0 = Instant::now();
        let mut c = Combined::new(Duration::from_secs(1));
        assert_eq!(c.fresh(t0), None);
        c.pitch(2.0, Source::new("XDR"), t0);
        assert_eq!(c.fresh(t0), None, "no roll yet");
        c.roll(-1.0, Source::new("PHTRO"), t0 + Duration::from_millis(300));
        let m = c.fresh(t0 + Duration::from_millis(900)).unwrap();
        assert_eq!((m.pitch, m.roll), (2.0, -1.0));
        assert_eq!(
            (m.pitch_from.as_str(), m.roll_from.as_str()),
            ("XDR", "PHTRO")
        );
        assert_eq!(
            c.fresh(t0 + Duration::from_millis(1100)),
            None,
            "the pitch is stale"
        );
    }
}
