//! Log files of either kind seabus writes: LCM event logs (`lcm-logger`'s format) and MCAP files.
//! [`Writer`] writes messages to one (`seabus record`, the `logger` module); [`Reader`] reads
//! either, told apart by the file's first bytes (`seabus replay`, `seabus export`).

use seabus_medium::eventlog::{self, event_data};
use seabus_medium::{Message, Payload, Stamp};
use seabus_modules::datasets::Catalogue;
use std::fs::File;
use std::io::{self, Read};
use std::path::Path;
use std::sync::Arc;

/// The kinds of log file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// An LCM event log.
    Lcm,
    /// An MCAP file.
    Mcap,
}

impl Kind {
    /// The kind of the file at `path`: MCAP when its first bytes are MCAP's magic or it is named
    /// `.mcap` (whose reader then says what is wrong with its start), else an LCM event log.
    pub fn of_file(path: &Path) -> io::Result<Kind> {
        let mut head = [0u8; 8];
        let mut file = File::open(path)?;
        let mut got = 0;
        while got < head.len() {
            match file.read(&mut head[got..])? {
                0 => break,
                n => got += n,
            }
        }
        // the magic's first five bytes (`\x89MCAP`) say MCAP; the rest is the format's version
        Ok(
            if (got >= 5 && head[..5] == crate::MAGIC[..5]) || Kind::of_name(path) == Kind::Mcap {
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
    /// An LCM event log.
    Lcm(eventlog::Reader<File>),
    /// An MCAP file.
    Mcap(Box<crate::Reader>),
}

impl Reader {
    /// Opens the log at `path`, of the kind its first bytes say.
    pub fn open(path: &Path) -> io::Result<Reader> {
        Ok(match Kind::of_file(path)? {
            Kind::Lcm => Reader::Lcm(eventlog::Reader::open(path)?),
            Kind::Mcap => Reader::Mcap(Box::new(crate::Reader::open(path)?)),
        })
    }

    /// The file's size, when known.
    pub fn size(&self) -> Option<u64> {
        match self {
            Reader::Lcm(r) => r.size(),
            Reader::Mcap(r) => r.size(),
        }
    }

    /// Bytes read so far.
    pub fn offset(&self) -> u64 {
        match self {
            Reader::Lcm(r) => r.offset(),
            Reader::Mcap(r) => r.offset(),
        }
    }

    /// The next event, `Ok(None)` at the log's end. A message whose payload cannot be read (an
    /// MCAP `json` message that is not JSON) is damage at the offset reached.
    pub fn next_event(&mut self) -> Result<Option<Event>, Damage> {
        match self {
            Reader::Lcm(r) => match r.next_event() {
                Ok(Some(e)) => Ok(Some(Event {
                    micros: e.timestamp,
                    channel: e.channel.to_string(),
                    payload: Payload::from(e.data),
                })),
                Ok(None) => Ok(None),
                Err(d) => Err(Damage {
                    offset: d.offset,
                    problem: d.problem.to_string(),
                }),
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

/// A log being written.
pub enum Writer {
    /// An LCM event log: one event per message, its data the payload's bytes (a datamap in
    /// seabus's binary form).
    Lcm(eventlog::Writer<File>),
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
            (Kind::Lcm, true) => Writer::Lcm(eventlog::Writer::create(path)?),
            (Kind::Lcm, false) => Writer::Lcm(eventlog::Writer::create_new(path)?),
            (Kind::Mcap, replace) => {
                Writer::Mcap(Box::new(crate::Writer::create(path, replace, catalogue)?))
            }
        })
    }

    /// Writes `msg`, logged at `log_time` (an LCM event's timestamp, an MCAP message's log time).
    pub fn write(&mut self, msg: &Message, log_time: Stamp) -> Result<(), WriteError> {
        match self {
            Writer::Lcm(w) => {
                let data = event_data(&msg.payload)
                    .map_err(|e| WriteError::Unwritable(format!("`{}`: {e}", msg.topic)))?;
                w.write(log_time.0.div_euclid(1000), &msg.topic, &data)
                    .map(|_| ())
                    .map_err(|e| WriteError::File(e.to_string()))
            }
            Writer::Mcap(w) => match w.write(msg, log_time) {
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
            Writer::Lcm(w) => w.flush(),
            Writer::Mcap(w) => w.flush().map_err(io::Error::other),
        }
    }

    /// Messages written.
    pub fn messages(&self) -> u64 {
        match self {
            Writer::Lcm(w) => w.events(),
            Writer::Mcap(w) => w.messages(),
        }
    }

    /// Ends the file: flushed, and for MCAP its summary, indexes and footer written.
    pub fn finish(self) -> io::Result<()> {
        match self {
            Writer::Lcm(mut w) => w.flush(),
            Writer::Mcap(w) => w.finish().map_err(io::Error::other),
        }
    }
}
