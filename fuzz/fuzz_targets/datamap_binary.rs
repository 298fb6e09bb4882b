//! Fuzzes the compact binary datamap decoder: any input decodes or is refused without a panic, and
//! every map it accepts encodes back to bytes that decode to the same map.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/core.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::datamap_binary(data);
});
