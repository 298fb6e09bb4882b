//! Simulators: stand-ins for devices and vehicles, for demos and tests without hardware.

pub mod kinematics;
pub mod vehicle;
