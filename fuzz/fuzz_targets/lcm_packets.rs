//! Fuzzes the LCM packet reader and the reassembly of fragments: datagrams parse or are refused
//! without a panic, and partial messages stay within the memory cap and complete at their size.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/lcm.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::lcm_packets(data);
});
