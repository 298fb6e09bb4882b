//! Units and coordinate frames for the `convert` module's declared conversions.
//!
//! - [`Unit`]: a table of the units marine sensors report in (lengths, speeds, angles, rates,
//!   temperatures, pressures, times, electrical and conductivity units), each a scale and offset
//!   to SI, so a conversion between two units of one quantity is linear.
//! - [`LocalFrame`]: WGS-84 geodetic positions to and from a local tangent plane at an origin
//!   (east-north-up, the x/y of MOOS's `NAV_X`/`NAV_Y`; or north-east-down), exact at any range
//!   through Earth-centred coordinates.
//! - [`attitude`]: the rotation of a vehicle (or a sensor's mounting) from roll, pitch and yaw in
//!   degrees, body (x forward, y starboard, z down) to north-east-down.
//! - [`Transform`]: one declared transform of a few fields of a datamap — geodetic ↔ ENU/NED,
//!   rotations by fixed or measured angles, ENU ↔ NED, compass heading ↔ ENU yaw — parsed from
//!   `KIND(ARGS): IN, … -> OUT, …`.

use nalgebra::{Matrix3, Rotation3, Vector3};
use std::f64::consts::PI;

/// WGS-84 semi-major axis, m.
pub const WGS84_A: f64 = 6_378_137.0;
/// WGS-84 flattening.
pub const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS-84 first eccentricity squared.
const E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// A unit: `SI value = value × scale + offset`, of one quantity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unit {
    /// Its name as written in configuration (`kn`, `m/s`, `degF`).
    pub name: &'static str,
    /// The quantity it measures (`length`, `speed`, …): only units of one quantity convert.
    pub quantity: &'static str,
    /// Multiplier to the SI unit.
    pub scale: f64,
    /// Added after scaling (temperatures).
    pub offset: f64,
}

const fn unit(name: &'static str, quantity: &'static str, scale: f64) -> Unit {
    Unit {
        name,
        quantity,
        scale,
        offset: 0.0,
    }
}

/// The units a conversion may name.
pub const UNITS: &[Unit] = &[
    unit("m", "length", 1.0),
    unit("km", "length", 1000.0),
    unit("cm", "length", 0.01),
    unit("mm", "length", 0.001),
    unit("ft", "length", 0.3048),
    unit("in", "length", 0.0254),
    unit("yd", "length", 0.9144),
    unit("fathom", "length", 1.8288),
    unit("nmi", "length", 1852.0),
    unit("m/s", "speed", 1.0),
    unit("cm/s", "speed", 0.01),
    unit("mm/s", "speed", 0.001),
    unit("km/h", "speed", 1.0 / 3.6),
    unit("kn", "speed", 1852.0 / 3600.0),
    unit("mph", "speed", 0.447_04),
    unit("ft/s", "speed", 0.3048),
    unit("rad", "angle", 1.0),
    unit("deg", "angle", PI / 180.0),
    unit("mrad", "angle", 0.001),
    unit("rad/s", "angular rate", 1.0),
    unit("deg/s", "angular rate", PI / 180.0),
    unit("K", "temperature", 1.0),
    Unit {
        name: "degC",
        quantity: "temperature",
        scale: 1.0,
        offset: 273.15,
    },
    Unit {
        name: "degF",
        quantity: "temperature",
        scale: 5.0 / 9.0,
        offset: 459.67 * 5.0 / 9.0,
    },
    unit("Pa", "pressure", 1.0),
    unit("hPa", "pressure", 100.0),
    unit("kPa", "pressure", 1000.0),
    unit("MPa", "pressure", 1e6),
    unit("mbar", "pressure", 100.0),
    unit("bar", "pressure", 1e5),
    unit("dbar", "pressure", 1e4),
    unit("psi", "pressure", 6_894.757_293_168),
    unit("atm", "pressure", 101_325.0),
    unit("s", "time", 1.0),
    unit("ms", "time", 0.001),
    unit("us", "time", 1e-6),
    unit("min", "time", 60.0),
    unit("h", "time", 3600.0),
    unit("V", "voltage", 1.0),
    unit("mV", "voltage", 0.001),
    unit("A", "current", 1.0),
    unit("mA", "current", 0.001),
    unit("W", "power", 1.0),
    unit("kW", "power", 1000.0),
    unit("Hz", "frequency", 1.0),
    unit("kHz", "frequency", 1000.0),
    unit("S/m", "conductivity", 1.0),
    unit("mS/cm", "conductivity", 0.1),
    unit("uS/cm", "conductivity", 1e-4),
];

