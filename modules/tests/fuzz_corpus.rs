//! Replays the seeds of the fuzz corpus for system files (`fuzz/corpus/system_file/`) through the
//! same property as the fuzz target, so that every seed runs with the ordinary tests, without
//! libFuzzer.

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
