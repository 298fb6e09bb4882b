//! Fuzzes the health rules reader and the monitor built from what it reads: any text is read or
//! refused with a place inside it, never a panic, and the monitor keeps the severity rules.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/dsaav_services.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::health_rules(data);
});
