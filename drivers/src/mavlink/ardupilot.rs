//! What ArduPilot's MAVLink messages mean, as plain functions: mode names of ArduSub and
//! ArduRover, the values MAVLink marks unknown, depth from pressure, and the datasets each message
//! gives. They work on the datamaps the MAVLink medium delivers (fields by their MAVLink names,
//! enums as their names), so the driver needs nothing of the medium but its topics.

use seabus_medium::{DataMap, Value};
use seabus_modules::geo::wrap360;

/// Standard gravity, m/s².
pub const G: f64 = 9.80665;
/// Sea water's density, kg/m³.
pub const SALT: f64 = 1025.0;
/// Fresh water's density, kg/m³.
pub const FRESH: f64 = 1000.0;
/// Mean sea-level pressure, hPa: the surface pressure unless the system file says otherwise.
pub const SURFACE_HPA: f64 = 1013.25;

/// Which of ArduPilot's firmwares a vehicle runs, as its HEARTBEAT's type says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Firmware {
    /// ArduSub (`MAV_TYPE_SUBMARINE`).
    Sub,
    /// ArduRover (`MAV_TYPE_GROUND_ROVER`, `MAV_TYPE_SURFACE_BOAT`).
    Rover,
    /// Anything else: modes are shown by number.
    Other,
}

impl Firmware {
    /// The firmware of a vehicle whose HEARTBEAT has `mav_type` and `autopilot` (names).
    pub fn of(mav_type: &str, autopilot: &str) -> Firmware {
        if autopilot != "MAV_AUTOPILOT_ARDUPILOTMEGA" {
            return Firmware::Other;
        }
        match mav_type {
            "MAV_TYPE_SUBMARINE" => Firmware::Sub,
            "MAV_TYPE_GROUND_ROVER" | "MAV_TYPE_SURFACE_BOAT" => Firmware::Rover,
            _ => Firmware::Other,
        }
    }

    /// Its modes: custom mode number and name.
    fn modes(self) -> &'static [(u32, &'static str)] {
        match self {
            // ArduSub's mode numbers (ArduSub/mode.h); mode 2 is ALT_HOLD in the code, DEPTH_HOLD to pilots
            Firmware::Sub => &[
                (0, "STABILIZE"),
                (1, "ACRO"),
                (2, "DEPTH_HOLD"),
                (3, "AUTO"),
                (4, "GUIDED"),
                (7, "CIRCLE"),
                (9, "SURFACE"),
                (16, "POSHOLD"),
                (19, "MANUAL"),
                (20, "MOTOR_DETECT"),
                (21, "SURFTRAK"),
            ],
            // ArduRover's (Rover/mode.h)
            Firmware::Rover => &[
                (0, "MANUAL"),
                (1, "ACRO"),
                (3, "STEERING"),
                (4, "HOLD"),
                (5, "LOITER"),
                (6, "FOLLOW"),
                (7, "SIMPLE"),
                (8, "DOCK"),
                (9, "CIRCLE"),
                (10, "AUTO"),
                (11, "RTL"),
                (12, "SMART_RTL"),
                (15, "GUIDED"),
                (16, "INITIALISING"),
            ],
            Firmware::Other => &[],
        }
    }

    /// The name of custom mode `n`; `MODE_n` for a number the firmware has no name for.
    pub fn mode_name(self, n: i64) -> String {
        self.modes()
            .iter()
            .find(|(m, _)| i64::from(*m) == n)
            .map_or_else(|| format!("MODE_{n}"), |(_, name)| (*name).to_string())
    }

    /// The custom mode called `name` (in any case; ArduSub's `ALT_HOLD` is `DEPTH_HOLD`; `MODE_n`
    /// is mode n of any firmware); the error lists the names there are.
    pub fn mode_number(self, name: &str) -> Result<u32, String> {
        let upper = name.trim().to_ascii_uppercase();
        let wanted = match (self, upper.as_str()) {
            (Firmware::Sub, "ALT_HOLD") => "DEPTH_HOLD",
            (_, other) => other,
        };
        if let Some((n, _)) = self.modes().iter().find(|(_, m)| *m == wanted) {
            return Ok(*n);
        }
        if let Some(n) = wanted
            .strip_prefix("MODE_")
            .and_then(|n| n.parse::<u32>().ok())
        {
            return Ok(n);
        }
        let names: Vec<&str> = self.modes().iter().map(|(_, m)| *m).collect();
        Err(if names.is_empty() {
            format!(
                "`{name}` is no mode this vehicle is known to have (give MODE_n, n its custom mode number)"
            )
        } else {
            format!(
                "`{name}` is no mode of this vehicle; its modes are {}",
                names.join(", ")
            )
        })
    }
}

