//! Fuzzes the `.lcm` type reader: any text is read or refused without a panic, and a set that
//! reads and resolves gives every struct a fingerprint by which it is found again.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/lcm.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::lcm_types(data);
});
