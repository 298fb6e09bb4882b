//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/can.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// slcan byte streams split into the same lines whole and in pieces, lines parse or are refused
    /// without a panic, and frames survive slcan and message round trips.
    slcan_lines_seeds => slcan_lines,
    /// cannelloni packets decode or are refused without a panic, and decoded packets encode to
    /// the same bytes.
    cannelloni_packets_seeds => cannelloni_packets,
}
