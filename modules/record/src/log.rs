//! Log files of either kind seabus writes: LCM event logs (`lcm-logger`'s format) and MCAP files.
//! [`Writer`] writes messages to one (`seabus record`, the `logger` module); [`Reader`] reads
//! either, told apart by the file's first bytes (`seabus replay`, `seabus export`); [`logs_in`]
//! finds the logs in a folder by those bytes, whatever the files are named.
//!
//! An LCM event log holds each event's channel and data, nothing of the payload's format. So that
//! a seabus log replays the messages it recorded, a channel whose payloads are not bytes is
//! preceded, where its format changes, by a [`FORMAT_CHANNEL`] event that says the format of what
//! follows on it: a datamap, written in seabus's binary form, or XML, written as its text. A
//! channel without such an event carries bytes, as every channel of a log from `lcm-logger` does;
//! and a recording of LCM traffic (bytes only) has none, event for event what `lcm-logger` writes.

use seabus_medium::eventlog::{self, event_data};
use seabus_medium::{DataMap, Format, Message, Payload, Stamp, binary};
use seabus_modules::datasets::Catalogue;
use std::collections::HashMap;
use std::fs::File;
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The channel of the events that say a channel's payload format in a seabus LCM event log: data a
/// binary datamap with `channel` (the channel's name) and `format` (`map`, `xml` or `bytes`).
pub const FORMAT_CHANNEL: &str = "seabus.log.format";

/// Channels whose format a reader or writer remembers before it starts over (a flood of names).
const MAX_FORMATS: usize = 100_000;

/// The kinds of log file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// An LCM event log.
    Lcm,
    /// An MCAP file.
    Mcap,
}

impl Kind {
    /// The kind of log `head` (a file's first bytes) opens, if any: MCAP's magic, or an LCM event
    /// log's first event's sync word.
    pub fn of_head(head: &[u8]) -> Option<Kind> {
        if head.len() >= 5 && head[..5] == crate::MAGIC[..5] {
            Some(Kind::Mcap)
        } else if head.len() >= 4 && head[..4] == eventlog::SYNC.to_be_bytes() {
            Some(Kind::Lcm)
        } else {
            None
        }
    }

    /// The kind of the file at `path`: MCAP when its first bytes are MCAP's magic or it is named
    /// `.mcap` (whose reader then says what is wrong with its start), else an LCM event log.
    pub fn of_file(path: &Path) -> io::Result<Kind> {
        let head = head(path)?;
        Ok(
            if Kind::of_head(&head) == Some(Kind::Mcap) || Kind::of_name(path) == Kind::Mcap {
                Kind::Mcap
            } else {
                Kind::Lcm
            },
        )
    }

    /// The kind a file to be written is, by its name: `.mcap` is MCAP, anything else LCM.
    pub fn of_name(path: &Path) -> Kind {
        if path
            .extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("mcap"))
        {
            Kind::Mcap
        } else {
            Kind::Lcm
        }
    }

    /// Reads `--format`: `lcm` or `mcap`.
    pub fn parse(text: &str) -> Option<Kind> {
        match text {
            "lcm" | "lcmlog" => Some(Kind::Lcm),
            "mcap" => Some(Kind::Mcap),
            _ => None,
        }
    }
}

/// One event of a log.
pub struct Event {
    /// When it was logged, microseconds since the Unix epoch.
    pub micros: i64,
    /// Its channel (an LCM channel, an MCAP topic).
    pub channel: String,
    /// Its payload: an LCM event's bytes; an MCAP message by its encoding (JSON as a datamap).
    pub payload: Payload,
    /// The LCM type an MCAP message was decoded from, when its channel says
    /// ([`crate::LCM_TYPE_KEY`]).
    pub lcm_type: Option<String>,
}

/// Where a log stops being readable: the byte offset and what is wrong there.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// The byte offset of the record or event that could not be read.
    pub offset: u64,
    /// What is wrong there.
    pub problem: String,
}

impl std::fmt::Display for Damage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "byte {}: {}", self.offset, self.problem)
    }
}

/// A log being read.
pub enum Reader {
    /// An LCM event log, and the format of each channel a [`FORMAT_CHANNEL`] event named.
    Lcm(eventlog::Reader<File>, HashMap<String, Format>),
    /// An MCAP file.
    Mcap(Box<crate::Reader>),
}

impl Reader {
    /// Opens the log at `path`, of the kind its first bytes say.
    pub fn open(path: &Path) -> io::Result<Reader> {
        Ok(match Kind::of_file(path)? {
            Kind::Lcm => Reader::Lcm(eventlog::Reader::open(path)?, HashMap::new()),
            Kind::Mcap => Reader::Mcap(Box::new(crate::Reader::open(path)?)),
        })
    }

