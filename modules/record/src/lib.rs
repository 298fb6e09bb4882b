//! seabus-record: recordings in MCAP, the indexed, compressed, self-describing log format that
//! Foxglove, Lichtblick, PlotJuggler, ROS 2 and Python's `mcap` read — written and read with the
//! `mcap` crate.
//!
//! - [`Writer`] writes messages as they come: one channel per topic (and payload form), each with
//!   its JSON Schema ([`seabus_modules::schema`]: the topic's standard dataset, or read off its first
//!   message); datamaps as JSON in seabus's JSON form, byte payloads as they are. Log time is
//!   seabus's clock when the message was recorded, publish time the message's own stamp. Chunks are
//!   zstd-compressed, and the file ends with a summary and indexes so readers can seek.
//!   [`Writer::flush`] closes the chunk under way: a file cut short later (a crash, power lost)
//!   still reads up to there.
//! - [`Reader`] reads any MCAP file message by message in bounded memory (chunks are
//!   decompressed as they stream), and says where a damaged or cut-short file stops being readable
//!   ([`Damage`], with the byte offset of the record it could not read).
//! - [`payload_of`] turns a read message back into a seabus payload by its channel's encoding.
//! - [`log`] writes and reads either kind of log seabus keeps — LCM event logs and MCAP files —
//!   through one writer and one reader.
//!
//! The format's details, as seabus uses them, are in `docs/wire-formats.md`.
//!
//! Who may depend on it: the program (`seabus record`, `replay`, `export`, `convert`) and product
//! crates that record (the `logger` module). It depends on the core and the module framework.

pub mod log;

use mcap::records::{MessageHeader, Record};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};
use seabus_medium::{DataMap, Kind, Message, Payload, Stamp, Topic};
use seabus_modules::datasets::Catalogue;
use seabus_modules::schema;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{self, BufWriter, Read, Seek, Write};
use std::path::Path;
use std::sync::Arc;

/// The eight bytes an MCAP file starts and ends with.
pub use mcap::MAGIC;

/// The message encoding of datamaps: JSON (MCAP's well-known `json` encoding).
pub const JSON: &str = "json";
/// The message encoding of byte payloads: the bytes as they were carried.
pub const BYTES: &str = "application/octet-stream";
/// The message encoding of XML payloads that are not a datamap document: the text.
pub const XML: &str = "xml";
/// The schema encoding of every schema seabus writes.
pub const JSON_SCHEMA: &str = "jsonschema";
/// The channel metadata key that says a channel carries commands (`"command"`).
pub const KIND_KEY: &str = "seabus.kind";
/// The channel metadata key that names the LCM type its messages were decoded from
/// (`package.name_t`): an LCM log made from the file encodes them with it again.
pub const LCM_TYPE_KEY: &str = "lcm.type";
/// The profile seabus writes in the header: none of the well-known ones fits.
const PROFILE: &str = "";
/// The largest record [`Reader`] reads (a chunk, an attachment): a longer one is damage.
pub const MAX_RECORD: u64 = 1 << 28;
/// How much of a record [`Reader`] reads from the file at once.
const READ_STEP: u64 = 64 * 1024;

/// Why a message could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The file could not be written (disk full, removed, …) or the `mcap` crate refused.
    #[error("{0}")]
    Mcap(#[from] mcap::McapError),
    /// A datamap has no JSON message (it nests too deep, or has a field of a reserved name).
    #[error("`{0}`: {1}")]
    NoJson(String, schema::MessageError),
    /// More channels than an MCAP file can name.
    #[error("`{0}`: the file already has 65 535 channels")]
    TooManyChannels(String),
}

/// How a payload is stored on a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Form {
    Json,
    Bytes,
    Xml,
}