impl Unit {
    /// The unit named `name`, or an error listing the known ones.
    pub fn named(name: &str) -> Result<Unit, String> {
        UNITS
            .iter()
            .find(|u| u.name == name)
            .copied()
            .ok_or_else(|| {
                let names: Vec<&str> = UNITS.iter().map(|u| u.name).collect();
                format!("unknown unit `{name}`; units: {}", names.join(", "))
            })
    }

    /// `(k, c)` such that a value in `self` is `x × k + c` in `to`, or why they do not convert.
    pub fn linear_to(&self, to: &Unit) -> Result<(f64, f64), String> {
        if self.quantity != to.quantity {
            return Err(format!(
                "`{}` is a {} and `{}` a {}: they do not convert",
                self.name, self.quantity, to.name, to.quantity
            ));
        }
        Ok((self.scale / to.scale, (self.offset - to.offset) / to.scale))
    }
}

/// A WGS-84 position (degrees, metres above the ellipsoid) in Earth-centred, Earth-fixed metres.
pub fn geodetic_to_ecef(lat: f64, lon: f64, height: f64) -> Vector3<f64> {
    let (sl, cl) = lat.to_radians().sin_cos();
    let (so, co) = lon.to_radians().sin_cos();
    let n = WGS84_A / (1.0 - E2 * sl * sl).sqrt();
    Vector3::new(
        (n + height) * cl * co,
        (n + height) * cl * so,
        (n * (1.0 - E2) + height) * sl,
    )
}

/// Earth-centred, Earth-fixed metres as a WGS-84 position (degrees, metres): exact to well under
/// a millimetre from the sea floor to orbit.
pub fn ecef_to_geodetic(v: Vector3<f64>) -> (f64, f64, f64) {
    let p = v.x.hypot(v.y);
    let lon = v.y.atan2(v.x);
    let mut lat = v.z.atan2(p * (1.0 - E2));
    for _ in 0..8 {
        let s = lat.sin();
        let n = WGS84_A / (1.0 - E2 * s * s).sqrt();
        lat = (v.z + E2 * n * s).atan2(p);
    }
    let (s, c) = lat.sin_cos();
    let height = p * c + v.z * s - WGS84_A * (1.0 - E2 * s * s).sqrt();
    (lat.to_degrees(), lon.to_degrees(), height)
}

/// A local tangent plane at an origin: east-north-up metres from WGS-84 positions and back.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalFrame {
    origin: Vector3<f64>,
    /// Rows: east, north and up as Earth-centred unit vectors.
    to_enu: Matrix3<f64>,
    height: f64,
}

impl LocalFrame {
    /// The plane at `lat`, `lon` (degrees) and `height` (m above the ellipsoid).
    pub fn new(lat: f64, lon: f64, height: f64) -> LocalFrame {
        let (sl, cl) = lat.to_radians().sin_cos();
        let (so, co) = lon.to_radians().sin_cos();
        #[rustfmt::skip]
        let to_enu = Matrix3::new(
            -so,       co,      0.0,
            -sl * co, -sl * so, cl,
            cl * co,   cl * so, sl,
        );
        LocalFrame {
            origin: geodetic_to_ecef(lat, lon, height),
            to_enu,
            height,
        }
    }

    /// The origin's height, m.
    pub fn height(&self) -> f64 {
        self.height
    }

    /// East, north, up in metres of a position.
    pub fn enu(&self, lat: f64, lon: f64, height: f64) -> Vector3<f64> {
        self.to_enu * (geodetic_to_ecef(lat, lon, height) - self.origin)
    }

    /// The position (degrees, m) at east, north, up metres.
    pub fn geodetic(&self, enu: Vector3<f64>) -> (f64, f64, f64) {
        ecef_to_geodetic(self.origin + self.to_enu.transpose() * enu)
    }
}

/// The rotation from a body frame (x forward, y starboard, z down) to north-east-down of a body
/// at `roll`, `pitch`, `yaw` degrees (yaw about down, then pitch, then roll: aerospace order).
pub fn attitude(roll: f64, pitch: f64, yaw: f64) -> Rotation3<f64> {
    Rotation3::from_euler_angles(roll.to_radians(), pitch.to_radians(), yaw.to_radians())
}

/// A compass heading (degrees clockwise from north) as a yaw in radians counter-clockwise from
/// east (east-north-up), in (-π, π].
pub fn compass_to_yaw(heading: f64) -> f64 {
    wrap_pi((90.0 - heading).to_radians())
}