/// A name without its MAVLink enum's prefix: `MAV_RESULT_DENIED` → `DENIED`.
pub fn short<'a>(name: &'a str, prefix: &str) -> &'a str {
    name.strip_prefix(prefix).unwrap_or(name)
}

/// An integer field, absent when it is missing or equals `unknown` (the value MAVLink gives for
/// "not known": `INT16_MAX`, `UINT16_MAX`, −1).
pub fn known(map: &DataMap, field: &str, unknown: i64) -> Option<i64> {
    map.get_i64(field).filter(|v| *v != unknown)
}

/// A float field, absent when missing or not a number.
pub fn float(map: &DataMap, field: &str) -> Option<f64> {
    map.get_f64(field).filter(|v| v.is_finite())
}

/// Depth in metres under a surface at `surface` hPa, from an absolute pressure in hPa, in water
/// of `density` kg/m³.
pub fn depth_from_pressure(press_abs: f64, surface: f64, density: f64) -> f64 {
    (press_abs - surface) * 100.0 / (density * G)
}

/// `nav.attitude` from ATTITUDE (radians and radians a second): degrees, yaw 0–360.
pub fn attitude(m: &DataMap) -> Option<DataMap> {
    let (roll, pitch, yaw) = (float(m, "roll")?, float(m, "pitch")?, float(m, "yaw")?);
    let mut out = DataMap::new()
        .with("yaw", wrap360(yaw.to_degrees()))
        .with("pitch", pitch.to_degrees())
        .with("roll", roll.to_degrees());
    for (from, to) in [
        ("yawspeed", "yaw_rate"),
        ("pitchspeed", "pitch_rate"),
        ("rollspeed", "roll_rate"),
    ] {
        if let Some(v) = float(m, from) {
            out.insert(to, v.to_degrees());
        }
    }
    Some(out)
}

/// What GLOBAL_POSITION_INT gives: position, velocity, heading and the depth its relative
/// altitude says.
#[derive(Debug, Default, PartialEq)]
pub struct GlobalPosition {
    /// `nav.position`: absent while the vehicle has no position (lat and lon both 0, as ArduPilot
    /// sends without an origin).
    pub position: Option<DataMap>,
    /// `nav.velocity` over ground, north-east-down.
    pub velocity: Option<DataMap>,
    /// `nav.heading`: absent when `hdg` is UINT16_MAX.
    pub heading: Option<DataMap>,
    /// Depth, m: minus the altitude above home (ArduSub's home is at the surface).
    pub depth: Option<f64>,
}

/// GLOBAL_POSITION_INT (degrees·10⁷, millimetres, centimetres a second, centidegrees).
pub fn global_position(m: &DataMap) -> GlobalPosition {
    let mut g = GlobalPosition::default();
    if let (Some(lat), Some(lon)) = (m.get_i64("lat"), m.get_i64("lon"))
        && (lat, lon) != (0, 0)
    {
        let mut p = DataMap::new()
            .with("lat", lat as f64 / 1e7)
            .with("lon", lon as f64 / 1e7)
            .with("source", Value::label("autopilot"));
        if let Some(alt) = m.get_i64("alt") {
            p.insert("alt", alt as f64 / 1000.0);
        }
        g.position = Some(p);
    }
    if let (Some(vx), Some(vy)) = (m.get_i64("vx"), m.get_i64("vy")) {
        let (north, east) = (vx as f64 / 100.0, vy as f64 / 100.0);
        let speed = north.hypot(east);
        let mut v = DataMap::new()
            .with("speed", speed)
            .with("north", north)
            .with("east", east)
            .with("reference", Value::label("ground"));
        // a course needs a speed: standing still, there is none
        if speed > 0.0 {
            v.insert("course", wrap360(east.atan2(north).to_degrees()));
        }
        if let Some(vz) = m.get_i64("vz") {
            v.insert("down", vz as f64 / 100.0);
        }
        g.velocity = Some(v);
    }
    if let Some(hdg) = known(m, "hdg", i64::from(u16::MAX)) {
        g.heading = Some(DataMap::new().with("heading", wrap360(hdg as f64 / 100.0)));
    }
    if let Some(rel) = m.get_i64("relative_alt") {
        g.depth = Some(-(rel as f64) / 1000.0);
    }
    g
}

