//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same property checks as the fuzz
//! targets, so that every seed runs with the ordinary tests, without libFuzzer.

#[path = "../fuzz/properties/urls.rs"]
mod properties;
#[macro_use]
#[path = "../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// Medium URLs parse and check without a panic, and a URL that checks out also parses.
    medium_url_seeds => medium_url,
}