/// A yaw in radians counter-clockwise from east as a compass heading in degrees, in [0, 360).
pub fn yaw_to_compass(yaw: f64) -> f64 {
    seabus_modules::geo::wrap360(90.0 - yaw.to_degrees())
}

/// Whether `name` can name a field in a declaration: letters, digits, `_` and `.`.
pub fn is_field_name(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.')
}

fn wrap_pi(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(2.0 * PI) - PI;
    if r <= -PI { r + 2.0 * PI } else { r }
}

/// An angle a rotation takes: fixed, or read from a field of the message (or of the latest
/// attitude).
#[derive(Debug, Clone, PartialEq)]
pub enum Angle {
    /// Degrees.
    Fixed(f64),
    /// The field holding it in degrees.
    Field(String),
}

/// What a [`Transform`] does.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    /// latitude, longitude[, height] → east, north[, up] (`true`) or north, east[, down].
    FromGeodetic(LocalFrame, bool),
    /// east, north[, up] (`true`) or north, east[, down] → latitude, longitude[, height].
    ToGeodetic(LocalFrame, bool),
    /// A vector rotated by roll, pitch, yaw (`false`), or by the inverse (`true`).
    Rotate([Angle; 3], bool),
    /// ENU ↔ NED (the same swap both ways).
    SwapEnuNed,
    /// Compass degrees → ENU yaw radians.
    CompassToYaw,
    /// ENU yaw radians → compass degrees.
    YawToCompass,
}

/// One declared transform: reads `inputs`, writes `outputs`.
#[derive(Debug, Clone, PartialEq)]
pub struct Transform {
    /// What it does.
    pub kind: Kind,
    /// The fields it reads, in order.
    pub inputs: Vec<String>,
    /// The fields it writes, in order.
    pub outputs: Vec<String>,
}

/// Where a transform's inputs and angles come from.
pub trait Fields {
    /// The numeric value of a field, if present.
    fn number(&self, name: &str) -> Option<f64>;
}

/// The field names of a comma-separated list in transform `text`, each once.
fn field_names(list: &str, text: &str) -> Result<Vec<String>, String> {
    let mut out: Vec<String> = Vec::new();
    for n in list.split(',').map(str::trim) {
        if !is_field_name(n) {
            return Err(format!("`{n}` in `{text}` is not a field name"));
        }
        if out.iter().any(|o| o == n) {
            return Err(format!("field `{n}` twice in `{text}`"));
        }
        out.push(n.to_string());
    }
    Ok(out)
}

/// Transform `name`'s arguments `args` as numbers, when there are as many as one of `wanted`.
fn numbers(name: &str, args: &[&str], wanted: &[usize], text: &str) -> Result<Vec<f64>, String> {
    if !wanted.contains(&args.len()) {
        return Err(format!(
            "`{name}` in `{text}` takes {} arguments, not {}",
            wanted
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(" or "),
            args.len()
        ));
    }
    args.iter()
        .map(|a| {
            a.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("`{a}` in `{text}` is not a number"))
        })
        .collect()
}

/// The local frame whose origin is latitude, longitude and (optional) height `v`.
fn local_frame(v: Vec<f64>, text: &str) -> Result<LocalFrame, String> {
    if !(-90.0..=90.0).contains(&v[0]) || !(-180.0..=360.0).contains(&v[1]) {
        return Err(format!(
            "`{text}`: the origin {}, {} is not a latitude and longitude",
            v[0], v[1]
        ));
    }
    Ok(LocalFrame::new(
        v[0],
        v[1],
        v.get(2).copied().unwrap_or(0.0),
    ))
}

/// The three angles (roll, pitch, yaw) of `rotate` or `unrotate`: degrees, or field names.
fn rotation_angles(name: &str, args: &[&str], text: &str) -> Result<[Angle; 3], String> {
    if args.len() != 3 {
        return Err(format!(
            "`{name}` in `{text}` takes 3 angles (roll, pitch, yaw), not {}",
            args.len()
        ));
    }
    let angle = |a: &str| match a.parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(Angle::Fixed(x)),
        Ok(_) => Err(format!("`{a}` in `{text}` is not a finite angle")),
        Err(_) if is_field_name(a) => Ok(Angle::Field(a.to_string())),
        Err(_) => Err(format!("`{a}` in `{text}` is neither an angle nor a field")),
    };
    Ok([angle(args[0])?, angle(args[1])?, angle(args[2])?])
}

