//! seabus-bridges: interconnection modules that join two media.
//!
//! - [`route`] — the generic bridge: routes by topic pattern in either direction, with topic and
//!   field renames, rate limits and the payload format of the far side; loop-safe through provenance
//!   (duplicate windows, hop limit, never back to the origin medium).
//!
//! Typed mappings (LCM types, MOOS strings, DSAAV sentuators, CAN signals) build on the same routes.

pub mod route;

use seabus_modules::Registry;

/// Registers the bridge types.
pub fn register(reg: &mut Registry) {
    reg.add_bridge(route::TYPE);
}
