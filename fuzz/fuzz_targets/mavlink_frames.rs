//! Fuzzes the MAVLink medium's frame reading: any bytes read as frames and refusals without a
//! panic, the same however a stream's bytes come, and every message read encodes back to the same
//! fields.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/mavlink.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::mavlink_frames(data);
});