/// The transform called `name` with `args`, and how many fields it takes in (and out).
fn transform_kind(
    name: &str,
    args: &[&str],
    text: &str,
) -> Result<(Kind, &'static [usize]), String> {
    let origin = || local_frame(numbers(name, args, &[2, 3], text)?, text);
    let none = || numbers(name, args, &[0], text).map(|_| ());
    Ok(match name {
        "geodetic->enu" => (Kind::FromGeodetic(origin()?, true), &[2, 3]),
        "geodetic->ned" => (Kind::FromGeodetic(origin()?, false), &[2, 3]),
        "enu->geodetic" => (Kind::ToGeodetic(origin()?, true), &[2, 3]),
        "ned->geodetic" => (Kind::ToGeodetic(origin()?, false), &[2, 3]),
        "rotate" | "unrotate" => (
            Kind::Rotate(rotation_angles(name, args, text)?, name == "unrotate"),
            &[2, 3],
        ),
        "enu->ned" | "ned->enu" => {
            none()?;
            (Kind::SwapEnuNed, &[2, 3])
        }
        "compass->yaw" => {
            none()?;
            (Kind::CompassToYaw, &[1])
        }
        "yaw->compass" => {
            none()?;
            (Kind::YawToCompass, &[1])
        }
        other => {
            return Err(format!(
                "unknown transform `{other}` in `{text}`; transforms: geodetic->enu, \
                 geodetic->ned, enu->geodetic, ned->geodetic, rotate, unrotate, enu->ned, \
                 ned->enu, compass->yaw, yaw->compass"
            ));
        }
    })
}

impl Transform {
    /// Parses `KIND[(ARGS)]: IN, … -> OUT, …`. Kinds: `geodetic->enu(LAT, LON[, HEIGHT])`,
    /// `geodetic->ned(…)`, `enu->geodetic(…)`, `ned->geodetic(…)`, `rotate(ROLL, PITCH, YAW)`,
    /// `unrotate(ROLL, PITCH, YAW)` (angles in degrees, numbers or field names), `enu->ned`,
    /// `ned->enu`, `compass->yaw`, `yaw->compass`.
    pub fn parse(text: &str) -> Result<Transform, String> {
        let text = text.trim();
        let (head, body) = text
            .split_once(':')
            .ok_or_else(|| format!("`{text}`: expected `KIND: INPUTS -> OUTPUTS`"))?;
        let (inputs, outputs) = body
            .split_once("->")
            .ok_or_else(|| format!("`{text}`: expected `INPUTS -> OUTPUTS` after `:`"))?;
        let (inputs, outputs) = (field_names(inputs, text)?, field_names(outputs, text)?);
        let head = head.trim();
        let (name, args) = match head.split_once('(') {
            None => (head, Vec::new()),
            Some((name, rest)) => {
                let args = rest
                    .strip_suffix(')')
                    .ok_or_else(|| format!("`{head}` in `{text}`: expected `)` at its end"))?;
                (name.trim(), args.split(',').map(str::trim).collect())
            }
        };
        let (kind, arity) = transform_kind(name, &args, text)?;
        if !arity.contains(&inputs.len()) || outputs.len() != inputs.len() {
            let takes = if arity == [1] {
                "one field"
            } else {
                "2 or 3 fields"
            };
            return Err(format!(
                "`{text}`: `{name}` takes {takes} in and as many out, not {} in and {} out",
                inputs.len(),
                outputs.len()
            ));
        }
        Ok(Transform {
            kind,
            inputs,
            outputs,
        })
    }

    /// The fields it needs besides its inputs (angles read from fields).
    pub fn angle_fields(&self) -> impl Iterator<Item = &str> {
        let angles: &[Angle] = match &self.kind {
            Kind::Rotate(a, _) => a,
            _ => &[],
        };
        angles.iter().filter_map(|a| match a {
            Angle::Field(f) => Some(f.as_str()),
            Angle::Fixed(_) => None,
        })
    }

