//! Fuzzes the DSAAV IComms frame decoder: any bytes decode or are refused without a panic, and a
//! decoded frame encodes back to the bytes it was read from.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/dsaav.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::dsaav_frame(data);
});
