//! Fuzzes CAN signal decoding: signals of any start, size, byte order and raw type decode any
//! frame data without a panic, and values encode back to the same raw bits.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/drivers.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::dbc_signals(data);
});
