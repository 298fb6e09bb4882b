//! CAN devices described by a CAN database: [`dbc`] reads `.dbc` files and decodes and encodes
//! their signals.

pub mod dbc;
