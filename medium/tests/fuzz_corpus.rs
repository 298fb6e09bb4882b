//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../fuzz/properties/medium.rs"]
mod properties;
#[macro_use]
#[path = "../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Binary datamaps decode or are refused, and accepted maps survive an encode/decode round trip.
    datamap_binary_seeds => datamap_binary,
    /// XML datamaps read or are refused, and accepted maps survive a write/read round trip.
    datamap_xml_seeds => datamap_xml,
    /// UDP datagrams decode or are rejected, and accepted messages survive an encode/decode round
    /// trip.
    udp_datagram_seeds => udp_datagram,
    /// Medium URLs parse and check without a panic, and a URL that checks out also parses.
    medium_url_seeds => medium_url,
    /// JSON datamaps read or are refused, and accepted maps without a NaN survive a write/read round
    /// trip.
    datamap_json_seeds => datamap_json,
    /// Framer seeds are framed without a panic and within the maximum, the same whole and in chunks;
    /// NMEA sentences handed out carry a correct checksum and every frame survives an encode/frame
    /// round trip.
    nmea_framer_seeds => nmea_framer,
    /// `.lcm` files are read or refused without a panic, refusals name a place in the file, and
    /// resolved structs are found by name and fingerprint, with consistent member types and sizes.
    lcm_types_seeds => lcm_types,
    /// LCM datagrams parse or are refused without a panic, short messages re-encode to the same
    /// bytes, and reassembly stays within its memory cap and completes messages at their size.
    lcm_packets_seeds => lcm_packets,
    /// LCM event logs read up to their end or damage, the same whole and a few bytes at a time, and
    /// the events read write back to the same bytes and read back the same.
    lcm_eventlog_seeds => lcm_eventlog,
    /// LCM messages decode or are refused without a panic, and those that decode encode back to
    /// the same bytes.
    lcm_codec_seeds => lcm_codec,
    /// DSAAV frames decode or are refused without a panic, and decoded frames encode to the same
    /// bytes.
    dsaav_frame_seeds => dsaav_frame,
    /// slcan byte streams split into the same lines whole and in pieces, lines parse or are refused
    /// without a panic, and frames survive slcan and message round trips.
    slcan_lines_seeds => slcan_lines,
    /// cannelloni packets decode or are refused without a panic, and decoded packets encode to
    /// the same bytes.
    cannelloni_packets_seeds => cannelloni_packets,
    /// MOOS packets read, wait for more or are refused without a panic, and packets read encode
    /// back to the same bytes.
    moos_packets_seeds => moos_packets,
}
