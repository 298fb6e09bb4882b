//! seabus-modules: the module abstraction, the runtime that runs modules, system files, the standard
//! datasets, and the supporting modules.
//!
//! How the parts fit:
//!
//! - [`module`] — a [`Module`] declares what it produces, consumes and accepts ([`Declaration`]) and
//!   gets its messages and timer ticks through handlers; its [`Context`] holds one interface ("port")
//!   per medium it is placed on.
//! - [`registry`](mod@registry) — module and bridge types by name; each builds fresh modules from a
//!   [`ModuleConfig`] (a system file's `<module>`) or a [`system::BridgeSpec`].
//! - [`system`] — system files: parsing, checking against a registry, route-cycle detection.
//! - [`runtime`] — the container: opens media, supervises modules (restart with back-off), shuts
//!   down on request.
//! - [`dsaav`] — the DSAAV services: the configuration database ([`dsaav::config`]) with its
//!   application data and data plumbing, and the health monitor's rules and state machine
//!   ([`dsaav::health`]).
//! - [`datasets`] — the standard datasets of `configs/datasets.xml` and validation against them.
//! - [`params`] — module parameters with their places in the file.
//! - [`geo`] — flat-earth distances and angles for helms, simulators and navigation.
//! - [`estimate`] — the navigation estimators (Kalman depth, position EKF, heading corrections).
//! - [`frames`] — units, WGS-84 local frames and rotations for `convert`'s declared conversions.
//! - [`support`] — supporting modules (`generator`, `convert`, `square`, `external`, `logger`,
//!   the navigation modules, the health monitor).

pub mod datasets;
pub mod dsaav;
pub mod estimate;
pub mod frames;
pub mod geo;
pub mod module;
pub mod params;
pub mod registry;
pub mod runtime;
pub mod support;
pub mod system;

pub use datasets::Catalogue;
pub use module::{Context, Declaration, Module, ModuleError, ModuleKind, TICK, TimerId, TopicDecl};
pub use params::Params;
pub use registry::{Built, ModuleConfig, ModuleType, Registry};
pub use runtime::Runtime;
pub use system::SystemSpec;

/// A registry holding the module types this crate provides.
pub fn registry() -> Registry {
    let mut reg = Registry::new();
    support::register(&mut reg);
    reg.add_module(dsaav::servers::CONFIG)
        .add_module(dsaav::servers::LOG)
        .add_module(dsaav::starfish::VEHICLE_SIM)
        .add_module(dsaav::starfish::DEPTH_FILTER)
        .add_module(dsaav::starfish::DEPTH_CONTROLLER)
        .add_module(dsaav::bridge::TYPE)
        .add_module(dsaav::ecomms::TYPE)
        .add_module(dsaav::udp_bridge::TYPE);
    reg
}
