//! The DSAAV configuration database: user-administered *configuration data* read from a sectioned
//! text file, software-controlled *application data* kept in a file of its own, and the "data
//! plumbing" that tells each component where its services are.
//!
//! # The file
//!
//! Configuration data and application data use one format:
//!
//! ```text
//! # the logging service, and the default log level of every component
//! [Logging]
//! Server = 1:0           # node 1, port 0
//! LogLevel = LOG_INFO
//!
//! [DepthFilter]
//! Server = 3:0
//! Depth.Server = 4:0     # this component reads depth from the sensor, not from itself
//!
//! [Operator]
//! Greeting = "hello # world"   # quoted: `#` and outer blanks kept, escapes \\ \" \n \r \t
//! ```
//!
//! - A line is blank, a comment (first non-blank character `#`), a section header `[Name]` or a
//!   setting `key = value`. Lines end in LF or CRLF; a UTF-8 byte-order mark at the start is skipped.
//!   Blanks are spaces and tabs; they are ignored around names, `=` and values.
//! - Section names and keys have letters, digits, `_` and `-`, and are case-sensitive. A key may be
//!   an override `Service.Key`: two names joined by one `.`. Blanks inside the brackets of a header
//!   are ignored (`[ Logging ]` is `[Logging]`).
//! - A setting belongs to the section above it; a setting before any header is an error. A section
//!   or a key in one section given twice is an error naming the earlier line (sections are never
//!   merged).
//! - A value runs from the first non-blank character after `=` to the end of the line or to a `#`,
//!   blanks at its end dropped; it may be empty. A value whose first character is `"` is quoted: it
//!   ends at the next unescaped `"`, keeps `#` and blanks, and knows the escapes `\\`, `\"`, `\n`,
//!   `\r` and `\t`; only blanks or a comment may follow it. Elsewhere `"` and `\` are plain
//!   characters.
//! - Values are text. [`Value::int`] reads a decimal 64-bit integer (`-12`, `+7`), [`Value::float`]
//!   a finite decimal number (`2.3`, `1e-3`, `5`), [`Value::address`] a service address `node:port`
//!   ([`Address`]).
//!
//! Every error in a file names the file, line and column ([`FileError`]) and says what was
//! expected:
//!
//! ```text
//! starfish.ini:12:1: expected `key = value`, found `Server 3:0`
//! starfish.ini:14:1: key `Server` is already set in section `[DepthFilter]` at line 12
//! ```
//!
//! # Two parts
//!
//! A [`Database`] holds the configuration data (never changed by software) and the application
//! data. `put_str`, `put_int` and `put_float` write application data; every get returns the
//! application data's value when both parts have the key (it *masks* the configuration value);
//! `remove` and `remove_section` delete application data and so unmask the configuration data.
//!
//! Opened with [`Database::open`], the application data lives in its own file in the same format
//! (settings in order, comments not kept) and is written after every change, atomically: to a
//! temporary file in the same directory, which is synced, renamed over the old file, and the
//! directory synced, so a crash leaves the old file or the new one, never a torn one. A damaged
//! application-data file is an error naming file and line, never silently dropped. The file is
//! the service's own: edits made by hand while it runs are overwritten by its next change. A
//! temporary file left by a crash (`.NAME.PID.N.tmp`) is ignored and never read.
//!
//! # Data plumbing
//!
//! Each service has a section with a `Server` key giving its address; a component's section can
//! override any of a service's settings with `Service.Key`. [`Database::setting`] looks up
//! `Service.Key` in the component's section first and `Key` in the service's section next (each
//! with application data masking configuration data); [`Database::server_of`] does so for `Server`.
//! Changing only the file re-plumbs the data: pointing `[Depth] Server` at the sensor makes every
//! component without an override read depth from the sensor.

use seabus_medium::xml::{FileError, Pos};
pub use seabus_medium_dsaav::wire::{Address, AddressError};
use std::collections::HashMap;
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use thiserror::Error;

/// The blanks of the format: space and tab.
const BLANKS: [char; 2] = [' ', '\t'];

/// Most characters of a file's text an error message quotes.
const SHOWN: usize = 40;

/// The comment written at the top of an application-data file.
const APP_DATA_HEADER: &str = "# DSAAV application data, kept by the configuration service\n\n";

/// True when `name` can name a section (or be a key that is not an override): letters, digits, `_`
/// and `-`, at least one.
pub fn is_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(is_name_char)
}

/// True when `key` can be a key: a name, or an override `Service.Key`.
pub fn is_key(key: &str) -> bool {
    match key.split_once('.') {
        None => is_name(key),
        Some((service, key)) => is_name(service) && is_name(key),
    }
}

fn is_name_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '-'
}

/// `text` for an error message: control characters escaped, cut after [`SHOWN`] characters.
fn shown(text: &str) -> String {
    let mut out = String::new();
    for (i, c) in text.chars().enumerate() {
        if i == SHOWN {
            out.push('…');
            break;
        }
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// One character for an error message.
fn describe(c: char) -> String {
    match c {
        ' ' => "space".to_owned(),
        '\t' => "tab".to_owned(),
        c if c.is_control() => format!("`{}`", c.escape_default()),
        c => format!("`{c}`"),
    }
}

/// One `key = value` setting.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Setting {
    /// The key: a name, or `Service.Key` for an override.
    pub key: String,
    /// The value, without quotes and escapes.
    pub value: String,
    /// Where the value starts in its file; `None` for a value put by software.
    pub pos: Option<Pos>,
}

/// A named section of settings, in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Section {
    name: String,
    pos: Option<Pos>,
    settings: Vec<Setting>,
}

impl Section {
    /// The section's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Where its header is; `None` for a section made by software.
    pub fn pos(&self) -> Option<&Pos> {
        self.pos.as_ref()
    }

    /// Its settings in order.
    pub fn settings(&self) -> &[Setting] {
        &self.settings
    }

    /// The setting with key `key`.
    pub fn get(&self, key: &str) -> Option<&Setting> {
        self.settings.iter().find(|s| s.key == key)
    }
}

/// A name that cannot be written to a file.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum NameError {
    /// Not a section name.
    #[error("`{}` is not a section name: use letters, digits, `_` and `-`", shown(.0))]
    Section(String),
    /// Not a key.
    #[error(
        "`{}` is not a key: use letters, digits, `_` and `-`, and one `.` in an override `Service.Key`",
        shown(.0)
    )]
    Key(String),
}

/// The sections of one file, in file order: the configuration data or the application data.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Sections {
    sections: Vec<Section>,
}

impl Sections {
    /// No sections.
    pub fn new() -> Self {
        Self::default()
    }

    /// Parses `text`, from a file called `file`.
    pub fn parse(file: &str, text: &str) -> Result<Self, FileError> {
        parse(file, text)
    }