impl Form {
    fn encoding(self) -> &'static str {
        match self {
            Form::Json => JSON,
            Form::Bytes => BYTES,
            Form::Xml => XML,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct ChannelKey {
    topic: Topic,
    form: Form,
    kind: Kind,
    lcm_type: Option<Arc<str>>,
}

struct Channel {
    id: u16,
    sequence: u32,
}

/// Writes seabus messages to an MCAP file.
pub struct Writer<W: Write + Seek = BufWriter<File>> {
    out: mcap::Writer<W>,
    catalogue: Arc<Catalogue>,
    channels: HashMap<ChannelKey, Channel>,
    schemas: HashMap<String, u16>,
    messages: u64,
    scratch: Vec<u8>,
}

impl Writer<BufWriter<File>> {
    /// Creates the file at `path`; `replace` says whether an existing file is replaced (else that
    /// is an error of kind `AlreadyExists`).
    pub fn create(
        path: impl AsRef<Path>,
        replace: bool,
        catalogue: Arc<Catalogue>,
    ) -> io::Result<Self> {
        let file = if replace {
            File::create(path)?
        } else {
            File::create_new(path)?
        };
        Writer::new(BufWriter::with_capacity(1 << 16, file), catalogue).map_err(io::Error::other)
    }
}

impl<W: Write + Seek> Writer<W> {
    /// A writer onto `out`, the schemas of datasets from `catalogue`.
    pub fn new(out: W, catalogue: Arc<Catalogue>) -> Result<Self, mcap::McapError> {
        let options = mcap::WriteOptions::new()
            .profile(PROFILE)
            .library(concat!("seabus ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            // no compression threads beside the autonomy: one core does it as messages come
            .compression_threads(0);
        Ok(Writer {
            out: options.create(out)?,
            catalogue,
            channels: HashMap::new(),
            schemas: HashMap::new(),
            messages: 0,
            scratch: Vec::new(),
        })
    }

    /// The schema id for `topic` and a datamap like `sample`, added the first time.
    fn schema_id(&mut self, topic: &str, sample: &DataMap) -> Result<u16, WriteError> {
        let s = schema::for_topic(&self.catalogue, topic, sample);
        if let Some(id) = self.schemas.get(&s.name) {
            return Ok(*id);
        }
        let id = self
            .out
            .add_schema(&s.name, JSON_SCHEMA, s.text.as_bytes())?;
        self.schemas.insert(s.name, id);
        Ok(id)
    }

    fn channel(
        &mut self,
        key: ChannelKey,
        sample: Option<&DataMap>,
    ) -> Result<&mut Channel, WriteError> {
        if !self.channels.contains_key(&key) {
            if self.channels.len() >= usize::from(u16::MAX) {
                return Err(WriteError::TooManyChannels(key.topic.to_string()));
            }
            let schema = match sample {
                Some(map) => self.schema_id(key.topic.as_str(), map)?,
                None => 0,
            };
            let mut metadata = BTreeMap::new();
            if key.kind == Kind::Command {
                metadata.insert(KIND_KEY.to_string(), "command".to_string());
            }
            if let Some(t) = &key.lcm_type {
                metadata.insert(LCM_TYPE_KEY.to_string(), t.to_string());
            }
            let id =
                self.out
                    .add_channel(schema, key.topic.as_str(), key.form.encoding(), &metadata)?;
            self.channels
                .insert(key.clone(), Channel { id, sequence: 0 });
        }
        Ok(self.channels.get_mut(&key).expect("added above"))
    }

    /// Writes `msg`, recorded at `log_time`.
    pub fn write(&mut self, msg: &Message, log_time: Stamp) -> Result<(), WriteError> {
        self.write_typed(msg, log_time, None)
    }

    /// Writes `msg`, recorded at `log_time`, decoded from an LCM message of type `lcm_type` (said
    /// in its channel's metadata, [`LCM_TYPE_KEY`]).
    pub fn write_typed(
        &mut self,
        msg: &Message,
        log_time: Stamp,
        lcm_type: Option<&str>,
    ) -> Result<(), WriteError> {
        let map = match &msg.payload {
            Payload::Map(m) => Some(m.clone()),
            Payload::Xml(_) => msg.payload.to_map().ok(),
            Payload::Bytes(_) => None,
        };
        let (form, data): (Form, &[u8]) = match (&map, &msg.payload) {
            (Some(m), _) => {
                self.scratch.clear();
                schema::write_message(m, &mut self.scratch)
                    .map_err(|e| WriteError::NoJson(msg.topic.to_string(), e))?;
                (Form::Json, &[])
            }
            (None, Payload::Bytes(b)) => (Form::Bytes, &b[..]),
            (None, Payload::Xml(x)) => (Form::Xml, x.as_bytes()),
            (None, Payload::Map(_)) => unreachable!("a map payload is a map"),
        };
        let key = ChannelKey {
            topic: msg.topic.clone(),
            form,
            kind: msg.kind,
            lcm_type: lcm_type.map(Arc::from),
        };
        let channel = self.channel(key, map.as_deref())?;
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: nanos(log_time),
            publish_time: nanos(msg.stamp),
        };
        channel.sequence = channel.sequence.wrapping_add(1);
        let data = if form == Form::Json {
            &self.scratch[..]
        } else {
            data
        };
        self.out.write_to_known_channel(&header, data)?;
        self.messages += 1;
        Ok(())
    }

    /// Closes the chunk under way and passes everything on to the file: a file cut short after
    /// this reads up to here.
    pub fn flush(&mut self) -> Result<(), WriteError> {
        Ok(self.out.flush()?)
    }

    /// Writes the summary, indexes and footer: the file is complete.
    pub fn finish(mut self) -> Result<(), WriteError> {
        self.out.finish()?;
        let mut out = self.out.into_inner();
        out.flush().map_err(mcap::McapError::from)?;
        Ok(())
    }

    /// How many messages were written.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// How many channels the file has.
    pub fn channels(&self) -> usize {
        self.channels.len()
    }
}

/// Nanoseconds since the Unix epoch of `s`; a stamp before the epoch is 0.
fn nanos(s: Stamp) -> u64 {
    u64::try_from(s.0).unwrap_or(0)
}

/// A channel of a file being read.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    /// Its id in the file.
    pub id: u16,
    /// Its topic, as the file names it.
    pub topic: String,
    /// Its message encoding (`json`, `application/octet-stream`, `cdr`, …).
    pub message_encoding: String,
    /// Its schema's name, empty when it has none.
    pub schema_name: String,
    /// Its schema's encoding, empty when it has none.
    pub schema_encoding: String,
    /// Its schema, empty when it has none.
    pub schema: Vec<u8>,
    /// Its metadata.
    pub metadata: BTreeMap<String, String>,
}

impl ChannelInfo {
    /// Whether seabus wrote it as a command channel.
    pub fn is_command(&self) -> bool {
        self.metadata.get(KIND_KEY).is_some_and(|k| k == "command")
    }

    /// The LCM type its messages were decoded from, when seabus said so ([`LCM_TYPE_KEY`]).
    pub fn lcm_type(&self) -> Option<&str> {
        self.metadata.get(LCM_TYPE_KEY).map(String::as_str)
    }
}

/// A message read from a file.
#[derive(Debug, Clone)]
pub struct ReadMessage {
    /// Its channel.
    pub channel: Arc<ChannelInfo>,
    /// Its sequence number on the channel.
    pub sequence: u32,
    /// When it was recorded, nanoseconds since the Unix epoch.
    pub log_time: u64,
    /// When it was published, nanoseconds since the Unix epoch.
    pub publish_time: u64,
    /// Its bytes, in the channel's encoding.
    pub data: Vec<u8>,
}

/// Where and why a file stops being readable. The messages before it were read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("byte {offset}: {problem}")]
pub struct Damage {
    /// The byte offset of the record that could not be read (0: the file's start).
    pub offset: u64,
    /// What is wrong there.
    pub problem: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Before the leading magic.
    Start,
    /// Between records.
    Records,
    /// After the footer: the closing magic comes next.
    EndMagic,
    /// After the closing magic.
    Done,
}

/// Reads an MCAP file message by message.
pub struct Reader<R: Read = io::BufReader<File>> {
    input: R,
    reader: LinearReader,
    phase: Phase,
    /// Where the record being fed starts.
    record_start: u64,
    /// The opcode of the record being fed.
    record_op: u8,
    /// Its whole length, header included.
    record_len: u64,
    /// How much of it is still to feed.
    remaining: u64,
    /// The walk through its records when it is a chunk.
    chunk: Option<ChunkWalk>,
    /// Bytes of the input read so far.
    offset: u64,
    size: Option<u64>,
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    /// The damage met: said again by every later call.
    damaged: Option<Damage>,
}

impl Reader<io::BufReader<File>> {
    /// Opens the file at `path`.
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        let file = File::open(path)?;
        let size = file.metadata()?.len();
        let mut r = Reader::new(io::BufReader::with_capacity(1 << 16, file));
        r.size = Some(size);
        Ok(r)
    }
}

/// The name of an MCAP record's opcode, for what a damage report says.
fn record_name(op: u8) -> &'static str {
    use mcap::records::op;
    match op {
        op::HEADER => "header",
        op::FOOTER => "footer",
        op::SCHEMA => "schema",
        op::CHANNEL => "channel",
        op::MESSAGE => "message",
        op::CHUNK => "chunk",
        op::MESSAGE_INDEX => "message index",
        op::CHUNK_INDEX => "chunk index",
        op::ATTACHMENT => "attachment",
        op::ATTACHMENT_INDEX => "attachment index",
        op::STATISTICS => "statistics",
        op::METADATA => "metadata",
        op::METADATA_INDEX => "metadata index",
        op::SUMMARY_OFFSET => "summary offset",
        op::DATA_END => "data end",
        _ => "unknown",
    }
}

