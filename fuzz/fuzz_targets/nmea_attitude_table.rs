//! Fuzzes the table of proprietary NMEA attitude sentences: any text is a table or an error placed
//! in the file, and a table reads any fields without a panic, to finite angles only.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/drivers.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::nmea_attitude_table(data);
});
