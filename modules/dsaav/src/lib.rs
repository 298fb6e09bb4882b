//! seabus-dsaav: the DSAAV services over the IComms medium of `seabus-medium-dsaav`
//! (`dsaav+…://`), layered as in the paper: [`rpc`] (reliable, unreliable and broadcast calls) carries the core services; the
//! configuration database ([`config`]) holds configuration data from a sectioned text file,
//! application data that software puts and that persists in its own file, and the "data plumbing"
//! that tells a component which server provides a service; [`config_service`] serves it over RPC.
//! [`sentuator`] puts sensors and actuators behind get / set / notify / health calls; [`logging`]
//! keeps one central log for every component; the health monitor's core ([`health`]) reads the
//! health rules file and turns component health updates into a vehicle severity; [`servers`] makes
//! the configuration and logging servers module types for system files, and [`starfish`] the
//! paper's depth-control example; [`bridge`] joins sentuators to a seabus bus (notifications to
//! datasets, actuator commands to set calls); [`ecomms`] queues messages for external links;
//! [`udp_bridge`] lets control stations on an allow-list reach the vehicle's services over UDP.
//! The `health-monitor` module ([`health_monitor`]) applies the health rules to every module and
//! medium of a system, lists the media that lost anything, and serves them over DSAAV
//! ([`health_service`]); [`central`] sends every
//! module's log records to the central log (a system's `<log>`).
//!
//! Who may depend on it: the program, which registers its types ([`register`]). It depends on the
//! core, the DSAAV medium and the module framework.

pub mod bridge;
pub mod central;
pub mod config;
pub mod config_service;
pub mod ecomms;
pub mod health;
pub mod health_monitor;
pub mod health_service;
pub mod logging;
pub mod rpc;
pub mod sentuator;
pub mod servers;
pub mod starfish;
pub mod udp_bridge;

pub use config::{Database, Sections, ValueError};
pub use seabus_medium_dsaav::wire::Address;

use seabus_modules::Registry;

/// Registers the DSAAV module types and the `<log>` service.
pub fn register(reg: &mut Registry) {
    reg.add_module(servers::CONFIG)
        .add_module(servers::LOG)
        .add_module(starfish::VEHICLE_SIM)
        .add_module(starfish::DEPTH_FILTER)
        .add_module(starfish::DEPTH_CONTROLLER)
        .add_module(bridge::TYPE)
        .add_module(ecomms::TYPE)
        .add_module(udp_bridge::TYPE)
        .add_module(health_monitor::TYPE)
        .add_service(central::LOG);
}
