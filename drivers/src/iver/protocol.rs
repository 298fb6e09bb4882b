//! The Iver2/Iver3 frontseat "Remote Helm" protocol: the NMEA-style ASCII sentences that an Iver
//! AUV's frontseat computer (the maker's vehicle control software) and a backseat computer
//! exchange over serial or TCP, read and written here.
//!
//! The protocol is defined by OceanServer's Remote Helm documentation for the vehicle, of which no
//! public copy is available. The facts used here (sentence layouts and field order, units, the
//! `$ACK` message-type and error numbers, the `$OSI` modes and error states that [`error_text`],
//! [`error_state_text`] and [`mode_text`] summarise) were gathered from open software that speaks
//! the protocol: the Iver frontseat driver of the Goby3 autonomy framework, the Iver code of the
//! University of Sydney's acfr-lcm, and public tools of the University of Southern Mississippi.
//! Where these sources disagree, the choice made here is written beside it.
//!
//! Everything here works on one whole sentence (with its checksum, as the serial medium's NMEA
//! framing hands it out) and never panics. Depths on the wire are in feet unless the Remote Helm
//! major version is 5 or later, where `$OMS` and `$OMW` depths are in metres; `$OSI`, `$C` and the
//! altimeter stay in feet in every version.

use crate::nmea::sentence::{self, Sentence, num, num_field};
pub use crate::nmea::sentence::{address, fields};
use crate::units::FOOT;
use seabus_medium::framing::nmea_sentence;
use seabus_modules::geo::wrap360;
use std::fmt;
use thiserror::Error;

/// Why a Remote Helm sentence could not be read.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{sentence}: {reason}")]
pub struct RhError {
    /// The sentence (shortened).
    pub sentence: String,
    /// What was wrong.
    pub reason: String,
}

fn rh_err(sentence: &str, reason: impl fmt::Display) -> RhError {
    RhError {
        sentence: sentence.chars().take(100).collect(),
        reason: reason.to_string(),
    }
}

/// The longest timeout, seconds, a Remote Helm command may carry.
pub const MAX_TIMEOUT: f64 = 120.0;

/// Depth units of a Remote Helm version.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthUnits {
    /// Remote Helm major version below 5.
    Feet,
    /// Remote Helm 5 and later.
    Metres,
}

impl DepthUnits {
    /// The units a Remote Helm major version uses in `$OMS` and `$OMW`.
    pub fn of_version(major: u32) -> DepthUnits {
        if major >= 5 {
            DepthUnits::Metres
        } else {
            DepthUnits::Feet
        }
    }

    /// A depth in metres, in these units.
    pub fn from_metres(self, m: f64) -> f64 {
        match self {
            DepthUnits::Feet => m / FOOT,
            DepthUnits::Metres => m,
        }
    }

    /// A depth in these units, in metres.
    pub fn to_metres(self, v: f64) -> f64 {
        match self {
            DepthUnits::Feet => v * FOOT,
            DepthUnits::Metres => v,
        }
    }
}

/// `$OSI`: vehicle state.
#[derive(Debug, Clone, PartialEq)]
pub struct Osi {
    /// Fin and motor positions, 10 hex digits (yaw-top, yaw-bottom, pitch-left, pitch-right, motor).
    pub fins: String,
    /// Mode letters (`N`, `S`, `P`, `M`, `m`, `mP`, `Mp`, `A`, `W`).
    pub mode: String,
    /// Next waypoint.
    pub next_waypoint: Option<i64>,
    /// Latitude, degrees.
    pub lat: Option<f64>,
    /// Longitude, degrees.
    pub lon: Option<f64>,
    /// Speed, knots.
    pub speed_knots: Option<f64>,
    /// Distance to the next waypoint, metres.
    pub distance_to_waypoint: Option<f64>,
    /// Error state: `N` for none, else codes such as `Sop` or `Sle`.
    pub error: String,
    /// Altimeter, feet.
    pub altimeter_feet: Option<f64>,
    /// Park time, seconds (`P<seconds>`).
    pub park_time: Option<f64>,
    /// Magnetic declination, degrees.
    pub declination: Option<f64>,
    /// Mission name.
    pub mission: String,
    /// Remaining mission time.
    pub remaining: Option<f64>,
    /// True heading, degrees.
    pub heading: Option<f64>,
    /// Depth from the surface, feet.
    pub depth_feet: Option<f64>,
    /// Fields 16 to 21 of the Iver3 form (21 fields or more); `None` for the short Iver2 form
    /// and for any other layout.
    pub iver3: Option<Iver3Osi>,
    /// Fields after those read, as sent: after the 21st in the Iver3 form, after the 15th in any
    /// other (their meaning differs between Remote Helm versions).
    pub extra: Vec<String>,
}

/// The fields an Iver3 (Remote Helm 5) `$OSI` carries after the 15th.
///
/// One Iver3 capture reads `…,<depth>,76,False,iver3-3082,5.4,True,False`.
#[derive(Debug, Clone, PartialEq)]
pub struct Iver3Osi {
    /// Field 16: battery, percent (0–100), `None` when empty.
    pub battery_percent: Option<f64>,
    /// Field 17: the safety return path (SRP) flag.
    pub srp: bool,
    /// Field 18: the vehicle's name.
    pub vehicle: String,
    /// Field 19: the Remote Helm / firmware version, as text.
    pub version: String,
    /// Fields 20 and 21: two more flags, whose meaning no open source documents; as sent.
    pub flags: [bool; 2],
}

/// How many fields the Iver3 `$OSI` has.
pub const IVER3_OSI_FIELDS: usize = 21;

impl Osi {
    /// The battery percent, when this `$OSI` carries one (the Iver3 form).
    pub fn battery_percent(&self) -> Option<f64> {
        self.iver3.as_ref().and_then(|i| i.battery_percent)
    }
}

