//! Replays the seeds of the fuzz corpus for declared conversions (`fuzz/corpus/conversions/`)
//! through the same property as the fuzz target, so that every seed runs with the ordinary tests,
//! without libFuzzer.

#[path = "../../../fuzz/properties/support.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Every conversion seed is read or refused with a reason, and the transforms that read keep
    /// their properties.
    conversions_seeds => conversions,
}
