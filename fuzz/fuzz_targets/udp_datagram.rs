//! Fuzzes the UDP datagram decoder: any datagram decodes or is rejected without a panic, and every
//! message it accepts encodes back to a datagram that decodes to the same message.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/udp.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::udp_datagram(data);
});