/// `$C`: compass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compass {
    /// Heading, degrees.
    pub heading: f64,
    /// Pitch, degrees.
    pub pitch: f64,
    /// Roll, degrees.
    pub roll: f64,
    /// Temperature, °C.
    pub temperature: Option<f64>,
    /// Depth, feet.
    pub depth_feet: Option<f64>,
}

/// `$OPI`: power.
#[derive(Debug, Clone, PartialEq)]
pub struct Opi {
    /// Battery, percent.
    pub percent: Option<f64>,
    /// Energy remaining, Wh.
    pub remaining_wh: Option<f64>,
    /// Power, W.
    pub power_w: Option<f64>,
    /// Volts.
    pub volts: Option<f64>,
    /// Current, A (positive while charging).
    pub current: Option<f64>,
    /// Minutes to full (charging) or to empty.
    pub minutes: Option<f64>,
    /// `C` charging, `D` discharging, `F` full.
    pub state: String,
    /// A leak is detected.
    pub leak: bool,
}

/// `$ACK`: acknowledgement of a backseat command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ack {
    /// Code of the acknowledged message type ([`Command::ack_code`]).
    pub msg_type: u32,
    /// 0 accepted, 1 refused.
    pub status: u32,
    /// Error number when refused ([`error_text`]).
    pub error: u32,
}

/// `$DVL`: Doppler velocity log; values of −3200 or less mean "invalid" and are `None`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dvl {
    /// Forward velocity, m/s.
    pub vx: Option<f64>,
    /// Sideways velocity, m/s.
    pub vy: Option<f64>,
    /// Vertical velocity, m/s.
    pub vz: Option<f64>,
    /// Distance run forward, m.
    pub xdist: Option<f64>,
    /// Distance run sideways, m.
    pub ydist: Option<f64>,
    /// Depth from the surface, m.
    pub depth: Option<f64>,
    /// Altitude, m.
    pub altitude: Option<f64>,
}

/// A sentence from the frontseat.
#[derive(Debug, Clone, PartialEq)]
pub enum FromFront {
    /// `$OSI`.
    Osi(Box<Osi>),
    /// `$C…`.
    Compass(Compass),
    /// `$OPI`.
    Opi(Opi),
    /// `$ACK`.
    Ack(Ack),
    /// `$DVL`.
    Dvl(Dvl),
    /// RMC from any talker (`$GPRMC`, `$GNRMC`, …), read by the NMEA parser.
    Rmc(nmea::sentences::RmcData),
    /// Another sentence, by address.
    Other(String),
}

fn not_a_number(line: &str, i: usize, what: &str, s: &str) -> RhError {
    rh_err(
        line,
        format!("field {} ({what}) `{s}` is not a number", i + 1),
    )
}

fn req_num(line: &str, f: &[&str], i: usize, what: &str) -> Result<f64, RhError> {
    let s = f.get(i).copied().unwrap_or("");
    num(s).ok_or_else(|| not_a_number(line, i, what, s))
}

fn opt_num(line: &str, f: &[&str], i: usize, what: &str) -> Result<Option<f64>, RhError> {
    num_field(f, i).map_err(|s| not_a_number(line, i, what, s))
}

fn text(f: &[&str], i: usize) -> String {
    f.get(i).map(|s| s.trim().to_string()).unwrap_or_default()
}

/// Reads a sentence from the frontseat.
pub fn parse_front(line: &str) -> Result<FromFront, RhError> {
    if !line.is_ascii() || !line.starts_with('$') {
        return Err(rh_err(line, "not a Remote Helm sentence"));
    }
    let addr = address(line);
    Ok(match addr {
        "OSI" => {
            let f = fields(line);
            if f.len() < 15 {
                return Err(rh_err(
                    line,
                    format!("$OSI has {} fields, at least 15 were expected", f.len()),
                ));
            }
            let (iver3, read) = if f.len() >= IVER3_OSI_FIELDS {
                (Some(parse_iver3_osi(line, &f)?), IVER3_OSI_FIELDS)
            } else {
                (None, 15)
            };
            let park = text(&f, 9);
            let park_time = match park.strip_prefix('P') {
                Some(p) => num(p),
                None => num(&park),
            };
            FromFront::Osi(Box::new(Osi {
                fins: text(&f, 0),
                mode: text(&f, 1),
                next_waypoint: opt_num(line, &f, 2, "next waypoint")?.map(|w| w as i64),
                lat: opt_num(line, &f, 3, "latitude")?,
                lon: opt_num(line, &f, 4, "longitude")?,
                speed_knots: opt_num(line, &f, 5, "speed")?,
                distance_to_waypoint: opt_num(line, &f, 6, "distance to waypoint")?,
                error: text(&f, 7),
                altimeter_feet: opt_num(line, &f, 8, "altimeter")?,
                park_time,
                declination: opt_num(line, &f, 10, "declination")?,
                mission: text(&f, 11),
                remaining: opt_num(line, &f, 12, "remaining time")?,
                heading: opt_num(line, &f, 13, "true heading")?,
                depth_feet: opt_num(line, &f, 14, "depth")?,
                iver3,
                extra: f.iter().skip(read).map(|s| s.trim().to_string()).collect(),
            }))
        }
        "OPI" => {
            let f = fields(line);
            FromFront::Opi(Opi {
                percent: opt_num(line, &f, 0, "battery percent")?,
                remaining_wh: opt_num(line, &f, 1, "remaining energy")?,
                power_w: opt_num(line, &f, 2, "power")?,
                volts: opt_num(line, &f, 3, "volts")?,
                current: opt_num(line, &f, 4, "current")?,
                minutes: opt_num(line, &f, 5, "minutes")?,
                state: text(&f, 6),
                leak: text(&f, 7) == "1",
            })
        }
        "ACK" => {
            let f = fields(line);
            let int = |i: usize, what: &str| -> Result<u32, RhError> {
                let s = f.get(i).map(|s| s.trim()).unwrap_or("");
                s.parse().map_err(|_| {
                    rh_err(
                        line,
                        format!("field {} ({what}) `{s}` is not a whole number", i + 1),
                    )
                })
            };
            FromFront::Ack(Ack {
                msg_type: int(0, "message type")?,
                status: int(1, "status")?,
                error: int(2, "error number")?,
            })
        }
        "DVL" => {
            let f = fields(line);
            let v = |i: usize, what: &str| -> Result<Option<f64>, RhError> {
                Ok(opt_num(line, &f, i, what)?.filter(|x| *x > -3200.0))
            };
            FromFront::Dvl(Dvl {
                vx: v(0, "vx")?,
                vy: v(1, "vy")?,
                vz: v(2, "vz")?,
                xdist: v(3, "xdist")?,
                ydist: v(4, "ydist")?,
                depth: v(5, "depth")?,
                altitude: v(6, "altitude")?,
            })
        }
        "C" => FromFront::Compass(parse_compass(line)?),
        rmc if rmc.len() == 5 && rmc.ends_with("RMC") => match sentence::parse(line) {
            Ok(p) => match p.sentence {
                Sentence::Rmc(r) => FromFront::Rmc(r),
                _ => FromFront::Other(rmc.to_string()),
            },
            Err(e) => return Err(rh_err(line, e.reason)),
        },
        other => FromFront::Other(other.to_string()),
    })
}

