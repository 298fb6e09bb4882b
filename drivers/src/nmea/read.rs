//! What each NMEA sensor driver makes of a sentence: the datasets of its outputs, every value
//! range-checked.

use super::attitude::Source;
use super::sensors::{Readings, Sensor, checked, in_range};
use super::sentence::{Parsed, Sentence, Transducer};
use crate::units::{FOOT, KNOT};
use nmea::sentences::FixType;
use seabus_medium::{DataMap, Key, Value};
use seabus_modules::geo::wrap360;
use tokio::time::Instant;

/// The deepest water there is, in metres (with margin): a deeper reading is not one.
pub const MAX_DEPTH: f64 = 12_000.0;
/// The fastest a vessel goes, in knots (with margin).
pub const MAX_KNOTS: f64 = 150.0;
/// The strongest wind measured, in metres per second (with margin).
pub const MAX_WIND: f64 = 120.0;
/// The largest dilution of precision a receiver reports.
pub const MAX_DOP: f64 = 99.99;
/// The fastest turn an instrument reports, degrees per minute (100°/s).
pub const MAX_TURN: f64 = 6_000.0;
/// The largest cross-track error, nautical miles.
pub const MAX_XTE: f64 = 1_000.0;

// output indices, as in `specs`
const POSITION: usize = 0;
const VELOCITY: usize = 1;
const FIX: usize = 2;
const TIME: usize = 3;
const TEXT: usize = 4;
const HEADING: usize = 0;
const ATTITUDE: usize = 1;
const RATE: usize = 2;

