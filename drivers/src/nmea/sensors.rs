//! NMEA sensor drivers: a GPS, a heading sensor and an echo sounder, each turning the sentences
//! it reads on a serial medium into standard datasets on a bus.
//!
//! Each is placed on two media, the serial line first (`media="gps-line bus"`). Parameters common to
//! all three: `talkers` (only sentences from these talkers, such as `GP GN`; default any), one
//! parameter per output naming the sentence formatters that feed it (only ones the driver reads
//! for that output: naming another is an error), and one naming its topic.
//!
//! | type | output ← sentences (parameter, default) | topic parameter (default) |
//! |---|---|---|
//! | `nmea-gps` | position ← `position` (`GGA GNS GLL`; `RMC` may be added); velocity ← `velocity` (`RMC VTG`) | `topic` (`nav.position`), `velocity_topic` (`nav.velocity`) |
//! | `nmea-heading` | heading ← `heading` (`HDT HDG HDM`); attitude when `XDR` pitch and roll are fresh | `topic` (`nav.heading`), `attitude_topic` (`nav.attitude`) |
//! | `nmea-sounder` | altitude ← `altitude` (`DBT DPT DBK`) | `topic` (`nav.altitude`) |
//!
//! `nmea-gps` also takes `source` (a name put in each position, such as `rtk`; none by default). `nmea-heading` corrects `HDG` by its deviation and
//! variation into a true heading, takes `variation` (degrees east, used when a magnetic heading comes
//! without one) and `fresh` (how long a pitch and roll stay usable, default 2s). `nmea-sounder` takes
//! `offset` (metres added to depths measured from the transducer).

use super::line::Reader;
use super::sentence::{Parsed, Sentence, talker};
use crate::units::{FOOT, KNOT};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Format, Key, Kind, Message, Topic, Value};
use seabus_modules::Catalogue;
use seabus_modules::geo::wrap360;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::time::Duration;
use tokio::time::Instant;

/// The `nmea-gps` module type.
pub const GPS: ModuleType = ModuleType {
    name: "nmea-gps",
    kind: ModuleKind::Driver,
    summary: "an NMEA GPS: position, velocity and fix quality",
    build: |c, cat| build(c, cat, Role::Gps),
};

/// The `nmea-heading` module type.
pub const HEADING: ModuleType = ModuleType {
    name: "nmea-heading",
    kind: ModuleKind::Driver,
    summary: "an NMEA compass or gyro: heading, and attitude with XDR pitch and roll",
    build: |c, cat| build(c, cat, Role::Heading),
};

/// The `nmea-sounder` module type.
pub const SOUNDER: ModuleType = ModuleType {
    name: "nmea-sounder",
    kind: ModuleKind::Driver,
    summary: "an NMEA echo sounder: altitude above the sea floor",
    build: |c, cat| build(c, cat, Role::Sounder),
};

/// What an NMEA sensor driver reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A GPS.
    Gps,
    /// A compass or gyro.
    Heading,
    /// An echo sounder.
    Sounder,
}

/// One output: the formatters that feed it, its dataset and topic.
struct Output {
    /// three-letter sentence formatters (`GGA`), each one the driver reads
    feeds: Vec<[u8; 3]>,
    dataset: &'static str,
    topic: Topic,
}

impl Output {
    /// Whether sentences of `formatter` feed this output.
    fn fed_by(&self, formatter: &str) -> bool {
        <[u8; 3]>::try_from(formatter.as_bytes()).is_ok_and(|f| self.feeds.contains(&f))
    }
}

/// An NMEA sensor driver: sentences in, datasets out.
pub struct Sensor {
    role: Role,
    talkers: Option<Vec<String>>,
    outputs: Vec<Output>,
    source: Option<String>,
    variation: Option<f64>,
    offset: f64,
    fresh: Duration,
    pitch_roll: Option<(f64, f64, Instant)>,
    /// The parse shared with the other drivers on the line, once the first sentence came.
    reader: Option<std::sync::Arc<Reader>>,
    tally: Tally,
}

/// A sentence formatter as three bytes, when it is three letters.
fn code(formatter: &str) -> Option<[u8; 3]> {
    formatter.as_bytes().try_into().ok()
}