    /// Parses `bytes`, from a file called `file`; bytes that are not UTF-8 are an error at their
    /// place.
    pub fn parse_bytes(file: &str, bytes: &[u8]) -> Result<Self, FileError> {
        match std::str::from_utf8(bytes) {
            Ok(text) => parse(file, text),
            Err(e) => {
                let good = bytes
                    .get(..e.valid_up_to())
                    .and_then(|b| std::str::from_utf8(b).ok())
                    .unwrap_or_default();
                let line = good.matches('\n').count() + 1;
                let last = good.rsplit('\n').next().unwrap_or_default();
                let last = if line == 1 {
                    last.strip_prefix('\u{feff}').unwrap_or(last)
                } else {
                    last
                };
                let byte = bytes.get(e.valid_up_to()).copied().unwrap_or_default();
                Err(Pos {
                    file: Arc::from(file),
                    line: saturate(line),
                    col: saturate(last.chars().count() + 1),
                }
                .error(format!("not UTF-8 text: byte 0x{byte:02x}")))
            }
        }
    }

    /// Reads and parses the file at `path`.
    pub fn read(path: &Path) -> Result<Self, FileError> {
        let name = path.display().to_string();
        let bytes =
            std::fs::read(path).map_err(|e| start_of(&name).error(format!("cannot read: {e}")))?;
        Self::parse_bytes(&name, &bytes)
    }

    /// The sections in order.
    pub fn iter(&self) -> std::slice::Iter<'_, Section> {
        self.sections.iter()
    }

    /// True when there are no sections.
    pub fn is_empty(&self) -> bool {
        self.sections.is_empty()
    }

    /// The section called `name`.
    pub fn section(&self, name: &str) -> Option<&Section> {
        self.sections.iter().find(|s| s.name == name)
    }

    /// The setting `key` of section `section`.
    pub fn get(&self, section: &str, key: &str) -> Option<&Setting> {
        self.section(section)?.get(key)
    }

    /// Sets `key` of `section` to `value`, adding the section (at the end) or the key (at the end of
    /// its section) when new.
    pub fn set(&mut self, section: &str, key: &str, value: &str) -> Result<(), NameError> {
        if !is_name(section) {
            return Err(NameError::Section(section.to_owned()));
        }
        if !is_key(key) {
            return Err(NameError::Key(key.to_owned()));
        }
        let index = match self.sections.iter().position(|s| s.name == section) {
            Some(i) => i,
            None => {
                self.sections.push(Section {
                    name: section.to_owned(),
                    pos: None,
                    settings: Vec::new(),
                });
                self.sections.len() - 1
            }
        };
        let settings = &mut self.sections[index].settings;
        let setting = Setting {
            key: key.to_owned(),
            value: value.to_owned(),
            pos: None,
        };
        match settings.iter_mut().find(|s| s.key == key) {
            Some(old) => *old = setting,
            None => settings.push(setting),
        }
        Ok(())
    }

    /// Removes `key` from `section` and returns it; a section left empty is removed too.
    pub fn remove(&mut self, section: &str, key: &str) -> Option<Setting> {
        let index = self.sections.iter().position(|s| s.name == section)?;
        let settings = &mut self.sections[index].settings;
        let at = settings.iter().position(|s| s.key == key)?;
        let removed = settings.remove(at);
        if settings.is_empty() {
            self.sections.remove(index);
        }
        Some(removed)
    }

    /// Removes section `name` with all its settings and returns it.
    pub fn remove_section(&mut self, name: &str) -> Option<Section> {
        let index = self.sections.iter().position(|s| s.name == name)?;
        Some(self.sections.remove(index))
    }

    /// The sections written in the file format, which parses back to the same sections, settings
    /// and values (comments and layout are not kept).
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        for (i, section) in self.sections.iter().enumerate() {
            if i > 0 {
                out.push('\n');
            }
            out.push('[');
            out.push_str(&section.name);
            out.push_str("]\n");
            for setting in &section.settings {
                out.push_str(&setting.key);
                out.push_str(" = ");
                write_value(&mut out, &setting.value);
                out.push('\n');
            }
        }
        out
    }
}

impl<'a> IntoIterator for &'a Sections {
    type Item = &'a Section;
    type IntoIter = std::slice::Iter<'a, Section>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// Writes `value` bare when it reads back as it is, quoted otherwise.
fn write_value(out: &mut String, value: &str) {
    let bare = !value.is_empty()
        && !value.starts_with(['"', ' '])
        && !value.ends_with(' ')
        && !value.contains('#')
        && !value.chars().any(char::is_control);
    if bare {
        out.push_str(value);
        return;
    }
    out.push('"');
    for c in value.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c => out.push(c),
        }
    }
    out.push('"');
}

fn saturate(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

fn start_of(file: &str) -> Pos {
    Pos {
        file: Arc::from(file),
        line: 1,
        col: 1,
    }
}

/// One line of a file being parsed, without its line ending.
struct Line<'a> {
    file: &'a Arc<str>,
    number: u32,
    text: &'a str,
}

impl Line<'_> {
    /// The place of byte `at` of the line.
    fn at(&self, at: usize) -> Pos {
        let col = self.text.get(..at).map_or(at, |s| s.chars().count()) + 1;
        Pos {
            file: self.file.clone(),
            line: self.number,
            col: saturate(col),
        }
    }

    /// The byte offset of the first non-blank at or after `from`.
    fn skip_blanks(&self, from: usize) -> usize {
        let rest = self.text.get(from..).unwrap_or_default();
        from + (rest.len() - rest.trim_start_matches(BLANKS).len())
    }

    /// Fails unless only blanks or a comment follow byte `from`.
    fn only_comment_after(&self, from: usize, what: &str) -> Result<(), FileError> {
        let at = self.skip_blanks(from);
        let rest = self.text.get(at..).unwrap_or_default();
        if rest.is_empty() || rest.starts_with('#') {
            return Ok(());
        }
        let rest = rest
            .split('#')
            .next()
            .unwrap_or_default()
            .trim_end_matches(BLANKS);
        Err(self.at(at).error(format!(
            "unexpected `{}` {what}; a comment starts with `#`",
            shown(rest)
        )))
    }
}

fn parse(file: &str, text: &str) -> Result<Sections, FileError> {
    let file: Arc<str> = Arc::from(file);
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut out = Sections::new();
    // The lines names were first given at, so that duplicates are found in any number of them.
    let mut sections: HashMap<&str, u32> = HashMap::new();
    let mut keys: HashMap<&str, u32> = HashMap::new();
    for (index, raw) in text.split('\n').enumerate() {
        let line = Line {
            file: &file,
            number: saturate(index + 1),
            text: raw.strip_suffix('\r').unwrap_or(raw),
        };
        let start = line.skip_blanks(0);
        let body = line.text.get(start..).unwrap_or_default();
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        if body.starts_with('[') {
            let (name, pos) = header(&line, start)?;
            if let Some(earlier) = sections.insert(name, line.number) {
                return Err(pos.error(format!(
                    "section `[{name}]` is already defined at line {earlier}"
                )));
            }
            keys.clear();
            out.sections.push(Section {
                name: name.to_owned(),
                pos: Some(pos),
                settings: Vec::new(),
            });
            continue;
        }
        let before_comment = body.split('#').next().unwrap_or_default();
        let Some(eq) = before_comment.find('=') else {
            let found = shown(before_comment.trim_end_matches(BLANKS));
            let expected = if out.sections.is_empty() {
                "a `[Section]` header"
            } else {
                "`key = value`"
            };
            return Err(line
                .at(start)
                .error(format!("expected {expected}, found `{found}`")));
        };
        let (key, setting) = entry(&line, start, start + eq)?;
        let Some(section) = out.sections.last_mut() else {
            return Err(line.at(start).error(format!(
                "setting `{key}` comes before any `[Section]` header"
            )));
        };
        if let Some(earlier) = keys.insert(key, line.number) {
            return Err(line.at(start).error(format!(
                "key `{key}` is already set in section `[{}]` at line {earlier}",
                section.name
            )));
        }
        section.settings.push(setting);
    }
    Ok(out)
}