impl<R: Read> Reader<R> {
    /// A reader of `input`.
    pub fn new(input: R) -> Self {
        let options = mcap::sans_io::linear_reader::LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            // a chunk is checked whole before any of its messages is given: none of a damaged
            // chunk's messages is ever replayed
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(MAX_RECORD as usize);
        Reader {
            input,
            reader: LinearReader::new_with_options(options),
            phase: Phase::Start,
            record_start: 0,
            record_op: 0,
            record_len: 0,
            remaining: 0,
            chunk: None,
            offset: 0,
            size: None,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            damaged: None,
        }
    }

    /// Bytes of the file read so far.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The file's size, when known.
    pub fn size(&self) -> Option<u64> {
        self.size
    }

    /// The channels met so far.
    pub fn channels(&self) -> impl Iterator<Item = &Arc<ChannelInfo>> {
        self.channels.values()
    }

    fn damage(&self, problem: impl Into<String>) -> Damage {
        Damage {
            offset: self.record_start,
            problem: problem.into(),
        }
    }

    /// Reads exactly `buf.len()` bytes, or as many as there are; how many.
    fn read_up_to(&mut self, buf: &mut [u8]) -> Result<usize, Damage> {
        let mut got = 0;
        while got < buf.len() {
            match self.input.read(&mut buf[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(Damage {
                        offset: self.offset + got as u64,
                        problem: format!("cannot read: {e}"),
                    });
                }
            }
        }
        self.offset += got as u64;
        Ok(got)
    }

