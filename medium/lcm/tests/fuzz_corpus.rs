//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/lcm.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// `.lcm` files are read or refused without a panic, refusals name a place in the file, and
    /// resolved structs are found by name and fingerprint, with consistent member types and sizes.
    lcm_types_seeds => lcm_types,
    /// LCM datagrams parse or are refused without a panic, short messages re-encode to the same
    /// bytes, and reassembly stays within its memory cap and completes messages at their size.
    lcm_packets_seeds => lcm_packets,
    /// LCM messages decode or are refused without a panic, and those that decode encode back to
    /// the same bytes.
    lcm_codec_seeds => lcm_codec,
}
