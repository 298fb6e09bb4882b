//! Properties of medium URLs, checked against every medium family's schemes.

use seabus_medium::Schemes;
use seabus_medium::url::MediumUrl;
use std::sync::OnceLock;

/// Every medium family's schemes.
fn schemes() -> &'static Schemes {
    static SCHEMES: OnceLock<Schemes> = OnceLock::new();
    SCHEMES.get_or_init(|| {
        Schemes::with(&[
            seabus_medium_udp::register,
            seabus_medium_serial::register,
            seabus_medium_can::register,
            seabus_medium_lcm::register,
            seabus_medium_dsaav::register,
            seabus_medium_moos::register,
        ])
    })
}

/// Medium URLs: any text parses or is refused without a panic, and checking a URL (scheme, options
/// and their values) never panics either; a URL that checks out also parses. True when `data` is
/// UTF-8 text that checks out as a medium URL.
pub fn medium_url(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let parsed = MediumUrl::parse(text);
    let checked = schemes().check(text);
    if checked.is_ok() {
        assert!(parsed.is_ok(), "a URL that checks out must parse: {text:?}");
    }
    checked.is_ok()
}
