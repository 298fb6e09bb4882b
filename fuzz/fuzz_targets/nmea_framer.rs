//! Fuzzes the stream framer of serial media (NMEA, lines, COBS, SLIP): any byte stream is framed
//! without a panic and within the maximum frame length, cutting the stream into chunks changes
//! nothing, every NMEA sentence handed out carries a correct checksum, and every frame handed out
//! encodes back to bytes that a fresh framer reads as the same frame.
//!
//! Input: the first byte picks the framing (`b % 4`: NMEA, lines, COBS, SLIP) and the checksum
//! policy (`b / 4 % 3`: require, allow-missing, ignore), the next two the maximum frame length
//! (little-endian, at least 8); the rest is the stream.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/core.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::nmea_framer(data);
});