/// A `True`/`False` field (any case; `1`/`0` too).
fn flag(line: &str, f: &[&str], i: usize, what: &str) -> Result<bool, RhError> {
    let s = f.get(i).map_or("", |s| s.trim());
    if s.eq_ignore_ascii_case("true") || s == "1" {
        Ok(true)
    } else if s.eq_ignore_ascii_case("false") || s == "0" {
        Ok(false)
    } else {
        Err(rh_err(
            line,
            format!("field {} ({what}) `{s}` is not True or False", i + 1),
        ))
    }
}

/// Fields 16 to 21 of an Iver3 `$OSI`: battery percent, SRP flag, vehicle name, version, two flags.
fn parse_iver3_osi(line: &str, f: &[&str]) -> Result<Iver3Osi, RhError> {
    let battery_percent = opt_num(line, f, 15, "battery percent")?;
    if let Some(pc) = battery_percent.filter(|pc| !(0.0..=100.0).contains(pc)) {
        return Err(rh_err(
            line,
            format!("field 16 (battery percent) `{pc}` is not 0 to 100"),
        ));
    }
    let vehicle = text(f, 17);
    if vehicle.is_empty() {
        return Err(rh_err(line, "field 18 (vehicle name) is empty"));
    }
    Ok(Iver3Osi {
        battery_percent,
        srp: flag(line, f, 16, "SRP flag")?,
        vehicle,
        version: text(f, 18),
        flags: [flag(line, f, 19, "flag 20")?, flag(line, f, 20, "flag 21")?],
    })
}

/// Reads `$C<heading>P<pitch>R<roll>T<temp>D<depth>*hh`.
fn parse_compass(line: &str) -> Result<Compass, RhError> {
    let body = line.get(2..).unwrap_or("");
    let body = body.rsplit_once('*').map_or(body, |(b, _)| b);
    // split at the letters: the value before the first letter is the heading
    let mut values: Vec<(char, &str)> = Vec::new();
    let mut key = 'C';
    let mut start = 0;
    for (i, c) in body.char_indices() {
        if c.is_ascii_alphabetic() {
            values.push((key, &body[start..i]));
            key = c;
            start = i + 1;
        }
    }
    values.push((key, &body[start..]));
    let get = |k: char| values.iter().find(|(c, _)| *c == k).map(|(_, v)| *v);
    let need = |k: char, what: &str| -> Result<f64, RhError> {
        let s = get(k).unwrap_or("");
        num(s).ok_or_else(|| rh_err(line, format!("{what} `{s}` is not a number")))
    };
    Ok(Compass {
        heading: need('C', "heading")?,
        pitch: need('P', "pitch")?,
        roll: need('R', "roll")?,
        temperature: get('T').and_then(num),
        depth_feet: get('D').and_then(num),
    })
}

impl Osi {
    /// Writes the sentence: the 15 fields, the Iver3 fields when present, then `extra`.
    pub fn sentence(&self) -> String {
        let o = |v: Option<f64>, p: usize| v.map_or(String::new(), |v| format!("{v:.p$}"));
        let mut body = format!(
            "OSI,{},{},{},{},{},{},{},{},{},P{},{},{},{},{},{}",
            self.fins,
            self.mode,
            self.next_waypoint.map_or(String::new(), |w| w.to_string()),
            o(self.lat, 8),
            o(self.lon, 8),
            o(self.speed_knots, 2),
            o(self.distance_to_waypoint, 2),
            self.error,
            o(self.altimeter_feet, 3),
            self.park_time.map_or(0.0, |p| p.round()),
            o(self.declination, 4),
            self.mission,
            o(self.remaining, 1),
            o(self.heading, 1),
            o(self.depth_feet, 1),
        );
        if let Some(i) = &self.iver3 {
            let b = |v: bool| if v { "True" } else { "False" };
            body.push_str(&format!(
                ",{},{},{},{},{},{}",
                o(i.battery_percent, 0),
                b(i.srp),
                i.vehicle,
                i.version,
                b(i.flags[0]),
                b(i.flags[1])
            ));
        }
        for e in &self.extra {
            body.push(',');
            body.push_str(e);
        }
        nmea_sentence(b'$', &body)
    }
}

impl Compass {
    /// Writes the sentence.
    pub fn sentence(&self) -> String {
        nmea_sentence(
            b'$',
            &format!(
                "C{:.1}P{:.2}R{:.2}T{:.1}D{:.1}",
                self.heading,
                self.pitch,
                self.roll,
                self.temperature.unwrap_or(0.0),
                self.depth_feet.unwrap_or(0.0)
            ),
        )
    }
}

