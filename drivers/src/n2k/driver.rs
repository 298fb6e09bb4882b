//! `nmea2000`: an NMEA 2000 network on a CAN medium, its PGNs on the bus.
//!
//! ```xml
//! <medium name="n2k" url="slcan:///dev/ttyACM0?bitrate=250000"/>
//! <module name="nmea2000" type="nmea2000" media="n2k bus"/>
//! ```
//!
//! Its first medium is the CAN medium, its second the bus. Every frame is read: its 29-bit
//! identifier gives the priority, PGN, source and destination; fast-packet and transport-protocol
//! messages are reassembled ([`super::frame`]); each whole message is decoded with the PGN
//! database ([`super::pgn`]) and published on the bus as `PREFIX.SOURCE.ID` — `n2k.35.vesselHeading`
//! — a datamap of its fields by canboat's identifiers, in seabus's units, with `header` (a map of
//! `pgn`, `src`, `dst`, `prio`). A PGN the database does not know is published on
//! `PREFIX.SOURCE.PGN` (`n2k.35.65280`) with its bytes as `data`. The navigation PGNs also become
//! the standard datasets ([`super::nav`]).
//!
//! Parameters:
//!
//! | parameter | default | meaning |
//! |---|---|---|
//! | `database` | none | canboat's `canboat.json`, relative to the system file: its definitions replace the built-in ones of the PGNs it has, and add the others |
//! | `prefix` | `n2k` | the first segment of the PGN topics |
//! | `sources` | any | the source addresses whose PGNs feed the datasets (space or comma separated); every source's PGNs are published on the PGN topics |
//! | `variation` | none | degrees east, for magnetic headings that come without one |
//! | `fresh` | `2s` | how long a true heading stands in for an attitude's missing yaw |
//! | `battery_instance` | 0 | the battery instance the `battery` dataset is of |
//! | `timeout` | `750ms` | a fast-packet or transport message is dropped when none of its frames comes for this long |
//! | `max_partial` | 128 | most messages under way at once |
//! | `heading_topic`, `attitude_topic`, `rate_topic`, `position_topic`, `velocity_topic`, `altitude_topic`, `wind_topic`, `battery_topic`, `time_topic` | the datasets' topics | where each dataset is published |
//!
//! What cannot be read is counted on the CAN medium by reason (what `seabus spy --stats` shows),
//! and logged at most once per reason every 10 s: the frame and reassembly reasons of
//! [`super::frame`], `n2k-short` (a message shorter than its PGN's definition: the fields it lacks
//! are left out) and `n2k-out-of-range` (a dataset value outside the dataset's range: the dataset
//! is not published).

use super::claim::{self, Claimer, Name};
use super::encode::EncodeError;
use super::frame::{Assembler, GLOBAL, Header, Limits, Message, fast_frames};
use super::nav::{self, Navigator};
use super::pgn::{Database, Packet, PgnDef};
use super::{builtin, json};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Format, Ingress, Key, Kind, Message as BusMessage, Topic, Value};
use seabus_medium_can::frame::{CanFrame, FrameKind};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::time::Duration;
use tokio::time::Instant;

/// The `nmea2000` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "nmea2000",
    kind: ModuleKind::Driver,
    summary: "an NMEA 2000 network on a CAN medium: every PGN as a topic, navigation PGNs as standard datasets",
    build,
};

/// The timer that drops messages whose frames stopped coming.
const SWEEP: TimerId = 1;
/// Its period.
const SWEEP_EVERY: Duration = Duration::from_millis(250);
/// The timer that publishes the address claim's status.
const STATUS: TimerId = 2;
/// Its period.
const STATUS_EVERY: Duration = Duration::from_secs(5);

