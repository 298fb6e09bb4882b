//! DSAAV services: the core services of the DSAAV architecture (the STARFISH AUV's) that every
//! component relies on. For now only the configuration database ([`config`]): configuration data
//! from a sectioned text file, application data that software puts and that persists in its own
//! file, and the "data plumbing" that tells a component which server provides a service.

pub mod config;

pub use config::{Address, Database, Sections, ValueError};
