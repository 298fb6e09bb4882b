//! Replays the seeds of the fuzz corpus for the layout reader (`fuzz/corpus/layout/`) through the
//! same property as the fuzz target, so that every seed runs with the ordinary tests, without
//! libFuzzer.

#[path = "../../fuzz/properties/ui.rs"]
mod properties;
#[macro_use]
#[path = "../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Every layout seed is read or refused with a place inside it; those that read keep their
    /// ids in their JSON form, and at least one reads (the shipped layouts are seeds).
    layout_seeds => layout,
}