/// The `nmea2000` driver.
pub struct Nmea2000 {
    db: Arc<Database>,
    prefix: String,
    sources: Option<Vec<u8>>,
    assembler: Assembler,
    nav: Navigator,
    /// each output's dataset and topic, in [`nav::OUTPUTS`] order
    outputs: Vec<(&'static str, Topic)>,
    /// topics made, by (source, PGN, definition)
    topics: HashMap<(u8, u32, usize), Topic>,
    catalogue: Arc<Catalogue>,
    ingress: Option<Ingress>,
    tally: Tally,
    /// sending: the address claim, when an address is configured
    sender: Option<Sender>,
}

/// What sending needs: the address claim, the topics sent as PGNs, the fast-packet sequences.
struct Sender {
    name: Name,
    preferred: u8,
    claimer: Option<Claimer>,
    /// `PREFIX.out.`
    out_prefix: String,
    /// topic → the PGN its data is sent as (`send`)
    sends: Vec<(String, Arc<PgnDef>)>,
    /// the next fast-packet sequence number of each PGN
    seq: HashMap<u32, u8>,
    status_topic: Topic,
    /// messages sent
    sent: u64,
    /// messages refused, by reason
    refused: BTreeMap<&'static str, u64>,
    /// the state last published
    shown: Option<(&'static str, u8)>,
}

/// The PGN a `send` entry or an `out` topic names: its number or canboat's identifier.
fn named_pgn(db: &Database, word: &str) -> Option<Arc<PgnDef>> {
    match word.parse::<u32>() {
        Ok(n) => db.definitions(n).first().cloned(),
        Err(_) => db.iter().find(|d| d.id == word).cloned(),
    }
}

/// A standard dataset's fields as the fields of the PGN it is sent as (keys the PGN does not
/// have are left out: a dataset carries more than a PGN holds).
fn from_dataset(def: &PgnDef, map: &DataMap) -> DataMap {
    let mut out = DataMap::with_capacity(map.len());
    for (k, v) in map.iter() {
        let (key, value) = match (def.pgn, k) {
            (127250, "magnetic") => (
                "reference",
                Value::from(if v.as_bool() == Some(true) {
                    "Magnetic"
                } else {
                    "True"
                }),
            ),
            (129025, "lat") => ("latitude", v.clone()),
            (129025, "lon") => ("longitude", v.clone()),
            (129026, "speed") => ("sog", v.clone()),
            (129026, "course") => ("cog", v.clone()),
            (128267, "altitude") => ("depth", v.clone()),
            _ => (k, v.clone()),
        };
        if key == "header" || def.fields.iter().any(|f| f.id == key) {
            out.insert(key.to_string(), value);
        }
    }
    if def.pgn == 129026 && out.get("cog").is_some() && out.get("cogReference").is_none() {
        out.insert("cogReference", Value::from("True"));
    }
    out
}

fn build(cfg: &ModuleConfig, cat: &Catalogue) -> Result<Built, FileError> {
    if cfg.media.len() != 2 {
        return Err(cfg.pos.error(
            "an nmea2000 driver is on two media: the CAN medium, then the bus (media=\"n2k bus\")",
        ));
    }
    let (driver, decl) = Nmea2000::new(&cfg.params, cat)?;
    Ok(Built {
        decl,
        module: Box::new(driver),
    })
}

impl Nmea2000 {
    /// A driver from its parameters, with its declaration.
    pub fn new(
        p: &seabus_modules::Params,
        cat: &Catalogue,
    ) -> Result<(Nmea2000, Declaration), FileError> {
        let built_in = builtin::database();
        let db = match p.get("database") {
            None => built_in,
            Some(param) => {
                let path = seabus_modules::system::beside(&param.pos, &param.value);
                if !path.exists() {
                    return Err(param.error(format!("`{}` does not exist", path.display())));
                }
                let mut db = json::load(&path)?;
                db.fill_from(&built_in);
                db
            }
        };
        let prefix = p.str("prefix").unwrap_or("n2k").trim().to_string();
        Topic::new(&format!("{prefix}.0.x"))
            .map_err(|e| p.get("prefix").map_or_else(|| p.error(&e), |a| a.error(&e)))?;
        let sources = match p.get("sources") {
            None => None,
            Some(param) => Some(
                param
                    .value
                    .split([' ', ','])
                    .filter(|w| !w.is_empty())
                    .map(|w| {
                        w.parse::<u8>().ok().filter(|a| *a < 254).ok_or_else(|| {
                            param.error(format!("`{w}` is not a source address (0 to 253)"))
                        })
                    })
                    .collect::<Result<Vec<u8>, _>>()?,
            ),
        };
        let limits = Limits {
            timeout: p.duration_or("timeout", Limits::default().timeout)?,
            max_partial: p
                .parse::<usize>("max_partial", "a number of messages")?
                .unwrap_or(Limits::default().max_partial),
        };
        if limits.max_partial == 0 {
            return Err(p
                .get("max_partial")
                .map_or_else(|| p.error("max_partial"), |a| a.error("must be 1 or more")));
        }
        let nav = Navigator::new(
            p.parse("variation", "degrees east")?,
            p.duration_or("fresh", Duration::from_secs(2))?,
            p.parse("battery_instance", "a battery instance (0 to 252)")?
                .unwrap_or(0),
        );
        let mut outputs = Vec::new();
        for (dataset, param, topic) in nav::OUTPUTS {
            outputs.push((dataset, p.dataset_topic_or(param, cat, dataset, topic)?));
        }
        let mut decl = Declaration::new(ModuleKind::Driver)
            .format(0, Some(Format::Map))
            .consumes(TopicDecl::topic("can.**"))
            .format(1, Some(Format::Map));
        for (dataset, topic) in &outputs {
            decl = decl.produces(TopicDecl::dataset(topic, dataset).on_port(1));
        }
        let sender = Self::sender(p, &db, &prefix, &outputs)?;
        if let Some(s) = &sender {
            decl = decl
                .consumes(TopicDecl::topic(format!("{}*", s.out_prefix)).on_port(1))
                .produces(
                    TopicDecl::topic(s.status_topic.as_str())
                        .field("address", "")
                        .field("state", "")
                        .field("name", "")
                        .on_port(1),
                )
                .produces(TopicDecl::topic("can.*"));
            for (topic, _) in &s.sends {
                decl = decl.consumes(TopicDecl::topic(topic).on_port(1));
            }
        } else if let Some(param) = p.get("send") {
            return Err(param.error("sending needs an `address` to claim"));
        }
        let mut declared = std::collections::HashSet::new();
        for d in db.iter() {
            if !declared.insert(d.id.clone()) {
                continue;
            }
            let mut t = TopicDecl::topic(format!("{prefix}.*.{}", d.id)).field("header", "");
            for f in d
                .fields
                .iter()
                .filter(|f| !matches!(f.kind, super::pgn::Kind::Reserved | super::pgn::Kind::Spare))
            {
                t = t.field(&f.id, f.seabus_unit());
            }
            decl = decl.produces(t.on_port(1));
        }
        Ok((
            Nmea2000 {
                db: Arc::new(db),
                prefix,
                sources,
                assembler: Assembler::new(limits),
                nav,
                outputs,
                topics: HashMap::new(),
                catalogue: Arc::new(cat.clone()),
                ingress: None,
                tally: Tally::new(),
                sender,
            },
            decl,
        ))
    }

