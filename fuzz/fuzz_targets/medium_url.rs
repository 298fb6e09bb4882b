//! Fuzzes medium URLs: any text parses or is refused without a panic, and checking a URL (scheme,
//! options and their values) never panics either; a URL that checks out also parses.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_medium::Medium;
use seabus_medium::url::MediumUrl;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let parsed = MediumUrl::parse(text);
    if Medium::check_url(text).is_ok() {
        assert!(parsed.is_ok(), "a URL that checks out must parse");
    }
});
