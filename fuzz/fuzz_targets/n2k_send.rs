//! Fuzzes what the NMEA 2000 driver sends: datamaps encoded into PGNs (taken or refused without a
//! panic; what is taken fits its framing and decodes back to the numbers given) and the messages
//! an address claimer hears (it always gives an address a device may hold, or the null address,
//! and answers only with its claim).

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/drivers.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::n2k_send(data);
});
