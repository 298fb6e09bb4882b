//! seabus-support: supporting modules — conversion, navigation, test signals, an example helm,
//! external programs and the logger.
//!
//! - `generator` publishes a counter and a sine wave at its tick rate, for testing links end to end;
//! - `convert` turns fields of one topic into fields of another by linear conversions declared in
//!   the system file (`depth_ft*0.3048 as depth`);
//! - `square` drives a vehicle around a square with course commands, leg by leg, from its position;
//! - `external` runs another program as a module, speaking JSON lines on its stdin and stdout;
//! - `logger` keeps one binary log of everything and a CSV per topic, stamped by seabus;
//! - `depth-kalman`, `position-ekf` and `heading-correction` estimate depth and vertical speed,
//!   position with the compass bias, and heading corrected for tilt and deviation, keeping the raw
//!   topics ([`estimate`] holds the estimators, [`frames`] the units, local frames and rotations
//!   of `convert`).
//!
//! Who may depend on it: the program, which registers its types ([`register`]). It depends on the
//! core and the module framework.

pub mod convert;
pub mod estimate;
pub mod external;
pub mod frames;
pub mod generator;
pub mod logger;
pub mod navigation;
pub mod square;

use seabus_modules::registry::Registry;

/// A registry with the supporting module types (and the in-process medium), for a program or test
/// that uses only these.
pub fn registry() -> Registry {
    let mut reg = Registry::new();
    register(&mut reg);
    reg
}

/// Registers the supporting module types.
pub fn register(reg: &mut Registry) {
    reg.add_module(generator::TYPE)
        .add_module(convert::TYPE)
        .add_module(square::TYPE)
        .add_module(external::TYPE)
        .add_module(logger::TYPE)
        .add_module(navigation::DEPTH)
        .add_module(navigation::POSITION)
        .add_module(navigation::HEADING);
}
