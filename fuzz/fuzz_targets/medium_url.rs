//! Fuzzes medium URLs: any text parses or is refused without a panic, and checking a URL (scheme,
//! options and their values) never panics either; a URL that checks out also parses.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/urls.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::medium_url(data);
});