impl Opi {
    /// Writes the sentence.
    pub fn sentence(&self) -> String {
        let o = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.1}"));
        nmea_sentence(
            b'$',
            &format!(
                "OPI,{},{},{},{},{},{},{},{}",
                o(self.percent),
                o(self.remaining_wh),
                o(self.power_w),
                o(self.volts),
                o(self.current),
                o(self.minutes),
                self.state,
                if self.leak { 1 } else { 0 }
            ),
        )
    }
}

impl Ack {
    /// Writes the sentence.
    pub fn sentence(&self) -> String {
        nmea_sentence(
            b'$',
            &format!("ACK,{},{},{}", self.msg_type, self.status, self.error),
        )
    }
}

impl Dvl {
    /// Writes the sentence; missing values as −3200.
    pub fn sentence(&self) -> String {
        let o = |v: Option<f64>| format!("{:.3}", v.unwrap_or(-3200.0));
        nmea_sentence(
            b'$',
            &format!(
                "DVL,{},{},{},{},{},{},{}",
                o(self.vx),
                o(self.vy),
                o(self.vz),
                o(self.xdist),
                o(self.ydist),
                o(self.depth),
                o(self.altitude)
            ),
        )
    }
}

/// What an `$OSD` asks for: GPS, compass, state, power, DVL (the `Y`, `D`, `CTD`, `INS` fields are
/// kept as sent).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DataRequest {
    /// `G`: `$GPRMC`.
    pub gps: bool,
    /// `C`: `$C`.
    pub compass: bool,
    /// `S`: `$OSI`.
    pub state: bool,
    /// `P`: `$OPI`.
    pub power: bool,
    /// `D` (sixth field): `$DVL`.
    pub dvl: bool,
}

/// A command from the backseat.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `$OSD`: data request.
    Osd(DataRequest),
    /// `$OMS`: heading (deg), depth (m), max pitch (deg), speed (knots), timeout (s).
    Oms {
        /// Heading, degrees.
        heading: f64,
        /// Depth, metres (written in the version's units).
        depth: f64,
        /// Largest pitch, degrees.
        max_pitch: f64,
        /// Speed, knots.
        speed_knots: f64,
        /// Validity, seconds (0 to [`MAX_TIMEOUT`]).
        timeout: f64,
    },
    /// `$OMP`: five fin/motor bytes and a timeout.
    Omp {
        /// yaw-top, yaw-bottom, pitch-left, pitch-right, motor; 0x80 is neutral.
        bytes: [u8; 5],
        /// Validity, seconds.
        timeout: f64,
    },
    /// `$OMSTART`.
    OmStart {
        /// Start without a GPS fix.
        ignore_gps: bool,
        /// Start without the sounder.
        ignore_sounder: bool,
        /// Start without a pressure calibration.
        ignore_pressure: bool,
        /// 0 normal, 1 safety return path.
        mission_type: u32,
        /// Mission name.
        mission: String,
    },
    /// `$OMSTOP,0`.
    OmStop,
    /// `$OJW`: jump to a waypoint (0–999).
    Ojw(u32),
    /// `$OMW`: go to a point, or `None` for `$OMW,STOP`.
    Omw(Option<Waypoint>),
    /// `$OPOS`: position injection.
    Opos {
        /// Latitude, degrees.
        lat: f64,
        /// Longitude, degrees.
        lon: f64,
        /// Speed, knots.
        speed_knots: f64,
    },
    /// `$ODVL`: velocity injection, m/s (+y is port in the vehicle's frame), and a timeout.
    Odvl {
        /// Forward, m/s.
        x: f64,
        /// Port, m/s.
        y: f64,
        /// Validity, seconds.
        timeout: f64,
    },
}

/// A single-waypoint command (`$OMW`).
#[derive(Debug, Clone, PartialEq)]
pub struct Waypoint {
    /// Clear the current waypoint list first.
    pub clear: bool,
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Depth in metres (positive from the surface, negative as height above the bottom).
    pub depth: f64,
    /// Speed, knots.
    pub speed_knots: f64,
}

/// The message-type code `$ACK` uses for the command with this address (`OMS`, …).
pub fn ack_code(address: &str) -> Option<u32> {
    Some(match address {
        "OMSTOP" => 1,
        "OMSTART" => 3,
        "OPOS" => 6,
        "OJW" => 7,
        "OSD" => 8,
        "OMS" => 9,
        "OMP" => 10,
        "ODVL" => 15,
        "OMW" => 16,
        _ => return None,
    })
}

impl Command {
    /// The message-type code `$ACK` uses for this command.
    pub fn ack_code(&self) -> u32 {
        // every command's name has a code (tested below)
        ack_code(self.name()).unwrap_or_default()
    }

