//! NMEA sensor drivers: each turns the sentences it reads on a serial medium into standard
//! datasets on a bus.
//!
//! Each is placed on two media, the serial line first (`media="gps-line bus"`). Parameters common to
//! all: `talkers` (only sentences from these talkers, such as `GP GN`; default any), one parameter
//! per output naming the sentences that feed it (only ones the driver reads for that output:
//! naming another is an error), and one naming its topic. The drivers on one line parse each
//! sentence once between them ([`super::line`]).
//!
//! | type | output ← sentences (parameter, default) | dataset | topic parameter (default) |
//! |---|---|---|---|
//! | `nmea-gps` | position ← `position` (`GGA GNS GLL`; `RMC` may be added) | `position` | `topic` (`nav.position`) |
//! | | velocity ← `velocity` (`RMC VTG`) | `velocity` | `velocity_topic` (`nav.velocity`) |
//! | | fix status ← `fix` (`GGA GNS GLL RMC GSA GSV GST`) | `gnss-fix` | `fix_topic` (`nav.fix`) |
//! | | time ← `time` (`ZDA`) | `time` | `time_topic` (`nav.time`) |
//! | | text ← `text` (`TXT`) | `device-text` | `text_topic` (`device.text`) |
//! | `nmea-heading` | heading ← `heading` (`HDT HDG HDM THS`, and the attitude table's sentences that carry one) | `heading` | `topic` (`nav.heading`) |
//! | | attitude ← `attitude` (`XDR` and the attitude table's sentences) | `attitude` | `attitude_topic` (`nav.attitude`) |
//! | | rate of turn ← `rate` (`ROT`) | `turn-rate` | `rate_topic` (`nav.rate`) |
//! | `nmea-sounder` | altitude ← `altitude` (`DBT DPT DBK`) | `altitude` | `topic` (`nav.altitude`) |
//! | `nmea-wind` | wind ← `wind` (`MWV MWD`) | `wind` | `topic` (`env.wind`) |
//! | `nmea-log` | speed through the water ← `velocity` (`VHW VBW`) | `velocity` | `topic` (`nav.water_velocity`) |
//! | `nmea-steering` | rudder ← `rudder` (`RSA`) | `rudder` | `topic` (`vehicle.rudder`) |
//! | | cross-track error ← `xte` (`XTE`) | `cross-track` | `xte_topic` (`nav.xte`) |
//!
//! `nmea-gps` also takes `source` (a name put in each position, such as `rtk`). `nmea-heading`
//! corrects `HDG` by its deviation and variation into a true heading, takes `variation` (degrees
//! east, used when a magnetic heading comes without one), `fresh` (how long a pitch and a roll
//! stay usable for an attitude, default 2s: they may come in separate sentences) and
//! `attitude_table` (a file of proprietary attitude sentences added to the built-in table, see
//! [`super::attitude`]). `nmea-sounder` takes `offset` (metres added to depths measured from the
//! transducer).
//!
//! Every value is checked against its range before it is published; a value out of range is
//! dropped (never wrapped or clamped) and counted on the line's medium as `out-of-range` with the
//! sentence and the reason. Sentences saying their data is not valid (RMC status `V`, GGA quality
//! 0, GNS mode `N`, GLL `V`) give no position; they still give the fix status, whose `valid`,
//! `quality`, `mode` and `status` fields carry what the sentence said.

use super::attitude::{Combined, Table};
use super::line::Reader;
use super::sentence::{Parsed, talker};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Format, Ingress, Kind, Message, Topic};
use seabus_modules::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::sync::Arc;
use std::time::Duration;
use tokio::time::Instant;

macro_rules! module_type {
    ($(#[$doc:meta])* $name:ident, $type_name:literal, $summary:literal, $role:expr) => {
        $(#[$doc])*
        pub const $name: ModuleType = ModuleType {
            name: $type_name,
            kind: ModuleKind::Driver,
            summary: $summary,
            build: |c, cat| build(c, cat, $role),
        };
    };
}

module_type!(
    /// The `nmea-gps` module type.
    GPS,
    "nmea-gps",
    "an NMEA GPS: position, velocity, fix status, time and the receiver's text messages",
    Role::Gps
);
module_type!(
    /// The `nmea-heading` module type.
    HEADING,
    "nmea-heading",
    "an NMEA compass or gyro: heading, rate of turn, and attitude with pitch and roll",
    Role::Heading
);
module_type!(
    /// The `nmea-sounder` module type.
    SOUNDER,
    "nmea-sounder",
    "an NMEA echo sounder: altitude above the sea floor",
    Role::Sounder
);
module_type!(
    /// The `nmea-wind` module type.
    WIND,
    "nmea-wind",
    "an NMEA wind instrument: apparent and true wind",
    Role::Wind
);
module_type!(
    /// The `nmea-log` module type.
    LOG,
    "nmea-log",
    "an NMEA speed log: speed through the water",
    Role::Log
);
module_type!(
    /// The `nmea-steering` module type.
    STEERING,
    "nmea-steering",
    "NMEA steering data: rudder angles and cross-track error",
    Role::Steering
);

/// What an NMEA sensor driver reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A GPS.
    Gps,
    /// A compass or gyro.
    Heading,
    /// An echo sounder.
    Sounder,
    /// A wind instrument.
    Wind,
    /// A speed log.
    Log,
    /// Rudder angle sensors and a cross-track error source.
    Steering,
}

/// How an output is set up: the parameter listing its sentences, the ones it takes by default
/// and the ones it can read, its dataset, its topic parameter and default topic.
struct Spec {
    list: &'static str,
    default: &'static [&'static str],
    readable: &'static [&'static str],
    dataset: &'static str,
    topic_param: &'static str,
    topic: &'static str,
}

