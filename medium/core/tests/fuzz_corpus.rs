//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/core.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Binary datamaps decode or are refused, and accepted maps survive an encode/decode round trip.
    datamap_binary_seeds => datamap_binary,
    /// XML datamaps read or are refused, and accepted maps survive a write/read round trip.
    datamap_xml_seeds => datamap_xml,
    /// JSON datamaps read or are refused, and accepted maps without a NaN survive a write/read round
    /// trip.
    datamap_json_seeds => datamap_json,
    /// Framer seeds are framed without a panic and within the maximum, the same whole and in chunks;
    /// NMEA sentences handed out carry a correct checksum and every frame survives an encode/frame
    /// round trip.
    nmea_framer_seeds => nmea_framer,
    /// LCM event logs read up to their end or damage, the same whole and a few bytes at a time, and
    /// the events read write back to the same bytes and read back the same.
    lcm_eventlog_seeds => lcm_eventlog,
}
