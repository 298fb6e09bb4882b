//! Fuzzes the LCM event-log reader and writer: any log reads without a panic up to its end or its
//! damage, the same in one piece or a few bytes at a time, and the events read write back to the
//! same bytes and read back the same.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/core.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::lcm_eventlog(data);
});
