//! NMEA 0183 sentences: parsing (the `nmea` crate where it covers a sentence, our own parsers for
//! the marine sentences it lacks) and building (for simulators).
//!
//! Input is one whole sentence with a correct checksum, as the serial medium's NMEA framing hands
//! it out: the checksum is not checked again here. Parsing never panics; a sentence it does not
//! know is [`Sentence::Other`].

use seabus_medium::framing::{nmea_address, nmea_sentence};
use seabus_modules::geo::wrap360;
use std::fmt;
use thiserror::Error;

/// Why a sentence could not be read.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{sentence}: {reason}")]
pub struct NmeaError {
    /// The sentence (shortened).
    pub sentence: String,
    /// What was wrong.
    pub reason: String,
}

fn err(sentence: &str, reason: impl fmt::Display) -> NmeaError {
    NmeaError {
        sentence: sentence.chars().take(90).collect(),
        reason: reason.to_string(),
    }
}

/// One transducer reading of an `XDR` sentence.
#[derive(Debug, Clone, PartialEq)]
pub struct Transducer {
    /// Transducer type (`A` angle, `C` temperature, `P` pressure, …).
    pub kind: String,
    /// The value, when given.
    pub value: Option<f64>,
    /// Unit (`D` degrees, `C` Celsius, `B` bar, …).
    pub unit: String,
    /// The transducer's name (`PITCH`, `ROLL`, …).
    pub name: String,
}

/// A parsed sentence.
#[derive(Debug, PartialEq)]
pub enum Sentence {
    /// GGA: fix data.
    Gga(nmea::sentences::GgaData),
    /// RMC: recommended minimum.
    Rmc(nmea::sentences::RmcData),
    /// VTG: course and speed over ground.
    Vtg(nmea::sentences::VtgData),
    /// GLL: position.
    Gll(nmea::sentences::GllData),
    /// GNS: GNSS fix (read by seabus: the crate refuses a mode of more than two letters).
    Gns(Gns),
    /// HDT: true heading.
    Hdt(nmea::sentences::HdtData),
    /// DPT: depth below transducer, with offset (read by seabus: the crate refuses a negative
    /// offset, which is the keel's).
    Dpt {
        /// Depth below the transducer, metres.
        depth: Option<f64>,
        /// Offset from the transducer, metres: positive to the waterline, negative to the keel.
        offset: Option<f64>,
        /// Maximum range scale in use, metres.
        range: Option<f64>,
    },
    /// DBS: depth below surface.
    Dbs(nmea::sentences::DbsData),
    /// DBK: depth below keel.
    Dbk(nmea::sentences::DbkData),
    /// MTW: water temperature.
    Mtw(nmea::sentences::MtwData),
    /// VHW: speed and heading through the water.
    Vhw(nmea::sentences::VhwData),
    /// ZDA: time and date.
    Zda(nmea::sentences::ZdaData),
    /// GSA: DOP and the satellites used.
    Gsa(nmea::sentences::GsaData),
    /// GSV: satellites in view (one sentence of a group).
    Gsv(nmea::sentences::GsvData),
    /// GST: position error statistics.
    Gst(nmea::sentences::GstData),
    /// MWV: wind speed and angle relative to the bow.
    Mwv(nmea::sentences::MwvData),
    /// TXT: a text message from the device.
    Txt(nmea::sentences::TxtData),
    /// MWD: wind direction (from true and magnetic north) and speed.
    Mwd {
        /// Direction the wind blows from, degrees true.
        true_direction: Option<f64>,
        /// Direction the wind blows from, degrees magnetic.
        magnetic_direction: Option<f64>,
        /// Speed, knots.
        knots: Option<f64>,
        /// Speed, metres per second.
        mps: Option<f64>,
    },
    /// VBW: speed through the water and over the ground, along and across the hull.
    Vbw {
        /// Water speed along the hull, knots, ahead positive.
        water_along: Option<f64>,
        /// Water speed across the hull, knots, to starboard positive.
        water_across: Option<f64>,
        /// Whether the water speeds are valid (`A`).
        water_valid: bool,
        /// Ground speed along the hull, knots.
        ground_along: Option<f64>,
        /// Ground speed across the hull, knots.
        ground_across: Option<f64>,
        /// Whether the ground speeds are valid.
        ground_valid: bool,
    },
    /// RSA: rudder angles, degrees, negative to port.
    Rsa {
        /// Starboard (or single) rudder.
        starboard: Option<f64>,
        /// Whether it is valid.
        starboard_valid: bool,
        /// Port rudder.
        port: Option<f64>,
        /// Whether it is valid.
        port_valid: bool,
    },
    /// XTE: cross-track error.
    Xte {
        /// Distance off the track, nautical miles, positive when right of it (steer left).
        error: Option<f64>,
        /// Whether the data is valid (both status fields `A`, mode not `N`).
        valid: bool,
        /// FAA mode (`A`, `D`, `E`, …), when given (NMEA 2.3 and later).
        mode: Option<char>,
    },
    /// THS: true heading and its mode (`A` autonomous, `E` estimated, `M` manual, `S` simulator,
    /// `V` not valid).
    Ths {
        /// Heading, degrees true.
        heading: Option<f64>,
        /// The mode letter.
        mode: char,
    },
    /// HDG: magnetic sensor heading, deviation and variation (east positive).
    Hdg {
        /// Sensor heading, degrees.
        heading: Option<f64>,
        /// Deviation, degrees, east positive.
        deviation: Option<f64>,
        /// Variation, degrees, east positive.
        variation: Option<f64>,
    },
    /// HDM: magnetic heading.
    Hdm {
        /// Heading, degrees magnetic.
        heading: Option<f64>,
    },
    /// DBT: depth below transducer.
    Dbt {
        /// Feet.
        feet: Option<f64>,
        /// Metres.
        metres: Option<f64>,
        /// Fathoms.
        fathoms: Option<f64>,
    },
    /// ROT: rate of turn.
    Rot {
        /// Degrees per minute, negative to port.
        rate: Option<f64>,
        /// Whether the data is valid (`A`).
        valid: bool,
    },
    /// XDR: transducer measurements.
    Xdr(Vec<Transducer>),
    /// A proprietary or other non-standard sentence (its address is the formatter), with its
    /// fields, for the tables that read them.
    Fields(Vec<Box<str>>),
    /// A standard sentence seabus does not read.
    Other,
}

