//! The standard datasets the navigation PGNs give, as the NMEA 0183 drivers give them from
//! sentences, so that an NMEA 2000 sensor and an NMEA 0183 one are interchangeable.
//!
//! | PGN | dataset (default topic) | how |
//! |---|---|---|
//! | 127250 vessel heading | `heading` (`nav.heading`) | a true heading as it is; a magnetic one corrected by its deviation and variation (or the `variation` parameter) into a true one, else published as magnetic |
//! | 127257 attitude | `attitude` (`nav.attitude`) | yaw, pitch, roll; without a yaw, the latest true heading within `fresh` |
//! | 127251 rate of turn | `turn-rate` (`nav.rate`) | the rate in °/s |
//! | 128267 water depth | `altitude` (`nav.altitude`) | the depth below the transducer, as an echo sounder's altitude; with a positive offset (transducer to waterline) also the water depth |
//! | 129025 position, 129029 GNSS position | `position` (`nav.position`) | 129029 adds the fix quality (its method, numbered as GGA's quality), satellites, HDOP and the height above mean sea level (altitude less the geoidal separation); none when its method is "no GNSS" |
//! | 129026 COG & SOG | `velocity` (`nav.velocity`) | speed over ground; course, north and east when the course is true |
//! | 130306 wind | `wind` (`env.wind`) | apparent or true (boat or water referenced) wind as an angle from the bow; ground-referenced wind as a direction, true or magnetic |
//! | 127508 battery status with 127506 DC status | `battery` (`power.battery`) | of instance `battery_instance`: the state of charge and time remaining of the DC status, with the voltage, current and temperature of the battery status (the two within 10 s of each other) |
//! | 126992 system time | `time` (`nav.time`) | seconds since 1970 |
//!
//! The values come from the decoded datamap (field identifiers as canboat names them, units as
//! seabus's): a value the PGN says is not available is missing there, and so the dataset lacks
//! it (or is not made, when the value is required).

use seabus_medium::{DataMap, Value};
use std::time::Duration;
use tokio::time::Instant;

/// Output: heading.
pub const HEADING: usize = 0;
/// Output: attitude.
pub const ATTITUDE: usize = 1;
/// Output: rate of turn.
pub const RATE: usize = 2;
/// Output: position.
pub const POSITION: usize = 3;
/// Output: velocity.
pub const VELOCITY: usize = 4;
/// Output: altitude above the sea floor.
pub const ALTITUDE: usize = 5;
/// Output: wind.
pub const WIND: usize = 6;
/// Output: battery.
pub const BATTERY: usize = 7;
/// Output: time.
pub const TIME: usize = 8;

/// Each output's dataset, topic parameter and default topic, in index order.
pub const OUTPUTS: [(&str, &str, &str); 9] = [
    ("heading", "heading_topic", "nav.heading"),
    ("attitude", "attitude_topic", "nav.attitude"),
    ("turn-rate", "rate_topic", "nav.rate"),
    ("position", "position_topic", "nav.position"),
    ("velocity", "velocity_topic", "nav.velocity"),
    ("altitude", "altitude_topic", "nav.altitude"),
    ("wind", "wind_topic", "env.wind"),
    ("battery", "battery_topic", "power.battery"),
    ("time", "time_topic", "nav.time"),
];

/// How long a battery status and a DC status of one instance are taken together.
pub const BATTERY_WINDOW: Duration = Duration::from_secs(10);

/// Turns decoded navigation PGNs into datasets, keeping what one PGN lends another.
#[derive(Debug)]
pub struct Navigator {
    /// Degrees east, for magnetic headings that come without one.
    pub variation: Option<f64>,
    /// How long a true heading stands in for an attitude's missing yaw.
    pub fresh: Duration,
    /// The battery instance whose status is the `battery` dataset.
    pub battery_instance: i64,
    heading: Option<(f64, Instant)>,
    charge: Option<(DataMap, Instant)>,
    status: Option<Instant>,
}

impl Navigator {
    /// A navigator with these settings.
    pub fn new(variation: Option<f64>, fresh: Duration, battery_instance: i64) -> Navigator {
        Navigator {
            variation,
            fresh,
            battery_instance,
            heading: None,
            charge: None,
            status: None,
        }
    }

