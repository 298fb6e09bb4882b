//! MOOS: [`wire`] is the V10 message and packet format.

pub mod wire;