    /// The file's size, when known.
    pub fn size(&self) -> Option<u64> {
        match self {
            Reader::Lcm(r, _) => r.size(),
            Reader::Mcap(r) => r.size(),
        }
    }

    /// Bytes read so far.
    pub fn offset(&self) -> u64 {
        match self {
            Reader::Lcm(r, _) => r.offset(),
            Reader::Mcap(r) => r.offset(),
        }
    }

    /// The next event, `Ok(None)` at the log's end. A message whose payload cannot be read (an
    /// MCAP `json` message that is not JSON) is damage at the offset reached.
    pub fn next_event(&mut self) -> Result<Option<Event>, Damage> {
        match self {
            Reader::Lcm(r, formats) => loop {
                let at = r.offset();
                let e = match r.next_event() {
                    Ok(Some(e)) => e,
                    Ok(None) => return Ok(None),
                    Err(d) => {
                        return Err(Damage {
                            offset: d.offset,
                            problem: d.problem.to_string(),
                        });
                    }
                };
                if e.channel == FORMAT_CHANNEL
                    && let Some((channel, format)) = format_event(e.data)
                {
                    if formats.len() >= MAX_FORMATS {
                        formats.clear();
                    }
                    formats.insert(channel, format);
                    continue;
                }
                let payload = match formats.get(e.channel).copied().unwrap_or(Format::Bytes) {
                    Format::Bytes => Payload::from(e.data),
                    Format::Map => match binary::decode(e.data) {
                        Ok(m) => Payload::from(m),
                        Err(err) => {
                            return Err(Damage {
                                offset: at,
                                problem: format!(
                                    "an event on `{}` is not the datamap its format event says: {err}",
                                    e.channel
                                ),
                            });
                        }
                    },
                    Format::Xml => match std::str::from_utf8(e.data) {
                        Ok(text) => Payload::Xml(Arc::from(text)),
                        Err(err) => {
                            return Err(Damage {
                                offset: at,
                                problem: format!(
                                    "an event on `{}` is not the XML text its format event says: {err}",
                                    e.channel
                                ),
                            });
                        }
                    },
                };
                return Ok(Some(Event {
                    micros: e.timestamp,
                    channel: e.channel.to_string(),
                    payload,
                    lcm_type: None,
                }));
            },
            Reader::Mcap(r) => match r.next_message() {
                Ok(Some(m)) => {
                    let payload = crate::payload_of(&m).map_err(|e| Damage {
                        offset: r.offset(),
                        problem: format!(
                            "a message on `{}` (sequence {}): {e}",
                            m.channel.topic, m.sequence
                        ),
                    })?;
                    Ok(Some(Event {
                        micros: i64::try_from(m.log_time / 1000).unwrap_or(i64::MAX),
                        channel: m.channel.topic.clone(),
                        payload,
                        lcm_type: m.channel.lcm_type().map(str::to_string),
                    }))
                }
                Ok(None) => Ok(None),
                Err(d) => Err(Damage {
                    offset: d.offset,
                    problem: d.problem,
                }),
            },
        }
    }
}

/// Why a message was not written to a log.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The file could not be written: the recording cannot go on.
    #[error("{0}")]
    File(String),
    /// This message has no form the log holds (a datamap nested too deep): it alone is left out.
    #[error("{0}")]
    Unwritable(String),
}

/// The payload formats of an LCM event log's channels, as written.
#[derive(Default)]
pub struct Formats {
    /// Each channel's format now (none: bytes).
    now: HashMap<String, Format>,
    /// Format events written.
    said: u64,
}

/// A log being written.
pub enum Writer {
    /// An LCM event log: one event per message, its data the payload's bytes (a datamap in
    /// seabus's binary form, XML as its text), and the format each channel has now.
    Lcm(eventlog::Writer<File>, Formats),
    /// An MCAP file ([`crate::Writer`]).
    Mcap(Box<crate::Writer>),
}

impl Writer {
    /// Creates a log of `kind` at `path`; `replace` says whether an existing file is replaced
    /// (else that is an error of kind `AlreadyExists`). MCAP schemas come from `catalogue`.
    pub fn create(
        path: &Path,
        kind: Kind,
        replace: bool,
        catalogue: Arc<Catalogue>,
    ) -> io::Result<Writer> {
        Ok(match (kind, replace) {
            (Kind::Lcm, true) => Writer::Lcm(eventlog::Writer::create(path)?, Formats::default()),
            (Kind::Lcm, false) => {
                Writer::Lcm(eventlog::Writer::create_new(path)?, Formats::default())
            }
            (Kind::Mcap, replace) => {
                Writer::Mcap(Box::new(crate::Writer::create(path, replace, catalogue)?))
            }
        })
    }