    /// The datasets the decoded PGN `pgn` (fields `m`) gives, by output.
    pub fn read(&mut self, pgn: u32, m: &DataMap, now: Instant) -> Vec<(usize, DataMap)> {
        let mut out = Vec::new();
        match pgn {
            127250 => self.heading(m, now, &mut out),
            127257 => self.attitude(m, now, &mut out),
            127251 => {
                if let Some(rate) = m.get_f64("rate") {
                    out.push((RATE, DataMap::new().and("rate", rate).and("valid", true)));
                }
            }
            128267 => {
                if let Some(depth) = m.get_f64("depth") {
                    let mut a = DataMap::new().and("altitude", depth).and("valid", true);
                    if let Some(off) = m.get_f64("offset").filter(|o| *o > 0.0) {
                        a.push("water_depth", depth + off);
                    }
                    out.push((ALTITUDE, a));
                }
            }
            129025 => {
                if let (Some(lat), Some(lon)) = (m.get_f64("latitude"), m.get_f64("longitude")) {
                    out.push((POSITION, DataMap::new().and("lat", lat).and("lon", lon)));
                }
            }
            129029 => self.gnss(m, &mut out),
            129026 => {
                if let Some(sog) = m.get_f64("sog") {
                    let mut v = DataMap::new().and("speed", sog);
                    if m.get_str("cogReference") == Some("True")
                        && let Some(cog) = m.get_f64("cog")
                    {
                        let c = wrap360(cog);
                        v.push("course", c);
                        v.push("north", sog * c.to_radians().cos());
                        v.push("east", sog * c.to_radians().sin());
                    }
                    v.push("reference", Value::label("ground"));
                    out.push((VELOCITY, v));
                }
            }
            130306 => {
                let (Some(speed), Some(angle)) = (m.get_f64("windSpeed"), m.get_f64("windAngle"))
                else {
                    return out;
                };
                let angle = wrap360(angle);
                let w = DataMap::new().and("speed", speed);
                let w = match m.get_str("reference") {
                    Some("Apparent") => w.and("angle", angle).and("reference", "apparent"),
                    Some("True (boat referenced)") | Some("True (water referenced)") => {
                        w.and("angle", angle).and("reference", "true")
                    }
                    Some("True (ground referenced to North)") => {
                        w.and("direction", angle).and("reference", "north")
                    }
                    Some("Magnetic (ground referenced to Magnetic North)") => {
                        w.and("magnetic_direction", angle).and("reference", "north")
                    }
                    _ => return out,
                };
                out.push((WIND, w));
            }
            127506 => self.charge(m, now, &mut out),
            127508 => self.battery(m, now, &mut out),
            126992 => {
                if let (Some(date), Some(time)) = (m.get_f64("date"), m.get_f64("time")) {
                    out.push((TIME, DataMap::new().and("utc", date * 86_400.0 + time)));
                }
            }
            _ => {}
        }
        out
    }

    fn heading(&mut self, m: &DataMap, now: Instant, out: &mut Vec<(usize, DataMap)>) {
        let Some(h) = m.get_f64("heading") else {
            return;
        };
        let map = match m.get_str("reference") {
            Some("True") => {
                let mut map = heading(h, false);
                if let Some(var) = m.get_f64("variation") {
                    map.push("variation", var);
                }
                map
            }
            Some("Magnetic") => {
                // a deviation the sender does not give is none known (the compass is taken as
                // compensated), and is not published as a number
                let dev = m.get_f64("deviation");
                let mut map = match m.get_f64("variation").or(self.variation) {
                    Some(var) => heading(h + dev.unwrap_or(0.0) + var, false).and("variation", var),
                    None => heading(h + dev.unwrap_or(0.0), true),
                };
                if let Some(dev) = dev {
                    map.push("deviation", dev);
                }
                map
            }
            // no reference (or an error): not a heading anyone can steer by
            _ => return,
        };
        if map.get_bool("magnetic") == Some(false)
            && let Some(t) = map.get_f64("heading")
        {
            self.heading = Some((t, now));
        }
        out.push((HEADING, map));
    }