/// A GNS fix.
#[derive(Debug, Clone, PartialEq)]
pub struct Gns {
    /// Latitude, degrees north.
    pub lat: Option<f64>,
    /// Longitude, degrees east.
    pub lon: Option<f64>,
    /// Mode letters, one per constellation (`AAN`: GPS autonomous, GLONASS autonomous, Galileo
    /// no fix); `N` for each when there is no fix.
    pub mode: String,
    /// Satellites in use.
    pub satellites: Option<u32>,
    /// Horizontal dilution of precision.
    pub hdop: Option<f64>,
    /// Antenna altitude above mean sea level, metres.
    pub alt: Option<f64>,
    /// Navigational status (NMEA 4.1: `S` safe, `C` caution, `U` unsafe, `V` not valid).
    pub status: Option<char>,
}

impl Gns {
    /// Whether any constellation has a fix (a mode letter other than `N`).
    pub fn fixed(&self) -> bool {
        self.mode.chars().any(|c| c != 'N') && self.status != Some('V')
    }
}

/// The longest address kept whole (`PTNTHPR` and the like are far shorter); a longer one is kept
/// cut to this length.
pub const MAX_ADDRESS: usize = 15;

/// A sentence with its talker (`GP`, `HC`, …; empty for proprietary and non-standard addresses)
/// and formatter (`GGA`, `HDG`, …, or the whole address when it is not standard). It owns what it
/// holds, so that one parse can serve every driver reading the line.
#[derive(Debug, PartialEq)]
pub struct Parsed {
    /// The address's letters, [`MAX_ADDRESS`] at most.
    address: [u8; MAX_ADDRESS],
    /// How many of them there are.
    len: u8,
    /// How many of them are the talker (2, or 0 when there is none).
    talker: u8,
    /// The contents.
    pub sentence: Sentence,
}

impl Parsed {
    fn new(talker: &str, formatter: &str, sentence: Sentence) -> Parsed {
        let mut address = [0; MAX_ADDRESS];
        let mut len = 0;
        for (slot, b) in address
            .iter_mut()
            .zip(talker.bytes().chain(formatter.bytes()))
        {
            *slot = b;
            len += 1;
        }
        Parsed {
            address,
            len,
            talker: talker.len().min(MAX_ADDRESS) as u8,
            sentence,
        }
    }

    /// The talker id (`GP`, `HC`, …), empty for proprietary and non-standard addresses.
    pub fn talker(&self) -> &str {
        // (an address is ASCII letters: every cut is a character boundary)
        std::str::from_utf8(&self.address[..usize::from(self.talker)]).unwrap_or_default()
    }

    /// The sentence formatter (`GGA`, `HDG`, …), or the whole address when it is not standard.
    pub fn formatter(&self) -> &str {
        std::str::from_utf8(&self.address[usize::from(self.talker)..usize::from(self.len)])
            .unwrap_or_default()
    }
}

/// The address of a sentence: the letters after `$`/`!` (`GPGGA`, `OSI`, and `C` for the Iver
/// compass sentence `$C82.8P…`, which has no comma) — the same rule that names its topic on a serial
/// medium.
pub fn address(line: &str) -> &str {
    let len = nmea_address(line.as_bytes()).len();
    // (letters are single bytes, so the address ends on a character boundary)
    line.get(1..1 + len).unwrap_or_default()
}

/// The fields of a sentence: between the first comma and the `*`.
pub fn fields(line: &str) -> Vec<&str> {
    let body = line.get(1..).unwrap_or("");
    let body = match body.rfind('*') {
        Some(i) => &body[..i],
        None => body,
    };
    match body.find(',') {
        Some(i) => body[i + 1..].split(',').collect(),
        None => Vec::new(),
    }
}

/// The talker and formatter of a standard address: five capital letters on a `$` sentence, not
/// proprietary (`$P…`).
pub(crate) fn standard<'a>(line: &str, addr: &'a str) -> Option<(&'a str, &'a str)> {
    let standard = line.starts_with('$')
        && addr.len() == 5
        && addr.bytes().all(|b| b.is_ascii_uppercase())
        && !addr.starts_with('P');
    standard.then(|| addr.split_at(2))
}

/// The talker of a sentence (`GP`, `HC`, …) as [`parse`] reads it: empty for proprietary,
/// encapsulated (`!…`) and non-standard addresses.
pub(crate) fn talker(line: &str) -> &str {
    standard(line, address(line)).map_or("", |(talker, _)| talker)
}