/// Reads the header starting with the `[` at byte `open`: its name and the place of the `[`.
fn header<'a>(line: &Line<'a>, open: usize) -> Result<(&'a str, Pos), FileError> {
    let after = open + 1;
    let rest = line.text.get(after..).unwrap_or_default();
    let Some(close) = rest.find(']').map(|i| after + i) else {
        return Err(line
            .at(open)
            .error("expected `]` to close the section header"));
    };
    let name_start = line.skip_blanks(after);
    let name = line
        .text
        .get(name_start..close)
        .unwrap_or_default()
        .trim_end_matches(BLANKS);
    if name.is_empty() {
        return Err(line
            .at(open)
            .error("expected a section name between `[` and `]`"));
    }
    if let Some((i, c)) = name.char_indices().find(|&(_, c)| !is_name_char(c)) {
        return Err(line.at(name_start + i).error(format!(
            "unexpected {} in section name `{}`; a section name has letters, digits, `_` and `-`",
            describe(c),
            shown(name)
        )));
    }
    line.only_comment_after(close + 1, "after the section header")?;
    Ok((name, line.at(open)))
}

/// Reads the setting starting at byte `start` whose `=` is at byte `eq`.
fn entry<'a>(line: &Line<'a>, start: usize, eq: usize) -> Result<(&'a str, Setting), FileError> {
    let key = line
        .text
        .get(start..eq)
        .unwrap_or_default()
        .trim_end_matches(BLANKS);
    if key.is_empty() {
        return Err(line.at(eq).error("expected a key before `=`"));
    }
    if let Some((i, c)) = key
        .char_indices()
        .find(|&(_, c)| !is_name_char(c) && c != '.')
    {
        return Err(line.at(start + i).error(format!(
            "unexpected {} in key `{}`; a key has letters, digits, `_` and `-`",
            describe(c),
            shown(key)
        )));
    }
    if !is_key(key) {
        return Err(line.at(start).error(format!(
            "key `{key}` is neither a name nor an override `Service.Key` (two names joined by one `.`)"
        )));
    }
    let at = line.skip_blanks(eq + 1);
    let rest = line.text.get(at..).unwrap_or_default();
    let value = if rest.starts_with('"') {
        let (value, end) = quoted(line, at)?;
        line.only_comment_after(end, "after the closing quote")?;
        value
    } else {
        rest.split('#')
            .next()
            .unwrap_or_default()
            .trim_end_matches(BLANKS)
            .to_owned()
    };
    let setting = Setting {
        key: key.to_owned(),
        value,
        pos: Some(line.at(at)),
    };
    Ok((key, setting))
}

/// Reads the quoted value whose opening `"` is at byte `open`: the value and the byte after its
/// closing `"`.
fn quoted(line: &Line<'_>, open: usize) -> Result<(String, usize), FileError> {
    let body = open + 1;
    let mut out = String::new();
    let mut chars = line.text.get(body..).unwrap_or_default().char_indices();
    while let Some((i, c)) = chars.next() {
        match c {
            '"' => return Ok((out, body + i + 1)),
            '\\' => match chars.next() {
                Some((_, '\\')) => out.push('\\'),
                Some((_, '"')) => out.push('"'),
                Some((_, 'n')) => out.push('\n'),
                Some((_, 'r')) => out.push('\r'),
                Some((_, 't')) => out.push('\t'),
                Some((_, other)) => {
                    return Err(line.at(body + i).error(format!(
                        "unknown escape `\\{}` in a quoted value; known: `\\\\`, `\\\"`, `\\n`, `\\r`, `\\t`",
                        shown(other.encode_utf8(&mut [0; 4]))
                    )));
                }
                None => break,
            },
            c => out.push(c),
        }
    }
    Err(line.at(open).error("quoted value without its closing `\"`"))
}

/// The part of the database a value comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// The user's configuration data.
    Configuration,
    /// The application data put by software.
    Application,
}

/// The type a value was read as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Expected {
    /// A decimal 64-bit integer.
    Integer,
    /// A finite decimal number.
    Float,
    /// A service address `node:port`.
    Address,
}

impl fmt::Display for Expected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Expected::Integer => "an integer",
            Expected::Float => "a finite float",
            Expected::Address => "an address `node:port` (node and port from 0 to 65535)",
        })
    }
}

/// A value that is missing or not of the type asked for.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ValueError {
    /// Neither part has the key.
    #[error("no key `{key}` in section `[{section}]`")]
    Missing {
        /// The section asked for.
        section: String,
        /// The key asked for.
        key: String,
    },
    /// Neither the component's override nor the service's section has the setting.
    #[error(
        "no `{key}` of service `{service}` for component `{component}`: neither `[{component}] {service}.{key}` nor `[{service}] {key}` is set"
    )]
    NoSetting {
        /// The component asking.
        component: String,
        /// The service.
        service: String,
        /// The setting.
        key: String,
    },
    /// The value is not of the type asked for.
    #[error("{}[{section}] {key} = `{}` is not {expected}", place(.pos, *.part), shown(.value))]
    Invalid {
        /// The section.
        section: String,
        /// The key.
        key: String,
        /// The value as stored.
        value: String,
        /// The type asked for.
        expected: Expected,
        /// The part the value came from.
        part: Part,
        /// Where the value was read, if from a file.
        pos: Option<Pos>,
    },
}

fn place(pos: &Option<Pos>, part: Part) -> String {
    match (pos, part) {
        (Some(pos), _) => format!("{pos}: "),
        (None, Part::Application) => "application data: ".to_owned(),
        (None, Part::Configuration) => String::new(),
    }
}

/// A change to the application data that could not be made.
#[derive(Debug, Error)]
pub enum StoreError {
    /// The section or key cannot be written to a file.
    #[error(transparent)]
    Name(#[from] NameError),
    /// A float that would not read back.
    #[error("[{section}] {key}: {value} is not a finite float")]
    NotFinite {
        /// The section.
        section: String,
        /// The key.
        key: String,
        /// The value refused.
        value: f64,
    },
    /// Writing the application-data file failed; the database is unchanged.
    #[error("{}: cannot write the application data: {source}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
}

/// A value found in the database, with where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Value<'a> {
    /// The section it is in.
    pub section: &'a str,
    /// Its key.
    pub key: &'a str,
    /// The value's text.
    pub text: &'a str,
    /// The part it came from.
    pub part: Part,
    /// Where it was read, if from a file.
    pub pos: Option<&'a Pos>,
}

