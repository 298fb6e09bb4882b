//! Fuzzes reading MCAP files: any bytes read to an end or to damage at an offset inside them, the
//! same whole and a few bytes at a time, without a panic.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/record.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::mcap_reader(data);
});
