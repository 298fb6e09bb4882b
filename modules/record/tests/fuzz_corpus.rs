//! Replays the seeds of the fuzz corpus for MCAP reading (`fuzz/corpus/mcap_reader/`) through the
//! same property as the fuzz target, so that every seed runs with the ordinary tests, without
//! libFuzzer.

#[path = "../../../fuzz/properties/record.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// MCAP files read to their end or to damage inside them, the same whole and a few bytes at a
    /// time.
    mcap_reader_seeds => mcap_reader,
}
