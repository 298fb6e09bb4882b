//! Fuzzes the NMEA 0183 sentence parser of the NMEA drivers: any text is read or refused without a
//! panic. Text that is not a whole sentence with a correct checksum is also read as the body of
//! one, so that the parsers behind a known address see well-framed sentences too.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/drivers.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::nmea_sentence(data);
});
