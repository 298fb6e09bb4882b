//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/dsaav.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// DSAAV frames decode or are refused without a panic, and decoded frames encode to the same
    /// bytes.
    dsaav_frame_seeds => dsaav_frame,
}