/// A datamap of the fields that are there, in order: one allocation of the exact size.
#[inline]
fn map<const N: usize>(fields: [(&'static str, Option<Value>); N]) -> DataMap {
    let mut entries = Vec::with_capacity(fields.iter().filter(|(_, v)| v.is_some()).count());
    for (k, v) in fields {
        if let Some(v) = v {
            entries.push((Key::Borrowed(k), v));
        }
    }
    DataMap::from_entries(entries)
}

/// Powers of ten that bracket the magnitudes sentences carry, `POWERS[i]` = 10^(i - 10).
const POWERS: [f64; 21] = [
    1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6,
    1e7, 1e8, 1e9, 1e10,
];

/// The decimal exponent of `x` (> 0, finite): ⌊log10 x⌋, from the table where it brackets `x`.
fn exponent(x: f64) -> i32 {
    if (POWERS[0]..POWERS[20]).contains(&x) {
        // (the first power above x, less one)
        POWERS.partition_point(|p| *p <= x) as i32 - 11
    } else {
        x.log10().floor() as i32
    }
}

/// An `f32` of the `nmea` crate as the decimal it was written as (`22.4`, not
/// `22.399999618530273`): rounded to the seven significant digits an `f32` holds.
fn decimal(x: f32) -> f64 {
    let x = f64::from(x);
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(6 - exponent(x.abs()));
    (x * scale).round() / scale
}

fn fix_quality(t: FixType) -> i64 {
    match t {
        FixType::Invalid => 0,
        FixType::Gps => 1,
        FixType::DGps => 2,
        FixType::Pps => 3,
        FixType::Rtk => 4,
        FixType::FloatRtk => 5,
        FixType::Estimated => 6,
        FixType::Manual => 7,
        FixType::Simulation => 8,
    }
}

fn valid_text(v: bool) -> Option<Value> {
    Some(Value::label(if v { "A" } else { "V" }))
}

/// A position's fields besides latitude and longitude (unused ones `("", None)`).
type More = [(&'static str, Option<Value>); 4];

/// No more fields.
const NO_MORE: More = [("", None), ("", None), ("", None), ("", None)];

impl Sensor {
    /// A position, with the source when one is configured.
    fn position(&self, lat: f64, lon: f64, more: More) -> DataMap {
        let [a, b, c, d] = more;
        map([
            ("lat", Some(lat.into())),
            ("lon", Some(lon.into())),
            a,
            b,
            c,
            d,
            ("source", self.source.clone().map(Value::from)),
        ])
    }

    /// A position when `lat`/`lon` are both there and in range.
    fn push_position(&self, lat: Option<f64>, lon: Option<f64>, more: More, out: &mut Readings) {
        if let (Some(lat), Some(lon)) = (lat, lon)
            && in_range("latitude", lat, -90.0, 90.0, out)
            && in_range("longitude", lon, -180.0, 180.0, out)
        {
            out.push((POSITION, self.position(lat, lon, more)));
        }
    }

    /// A GPS: positions, velocities, fix status, time and text.
    pub(super) fn read_gps(&self, parsed: &Parsed, out: &mut Readings) {
        let f = parsed.formatter();
        let fed = |i: usize| self.fed(i, f);
        match &parsed.sentence {
            Sentence::Gga(g) => {
                let quality = g.fix_type.map_or(0, fix_quality);
                let Ok(hdop) = checked("HDOP", g.hdop.map(decimal), 0.0, MAX_DOP, out) else {
                    return;
                };
                let sats = g.fix_satellites.map(Value::from);
                // quality 0 (no fix): whatever position it carries is not one
                if fed(POSITION) && quality > 0 {
                    let more = [
                        ("fix", Some(quality.into())),
                        ("satellites", sats.clone()),
                        ("hdop", hdop.map(Value::from)),
                        ("alt", g.altitude.map(|a| decimal(a).into())),
                    ];
                    self.push_position(g.latitude, g.longitude, more, out);
                }
                if fed(FIX) {
                    out.push((
                        FIX,
                        map([
                            ("valid", Some((quality > 0).into())),
                            ("sentence", Some(Value::label("GGA"))),
                            ("quality", Some(quality.into())),
                            ("satellites", sats),
                            ("hdop", hdop.map(Value::from)),
                        ]),
                    ));
                }
            }
            Sentence::Gns(g) => {
                let Ok(hdop) = checked("HDOP", g.hdop, 0.0, MAX_DOP, out) else {
                    return;
                };
                let mode = Some(Value::from(g.mode.as_str()));
                let sats = g.satellites.map(Value::from);
                if fed(POSITION) && g.fixed() {
                    let more = [
                        ("mode", mode.clone()),
                        ("satellites", sats.clone()),
                        ("hdop", hdop.map(Value::from)),
                        ("alt", g.alt.map(Value::from)),
                    ];
                    self.push_position(g.lat, g.lon, more, out);
                }
                if fed(FIX) {
                    out.push((
                        FIX,
                        map([
                            ("valid", Some(g.fixed().into())),
                            ("sentence", Some(Value::label("GNS"))),
                            ("mode", mode),
                            ("status", g.status.map(|c| Value::from(c.to_string()))),
                            ("satellites", sats),
                            ("hdop", hdop.map(Value::from)),
                        ]),
                    ));
                }
            }
            Sentence::Gll(g) => {
                if fed(POSITION) && g.valid {
                    self.push_position(g.latitude, g.longitude, NO_MORE, out);
                }
                if fed(FIX) {
                    out.push((FIX, status_only("GLL", g.valid)));
                }
            }
            Sentence::Rmc(r) => {
                let valid = r.status_of_fix != nmea::sentences::rmc::RmcStatusOfFix::Invalid;
                if valid && fed(POSITION) {
                    self.push_position(r.lat, r.lon, NO_MORE, out);
                }
                if valid && fed(VELOCITY) {
                    ground_velocity(
                        r.speed_over_ground.map(decimal),
                        r.true_course.map(decimal),
                        out,
                    );
                }
                if fed(FIX) {
                    out.push((FIX, status_only("RMC", valid)));
                }
            }
            Sentence::Vtg(v) if fed(VELOCITY) => {
                ground_velocity(
                    v.speed_over_ground.map(decimal),
                    v.true_course.map(decimal),
                    out,
                );
            }
            Sentence::Gsa(g) if fed(FIX) => gsa(g, out),
            Sentence::Gsv(g) if fed(FIX) && g.sentence_num == 1 => {
                out.push((
                    FIX,
                    map([
                        ("valid", Some(true.into())),
                        ("sentence", Some(Value::label("GSV"))),
                        ("in_view", Some(u32::from(g.sats_in_view).into())),
                        ("constellation", Some(Value::from(g.gnss_type.to_string()))),
                    ]),
                ));
            }
            Sentence::Gst(g) if fed(FIX) => gst(g, out),
            Sentence::Zda(z) if fed(TIME) => zda(z, out),
            Sentence::Txt(t) if fed(TEXT) => {
                let kind = match t.text_ident {
                    0 => "error",
                    1 => "warning",
                    2 => "notice",
                    7 => "user",
                    _ => "other",
                };
                out.push((
                    TEXT,
                    map([
                        ("text", Some(Value::from(t.text.as_str()))),
                        ("kind", Some(Value::label(kind))),
                        ("part", Some(t.seq.into())),
                        ("parts", Some(t.count.into())),
                        ("talker", Some(Value::from(parsed.talker()))),
                    ]),
                ));
            }
            _ => {}
        }
    }

    /// A compass or gyro: headings from HDT, HDG, HDM and THS (HDG and HDM corrected into a true
    /// heading where the variation is known) and from the attitude table's sentences that carry
    /// one; pitch and roll from XDR and the table, kept across sentences; an attitude whenever a
    /// true heading comes while both are fresh; rates of turn from ROT.
    pub(super) fn read_heading(&mut self, parsed: &Parsed, now: Instant, out: &mut Readings) {
        let f = parsed.formatter();
        let fed = |i: usize| self.fed(i, f);
        match &parsed.sentence {
            Sentence::Hdt(h) if fed(HEADING) => {
                if let Some(hdg) = h.heading.map(decimal)
                    && in_range("heading", hdg, 0.0, 360.0, out)
                {
                    out.push((HEADING, heading(hdg, false)));
                }
            }
            Sentence::Ths {
                heading: Some(hdg),
                mode,
            } if fed(HEADING) && *mode != 'V' && in_range("heading", *hdg, 0.0, 360.0, out) => {
                let mut m = heading(*hdg, false);
                m.push("mode", mode.to_string());
                out.push((HEADING, m));
            }
            Sentence::Hdg {
                heading: Some(hdg),
                deviation,
                variation,
            } if fed(HEADING) && in_range("heading", *hdg, 0.0, 360.0, out) => {
                let dev = deviation.unwrap_or(0.0);
                if in_range("deviation", dev, -180.0, 180.0, out) {
                    let var = variation.or(self.variation);
                    let mut m = heading(hdg + dev + var.unwrap_or(0.0), var.is_none());
                    m.push("deviation", dev);
                    if let Some(var) = var {
                        m.push("variation", var);
                    }
                    out.push((HEADING, m));
                }
            }
            Sentence::Hdm { heading: Some(hdg) }
                if fed(HEADING) && in_range("heading", *hdg, 0.0, 360.0, out) =>
            {
                match self.variation {
                    Some(var) => {
                        out.push((HEADING, heading(hdg + var, false).and("variation", var)))
                    }
                    None => out.push((HEADING, heading(*hdg, true))),
                }
            }
            Sentence::Xdr(x) if fed(ATTITUDE) => self.xdr(x, now, out),
            Sentence::Fields(fields) if fed(ATTITUDE) => self.proprietary(f, fields, now, out),
            Sentence::Rot {
                rate: Some(r),
                valid: true,
            } if fed(RATE) && in_range("rate of turn (°/min)", *r, -MAX_TURN, MAX_TURN, out) => {
                out.push((
                    RATE,
                    map([
                        ("rate", Some((r / 60.0).into())),
                        ("valid", Some(true.into())),
                    ]),
                ));
            }
            _ => {}
        }
        self.attitude(f, now, out);
    }

    /// Pitch and roll from an XDR's angle transducers (`PITCH`/`PTCH`, `ROLL`), alone or
    /// together.
    fn xdr(&mut self, x: &[Transducer], now: Instant, out: &mut Readings) {
        for t in x.iter().filter(|t| t.kind == "A") {
            let Some(v) = t.value else { continue };
            let name = t.name.as_str();
            if name.eq_ignore_ascii_case("PITCH") || name.eq_ignore_ascii_case("PTCH") {
                if in_range("pitch", v, -90.0, 90.0, out) {
                    self.combined.pitch(v, Source::new("XDR"), now);
                }
            } else if name.eq_ignore_ascii_case("ROLL") && in_range("roll", v, -180.0, 180.0, out) {
                self.combined.roll(v, Source::new("XDR"), now);
            }
        }
    }

    /// Pitch, roll and heading from a proprietary sentence the attitude table reads.
    fn proprietary(
        &mut self,
        address: &str,
        fields: &[Box<str>],
        now: Instant,
        out: &mut Readings,
    ) {
        let Some(read) = self.table.read(address, fields) else {
            return;
        };
        let (a, magnetic) = match read {
            Ok((a, entry)) => (a, entry.magnetic),
            Err(why) => {
                out.out_of_range(why);
                return;
            }
        };
        let from = Source::new(address);
        let pitch = checked("pitch", a.pitch, -90.0, 90.0, out);
        let roll = checked("roll", a.roll, -180.0, 180.0, out);
        let hdg = checked("heading", a.heading, 0.0, 360.0, out);
        let (Ok(pitch), Ok(roll), Ok(hdg)) = (pitch, roll, hdg) else {
            return;
        };
        if let Some(p) = pitch {
            self.combined.pitch(p, from, now);
        }
        if let Some(r) = roll {
            self.combined.roll(r, from, now);
        }
        // (a sentence the table reads is fed to the attitude; a heading it carries is one)
        if let Some(h) = hdg {
            out.push((HEADING, heading(h, magnetic)));
        }
    }

    /// An attitude when this sentence gave a true heading and pitch and roll are fresh; it says
    /// which sentence gave each angle.
    fn attitude(&self, formatter: &str, now: Instant, out: &mut Readings) {
        // (pitch and roll are looked at first: without them no heading makes an attitude)
        let Some(made) = self.combined.fresh(now) else {
            return;
        };
        let Some(yaw) = out.true_heading() else {
            return;
        };
        let sources = format!(
            "yaw {formatter}, pitch {}, roll {}",
            made.pitch_from.as_str(),
            made.roll_from.as_str()
        );
        out.push((
            ATTITUDE,
            map([
                ("yaw", Some(wrap360(yaw).into())),
                ("pitch", Some(made.pitch.into())),
                ("roll", Some(made.roll.into())),
                ("sources", Some(sources.into())),
            ]),
        ));
    }

    /// An echo sounder: altitudes from DBT, DPT and DBK, plus the offset.
    pub(super) fn read_sounder(&self, parsed: &Parsed, out: &mut Readings) {
        if !self.fed(0, parsed.formatter()) {
            return;
        }
        let depth = match &parsed.sentence {
            Sentence::Dbt { metres, feet, .. } => metres.or(feet.map(|f| f * FOOT)),
            Sentence::Dpt { depth, .. } => *depth,
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
            out.push((
                0,
                map([
                    ("altitude", Some((d + self.offset).into())),
                    ("valid", Some(true.into())),
                ]),
            ));
        }
    }

    /// A wind instrument: apparent or true wind relative to the bow (MWV), wind direction from
    /// north (MWD).
    pub(super) fn read_wind(&self, parsed: &Parsed, out: &mut Readings) {
        use nmea::sentences::mwv::{MwvReference, MwvWindSpeedUnits as U};
        if !self.fed(0, parsed.formatter()) {
            return;
        }
        match &parsed.sentence {
            Sentence::Mwv(w) if w.data_valid => {
                let (Some(angle), Some(speed), Some(unit)) =
                    (w.wind_direction, w.wind_speed, w.wind_speed_units)
                else {
                    return;
                };
                let mps = decimal(speed)
                    * match unit {
                        U::MetersPerSecond => 1.0,
                        U::Knots => KNOT,
                        U::KilometersPerHour => 1.0 / 3.6,
                        U::MilesPerHour => 1609.344 / 3600.0,
                    };
                let angle = decimal(angle);
                if in_range("wind angle", angle, 0.0, 360.0, out)
                    && in_range("wind speed (m/s)", mps, 0.0, MAX_WIND, out)
                {
                    let reference = match w.reference {
                        Some(MwvReference::Theoretical) => "true",
                        _ => "apparent",
                    };
                    out.push((
                        0,
                        map([
                            ("speed", Some(mps.into())),
                            ("angle", Some(wrap360(angle).into())),
                            ("reference", Some(Value::label(reference))),
                        ]),
                    ));
                }
            }
            Sentence::Mwd {
                true_direction,
                magnetic_direction,
                knots,
                mps,
            } => {
                let Some(speed) = mps.or(knots.map(|k| k * KNOT)) else {
                    return;
                };
                let dir = checked("wind direction", *true_direction, 0.0, 360.0, out);
                let mag = checked(
                    "magnetic wind direction",
                    *magnetic_direction,
                    0.0,
                    360.0,
                    out,
                );
                if let (Ok(dir), Ok(mag)) = (dir, mag)
                    && (dir.is_some() || mag.is_some())
                    && in_range("wind speed (m/s)", speed, 0.0, MAX_WIND, out)
                {
                    out.push((
                        0,
                        map([
                            ("speed", Some(speed.into())),
                            ("direction", dir.map(|d| wrap360(d).into())),
                            ("magnetic_direction", mag.map(|d| wrap360(d).into())),
                            ("reference", Some(Value::label("north"))),
                        ]),
                    ));
                }
            }
            _ => {}
        }
    }

    /// A speed log: speed through the water (VHW), along and across the hull (VBW).
    pub(super) fn read_log(&self, parsed: &Parsed, out: &mut Readings) {
        if !self.fed(0, parsed.formatter()) {
            return;
        }
        let max = MAX_KNOTS * KNOT;
        match &parsed.sentence {
            Sentence::Vhw(v) => {
                let speed = v
                    .relative_speed_knots
                    .map(|k| k * KNOT)
                    .or(v.relative_speed_kmph.map(|k| k / 3.6));
                if let Some(s) = speed
                    && in_range("water speed (m/s)", s, 0.0, max, out)
                {
                    out.push((
                        0,
                        map([
                            ("speed", Some(s.into())),
                            ("reference", Some(Value::label("water"))),
                        ]),
                    ));
                }
            }
            Sentence::Vbw {
                water_along: Some(along),
                water_across,
                water_valid: true,
                ..
            } => {
                let (along, across) = (along * KNOT, water_across.unwrap_or(0.0) * KNOT);
                if in_range("water speed along (m/s)", along, -max, max, out)
                    && in_range("water speed across (m/s)", across, -max, max, out)
                {
                    out.push((
                        0,
                        map([
                            ("speed", Some(along.hypot(across).into())),
                            ("surge", Some(along.into())),
                            ("sway", water_across.map(|_| across.into())),
                            ("reference", Some(Value::label("water"))),
                        ]),
                    ));
                }
            }
            _ => {}
        }
    }

    /// Steering: rudder angles (RSA), cross-track error (XTE).
    pub(super) fn read_steering(&self, parsed: &Parsed, out: &mut Readings) {
        let f = parsed.formatter();
        match &parsed.sentence {
            Sentence::Rsa {
                starboard,
                starboard_valid,
                port,
                port_valid,
            } if self.fed(0, f) => {
                let stbd = starboard.filter(|_| *starboard_valid);
                let port = port.filter(|_| *port_valid);
                let (Ok(stbd), Ok(port)) = (
                    checked("rudder", stbd, -90.0, 90.0, out),
                    checked("port rudder", port, -90.0, 90.0, out),
                ) else {
                    return;
                };
                if let Some(angle) = stbd.or(port) {
                    out.push((
                        0,
                        map([
                            ("angle", Some(angle.into())),
                            (
                                "port_angle",
                                port.filter(|_| stbd.is_some()).map(Value::from),
                            ),
                        ]),
                    ));
                }
            }
            Sentence::Xte {
                error: Some(nm),
                valid: true,
                mode,
            } if self.fed(1, f)
                && in_range("cross-track error (nm)", *nm, -MAX_XTE, MAX_XTE, out) =>
            {
                out.push((
                    1,
                    map([
                        ("error", Some((nm * 1852.0).into())),
                        ("mode", mode.map(|c| Value::from(c.to_string()))),
                    ]),
                ));
            }
            _ => {}
        }
    }
}

/// A fix status that says only whether the sentence's data is valid.
fn status_only(sentence: &'static str, valid: bool) -> DataMap {
    map([
        ("valid", Some(valid.into())),
        ("sentence", Some(Value::label(sentence))),
        ("status", valid_text(valid)),
    ])
}

/// The fix status of a GSA: 2D or 3D, the satellites used, the DOPs.
fn gsa(g: &nmea::sentences::GsaData, out: &mut Readings) {
    use nmea::sentences::gsa::GsaMode2;
    let dop =
        |what, v: Option<f32>, out: &mut Readings| checked(what, v.map(decimal), 0.0, MAX_DOP, out);
    let (Ok(pdop), Ok(hdop), Ok(vdop)) = (
        dop("PDOP", g.pdop, out),
        dop("HDOP", g.hdop, out),
        dop("VDOP", g.vdop, out),
    ) else {
        return;
    };
    let fix = match g.mode2 {
        GsaMode2::NoFix => "none",
        GsaMode2::Fix2D => "2d",
        GsaMode2::Fix3D => "3d",
    };
    let used = g.fix_sats_prn.len() as u32;
    let m = map([
        ("valid", Some((g.mode2 != GsaMode2::NoFix).into())),
        ("sentence", Some(Value::label("GSA"))),
        ("fix_type", Some(Value::label(fix))),
        ("satellites", Some(used.into())),
        ("pdop", pdop.map(Value::from)),
        ("hdop", hdop.map(Value::from)),
        ("vdop", vdop.map(Value::from)),
    ]);
    out.push((FIX, m));
}

/// The position error statistics of a GST, as standard deviations in metres.
fn gst(g: &nmea::sentences::GstData, out: &mut Readings) {
    let sd =
        |what, v: Option<f32>, out: &mut Readings| checked(what, v.map(decimal), 0.0, 1e6, out);
    let (Ok(lat), Ok(lon), Ok(alt)) = (
        sd("latitude error", g.lat_sd, out),
        sd("longitude error", g.long_sd, out),
        sd("altitude error", g.alt_sd, out),
    ) else {
        return;
    };
    if lat.is_none() && lon.is_none() && alt.is_none() {
        return;
    }
    out.push((
        FIX,
        map([
            ("valid", Some(true.into())),
            ("sentence", Some(Value::label("GST"))),
            ("lat_sigma", lat.map(Value::from)),
            ("lon_sigma", lon.map(Value::from)),
            ("alt_sigma", alt.map(Value::from)),
        ]),
    ));
}

/// The time of a ZDA as seconds since 1970 (UTC), with the local zone in minutes east.
fn zda(z: &nmea::sentences::ZdaData, out: &mut Readings) {
    let Some(t) = z.utc_date_time() else {
        return;
    };
    let year = i64::from(z.year.unwrap_or(0));
    if !(1980..=2200).contains(&year) {
        out.out_of_range(format!("year {year} is not within 1980–2200"));
        return;
    }
    let utc = t.and_utc().timestamp_micros() as f64 / 1e6;
    let zone = z.offset().map(|o| i64::from(o.local_minus_utc() / 60));
    out.push((
        TIME,
        map([("utc", Some(utc.into())), ("zone", zone.map(Value::from))]),
    ));
}

/// A velocity over ground from `knots` and `course` (degrees true) when they are in range; a
/// speed without a course gives the speed alone.
fn ground_velocity(knots: Option<f64>, course: Option<f64>, out: &mut Readings) {
    let Some(knots) = knots else { return };
    let Ok(course) = checked("course", course, 0.0, 360.0, out) else {
        return;
    };
    if !in_range("speed (knots)", knots, 0.0, MAX_KNOTS, out) {
        return;
    }
    let speed = knots * KNOT;
    let m = match course {
        Some(c) => {
            let (sin, cos) = c.to_radians().sin_cos();
            map([
                ("speed", Some(speed.into())),
                ("course", Some(wrap360(c).into())),
                ("north", Some((speed * cos).into())),
                ("east", Some((speed * sin).into())),
                ("reference", Some(Value::label("ground"))),
            ])
        }
        None => map([
            ("speed", Some(speed.into())),
            ("reference", Some(Value::label("ground"))),
        ]),
    };
    out.push((VELOCITY, m));
}

fn heading(h: f64, magnetic: bool) -> DataMap {
    map([
        ("heading", Some(wrap360(h).into())),
        ("magnetic", Some(magnetic.into())),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exponent_from_the_table_is_that_of_log10() {
        // every power of ten an f32 holds, its neighbours and values between (what `decimal` sees)
        for e in -40..=38 {
            let p: f32 = format!("1e{e}").parse().expect("a power of ten");
            let near = [p.to_bits() - 1, p.to_bits(), p.to_bits() + 1].map(f32::from_bits);
            for v in near.into_iter().chain([p * 2.5, p * 7.3, p * 9.99]) {
                let v = f64::from(v);
                if v > 0.0 && v.is_finite() {
                    assert_eq!(exponent(v), v.log10().floor() as i32, "{v}");
                }
            }
        }
        for v in [
            22.4_f32, 0.9, 545.4, 46.9, 1.5, 359.9, 1e-3, 99.99, 12_000.0,
        ] {
            let d = decimal(v);
            assert_eq!(d.to_string(), v.to_string(), "{v}");
        }
    }
}
