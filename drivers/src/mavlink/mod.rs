//! MAVLink vehicles (ArduSub ROVs, ArduRover boats): the `mavlink` driver, which turns one
//! vehicle's messages on a `mavlink://` medium into standard datasets and the bus's commands into
//! MAVLink commands ([`driver`]), and what ArduPilot's messages mean ([`ardupilot`]).
//!
//! The driver talks to the medium through its topics only (`mavlink.SYSID.NAME`,
//! `mavlink.vehicles`), so it works on any medium that carries them, bridged or not.

pub mod ardupilot;
pub mod driver;
