//! Fuzzes the slcan line splitter and parser: any byte stream splits and parses without a panic,
//! and frames survive the slcan and message round trips.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/can.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::slcan_lines(data);
});