/// A number field: `None` when it is empty or not a finite number.
pub(crate) fn num(s: &str) -> Option<f64> {
    let s = s.trim();
    if s.is_empty() {
        return None;
    }
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Field `i` read as a number when present: `None` when it is missing or empty, and its trimmed
/// text as the error when it is not a number.
pub(crate) fn num_field<'a>(f: &[&'a str], i: usize) -> Result<Option<f64>, &'a str> {
    match f.get(i).map(|s| s.trim()) {
        None | Some("") => Ok(None),
        Some(s) => num(s).map(Some).ok_or(s),
    }
}

/// A field that must be a number when present.
fn opt_num(line: &str, f: &[&str], i: usize, what: &str) -> Result<Option<f64>, NmeaError> {
    num_field(f, i).map_err(|s| err(line, format!("{what} `{s}` is not a number")))
}

/// An east/west signed value (`value,E` positive, `value,W` negative).
fn east_west(line: &str, f: &[&str], i: usize, what: &str) -> Result<Option<f64>, NmeaError> {
    let v = opt_num(line, f, i, what)?;
    Ok(match (v, f.get(i + 1).map(|s| s.trim())) {
        (Some(v), Some("W")) => Some(-v),
        (Some(v), _) => Some(v),
        (None, _) => None,
    })
}

/// The single letter of field `i`, when it is one.
fn letter(f: &[&str], i: usize) -> Option<char> {
    let s = f.get(i)?.trim();
    let mut c = s.chars();
    match (c.next(), c.next()) {
        (Some(l), None) => Some(l),
        _ => None,
    }
}

/// A latitude or longitude written `ddmm.mmmm` (`dddmm.mmmm`) with its hemisphere letter in the
/// next field; `None` when empty.
fn angle(
    line: &str,
    f: &[&str],
    i: usize,
    what: &str,
    negative: char,
) -> Result<Option<f64>, NmeaError> {
    let Some(v) = opt_num(line, f, i, what)? else {
        return Ok(None);
    };
    let degrees = (v / 100.0).trunc();
    let minutes = v - degrees * 100.0;
    if v < 0.0 || minutes >= 60.0 {
        return Err(err(
            line,
            format!("{what} `{}` is not ddmm.mmmm", f[i].trim()),
        ));
    }
    let a = degrees + minutes / 60.0;
    Ok(Some(if letter(f, i + 1) == Some(negative) {
        -a
    } else {
        a
    }))
}

/// A GNS: time, position, mode letters (any number), satellites, HDOP, altitude, geoid separation,
/// age and station of differential data, and (NMEA 4.1) the navigational status.
fn gns(line: &str, f: &[&str]) -> Result<Gns, NmeaError> {
    if f.len() < 12 {
        return Err(err(
            line,
            format!("GNS has {} fields, 12 or more were expected", f.len()),
        ));
    }
    let mode = f[5].trim();
    if mode.is_empty() || !mode.bytes().all(|b| b.is_ascii_uppercase()) {
        return Err(err(line, format!("GNS mode `{mode}` is not mode letters")));
    }
    let satellites = opt_num(line, f, 6, "satellites")?;
    Ok(Gns {
        lat: angle(line, f, 1, "latitude", 'S')?,
        lon: angle(line, f, 3, "longitude", 'W')?,
        mode: mode.to_string(),
        satellites: satellites
            .filter(|n| n.fract() == 0.0 && (0.0..=999.0).contains(n))
            .map(|n| n as u32),
        hdop: opt_num(line, f, 7, "HDOP")?,
        alt: opt_num(line, f, 8, "altitude")?,
        status: letter(f, 12),
    })
}

/// An XTE: two status letters, the magnitude, the direction to steer, the unit (`N`), and (NMEA
/// 2.3) the mode.
fn xte(line: &str, f: &[&str]) -> Result<Sentence, NmeaError> {
    let magnitude = opt_num(line, f, 2, "cross-track error")?;
    let error = match (magnitude, letter(f, 3)) {
        (Some(m), Some('L')) => Some(m),
        (Some(m), Some('R')) => Some(-m),
        (Some(_), _) => {
            return Err(err(line, "XTE direction to steer is not L or R"));
        }
        (None, _) => None,
    };
    if magnitude.is_some() && letter(f, 4) != Some('N') {
        return Err(err(line, "XTE unit is not N (nautical miles)"));
    }
    let mode = letter(f, 5);
    Ok(Sentence::Xte {
        error,
        valid: letter(f, 0) == Some('A') && letter(f, 1) == Some('A') && mode != Some('N'),
        mode,
    })
}

