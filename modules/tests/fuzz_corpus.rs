//! Replays the system-file seeds of the fuzz corpus (`fuzz/corpus/system_file/`) through the same
//! readers as the fuzz target, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../fuzz/properties/modules.rs"]
mod properties;
#[macro_use]
#[path = "../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Every system-file seed is read or refused without a panic, and at least one is a valid
    /// system.
    system_file_seeds => system_file,
}
