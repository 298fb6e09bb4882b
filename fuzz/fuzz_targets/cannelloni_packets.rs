//! Fuzzes the cannelloni packet reader: any bytes decode or are refused without a panic, and
//! decoded packets encode back to the same bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/can.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::cannelloni_packets(data);
});
