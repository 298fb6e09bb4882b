//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/moos.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// MOOS packets read, wait for more or are refused without a panic, and packets read encode
    /// back to the same bytes.
    moos_packets_seeds => moos_packets,
}