    /// Hands the linear reader the next piece of the file: the rest of the record under way,
    /// or the next record's header. `Ok(false)` at the file's proper end.
    fn feed(&mut self) -> Result<bool, Damage> {
        if self.remaining == 0 {
            match self.phase {
                Phase::Start | Phase::EndMagic => {
                    self.record_start = self.offset;
                    self.record_op = 0;
                    let mut magic = [0u8; 8];
                    let got = self.read_up_to(&mut magic)?;
                    let what = if self.phase == Phase::Start {
                        "the file's opening magic"
                    } else {
                        "the file's closing magic"
                    };
                    if got < magic.len() {
                        return Err(self.damage(format!(
                            "the file ends inside {what} (cut short: {got} of 8 bytes)"
                        )));
                    }
                    if magic != *mcap::MAGIC {
                        return Err(self.damage(format!("{what} is wrong: not an MCAP file")));
                    }
                    self.reader.insert(8).copy_from_slice(&magic);
                    self.reader.notify_read(8);
                    self.phase = if self.phase == Phase::Start {
                        Phase::Records
                    } else {
                        Phase::Done
                    };
                    return Ok(true);
                }
                Phase::Done => return Ok(false),
                Phase::Records => {
                    self.record_start = self.offset;
                    let mut head = [0u8; 9];
                    let got = self.read_up_to(&mut head)?;
                    if got == 0 {
                        return Err(self.damage(
                            "the file ends without its footer (cut short: the messages before \
                             this were read)",
                        ));
                    }
                    if got < head.len() {
                        return Err(self.damage(format!(
                            "the file ends inside a record's header (cut short: {got} of 9 bytes)"
                        )));
                    }
                    self.record_op = head[0];
                    let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
                    if head[0] == mcap::records::op::CHUNK && len == u64::MAX {
                        // a writer gives a chunk its length when it closes it
                        return Err(self.damage(
                            "an unfinished chunk: the writer stopped before closing it (cut \
                             short: the messages before this chunk were read)",
                        ));
                    }
                    if len > MAX_RECORD {
                        return Err(self.damage(format!(
                            "a {} record of {len} bytes, longer than the {MAX_RECORD} read",
                            record_name(head[0])
                        )));
                    }
                    self.record_len = 9 + len;
                    self.remaining = len;
                    self.chunk = (head[0] == mcap::records::op::CHUNK).then(|| ChunkWalk::new(len));
                    if head[0] == mcap::records::op::FOOTER {
                        self.phase = Phase::EndMagic;
                    }
                    self.reader.insert(9).copy_from_slice(&head);
                    self.reader.notify_read(9);
                    return Ok(true);
                }
            }
        }
        let step = self.remaining.min(READ_STEP) as usize;
        let buf = self.reader.insert(step);
        let mut got = 0;
        while got < step {
            match self.input.read(&mut buf[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    self.reader.notify_read(got);
                    self.offset += got as u64;
                    return Err(Damage {
                        offset: self.offset,
                        problem: format!("cannot read: {e}"),
                    });
                }
            }
        }
        // a chunk's records are checked before the linear reader is given them
        if let Some(walk) = &mut self.chunk
            && let Err(problem) = walk.pass(&buf[..got])
        {
            self.offset += got as u64;
            return Err(self.damage(format!("a chunk record: {problem}")));
        }
        self.reader.notify_read(got);
        self.offset += got as u64;
        self.remaining -= got as u64;
        if got < step {
            return Err(self.damage(format!(
                "the file ends at byte {} inside a {} record of {} bytes (cut short: the \
                 messages before this record were read)",
                self.offset,
                record_name(self.record_op),
                self.record_len
            )));
        }
        Ok(true)
    }