/// Parses one sentence (with its checksum, without line ending).
pub fn parse(line: &str) -> Result<Parsed, NmeaError> {
    if !line.is_ascii() || !line.starts_with(['$', '!']) {
        return Err(err(line, "not an NMEA sentence"));
    }
    let addr = address(line);
    let Some((talker, formatter)) = standard(line, addr) else {
        let f = fields(line).into_iter().map(Box::from).collect();
        return Ok(Parsed::new("", addr, Sentence::Fields(f)));
    };
    // (a standard address has five letters: the formatter is three bytes, matched as a word)
    let code: [u8; 3] = formatter.as_bytes().try_into().unwrap_or_default();
    // our own parsers read the fields; the crate's read the whole line
    let f = match &code {
        b"HDG" | b"HDM" | b"DBT" | b"ROT" | b"XDR" | b"DPT" | b"GNS" | b"MWD" | b"VBW" | b"RSA"
        | b"XTE" | b"THS" => fields(line),
        _ => Vec::new(),
    };
    // The crate's parser for each sentence is handed the sentence's data directly: the framing
    // has already checked the checksum and the address is known, so neither is worked out again.
    let data = {
        // usually the comma right after the address, and the `*` three bytes from the end
        let after = 1 + addr.len();
        let start = match line.as_bytes().get(after) {
            Some(b',') => after + 1,
            _ => line[after..]
                .find(',')
                .map_or(line.len(), |i| after + i + 1),
        };
        let end = match line.len().checked_sub(3) {
            Some(e) if e >= start && line.as_bytes()[e] == b'*' => e,
            _ => line
                .rfind('*')
                .filter(|e| *e >= start)
                .unwrap_or(line.len()),
        };
        &line[start..end]
    };
    // a GLL of NMEA 2.0 and older has no mode field: it reads as an empty one (no mode given)
    let padded;
    let data = if &code == b"GLL" && data.matches(',').count() == 5 {
        padded = format!("{data},");
        padded.as_str()
    } else {
        data
    };
    let crate_sentence = |id: nmea::SentenceType| nmea::NmeaSentence {
        talker_id: talker,
        message_id: id,
        data,
        checksum: 0,
    };
    let crate_err = |e: nmea::Error<'_>| err(line, e);
    use nmea::SentenceType as T;
    use nmea::sentences as n;
    let sentence = match &code {
        b"GGA" => Sentence::Gga(n::parse_gga(crate_sentence(T::GGA)).map_err(crate_err)?),
        b"RMC" => Sentence::Rmc(n::parse_rmc(crate_sentence(T::RMC)).map_err(crate_err)?),
        b"VTG" => Sentence::Vtg(n::parse_vtg(crate_sentence(T::VTG)).map_err(crate_err)?),
        b"GLL" => Sentence::Gll(n::parse_gll(crate_sentence(T::GLL)).map_err(crate_err)?),
        b"HDT" => Sentence::Hdt(n::parse_hdt(crate_sentence(T::HDT)).map_err(crate_err)?),
        b"DBS" => Sentence::Dbs(n::parse_dbs(crate_sentence(T::DBS)).map_err(crate_err)?),
        b"DBK" => Sentence::Dbk(n::parse_dbk(crate_sentence(T::DBK)).map_err(crate_err)?),
        b"MTW" => Sentence::Mtw(n::parse_mtw(crate_sentence(T::MTW)).map_err(crate_err)?),
        b"VHW" => Sentence::Vhw(n::parse_vhw(crate_sentence(T::VHW)).map_err(crate_err)?),
        b"ZDA" => Sentence::Zda(n::parse_zda(crate_sentence(T::ZDA)).map_err(crate_err)?),
        b"GSA" => Sentence::Gsa(n::parse_gsa(crate_sentence(T::GSA)).map_err(crate_err)?),
        b"GSV" => Sentence::Gsv(n::parse_gsv(crate_sentence(T::GSV)).map_err(crate_err)?),
        b"GST" => Sentence::Gst(n::parse_gst(crate_sentence(T::GST)).map_err(crate_err)?),
        b"MWV" => Sentence::Mwv(n::parse_mwv(crate_sentence(T::MWV)).map_err(crate_err)?),
        b"TXT" => Sentence::Txt(n::parse_txt(crate_sentence(T::TXT)).map_err(crate_err)?),
        b"DPT" => Sentence::Dpt {
            depth: opt_num(line, &f, 0, "depth")?,
            offset: opt_num(line, &f, 1, "offset")?,
            range: opt_num(line, &f, 2, "range scale")?,
        },
        b"GNS" => Sentence::Gns(gns(line, &f)?),
        b"MWD" => Sentence::Mwd {
            true_direction: opt_num(line, &f, 0, "true direction")?,
            magnetic_direction: opt_num(line, &f, 2, "magnetic direction")?,
            knots: opt_num(line, &f, 4, "speed in knots")?,
            mps: opt_num(line, &f, 6, "speed in m/s")?,
        },
        b"VBW" => Sentence::Vbw {
            water_along: opt_num(line, &f, 0, "water speed along")?,
            water_across: opt_num(line, &f, 1, "water speed across")?,
            water_valid: letter(&f, 2) == Some('A'),
            ground_along: opt_num(line, &f, 3, "ground speed along")?,
            ground_across: opt_num(line, &f, 4, "ground speed across")?,
            ground_valid: letter(&f, 5) == Some('A'),
        },
        b"RSA" => Sentence::Rsa {
            starboard: opt_num(line, &f, 0, "starboard rudder")?,
            starboard_valid: letter(&f, 1) == Some('A'),
            port: opt_num(line, &f, 2, "port rudder")?,
            port_valid: letter(&f, 3) == Some('A'),
        },
        b"XTE" => xte(line, &f)?,
        b"THS" => Sentence::Ths {
            heading: opt_num(line, &f, 0, "heading")?,
            mode: letter(&f, 1).unwrap_or('V'),
        },
        b"HDG" => Sentence::Hdg {
            heading: opt_num(line, &f, 0, "heading")?,
            deviation: east_west(line, &f, 1, "deviation")?,
            variation: east_west(line, &f, 3, "variation")?,
        },
        b"HDM" => Sentence::Hdm {
            heading: opt_num(line, &f, 0, "heading")?,
        },
        b"DBT" => Sentence::Dbt {
            feet: opt_num(line, &f, 0, "depth in feet")?,
            metres: opt_num(line, &f, 2, "depth in metres")?,
            fathoms: opt_num(line, &f, 4, "depth in fathoms")?,
        },
        b"ROT" => Sentence::Rot {
            rate: opt_num(line, &f, 0, "rate of turn")?,
            valid: f.get(1).is_some_and(|s| s.trim() == "A"),
        },
        b"XDR" => {
            if f.len() % 4 != 0 {
                return Err(err(
                    line,
                    format!("XDR has {} fields, a multiple of 4 was expected", f.len()),
                ));
            }
            let mut out = Vec::with_capacity(f.len() / 4);
            for (i, q) in f.chunks(4).enumerate() {
                out.push(Transducer {
                    kind: q[0].trim().to_string(),
                    value: opt_num(line, &f, i * 4 + 1, "measurement")?,
                    unit: q[2].trim().to_string(),
                    name: q[3].trim().to_string(),
                });
            }
            Sentence::Xdr(out)
        }
        _ => Sentence::Other,
    };
    Ok(Parsed::new(talker, formatter, sentence))
}

