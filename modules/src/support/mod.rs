//! Supporting modules: conversion, test signals, and an example helm.
//!
//! - `generator` publishes a counter and a sine wave at its tick rate, for testing links end to end;
//! - `convert` turns fields of one topic into fields of another by linear conversions declared in
//!   the system file (`depth_ft*0.3048 as depth`);
//! - `square` drives a vehicle around a square with course commands, leg by leg, from its position;
//! - `health-monitor` watches every module and medium by a health rules file and publishes the
//!   vehicle's severity;
//! - `external` runs another program as a module, speaking JSON lines on its stdin and stdout;
//! - `logger` keeps one binary log of everything and a CSV per topic, stamped by seabus;
//! - `depth-kalman`, `position-ekf` and `heading-correction` estimate depth and vertical speed,
//!   position with the compass bias, and heading corrected for tilt and deviation, keeping the raw
//!   topics.

pub mod convert;
pub mod external;
pub mod generator;
pub mod health_monitor;
pub mod logger;
pub mod navigation;
pub mod square;

use crate::registry::Registry;

/// Registers the supporting module types.
pub fn register(reg: &mut Registry) {
    reg.add_module(generator::TYPE)
        .add_module(convert::TYPE)
        .add_module(square::TYPE)
        .add_module(health_monitor::TYPE)
        .add_module(external::TYPE)
        .add_module(logger::TYPE)
        .add_module(navigation::DEPTH)
        .add_module(navigation::POSITION)
        .add_module(navigation::HEADING);
}