    /// The sending side, when `address` is given: the NAME, the `send` topics.
    fn sender(
        p: &seabus_modules::Params,
        db: &Database,
        prefix: &str,
        outputs: &[(&'static str, Topic)],
    ) -> Result<Option<Sender>, FileError> {
        let Some(address) = p.get("address") else {
            return Ok(None);
        };
        let preferred = address
            .value
            .trim()
            .parse::<u8>()
            .ok()
            .filter(|a| *a <= claim::MAX_ADDRESS)
            .ok_or_else(|| {
                address.error(format!("`{}` is not an address (0 to 251)", address.value))
            })?;
        let ranged = |name: &str, max: u32, default: u32, what: &str| -> Result<u32, FileError> {
            match p.get(name) {
                None => Ok(default),
                Some(a) => a
                    .value
                    .trim()
                    .parse::<u32>()
                    .ok()
                    .filter(|v| *v <= max)
                    .ok_or_else(|| a.error(format!("`{}` is not {what} (0 to {max})", a.value))),
            }
        };
        let name = Name {
            unique_number: ranged("unique_number", 0x1F_FFFF, 0, "a unique number")?,
            manufacturer_code: ranged("manufacturer_code", 2047, 2046, "a manufacturer code")?
                as u16,
            device_instance: ranged("device_instance", 255, 0, "a device instance")? as u8,
            device_function: ranged("device_function", 255, 130, "a device function")? as u8,
            device_class: ranged("device_class", 127, 25, "a device class")? as u8,
            system_instance: ranged("system_instance", 15, 0, "a system instance")? as u8,
            industry_group: ranged("industry_group", 7, 4, "an industry group")? as u8,
            arbitrary_address_capable: p.flag_or("arbitrary_address", true)?,
        };
        if p.get("unique_number").is_none() {
            return Err(address.error(
                "a device that claims an address needs its `unique_number` (0 to 2097151), \
                 different from every other device of its manufacturer code on the network",
            ));
        }
        let mut sends = Vec::new();
        if let Some(param) = p.get("send") {
            for word in param.value.split([' ', ',']).filter(|w| !w.is_empty()) {
                let Some((topic, pgn)) = word.split_once('=') else {
                    return Err(param.error(format!(
                        "`{word}` is not TOPIC=PGN (`nav.heading=vesselHeading`)"
                    )));
                };
                Topic::new(topic).map_err(|e| param.error(format!("`{topic}`: {e}")))?;
                let def = named_pgn(db, pgn).ok_or_else(|| {
                    param.error(format!(
                        "`{pgn}` is no PGN of the database ({}): a number or canboat's identifier",
                        db.source
                    ))
                })?;
                if let Some((dataset, _)) = outputs.iter().find(|(_, t)| t.as_str() == topic) {
                    return Err(param.error(format!(
                        "`{topic}` is where this driver publishes the {dataset} dataset it reads \
                         from the network: sending it back would loop (publish it on another topic)"
                    )));
                }
                if topic.starts_with(&format!("{prefix}.")) {
                    return Err(param.error(format!(
                        "`{topic}` is under `{prefix}.`, where this driver publishes the PGNs it \
                         reads: publish on `{prefix}.out.ID` to send a PGN"
                    )));
                }
                if def.packet == Packet::Iso {
                    return Err(param.error(format!(
                        "PGN {} travels by the ISO transport protocol, which this driver does \
                         not send",
                        def.pgn
                    )));
                }
                sends.push((topic.to_string(), def));
            }
        }
        let status_topic = Topic::new(&format!("{prefix}.status"))
            .map_err(|e| p.get("prefix").map_or_else(|| p.error(&e), |a| a.error(&e)))?;
        Ok(Some(Sender {
            name,
            preferred,
            claimer: None,
            out_prefix: format!("{prefix}.out."),
            sends,
            seq: HashMap::new(),
            status_topic,
            sent: 0,
            refused: BTreeMap::new(),
            shown: None,
        }))
    }

    /// The address this driver sends from, once claimed and its wait is over.
    pub fn source(&mut self, now: Instant) -> Option<u8> {
        self.sender
            .as_mut()?
            .claimer
            .as_mut()
            .and_then(|c| c.source(now))
    }

    /// Starts the address claim: the frames to send.
    pub fn start_claim(&mut self, now: Instant) -> Vec<CanFrame> {
        let Some(s) = self.sender.as_mut() else {
            return Vec::new();
        };
        let mut c = Claimer::new(s.name, s.preferred, now);
        let out = c.start(now);
        s.claimer = Some(c);
        out.into_iter()
            .filter_map(|(h, d)| CanFrame::data(h.id(), true, &d).ok())
            .collect()
    }

    /// Counts (and logs, rate-limited) a message that was not sent.
    fn refuse_send(&mut self, reason: &'static str, detail: impl std::fmt::Display) {
        if let Some(s) = self.sender.as_mut() {
            *s.refused.entry(reason).or_default() += 1;
        }
        self.tally.record("nmea2000", reason, detail);
    }

    /// The frames of bus message `topic`/`map` sent as a PGN: for `PREFIX.out.ID` topics the
    /// datamap is the PGN's fields (a key that is not one is refused); for the `send` topics a
    /// standard dataset or the PGN's fields. Nothing (counted) before an address is held, and
    /// for a datamap the PGN cannot hold.
    pub fn outgoing(&mut self, topic: &str, map: &DataMap, now: Instant) -> Vec<CanFrame> {
        let Some(s) = self.sender.as_ref() else {
            return Vec::new();
        };
        let (def, map) = if let Some(id) = topic.strip_prefix(&s.out_prefix) {
            match named_pgn(&self.db, id) {
                Some(d) => (d, map.clone()),
                None => {
                    self.refuse_send(
                        "n2k-send-unknown-pgn",
                        format_args!("topic `{topic}`: `{id}` is no PGN of the database"),
                    );
                    return Vec::new();
                }
            }
        } else if let Some((_, d)) = s.sends.iter().find(|(t, _)| t == topic) {
            let d = d.clone();
            let m = from_dataset(&d, map);
            (d, m)
        } else {
            return Vec::new();
        };
        let Some(source) = self.source(now) else {
            self.refuse_send(
                "n2k-send-no-address",
                format_args!(
                    "topic `{topic}`: PGN {} not sent: no address claimed yet",
                    def.pgn
                ),
            );
            return Vec::new();
        };
        match self.frames(&def, &map, source) {
            Ok(frames) => {
                if let Some(s) = self.sender.as_mut() {
                    s.sent += 1;
                }
                frames
            }
            Err(e) => {
                self.refuse_send(e.reason, format_args!("topic `{topic}`: {e}"));
                Vec::new()
            }
        }
    }

    /// The frames of `map` as `def` from `source`.
    fn frames(
        &mut self,
        def: &PgnDef,
        map: &DataMap,
        source: u8,
    ) -> Result<Vec<CanFrame>, EncodeError> {
        let data = def.encode(map)?;
        let header = map.get("header").and_then(Value::as_map);
        let number = |key: &str, max: i64| {
            header
                .and_then(|h| h.get_i64(key))
                .filter(|v| (0..=max).contains(v))
        };
        let h = Header {
            priority: number("prio", 7).map_or(def.priority.unwrap_or(6), |v| v as u8),
            pgn: def.pgn,
            source,
            destination: number("dst", 255).map_or(GLOBAL, |v| v as u8),
        };
        let chunks = match def.packet {
            Packet::Single => vec![data],
            Packet::Fast => {
                let s = self
                    .sender
                    .as_mut()
                    .map(|s| s.seq.entry(def.pgn).or_insert(0));
                let seq = s.map_or(0, |n| {
                    let v = *n;
                    *n = (v + 1) & 7;
                    v
                });
                fast_frames(seq, &data)
            }
            Packet::Iso => {
                return Err(EncodeError {
                    reason: "n2k-send-iso",
                    detail: format!(
                        "PGN {} travels by the ISO transport protocol, which this driver does not send",
                        def.pgn
                    ),
                });
            }
        };
        Ok(chunks
            .iter()
            .filter_map(|c| CanFrame::data(h.id(), true, c).ok())
            .collect())
    }

    /// The status of the address claim (`PREFIX.status`), when it changed or `always`.
    fn status(&mut self, now: Instant, always: bool) -> Option<(Topic, DataMap)> {
        let s = self.sender.as_mut()?;
        let c = s.claimer.as_mut()?;
        c.poll(now);
        let key = (c.state().name(), c.address());
        if !always && s.shown == Some(key) {
            return None;
        }
        s.shown = Some(key);
        let devices: DataMap = c
            .devices()
            .iter()
            .map(|(a, n)| (Key::Owned(a.to_string()), Value::from(format!("{n:016x}"))))
            .collect::<Vec<_>>()
            .into_iter()
            .fold(DataMap::new(), |m, (k, v)| m.and(k, v));
        let refused = s
            .refused
            .iter()
            .fold(DataMap::new(), |m, (k, v)| m.and(*k, Value::Int(*v as i64)));
        let map = DataMap::new()
            .and("address", Value::Int(i64::from(c.address())))
            .and("preferred", Value::Int(i64::from(s.preferred)))
            .and("state", Value::label(c.state().name()))
            .and("name", Value::from(format!("{:016x}", c.name())))
            .and("devices", Value::Map(devices))
            .and("sent", Value::Int(s.sent as i64))
            .and("refused", Value::Map(refused));
        Some((s.status_topic.clone(), map))
    }

    /// Takes a whole message for the address claim: the frames to answer with.
    fn claim_take(&mut self, msg: &Message, now: Instant) -> Vec<CanFrame> {
        let Some(c) = self.sender.as_mut().and_then(|s| s.claimer.as_mut()) else {
            return Vec::new();
        };
        let out = c.take(msg, now);
        let events = c.take_events();
        // logged at most once a kind every 10 s: a device that keeps claiming our address
        // cannot flood the log
        for e in events {
            let (reason, text) = match e {
                claim::Event::Defended { address, other } => (
                    "n2k-address-defended",
                    format!(
                        "address {address}: claimed by NAME {other:016x} too; ours is lower, kept"
                    ),
                ),
                claim::Event::Moved { from, to, other } => (
                    "n2k-address-moved",
                    format!(
                        "address {from} lost to NAME {other:016x} (lower than ours): claiming {to}"
                    ),
                ),
                claim::Event::Lost { from, other } => (
                    "n2k-address-lost",
                    format!(
                        "address {from} lost to NAME {other:016x} (lower than ours), and no other \
                         can be claimed: sending nothing"
                    ),
                ),
            };
            self.tally.record("nmea2000", reason, text);
        }
        out.into_iter()
            .filter_map(|(h, d)| CanFrame::data(h.id(), true, &d).ok())
            .collect()
    }

    /// The assembler's counts of what it refused, by reason.
    pub fn counts(&self) -> &std::collections::BTreeMap<&'static str, u64> {
        self.assembler.counts()
    }

    /// Counts (and logs, rate-limited) what was refused, on the CAN medium when there is one.
    fn refuse(&self, reason: &str, detail: impl std::fmt::Display) {
        match &self.ingress {
            Some(i) => i.reject(reason, detail),
            None => {
                self.tally.record("nmea2000", reason, detail);
            }
        }
    }

    fn report(&mut self) {
        for r in self.assembler.take_rejections() {
            self.refuse(r.reason, &r.detail);
        }
    }

    /// The topic of a message of `pgn` from `source`, decoded with `def`.
    fn topic(&mut self, source: u8, pgn: u32, def: Option<&Arc<PgnDef>>) -> Option<Topic> {
        let key = (source, pgn, def.map_or(0, |d| Arc::as_ptr(d) as usize));
        if let Some(t) = self.topics.get(&key) {
            return Some(t.clone());
        }
        if self.topics.len() > 8192 {
            self.topics.clear();
        }
        let name = match def {
            Some(d) => format!("{}.{source}.{}", self.prefix, d.id),
            None => format!("{}.{source}.{pgn}", self.prefix),
        };
        let t = Topic::new(&name).ok()?;
        self.topics.insert(key, t.clone());
        Some(t)
    }

    /// What a whole message gives: its PGN topic and datamap, and the datasets it makes (each
    /// already checked against its dataset).
    pub fn read(&mut self, msg: &Message, now: Instant) -> Vec<(Topic, &'static str, DataMap)> {
        let h = msg.header;
        let header = DataMap::new()
            .and("pgn", Value::Int(i64::from(h.pgn)))
            .and("src", Value::Int(i64::from(h.source)))
            .and("dst", Value::Int(i64::from(h.destination)))
            .and("prio", Value::Int(i64::from(h.priority)));
        let db = self.db.clone();
        let def = db.select(h.pgn, &msg.data);
        let fields = match def {
            Some(d) => {
                let decoded = d.decode(&msg.data);
                if decoded.short {
                    self.refuse(
                        "n2k-short",
                        format_args!(
                            "PGN {} ({}) from {}: {} bytes lack fields of its definition",
                            h.pgn,
                            d.id,
                            h.source,
                            msg.data.len()
                        ),
                    );
                }
                decoded.map
            }
            None => DataMap::new().and("data", Value::Bytes(msg.data.clone())),
        };
        let mut datasets = Vec::new();
        if def.is_some() && self.sources.as_ref().is_none_or(|s| s.contains(&h.source)) {
            for (i, dataset) in self.nav.read(h.pgn, &fields, now) {
                let (name, topic) = &self.outputs[i];
                match self.catalogue.validate(name, &dataset) {
                    Ok(()) => datasets.push((topic.clone(), *name, dataset)),
                    Err(e) => self.refuse(
                        "n2k-out-of-range",
                        format_args!("PGN {} from {}: {e}", h.pgn, h.source),
                    ),
                }
            }
        }
        let mut out = Vec::with_capacity(1 + datasets.len());
        if let Some(topic) = self.topic(h.source, h.pgn, def) {
            let mut entries = Vec::with_capacity(fields.len() + 1);
            entries.push((Key::Borrowed("header"), Value::Map(header)));
            entries.extend(fields.into_entries());
            out.push((topic, "", DataMap::from_entries(entries)));
        }
        out.extend(datasets);
        out
    }

    /// What one CAN frame gives: nothing until it completes a message, then its PGN topic (with
    /// an empty dataset name) and datamap, and the datasets it makes.
    pub fn take(&mut self, frame: &CanFrame, now: Instant) -> Vec<(Topic, &'static str, DataMap)> {
        match self.assemble(frame, now) {
            Some(m) => self.read(&m, now),
            None => Vec::new(),
        }
    }

    /// The whole message one CAN frame completes, if any.
    pub fn assemble(&mut self, frame: &CanFrame, now: Instant) -> Option<Message> {
        if frame.kind() == FrameKind::Error {
            return None;
        }
        let db = self.db.clone();
        let whole = self.assembler.push(
            frame.id(),
            frame.is_extended(),
            matches!(frame.kind(), FrameKind::Remote { .. }),
            frame.payload(),
            |pgn| db.packet(pgn),
            now,
        );
        self.report();
        whole
    }

    /// Sends CAN frames on the CAN medium.
    async fn transmit(&mut self, ctx: &mut Context, frames: Vec<CanFrame>) {
        for f in frames {
            let map = DataMap::new().and("data", Value::Bytes(f.payload().to_vec()));
            if let Err(e) = ctx
                .publish_on(0, Kind::Data, format!("can.{:08x}", f.id()), map)
                .await
            {
                self.refuse_send("n2k-send-failed", &e);
            }
        }
    }

    /// Publishes the claim's status when it changed (or `always`).
    async fn show_status(&mut self, ctx: &mut Context, always: bool) {
        if let Some((topic, map)) = self.status(Instant::now(), always)
            && let Err(e) = ctx.publish_on(1, Kind::Data, topic, map).await
        {
            self.tally.record(ctx.name(), "not-published", &e);
        }
    }

    async fn on_frame(&mut self, ctx: &mut Context, msg: &BusMessage) -> Result<(), ModuleError> {
        let Ok(frame) = CanFrame::from_message(msg.topic.as_str(), &msg.payload) else {
            return Ok(());
        };
        let now = Instant::now();
        let Some(whole) = self.assemble(&frame, now) else {
            return Ok(());
        };
        if matches!(whole.header.pgn, claim::ADDRESS_CLAIM | claim::REQUEST) {
            let answer = self.claim_take(&whole, now);
            self.transmit(ctx, answer).await;
            self.show_status(ctx, false).await;
        }
        for (topic, dataset, map) in self.read(&whole, now) {
            let sent = if dataset.is_empty() {
                ctx.publish_on(1, Kind::Data, topic, map).await
            } else {
                ctx.dataset_on(1, Kind::Data, dataset, topic, map).await
            };
            if let Err(e) = sent {
                self.tally.record(ctx.name(), "not-published", &e);
            }
        }
        Ok(())
    }
}

#[async_trait]
impl Module for Nmea2000 {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        self.ingress = ctx.port(0).map(|p| p.medium().ingress());
        ctx.every(SWEEP, SWEEP_EVERY);
        if self.sender.is_some() {
            let frames = self.start_claim(Instant::now());
            self.transmit(ctx, frames).await;
            self.show_status(ctx, true).await;
            ctx.every(STATUS, STATUS_EVERY);
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: BusMessage,
    ) -> Result<(), ModuleError> {
        if port == 0 {
            self.on_frame(ctx, &msg).await
        } else {
            let Some(map) = msg.payload.as_map() else {
                self.refuse_send(
                    "n2k-send-bad-value",
                    format_args!("topic `{}`: not a datamap", msg.topic),
                );
                return Ok(());
            };
            let frames = self.outgoing(msg.topic.as_str(), map, Instant::now());
            self.transmit(ctx, frames).await;
            self.show_status(ctx, false).await;
            Ok(())
        }
    }