    /// The outputs from the inputs found in `fields`; `Err` names the field that is missing.
    pub fn apply(&self, fields: &dyn Fields) -> Result<Vec<f64>, String> {
        let get = |name: &str| {
            fields
                .number(name)
                .filter(|x| x.is_finite())
                .ok_or_else(|| name.to_string())
        };
        let x: Vec<f64> = self
            .inputs
            .iter()
            .map(|n| get(n))
            .collect::<Result<_, _>>()?;
        let v3 = |z: f64| Vector3::new(x[0], x[1], x.get(2).copied().unwrap_or(z));
        let out = match &self.kind {
            Kind::FromGeodetic(frame, enu) => {
                let v = frame.enu(x[0], x[1], x.get(2).copied().unwrap_or(frame.height()));
                if *enu {
                    v
                } else {
                    Vector3::new(v.y, v.x, -v.z)
                }
            }
            Kind::ToGeodetic(frame, enu) => {
                let v = v3(0.0);
                let (lat, lon, h) = frame.geodetic(if *enu {
                    v
                } else {
                    Vector3::new(v.y, v.x, -v.z)
                });
                Vector3::new(lat, lon, h)
            }
            Kind::Rotate(angles, inverse) => {
                let mut a = [0.0; 3];
                for (slot, angle) in a.iter_mut().zip(angles) {
                    *slot = match angle {
                        Angle::Fixed(d) => *d,
                        Angle::Field(f) => get(f)?,
                    };
                }
                let r = attitude(a[0], a[1], a[2]);
                if *inverse {
                    r.inverse() * v3(0.0)
                } else {
                    r * v3(0.0)
                }
            }
            Kind::SwapEnuNed => {
                let v = v3(0.0);
                Vector3::new(v.y, v.x, -v.z)
            }
            Kind::CompassToYaw => Vector3::new(compass_to_yaw(x[0]), 0.0, 0.0),
            Kind::YawToCompass => Vector3::new(yaw_to_compass(x[0]), 0.0, 0.0),
        };
        Ok(out.iter().take(self.outputs.len()).copied().collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    impl Fields for HashMap<&str, f64> {
        fn number(&self, name: &str) -> Option<f64> {
            self.get(name).copied()
        }
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn units_convert_within_a_quantity_only() {
        let (k, c) = Unit::named("ft")
            .unwrap()
            .linear_to(&Unit::named("m").unwrap())
            .unwrap();
        assert!(close(10.0 * k + c, 3.048, 1e-12));
        let (k, c) = Unit::named("degF")
            .unwrap()
            .linear_to(&Unit::named("degC").unwrap())
            .unwrap();
        assert!(close(212.0 * k + c, 100.0, 1e-9) && close(32.0 * k + c, 0.0, 1e-9));
        let (k, c) = Unit::named("kn")
            .unwrap()
            .linear_to(&Unit::named("m/s").unwrap())
            .unwrap();
        assert!(close(k, 0.514_444, 1e-6) && c == 0.0);
        let (k, _) = Unit::named("dbar")
            .unwrap()
            .linear_to(&Unit::named("psi").unwrap())
            .unwrap();
        assert!(close(k, 1.450_377, 1e-6));
        let e = Unit::named("ft")
            .unwrap()
            .linear_to(&Unit::named("kn").unwrap())
            .unwrap_err();
        assert!(e.contains("length") && e.contains("speed"), "{e}");
        assert!(Unit::named("furlong").unwrap_err().contains("units: m, km"));
    }

    #[test]
    fn geodetic_round_trips_and_matches_the_ellipsoid() {
        // one thousandth of a degree of latitude at 45°: the meridian radius of curvature
        // a(1-e²)/(1-e² sin²φ)^1.5 = 6 367 381.8 m gives 111.132 m (a sphere would say 111.19)
        let f = LocalFrame::new(45.0, 16.0, 0.0);
        let v = f.enu(45.001, 16.0, 0.0);
        assert!(close(v.y, 111.132, 0.002) && close(v.x, 0.0, 1e-6), "{v}");
        // a degree of longitude on the equator is a·π/180 = 111 319.49 m along the ground; the
        // tangent plane sees its chord a·sin(1°)
        let f0 = LocalFrame::new(0.0, 0.0, 0.0);
        let v = f0.enu(0.0, 1.0, 0.0);
        assert!(close(v.x, WGS84_A * 1f64.to_radians().sin(), 1e-6), "{v}");
        for (lat, lon, h) in [
            (43.508, 16.44, -35.0),
            (89.99, 120.0, 10.0),
            (-60.0, -170.0, -6000.0),
        ] {
            let g = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h));
            assert!(
                close(g.0, lat, 1e-11) && close(g.1, lon, 1e-11) && close(g.2, h, 1e-6),
                "{g:?}"
            );
            let f = LocalFrame::new(lat + 0.01, lon - 0.02, 0.0);
            let back = f.geodetic(f.enu(lat, lon, h));
            assert!(
                close(back.0, lat, 1e-11) && close(back.2, h, 1e-6),
                "{back:?}"
            );
        }
    }

    #[test]
    fn attitudes_rotate_body_vectors_to_north_east_down() {
        // heading east, going forward: the velocity points east
        let v = attitude(0.0, 0.0, 90.0) * Vector3::new(1.0, 0.0, 0.0);
        assert!(close(v.x, 0.0, 1e-12) && close(v.y, 1.0, 1e-12), "{v}");
        // nose up 30°: forward has a negative down component
        let v = attitude(0.0, 30.0, 0.0) * Vector3::new(1.0, 0.0, 0.0);
        assert!(close(v.z, -0.5, 1e-12), "{v}");
        // rolled 90° to starboard: the starboard axis points down
        let v = attitude(90.0, 0.0, 0.0) * Vector3::new(0.0, 1.0, 0.0);
        assert!(close(v.z, 1.0, 1e-12), "{v}");
        assert!(close(compass_to_yaw(0.0), PI / 2.0, 1e-12));
        assert!(close(compass_to_yaw(90.0), 0.0, 1e-12));
        assert!(close(compass_to_yaw(270.0), PI, 1e-12));
        assert!(close(yaw_to_compass(-PI / 2.0), 180.0, 1e-9));
    }

    #[test]
    fn transforms_parse_and_apply() {
        let t = Transform::parse("rotate(0, 0, heading): surge, sway -> north, east").unwrap();
        let m = HashMap::from([("surge", 2.0), ("sway", 0.0), ("heading", 180.0)]);
        let out = t.apply(&m).unwrap();
        assert!(close(out[0], -2.0, 1e-12) && close(out[1], 0.0, 1e-12));
        assert_eq!(t.angle_fields().collect::<Vec<_>>(), ["heading"]);
        let missing = HashMap::from([("surge", 2.0), ("sway", 0.0)]);
        assert_eq!(t.apply(&missing).unwrap_err(), "heading");
        let back = Transform::parse("unrotate(0,0,heading): north, east -> surge, sway").unwrap();
        let m = HashMap::from([("north", -2.0), ("east", 0.0), ("heading", 180.0)]);
        assert!(close(back.apply(&m).unwrap()[0], 2.0, 1e-12));
        let t = Transform::parse("geodetic->ned(45, 16): lat, lon -> n, e").unwrap();
        let out = t
            .apply(&HashMap::from([("lat", 45.001), ("lon", 16.0)]))
            .unwrap();
        assert_eq!(out.len(), 2);
        assert!(close(out[0], 111.132, 0.002), "{out:?}");
        let t = Transform::parse("ned->enu: n, e, d -> x, y, z").unwrap();
        let out = t
            .apply(&HashMap::from([("n", 1.0), ("e", 2.0), ("d", 3.0)]))
            .unwrap();
        assert_eq!(out, [2.0, 1.0, -3.0]);
    }

    #[test]
    fn bad_transforms_say_why() {
        let bad = |t: &str| Transform::parse(t).unwrap_err();
        assert!(bad("rotate(0,0,90) surge -> n").contains("expected `KIND"));
        assert!(bad("rotate(0,0,90): surge, sway").contains("INPUTS -> OUTPUTS"));
        assert!(bad("spin: a -> b").contains("unknown transform `spin`"));
        assert!(bad("rotate(0,90): a, b -> c, d").contains("3 angles"));
        assert!(bad("geodetic->enu(95, 0): lat, lon -> x, y").contains("not a latitude"));
        assert!(bad("geodetic->enu(x, 0): lat, lon -> x, y").contains("`x`"));
        assert!(bad("geodetic->enu(1, 2): lat -> x").contains("2 or 3 fields"));
        assert!(bad("compass->yaw: a, b -> c, d").contains("one field"));
        assert!(bad("enu->ned: a, b -> c").contains("not 2 in and 1 out"));
        assert!(bad("rotate(0,0,90: a, b -> c, d").contains("expected `)`"));
        assert!(bad("rotate(0,0,inf): a, b -> c, d").contains("finite"));
        assert!(bad("enu->ned: z, y, z -> a, b, c").contains("field `z` twice"));
        assert!(bad("enu->ned: a, b -> c, d e").contains("`d e` in"));
        assert!(bad("rotate(0, 0, h\0): a, b -> c, d").contains("neither"));
    }
}