    fn attitude(&mut self, m: &DataMap, now: Instant, out: &mut Vec<(usize, DataMap)>) {
        let (Some(pitch), Some(roll)) = (m.get_f64("pitch"), m.get_f64("roll")) else {
            return;
        };
        let (yaw, from) = match m.get_f64("yaw") {
            Some(y) => (y, "127257"),
            None => match self.heading {
                Some((h, at)) if now.saturating_duration_since(at) <= self.fresh => (h, "127250"),
                _ => return,
            },
        };
        out.push((
            ATTITUDE,
            DataMap::new()
                .and("yaw", wrap360(yaw))
                .and("pitch", pitch)
                .and("roll", roll)
                .and(
                    "sources",
                    format!("yaw PGN {from}, pitch PGN 127257, roll PGN 127257"),
                ),
        ));
    }

    fn gnss(&mut self, m: &DataMap, out: &mut Vec<(usize, DataMap)>) {
        let (Some(lat), Some(lon)) = (m.get_f64("latitude"), m.get_f64("longitude")) else {
            return;
        };
        // the method numbers as GGA's quality does
        let fix = match m.get_str("method") {
            Some("no GNSS") => return,
            Some("GNSS fix") => Some(1),
            Some("DGNSS fix") => Some(2),
            Some("Precise GNSS") => Some(3),
            Some("RTK Fixed Integer") => Some(4),
            Some("RTK float") => Some(5),
            Some("Estimated (DR) mode") => Some(6),
            Some("Manual Input") => Some(7),
            Some("Simulate mode") => Some(8),
            _ => None,
        };
        let mut p = DataMap::new().and("lat", lat).and("lon", lon);
        if let Some(f) = fix {
            p.push("fix", Value::Int(f));
        }
        if let Some(n) = m.get_i64("numberOfSvs") {
            p.push("satellites", n);
        }
        if let Some(h) = m.get_f64("hdop").filter(|h| *h >= 0.0) {
            p.push("hdop", h);
        }
        if let (Some(alt), Some(sep)) = (m.get_f64("altitude"), m.get_f64("geoidalSeparation")) {
            p.push("alt", alt - sep);
        }
        out.push((POSITION, p));
    }

    /// A DC detailed status: kept for the battery status of its instance, published alone when
    /// no battery status comes.
    fn charge(&mut self, m: &DataMap, now: Instant, out: &mut Vec<(usize, DataMap)>) {
        if m.get_i64("instance") != Some(self.battery_instance)
            || m.get_str("dcType").is_some_and(|t| t != "Battery")
        {
            return;
        }
        let Some(soc) = m.get_f64("stateOfCharge") else {
            return;
        };
        let mut c = DataMap::new().and("percent", soc);
        if let Some(s) = m.get_f64("timeRemaining") {
            c.push("minutes", s / 60.0);
        }
        self.charge = Some((c.clone(), now));
        let status_fresh = self
            .status
            .is_some_and(|at| now.saturating_duration_since(at) <= BATTERY_WINDOW);
        if !status_fresh {
            out.push((BATTERY, c));
        }
    }

    fn battery(&mut self, m: &DataMap, now: Instant, out: &mut Vec<(usize, DataMap)>) {
        if m.get_i64("instance") != Some(self.battery_instance) {
            return;
        }
        self.status = Some(now);
        let Some((charge, at)) = &self.charge else {
            return;
        };
        if now.saturating_duration_since(*at) > BATTERY_WINDOW {
            return;
        }
        let mut b = charge.clone();
        for (from, to) in [
            ("voltage", "voltage"),
            ("current", "current"),
            ("temperature", "temperature"),
        ] {
            if let Some(v) = m.get_f64(from) {
                b.push(to, v);
            }
        }
        if let (Some(v), Some(i)) = (m.get_f64("voltage"), m.get_f64("current")) {
            b.push("power", v * i);
        }
        out.push((BATTERY, b));
    }
}

fn heading(h: f64, magnetic: bool) -> DataMap {
    DataMap::new()
        .and("heading", wrap360(h))
        .and("magnetic", magnetic)
}

/// An angle in degrees brought into 0 to 360.
pub fn wrap360(a: f64) -> f64 {
    let w = a.rem_euclid(360.0);
    // rem_euclid of a value a hair below 0 can round up to 360
    if w >= 360.0 { 0.0 } else { w }
}