/// VFR_HUD: `nav.velocity` (ground speed alone: the HUD has no course) and `nav.heading`.
pub fn vfr_hud(m: &DataMap) -> (Option<DataMap>, Option<DataMap>) {
    let velocity = float(m, "groundspeed").filter(|s| *s >= 0.0).map(|s| {
        DataMap::new()
            .with("speed", s)
            .with("reference", Value::label("ground"))
    });
    let heading = m
        .get_i64("heading")
        .filter(|h| (0..=360).contains(h))
        .map(|h| DataMap::new().with("heading", wrap360(h as f64)));
    (velocity, heading)
}

/// `nav.depth` from a SCALED_PRESSURE (hPa, centidegrees Celsius).
pub fn pressure_depth(m: &DataMap, surface: f64, density: f64) -> Option<DataMap> {
    let press = float(m, "press_abs").filter(|p| *p > 0.0)?;
    let mut d = DataMap::new()
        .with("depth", depth_from_pressure(press, surface, density))
        .with("pressure", press / 100.0);
    // 0 is what a sensor without a thermometer sends
    if let Some(t) = known(m, "temperature", 0) {
        d.insert("temperature", t as f64 / 100.0);
    }
    Some(d)
}

/// `power.battery` from SYS_STATUS (millivolts, centiamperes, percent): none when the remaining
/// charge is unknown (−1), the dataset's one required field.
pub fn sys_status_battery(m: &DataMap) -> Option<DataMap> {
    let percent = known(m, "battery_remaining", -1).filter(|p| (0..=100).contains(p))?;
    let mut b = DataMap::new().with("percent", percent as f64);
    if let Some(mv) = known(m, "voltage_battery", i64::from(u16::MAX)) {
        b.insert("voltage", mv as f64 / 1000.0);
    }
    if let Some(ca) = known(m, "current_battery", -1) {
        // MAVLink's current is drawn (positive while discharging); the dataset's is charging
        b.insert("current", -(ca as f64) / 100.0);
    }
    Some(b)
}