impl<'a> Value<'a> {
    /// The value's text.
    pub fn as_str(&self) -> &'a str {
        self.text
    }

    /// The value as a decimal 64-bit integer.
    pub fn int(&self) -> Result<i64, ValueError> {
        self.text
            .parse()
            .map_err(|_| self.invalid(Expected::Integer))
    }

    /// The value as a finite float.
    pub fn float(&self) -> Result<f64, ValueError> {
        match self.text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.invalid(Expected::Float)),
        }
    }

    /// The value as a service address `node:port`.
    pub fn address(&self) -> Result<Address, ValueError> {
        self.text
            .parse()
            .map_err(|_| self.invalid(Expected::Address))
    }

    fn invalid(&self, expected: Expected) -> ValueError {
        ValueError::Invalid {
            section: self.section.to_owned(),
            key: self.key.to_owned(),
            value: self.text.to_owned(),
            expected,
            part: self.part,
            pos: self.pos.cloned(),
        }
    }
}

/// The configuration database: configuration data, application data masking it, and the file the
/// application data persists in.
#[derive(Debug, Clone, Default)]
pub struct Database {
    config: Sections,
    app: Sections,
    app_path: Option<PathBuf>,
}

impl Database {
    /// A database of `config` with no application data, kept in memory only.
    pub fn new(config: Sections) -> Self {
        Database {
            config,
            app: Sections::new(),
            app_path: None,
        }
    }

    /// A database of the configuration data in `text` (from a file called `file`), with application
    /// data kept in memory only.
    pub fn parse(file: &str, text: &str) -> Result<Self, FileError> {
        Sections::parse(file, text).map(Self::new)
    }

    /// Reads the configuration data at `config` and the application data at `app_data` (none when
    /// that file does not exist); changes to the application data are written to `app_data`.
    pub fn open(config: &Path, app_data: &Path) -> Result<Self, FileError> {
        let config = Sections::read(config)?;
        let app = match std::fs::metadata(app_data) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => Sections::new(),
            _ => Sections::read(app_data)?,
        };
        Ok(Database {
            config,
            app,
            app_path: Some(app_data.to_owned()),
        })
    }

    /// The user's configuration data.
    pub fn config_data(&self) -> &Sections {
        &self.config
    }

    /// The application data.
    pub fn app_data(&self) -> &Sections {
        &self.app
    }

    /// The file the application data is written to, if any.
    pub fn app_data_path(&self) -> Option<&Path> {
        self.app_path.as_deref()
    }

    /// The value of `key` in `section`: the application data's when it has the key, else the
    /// configuration data's.
    pub fn value(&self, section: &str, key: &str) -> Option<Value<'_>> {
        found(&self.app, Part::Application, section, key)
            .or_else(|| found(&self.config, Part::Configuration, section, key))
    }

    /// The value of `key` in `section`, or an error naming both.
    pub fn get(&self, section: &str, key: &str) -> Result<Value<'_>, ValueError> {
        self.value(section, key).ok_or_else(|| ValueError::Missing {
            section: section.to_owned(),
            key: key.to_owned(),
        })
    }

    /// The value of `key` in `section` as text (the paper's getString).
    pub fn get_str(&self, section: &str, key: &str) -> Result<&str, ValueError> {
        self.get(section, key).map(|v| v.text)
    }

    /// The value of `key` in `section` as an integer (getInteger).
    pub fn get_int(&self, section: &str, key: &str) -> Result<i64, ValueError> {
        self.get(section, key)?.int()
    }

    /// The value of `key` in `section` as a float (getFloat).
    pub fn get_float(&self, section: &str, key: &str) -> Result<f64, ValueError> {
        self.get(section, key)?.float()
    }

    /// The value of `key` in `section` as a service address.
    pub fn get_address(&self, section: &str, key: &str) -> Result<Address, ValueError> {
        self.get(section, key)?.address()
    }

    /// Puts text into the application data (putString) and writes it out.
    pub fn put_str(&mut self, section: &str, key: &str, value: &str) -> Result<(), StoreError> {
        let mut app = self.app.clone();
        app.set(section, key, value)?;
        self.commit(app)
    }

    /// Puts an integer into the application data (putInteger) and writes it out.
    pub fn put_int(&mut self, section: &str, key: &str, value: i64) -> Result<(), StoreError> {
        self.put_str(section, key, &value.to_string())
    }

    /// Puts a finite float into the application data (putFloat) and writes it out; it reads back
    /// exactly.
    pub fn put_float(&mut self, section: &str, key: &str, value: f64) -> Result<(), StoreError> {
        if !value.is_finite() {
            return Err(StoreError::NotFinite {
                section: section.to_owned(),
                key: key.to_owned(),
                value,
            });
        }
        self.put_str(section, key, &value.to_string())
    }

    /// Removes `key` of `section` from the application data, unmasking the configuration data's
    /// value; true when there was one to remove.
    pub fn remove(&mut self, section: &str, key: &str) -> Result<bool, StoreError> {
        let mut app = self.app.clone();
        if app.remove(section, key).is_none() {
            return Ok(false);
        }
        self.commit(app).map(|()| true)
    }

    /// Removes the whole application-data section `section`, unmasking the configuration data of
    /// that section; true when there was one to remove.
    pub fn remove_section(&mut self, section: &str) -> Result<bool, StoreError> {
        let mut app = self.app.clone();
        if app.remove_section(section).is_none() {
            return Ok(false);
        }
        self.commit(app).map(|()| true)
    }

    /// Writes `app` to the application-data file, if there is one, and then keeps it.
    fn commit(&mut self, app: Sections) -> Result<(), StoreError> {
        if let Some(path) = &self.app_path {
            let mut text = String::from(APP_DATA_HEADER);
            text.push_str(&app.to_text());
            seabus_medium::fs::atomic_write(path, text.as_bytes()).map_err(|source| {
                StoreError::Write {
                    path: path.clone(),
                    source,
                }
            })?;
        }
        self.app = app;
        Ok(())
    }

    /// Setting `key` of service `service` as seen by component `component`: the override
    /// `Service.Key` in the component's section when set, else `Key` in the service's section.
    pub fn setting(
        &self,
        component: &str,
        service: &str,
        key: &str,
    ) -> Result<Value<'_>, ValueError> {
        self.value(component, &format!("{service}.{key}"))
            .or_else(|| self.value(service, key))
            .ok_or_else(|| ValueError::NoSetting {
                component: component.to_owned(),
                service: service.to_owned(),
                key: key.to_owned(),
            })
    }

    /// The address component `component` reaches service `service` at: its `Server` setting.
    pub fn server_of(&self, component: &str, service: &str) -> Result<Address, ValueError> {
        self.setting(component, service, "Server")?.address()
    }
}

