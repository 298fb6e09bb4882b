//! CAN devices described by a CAN database: [`dbc`] reads `.dbc` files and decodes and encodes
//! their signals; [`device`] is the `can-device` module that puts a device's messages on the bus
//! and its commands on the CAN medium.

pub mod dbc;
pub mod device;