    /// The next message, `Ok(None)` at the file's proper end. After damage, the same damage
    /// again: nothing past it is read.
    pub fn next_message(&mut self) -> Result<Option<ReadMessage>, Damage> {
        if let Some(d) = &self.damaged {
            return Err(d.clone());
        }
        let read = self.read_message();
        if let Err(d) = &read {
            self.damaged = Some(d.clone());
        }
        read
    }

    fn read_message(&mut self) -> Result<Option<ReadMessage>, Damage> {
        loop {
            let event = match self.reader.next_event() {
                None => return Ok(None),
                Some(Err(e)) => {
                    return Err(
                        self.damage(format!("the {} record: {e}", record_name(self.record_op)))
                    );
                }
                Some(Ok(event)) => event,
            };
            let (opcode, data) = match event {
                LinearReadEvent::ReadRequest(_) => {
                    if !self.feed()? {
                        return Ok(None);
                    }
                    continue;
                }
                LinearReadEvent::Record { opcode, data } => (opcode, data),
            };
            use mcap::records::op;
            // only the records that give messages are read; the others (indexes, statistics,
            // attachments, metadata) are passed over
            if ![op::SCHEMA, op::CHANNEL, op::MESSAGE].contains(&opcode) {
                continue;
            }
            if let Err(problem) = lengths_fit(opcode, data) {
                let problem = format!("a {} record: {problem}", record_name(opcode));
                return Err(self.damage(problem));
            }
            let record = match mcap::parse_record(opcode, data) {
                Ok(r) => r,
                Err(e) => {
                    let problem = format!("a {} record: {e}", record_name(opcode));
                    return Err(self.damage(problem));
                }
            };
            match record {
                Record::Schema { header, data } => {
                    self.schemas
                        .insert(header.id, (header.name, header.encoding, data.into_owned()));
                }
                Record::Channel(c) => {
                    let (schema_name, schema_encoding, schema) = match c.schema_id {
                        0 => Default::default(),
                        id => match self.schemas.get(&id) {
                            Some(s) => s.clone(),
                            None => {
                                return Err(self.damage(format!(
                                    "channel {} (`{}`) names schema {id}, which the file has not \
                                     given before it",
                                    c.id, c.topic
                                )));
                            }
                        },
                    };
                    let info = ChannelInfo {
                        id: c.id,
                        topic: c.topic,
                        message_encoding: c.message_encoding,
                        schema_name,
                        schema_encoding,
                        schema,
                        metadata: c.metadata,
                    };
                    self.channels.insert(c.id, Arc::new(info));
                }
                Record::Message { header, data } => {
                    let Some(channel) = self.channels.get(&header.channel_id) else {
                        return Err(self.damage(format!(
                            "a message on channel {}, which the file has not given before it",
                            header.channel_id
                        )));
                    };
                    return Ok(Some(ReadMessage {
                        channel: channel.clone(),
                        sequence: header.sequence,
                        log_time: header.log_time,
                        publish_time: header.publish_time,
                        data: data.into_owned(),
                    }));
                }
                _ => {}
            }
        }
    }
}