const fn spec(
    list: &'static str,
    default: &'static [&'static str],
    readable: &'static [&'static str],
    dataset: &'static str,
    topic_param: &'static str,
    topic: &'static str,
) -> Spec {
    Spec {
        list,
        default,
        readable,
        dataset,
        topic_param,
        topic,
    }
}

const FIX_SENTENCES: &[&str] = &["GGA", "GNS", "GLL", "RMC", "GSA", "GSV", "GST"];
const HEADINGS: &[&str] = &["HDT", "HDG", "HDM", "THS"];

/// The outputs of each role, in index order (the index is what [`Readings`] name).
fn specs(role: Role) -> &'static [Spec] {
    const GPS: &[Spec] = &[
        spec(
            "position",
            &["GGA", "GNS", "GLL"],
            &["GGA", "GNS", "GLL", "RMC"],
            "position",
            "topic",
            "nav.position",
        ),
        spec(
            "velocity",
            &["RMC", "VTG"],
            &["RMC", "VTG"],
            "velocity",
            "velocity_topic",
            "nav.velocity",
        ),
        spec(
            "fix",
            FIX_SENTENCES,
            FIX_SENTENCES,
            "gnss-fix",
            "fix_topic",
            "nav.fix",
        ),
        spec("time", &["ZDA"], &["ZDA"], "time", "time_topic", "nav.time"),
        spec(
            "text",
            &["TXT"],
            &["TXT"],
            "device-text",
            "text_topic",
            "device.text",
        ),
    ];
    const HEADING: &[Spec] = &[
        spec(
            "heading",
            HEADINGS,
            HEADINGS,
            "heading",
            "topic",
            "nav.heading",
        ),
        // (the attitude table's sentences are added to these)
        spec(
            "attitude",
            &["XDR"],
            &["XDR"],
            "attitude",
            "attitude_topic",
            "nav.attitude",
        ),
        spec(
            "rate",
            &["ROT"],
            &["ROT"],
            "turn-rate",
            "rate_topic",
            "nav.rate",
        ),
    ];
    const SOUNDER: &[Spec] = &[spec(
        "altitude",
        &["DBT", "DPT", "DBK"],
        &["DBT", "DPT", "DBK"],
        "altitude",
        "topic",
        "nav.altitude",
    )];
    const WIND: &[Spec] = &[spec(
        "wind",
        &["MWV", "MWD"],
        &["MWV", "MWD"],
        "wind",
        "topic",
        "env.wind",
    )];
    const LOG: &[Spec] = &[spec(
        "velocity",
        &["VHW", "VBW"],
        &["VHW", "VBW"],
        "velocity",
        "topic",
        "nav.water_velocity",
    )];
    const STEERING: &[Spec] = &[
        spec(
            "rudder",
            &["RSA"],
            &["RSA"],
            "rudder",
            "topic",
            "vehicle.rudder",
        ),
        spec(
            "xte",
            &["XTE"],
            &["XTE"],
            "cross-track",
            "xte_topic",
            "nav.xte",
        ),
    ];
    match role {
        Role::Gps => GPS,
        Role::Heading => HEADING,
        Role::Sounder => SOUNDER,
        Role::Wind => WIND,
        Role::Log => LOG,
        Role::Steering => STEERING,
    }
}

/// One output: the sentences that feed it, its dataset and topic.
pub(super) struct Output {
    /// formatters (`GGA`) or proprietary addresses (`PHTRO`), each one the driver reads
    feeds: Vec<Box<str>>,
    dataset: &'static str,
    topic: Topic,
}

/// An NMEA sensor driver: sentences in, datasets out.
pub struct Sensor {
    pub(super) role: Role,
    talkers: Option<Vec<String>>,
    pub(super) outputs: Vec<Output>,
    pub(super) source: Option<String>,
    pub(super) variation: Option<f64>,
    pub(super) offset: f64,
    /// Proprietary attitude sentences read (a heading driver's).
    pub(super) table: Table,
    /// Pitch and roll kept for an attitude.
    pub(super) combined: Combined,
    /// The parse shared with the other drivers on the line, and the line's ingress (where what
    /// cannot be read is counted), from the driver's start.
    line: Option<(Arc<Reader>, Ingress)>,
    tally: Tally,
}