/// `key` of `section` in `sections`, from `part`.
fn found<'a>(sections: &'a Sections, part: Part, section: &str, key: &str) -> Option<Value<'a>> {
    let s = sections.section(section)?;
    let setting = s.get(key)?;
    Some(Value {
        section: &s.name,
        key: &setting.key,
        text: &setting.value,
        part,
        pos: setting.pos.as_ref(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The configuration file extract of the STARFISH paper, laid out one setting per line.
    const PAPER: &str = "\
[Logging]
Server = 1:0                  # running on node 1 port 0
LogLevel = LOG_INFO           # default log level

[Elevators]
Server = 2:0                  # driver on node 2 port 0

[Depth]
Server = 3:0                  # depth from node 3 port 0

[DepthSensor]
Server = 4:0                  # driver on node 4 port 0

[DepthFilter]
Server = 3:0                  # filter on node 3 port 0
Depth.Server = 4:0            # get depth data from sensor

[MyDepthController]
ControlGain = 2.3             # gain control parameter
Logging.LogLevel = LOG_DEBUG  # override log level
";

    const COMPONENTS: [&str; 5] = [
        "Elevators",
        "Depth",
        "DepthSensor",
        "DepthFilter",
        "MyDepthController",
    ];

    fn at(node: u16, port: u16) -> Address {
        Address { node, port }
    }

    fn paper() -> Database {
        Database::parse("starfish.ini", PAPER).expect("the paper's file parses")
    }

    /// The data flow of the paper's example, checked on `db`.
    fn check_paper_plumbing(db: &Database) {
        assert_eq!(db.server_of("DepthFilter", "Depth"), Ok(at(4, 0)));
        assert_eq!(db.server_of("MyDepthController", "Depth"), Ok(at(3, 0)));
        assert_eq!(db.server_of("MyDepthController", "Elevators"), Ok(at(2, 0)));
        assert_eq!(db.server_of("DepthFilter", "DepthSensor"), Ok(at(4, 0)));
        for component in COMPONENTS {
            assert_eq!(db.server_of(component, "Logging"), Ok(at(1, 0)));
            let level = db.setting(component, "Logging", "LogLevel").map(|v| v.text);
            let expected = if component == "MyDepthController" {
                "LOG_DEBUG"
            } else {
                "LOG_INFO"
            };
            assert_eq!(level, Ok(expected), "log level of {component}");
        }
        assert_eq!(db.get_float("MyDepthController", "ControlGain"), Ok(2.3));
    }

    #[test]
    fn paper_example_plumbs_depth_through_the_filter() {
        let db = paper();
        check_paper_plumbing(&db);
        let names: Vec<&str> = db.config_data().iter().map(Section::name).collect();
        assert_eq!(
            names,
            [
                "Logging",
                "Elevators",
                "Depth",
                "DepthSensor",
                "DepthFilter",
                "MyDepthController"
            ]
        );
        let level = db
            .setting("MyDepthController", "Logging", "LogLevel")
            .expect("set");
        assert_eq!(
            (level.section, level.key),
            ("MyDepthController", "Logging.LogLevel")
        );
        let level = db
            .setting("DepthFilter", "Logging", "LogLevel")
            .expect("set");
        assert_eq!((level.section, level.key), ("Logging", "LogLevel"));
    }

    #[test]
    fn changing_only_the_configuration_replumbs_the_data() {
        let text = PAPER.replace(
            "[Depth]\nServer = 3:0                  # depth from node 3 port 0",
            "[Depth]\nServer = 4:0                  # depth straight from the sensor",
        );
        assert_ne!(text, PAPER);
        let db = Database::parse("starfish.ini", &text).expect("parses");
        assert_eq!(db.server_of("MyDepthController", "Depth"), Ok(at(4, 0)));
        assert_eq!(db.server_of("DepthFilter", "Depth"), Ok(at(4, 0)));
        // Dropping the filter's override makes it read its own output, as the file says.
        let text = PAPER.replace("Depth.Server = 4:0", "");
        let db = Database::parse("starfish.ini", &text).expect("parses");
        assert_eq!(db.server_of("DepthFilter", "Depth"), Ok(at(3, 0)));
    }

    #[test]
    fn the_shipped_starfish_file_is_the_papers_example() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/starfish.ini");
        let db = Database::open(&config, &dir.path().join("appdata.ini")).expect("loads");
        check_paper_plumbing(&db);
        assert_eq!(db.server_of("MyDepthController", "Health"), Ok(at(1, 1)));
        assert!(db.app_data().is_empty());
        // Same sections and settings as the paper's extract, plus the health monitor and the
        // controller's address for its polls.
        assert_eq!(
            db.server_of("MyDepthController", "MyDepthController"),
            Ok(at(5, 0))
        );
        let paper_text = paper().config_data().to_text();
        let mut shipped = db.config_data().clone();
        assert_eq!(
            shipped.remove_section("Health").map(|s| s.settings.len()),
            Some(1)
        );
        assert!(shipped.remove("MyDepthController", "Server").is_some());
        assert_eq!(shipped.to_text(), paper_text);
    }

    #[test]
    fn settings_remember_where_their_values_are() {
        let s = Sections::parse("starfish.ini", PAPER).expect("parses");
        let setting = s.get("DepthFilter", "Depth.Server").expect("set");
        assert_eq!(setting.value, "4:0");
        assert_eq!(
            setting.pos.as_ref().map(ToString::to_string).as_deref(),
            Some("starfish.ini:16:16")
        );
        let section = s.section("MyDepthController").expect("there");
        assert_eq!(
            section.pos().map(ToString::to_string).as_deref(),
            Some("starfish.ini:18:1")
        );
        assert_eq!(s.get("Depth", "server"), None, "keys are case-sensitive");
        assert_eq!(s.get("depth", "Server"), None, "names are case-sensitive");
    }

    #[test]
    fn comments_blanks_and_quotes() {
        let text = "\u{feff}# a whole-line comment\r\n\
            \r\n\
            \t[ Op_1-b ]\t# a header with blanks and a comment\r\n\
            plain=a b  c\t# trailing comment\r\n\
            \tspaced   =   x\r\n\
            empty =\r\n\
            empty_comment = # nothing\r\n\
            hash = \"a # b\"  # the quoted `#` stays\r\n\
            outer = \"  both ends  \"\r\n\
            escapes = \"q\\\"b\\\\n\\nt\\tr\\r\"\r\n\
            inner = say \"hi\" \\n\r\n\
            unicode = Ωmega ✓\r\n\
            \x20  # an indented comment\n\
            [Empty]\n\
            [Last]\n\
            Svc.Key = \"\"";
        let s = Sections::parse("t.ini", text).expect("parses");
        let op = s
            .section("Op_1-b")
            .expect("blanks inside brackets are ignored");
        let got: Vec<(&str, &str)> = op
            .settings()
            .iter()
            .map(|s| (s.key.as_str(), s.value.as_str()))
            .collect();
        assert_eq!(
            got,
            [
                ("plain", "a b  c"),
                ("spaced", "x"),
                ("empty", ""),
                ("empty_comment", ""),
                ("hash", "a # b"),
                ("outer", "  both ends  "),
                ("escapes", "q\"b\\n\nt\tr\r"),
                ("inner", "say \"hi\" \\n"),
                ("unicode", "Ωmega ✓"),
            ]
        );
        assert_eq!(s.section("Empty").map(|s| s.settings().len()), Some(0));
        assert_eq!(s.get("Last", "Svc.Key").map(|s| s.value.as_str()), Some(""));
        // Columns count characters, and the byte-order mark is not one.
        let pos = s.get("Op_1-b", "spaced").and_then(|s| s.pos.clone());
        assert_eq!(pos.map(|p| (p.line, p.col)), Some((5, 15)));
        assert!(Sections::parse("t.ini", "").expect("empty").is_empty());
        assert!(
            Sections::parse("t.ini", "\n  \n# only\n")
                .expect("blank")
                .is_empty()
        );
    }

    #[test]
    fn errors_name_file_line_column_and_what_was_expected() {
        let cases: &[(&str, &str)] = &[
            (
                "[A]\nServer 3:0\n",
                "f.ini:2:1: expected `key = value`, found `Server 3:0`",
            ),
            (
                "# intro\n  Server 3:0 # note\n",
                "f.ini:2:3: expected a `[Section]` header, found `Server 3:0`",
            ),
            (
                "\n\nServer = 1:0\n[A]\n",
                "f.ini:3:1: setting `Server` comes before any `[Section]` header",
            ),
            (
                "[A]\nk# = 1\n",
                "f.ini:2:1: expected `key = value`, found `k`",
            ),
            (
                "[Logging\n",
                "f.ini:1:1: expected `]` to close the section header",
            ),
            (
                "[A]\n  [ \t]\n",
                "f.ini:2:3: expected a section name between `[` and `]`",
            ),
            (
                "[Log.ging]\n",
                "f.ini:1:5: unexpected `.` in section name `Log.ging`; a section name has letters, \
                 digits, `_` and `-`",
            ),
            (
                "[Log ging]\n",
                "f.ini:1:5: unexpected space in section name `Log ging`; a section name has \
                 letters, digits, `_` and `-`",
            ),
            (
                "[A] B\n",
                "f.ini:1:5: unexpected `B` after the section header; a comment starts with `#`",
            ),
            (
                "[A]]\n",
                "f.ini:1:4: unexpected `]` after the section header; a comment starts with `#`",
            ),
            ("[A]\n = 3\n", "f.ini:2:2: expected a key before `=`"),
            (
                "[A]\nDe pth = 3\n",
                "f.ini:2:3: unexpected space in key `De pth`; a key has letters, digits, `_` \
                 and `-`",
            ),
            (
                "[A]\nDépth = 3\n",
                "f.ini:2:2: unexpected `é` in key `Dépth`; a key has letters, digits, `_` and `-`",
            ),
            (
                "[A]\n\tDepth.Server.X = 4:0\n",
                "f.ini:2:2: key `Depth.Server.X` is neither a name nor an override `Service.Key` \
                 (two names joined by one `.`)",
            ),
            (
                "[A]\n.Server = 4:0\n",
                "f.ini:2:1: key `.Server` is neither a name nor an override `Service.Key` (two \
                 names joined by one `.`)",
            ),
            (
                "[A]\nk = \"open # not a comment\n",
                "f.ini:2:5: quoted value without its closing `\"`",
            ),
            (
                "[A]\nk = \"ends in a backslash\\\n",
                "f.ini:2:5: quoted value without its closing `\"`",
            ),
            (
                "[A]\nk = \"a\\qb\"\n",
                "f.ini:2:7: unknown escape `\\q` in a quoted value; known: `\\\\`, `\\\"`, `\\n`, \
                 `\\r`, `\\t`",
            ),
            (
                "[A]\nk = \"a\" b # c\n",
                "f.ini:2:9: unexpected `b` after the closing quote; a comment starts with `#`",
            ),
            (
                "[Logging]\nServer = 1:0\n\n[Depth]\n[Logging]\n",
                "f.ini:5:1: section `[Logging]` is already defined at line 1",
            ),
            (
                "[Logging]\nServer = 1:0\n# again\n  Server = 2:0\n",
                "f.ini:4:3: key `Server` is already set in section `[Logging]` at line 2",
            ),
            (
                "[A]\r\nx\u{1}y\r\n",
                "f.ini:2:1: expected `key = value`, found `x\\u{1}y`",
            ),
            (
                "[A]\nkey_that_is_long = fine\nthis line has no equals sign and goes on and on\n",
                "f.ini:3:1: expected `key = value`, found `this line has no equals sign and goes \
                 on…`",
            ),
        ];
        for (text, expected) in cases {
            let err = Sections::parse("f.ini", text).expect_err(text);
            assert_eq!(err.to_string(), *expected, "for {text:?}");
        }
    }

    #[test]
    fn bytes_that_are_not_utf8_are_placed() {
        let err = Sections::parse_bytes("f.ini", b"[A]\nk = ab\xffc\n").expect_err("not UTF-8");
        assert_eq!(err.to_string(), "f.ini:2:7: not UTF-8 text: byte 0xff");
        let err = Sections::parse_bytes("f.ini", b"\xef\xbb\xbf[A\xc3").expect_err("cut");
        assert_eq!(err.to_string(), "f.ini:1:3: not UTF-8 text: byte 0xc3");
        let s = Sections::parse_bytes("f.ini", "[Å]".as_bytes());
        assert_eq!(
            s.map_err(|e| e.to_string()),
            Err(
                "f.ini:1:2: unexpected `Å` in section name `Å`; a section name has letters, \
                 digits, `_` and `-`"
                    .to_owned()
            )
        );
    }

    #[test]
    fn reading_a_missing_file_names_it() {
        let err = Sections::read(Path::new("/no/such/dir/starfish.ini")).expect_err("missing");
        assert!(
            err.to_string()
                .starts_with("/no/such/dir/starfish.ini:1:1: cannot read: "),
            "{err}"
        );
    }

    #[test]
    fn addresses() {
        assert_eq!("4:0".parse(), Ok(at(4, 0)));
        assert_eq!("65534:007".parse(), Ok(at(65534, 7)));
        assert_eq!(at(12, 3).to_string(), "12:3");
        let cases = [
            (
                "4",
                "`4` is not an address: expected `node:port`, e.g. `4:0`",
            ),
            ("", "`` is not an address: expected `node:port`, e.g. `4:0`"),
            (
                "65536:0",
                "`65536:0` is not an address: node `65536` is not a number from 0 to 65534",
            ),
            (
                ":1",
                "`:1` is not an address: node `` is not a number from 0 to 65534",
            ),
            (
                "+1:1",
                "`+1:1` is not an address: node `+1` is not a number from 0 to 65534",
            ),
            (
                "1:2:3",
                "`1:2:3` is not an address: port `2:3` is not a number from 0 to 65535",
            ),
            (
                "1: 2",
                "`1: 2` is not an address: port ` 2` is not a number from 0 to 65535",
            ),
        ];
        for (text, expected) in cases {
            let err = text.parse::<Address>().expect_err(text);
            assert_eq!(err.to_string(), expected);
        }
    }

    #[test]
    fn typed_values_and_their_errors() {
        let text = "[A]\nint = -42\nplus = +7\nfloat = 1e-3\nwhole = 5\ninf = inf\n\
                    word = fast\naddr = 70000:1\n";
        let mut db = Database::parse("a.ini", text).expect("parses");
        assert_eq!(db.get_int("A", "int"), Ok(-42));
        assert_eq!(db.get_int("A", "plus"), Ok(7));
        assert_eq!(db.get_float("A", "float"), Ok(1e-3));
        assert_eq!(db.get_float("A", "whole"), Ok(5.0));
        assert_eq!(db.get_str("A", "word"), Ok("fast"));
        let errors = [
            (
                db.get_int("A", "float"),
                "a.ini:4:9: [A] float = `1e-3` is not an integer",
            ),
            (
                db.get_int("A", "word"),
                "a.ini:7:8: [A] word = `fast` is not an integer",
            ),
        ];
        for (got, expected) in errors {
            assert_eq!(got.map_err(|e| e.to_string()), Err(expected.to_owned()));
        }
        let err = db.get_float("A", "inf").expect_err("not finite");
        assert_eq!(
            err.to_string(),
            "a.ini:6:7: [A] inf = `inf` is not a finite float"
        );
        assert!(matches!(
            err,
            ValueError::Invalid {
                expected: Expected::Float,
                part: Part::Configuration,
                ..
            }
        ));
        assert_eq!(
            db.get_address("A", "addr").map_err(|e| e.to_string()),
            Err(
                "a.ini:8:8: [A] addr = `70000:1` is not an address `node:port` (node and port \
                 from 0 to 65535)"
                    .to_owned()
            )
        );
        assert_eq!(
            db.get_str("A", "nothing").map_err(|e| e.to_string()),
            Err("no key `nothing` in section `[A]`".to_owned())
        );
        assert_eq!(
            db.get_str("B", "int"),
            Err(ValueError::Missing {
                section: "B".into(),
                key: "int".into()
            })
        );
        db.put_str("A", "word", "quick\nbrown").expect("put");
        assert_eq!(
            db.get_float("A", "word").map_err(|e| e.to_string()),
            Err("application data: [A] word = `quick\\nbrown` is not a finite float".to_owned())
        );
        assert_eq!(
            db.server_of("Controller", "Depth")
                .map_err(|e| e.to_string()),
            Err(
                "no `Server` of service `Depth` for component `Controller`: neither \
                 `[Controller] Depth.Server` nor `[Depth] Server` is set"
                    .to_owned()
            )
        );
    }

    #[test]
    fn application_data_masks_configuration_data_until_removed() {
        let mut db = paper();
        assert_eq!(db.get_float("MyDepthController", "ControlGain"), Ok(2.3));
        db.put_float("MyDepthController", "ControlGain", 2.75)
            .expect("put");
        assert_eq!(db.get_float("MyDepthController", "ControlGain"), Ok(2.75));
        let v = db.get("MyDepthController", "ControlGain").expect("set");
        assert_eq!((v.part, v.pos), (Part::Application, None));
        // The configuration data is never changed by software.
        let config = db.config_data().get("MyDepthController", "ControlGain");
        assert_eq!(config.map(|s| s.value.as_str()), Some("2.3"));
        // Application data may hold keys and sections the configuration data lacks.
        db.put_int("MyDepthController", "Trims", 12).expect("put");
        db.put_str("Adaptive", "Model", "second order")
            .expect("put");
        assert_eq!(db.get_int("MyDepthController", "Trims"), Ok(12));
        assert_eq!(db.get_str("Adaptive", "Model"), Ok("second order"));
        // Removing unmasks; removing again finds nothing.
        assert_eq!(
            db.remove("MyDepthController", "ControlGain").ok(),
            Some(true)
        );
        assert_eq!(db.get_float("MyDepthController", "ControlGain"), Ok(2.3));
        let v = db.get("MyDepthController", "ControlGain").expect("set");
        assert_eq!(v.part, Part::Configuration);
        assert_eq!(
            db.remove("MyDepthController", "ControlGain").ok(),
            Some(false)
        );
        assert_eq!(db.remove("MyDepthController", "Nothing").ok(), Some(false));
        assert_eq!(db.get_int("MyDepthController", "Trims"), Ok(12));
        // Removing the section removes all its application data and unmasks the rest.
        db.put_str("MyDepthController", "Logging.LogLevel", "LOG_ERROR")
            .expect("put");
        assert_eq!(
            db.setting("MyDepthController", "Logging", "LogLevel")
                .map(|v| v.text),
            Ok("LOG_ERROR")
        );
        assert_eq!(db.remove_section("MyDepthController").ok(), Some(true));
        assert_eq!(db.remove_section("MyDepthController").ok(), Some(false));
        assert_eq!(
            db.get_int("MyDepthController", "Trims"),
            Err(ValueError::Missing {
                section: "MyDepthController".into(),
                key: "Trims".into()
            })
        );
        assert_eq!(
            db.setting("MyDepthController", "Logging", "LogLevel")
                .map(|v| v.text),
            Ok("LOG_DEBUG")
        );
        let names: Vec<&str> = db.app_data().iter().map(Section::name).collect();
        assert_eq!(names, ["Adaptive"]);
        // Removing a section's last key drops the section.
        assert_eq!(db.remove("Adaptive", "Model").ok(), Some(true));
        assert!(db.app_data().is_empty());
    }

    #[test]
    fn application_data_masks_plumbing_too() {
        let mut db = paper();
        // A service's address put by software re-plumbs everyone without an override ...
        db.put_str("Depth", "Server", "4:0").expect("put");
        assert_eq!(db.server_of("MyDepthController", "Depth"), Ok(at(4, 0)));
        // ... and a component's override put by software beats the service's setting.
        db.put_str("MyDepthController", "Depth.Server", "5:2")
            .expect("put");
        assert_eq!(db.server_of("MyDepthController", "Depth"), Ok(at(5, 2)));
        assert_eq!(db.server_of("DepthFilter", "Depth"), Ok(at(4, 0)));
        db.remove_section("MyDepthController").expect("in memory");
        db.remove("Depth", "Server").expect("in memory");
        check_paper_plumbing(&db);
    }

    #[test]
    fn puts_refuse_what_would_not_read_back() {
        let mut db = paper();
        let refused = [
            (
                db.put_str("Bad Name", "k", "v"),
                "`Bad Name` is not a section name: use letters, digits, `_` and `-`",
            ),
            (
                db.put_str("A.B", "k", "v"),
                "`A.B` is not a section name: use letters, digits, `_` and `-`",
            ),
            (
                db.put_str("", "k", "v"),
                "`` is not a section name: use letters, digits, `_` and `-`",
            ),
            (
                db.put_int("A", "a.b.c", 1),
                "`a.b.c` is not a key: use letters, digits, `_` and `-`, and one `.` in an override `Service.Key`",
            ),
            (
                db.put_int("A", "k\n", 1),
                "`k\\n` is not a key: use letters, digits, `_` and `-`, and one `.` in an override `Service.Key`",
            ),
            (
                db.put_float("A", "k", f64::NAN),
                "[A] k: NaN is not a finite float",
            ),
            (
                db.put_float("A", "k", f64::NEG_INFINITY),
                "[A] k: -inf is not a finite float",
            ),
        ];
        for (got, expected) in refused {
            assert_eq!(got.map_err(|e| e.to_string()), Err(expected.to_owned()));
        }
        assert!(db.app_data().is_empty());
    }

    #[test]
    fn floats_and_integers_read_back_exactly() {
        let mut db = Database::default();
        let floats = [0.1, -2.5e-300, 1.7976931348623157e308, 5e-324, -0.0, 2.3];
        for (i, f) in floats.into_iter().enumerate() {
            let key = format!("f{i}");
            db.put_float("Num", &key, f).expect("finite");
            let back = db.get_float("Num", &key).expect("reads");
            assert_eq!(back.to_bits(), f.to_bits(), "{f}");
        }
        for (i, n) in [i64::MIN, -1, 0, i64::MAX].into_iter().enumerate() {
            let key = format!("i{i}");
            db.put_int("Num", &key, n).expect("put");
            assert_eq!(db.get_int("Num", &key), Ok(n));
        }
        let back = Sections::parse("app.ini", &db.app_data().to_text()).expect("parses");
        assert_eq!(back.to_text(), db.app_data().to_text());
    }

    #[test]
    fn the_writer_quotes_what_needs_it() {
        let values = [
            "plain value",
            "",
            " leading",
            "trailing ",
            "\ttab",
            "has # hash",
            "\"starts quoted\"",
            "ends quoted\"",
            "back\\slash",
            "line\nbreak\r\n",
            "nul\0and\u{7f}",
            "Ωmega",
            "=",
        ];
        let mut s = Sections::new();
        for (i, v) in values.iter().enumerate() {
            s.set("Odd", &format!("k{i}"), v).expect("names");
        }
        s.set("Empty-2", "Svc.Key", "x").expect("names");
        let text = s.to_text();
        assert!(text.starts_with(
            "[Odd]\nk0 = plain value\nk1 = \"\"\nk2 = \" leading\"\nk3 = \"trailing \"\n\
             k4 = \"\\ttab\"\nk5 = \"has # hash\"\nk6 = \"\\\"starts quoted\\\"\"\n\
             k7 = ends quoted\"\nk8 = back\\slash\nk9 = \"line\\nbreak\\r\\n\"\n"
        ));
        assert!(
            text.ends_with("k12 = =\n\n[Empty-2]\nSvc.Key = x\n"),
            "{text}"
        );
        let back = Sections::parse("app.ini", &text).expect("parses");
        for (i, v) in values.iter().enumerate() {
            let got = back.get("Odd", &format!("k{i}")).map(|s| s.value.as_str());
            assert_eq!(got, Some(*v));
        }
        assert_eq!(back.to_text(), text);
    }

    #[test]
    fn application_data_persists_in_its_own_file() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let config = dir.path().join("starfish.ini");
        let app = dir.path().join("appdata.ini");
        std::fs::write(&config, PAPER).expect("written");
        let mut db = Database::open(&config, &app).expect("opens without application data");
        assert_eq!(db.app_data_path(), Some(app.as_path()));
        assert!(!app.exists(), "nothing is written before the first put");
        db.put_float("MyDepthController", "ControlGain", 2.5)
            .expect("put");
        db.put_str("MyDepthController", "Note", "tuned # at sea")
            .expect("put");
        db.put_int("Counters", "Dives", 3).expect("put");
        let text = std::fs::read_to_string(&app).expect("written");
        assert_eq!(
            text,
            format!(
                "{APP_DATA_HEADER}[MyDepthController]\nControlGain = 2.5\n\
                 Note = \"tuned # at sea\"\n\n[Counters]\nDives = 3\n"
            )
        );
        let again = Database::open(&config, &app).expect("reopens");
        assert_eq!(again.get_float("MyDepthController", "ControlGain"), Ok(2.5));
        assert_eq!(
            again.get_str("MyDepthController", "Note"),
            Ok("tuned # at sea")
        );
        assert_eq!(again.get_int("Counters", "Dives"), Ok(3));
        let v = again.get("Counters", "Dives").expect("set");
        assert_eq!(v.pos.map(|p| (p.line, p.col)), Some((8, 9)));
        assert_eq!(db.remove_section("Counters").ok(), Some(true));
        assert_eq!(
            db.remove("MyDepthController", "ControlGain").ok(),
            Some(true)
        );
        let again = Database::open(&config, &app).expect("reopens");
        assert_eq!(again.get_float("MyDepthController", "ControlGain"), Ok(2.3));
        assert!(again.get("Counters", "Dives").is_err());
        // Only the two files remain: no temporary file is left behind.
        let mut names: Vec<String> = std::fs::read_dir(dir.path())
            .expect("listed")
            .map(|e| {
                e.expect("an entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        names.sort();
        assert_eq!(names, ["appdata.ini", "starfish.ini"]);
    }

    #[test]
    fn damaged_application_data_is_an_error_naming_file_and_line() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let config = dir.path().join("starfish.ini");
        let app = dir.path().join("appdata.ini");
        std::fs::write(&config, PAPER).expect("written");
        std::fs::write(
            &app,
            "[MyDepthController]\nControlGain = 2.5\nNote = \"cut sh",
        )
        .expect("w");
        let err = Database::open(&config, &app).expect_err("damaged");
        assert_eq!(
            err.to_string(),
            format!(
                "{}:3:8: quoted value without its closing `\"`",
                app.display()
            )
        );
        std::fs::write(&app, b"[Counters]\nDives = \xff\n").expect("written");
        let err = Database::open(&config, &app).expect_err("damaged");
        assert_eq!(
            err.to_string(),
            format!("{}:2:9: not UTF-8 text: byte 0xff", app.display())
        );
        std::fs::create_dir(dir.path().join("dir.ini")).expect("made");
        let err = Database::open(&config, &dir.path().join("dir.ini")).expect_err("a directory");
        assert!(
            err.to_string().contains("dir.ini:1:1: cannot read: "),
            "{err}"
        );
    }

    #[test]
    fn a_failed_write_leaves_the_database_unchanged() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let config = dir.path().join("starfish.ini");
        std::fs::write(&config, PAPER).expect("written");
        let app = dir.path().join("gone").join("appdata.ini");
        let mut db = Database::open(&config, &app).expect("opens");
        let err = db
            .put_int("Counters", "Dives", 1)
            .expect_err("no directory");
        assert!(matches!(err, StoreError::Write { ref path, .. } if *path == app));
        assert!(
            err.to_string().starts_with(&format!(
                "{}: cannot write the application data: ",
                app.display()
            )),
            "{err}"
        );
        assert!(db.app_data().is_empty());
        assert!(db.get("Counters", "Dives").is_err());
    }
}
