//! Fuzzes NMEA 2000 frame decoding and reassembly: any sequence of frames goes through the
//! `nmea2000` driver without a panic, gives messages of bounded length, finite values and datasets
//! the catalogue accepts, and reassembled fast packets frame again to themselves.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/drivers.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::n2k_frames(data);
});
