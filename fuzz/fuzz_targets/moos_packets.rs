//! Fuzzes the MOOS packet reader: any bytes read, wait for more or are refused without a panic,
//! and packets read encode back to the same bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/moos.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::moos_packets(data);
});
