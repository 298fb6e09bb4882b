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

use super::frame::{Assembler, Limits, Message};
use super::nav::{self, Navigator};
use super::pgn::{Database, PgnDef};
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
use std::collections::HashMap;
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
            },
            decl,
        ))
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
        if frame.kind() == FrameKind::Error {
            return Vec::new();
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
        match whole {
            Some(m) => self.read(&m, now),
            None => Vec::new(),
        }
    }

    async fn on_frame(&mut self, ctx: &mut Context, msg: &BusMessage) -> Result<(), ModuleError> {
        let Ok(frame) = CanFrame::from_message(msg.topic.as_str(), &msg.payload) else {
            return Ok(());
        };
        for (topic, dataset, map) in self.take(&frame, Instant::now()) {
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
            Ok(())
        }
    }

    async fn on_timer(&mut self, _ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        if timer == SWEEP {
            self.assembler.expire(Instant::now());
            self.report();
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
}