/// Whether two short names (`GGA`, `PRDID`) are the same: compared byte by byte in line, a
/// library call costing more than the comparison for three letters.
#[inline]
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).all(|(x, y)| x == y)
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

/// The sentences parameter `name` lists (or `default`), each one of `readable`.
fn sentence_list(
    p: &seabus_modules::Params,
    name: &str,
    default: &[&str],
    readable: &[&str],
) -> Result<Vec<Box<str>>, FileError> {
    let Some(param) = p.get(name) else {
        return Ok(default.iter().map(|f| Box::from(*f)).collect());
    };
    let named = words(&param.value);
    if named.is_empty() {
        return Err(param.error("names no sentence"));
    }
    named
        .iter()
        .map(|w| {
            readable
                .iter()
                .find(|r| **r == w.as_str())
                .map(|r| Box::from(*r))
                .ok_or_else(|| {
                    param.error(format!(
                        "`{w}` is not a sentence this driver reads for it (it reads {})",
                        readable.join(", ")
                    ))
                })
        })
        .collect()
}

/// The attitude table a heading driver reads: the built-in one, plus the `attitude_table` file.
fn attitude_table(p: &seabus_modules::Params) -> Result<Table, FileError> {
    let table = Table::built_in();
    let Some(param) = p.get("attitude_table") else {
        return Ok(table);
    };
    let path = seabus_modules::system::beside(&param.pos, &param.value);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| param.error(format!("cannot read {}: {e}", path.display())))?;
    Ok(table.extended(Table::parse(&path.display().to_string(), &text)?))
}

impl Sensor {
    /// A driver of `role` from its parameters, with its declaration.
    pub fn new(
        p: &seabus_modules::Params,
        cat: &Catalogue,
        role: Role,
    ) -> Result<(Sensor, Declaration), FileError> {
        let table = if role == Role::Heading {
            attitude_table(p)?
        } else {
            Table::default()
        };
        let mut outputs = Vec::new();
        for s in specs(role) {
            let feeds = if s.dataset == "attitude" {
                let mut all: Vec<&str> = s.readable.to_vec();
                all.extend(table.addresses());
                sentence_list(p, s.list, &all, &all)?
            } else {
                sentence_list(p, s.list, s.default, s.readable)?
            };
            // a speed log's velocity is through the water: not on the GPS's topic
            let topic = if role == Role::Log {
                p.topic_or(s.topic_param, s.topic)?
            } else {
                p.dataset_topic_or(s.topic_param, cat, s.dataset, s.topic)?
            };
            outputs.push(Output {
                feeds,
                dataset: s.dataset,
                topic,
            });
        }
        let mut decl = Declaration::new(ModuleKind::Driver)
            .format(0, Some(Format::Bytes))
            .consumes(TopicDecl::topic(p.str("input").unwrap_or("nmea.**")))
            .format(1, Some(Format::Map));
        for o in &outputs {
            decl = decl.produces(TopicDecl::dataset(&o.topic, o.dataset).on_port(1));
        }
        let only = |r: Role| role == r;
        let sensor = Sensor {
            role,
            talkers: p.get("talkers").map(|t| words(&t.value)),
            outputs,
            source: only(Role::Gps)
                .then(|| p.str("source").map(str::to_string))
                .flatten(),
            variation: if only(Role::Heading) {
                p.parse("variation", "degrees east")?
            } else {
                None
            },
            offset: if only(Role::Sounder) {
                p.float_or("offset", 0.0)?
            } else {
                0.0
            },
            combined: Combined::new(if only(Role::Heading) {
                p.duration_or("fresh", Duration::from_secs(2))?
            } else {
                Duration::ZERO
            }),
            table,
            line: None,
            tally: Tally::new(),
        };
        Ok((sensor, decl))
    }

    /// The dataset output `i` publishes.
    pub fn dataset_of(&self, i: usize) -> Option<&'static str> {
        self.outputs.get(i).map(|o| o.dataset)
    }

    /// Whether sentences of `formatter` feed output `i`.
    pub(super) fn fed(&self, i: usize, formatter: &str) -> bool {
        self.outputs
            .get(i)
            .is_some_and(|o| o.feeds.iter().any(|f| same(f, formatter)))
    }

    /// Turns a parsed sentence into readings.
    pub fn read(&mut self, parsed: &Parsed, now: Instant) -> Readings {
        let mut out = Readings::default();
        match self.role {
            Role::Gps => self.read_gps(parsed, &mut out),
            Role::Heading => self.read_heading(parsed, now, &mut out),
            Role::Sounder => self.read_sounder(parsed, &mut out),
            Role::Wind => self.read_wind(parsed, &mut out),
            Role::Log => self.read_log(parsed, &mut out),
            Role::Steering => self.read_steering(parsed, &mut out),
        }
        out
    }
}