    /// The command's name (its sentence address).
    pub fn name(&self) -> &'static str {
        match self {
            Command::Osd(_) => "OSD",
            Command::Oms { .. } => "OMS",
            Command::Omp { .. } => "OMP",
            Command::OmStart { .. } => "OMSTART",
            Command::OmStop => "OMSTOP",
            Command::Ojw(_) => "OJW",
            Command::Omw(_) => "OMW",
            Command::Opos { .. } => "OPOS",
            Command::Odvl { .. } => "ODVL",
        }
    }

    /// Writes the sentence; depths in `units`.
    pub fn sentence(&self, units: DepthUnits) -> String {
        let body = match self {
            Command::Osd(r) => format!(
                "OSD,{},{},{},{},,{},,",
                if r.gps { "G" } else { "" },
                if r.compass { "C" } else { "" },
                if r.state { "S" } else { "" },
                if r.power { "P" } else { "" },
                if r.dvl { "D" } else { "" },
            ),
            Command::Oms {
                heading,
                depth,
                max_pitch,
                speed_knots,
                timeout,
            } => format!(
                "OMS,{:.1},{:.1},{:.1},{:.1},{:.0}",
                wrap360(*heading),
                units.from_metres(*depth),
                max_pitch,
                speed_knots,
                timeout
            ),
            Command::Omp { bytes, timeout } => format!(
                "OMP,{:02X}{:02X}{:02X}{:02X}{:02X},00,{:.0}",
                bytes[0], bytes[1], bytes[2], bytes[3], bytes[4], timeout
            ),
            Command::OmStart {
                ignore_gps,
                ignore_sounder,
                ignore_pressure,
                mission_type,
                mission,
            } => format!(
                "OMSTART,{},{},{},{},{}",
                u8::from(*ignore_gps),
                u8::from(*ignore_sounder),
                u8::from(*ignore_pressure),
                mission_type,
                mission
            ),
            Command::OmStop => "OMSTOP,0".to_string(),
            Command::Ojw(wp) => format!("OJW,{wp}"),
            Command::Omw(None) => "OMW,STOP".to_string(),
            Command::Omw(Some(w)) => format!(
                "OMW,{}{:.8},{:.8},{:.1},0.0,20.0,{:.1},0,0",
                if w.clear { "CLEAR," } else { "" },
                w.lat,
                w.lon,
                units.from_metres(w.depth),
                w.speed_knots
            ),
            Command::Opos {
                lat,
                lon,
                speed_knots,
            } => format!("OPOS,{lat:.8},{lon:.8},{speed_knots:.1},1,0.0"),
            Command::Odvl { x, y, timeout } => format!("ODVL,{x:.2},{y:.2},{timeout:.0}"),
        };
        nmea_sentence(b'$', &body)
    }
}

/// Reads a backseat command (what a frontseat, or its simulator, receives); depths in `units`.
pub fn parse_command(line: &str, units: DepthUnits) -> Result<Command, RhError> {
    if !line.is_ascii() || !line.starts_with('$') {
        return Err(rh_err(line, "not a Remote Helm sentence"));
    }
    let f = fields(line);
    Ok(match address(line) {
        "OSD" => parse_osd(line, &f)?,
        "OMS" => parse_oms(line, &f, units)?,
        "OMP" => parse_omp(line, &f)?,
        "OMSTART" => parse_omstart(line, &f)?,
        "OMSTOP" => Command::OmStop,
        "OJW" => {
            let wp = req_num(line, &f, 0, "waypoint")?;
            if !(0.0..=999.0).contains(&wp) || wp.fract() != 0.0 {
                return Err(rh_err(line, format!("waypoint {wp} is not 0–999")));
            }
            Command::Ojw(wp as u32)
        }
        "OMW" => parse_omw(line, &f, units)?,
        "OPOS" => Command::Opos {
            lat: req_num(line, &f, 0, "latitude")?,
            lon: req_num(line, &f, 1, "longitude")?,
            speed_knots: opt_num(line, &f, 2, "speed")?.unwrap_or(0.0),
        },
        "ODVL" => Command::Odvl {
            x: req_num(line, &f, 0, "x speed")?,
            y: req_num(line, &f, 1, "y speed")?,
            timeout: req_num(line, &f, 2, "timeout")?,
        },
        other => return Err(rh_err(line, format!("`{other}` is not a backseat command"))),
    })
}

/// `$OSD,<G>,<C>,<S>,<P>,<Y>,<D>,<CTD>,<INS>`: each field its letter or empty.
fn parse_osd(line: &str, f: &[&str]) -> Result<Command, RhError> {
    let has = |i: usize, letter: &str| f.get(i).is_some_and(|s| s.trim() == letter);
    for (i, s) in f.iter().enumerate() {
        let s = s.trim();
        let allowed = ["G", "C", "S", "P", "Y", "D", "CTD", "INS"];
        if !s.is_empty() && !allowed.contains(&s) {
            return Err(rh_err(
                line,
                format!("field {} `{s}` is not a data request letter", i + 1),
            ));
        }
    }
    Ok(Command::Osd(DataRequest {
        gps: has(0, "G"),
        compass: has(1, "C"),
        state: has(2, "S"),
        power: has(3, "P"),
        dvl: has(5, "D"),
    }))
}

/// `$OMS,<heading>,<depth>,<max pitch>,<speed knots>,<timeout>`, the depth in `units`.
fn parse_oms(line: &str, f: &[&str], units: DepthUnits) -> Result<Command, RhError> {
    if f.len() != 5 {
        return Err(rh_err(
            line,
            format!("$OMS has {} fields, 5 were expected", f.len()),
        ));
    }
    Ok(Command::Oms {
        heading: req_num(line, f, 0, "heading")?,
        depth: units.to_metres(req_num(line, f, 1, "depth")?),
        max_pitch: req_num(line, f, 2, "max pitch")?,
        speed_knots: req_num(line, f, 3, "speed")?,
        timeout: req_num(line, f, 4, "timeout")?,
    })
}

/// `$OMP,<10 hex digits>,00,<timeout>`: five fin/motor bytes.
fn parse_omp(line: &str, f: &[&str]) -> Result<Command, RhError> {
    let hex = text(f, 0);
    if hex.len() != 10 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(rh_err(
            line,
            format!("fin/motor field `{hex}` is not 10 hex digits"),
        ));
    }
    let mut bytes = [0u8; 5];
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[i * 2..i * 2 + 2], 16)
            .map_err(|_| rh_err(line, "bad hex digits"))?;
    }
    Ok(Command::Omp {
        bytes,
        timeout: req_num(line, f, 2, "timeout")?,
    })
}

/// `$OMSTART,<ignoreGPS>,<ignoreSounder>,<ignorePressureCal>,<missionType>,<missionName>[,…]`.
fn parse_omstart(line: &str, f: &[&str]) -> Result<Command, RhError> {
    if f.len() < 5 {
        return Err(rh_err(
            line,
            format!("$OMSTART has {} fields, at least 5 were expected", f.len()),
        ));
    }
    let flag = |i: usize, what: &str| -> Result<bool, RhError> {
        match f[i].trim() {
            "0" => Ok(false),
            "1" => Ok(true),
            s => Err(rh_err(
                line,
                format!("field {} ({what}) `{s}` is not 0 or 1", i + 1),
            )),
        }
    };
    Ok(Command::OmStart {
        ignore_gps: flag(0, "ignore GPS")?,
        ignore_sounder: flag(1, "ignore sounder")?,
        ignore_pressure: flag(2, "ignore pressure calibration")?,
        mission_type: match f[3].trim() {
            "0" => 0,
            "1" => 1,
            s => {
                return Err(rh_err(
                    line,
                    format!("field 4 (mission type) `{s}` is not 0 or 1"),
                ));
            }
        },
        mission: f[4].trim().to_string(),
    })
}

