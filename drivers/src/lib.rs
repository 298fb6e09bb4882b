//! seabus-drivers: device drivers, which marshal a device's data into standard datasets and its
//! commands back to the device, and the simulators that stand in for devices.
//!
//! - [`sim`] — a simulated vehicle: [`sim::kinematics`] (heading, depth, speed dynamics and dead
//!   reckoning) and the `vehicle-sim` module that follows course commands and publishes navigation,
//!   battery and state datasets.

pub mod sim;

use seabus_modules::Registry;

/// Registers the driver and simulator module types.
pub fn register(reg: &mut Registry) {
    reg.add_module(sim::vehicle::TYPE);
}