fn words(s: &str) -> Vec<String> {
    s.split([' ', ','])
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

fn build(cfg: &ModuleConfig, cat: &Catalogue, role: Role) -> Result<Built, FileError> {
    let (sensor, decl) = Sensor::new(&cfg.params, cat, role)?;
    Ok(Built {
        decl,
        module: Box::new(sensor),
    })
}

impl Sensor {
    /// A driver of `role` from its parameters, with its declaration.
    pub fn new(
        p: &seabus_modules::Params,
        cat: &Catalogue,
        role: Role,
    ) -> Result<(Sensor, Declaration), FileError> {
        // the sentences feeding an output: any of those the driver can read for it
        let list = |name: &str, default: &[&str], readable: &[&str]| {
            let Some(param) = p.get(name) else {
                return Ok(default.iter().filter_map(|f| code(f)).collect());
            };
            let named = words(&param.value);
            if named.is_empty() {
                return Err(param.error("names no sentence"));
            }
            named
                .iter()
                .map(|w| {
                    code(w)
                        .filter(|_| readable.contains(&w.as_str()))
                        .ok_or_else(|| {
                            param.error(format!(
                                "`{w}` is not a sentence this driver reads for it (it reads {})",
                                readable.join(", ")
                            ))
                        })
                })
                .collect::<Result<Vec<_>, FileError>>()
        };
        let topic = |name: &str, dataset: &str, fallback: &str| {
            p.dataset_topic_or(name, cat, dataset, fallback)
        };
        let outputs = match role {
            Role::Gps => vec![
                Output {
                    feeds: list(
                        "position",
                        &["GGA", "GNS", "GLL"],
                        &["GGA", "GNS", "GLL", "RMC"],
                    )?,
                    dataset: "position",
                    topic: topic("topic", "position", "nav.position")?,
                },
                Output {
                    feeds: list("velocity", &["RMC", "VTG"], &["RMC", "VTG"])?,
                    dataset: "velocity",
                    topic: topic("velocity_topic", "velocity", "nav.velocity")?,
                },
            ],
            Role::Heading => vec![
                Output {
                    feeds: list("heading", &["HDT", "HDG", "HDM"], &["HDT", "HDG", "HDM"])?,
                    dataset: "heading",
                    topic: topic("topic", "heading", "nav.heading")?,
                },
                Output {
                    feeds: vec![*b"XDR"],
                    dataset: "attitude",
                    topic: topic("attitude_topic", "attitude", "nav.attitude")?,
                },
            ],
            Role::Sounder => vec![Output {
                feeds: list("altitude", &["DBT", "DPT", "DBK"], &["DBT", "DPT", "DBK"])?,
                dataset: "altitude",
                topic: topic("topic", "altitude", "nav.altitude")?,
            }],
        };
        let mut decl = Declaration::new(ModuleKind::Driver)
            .format(0, Some(Format::Bytes))
            .consumes(TopicDecl::topic(p.str("input").unwrap_or("nmea.**")))
            .format(1, Some(Format::Map));
        for o in &outputs {
            decl = decl.produces(TopicDecl::dataset(&o.topic, o.dataset).on_port(1));
        }
        let talkers = p.get("talkers").map(|t| words(&t.value));
        let sensor = Sensor {
            role,
            talkers,
            outputs,
            source: if role == Role::Gps {
                p.str("source").map(str::to_string)
            } else {
                None
            },
            variation: if role == Role::Heading {
                p.parse("variation", "degrees east")?
            } else {
                None
            },
            offset: if role == Role::Sounder {
                p.float_or("offset", 0.0)?
            } else {
                0.0
            },
            fresh: if role == Role::Heading {
                p.duration_or("fresh", Duration::from_secs(2))?
            } else {
                Duration::ZERO
            },
            pitch_roll: None,
            reader: None,
            tally: Tally::new(),
        };
        Ok((sensor, decl))
    }
}

/// What one sentence gives: the index of an output and the dataset to publish on it.
pub type Reading = (usize, DataMap);

/// The readings of one sentence: at most two (RMC gives a position and a velocity; a heading
/// gives a heading and an attitude), kept without allocating.
#[derive(Debug, Default)]
pub struct Readings([Option<Reading>; 2], Option<String>);

impl Readings {
    /// A value of the sentence out of its range: dropped (never wrapped or clamped) and said why.
    fn out_of_range(&mut self, why: String) {
        self.1.get_or_insert(why);
    }

    /// Why a value of the sentence was dropped, if one was.
    pub fn dropped(&self) -> Option<&str> {
        self.1.as_deref()
    }

    fn push(&mut self, r: Reading) {
        if let Some(slot) = self.0.iter_mut().find(|s| s.is_none()) {
            *slot = Some(r);
        }
    }

    fn iter(&self) -> impl Iterator<Item = &Reading> {
        self.0.iter().flatten()
    }

    /// How many readings there are.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// The true heading among the readings, if there is one.
    fn true_heading(&self) -> Option<f64> {
        let (_, m) = self.iter().find(|(i, _)| *i == 0)?;
        match m.get_bool("magnetic") {
            Some(true) => None,
            _ => m.get_f64("heading"),
        }
    }

    /// True when the sentence gave nothing.
    pub fn is_empty(&self) -> bool {
        self.0[0].is_none()
    }
}

impl IntoIterator for Readings {
    type Item = Reading;
    type IntoIter = std::iter::Flatten<std::array::IntoIter<Option<Reading>, 2>>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.into_iter().flatten()
    }
}

