//! seabus-drivers: device drivers, which marshal a device's data into standard datasets and its
//! commands back to the device, and the simulators that stand in for devices.
//!
#![cfg_attr(
    feature = "can",
    doc = "- [`can`] — CAN devices described by DBC files: signal decoding and encoding, the \
           `can-device` module (the `can` feature, on by default)."
)]
#![cfg_attr(
    not(feature = "can"),
    doc = "- `can` — CAN devices described by DBC files: signal decoding and encoding, the \
           `can-device` module (the `can` feature, on by default, left out of this build)."
)]
#![cfg_attr(
    feature = "can",
    doc = "- [`n2k`] — NMEA 2000 on a CAN medium: fast-packet and transport-protocol reassembly, \
           PGN decoding with a built-in set or canboat's database, the `nmea2000` module (the \
           `can` feature)."
)]
#![cfg_attr(
    not(feature = "can"),
    doc = "- `n2k` — NMEA 2000 on a CAN medium, the `nmea2000` module (the `can` feature, left \
           out of this build)."
)]
//! - [`command_status`] — the `command-status` dataset every driver and simulator answers its
//!   commands with on `cmd.status`.
//! - [`iver`] — the Iver2/Iver3 frontseat: Remote Helm protocol, backseat driver, simulated frontseat.
//! - [`mavlink`] — MAVLink vehicles (ArduSub, ArduRover): the `mavlink` driver on a MAVLink medium's
//!   topics.
//! - [`nmea`] — NMEA 0183 sentences and the GPS, heading, echo-sounder, wind, speed-log and
//!   steering drivers built on them.
//! - [`units`] — unit conversions of device protocols.
//! - [`sim`] — a simulated vehicle: [`sim::kinematics`] (heading, depth, speed dynamics and dead
//!   reckoning) and the `vehicle-sim` module that follows course commands and publishes navigation,
//!   battery and state datasets.
//!
//! The CAN device driver (`can`, DBC files) and the NMEA 2000 driver (`n2k`) need the `can`
//! feature (default on), which brings in `seabus-medium-can` for its frames.
//!
//! Who may depend on it: the program, which registers its types. It depends on the core, the
//! module framework and (with `can`) the CAN medium's frame model.

#[cfg(feature = "can")]
pub mod can;
pub mod command_status;
pub mod iver;
pub mod mavlink;
#[cfg(feature = "can")]
pub mod n2k;
pub mod nmea;
pub mod sim;
pub mod units;

use seabus_modules::Registry;

/// Registers the driver and simulator module types (`can-device` and `nmea2000` with the `can`
/// feature only).
pub fn register(reg: &mut Registry) {
    reg.add_module(sim::vehicle::TYPE)
        .add_module(nmea::sensors::GPS)
        .add_module(nmea::sensors::HEADING)
        .add_module(nmea::sensors::SOUNDER)
        .add_module(nmea::sensors::WIND)
        .add_module(nmea::sensors::LOG)
        .add_module(nmea::sensors::STEERING)
        .add_module(iver::driver::TYPE)
        .add_module(iver::sim::TYPE)
        .add_module(mavlink::driver::TYPE);
    #[cfg(feature = "can")]
    reg.add_module(can::device::TYPE)
        .add_module(n2k::driver::TYPE);
}
