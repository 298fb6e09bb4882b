//! Fuzzes the JSON form of a datamap: any text reads or is refused without a panic, and every map it
//! reads writes back to JSON that reads as the same map.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/core.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::datamap_json(data);
});