/// `$OMW,[CLEAR,]<lat>,<lon>,<depth1>,<depth2>,<maxAngle>,<speed>,…` (the depth in `units`), or
/// `$OMW,STOP`.
fn parse_omw(line: &str, f: &[&str], units: DepthUnits) -> Result<Command, RhError> {
    if f.first().is_some_and(|s| s.trim() == "STOP") {
        return Ok(Command::Omw(None));
    }
    let clear = f.first().is_some_and(|s| s.trim() == "CLEAR");
    let o = usize::from(clear);
    Ok(Command::Omw(Some(Waypoint {
        clear,
        lat: req_num(line, f, o, "latitude")?,
        lon: req_num(line, f, o + 1, "longitude")?,
        depth: units.to_metres(req_num(line, f, o + 2, "depth")?),
        speed_knots: req_num(line, f, o + 5, "speed")?,
    })))
}

/// The meaning of an `$ACK` error number, where known.
pub fn error_text(n: u32) -> &'static str {
    match n {
        0 => "no error",
        1 => "mission file error",
        2 => "mission directory error",
        3 => "mission load error",
        14 => "compass data too old",
        15 => "GPS data too old",
        16 => "sounder data too old",
        17 => "error starting the mission",
        20 => "bad $OMS values",
        21 => "bad $OMP values",
        26 => "a safety rule is engaged",
        27 => "bad $OSD values",
        30 => "bad $OMSTART values",
        39 => "not enough power to park",
        45 => "a mission must be running",
        _ => "unknown error",
    }
}

/// The meaning of an `$OSI` error state.
pub fn error_state_text(code: &str) -> &'static str {
    match code {
        "" | "N" => "",
        "Sop" => "over pitch",
        "Stl" => "mission time exceeded",
        "Sle" => "leak",
        "Sfp" => "no forward progress",
        "Sed" => "maximum depth exceeded",
        "Sup" => "no upward progress",
        "Stf" => "tow float engaged",
        "Srp" => "safety return path",
        "Snd" => "depth unchanged",
        "Snc" => "compass stopped",
        "Spw" => "below minimum power",
        "Sti" => "stop and transmit Iridium",
        _ => "unknown error state",
    }
}