/// Checks that every length a schema or channel record gives for its strings, bytes and metadata
/// fits inside the record, before the `mcap` crate reads it: the crate sets aside room for a
/// string by its stated length, so a damaged length of gigabytes must not reach it.
fn lengths_fit(opcode: u8, data: &[u8]) -> Result<(), String> {
    use mcap::records::op;
    struct Fields<'a>(&'a [u8]);
    impl Fields<'_> {
        fn skip(&mut self, n: usize, what: &str) -> Result<(), String> {
            match self.0.get(n..) {
                Some(rest) => {
                    self.0 = rest;
                    Ok(())
                }
                None => Err(format!("it ends inside its {what}")),
            }
        }
        /// A u32 length and that many bytes.
        fn sized(&mut self, what: &str) -> Result<(), String> {
            let Some(head) = self.0.get(..4) else {
                return Err(format!("it ends inside its {what}'s length"));
            };
            let len = u32::from_le_bytes(head.try_into().expect("4 bytes")) as usize;
            self.0 = &self.0[4..];
            if len > self.0.len() {
                return Err(format!(
                    "its {what} of {len} bytes is longer than the {} bytes left in it",
                    self.0.len()
                ));
            }
            self.0 = &self.0[len..];
            Ok(())
        }
    }
    let mut f = Fields(data);
    match opcode {
        op::SCHEMA => {
            f.skip(2, "schema id")?;
            f.sized("name")?;
            f.sized("encoding")?;
            f.sized("data")
        }
        op::CHANNEL => {
            f.skip(4, "channel and schema ids")?;
            f.sized("topic")?;
            f.sized("message encoding")?;
            let Some(head) = f.0.get(..4) else {
                return Err("it ends inside its metadata's length".into());
            };
            let len = u32::from_le_bytes(head.try_into().expect("4 bytes")) as usize;
            let rest = &f.0[4..];
            let Some(map) = rest.get(..len) else {
                return Err(format!(
                    "its metadata of {len} bytes is longer than the {} bytes left in it",
                    rest.len()
                ));
            };
            let mut m = Fields(map);
            while !m.0.is_empty() {
                m.sized("metadata key")?;
                m.sized("metadata value")?;
            }
            Ok(())
        }
        _ => Ok(()),
    }
}

/// The bytes of a chunk record's body up to its records when it is uncompressed: times,
/// uncompressed size and CRC, the compression's name (empty: 4 bytes of length 0) and the records'
/// size.
const CHUNK_HEAD: usize = 40;
/// The header of a record inside a chunk: its opcode and length.
const RECORD_HEAD: usize = 9;

/// Walks the records of an uncompressed chunk as the chunk is fed to the linear reader, a piece at
/// a time, and finds a record that does not fit in them: the `mcap` crate takes the length of a
/// record inside an uncompressed chunk on trust, reads on past the chunk's end and miscounts what
/// is left of it (a subtraction that overflows). A compressed chunk is not walked: the crate stops
/// its records at the size they decompress to.
struct ChunkWalk {
    /// The length of the chunk's body.
    len: u64,
    /// The header being gathered: the chunk's own, then each record's.
    head: [u8; CHUNK_HEAD],
    /// How much of it is gathered.
    have: usize,
    /// The size of the chunk's records.
    records: u64,
    /// How far into them the walk is.
    pos: u64,
    at: Walk,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Walk {
    /// In the chunk's header.
    ChunkHead,
    /// In a record's header.
    RecordHead,
    /// In a record's body, with this many bytes of it to come.
    Body(u64),
    /// Past the records (the padding after them), or in a compressed chunk: nothing to check.
    Done,
}

impl ChunkWalk {
    /// A walk through a chunk whose body is `len` bytes long.
    fn new(len: u64) -> Self {
        ChunkWalk {
            len,
            head: [0; CHUNK_HEAD],
            have: 0,
            records: 0,
            pos: 0,
            at: Walk::ChunkHead,
        }
    }

