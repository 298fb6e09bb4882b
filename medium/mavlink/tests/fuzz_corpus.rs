//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/mavlink.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// MAVLink frames read as frames and refusals, the same however a stream's bytes come, and
    /// every message read encodes back to the same fields.
    mavlink_frames_seeds => mavlink_frames,
}