impl Sensor {
    /// A position: latitude and longitude, then the fields of `more` that are there, then the
    /// source when one is configured.
    fn fix<const N: usize>(
        &self,
        lat: f64,
        lon: f64,
        more: [(&'static str, Option<Value>); N],
    ) -> DataMap {
        let mut e: Vec<(Key, Value)> = Vec::with_capacity(3 + N);
        e.extend([("lat".into(), lat.into()), ("lon".into(), lon.into())]);
        for (k, v) in more {
            if let Some(v) = v {
                e.push((Key::Borrowed(k), v));
            }
        }
        if let Some(src) = &self.source {
            e.push(("source".into(), src.clone().into()));
        }
        DataMap::from_entries(e)
    }

    /// Turns a parsed sentence into readings.
    pub fn read(&mut self, parsed: &Parsed, now: Instant) -> Readings {
        let mut out = Readings::default();
        match self.role {
            Role::Gps => self.read_gps(parsed, &mut out),
            Role::Heading => self.read_heading(parsed, now, &mut out),
            Role::Sounder => self.read_sounder(parsed, &mut out),
        }
        out
    }

    /// Whether sentences of `formatter` feed output `i`.
    fn fed(&self, i: usize, formatter: &str) -> bool {
        self.outputs.get(i).is_some_and(|o| o.fed_by(formatter))
    }

    /// A GPS: positions (output 0) from GGA, GNS, GLL and RMC; velocities (output 1) from RMC and
    /// VTG.
    fn read_gps(&self, parsed: &Parsed, out: &mut Readings) {
        let fed = |i: usize| self.fed(i, parsed.formatter());
        match &parsed.sentence {
            Sentence::Gga(g) if fed(0) => {
                // quality 0 (no fix): whatever position it carries is not one
                let fixed = g.fix_type.is_some_and(|t| fix_quality(t) > 0);
                if fixed && let (Some(lat), Some(lon)) = (g.latitude, g.longitude) {
                    let m = self.fix(
                        lat,
                        lon,
                        [
                            ("fix", Some(g.fix_type.map_or(0, fix_quality).into())),
                            ("satellites", g.fix_satellites.map(Value::from)),
                            ("hdop", g.hdop.map(Value::from)),
                            ("alt", g.altitude.map(Value::from)),
                        ],
                    );
                    out.push((0, m));
                }
            }
            Sentence::Gns(g) if fed(0) => {
                if let (Some(lat), Some(lon)) = (g.lat, g.lon) {
                    let m = self.fix(
                        lat,
                        lon,
                        [
                            ("satellites", Some(i64::from(g.nsattelites).into())),
                            ("hdop", g.hdop.map(Value::from)),
                        ],
                    );
                    out.push((0, m));
                }
            }
            Sentence::Gll(g) if fed(0) && g.valid => {
                if let (Some(lat), Some(lon)) = (g.latitude, g.longitude) {
                    out.push((0, self.fix(lat, lon, [])));
                }
            }
            Sentence::Rmc(r) => {
                let valid = r.status_of_fix != nmea::sentences::rmc::RmcStatusOfFix::Invalid;
                if valid
                    && fed(0)
                    && let (Some(lat), Some(lon)) = (r.lat, r.lon)
                {
                    out.push((0, self.fix(lat, lon, [])));
                }
                if valid
                    && fed(1)
                    && let (Some(sog), Some(cog)) = (r.speed_over_ground, r.true_course)
                {
                    ground_velocity(f64::from(sog), f64::from(cog), out);
                }
            }
            Sentence::Vtg(v) if fed(1) => {
                if let (Some(sog), Some(cog)) = (v.speed_over_ground, v.true_course) {
                    ground_velocity(f64::from(sog), f64::from(cog), out);
                }
            }
            _ => {}
        }
    }

    /// A compass or gyro: headings (output 0) from HDT, HDG and HDM, HDG and HDM corrected into a
    /// true heading where the variation is known; pitch and roll from XDR, which with a fresh
    /// true heading make an attitude (output 1).
    fn read_heading(&mut self, parsed: &Parsed, now: Instant, out: &mut Readings) {
        // asked only of the sentences a heading is read from
        let fed = || self.fed(0, parsed.formatter());
        match &parsed.sentence {
            Sentence::Hdt(h) if fed() => {
                if let Some(hdg) = h.heading.map(f64::from)
                    && in_range("heading", hdg, 0.0, 360.0, out)
                {
                    out.push((0, heading(hdg, false)));
                }
            }
            Sentence::Hdg {
                heading: Some(hdg),
                deviation,
                variation,
            } if fed() && in_range("heading", *hdg, 0.0, 360.0, out) => {
                let dev = deviation.unwrap_or(0.0);
                match variation.or(self.variation) {
                    Some(var) => {
                        let mut m = heading(hdg + dev + var, false);
                        m.push("deviation", dev);
                        m.push("variation", var);
                        out.push((0, m));
                    }
                    None => {
                        let mut m = heading(hdg + dev, true);
                        m.push("deviation", dev);
                        out.push((0, m));
                    }
                }
            }
            Sentence::Hdm { heading: Some(hdg) }
                if fed() && in_range("heading", *hdg, 0.0, 360.0, out) =>
            {
                match self.variation {
                    Some(var) => out.push((0, heading(hdg + var, false).and("variation", var))),
                    None => out.push((0, heading(*hdg, true))),
                }
            }
            Sentence::Xdr(x) => {
                let angle = |name: &str| {
                    x.iter()
                        .find(|t| t.kind == "A" && t.name.eq_ignore_ascii_case(name))
                        .and_then(|t| t.value)
                };
                if let (Some(pitch), Some(roll)) = (angle("PITCH"), angle("ROLL")) {
                    self.pitch_roll = Some((pitch, roll, now));
                }
            }
            _ => {}
        }
        // a heading sensor that also gives pitch and roll is an attitude sensor
        if let Some(yaw) = out.true_heading()
            && let Some((pitch, roll, at)) = self.pitch_roll
            && now.duration_since(at) <= self.fresh
        {
            out.push((
                1,
                DataMap::with_capacity(3)
                    .and("yaw", yaw)
                    .and("pitch", pitch)
                    .and("roll", roll),
            ));
        }
    }

    /// An echo sounder: altitudes (output 0) from DBT, DPT and DBK, plus the offset.
    fn read_sounder(&self, parsed: &Parsed, out: &mut Readings) {
        if !self.fed(0, parsed.formatter()) {
            return;
        }
        let depth = match &parsed.sentence {
            Sentence::Dbt { metres, feet, .. } => metres.or(feet.map(|f| f * FOOT)),
            Sentence::Dpt(d) => d.water_depth,
            Sentence::Dbk(d) => d.depth_meters.or(d.depth_feet.map(|f| f * FOOT)),
            _ => None,
        };
        if let Some(d) = depth
            && in_range("depth", d, 0.0, MAX_DEPTH, out)
            && in_range(
                "depth with the offset",
                d + self.offset,
                0.0,
                MAX_DEPTH,
                out,
            )
        {
            out.push((0, altitude(d + self.offset)));
        }
    }
}

fn fix_quality(t: nmea::sentences::FixType) -> i64 {
    use nmea::sentences::FixType::*;
    match t {
        Invalid => 0,
        Gps => 1,
        DGps => 2,
        Pps => 3,
        Rtk => 4,
        FloatRtk => 5,
        Estimated => 6,
        Manual => 7,
        Simulation => 8,
    }
}

/// The deepest water there is, in metres (with margin): a deeper reading is not one.
const MAX_DEPTH: f64 = 12_000.0;
/// The fastest a vessel goes, in knots (with margin).
const MAX_KNOTS: f64 = 150.0;

/// Whether `what` = `value` is within `lo`–`hi` (and finite); if not, `out` says why it is
/// dropped.
fn in_range(what: &str, value: f64, lo: f64, hi: f64, out: &mut Readings) -> bool {
    let ok = value.is_finite() && (lo..=hi).contains(&value);
    if !ok {
        out.out_of_range(format!("{what} {value} is not within {lo}–{hi}"));
    }
    ok
}

/// A velocity over ground from `knots` and `course` (degrees true), when both are in range.
fn ground_velocity(knots: f64, course: f64, out: &mut Readings) {
    if in_range("speed (knots)", knots, 0.0, MAX_KNOTS, out)
        && in_range("course", course, 0.0, 360.0, out)
    {
        out.push((1, velocity(knots * KNOT, course)));
    }
}

fn velocity(speed: f64, course: f64) -> DataMap {
    let (sin, cos) = course.to_radians().sin_cos();
    DataMap::from_entries(vec![
        ("speed".into(), Value::Float(speed)),
        ("course".into(), Value::Float(wrap360(course))),
        ("north".into(), Value::Float(speed * cos)),
        ("east".into(), Value::Float(speed * sin)),
        ("reference".into(), Value::label("ground")),
    ])
}

fn heading(h: f64, magnetic: bool) -> DataMap {
    let mut e = Vec::with_capacity(4);
    e.extend([
        ("heading".into(), Value::Float(wrap360(h))),
        ("magnetic".into(), Value::Bool(magnetic)),
    ]);
    DataMap::from_entries(e)
}

fn altitude(a: f64) -> DataMap {
    DataMap::from_entries(vec![
        ("altitude".into(), Value::Float(a)),
        ("valid".into(), Value::Bool(true)),
    ])
}

#[async_trait]
impl Module for Sensor {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        if port != 0 {
            return Ok(());
        }
        let Some(bytes) = msg.payload.as_bytes() else {
            return Ok(());
        };
        // framed NMEA is ASCII; anything else is no sentence (and is not one any driver reads)
        let Ok(line) = std::str::from_utf8(bytes) else {
            return Ok(());
        };
        if let Some(t) = &self.talkers {
            let talker = talker(line);
            if !talker.is_empty() && !t.iter().any(|x| x == talker) {
                return Ok(());
            }
        }
        let Some(medium) = ctx.port(0).map(|p| p.medium().clone()) else {
            return Ok(());
        };
        let reader = self.reader.get_or_insert_with(|| {
            let r = medium.shared::<Reader>();
            r.want(
                self.outputs
                    .iter()
                    .flat_map(|o| o.feeds.iter())
                    .filter_map(|f| std::str::from_utf8(f).ok()),
            );
            r
        });
        let Some(read) = reader.read(&msg, line, &medium.ingress()) else {
            return Ok(());
        };
        let Ok(parsed) = &*read else {
            return Ok(());
        };
        let readings = self.read(parsed, Instant::now());
        if let Some(why) = readings.dropped() {
            medium
                .ingress()
                .reject("out-of-range", format_args!("{}: {why}", line.trim_end()));
        }
        for (i, map) in readings {
            let o = &self.outputs[i];
            if let Err(e) = ctx
                .dataset_on(1, Kind::Data, o.dataset, &o.topic, map)
                .await
            {
                self.tally.record(ctx.name(), "invalid", &e);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::sentence::parse;
    use super::*;
    use seabus_medium::framing::nmea_sentence;
    use seabus_modules::Params;

    fn sensor(role: Role, pairs: &[(&str, &str)]) -> Sensor {
        let params = Params::from_pairs(pairs);
        let (s, _) = Sensor::new(&params, &Catalogue::built_in(), role).unwrap();
        params.finish("t").unwrap();
        s
    }

    fn read(s: &mut Sensor, body: &str) -> Vec<(usize, DataMap)> {
        let line = nmea_sentence(b'$', body);
        let parsed = parse(&line).unwrap();
        s.read(&parsed, Instant::now()).into_iter().collect()
    }

    #[test]
    fn an_output_takes_only_sentences_its_driver_reads() {
        let bad = |role, pairs: &[(&str, &str)]| {
            let params = Params::from_pairs(pairs);
            match Sensor::new(&params, &Catalogue::built_in(), role) {
                Ok(_) => panic!("{pairs:?} was taken"),
                Err(e) => e.to_string(),
            }
        };
        let e = bad(Role::Gps, &[("position", "GGA GGX")]);
        assert!(
            e.contains("parameter `position`: `GGX` is not a sentence this driver reads for it (it reads GGA, GNS, GLL, RMC)"),
            "{e}"
        );
        let e = bad(Role::Heading, &[("heading", "VTG")]);
        assert!(e.contains("`VTG` is not a sentence"), "{e}");
        let e = bad(Role::Sounder, &[("altitude", " , ")]);
        assert!(e.contains("parameter `altitude`: names no sentence"), "{e}");
    }

    #[test]
    fn gps_sentences_become_position_and_velocity() {
        let mut g = sensor(Role::Gps, &[]);
        let out = read(
            &mut g,
            "GPGGA,123519,4807.038,N,01131.000,E,2,08,0.9,545.4,M,46.9,M,,",
        );
        assert_eq!(out.len(), 1);
        let (i, m) = &out[0];
        assert_eq!(*i, 0);
        assert_eq!(
            (
                m.get_i64("fix"),
                m.get_i64("satellites"),
                m.get_str("source")
            ),
            (Some(2), Some(8), None)
        );
        assert!((m.get_f64("hdop").unwrap() - 0.9).abs() < 1e-6);
        let out = read(
            &mut g,
            "GPRMC,123519,A,4807.038,N,01131.000,E,010.0,090.0,230394,,",
        );
        assert_eq!(out.len(), 1, "RMC feeds velocity only by default");
        let (i, v) = &out[0];
        assert_eq!(*i, 1);
        assert!((v.get_f64("speed").unwrap() - 10.0 * KNOT).abs() < 1e-9);
        assert!((v.get_f64("east").unwrap() - 10.0 * KNOT).abs() < 1e-6);
        let mut named = sensor(Role::Gps, &[("source", "rtk")]);
        let out = read(
            &mut named,
            "GPGGA,123519,4807.038,N,01131.000,E,4,12,0.5,5.0,M,46.9,M,,",
        );
        assert_eq!(out[0].1.get_str("source"), Some("rtk"));
        // no fix, no position
        assert!(read(&mut g, "GPGGA,123519,,,,,0,00,,,M,,M,,").is_empty());
        // other talkers can be left out, and RMC can feed position too
        let mut only = sensor(Role::Gps, &[("talkers", "GN"), ("position", "RMC")]);
        assert!(only.talkers.as_ref().unwrap().contains(&"GN".to_string()));
        let out = read(
            &mut only,
            "GNRMC,123519,A,4807.038,N,01131.000,E,010.0,090.0,230394,,",
        );
        assert_eq!(out.iter().map(|(i, _)| *i).collect::<Vec<_>>(), [0, 1]);
    }

    #[test]
    fn headings_are_corrected_and_attitude_needs_fresh_pitch_and_roll() {
        let mut h = sensor(Role::Heading, &[]);
        let out = read(&mut h, "HCHDG,100.0,2.0,W,5.0,E");
        let (_, m) = &out[0];
        assert_eq!(
            (m.get_f64("heading"), m.get_bool("magnetic")),
            (Some(103.0), Some(false))
        );
        assert_eq!(
            (m.get_f64("deviation"), m.get_f64("variation")),
            (Some(-2.0), Some(5.0))
        );
        let out = read(&mut h, "HCHDM,10.0,M");
        assert_eq!(out[0].1.get_bool("magnetic"), Some(true));
        assert!(read(&mut h, "HCXDR,A,2.5,D,PITCH,A,-1.0,D,ROLL").is_empty());
        let out = read(&mut h, "HEHDT,359.5,T");
        assert_eq!(
            out.len(),
            2,
            "heading, and attitude with the fresh pitch and roll"
        );
        let (i, a) = &out[1];
        assert_eq!(
            (*i, a.get_f64("yaw"), a.get_f64("pitch"), a.get_f64("roll")),
            (1, Some(359.5), Some(2.5), Some(-1.0))
        );
        let mut with_var = sensor(Role::Heading, &[("variation", "-3")]);
        let out = read(&mut with_var, "HCHDM,10.0,M");
        assert_eq!(
            (out[0].1.get_f64("heading"), out[0].1.get_bool("magnetic")),
            (Some(7.0), Some(false))
        );
    }

    #[test]
    fn sounder_depths_become_altitude() {
        let mut s = sensor(Role::Sounder, &[("offset", "0.5")]);
        let out = read(&mut s, "SDDBT,24.6,f,7.5,M,4.1,F");
        assert_eq!(out[0].1.get_f64("altitude"), Some(8.0));
        let out = read(&mut s, "SDDPT,17.5,0.3,100");
        assert_eq!(out[0].1.get_f64("altitude"), Some(18.0));
        let out = read(&mut s, "SDDBT,10.0,f,,M,,F");
        assert!((out[0].1.get_f64("altitude").unwrap() - (10.0 * FOOT + 0.5)).abs() < 1e-9);
    }

    /// What `body` gives, and why a value of it was dropped.
    fn read_dropped(s: &mut Sensor, body: &str) -> (Vec<(usize, DataMap)>, Option<String>) {
        let line = nmea_sentence(b'$', body);
        let parsed = parse(&line).unwrap();
        let r = s.read(&parsed, Instant::now());
        let why = r.dropped().map(str::to_string);
        (r.into_iter().collect(), why)
    }

    #[test]
    fn values_out_of_range_are_dropped_with_the_reason_never_wrapped_or_clamped() {
        let mut compass = sensor(Role::Heading, &[]);
        let (out, why) = read_dropped(&mut compass, "HEHDT,400.0,T");
        assert!(out.is_empty());
        assert_eq!(why.as_deref(), Some("heading 400 is not within 0–360"));
        let (out, why) = read_dropped(&mut compass, "HEHDT,359.9,T");
        assert_eq!((out.len(), why), (1, None));
        let mut gps = sensor(Role::Gps, &[]);
        let (out, why) = read_dropped(&mut gps, "GPVTG,720.0,T,,M,5.0,N,9.3,K");
        assert!(out.is_empty());
        assert_eq!(why.as_deref(), Some("course 720 is not within 0–360"));
        let mut sounder = sensor(Role::Sounder, &[]);
        let (out, why) = read_dropped(&mut sounder, "SDDBT,,f,-1.5,M,,F");
        assert!(out.is_empty());
        assert_eq!(why.as_deref(), Some("depth -1.5 is not within 0–12000"));
        let mut keel = sensor(Role::Sounder, &[("offset", "-2.0")]);
        let (out, why) = read_dropped(&mut keel, "SDDBT,,f,1.5,M,,F");
        assert!(out.is_empty());
        assert_eq!(
            why.as_deref(),
            Some("depth with the offset -0.5 is not within 0–12000")
        );
    }

    #[test]
    fn a_fix_of_quality_zero_is_no_position() {
        let mut gps = sensor(Role::Gps, &[]);
        let none = read(
            &mut gps,
            "GPGGA,123519,4807.038,N,01131.000,E,0,08,0.9,545.4,M,46.9,M,,",
        );
        assert!(none.is_empty());
        let one = read(
            &mut gps,
            "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        );
        assert_eq!(one.len(), 1);
        assert!((one[0].1.get_f64("lat").unwrap() - 48.1173).abs() < 1e-7);
    }
}
