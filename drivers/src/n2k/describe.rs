//! NMEA 2000 for people: the frames of a CAN medium reassembled and decoded into PGNs shown with
//! their names and their fields' names and units, as `seabus spy --n2k` prints them.
//!
//! ```text
//! 127250 Vessel Heading from 35 to 255 prio 2: SID=7, Heading=70.73 deg, Deviation=-0.7 deg, Variation=2.61 deg, Reference=Magnetic
//! ```
//!
//! [`Listener`] takes CAN frames and gives [`Described`] PGNs; what it cannot reassemble is
//! counted by the reasons of [`super::frame`] ([`Listener::take_rejections`]).

use super::frame::{Assembler, Header, Limits, Rejection};
use super::pgn::{Database, Kind};
use super::{builtin, json};
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Value};
use seabus_medium_can::frame::{CanFrame, FrameKind};
use std::fmt;
use std::path::Path;
use tokio::time::Instant;

/// A decoded PGN, with the names and units of its fields.
#[derive(Debug, Clone, PartialEq)]
pub struct Described {
    /// Its header.
    pub header: Header,
    /// canboat's identifier of the PGN (`vesselHeading`), or its number for an unknown PGN.
    pub id: String,
    /// Its description (`Vessel Heading`), empty for an unknown PGN.
    pub description: String,
    /// Each field present: identifier, name, value (in seabus's units), unit.
    pub fields: Vec<(String, String, Value, String)>,
}

impl Described {
    /// Its topic as the `nmea2000` driver names it: `n2k.SOURCE.ID`.
    pub fn topic(&self) -> String {
        format!("n2k.{}.{}", self.header.source, self.id)
    }

    /// The fields as a datamap: `Name (unit)` → value (numbers to six decimals), for a table.
    pub fn named(&self) -> DataMap {
        let mut m = DataMap::with_capacity(self.fields.len());
        for (_, name, value, unit) in &self.fields {
            let value = match value {
                Value::Float(x) => Value::Float((x * 1e6).round() / 1e6),
                v => v.clone(),
            };
            let key = if unit.is_empty() {
                name.clone()
            } else {
                format!("{name} ({unit})")
            };
            m.push(key, value);
        }
        m
    }

    /// Everything as a datamap: `pgn`, `id`, `description`, `src`, `dst`, `prio`, `fields`
    /// (identifier → value), `names` (identifier → name) and `units` (identifier → unit, for
    /// the fields that have one).
    pub fn to_map(&self) -> DataMap {
        let h = self.header;
        let (mut fields, mut names, mut units) = (DataMap::new(), DataMap::new(), DataMap::new());
        for (id, name, value, unit) in &self.fields {
            fields.push(id.clone(), value.clone());
            names.push(id.clone(), Value::from(name.clone()));
            if !unit.is_empty() {
                units.push(id.clone(), Value::from(unit.clone()));
            }
        }
        DataMap::new()
            .and("pgn", Value::Int(i64::from(h.pgn)))
            .and("id", Value::from(self.id.clone()))
            .and("description", Value::from(self.description.clone()))
            .and("src", Value::Int(i64::from(h.source)))
            .and("dst", Value::Int(i64::from(h.destination)))
            .and("prio", Value::Int(i64::from(h.priority)))
            .and("fields", Value::Map(fields))
            .and("names", Value::Map(names))
            .and("units", Value::Map(units))
    }
}

impl fmt::Display for Described {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let h = self.header;
        let what = if self.description.is_empty() {
            "(not in the database)"
        } else {
            &self.description
        };
        write!(
            f,
            "{} {what} from {} to {} prio {}:",
            h.pgn, h.source, h.destination, h.priority
        )?;
        for (i, (_, name, value, unit)) in self.fields.iter().enumerate() {
            let sep = if i == 0 { " " } else { ", " };
            let value = match value {
                Value::Float(x) => format!("{}", (x * 1e6).round() / 1e6),
                Value::Str(s) => s.to_string(),
                other => other.to_string(),
            };
            if unit.is_empty() {
                write!(f, "{sep}{name}={value}")?;
            } else {
                write!(f, "{sep}{name}={value} {unit}")?;
            }
        }
        Ok(())
    }
}

/// Turns CAN frames into described PGNs.
#[derive(Debug)]
pub struct Listener {
    db: Database,
    assembler: Assembler,
}