/// What one sentence gives: the index of an output and the dataset to publish on it.
pub type Reading = (usize, DataMap);

/// The readings of one sentence: at most three (an RMC gives a position, a velocity and a fix
/// status), kept without allocating, and why a value of it was dropped.
#[derive(Debug, Default)]
pub struct Readings([Option<Reading>; 3], Option<String>);

impl Readings {
    /// A value of the sentence out of its range: dropped (never wrapped or clamped) and said why.
    pub(super) fn out_of_range(&mut self, why: String) {
        self.1.get_or_insert(why);
    }

    /// Why a value of the sentence was dropped, if one was.
    pub fn dropped(&self) -> Option<&str> {
        self.1.as_deref()
    }

    pub(super) fn push(&mut self, r: Reading) {
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
    pub(super) fn true_heading(&self) -> Option<f64> {
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
    type IntoIter = std::iter::Flatten<std::array::IntoIter<Option<Reading>, 3>>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.into_iter().flatten()
    }
}

/// Whether `what` = `value` is within `lo`–`hi` (and finite); if not, `out` says why it is
/// dropped.
pub(super) fn in_range(what: &str, value: f64, lo: f64, hi: f64, out: &mut Readings) -> bool {
    let ok = value.is_finite() && (lo..=hi).contains(&value);
    if !ok {
        out.out_of_range(format!("{what} {value} is not within {lo}–{hi}"));
    }
    ok
}

/// `value` when it is absent or within `lo`–`hi`; an out-of-range one is dropped and said.
pub(super) fn checked(
    what: &str,
    value: Option<f64>,
    lo: f64,
    hi: f64,
    out: &mut Readings,
) -> Result<Option<f64>, ()> {
    match value {
        Some(v) if !in_range(what, v, lo, hi, out) => Err(()),
        v => Ok(v),
    }
}

impl Sensor {
    /// The parse shared by the drivers on the line (port 0) and the line's ingress, the parse told
    /// what this driver reads the first time.
    fn line(&mut self, ctx: &Context) -> Option<(Arc<Reader>, Ingress)> {
        if self.line.is_none() {
            let medium = ctx.port(0)?.medium();
            let reader = medium.shared::<Reader>();
            reader.want(
                self.outputs
                    .iter()
                    .flat_map(|o| o.feeds.iter().map(|f| &**f)),
            );
            self.line = Some((reader, medium.ingress()));
        }
        self.line.clone()
    }
}

#[async_trait]
impl Module for Sensor {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        // what this driver reads is known before its first sentence comes
        self.line(ctx);
        Ok(())
    }

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
        // framed NMEA is ASCII; anything else is no sentence (and not one a driver reads)
        let Ok(line) = std::str::from_utf8(bytes) else {
            return Ok(());
        };
        if let Some(t) = &self.talkers {
            let talker = talker(line);
            if !talker.is_empty() && !t.iter().any(|x| x == talker) {
                return Ok(());
            }
        }
        let Some((reader, ingress)) = self.line(ctx) else {
            return Ok(());
        };
        let Some(read) = reader.read(&msg, line, &ingress) else {
            return Ok(());
        };
        let Ok(parsed) = &*read else {
            return Ok(());
        };
        let readings = self.read(parsed, Instant::now());
        if let Some(why) = readings.dropped() {
            ingress.reject("out-of-range", format_args!("{}: {why}", line.trim_end()));
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
    use crate::units::{FOOT, KNOT};
    use seabus_medium::framing::nmea_sentence;
    use seabus_modules::Params;

    fn sensor(role: Role, pairs: &[(&str, &str)]) -> Sensor {
        let params = Params::from_pairs(pairs);
        let (s, _) = Sensor::new(&params, &Catalogue::built_in(), role).unwrap();
        params.finish("t").unwrap();
        s
    }

    /// What `body` gives, every dataset checked against the catalogue, and why a value of it was
    /// dropped.
    fn read_dropped(s: &mut Sensor, body: &str) -> (Vec<(usize, DataMap)>, Option<String>) {
        let line = nmea_sentence(b'$', body);
        let parsed = parse(&line).unwrap();
        let r = s.read(&parsed, Instant::now());
        let why = r.dropped().map(str::to_string);
        let out: Vec<_> = r.into_iter().collect();
        let cat = Catalogue::built_in();
        for (i, m) in &out {
            let dataset = s.outputs[*i].dataset;
            if let Err(e) = cat.validate(dataset, m) {
                panic!("{body}: {dataset}: {e}: {m:?}");
            }
        }
        (out, why)
    }

    fn read(s: &mut Sensor, body: &str) -> Vec<(usize, DataMap)> {
        read_dropped(s, body).0
    }

    /// The one dataset `body` gives on output `i`.
    fn one(s: &mut Sensor, body: &str, i: usize) -> DataMap {
        let mut on: Vec<DataMap> = read(s, body)
            .into_iter()
            .filter(|(o, _)| *o == i)
            .map(|(_, m)| m)
            .collect();
        assert_eq!(on.len(), 1, "{body} on output {i}: {on:?}");
        on.remove(0)
    }

    fn outputs(s: &mut Sensor, body: &str) -> Vec<usize> {
        read(s, body).into_iter().map(|(i, _)| i).collect()
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
        let e = bad(Role::Heading, &[("attitude", "PGRME")]);
        assert!(e.contains("(it reads XDR, PRDID, PHTRO, PSXN)"), "{e}");
    }

    #[test]
    fn gps_sentences_become_position_velocity_and_fix_status() {
        let mut g = sensor(Role::Gps, &[]);
        let body = "GPGGA,123519,4807.038,N,01131.000,E,2,08,0.9,545.4,M,46.9,M,,";
        assert_eq!(outputs(&mut g, body), [0, 2]);
        let m = one(&mut g, body, 0);
        assert_eq!(
            (
                m.get_i64("fix"),
                m.get_i64("satellites"),
                m.get_str("source")
            ),
            (Some(2), Some(8), None)
        );
        assert_eq!(
            (m.get_f64("hdop"), m.get_f64("alt")),
            (Some(0.9), Some(545.4))
        );
        let f = one(&mut g, body, 2);
        assert_eq!(
            (
                f.get_bool("valid"),
                f.get_str("sentence"),
                f.get_i64("quality")
            ),
            (Some(true), Some("GGA"), Some(2))
        );
        let rmc = "GPRMC,123519,A,4807.038,N,01131.000,E,010.0,090.0,230394,,";
        assert_eq!(
            outputs(&mut g, rmc),
            [1, 2],
            "RMC feeds velocity, not position, by default"
        );
        let v = one(&mut g, rmc, 1);
        assert!((v.get_f64("speed").unwrap() - 10.0 * KNOT).abs() < 1e-9);
        assert!((v.get_f64("east").unwrap() - 10.0 * KNOT).abs() < 1e-6);
        let mut named = sensor(Role::Gps, &[("source", "rtk")]);
        let body = "GPGGA,123519,4807.038,N,01131.000,E,4,12,0.5,5.0,M,46.9,M,,";
        assert_eq!(one(&mut named, body, 0).get_str("source"), Some("rtk"));
        // other talkers can be left out, and RMC can feed position too
        let mut only = sensor(Role::Gps, &[("talkers", "GN"), ("position", "RMC")]);
        assert!(only.talkers.as_ref().unwrap().contains(&"GN".to_string()));
        let body = "GNRMC,123519,A,4807.038,N,01131.000,E,010.0,090.0,230394,,";
        assert_eq!(outputs(&mut only, body), [0, 1, 2]);
    }

    #[test]
    fn a_fix_of_quality_zero_is_no_position_but_a_fix_status() {
        let mut gps = sensor(Role::Gps, &[]);
        let none = "GPGGA,123519,4807.038,N,01131.000,E,0,08,0.9,545.4,M,46.9,M,,";
        assert_eq!(outputs(&mut gps, none), [2]);
        let f = one(&mut gps, none, 2);
        assert_eq!(
            (f.get_bool("valid"), f.get_i64("quality")),
            (Some(false), Some(0))
        );
        let one_fix = one(
            &mut gps,
            "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
            0,
        );
        assert!((one_fix.get_f64("lat").unwrap() - 48.1173).abs() < 1e-7);
        // RMC status V, GLL V, GNS mode N: status only
        let rmc = "GPRMC,123519,V,4807.038,N,01131.000,E,010.0,090.0,230394,,";
        assert_eq!(outputs(&mut gps, rmc), [2]);
        assert_eq!(one(&mut gps, rmc, 2).get_str("status"), Some("V"));
        let gll = "GPGLL,4916.450,N,12311.120,W,225444.00,V,N";
        assert_eq!(outputs(&mut gps, gll), [2]);
        let gns = "GNGNS,101530.00,4330.4800,N,01626.4000,E,NNN,00,,,,,,V";
        assert_eq!(outputs(&mut gps, gns), [2]);
        let f = one(&mut gps, gns, 2);
        assert_eq!(
            (f.get_bool("valid"), f.get_str("mode"), f.get_str("status")),
            (Some(false), Some("NNN"), Some("V"))
        );
    }

    #[test]
    fn gns_with_a_mode_per_constellation_gives_a_position_with_its_mode() {
        let mut gps = sensor(Role::Gps, &[]);
        let body = "GNGNS,101530.00,4330.4800,N,01626.4000,W,AAN,14,0.7,12.5,41.2,,,S";
        let p = one(&mut gps, body, 0);
        assert!((p.get_f64("lat").unwrap() - (43.0 + 30.48 / 60.0)).abs() < 1e-9);
        assert!((p.get_f64("lon").unwrap() + (16.0 + 26.4 / 60.0)).abs() < 1e-9);
        assert_eq!(
            (p.get_str("mode"), p.get_i64("satellites")),
            (Some("AAN"), Some(14))
        );
        let f = one(&mut gps, body, 2);
        assert_eq!(
            (f.get_bool("valid"), f.get_str("status")),
            (Some(true), Some("S"))
        );
    }

    #[test]
    fn a_speed_without_a_course_is_a_velocity_without_a_course() {
        let mut gps = sensor(Role::Gps, &[]);
        let v = one(
            &mut gps,
            "GPRMC,123519,A,4807.038,N,01131.000,E,0.2,,230394,,",
            1,
        );
        assert!((v.get_f64("speed").unwrap() - 0.2 * KNOT).abs() < 1e-12);
        assert_eq!((v.get_f64("course"), v.get_f64("north")), (None, None));
        let v = one(&mut gps, "GPVTG,,T,,M,0.1,N,0.2,K,A", 1);
        assert!((v.get_f64("speed").unwrap() - 0.1 * KNOT).abs() < 1e-12);
        assert_eq!(v.get_str("reference"), Some("ground"));
        // no speed: nothing
        assert_eq!(
            outputs(&mut gps, "GPVTG,,T,,M,,N,,K,N"),
            Vec::<usize>::new()
        );
    }

    #[test]
    fn satellites_dop_errors_time_and_text() {
        let mut gps = sensor(Role::Gps, &[]);
        let f = one(&mut gps, "GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1", 2);
        assert_eq!(
            (
                f.get_str("fix_type"),
                f.get_i64("satellites"),
                f.get_bool("valid")
            ),
            (Some("3d"), Some(5), Some(true))
        );
        assert_eq!(
            (f.get_f64("pdop"), f.get_f64("hdop"), f.get_f64("vdop")),
            (Some(2.5), Some(1.3), Some(2.1))
        );
        let f = one(&mut gps, "GPGSA,A,1,,,,,,,,,,,,,,,", 2);
        assert_eq!(
            (f.get_str("fix_type"), f.get_bool("valid")),
            (Some("none"), Some(false))
        );
        let f = one(
            &mut gps,
            "GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,292,00",
            2,
        );
        assert_eq!(
            (f.get_i64("in_view"), f.get_str("constellation")),
            (Some(11), Some("GPS"))
        );
        // the group's other sentences repeat the count: one status per group
        assert!(
            read(
                &mut gps,
                "GPGSV,3,2,11,14,25,170,00,16,57,208,39,18,67,296,40,19,40,246,00"
            )
            .is_empty()
        );
        let f = one(
            &mut gps,
            "GPGST,172814.0,0.006,0.023,0.020,273.6,0.023,0.020,0.031",
            2,
        );
        assert_eq!(
            (
                f.get_f64("lat_sigma"),
                f.get_f64("lon_sigma"),
                f.get_f64("alt_sigma")
            ),
            (Some(0.023), Some(0.02), Some(0.031))
        );
        let t = one(&mut gps, "GPZDA,101530.50,21,11,2026,01,30", 3);
        assert_eq!(t.get_f64("utc"), Some(1_795_256_130.5));
        assert_eq!(t.get_i64("zone"), Some(90));
        let x = one(&mut gps, "GPTXT,01,01,02,ANTENNA OK", 4);
        assert_eq!(
            (x.get_str("text"), x.get_str("kind"), x.get_str("talker")),
            (Some("ANTENNA OK"), Some("notice"), Some("GP"))
        );
        let (out, why) = read_dropped(&mut gps, "GPZDA,101530.50,21,11,1970,,");
        assert!(out.is_empty());
        assert_eq!(why.as_deref(), Some("year 1970 is not within 1980–2200"));
    }

    #[test]
    fn headings_are_corrected_and_attitude_needs_fresh_pitch_and_roll() {
        let mut h = sensor(Role::Heading, &[]);
        let m = one(&mut h, "HCHDG,100.0,2.0,W,5.0,E", 0);
        assert_eq!(
            (m.get_f64("heading"), m.get_bool("magnetic")),
            (Some(103.0), Some(false))
        );
        assert_eq!(
            (m.get_f64("deviation"), m.get_f64("variation")),
            (Some(-2.0), Some(5.0))
        );
        assert_eq!(
            one(&mut h, "HCHDM,10.0,M", 0).get_bool("magnetic"),
            Some(true)
        );
        assert!(read(&mut h, "HCXDR,A,2.5,D,PITCH,A,-1.0,D,ROLL").is_empty());
        assert_eq!(
            outputs(&mut h, "HEHDT,359.5,T"),
            [0, 1],
            "heading, and attitude"
        );
        let a = one(&mut h, "HEHDT,359.5,T", 1);
        assert_eq!(
            (a.get_f64("yaw"), a.get_f64("pitch"), a.get_f64("roll")),
            (Some(359.5), Some(2.5), Some(-1.0))
        );
        assert_eq!(a.get_str("sources"), Some("yaw HDT, pitch XDR, roll XDR"));
        assert_eq!(
            outputs(&mut h, "HCHDM,10.0,M"),
            [0],
            "no attitude from a magnetic heading"
        );
        let mut with_var = sensor(Role::Heading, &[("variation", "-3")]);
        let m = one(&mut with_var, "HCHDM,10.0,M", 0);
        assert_eq!(
            (m.get_f64("heading"), m.get_bool("magnetic")),
            (Some(7.0), Some(false))
        );
        let t = one(&mut h, "HETHS,123.4,E", 0);
        assert_eq!(
            (t.get_f64("heading"), t.get_str("mode")),
            (Some(123.4), Some("E"))
        );
        assert!(read(&mut h, "HETHS,123.4,V").is_empty(), "not valid");
    }

    #[test]
    fn pitch_and_roll_from_separate_sentences_make_an_attitude_within_the_window() {
        let mut h = sensor(Role::Heading, &[("fresh", "500ms")]);
        assert!(read(&mut h, "IIXDR,A,1.5,D,PITCH").is_empty());
        assert_eq!(outputs(&mut h, "HEHDT,90.0,T"), [0], "no roll yet");
        assert!(read(&mut h, "IIXDR,A,-3.0,D,ROLL").is_empty());
        let a = one(&mut h, "HEHDT,90.0,T", 1);
        assert_eq!(
            (a.get_f64("pitch"), a.get_f64("roll")),
            (Some(1.5), Some(-3.0))
        );
        // a maker's sentence: iXblue's pitch and roll, then a heading
        assert!(read(&mut h, "PHTRO,2.00,P,0.50,T").is_empty());
        let a = one(&mut h, "HEHDT,91.0,T", 1);
        assert_eq!(
            (a.get_f64("pitch"), a.get_f64("roll")),
            (Some(-2.0), Some(0.5))
        );
        assert_eq!(
            a.get_str("sources"),
            Some("yaw HDT, pitch PHTRO, roll PHTRO")
        );
        // one that gives all three is a heading and an attitude at once
        let out = read(&mut h, "PRDID,-1.25,2.50,180.00");
        assert_eq!(out.iter().map(|(i, _)| *i).collect::<Vec<_>>(), [0, 1]);
        assert_eq!(
            out[1].1.get_str("sources"),
            Some("yaw PRDID, pitch PRDID, roll PRDID")
        );
        // past the window: no attitude
        std::thread::sleep(Duration::from_millis(600));
        assert_eq!(outputs(&mut h, "HEHDT,92.0,T"), [0]);
        let (out, why) = read_dropped(&mut h, "IIXDR,A,95.0,D,PITCH");
        assert!(out.is_empty());
        assert_eq!(why.as_deref(), Some("pitch 95 is not within -90–90"));
    }

    #[test]
    fn rate_of_turn_wind_water_speed_rudder_and_cross_track() {
        let mut h = sensor(Role::Heading, &[]);
        let r = one(&mut h, "TIROT,-30.0,A", 2);
        assert_eq!(r.get_f64("rate"), Some(-0.5));
        assert!(read(&mut h, "TIROT,-30.0,V").is_empty());
        let mut w = sensor(Role::Wind, &[]);
        let m = one(&mut w, "WIMWV,045.0,R,10.0,N,A", 0);
        assert_eq!(
            (m.get_f64("angle"), m.get_str("reference")),
            (Some(45.0), Some("apparent"))
        );
        assert!((m.get_f64("speed").unwrap() - 10.0 * KNOT).abs() < 1e-9);
        let m = one(&mut w, "WIMWV,270.0,T,5.5,M,A", 0);
        assert_eq!(
            (m.get_f64("speed"), m.get_str("reference")),
            (Some(5.5), Some("true"))
        );
        assert!(read(&mut w, "WIMWV,270.0,T,5.5,M,V").is_empty());
        let m = one(&mut w, "WIMWD,180.0,T,175.0,M,12.0,N,6.2,M", 0);
        assert_eq!(
            (
                m.get_f64("direction"),
                m.get_f64("magnetic_direction"),
                m.get_f64("speed")
            ),
            (Some(180.0), Some(175.0), Some(6.2))
        );
        let mut log = sensor(Role::Log, &[]);
        let v = one(&mut log, "VWVHW,245.1,T,241.3,M,4.0,N,7.4,K", 0);
        assert!((v.get_f64("speed").unwrap() - 4.0 * KNOT).abs() < 1e-12);
        assert_eq!(v.get_str("reference"), Some("water"));
        let v = one(&mut log, "VDVBW,3.0,-0.4,A,3.1,-0.5,A", 0);
        assert!((v.get_f64("surge").unwrap() - 3.0 * KNOT).abs() < 1e-12);
        assert!((v.get_f64("sway").unwrap() + 0.4 * KNOT).abs() < 1e-12);
        assert!(read(&mut log, "VDVBW,3.0,-0.4,V,3.1,-0.5,A").is_empty());
        let mut st = sensor(Role::Steering, &[]);
        let r = one(&mut st, "AGRSA,-12.5,A,,V", 0);
        assert_eq!(
            (r.get_f64("angle"), r.get_f64("port_angle")),
            (Some(-12.5), None)
        );
        let r = one(&mut st, "AGRSA,10.0,A,9.5,A", 0);
        assert_eq!(r.get_f64("port_angle"), Some(9.5));
        let x = one(&mut st, "GPXTE,A,A,0.67,L,N,D", 1);
        assert!((x.get_f64("error").unwrap() - 0.67 * 1852.0).abs() < 1e-9);
        assert_eq!(x.get_str("mode"), Some("D"));
        let x = one(&mut st, "GPXTE,A,A,0.10,R,N", 1);
        assert!((x.get_f64("error").unwrap() + 185.2).abs() < 1e-9);
        assert!(read(&mut st, "GPXTE,V,A,0.10,R,N").is_empty());
    }

    #[test]
    fn sounder_depths_become_altitude() {
        let mut s = sensor(Role::Sounder, &[("offset", "0.5")]);
        assert_eq!(
            one(&mut s, "SDDBT,24.6,f,7.5,M,4.1,F", 0).get_f64("altitude"),
            Some(8.0)
        );
        assert_eq!(
            one(&mut s, "SDDPT,17.5,0.3,100", 0).get_f64("altitude"),
            Some(18.0)
        );
        // a keel offset (negative) is read; the altitude is the depth below the transducer
        assert_eq!(
            one(&mut s, "SDDPT,12.0,-1.5", 0).get_f64("altitude"),
            Some(12.5)
        );
        let a = one(&mut s, "SDDBT,10.0,f,,M,,F", 0)
            .get_f64("altitude")
            .unwrap();
        assert!((a - (10.0 * FOOT + 0.5)).abs() < 1e-9);
    }

    #[test]
    fn values_out_of_range_are_dropped_with_the_reason_never_wrapped_or_clamped() {
        type Case = (
            Role,
            &'static [(&'static str, &'static str)],
            &'static str,
            &'static str,
        );
        let cases: &[Case] = &[
            (
                Role::Heading,
                &[],
                "HEHDT,400.0,T",
                "heading 400 is not within 0–360",
            ),
            (
                Role::Gps,
                &[],
                "GPVTG,720.0,T,,M,5.0,N,9.3,K",
                "course 720 is not within 0–360",
            ),
            (
                Role::Gps,
                &[],
                "GPVTG,90.0,T,,M,500.0,N,,K",
                "speed (knots) 500 is not within 0–150",
            ),
            (
                Role::Sounder,
                &[],
                "SDDBT,,f,-1.5,M,,F",
                "depth -1.5 is not within 0–12000",
            ),
            (
                Role::Sounder,
                &[("offset", "-2.0")],
                "SDDBT,,f,1.5,M,,F",
                "depth with the offset -0.5 is not within 0–12000",
            ),
            (
                Role::Gps,
                &[],
                "GPGSA,A,3,04,05,,,,,,,,,,,120.0,1.3,2.1",
                "PDOP 120 is not within 0–99.99",
            ),
            (
                Role::Gps,
                &[],
                "GPGGA,123519,4807.038,N,01131.000,E,1,08,-0.9,545.4,M,46.9,M,,",
                "HDOP -0.9 is not within 0–99.99",
            ),
            (
                Role::Wind,
                &[],
                "WIMWV,045.0,R,300.0,M,A",
                "wind speed (m/s) 300 is not within 0–120",
            ),
            (
                Role::Steering,
                &[],
                "AGRSA,120.0,A,,V",
                "rudder 120 is not within -90–90",
            ),
        ];
        for (role, params, body, reason) in cases {
            let mut s = sensor(*role, params);
            let (out, why) = read_dropped(&mut s, body);
            assert!(out.is_empty(), "{body}: {out:?}");
            assert_eq!(why.as_deref(), Some(*reason), "{body}");
        }
        let mut compass = sensor(Role::Heading, &[]);
        let (out, why) = read_dropped(&mut compass, "HEHDT,359.9,T");
        assert_eq!((out.len(), why), (1, None));
    }
}
