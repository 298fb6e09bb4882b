//! Fuzzes the DSAAV configuration-file reader: any bytes are read or refused with a place inside
//! the file, never a panic, and a file that reads writes back to text that reads the same.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/dsaav_services.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::dsaav_config(data);
});