impl Listener {
    /// A listener with the built-in PGNs and, when given, canboat's database file (its
    /// definitions first).
    pub fn new(database: Option<&Path>) -> Result<Listener, FileError> {
        let built_in = builtin::database();
        let db = match database {
            None => built_in,
            Some(path) => {
                let mut db = json::load(path)?;
                db.fill_from(&built_in);
                db
            }
        };
        Ok(Listener {
            db,
            assembler: Assembler::new(Limits::default()),
        })
    }

    /// What the frames refused since the last call were.
    pub fn take_rejections(&mut self) -> Vec<Rejection> {
        self.assembler.take_rejections()
    }

    /// Takes one frame; gives the PGN it completes, if any.
    pub fn push(&mut self, frame: &CanFrame, now: Instant) -> Option<Described> {
        if frame.kind() == FrameKind::Error {
            return None;
        }
        let db = &self.db;
        let msg = self.assembler.push(
            frame.id(),
            frame.is_extended(),
            matches!(frame.kind(), FrameKind::Remote { .. }),
            frame.payload(),
            |pgn| db.packet(pgn),
            now,
        )?;
        let Some(def) = self.db.select(msg.header.pgn, &msg.data) else {
            return Some(Described {
                header: msg.header,
                id: msg.header.pgn.to_string(),
                description: String::new(),
                fields: vec![(
                    "data".into(),
                    "Data".into(),
                    Value::Bytes(msg.data),
                    String::new(),
                )],
            });
        };
        let decoded = def.decode(&msg.data).map;
        let mut fields = Vec::with_capacity(decoded.len());
        for f in def
            .fields
            .iter()
            .filter(|f| !matches!(f.kind, Kind::Reserved | Kind::Spare))
        {
            if let Some(v) = decoded.get(&f.id) {
                fields.push((
                    f.id.to_string(),
                    f.name.to_string(),
                    v.clone(),
                    f.seabus_unit().to_string(),
                ));
            }
        }
        for key in ["list", "list2"] {
            if let Some(v) = decoded.get(key) {
                fields.push((key.into(), key.into(), v.clone(), String::new()));
            }
        }
        Some(Described {
            header: msg.header,
            id: def.id.to_string(),
            description: def.description.to_string(),
            fields,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_heading_is_shown_with_its_names_and_units() {
        let mut l = Listener::new(None).unwrap();
        let frame = CanFrame::data(
            0x09F1_1223,
            true,
            &[1, 0x5C, 0x3D, 0xFF, 0x7F, 0xFF, 0x7F, 0xFC],
        )
        .unwrap();
        let d = l.push(&frame, Instant::now()).unwrap();
        assert_eq!(
            d.to_string(),
            "127250 Vessel Heading from 35 to 255 prio 2: SID=1, Heading=90.00021 deg, Reference=True"
        );
        assert_eq!(d.topic(), "n2k.35.vesselHeading");
        assert_eq!(
            d.named().get_str("Reference"),
            Some("True"),
            "{:?}",
            d.named()
        );
        let m = d.to_map();
        assert_eq!(
            m.get("units")
                .and_then(Value::as_map)
                .unwrap()
                .get_str("heading"),
            Some("deg")
        );
    }

    #[test]
    fn a_fast_packet_is_shown_once_whole_and_a_broken_one_counted() {
        let mut l = Listener::new(None).unwrap();
        let db = builtin::database();
        let data = db.definitions(129029)[0]
            .encode(&DataMap::new().and("latitude", Value::Float(43.5)))
            .unwrap();
        let frames = super::super::frame::fast_frames(2, &data);
        let id = 0x0DF8_0507;
        let now = Instant::now();
        let mut got = Vec::new();
        for f in &frames {
            got.extend(l.push(&CanFrame::data(id, true, f).unwrap(), now));
        }
        assert_eq!(got.len(), 1);
        assert!(
            got[0]
                .to_string()
                .starts_with("129029 GNSS Position Data from 7 to 255 prio 3: Latitude=43.5 deg"),
            "{}",
            got[0]
        );
        for (i, f) in frames.iter().enumerate() {
            if i != 2 {
                assert!(l.push(&CanFrame::data(id, true, f).unwrap(), now).is_none());
            }
        }
        let r = l.take_rejections();
        assert_eq!(r[0].reason, "n2k-fast-packet-lost-frame");
    }
}
