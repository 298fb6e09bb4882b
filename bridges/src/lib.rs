//! seabus-bridges: interconnection modules that join two media.
//!
//! - [`route`] — the generic bridge: routes by topic pattern in either direction, with topic and
//!   field renames, rate limits and the payload format of the far side; loop-safe through provenance
//!   (duplicate windows, hop limit, never back to the origin medium).
//!
//! - [`lcm`] — LCM types on routes: a route with `lcm="package.type_t"` decodes LCM messages from
//!   an LCM medium into datamaps, or encodes datamaps for one, checking type fingerprints.
//!
//! Other typed mappings (MOOS strings, DSAAV sentuators, CAN signals) build on the same routes.
//!
//! Bridges ask what their media can do ([`seabus_medium::Capabilities`]), never their URLs' schemes.
//! The LCM mapping needs the `lcm` feature (default on), which brings in `seabus-medium-lcm`.
//!
//! Who may depend on it: the program. It depends on the core, the module framework and (with
//! `lcm`) the LCM medium's types.

#[cfg(feature = "lcm")]
pub mod lcm;
#[cfg(not(feature = "lcm"))]
#[path = "lcm_off.rs"]
pub mod lcm;
pub mod rate;
pub mod route;

use seabus_modules::Registry;

/// Registers the bridge types.
pub fn register(reg: &mut Registry) {
    reg.add_bridge(route::TYPE);
}