/// The meaning of an `$OSI` mode.
pub fn mode_text(mode: &str) -> &'static str {
    match mode {
        "N" => "normal (mission running)",
        "S" => "stopped",
        "P" => "park",
        "M" => "manual override",
        "m" | "mP" | "Mp" => "manual park",
        "A" => "servo",
        "W" => "mission mode",
        _ => "unknown mode",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(body: &str) -> String {
        nmea_sentence(b'$', body)
    }

    #[test]
    fn osi_is_read_field_by_field() {
        // the short (Iver2) line of the protocol notes, with its checksum
        let line = "$OSI,8080808080,S,1,30.36342050,-89.09611017,0.00,162.91,N,6.204,P0,-1.8894,test,0.0,90.0,3.2*02";
        assert_eq!(line, s(&line[1..line.len() - 3]));
        let FromFront::Osi(o) = parse_front(line).unwrap() else {
            panic!()
        };
        assert_eq!(
            (o.fins.as_str(), o.mode.as_str(), o.next_waypoint),
            ("8080808080", "S", Some(1))
        );
        assert_eq!((o.lat, o.lon), (Some(30.36342050), Some(-89.09611017)));
        assert_eq!(
            (o.speed_knots, o.distance_to_waypoint),
            (Some(0.0), Some(162.91))
        );
        assert_eq!(
            (o.error.as_str(), o.altimeter_feet, o.park_time),
            ("N", Some(6.204), Some(0.0))
        );
        assert_eq!(
            (o.declination, o.mission.as_str(), o.remaining),
            (Some(-1.8894), "test", Some(0.0))
        );
        assert_eq!(
            (o.heading, o.depth_feet, o.battery_percent()),
            (Some(90.0), Some(3.2), None)
        );
        assert_eq!((o.iver3.as_ref(), o.extra.len()), (None, 0));
    }

    /// The Iver3 line of the protocol notes, with its checksum.
    const IVER3_OSI: &str = "$OSI,8080808080,N,2,30.1,-89.2,1.50,10.0,Sle,12.0,P30,-1.9,m1,100.0,180.0,15.0,76,False,iver3-3082,5.4,True,False*72";

    #[test]
    fn the_iver3_osi_gives_battery_srp_name_version_and_flags() {
        assert_eq!(IVER3_OSI, s(&IVER3_OSI[1..IVER3_OSI.len() - 3]));
        let FromFront::Osi(o) = parse_front(IVER3_OSI).unwrap() else {
            panic!()
        };
        assert_eq!(
            o.iver3,
            Some(Iver3Osi {
                battery_percent: Some(76.0),
                srp: false,
                vehicle: "iver3-3082".into(),
                version: "5.4".into(),
                flags: [true, false],
            })
        );
        assert_eq!(
            (o.battery_percent(), o.depth_feet, o.park_time),
            (Some(76.0), Some(15.0), Some(30.0))
        );
        assert!(o.extra.is_empty(), "{:?}", o.extra);
        assert_eq!(error_state_text(&o.error), "leak");
        // an empty battery field is no battery; fields after the 21st are kept
        let line = s(
            "OSI,8080808080,S,1,30.1,-89.2,0.00,0.0,N,6.0,P0,-1.9,m1,0.0,90.0,0.0,,true,v1,5.2,0,1,x",
        );
        let FromFront::Osi(o) = parse_front(&line).unwrap() else {
            panic!()
        };
        let i = o.iver3.as_ref().unwrap();
        assert_eq!(
            (i.battery_percent, i.srp, i.flags, o.extra.as_slice()),
            (None, true, [false, true], &["x".to_string()][..])
        );
    }

    #[test]
    fn short_and_unknown_osi_layouts_read_no_iver3_fields() {
        // 19 fields: neither the Iver2 nor the Iver3 form; fields 16+ are kept, not read
        let line = s(
            "OSI,8080808080,S,1,30.1,-89.2,0.00,0.0,N,6.0,P0,-1.9,m1,0.0,90.0,3.0,76,False,v,5.0",
        );
        let FromFront::Osi(o) = parse_front(&line).unwrap() else {
            panic!()
        };
        assert_eq!(
            (o.battery_percent(), o.iver3, o.extra.len()),
            (None, None, 4)
        );
    }

    #[test]
    fn malformed_iver3_osi_fields_are_refused_by_name() {
        let head = "OSI,8080808080,N,2,30.1,-89.2,1.50,10.0,Sle,12.0,P30,-1.9,m1,100.0,180.0,15.0";
        for (tail, want) in [
            (
                "full,False,iver3,5.4,True,False",
                "field 16 (battery percent) `full` is not a number",
            ),
            (
                "120,False,iver3,5.4,True,False",
                "field 16 (battery percent) `120` is not 0 to 100",
            ),
            (
                "-1,False,iver3,5.4,True,False",
                "field 16 (battery percent) `-1` is not 0 to 100",
            ),
            (
                "76,maybe,iver3,5.4,True,False",
                "field 17 (SRP flag) `maybe` is not True or False",
            ),
            (
                "76,False,,5.4,True,False",
                "field 18 (vehicle name) is empty",
            ),
            (
                "76,False,iver3,5.4,yes,False",
                "field 20 (flag 20) `yes` is not True or False",
            ),
            (
                "76,False,iver3,5.4,True,",
                "field 21 (flag 21) `` is not True or False",
            ),
        ] {
            let e = parse_front(&s(&format!("{head},{tail}"))).unwrap_err();
            assert_eq!(e.reason, want, "{tail}");
        }
    }

    #[test]
    fn compass_power_ack_and_dvl_are_read() {
        assert_eq!(
            parse_front("$C82.8P-3.89R-2.63T20.3D3.2*78").unwrap(),
            FromFront::Compass(Compass {
                heading: 82.8,
                pitch: -3.89,
                roll: -2.63,
                temperature: Some(20.3),
                depth_feet: Some(3.2)
            })
        );
        let FromFront::Opi(p) = parse_front(&s("OPI,76.5,512.0,35.2,15.9,-2.2,880,D,0")).unwrap()
        else {
            panic!()
        };
        assert_eq!(
            (p.percent, p.volts, p.current, p.state.as_str(), p.leak),
            (Some(76.5), Some(15.9), Some(-2.2), "D", false)
        );
        assert_eq!(
            parse_front(&s("ACK,9,1,20")).unwrap(),
            FromFront::Ack(Ack {
                msg_type: 9,
                status: 1,
                error: 20
            })
        );
        let FromFront::Dvl(d) =
            parse_front(&s("DVL,1.20,-0.05,-3200.000,10.5,0.2,5.0,12.3")).unwrap()
        else {
            panic!()
        };
        assert_eq!(
            (d.vx, d.vy, d.vz, d.altitude),
            (Some(1.2), Some(-0.05), None, Some(12.3))
        );
    }

    #[test]
    fn rmc_is_read_from_any_talker() {
        for talker in ["GP", "GN", "GL"] {
            let line = s(&format!(
                "{talker}RMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W"
            ));
            let FromFront::Rmc(r) = parse_front(&line).unwrap() else {
                panic!("{line}")
            };
            assert!((r.lat.unwrap() - (48.0 + 7.038 / 60.0)).abs() < 1e-9);
            assert!((r.lon.unwrap() - (11.0 + 31.0 / 60.0)).abs() < 1e-9);
        }
        assert!(parse_front(&s("GNRMC,123519,A,north,N,01131.000,E,,,230394,,")).is_err());
        assert_eq!(
            parse_front(&s("PXRMC,1,2")).unwrap(),
            FromFront::Other("PXRMC".into())
        );
    }

    #[test]
    fn malformed_front_sentences_say_which_field() {
        let e = parse_front(&s("OSI,8080808080,S,1,north")).unwrap_err();
        assert!(e.reason.contains("at least 15"), "{e}");
        let e = parse_front(&s(
            "OSI,8080808080,S,1,north,-89.09611017,0.00,162.91,N,6.204,P0,-1.8894,test,0.0,90.0,3.2",
        ))
        .unwrap_err();
        assert_eq!(e.reason, "field 4 (latitude) `north` is not a number");
        let e = parse_front(&s(
            "OSI,8080808080,S,1,30.1,-89.2,0.00,162.91,N,6.204,P0,-1.8894,test,0.0,90.0,deep",
        ))
        .unwrap_err();
        assert_eq!(e.reason, "field 15 (depth) `deep` is not a number");
        let e = parse_front(&s("ACK,9,x,0")).unwrap_err();
        assert!(e.reason.contains("field 2 (status) `x`"), "{e}");
        let e = parse_front(&s("C82.8P--1R2")).unwrap_err();
        assert!(e.reason.contains("pitch `--1`"), "{e}");
    }

    #[test]
    fn commands_are_written_as_the_protocol_says() {
        let oms = Command::Oms {
            heading: 90.0,
            depth: 3.048,
            max_pitch: 20.0,
            speed_knots: 2.5,
            timeout: 5.0,
        };
        assert_eq!(
            oms.sentence(DepthUnits::Metres),
            s("OMS,90.0,3.0,20.0,2.5,5")
        );
        assert_eq!(
            oms.sentence(DepthUnits::Feet),
            s("OMS,90.0,10.0,20.0,2.5,5")
        );
        let osd = Command::Osd(DataRequest {
            gps: true,
            compass: true,
            state: true,
            power: true,
            dvl: false,
        });
        assert_eq!(osd.sentence(DepthUnits::Metres), s("OSD,G,C,S,P,,,,"));
        let omp = Command::Omp {
            bytes: [0x80, 0x80, 0x90, 0x70, 0xC0],
            timeout: 3.0,
        };
        assert_eq!(omp.sentence(DepthUnits::Metres), s("OMP,80809070C0,00,3"));
        let start = Command::OmStart {
            ignore_gps: false,
            ignore_sounder: true,
            ignore_pressure: false,
            mission_type: 0,
            mission: "survey.mis".into(),
        };
        assert_eq!(
            start.sentence(DepthUnits::Metres),
            s("OMSTART,0,1,0,0,survey.mis")
        );
        assert_eq!(Command::OmStop.sentence(DepthUnits::Metres), s("OMSTOP,0"));
        assert_eq!(Command::Ojw(12).sentence(DepthUnits::Metres), s("OJW,12"));
        assert_eq!(
            Command::Omw(None).sentence(DepthUnits::Metres),
            s("OMW,STOP")
        );
        let omw = Command::Omw(Some(Waypoint {
            clear: true,
            lat: 43.5,
            lon: 16.25,
            depth: 2.0,
            speed_knots: 2.0,
        }));
        assert_eq!(
            omw.sentence(DepthUnits::Metres),
            s("OMW,CLEAR,43.50000000,16.25000000,2.0,0.0,20.0,2.0,0,0")
        );
        assert_eq!(
            Command::Opos {
                lat: 43.5,
                lon: 16.25,
                speed_knots: 1.0
            }
            .sentence(DepthUnits::Metres),
            s("OPOS,43.50000000,16.25000000,1.0,1,0.0")
        );
        assert_eq!(
            Command::Odvl {
                x: 1.5,
                y: -0.25,
                timeout: 5.0
            }
            .sentence(DepthUnits::Metres),
            s("ODVL,1.50,-0.25,5")
        );
    }

    #[test]
    fn every_command_reads_back() {
        let cmds = vec![
            Command::Osd(DataRequest {
                gps: true,
                compass: false,
                state: true,
                power: false,
                dvl: true,
            }),
            Command::Oms {
                heading: 359.5,
                depth: 4.0,
                max_pitch: 15.0,
                speed_knots: 3.0,
                timeout: 10.0,
            },
            Command::Omp {
                bytes: [1, 2, 3, 4, 255],
                timeout: 2.0,
            },
            Command::OmStart {
                ignore_gps: true,
                ignore_sounder: false,
                ignore_pressure: true,
                mission_type: 1,
                mission: "m".into(),
            },
            Command::OmStop,
            Command::Ojw(999),
            Command::Omw(None),
            Command::Opos {
                lat: -1.0,
                lon: 2.0,
                speed_knots: 0.5,
            },
            Command::Odvl {
                x: 0.5,
                y: 0.25,
                timeout: 1.0,
            },
        ];
        for c in cmds {
            for units in [DepthUnits::Feet, DepthUnits::Metres] {
                let back = parse_command(&c.sentence(units), units).unwrap();
                match (&c, &back) {
                    (Command::Oms { depth: a, .. }, Command::Oms { depth: b, .. }) => {
                        assert!((a - b).abs() < 0.1, "{c:?}")
                    }
                    _ => assert_eq!(back, c),
                }
                assert_eq!(back.ack_code(), c.ack_code());
                assert_eq!(ack_code(c.name()), Some(c.ack_code()));
            }
        }
        let e = parse_command(&s("OSD,X,C,S,P,,,,"), DepthUnits::Metres).unwrap_err();
        assert!(e.reason.contains("field 1 `X`"), "{e}");
        assert!(parse_command(&s("OMS,90,1,20,2"), DepthUnits::Metres).is_err());
        assert!(parse_command(&s("OJW,1000"), DepthUnits::Metres).is_err());
    }

    #[test]
    fn built_frontseat_sentences_read_back() {
        let osi = Osi {
            fins: "8080808080".into(),
            mode: "N".into(),
            next_waypoint: Some(3),
            lat: Some(43.5),
            lon: Some(16.4),
            speed_knots: Some(2.5),
            distance_to_waypoint: Some(12.0),
            error: "N".into(),
            altimeter_feet: Some(30.0),
            park_time: Some(0.0),
            declination: Some(3.0),
            mission: "demo".into(),
            remaining: Some(120.0),
            heading: Some(45.0),
            depth_feet: Some(10.0),
            iver3: Some(Iver3Osi {
                battery_percent: Some(88.0),
                srp: true,
                vehicle: "sim".into(),
                version: "5.0".into(),
                flags: [false, true],
            }),
            extra: vec!["more".into()],
        };
        let FromFront::Osi(back) = parse_front(&osi.sentence()).unwrap() else {
            panic!()
        };
        assert_eq!(*back, osi);
        let short = Osi {
            iver3: None,
            extra: Vec::new(),
            ..osi
        };
        assert_eq!(fields(&short.sentence()).len(), 15);
        let FromFront::Osi(back) = parse_front(&short.sentence()).unwrap() else {
            panic!()
        };
        assert_eq!(*back, short);
        let c = Compass {
            heading: 10.5,
            pitch: 1.25,
            roll: -0.5,
            temperature: Some(18.0),
            depth_feet: Some(6.5),
        };
        assert_eq!(parse_front(&c.sentence()).unwrap(), FromFront::Compass(c));
        let a = Ack {
            msg_type: 3,
            status: 1,
            error: 30,
        };
        assert_eq!(parse_front(&a.sentence()).unwrap(), FromFront::Ack(a));
    }
}