    /// Walks through `piece`, the next bytes of the chunk's body.
    fn pass(&mut self, mut piece: &[u8]) -> Result<(), String> {
        while !piece.is_empty() {
            match self.at {
                Walk::Done => break,
                Walk::ChunkHead => {
                    if !self.gather(CHUNK_HEAD, &mut piece) {
                        continue;
                    }
                    let compression =
                        u32::from_le_bytes(self.head[28..32].try_into().expect("4 bytes"));
                    if compression != 0 {
                        self.at = Walk::Done;
                        continue;
                    }
                    let records =
                        u64::from_le_bytes(self.head[32..40].try_into().expect("8 bytes"));
                    let room = self.len.saturating_sub(CHUNK_HEAD as u64);
                    if records > room {
                        return Err(format!(
                            "its records of {records} bytes are longer than the {room} bytes left \
                             in it"
                        ));
                    }
                    self.records = records;
                    self.next_record()?;
                }
                Walk::RecordHead => {
                    if !self.gather(RECORD_HEAD, &mut piece) {
                        continue;
                    }
                    let opcode = self.head[0];
                    let len = u64::from_le_bytes(self.head[1..9].try_into().expect("8 bytes"));
                    let left = self.records - self.pos - RECORD_HEAD as u64;
                    if len > left {
                        return Err(format!(
                            "the {} record at byte {} of its records is {len} bytes long, longer \
                             than the {left} bytes left in them",
                            record_name(opcode),
                            self.pos
                        ));
                    }
                    self.pos += RECORD_HEAD as u64;
                    self.body(len)?;
                }
                Walk::Body(to_come) => {
                    let n = to_come.min(piece.len() as u64);
                    piece = &piece[n as usize..];
                    self.pos += n;
                    self.body(to_come - n)?;
                }
            }
        }
        Ok(())
    }

    /// Adds the first bytes of `piece` to the header being gathered, up to `want` of it: whether
    /// it is whole (in `head`).
    fn gather(&mut self, want: usize, piece: &mut &[u8]) -> bool {
        let n = (want - self.have).min(piece.len());
        self.head[self.have..self.have + n].copy_from_slice(&piece[..n]);
        self.have += n;
        *piece = &piece[n..];
        if self.have < want {
            return false;
        }
        self.have = 0;
        true
    }

    /// In a record's body with `to_come` bytes of it still to come.
    fn body(&mut self, to_come: u64) -> Result<(), String> {
        if to_come > 0 {
            self.at = Walk::Body(to_come);
            return Ok(());
        }
        self.next_record()
    }

    /// At the start of a record, or past the last.
    fn next_record(&mut self) -> Result<(), String> {
        let left = self.records - self.pos;
        if left == 0 {
            self.at = Walk::Done;
        } else if left < RECORD_HEAD as u64 {
            return Err(format!(
                "its records end inside the header of the record at byte {} of them ({left} of \
                 9 bytes)",
                self.pos
            ));
        } else {
            self.at = Walk::RecordHead;
        }
        Ok(())
    }
}

/// Why a read message has no seabus payload.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PayloadError {
    /// A `json` message that is not a JSON object in seabus's JSON form.
    #[error("not a JSON object seabus reads: {0}")]
    Json(String),
    /// An `xml` message that is not UTF-8 text.
    #[error("XML that is not UTF-8 text")]
    Xml,
}

/// The seabus payload of `m`: a `json` message as a datamap, an `xml` one as XML text, any other
/// encoding as its bytes.
pub fn payload_of(m: &ReadMessage) -> Result<Payload, PayloadError> {
    match m.channel.message_encoding.as_str() {
        JSON => {
            let text =
                std::str::from_utf8(&m.data).map_err(|e| PayloadError::Json(e.to_string()))?;
            let map = schema::read_message(text).map_err(|e| PayloadError::Json(e.to_string()))?;
            Ok(Payload::from(map))
        }
        XML => {
            let text = std::str::from_utf8(&m.data).map_err(|_| PayloadError::Xml)?;
            Ok(Payload::Xml(Arc::from(text)))
        }
        _ => Ok(Payload::from(m.data.clone())),
    }
}

#[cfg(test)]
mod tests;