    /// Writes `msg`, logged at `log_time` (an LCM event's timestamp, an MCAP message's log time).
    pub fn write(&mut self, msg: &Message, log_time: Stamp) -> Result<(), WriteError> {
        self.write_typed(msg, log_time, None)
    }

    /// Writes `msg` like [`Writer::write`], decoded from an LCM message of type `lcm_type`: an
    /// MCAP file says so in the channel's metadata (an LCM log holds the LCM bytes themselves).
    pub fn write_typed(
        &mut self,
        msg: &Message,
        log_time: Stamp,
        lcm_type: Option<&str>,
    ) -> Result<(), WriteError> {
        match self {
            Writer::Lcm(w, formats) => {
                let data = event_data(&msg.payload)
                    .map_err(|e| WriteError::Unwritable(format!("`{}`: {e}", msg.topic)))?;
                let micros = log_time.0.div_euclid(1000);
                let file = |e: eventlog::WriteError| WriteError::File(e.to_string());
                let format = msg.payload.format();
                let was = formats.now.get(msg.topic.as_str()).copied();
                if was.unwrap_or(Format::Bytes) != format {
                    if formats.now.len() >= MAX_FORMATS {
                        // (those forgotten are said again when they next come)
                        formats.now.clear();
                    }
                    let said = DataMap::new()
                        .with("channel", msg.topic.as_str())
                        .with("format", format.name());
                    let said =
                        binary::encode(&said).map_err(|e| WriteError::Unwritable(e.to_string()))?;
                    w.write(micros, FORMAT_CHANNEL, &said).map_err(file)?;
                    formats.said += 1;
                    formats.now.insert(msg.topic.to_string(), format);
                }
                w.write(micros, &msg.topic, &data).map(|_| ()).map_err(file)
            }
            Writer::Mcap(w) => match w.write_typed(msg, log_time, lcm_type) {
                Ok(()) => Ok(()),
                Err(crate::WriteError::Mcap(e)) => Err(WriteError::File(e.to_string())),
                Err(e) => Err(WriteError::Unwritable(e.to_string())),
            },
        }
    }

    /// Passes what was buffered on to the file (MCAP: closes the chunk under way, so a file cut
    /// short later reads up to here).
    pub fn flush(&mut self) -> io::Result<()> {
        match self {
            Writer::Lcm(w, _) => w.flush(),
            Writer::Mcap(w) => w.flush().map_err(io::Error::other),
        }
    }

    /// Messages written (not counting format events).
    pub fn messages(&self) -> u64 {
        match self {
            Writer::Lcm(w, formats) => w.events() - formats.said,
            Writer::Mcap(w) => w.messages(),
        }
    }

    /// Ends the file: flushed, and for MCAP its summary, indexes and footer written.
    pub fn finish(self) -> io::Result<()> {
        match self {
            Writer::Lcm(mut w, _) => w.flush(),
            Writer::Mcap(w) => w.finish().map_err(io::Error::other),
        }
    }
}

/// A [`FORMAT_CHANNEL`] event's channel and format, if its data is one.
fn format_event(data: &[u8]) -> Option<(String, Format)> {
    let map = binary::decode(data).ok()?;
    let channel = map.get("channel")?.as_str()?.to_string();
    let format = Format::parse(map.get("format")?.as_str()?)?;
    Some((channel, format))
}

/// Files of a folder that are not logs, each with why.
pub type Skipped = Vec<(PathBuf, String)>;

/// The logs in a folder: its files that are LCM event logs or MCAP files by their first bytes,
/// whatever they are named, in name order; and the others, each with why it is not one.
pub fn logs_in(dir: &Path) -> io::Result<(Vec<PathBuf>, Skipped)> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)?
        .map(|e| e.map(|e| e.path()))
        .collect::<io::Result<_>>()?;
    entries.sort();
    let (mut logs, mut skipped) = (Vec::new(), Vec::new());
    for path in entries {
        if path.is_dir() {
            skipped.push((path, "a folder".to_string()));
            continue;
        }
        match head(&path) {
            Err(e) => skipped.push((path, format!("cannot read: {e}"))),
            Ok(h) if h.is_empty() => skipped.push((path, "empty".to_string())),
            Ok(h) => match Kind::of_head(&h) {
                Some(_) => logs.push(path),
                None => skipped.push((
                    path,
                    "not an LCM event log or MCAP file (its first bytes are neither's)".to_string(),
                )),
            },
        }
    }
    Ok((logs, skipped))
}

/// A file's first bytes (up to 8: enough for either kind's magic).
fn head(path: &Path) -> io::Result<Vec<u8>> {
    let mut head = Vec::with_capacity(8);
    File::open(path)?.take(8).read_to_end(&mut head)?;
    Ok(head)
}
