//! seabus-modules: the module framework — the module abstraction, the registry of module, bridge
//! and service types, the runtime that runs modules, parameters, system files and the standard
//! datasets.
//!
//! How the parts fit:
//!
//! - [`module`] — a [`Module`] declares what it produces, consumes and accepts ([`Declaration`]) and
//!   gets its messages and timer ticks through handlers (the Zagreb design's active mode); its
//!   [`Context`] holds one interface ("port") per medium it is placed on.
//! - [`registry`](mod@registry) — module, bridge and service types by name, and the program's
//!   medium schemes; each type builds fresh modules from a [`ModuleConfig`] (a system file's
//!   `<module>`) or a [`system::BridgeSpec`].
//! - [`system`] — system files: parsing, checking against a registry, route-cycle detection.
//! - [`runtime`] — the container: opens media, starts services, supervises modules (restart with
//!   back-off), publishes every medium's counters (`seabus.media`), shuts down on request.
//! - [`datasets`] — the standard datasets of `configs/datasets.xml` and validation against them.
//! - [`schema`] — JSON Schemas of topics (from their dataset, or read off a message) for MCAP files
//!   and live views.
//! - [`params`] — module parameters with their places in the file.
//! - [`logs`] — this program's own log as records, for the services that send it elsewhere (the
//!   DSAAV central log, the Foxglove live view).
//! - [`geo`] — flat-earth distances and angles for helms, simulators and navigation.
//!
//! The products built on it live in crates of their own: `seabus-dsaav` (the DSAAV services),
//! `seabus-support` (supporting and navigation modules), `seabus-drivers`, `seabus-bridges`,
//! `seabus-ui`.
//!
//! Who may depend on it: every product crate and the program. It depends on the core
//! (`seabus-medium`) only.

pub mod datasets;
pub mod geo;
pub mod logs;
pub mod module;
pub mod params;
pub mod registry;
pub mod runtime;
pub mod schema;
pub mod system;

pub use datasets::Catalogue;
pub use module::{Context, Declaration, Module, ModuleError, ModuleKind, TICK, TimerId, TopicDecl};
pub use params::Params;
pub use registry::{Built, ModuleConfig, ModuleType, Registry, Service, ServiceType};
pub use runtime::Runtime;
pub use system::SystemSpec;