/// `power.battery` from BATTERY_STATUS: the voltage is the sum of the cells known (UINT16_MAX
/// marks a cell not there); none when the remaining charge is unknown.
pub fn battery_status(m: &DataMap) -> Option<DataMap> {
    let percent = known(m, "battery_remaining", -1).filter(|p| (0..=100).contains(p))?;
    let mut b = DataMap::new().with("percent", percent as f64);
    let cells: Vec<i64> = match m.get("voltages") {
        Some(Value::List(l)) => l
            .iter()
            .filter_map(Value::as_i64)
            .filter(|v| *v != i64::from(u16::MAX))
            .collect(),
        _ => Vec::new(),
    };
    if !cells.is_empty() {
        b.insert("voltage", cells.iter().sum::<i64>() as f64 / 1000.0);
    }
    if let Some(ca) = known(m, "current_battery", -1) {
        b.insert("current", -(ca as f64) / 100.0);
    }
    if let Some(t) = known(m, "temperature", i64::from(i16::MAX)) {
        b.insert("temperature", t as f64 / 100.0);
    }
    if let Some(s) = known(m, "time_remaining", 0) {
        b.insert("minutes", s as f64 / 60.0);
    }
    match m.get_str("charge_state") {
        Some("MAV_BATTERY_CHARGE_STATE_CHARGING") => b.insert("state", "charging"),
        Some(s)
            if s.starts_with("MAV_BATTERY_CHARGE_STATE_")
                && s != "MAV_BATTERY_CHARGE_STATE_UNDEFINED" =>
        {
            b.insert("state", "discharging")
        }
        _ => {}
    }
    Some(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_are_named_by_firmware_and_read_back() {
        let sub = Firmware::of("MAV_TYPE_SUBMARINE", "MAV_AUTOPILOT_ARDUPILOTMEGA");
        let rover = Firmware::of("MAV_TYPE_SURFACE_BOAT", "MAV_AUTOPILOT_ARDUPILOTMEGA");
        assert_eq!((sub, rover), (Firmware::Sub, Firmware::Rover));
        assert_eq!(
            Firmware::of("MAV_TYPE_SUBMARINE", "MAV_AUTOPILOT_PX4"),
            Firmware::Other
        );
        assert_eq!(sub.mode_name(19), "MANUAL");
        assert_eq!(sub.mode_name(2), "DEPTH_HOLD");
        assert_eq!(sub.mode_name(16), "POSHOLD");
        assert_eq!(sub.mode_name(4), "GUIDED");
        assert_eq!(sub.mode_name(5), "MODE_5");
        assert_eq!(rover.mode_name(0), "MANUAL");
        assert_eq!(rover.mode_name(4), "HOLD");
        assert_eq!(rover.mode_name(15), "GUIDED");
        assert_eq!(Firmware::Other.mode_name(3), "MODE_3");
        assert_eq!(sub.mode_number("alt_hold"), Ok(2));
        assert_eq!(sub.mode_number("DEPTH_HOLD"), Ok(2));
        assert_eq!(rover.mode_number("hold"), Ok(4));
        assert_eq!(Firmware::Other.mode_number("MODE_7"), Ok(7));
        let e = rover.mode_number("DEPTH_HOLD").unwrap_err();
        assert!(
            e.starts_with("`DEPTH_HOLD` is no mode of this vehicle; its modes are MANUAL, ACRO"),
            "{e}"
        );
    }

    #[test]
    fn attitude_is_in_degrees_with_yaw_from_0_to_360() {
        let m = DataMap::new()
            .with("time_boot_ms", 1i64)
            .with("roll", 0.1)
            .with("pitch", -0.05)
            .with("yaw", -1.57)
            .with("rollspeed", 0.01)
            .with("pitchspeed", 0.0)
            .with("yawspeed", -0.02);
        let a = attitude(&m).unwrap();
        let f = |k: &str| a.get_f64(k).unwrap();
        assert!((f("yaw") - (360.0 - 1.57f64.to_degrees())).abs() < 1e-9);
        assert!((f("roll") - 0.1f64.to_degrees()).abs() < 1e-9);
        assert!((f("pitch") + 0.05f64.to_degrees()).abs() < 1e-9);
        assert!((f("yaw_rate") + 0.02f64.to_degrees()).abs() < 1e-9);
        // NaN angles are no attitude
        assert!(attitude(&m.clone().with("yaw", f64::NAN)).is_none());
    }

    #[test]
    fn unknown_values_are_absent_never_numbers() {
        // GLOBAL_POSITION_INT: no heading (UINT16_MAX), no position yet (0, 0)
        let gpi = DataMap::new()
            .with("lat", 0i64)
            .with("lon", 0i64)
            .with("alt", -12500i64)
            .with("relative_alt", -12500i64)
            .with("vx", 0i64)
            .with("vy", 0i64)
            .with("vz", 2i64)
            .with("hdg", 65535i64);
        let g = global_position(&gpi);
        assert_eq!(g.position, None);
        assert_eq!(g.heading, None);
        assert_eq!(g.depth, Some(12.5));
        let v = g.velocity.unwrap();
        assert_eq!(v.get_f64("speed"), Some(0.0));
        assert_eq!(v.get("course"), None, "no course standing still");
        // SYS_STATUS: current unknown (-1), voltage unknown (UINT16_MAX)
        let sys = DataMap::new()
            .with("voltage_battery", 65535i64)
            .with("current_battery", -1i64)
            .with("battery_remaining", 76i64);
        let b = sys_status_battery(&sys).unwrap();
        assert_eq!(b, DataMap::new().with("percent", 76.0));
        // the remaining charge unknown: no battery dataset at all (percent is required)
        assert_eq!(
            sys_status_battery(&sys.clone().with("battery_remaining", -1i64)),
            None
        );
        // BATTERY_STATUS: cells not there, temperature INT16_MAX, time remaining 0
        let bat = DataMap::new()
            .with("current_consumed", -1i64)
            .with("energy_consumed", -1i64)
            .with("temperature", 32767i64)
            .with(
                "voltages",
                vec![
                    Value::Int(4100),
                    Value::Int(4050),
                    Value::Int(65535),
                    Value::Int(65535),
                ],
            )
            .with("current_battery", 1250i64)
            .with("battery_remaining", 55i64)
            .with("time_remaining", 0i64)
            .with("charge_state", "MAV_BATTERY_CHARGE_STATE_OK");
        let b = battery_status(&bat).unwrap();
        assert_eq!(
            b,
            DataMap::new()
                .with("percent", 55.0)
                .with("voltage", 8.15)
                .with("current", -12.5)
                .with("state", "discharging")
        );
        // VFR_HUD with a heading out of range
        let (v, h) = vfr_hud(
            &DataMap::new()
                .with("groundspeed", 1.5)
                .with("heading", 400i64),
        );
        assert_eq!(v.unwrap().get_f64("speed"), Some(1.5));
        assert_eq!(h, None);
        // a pressure sensor without a thermometer
        let d = pressure_depth(
            &DataMap::new()
                .with("press_abs", 2038.25)
                .with("temperature", 0i64),
            SURFACE_HPA,
            SALT,
        )
        .unwrap();
        assert_eq!(d.get("temperature"), None);
    }

    #[test]
    fn position_velocity_heading_and_depth_from_global_position_int() {
        let gpi = DataMap::new()
            .with("lat", 435081000i64)
            .with("lon", 164402000i64)
            .with("alt", -12500i64)
            .with("relative_alt", -12500i64)
            .with("vx", 10i64)
            .with("vy", -10i64)
            .with("vz", 2i64)
            .with("hdg", 9000i64);
        let g = global_position(&gpi);
        let p = g.position.unwrap();
        assert_eq!(p.get_f64("lat"), Some(43.5081));
        assert_eq!(p.get_f64("lon"), Some(16.4402));
        assert_eq!(p.get_f64("alt"), Some(-12.5));
        let v = g.velocity.unwrap();
        assert!((v.get_f64("speed").unwrap() - 0.1f64.hypot(0.1)).abs() < 1e-12);
        assert!((v.get_f64("course").unwrap() - 315.0).abs() < 1e-9);
        assert_eq!(v.get_f64("down"), Some(0.02));
        assert_eq!(g.heading.unwrap().get_f64("heading"), Some(90.0));
        assert_eq!(g.depth, Some(12.5));
    }

    #[test]
    fn depth_from_pressure_in_salt_and_fresh_water() {
        // 10 m of sea water is 1005.525 hPa over the surface
        let over = 10.0 * SALT * G / 100.0;
        assert!((depth_from_pressure(SURFACE_HPA + over, SURFACE_HPA, SALT) - 10.0).abs() < 1e-9);
        // the same pressure in fresh water is deeper
        assert!((depth_from_pressure(SURFACE_HPA + over, SURFACE_HPA, FRESH) - 10.25).abs() < 1e-9);
        let d = pressure_depth(
            &DataMap::new()
                .with("press_abs", 2250.5)
                .with("temperature", 1850i64),
            1013.25,
            SALT,
        )
        .unwrap();
        assert!(
            (d.get_f64("depth").unwrap() - (2250.5 - 1013.25) * 100.0 / (SALT * G)).abs() < 1e-9
        );
        assert_eq!(d.get_f64("pressure"), Some(22.505));
        assert_eq!(d.get_f64("temperature"), Some(18.5));
    }
}
