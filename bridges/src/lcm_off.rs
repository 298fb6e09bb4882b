//! LCM types on routes, left out of this build (cargo feature `lcm`): a bridge whose routes name
//! an LCM type, or that loads `lcm_types`, is refused with that reason.

use crate::route::Problem;
use seabus_medium::xml::FileError;
use seabus_medium::{Capabilities, DataMap, Payload, Stamp};
use seabus_modules::system::{BridgeSpec, RouteSpec};
use std::sync::Arc;

/// LCM types: none in this build.
pub enum ResolvedTypes {}

/// A route's LCM type: none in this build.
pub enum Mapping {}

/// Refuses the bridge: it needs LCM types.
pub fn load(spec: &BridgeSpec) -> Result<Arc<ResolvedTypes>, FileError> {
    Err(spec.pos.error(format!(
        "bridge `{}`: LCM types on routes are not compiled into this seabus (feature `lcm`)",
        spec.name
    )))
}

impl Mapping {
    /// No mapping can be made without types.
    pub fn new(
        _: &BridgeSpec,
        _: &[Capabilities; 2],
        _: &RouteSpec,
        types: &ResolvedTypes,
        _: usize,
        _: usize,
    ) -> Result<Option<Mapping>, FileError> {
        match *types {}
    }

    /// Never called: there is no mapping.
    pub fn decodes(&self) -> bool {
        match *self {}
    }

    /// Never called: there is no mapping.
    pub fn encodes(&self) -> bool {
        match *self {}
    }

    /// Never called: there is no mapping.
    pub fn decode(
        &self,
        _: &ResolvedTypes,
        _: &str,
        _: &Payload,
        _: &seabus_medium::tally::Tally,
        _: &str,
    ) -> Result<DataMap, Problem> {
        match *self {}
    }

    /// Never called: there is no mapping.
    pub fn encode(
        &self,
        _: &ResolvedTypes,
        _: &str,
        _: &DataMap,
        _: Stamp,
    ) -> Result<Payload, Problem> {
        match *self {}
    }
}
