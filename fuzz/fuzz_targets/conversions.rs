//! Fuzzes the `convert` module's unit conversions and frame transforms: any line is read or
//! refused with a reason, never a panic, and what reads keeps the transforms' properties.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/support.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::conversions(data);
});
