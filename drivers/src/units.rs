//! Unit conversions the device protocols need.

/// Metres per second in one knot.
pub const KNOT: f64 = 1852.0 / 3600.0;
/// Metres in one foot.
pub const FOOT: f64 = 0.3048;
/// Metres in one fathom (six feet).
pub const FATHOM: f64 = 6.0 * FOOT;