    async fn on_timer(&mut self, _ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        if timer == SWEEP {
            self.assembler.expire(Instant::now());
            self.report();
            self.show_status(_ctx, false).await;
        } else if timer == STATUS {
            self.show_status(_ctx, true).await;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::frame::{Header, fast_frames};
    use super::*;
    use seabus_modules::Params;

    fn driver(pairs: &[(&str, &str)]) -> Nmea2000 {
        let params = Params::from_pairs(pairs);
        let (d, _) = Nmea2000::new(&params, &Catalogue::built_in()).unwrap();
        params.finish("nmea2000").unwrap();
        d
    }

    fn id(pgn: u32, src: u8) -> u32 {
        Header {
            priority: 2,
            pgn,
            source: src,
            destination: 255,
        }
        .id()
    }

    /// What the frames of `data` (fast-packet frames when longer than 8 bytes) give.
    fn send(
        d: &mut Nmea2000,
        pgn: u32,
        src: u8,
        data: &[u8],
        now: Instant,
    ) -> Vec<(Topic, &'static str, DataMap)> {
        let frames = if d.db.packet(pgn) == super::super::pgn::Packet::Fast {
            fast_frames(1, data)
        } else {
            vec![data.to_vec()]
        };
        let mut out = Vec::new();
        for f in frames {
            out.extend(d.take(&CanFrame::data(id(pgn, src), true, &f).unwrap(), now));
        }
        out
    }

    fn on<'a>(out: &'a [(Topic, &'static str, DataMap)], topic: &str) -> &'a DataMap {
        out.iter()
            .find(|(t, _, _)| t.as_str() == topic)
            .map(|(_, _, m)| m)
            .unwrap_or_else(|| {
                let topics: Vec<&str> = out.iter().map(|(t, _, _)| t.as_str()).collect();
                panic!("nothing on {topic}; on {topics:?}")
            })
    }

    #[track_caller]
    fn near(m: &DataMap, key: &str, want: f64) {
        let got = m
            .get_f64(key)
            .unwrap_or_else(|| panic!("no {key} in {m:?}"));
        assert!((got - want).abs() < 1e-6, "{key}: {got}, not {want}");
    }

    #[test]
    fn a_pgn_is_its_topic_with_its_header_and_the_datasets_it_gives() {
        let mut d = driver(&[]);
        let now = Instant::now();
        // magnetic 90.0002°, deviation −0.573°, variation 2.865°
        let out = send(
            &mut d,
            127250,
            35,
            &[7, 0x5C, 0x3D, 0x9C, 0xFF, 0xF4, 0x01, 0xFD],
            now,
        );
        assert_eq!(out.len(), 2);
        let m = on(&out, "n2k.35.vesselHeading");
        let h = m.get("header").and_then(Value::as_map).unwrap();
        assert_eq!(
            (
                h.get_i64("pgn"),
                h.get_i64("src"),
                h.get_i64("dst"),
                h.get_i64("prio")
            ),
            (Some(127250), Some(35), Some(255), Some(2))
        );
        assert_eq!(m.get_str("reference"), Some("Magnetic"));
        let hd = on(&out, "nav.heading");
        let want = (15708.0 * 1e-4f64 - 0.01 + 0.05).to_degrees();
        near(hd, "heading", want);
        assert_eq!(hd.get_bool("magnetic"), Some(false));
        // an attitude without a yaw takes that true heading
        let out = send(
            &mut d,
            127257,
            36,
            &[2, 0xFF, 0x7F, 0x69, 0x03, 0x2F, 0xF9, 0xFF],
            now,
        );
        let a = on(&out, "nav.attitude");
        near(a, "yaw", want);
        near(a, "pitch", 0.0873f64.to_degrees());
        near(a, "roll", -0.1745f64.to_degrees());
        assert_eq!(
            a.get_str("sources"),
            Some("yaw PGN 127250, pitch PGN 127257, roll PGN 127257")
        );
        // past `fresh`, no attitude
        let later = now + Duration::from_secs(3);
        let out = send(
            &mut d,
            127257,
            36,
            &[2, 0xFF, 0x7F, 0x69, 0x03, 0x2F, 0xF9, 0xFF],
            later,
        );
        assert_eq!(out.len(), 1, "only the PGN's topic");
        // a PGN no definition has: its bytes
        let out = send(&mut d, 65280, 35, &[1, 2, 3], now);
        assert_eq!(
            on(&out, "n2k.35.65280").get("data"),
            Some(&Value::Bytes(vec![1, 2, 3]))
        );
    }

    #[test]
    fn gnss_course_depth_wind_battery_and_time_become_datasets() {
        let mut d = driver(&[]);
        let now = Instant::now();
        let gnss = [
            0x09, 0x38, 0x4A, 0x88, 0x3D, 0x75, 0x15, 0x00, 0x80, 0x4B, 0xFD, 0x31, 0x6E, 0x09,
            0x06, 0x00, 0xC0, 0xFF, 0x67, 0x1C, 0xAF, 0xBE, 0xFD, 0x20, 0xBC, 0xBE, 0x00, 0x00,
            0x00, 0x00, 0x00, 0x42, 0xFD, 0x0C, 0x50, 0x00, 0x96, 0x00, 0xA0, 0x0F, 0x00, 0x00,
            0x01, 0x40, 0x06, 0xFA, 0x00,
        ];
        let out = send(&mut d, 129029, 7, &gnss, now);
        let p = on(&out, "nav.position");
        near(p, "lat", 43.5);
        near(p, "lon", -16.25);
        near(p, "alt", 12.5 - 40.0);
        near(p, "hdop", 0.8);
        assert_eq!(
            (p.get_i64("fix"), p.get_i64("satellites")),
            (Some(4), Some(12))
        );
        let out = send(
            &mut d,
            129026,
            7,
            &[6, 0xFC, 0x10, 0x27, 0x02, 0x02, 0xFF, 0xFF],
            now,
        );
        let v = on(&out, "nav.velocity");
        near(v, "speed", 5.14);
        near(v, "course", 1f64.to_degrees());
        near(v, "north", 5.14 * 1f64.cos());
        near(v, "east", 5.14 * 1f64.sin());
        let out = send(
            &mut d,
            128267,
            8,
            &[5, 0xD2, 0x04, 0, 0, 0xF4, 0x01, 0x0A],
            now,
        );
        let a = on(&out, "nav.altitude");
        near(a, "altitude", 12.34);
        near(a, "water_depth", 12.84);
        let out = send(
            &mut d,
            130306,
            9,
            &[8, 0xEE, 0x02, 0xAE, 0x1E, 0xFA, 0xFF, 0xFF],
            now,
        );
        let w = on(&out, "env.wind");
        near(w, "speed", 7.5);
        near(w, "angle", (7854.0 * 1e-4f64).to_degrees());
        assert_eq!(w.get_str("reference"), Some("apparent"));
        // the DC status alone, then the battery status with it
        let dc = [
            0x03, 0x00, 0x00, 0x57, 0x5F, 0x78, 0x00, 0x19, 0x00, 0x64, 0x00,
        ];
        let out = send(&mut d, 127506, 10, &dc, now);
        let b = on(&out, "power.battery");
        near(b, "percent", 87.0);
        near(b, "minutes", 120.0);
        let out = send(
            &mut d,
            127508,
            10,
            &[0, 0x00, 0x05, 0xDD, 0xFF, 0x77, 0x74, 4],
            now,
        );
        let b = on(&out, "power.battery");
        near(b, "percent", 87.0);
        near(b, "voltage", 12.8);
        near(b, "current", -3.5);
        near(b, "temperature", 25.0);
        near(b, "power", 12.8 * -3.5);
        // with a battery status heard, a DC status alone makes no battery dataset
        let out = send(&mut d, 127506, 10, &dc, now);
        assert!(out.iter().all(|(t, _, _)| t.as_str() != "power.battery"));
        let out = send(
            &mut d,
            126992,
            7,
            &[0, 0xF0, 0x38, 0x4A, 0x00, 0xCC, 0xBF, 0x19],
            now,
        );
        near(on(&out, "nav.time"), "utc", 19000.0 * 86400.0 + 43200.0);
        assert!(d.counts().is_empty(), "{:?}", d.counts());
    }

    #[test]
    fn sources_limit_the_datasets_and_values_out_of_range_are_refused() {
        let mut d = driver(&[("sources", "35, 36"), ("heading_topic", "gyro.heading")]);
        let now = Instant::now();
        let frame = [7, 0x5C, 0x3D, 0x9C, 0xFF, 0xF4, 0x01, 0xFC];
        let out = send(&mut d, 127250, 35, &frame, now);
        near(
            on(&out, "gyro.heading"),
            "heading",
            (15708.0 * 1e-4f64).to_degrees(),
        );
        let out = send(&mut d, 127250, 40, &frame, now);
        assert_eq!(out.len(), 1, "source 40 gives its PGN topic only");
        on(&out, "n2k.40.vesselHeading");
        // pitch 100° (1.7453 rad) is no attitude
        let out = send(&mut d, 127257, 35, &[2, 0, 0, 0x2D, 0x44, 0, 0, 0xFF], now);
        assert_eq!(out.len(), 1);
        assert_eq!(d.tally.counts().get("n2k-out-of-range"), Some(&1));
        // a short single frame is counted, what it has is published
        let out = send(&mut d, 127250, 35, &[7, 0x5C, 0x3D], now);
        assert_eq!(on(&out, "n2k.35.vesselHeading").get_i64("sid"), Some(7));
        assert_eq!(d.tally.counts().get("n2k-short"), Some(&1));
    }

    #[test]
    fn the_frame_of_the_example_system_is_a_true_heading_of_90_degrees() {
        // configs/nmea2000.xml: 0x09F11223 015c3dff7fff7ffc
        let mut d = driver(&[]);
        let frame = CanFrame::data(
            0x09F1_1223,
            true,
            &[1, 0x5C, 0x3D, 0xFF, 0x7F, 0xFF, 0x7F, 0xFC],
        );
        let out = d.take(&frame.unwrap(), Instant::now());
        let m = on(&out, "n2k.35.vesselHeading");
        assert_eq!((m.get("deviation"), m.get("variation")), (None, None));
        let h = on(&out, "nav.heading");
        near(h, "heading", (15708.0 * 1e-4f64).to_degrees());
        assert!((h.get_f64("heading").unwrap() - 90.0002).abs() < 5e-5);
        assert_eq!(h.get_bool("magnetic"), Some(false));
    }

    #[test]
    fn a_magnetic_heading_without_a_deviation_gives_none() {
        let mut d = driver(&[]);
        // magnetic 90.0002°, deviation not available (0x7FFF), variation 2.865°
        let out = send(
            &mut d,
            127250,
            35,
            &[7, 0x5C, 0x3D, 0xFF, 0x7F, 0xF4, 0x01, 0xFD],
            Instant::now(),
        );
        assert_eq!(on(&out, "n2k.35.vesselHeading").get("deviation"), None);
        let hd = on(&out, "nav.heading");
        assert_eq!(hd.get("deviation"), None, "{hd:?}");
        near(hd, "variation", 0.05f64.to_degrees());
        near(hd, "heading", (15708.0 * 1e-4f64 + 0.05).to_degrees());
        assert_eq!(hd.get_bool("magnetic"), Some(false));
    }

    #[test]
    fn parameters_are_checked() {
        let bad = |pairs: &[(&str, &str)]| match Nmea2000::new(
            &Params::from_pairs(pairs),
            &Catalogue::built_in(),
        ) {
            Ok(_) => panic!("{pairs:?} was taken"),
            Err(e) => e.to_string(),
        };
        assert!(bad(&[("sources", "35 300")]).contains("`300` is not a source address"));
        assert!(bad(&[("database", "nowhere.json")]).contains("does not exist"));
        assert!(bad(&[("prefix", "a..b")]).contains("empty segment"));
        assert!(bad(&[("timeout", "soon")]).contains("not a duration"));
        assert!(bad(&[("max_partial", "0")]).contains("must be 1 or more"));
    }
    #[test]
    fn it_sends_only_from_a_claimed_address_and_refuses_what_a_pgn_cannot_hold() {
        let mut d = driver(&[
            ("address", "40"),
            ("unique_number", "1234"),
            ("send", "compass.heading=vesselHeading gnss.fix=129029"),
        ]);
        let t = Instant::now();
        let claim = d.start_claim(t);
        assert_eq!(claim.len(), 2);
        assert_eq!(claim[1].id(), 0x18EEFF28, "ISO address claim from 40");
        let heading = DataMap::new()
            .and("heading", Value::Float(90.0))
            .and("magnetic", Value::Bool(false))
            .and("sources", Value::from("HDT"));
        assert!(d.outgoing("compass.heading", &heading, t).is_empty());
        let later = t + claim::CLAIM_WAIT;
        let frames = d.outgoing("compass.heading", &heading, later);
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].id(), 0x09F11228);
        assert_eq!(&frames[0].payload()[..3], &[0xFF, 0x5C, 0x3D]);
        assert_eq!(frames[0].payload()[7] & 3, 0, "reference True");
        // a fast packet: its sequence counts up per PGN
        let fix = DataMap::new().and("latitude", Value::Float(43.5));
        let a = d.outgoing("n2k.out.gnssPositionData", &fix, later);
        let b = d.outgoing(
            "gnss.fix",
            &DataMap::new().and("lat", Value::Float(43.5)),
            later,
        );
        assert_eq!(a.len(), 7);
        assert_eq!(a[0].payload()[..2], [0x00, 43]);
        assert_eq!(b[0].payload()[..2], [0x20, 43]);
        // refused, counted
        let bad = DataMap::new().and("heading", Value::Float(400.0));
        assert!(d.outgoing("compass.heading", &bad, later).is_empty());
        assert!(
            d.outgoing(
                "n2k.out.vesselHeading",
                &DataMap::new().and("headng", Value::Int(1)),
                later
            )
            .is_empty()
        );
        assert!(
            d.outgoing("n2k.out.nothing", &DataMap::new(), later)
                .is_empty()
        );
        let s = d.sender.as_ref().unwrap();
        assert_eq!(s.sent, 3);
        let refused: Vec<(&str, u64)> = s.refused.iter().map(|(k, v)| (*k, *v)).collect();
        assert_eq!(
            refused,
            [
                ("n2k-send-no-address", 1),
                ("n2k-send-out-of-range", 1),
                ("n2k-send-unknown-field", 1),
                ("n2k-send-unknown-pgn", 1)
            ]
        );
    }

    #[test]
    fn sending_parameters_are_checked() {
        let bad = |pairs: &[(&str, &str)]| match Nmea2000::new(
            &Params::from_pairs(pairs),
            &Catalogue::built_in(),
        ) {
            Ok(_) => panic!("{pairs:?} was taken"),
            Err(e) => e.to_string(),
        };
        assert!(bad(&[("send", "a.b=127250")]).contains("needs an `address`"));
        assert!(bad(&[("address", "252"), ("unique_number", "1")]).contains("not an address"));
        assert!(bad(&[("address", "40")]).contains("needs its `unique_number`"));
        let with = |send: &str| bad(&[("address", "40"), ("unique_number", "1"), ("send", send)]);
        assert!(with("nav.heading=vesselHeading").contains("would loop"));
        assert!(with("n2k.x=vesselHeading").contains("publish on `n2k.out.ID`"));
        assert!(with("a.b=nothing").contains("`nothing` is no PGN"));
        assert!(with("a.b").contains("is not TOPIC=PGN"));
    }
}