/// Writes a latitude as `ddmm.mmmm,N`.
pub fn lat_field(lat: f64) -> String {
    angle_field(lat, 2, ['N', 'S'])
}

/// Writes a longitude as `dddmm.mmmm,E`.
pub fn lon_field(lon: f64) -> String {
    angle_field(lon, 3, ['E', 'W'])
}

/// An angle as degrees (`width` digits), minutes to four decimals, and its hemisphere letter
/// (`[positive, negative]`). It is rounded as a whole first, so 59.99999′ carries into the degrees
/// rather than printing as 60.0000′.
fn angle_field(value: f64, width: usize, hemi: [char; 2]) -> String {
    const PER_DEGREE: u64 = 60 * 10_000;
    let total = (value.abs() * PER_DEGREE as f64).round() as u64;
    let (deg, rest) = (total / PER_DEGREE, total % PER_DEGREE);
    let hemi = hemi[usize::from(value < 0.0)];
    format!(
        "{deg:0width$}{:02}.{:04},{hemi}",
        rest / 10_000,
        rest % 10_000
    )
}

/// Time of day as `hhmmss.ss` from seconds since midnight (rounded as a whole to the hundredth, so
/// 59.999 s carries into the minutes).
pub fn time_field(secs_of_day: f64) -> String {
    const DAY: u64 = 86_400 * 100;
    let cs = (secs_of_day.rem_euclid(86_400.0) * 100.0).round() as u64 % DAY;
    format!(
        "{:02}{:02}{:02}.{:02}",
        cs / 360_000,
        cs / 6_000 % 60,
        cs / 100 % 60,
        cs % 100
    )
}

/// Builders of the sentences simulators send.
pub mod build {
    use super::*;

    /// `$<talker>GGA`: a fix with `satellites` satellites, quality 1 when `fixed`, else 0.
    pub fn gga(
        talker: &str,
        secs_of_day: f64,
        lat: f64,
        lon: f64,
        fixed: bool,
        satellites: u32,
    ) -> String {
        let q = if fixed { 1 } else { 0 };
        nmea_sentence(
            b'$',
            &format!(
                "{talker}GGA,{},{},{},{q},{satellites:02},0.9,0.0,M,0.0,M,,",
                time_field(secs_of_day),
                lat_field(lat),
                lon_field(lon)
            ),
        )
    }

    /// `$<talker>RMC` with speed in m/s and course in degrees; `date` is `ddmmyy`.
    pub fn rmc(
        talker: &str,
        secs_of_day: f64,
        date: &str,
        lat: f64,
        lon: f64,
        speed: f64,
        course: f64,
    ) -> String {
        nmea_sentence(
            b'$',
            &format!(
                "{talker}RMC,{},A,{},{},{:.2},{:.1},{date},,,A",
                time_field(secs_of_day),
                lat_field(lat),
                lon_field(lon),
                speed / crate::units::KNOT,
                wrap360(course)
            ),
        )
    }

    /// `$<talker>HDT`.
    pub fn hdt(talker: &str, heading: f64) -> String {
        nmea_sentence(b'$', &format!("{talker}HDT,{:.1},T", wrap360(heading)))
    }

    /// `$<talker>HDG` with deviation and variation (east positive).
    pub fn hdg(talker: &str, heading: f64, deviation: f64, variation: f64) -> String {
        let ew = |v: f64| format!("{:.1},{}", v.abs(), if v < 0.0 { 'W' } else { 'E' });
        nmea_sentence(
            b'$',
            &format!(
                "{talker}HDG,{:.1},{},{}",
                wrap360(heading),
                ew(deviation),
                ew(variation)
            ),
        )
    }

    /// `$<talker>XDR` with pitch and roll angles.
    pub fn xdr_pitch_roll(talker: &str, pitch: f64, roll: f64) -> String {
        nmea_sentence(
            b'$',
            &format!("{talker}XDR,A,{pitch:.1},D,PITCH,A,{roll:.1},D,ROLL"),
        )
    }

