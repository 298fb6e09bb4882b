//! Properties of the `mavlink` driver's reading of MAVLink messages that every input must keep.

use seabus_drivers::mavlink::ardupilot::{self, Firmware};
use seabus_drivers::mavlink::driver::Manual;
use seabus_medium::Value;
use seabus_medium::datamap::DataMap;
use seabus_medium_mavlink::Dialect;
use seabus_medium_mavlink::frame::{self, Item};
use seabus_modules::Catalogue;
use seabus_modules::datasets::{Problem, ValidationError};

/// Every number in `m` is finite.
fn finite(what: &str, m: &DataMap) {
    for (k, v) in m.iter() {
        if let Value::Float(x) = v {
            assert!(x.is_finite(), "{what}: `{k}` = {x} is not finite in {m}");
        }
    }
}

/// A dataset the driver made: its numbers finite, its required fields there with their types; a
/// value outside the dataset's range is the one thing publishing may still refuse (counted). True
/// when it is valid.
fn dataset(cat: &Catalogue, name: &str, m: &DataMap) -> bool {
    finite(name, m);
    match cat.validate(name, m) {
        Ok(()) => true,
        Err(ValidationError::Invalid { problems, .. }) => {
            for p in &problems {
                assert!(matches!(p, Problem::OutOfRange { .. }), "{name} {m}: {p}");
            }
            false
        }
        Err(e) => panic!("{name}: {e}"),
    }
}

/// MAVLink messages through the driver's mappings: any frames read from the bytes become datasets
/// with finite numbers and their required fields, or none; the unknown markers never come out as
/// numbers; a MANUAL_CONTROL's axes are taken whole or refused, never changed; a HEARTBEAT's mode
/// has a name that reads back to its number. True when a valid dataset was made.
pub fn mavlink_datasets(data: &[u8]) -> bool {
    let cat = Catalogue::built_in();
    let mut maps = Vec::new();
    frame::datagram(Dialect::ArduPilotMega, data, |item| {
        if let Item::Frame(f) = item
            && let Ok(decoded) = Dialect::ArduPilotMega.decode(&f.raw)
        {
            maps.push(decoded);
        }
    });
    let mut valid = false;
    for (name, m) in &maps {
        let mut made: Vec<(&str, DataMap)> = Vec::new();
        match *name {
            "ATTITUDE" => made.extend(ardupilot::attitude(m).map(|a| ("attitude", a))),
            "GLOBAL_POSITION_INT" => {
                let g = ardupilot::global_position(m);
                made.extend(g.position.map(|p| ("position", p)));
                made.extend(g.velocity.map(|v| ("velocity", v)));
                if let Some(h) = g.heading {
                    assert_ne!(m.get_i64("hdg"), Some(65535), "an unknown hdg published");
                    made.push(("heading", h));
                }
                if let Some(d) = g.depth {
                    made.push(("depth", DataMap::new().with("depth", d)));
                }
            }
            "VFR_HUD" => {
                let (v, h) = ardupilot::vfr_hud(m);
                made.extend(v.map(|v| ("velocity", v)));
                made.extend(h.map(|h| ("heading", h)));
            }
            "SCALED_PRESSURE" | "SCALED_PRESSURE2" | "SCALED_PRESSURE3" => {
                for density in [ardupilot::SALT, ardupilot::FRESH] {
                    made.extend(
                        ardupilot::pressure_depth(m, ardupilot::SURFACE_HPA, density)
                            .map(|d| ("depth", d)),
                    );
                }
            }
            "SYS_STATUS" => {
                if let Some(b) = ardupilot::sys_status_battery(m) {
                    assert!(b.get("current").is_none() || m.get_i64("current_battery") != Some(-1));
                    assert!(
                        b.get("voltage").is_none() || m.get_i64("voltage_battery") != Some(65535)
                    );
                    made.push(("battery", b));
                }
            }
            "BATTERY_STATUS" => {
                if let Some(b) = ardupilot::battery_status(m) {
                    assert!(
                        b.get("temperature").is_none() || m.get_i64("temperature") != Some(32767)
                    );
                    made.push(("battery", b));
                }
            }
            "MANUAL_CONTROL" => {
                for z_min in [0, -1000] {
                    if let Ok(manual) = Manual::from_map(m, z_min) {
                        let axes = [manual.x, manual.y, manual.z, manual.r];
                        let sent = ["x", "y", "z", "r"].map(|k| m.get_i64(k).unwrap_or(i64::MIN));
                        assert_eq!(axes, sent, "a stick's values changed");
                        assert!(axes.iter().all(|a| (-1000..=1000).contains(a)));
                        assert!(manual.z >= z_min);
                    }
                }
            }
            "HEARTBEAT" => {
                let fw = Firmware::of(
                    m.get_str("type").unwrap_or_default(),
                    m.get_str("autopilot").unwrap_or_default(),
                );
                let n = m.get_i64("custom_mode").unwrap_or(0);
                let mode = fw.mode_name(n);
                assert_eq!(fw.mode_number(&mode).map(i64::from), Ok(n), "mode {mode}");
            }
            _ => {}
        }
        for (ds, out) in &made {
            valid |= dataset(&cat, ds, out);
        }
    }
    valid
}
