//! Fuzzes the NMEA 0183 sentence parser of the NMEA drivers: any text is read or refused without a
//! panic. Text that is not a whole sentence with a correct checksum is also read as the body of
//! one, so that the parsers behind a known address see well-framed sentences too.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_drivers::nmea::sentence::parse;
use seabus_medium::serial::framing::{ChecksumPolicy, check_nmea, nmea_sentence};

/// `text` (without a leading `$` or `!`) written as a `$` sentence with its checksum, when it can
/// be a sentence body: printable ASCII without `*`.
fn wrapped(text: &str) -> Option<String> {
    let body = text.strip_prefix(['$', '!']).unwrap_or(text);
    let printable = body
        .bytes()
        .all(|b| (0x20..=0x7e).contains(&b) && b != b'*');
    printable.then(|| nmea_sentence(b'$', body))
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = parse(text);
    if check_nmea(text.as_bytes(), ChecksumPolicy::Require).is_err()
        && let Some(line) = wrapped(text)
    {
        if line.len() > 4 {
            assert_eq!(
                check_nmea(line.as_bytes(), ChecksumPolicy::Require).as_deref(),
                Ok(line.as_bytes()),
                "a built sentence carries a correct checksum"
            );
        }
        let _ = parse(&line);
    }
});