    /// `$<talker>DBT` from metres.
    pub fn dbt(talker: &str, metres: f64) -> String {
        nmea_sentence(
            b'$',
            &format!(
                "{talker}DBT,{:.1},f,{metres:.1},M,{:.1},F",
                metres / crate::units::FOOT,
                metres / crate::units::FATHOM
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sentence kept for the rest of the test run, so that what is parsed from it can be kept too.
    fn line(start: u8, body: &str) -> &'static str {
        Box::leak(nmea_sentence(start, body).into_boxed_str())
    }

    fn p(body: &str) -> Parsed {
        parse(line(b'$', body)).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn crate_sentences_parse_field_by_field() {
        let g = p("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,");
        assert_eq!((g.talker(), g.formatter()), ("GP", "GGA"));
        let Sentence::Gga(d) = g.sentence else {
            panic!()
        };
        assert!((d.latitude.unwrap() - (48.0 + 7.038 / 60.0)).abs() < 1e-9);
        assert!((d.longitude.unwrap() - (11.0 + 31.0 / 60.0)).abs() < 1e-9);
        assert_eq!(
            (d.fix_satellites, d.fix_type),
            (Some(8), Some(nmea::sentences::FixType::Gps))
        );
        let Sentence::Rmc(r) =
            p("GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W").sentence
        else {
            panic!()
        };
        assert_eq!(
            (r.speed_over_ground, r.true_course),
            (Some(22.4), Some(84.4))
        );
        let Sentence::Hdt(h) = p("HEHDT,274.07,T").sentence else {
            panic!()
        };
        assert_eq!(h.heading, Some(274.07));
        let Sentence::Dpt { depth, offset, .. } = p("SDDPT,17.5,0.3,100").sentence else {
            panic!()
        };
        assert_eq!((depth, offset), (Some(17.5), Some(0.3)));
        let Sentence::Mtw(m) = p("YXMTW,17.9,C").sentence else {
            panic!()
        };
        assert_eq!(m.temperature, Some(17.9));
        let Sentence::Vtg(v) = p("GPVTG,054.7,T,034.4,M,005.5,N,010.2,K").sentence else {
            panic!()
        };
        assert_eq!(
            (v.true_course, v.speed_over_ground),
            (Some(54.7), Some(5.5))
        );
    }

    #[test]
    fn written_fields_round_as_a_whole() {
        assert_eq!(lat_field(43.5), "4330.0000,N");
        assert_eq!(lat_field(-43.999_999_99), "4400.0000,S");
        assert_eq!(lon_field(16.440_000_2), "01626.4000,E");
        assert_eq!(lon_field(-179.999_999_999), "18000.0000,W");
        assert_eq!(time_field(3723.5), "010203.50");
        assert_eq!(time_field(59.999), "000100.00");
        assert_eq!(time_field(86_399.999), "000000.00");
        assert_eq!(time_field(-1.0), "235959.00");
    }

    #[test]
    fn a_gll_without_its_mode_field_reads_as_one_with_no_mode() {
        let Sentence::Gll(g) = p("GPGLL,4916.450,N,12311.120,W,225444.00,A").sentence else {
            panic!("a GLL")
        };
        assert!((g.latitude.unwrap() - (49.0 + 16.45 / 60.0)).abs() < 1e-9);
        assert!((g.longitude.unwrap() + (123.0 + 11.12 / 60.0)).abs() < 1e-9);
        assert!(g.valid);
        assert_eq!(g.faa_mode, None);
        let Sentence::Gll(g) = p("GPGLL,4916.450,N,12311.120,W,225444.00,V").sentence else {
            panic!("a GLL")
        };
        assert!(!g.valid);
        // a field short of that is still an error
        assert!(parse(line(b'$', "GPGLL,4916.450,N,12311.120,W,225444.00")).is_err());
    }

    #[test]
    fn the_other_crate_sentences_parse_field_by_field() {
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-9);
        let Sentence::Gll(g) = p("GPGLL,4916.450,N,12311.120,W,225444.00,A,A").sentence else {
            panic!()
        };
        assert!(close(g.latitude, 49.0 + 16.45 / 60.0), "{g:?}");
        assert!(close(g.longitude, -(123.0 + 11.12 / 60.0)), "{g:?}");
        assert!(g.valid);
        let Sentence::Gll(g) = p("GPGLL,,,,,225444.00,V,N").sentence else {
            panic!()
        };
        assert!(!g.valid && g.latitude.is_none());
        let Sentence::Gns(g) =
            p("GNGNS,101530.00,4330.4800,N,01626.4000,E,AA,11,0.8,12.5,41.2,,,V").sentence
        else {
            panic!()
        };
        assert!(close(g.lat, 43.0 + 30.48 / 60.0), "{g:?}");
        assert!(close(g.lon, 16.0 + 26.4 / 60.0), "{g:?}");
        assert_eq!(
            (g.satellites, g.hdop, g.alt, g.mode.as_str()),
            (Some(11), Some(0.8), Some(12.5), "AA")
        );
        let Sentence::Dbs(d) = p("SDDBS,39.4,f,12.0,M,6.6,F").sentence else {
            panic!()
        };
        assert_eq!(
            (
                d.water_depth_feet,
                d.water_depth_meters,
                d.water_depth_fathoms
            ),
            (Some(39.4), Some(12.0), Some(6.6))
        );
        let Sentence::Dbk(d) = p("SDDBK,16.4,f,5.0,M,2.7,F").sentence else {
            panic!()
        };
        assert_eq!(
            (d.depth_feet, d.depth_meters, d.depth_fathoms),
            (Some(16.4), Some(5.0), Some(2.7))
        );
        let Sentence::Vhw(v) = p("VWVHW,245.1,T,241.3,M,4.2,N,7.8,K").sentence else {
            panic!()
        };
        assert_eq!(
            (
                v.heading_true,
                v.heading_magnetic,
                v.relative_speed_knots,
                v.relative_speed_kmph
            ),
            (Some(245.1), Some(241.3), Some(4.2), Some(7.8))
        );
        let Sentence::Zda(z) = p("GPZDA,101530.50,21,11,2026,01,30").sentence else {
            panic!()
        };
        assert_eq!((z.day, z.month, z.year), (Some(21), Some(11), Some(2026)));
        assert_eq!(
            (z.local_zone_hours, z.local_zone_minutes),
            (Some(1), Some(30))
        );
        assert_eq!(
            z.utc_time.map(|t| t.to_string()),
            Some("10:15:30.500".to_string())
        );
    }

    #[test]
    fn our_marine_sentences_parse_field_by_field() {
        assert_eq!(
            p("HCHDG,101.1,2.5,W,4.0,E").sentence,
            Sentence::Hdg {
                heading: Some(101.1),
                deviation: Some(-2.5),
                variation: Some(4.0)
            }
        );
        assert_eq!(
            p("HCHDG,98.3,,,,").sentence,
            Sentence::Hdg {
                heading: Some(98.3),
                deviation: None,
                variation: None
            }
        );
        assert_eq!(
            p("HCHDM,235.7,M").sentence,
            Sentence::Hdm {
                heading: Some(235.7)
            }
        );
        assert_eq!(
            p("SDDBT,24.6,f,7.5,M,4.1,F").sentence,
            Sentence::Dbt {
                feet: Some(24.6),
                metres: Some(7.5),
                fathoms: Some(4.1)
            }
        );
        assert_eq!(
            p("TIROT,-12.3,A").sentence,
            Sentence::Rot {
                rate: Some(-12.3),
                valid: true
            }
        );
        assert_eq!(
            p("TIROT,5.0,V").sentence,
            Sentence::Rot {
                rate: Some(5.0),
                valid: false
            }
        );
        let Sentence::Xdr(x) = p("IIXDR,A,-2.5,D,PITCH,A,1.25,D,ROLL").sentence else {
            panic!()
        };
        assert_eq!(x.len(), 2);
        assert_eq!((x[0].name.as_str(), x[0].value), ("PITCH", Some(-2.5)));
        assert_eq!(
            (x[1].kind.as_str(), x[1].unit.as_str(), x[1].value),
            ("A", "D", Some(1.25))
        );
    }

    #[test]
    fn dpt_and_gns_read_the_crates_vectors_and_the_forms_it_refuses() {
        // the nmea crate's own test sentences, whole (checksums as the crate has them)
        for (l, depth, offset) in [
            ("$SDDPT,2.4,,*53", Some(2.4), None),
            ("$SDDPT,15.2,0.5*64", Some(15.2), Some(0.5)),
            ("$SDDPT,17.3,0.5*67", Some(17.3), Some(0.5)),
        ] {
            let Sentence::Dpt {
                depth: d,
                offset: o,
                range,
            } = parse(l).unwrap().sentence
            else {
                panic!("{l}")
            };
            assert_eq!((d, o, range), (depth, offset, None), "{l}");
        }
        let keel = p("SDDPT,12.0,-1.5,100");
        assert_eq!(
            keel.sentence,
            Sentence::Dpt {
                depth: Some(12.0),
                offset: Some(-1.5),
                range: Some(100.0)
            }
        );
        let l = "$GPGNS,224749.00,3333.4268304,N,11153.3538273,W,D,19,0.6,406.110,-26.294,6.0,0138,S,*46";
        let Sentence::Gns(g) = parse(l).unwrap().sentence else {
            panic!()
        };
        assert!((g.lat.unwrap() - (33.0 + 33.4268304 / 60.0)).abs() < 1e-12);
        assert!((g.lon.unwrap() + (111.0 + 53.3538273 / 60.0)).abs() < 1e-12);
        assert_eq!(
            (g.mode.as_str(), g.satellites, g.hdop, g.alt, g.status),
            ("D", Some(19), Some(0.6), Some(406.11), Some('S'))
        );
        let Sentence::Gns(g) =
            p("GNGNS,101530.00,4330.4800,N,01626.4000,E,AAN,14,0.7,12.5,41.2,,").sentence
        else {
            panic!()
        };
        assert_eq!((g.mode.as_str(), g.status, g.fixed()), ("AAN", None, true));
        for (body, reason) in [
            (
                "GNGNS,101530.00,4330.4800,N,01626.4000,E,a1,14,0.7,12.5,41.2,,",
                "GNS mode `a1` is not mode letters",
            ),
            (
                "GNGNS,101530.00,4390.4800,N,01626.4000,E,A,14,0.7,12.5,41.2,,",
                "latitude `4390.4800` is not ddmm.mmmm",
            ),
            (
                "GNGNS,101530.00,4330.4800,N",
                "GNS has 3 fields, 12 or more were expected",
            ),
            ("GPXTE,A,A,0.67,X,N", "XTE direction to steer is not L or R"),
            ("GPXTE,A,A,0.67,L,K", "XTE unit is not N (nautical miles)"),
        ] {
            let e = parse(line(b'$', body)).unwrap_err();
            assert!(e.reason.contains(reason), "{body}: {e}");
        }
    }

    #[test]
    fn marine_sentences_the_crate_lacks_parse_field_by_field() {
        assert_eq!(
            p("WIMWD,180.0,T,175.0,M,12.0,N,6.2,M").sentence,
            Sentence::Mwd {
                true_direction: Some(180.0),
                magnetic_direction: Some(175.0),
                knots: Some(12.0),
                mps: Some(6.2)
            }
        );
        assert_eq!(
            p("VDVBW,3.0,-0.4,A,3.1,-0.5,V").sentence,
            Sentence::Vbw {
                water_along: Some(3.0),
                water_across: Some(-0.4),
                water_valid: true,
                ground_along: Some(3.1),
                ground_across: Some(-0.5),
                ground_valid: false
            }
        );
        assert_eq!(
            p("AGRSA,-12.5,A,,V").sentence,
            Sentence::Rsa {
                starboard: Some(-12.5),
                starboard_valid: true,
                port: None,
                port_valid: false
            }
        );
        assert_eq!(
            p("GPXTE,A,A,0.67,L,N,D").sentence,
            Sentence::Xte {
                error: Some(0.67),
                valid: true,
                mode: Some('D')
            }
        );
        assert_eq!(
            p("GPXTE,A,A,0.67,R,N,N").sentence,
            Sentence::Xte {
                error: Some(-0.67),
                valid: false,
                mode: Some('N')
            }
        );
        assert_eq!(
            p("HETHS,77.52,E").sentence,
            Sentence::Ths {
                heading: Some(77.52),
                mode: 'E'
            }
        );
        let Sentence::Mwv(w) = p("WIMWV,214.8,R,0.1,K,A").sentence else {
            panic!()
        };
        assert_eq!(
            (w.wind_direction, w.wind_speed, w.data_valid),
            (Some(214.8), Some(0.1), true)
        );
        let Sentence::Txt(t) = p("GPTXT,01,01,02,u-blox ag - www.u-blox.com").sentence else {
            panic!()
        };
        assert_eq!(
            (t.count, t.seq, t.text_ident, t.text.as_str()),
            (1, 1, 2, "u-blox ag - www.u-blox.com")
        );
    }

    #[test]
    fn bad_fields_are_errors_naming_the_field() {
        let e = parse(line(b'$', "HCHDG,east,,,,")).unwrap_err();
        assert!(e.reason.contains("heading `east` is not a number"), "{e}");
        let e = parse(line(b'$', "IIXDR,A,1,D")).unwrap_err();
        assert!(e.reason.contains("multiple of 4"), "{e}");
        assert!(parse(line(b'$', "GPGGA,garbage")).is_err());
        let e = parse(line(b'$', "SDDPT,inf,0.5")).unwrap_err();
        assert!(e.reason.contains("depth `inf` is not a number"), "{e}");
        assert!(parse("GPGGA,1*00").is_err());
    }

    #[test]
    fn the_talker_is_read_as_parse_reads_it() {
        for (body, start) in [
            (
                "GNRMC,123519,A,4807.038,N,01131.000,E,010.0,090.0,230394,,",
                b'$',
            ),
            ("HCHDG,98.3,,,,", b'$'),
            ("AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0", b'!'),
            ("PGRME,15.0,M,45.0,M,25.0,M", b'$'),
            ("OSI,8080808080,S,1", b'$'),
        ] {
            let l = line(start, body);
            assert_eq!(talker(l), parse(l).unwrap().talker(), "{l}");
        }
        assert_eq!(talker(line(b'$', "GNRMC,1")), "GN");
        assert_eq!(talker("GPGGA,1*00"), "");
    }

    #[test]
    fn others_pass_through() {
        let a = parse(line(b'!', "AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0")).unwrap();
        assert_eq!((a.talker(), a.formatter()), ("", "AIVDM"));
        let Sentence::Fields(f) = &a.sentence else {
            panic!("{a:?}")
        };
        assert_eq!(f.len(), 6);
        assert_eq!(&*f[4], "13aEOK?P00PD2wVMdLDRhgvL289?");
        let o = parse(line(b'$', "OSI,8080808080,S,1")).unwrap();
        assert_eq!(o.formatter(), "OSI");
        let x = parse(line(b'$', "PGRME,15.0,M,45.0,M,25.0,M")).unwrap();
        assert_eq!(x.formatter(), "PGRME");
        assert!(matches!(&x.sentence, Sentence::Fields(f) if f.len() == 6));
        let long = parse(line(b'$', "PABCDEFGHIJKLMNOPQRS,1")).unwrap();
        assert_eq!(
            long.formatter(),
            "PABCDEFGHIJKLMN",
            "cut to {MAX_ADDRESS} letters"
        );
        let unread = parse(line(b'$', "GPAAM,A,A,0.10,N,WPTNME")).unwrap();
        assert_eq!(
            (unread.formatter(), &unread.sentence),
            ("AAM", &Sentence::Other)
        );
    }

    #[test]
    fn built_sentences_read_back() {
        let keep = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
        let Sentence::Gga(g) = parse(keep(build::gga("GP", 3723.5, 43.508, -16.44, true, 9)))
            .unwrap()
            .sentence
        else {
            panic!()
        };
        assert!((g.latitude.unwrap() - 43.508).abs() < 1e-6);
        assert!((g.longitude.unwrap() + 16.44).abs() < 1e-6);
        let rmc = keep(build::rmc("GP", 60.0, "211126", -12.5, 170.25, 2.0, 359.9));
        let Sentence::Rmc(r) = parse(rmc).unwrap().sentence else {
            panic!()
        };
        assert!((f64::from(r.speed_over_ground.unwrap()) - 2.0 / crate::units::KNOT).abs() < 0.01);
        assert_eq!(
            parse(keep(build::hdg("HC", 10.0, -1.5, 3.0)))
                .unwrap()
                .sentence,
            Sentence::Hdg {
                heading: Some(10.0),
                deviation: Some(-1.5),
                variation: Some(3.0)
            }
        );
        let Sentence::Xdr(x) = parse(keep(build::xdr_pitch_roll("II", 3.0, -4.0)))
            .unwrap()
            .sentence
        else {
            panic!()
        };
        assert_eq!((x[0].value, x[1].value), (Some(3.0), Some(-4.0)));
        assert_eq!(time_field(3723.5), "010203.50");
    }
}
