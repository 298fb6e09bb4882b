//! Fuzzes the LCM message codec: any bytes decode or are refused without a panic, and every
//! message that decodes encodes back to the same bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/lcm.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::lcm_codec(data);
});
