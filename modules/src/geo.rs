//! Small flat-earth geometry shared by helms, simulators and navigation modules: good to a few
//! kilometres, which is the scale of a vehicle's leg.

/// Metres per degree of latitude.
pub const METRES_PER_DEG: f64 = 111_320.0;

/// Distance in metres between two positions given in degrees (equirectangular).
pub fn distance(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> f64 {
    let (north, east) = offset(lat1, lon1, lat2, lon2);
    north.hypot(east)
}

/// The (north, east) offset in metres from the first position to the second.
pub fn offset(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> (f64, f64) {
    let north = (lat2 - lat1) * METRES_PER_DEG;
    let east = wrap180(lon2 - lon1) * METRES_PER_DEG * ((lat1 + lat2) / 2.0).to_radians().cos();
    (north, east)
}

/// The position `north` and `east` metres away.
pub fn moved(lat: f64, lon: f64, north: f64, east: f64) -> (f64, f64) {
    let lat2 = (lat + north / METRES_PER_DEG).clamp(-90.0, 90.0);
    let cos_lat = lat2.to_radians().cos().max(1e-6);
    (lat2, wrap180(lon + east / (METRES_PER_DEG * cos_lat)))
}

/// An angle in degrees, in (-180, 180].
pub fn wrap180(a: f64) -> f64 {
    let r = wrap360(a);
    if r > 180.0 { r - 360.0 } else { r }
}

/// An angle in degrees, in [0, 360) (an angle already there is returned as is, without a division).
pub fn wrap360(a: f64) -> f64 {
    if (0.0..360.0).contains(&a) {
        a
    } else {
        a.rem_euclid(360.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_metres() {
        assert!((distance(0.0, 0.0, 0.001, 0.0) - 111.32).abs() < 1e-6);
        let d = distance(60.0, 10.0, 60.0, 10.002);
        assert!((d - 111.32).abs() < 0.5, "{d}");
        let (lat, lon) = moved(43.5, 16.4, 100.0, -50.0);
        let (n, e) = offset(43.5, 16.4, lat, lon);
        assert!(
            (n - 100.0).abs() < 1e-6 && (e + 50.0).abs() < 0.01,
            "{n} {e}"
        );
    }

    #[test]
    fn angles_wrap() {
        assert_eq!(wrap180(190.0), -170.0);
        assert_eq!(wrap180(-190.0), 170.0);
        assert_eq!(wrap180(180.0), 180.0);
        assert_eq!(wrap360(-90.0), 270.0);
        assert_eq!(wrap360(720.5), 0.5);
        assert_eq!(wrap360(359.5), 359.5);
        assert_eq!(wrap360(360.0), 0.0);
    }
}
