//! Replays the seeds of the fuzz corpus for the DSAAV services' readers
//! (`fuzz/corpus/dsaav_config/`, `fuzz/corpus/health_rules/`) through the same properties as the
//! fuzz targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../../../fuzz/properties/dsaav_services.rs"]
mod properties;
#[macro_use]
#[path = "../../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Every DSAAV configuration seed is read or refused with a place inside it, and those that
    /// read write back to text that reads the same.
    dsaav_config_seeds => dsaav_config,
    /// Every health-rules seed is read or refused with a place inside it, and a monitor following
    /// the rules that read keeps the severity rules.
    health_rules_seeds => health_rules,
}
