//! Fuzzes the Iver Remote Helm protocol: any text is read as a frontseat sentence and as a backseat
//! command (in feet and in metres) without a panic, and every sentence read is written back to a
//! sentence that reads as the same kind of sentence. Text that is not a whole sentence with a
//! correct checksum is also read as the body of one.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_drivers::iver::protocol::{DepthUnits, FromFront, parse_command, parse_front};
use seabus_medium::serial::framing::{ChecksumPolicy, check_nmea, nmea_sentence};

/// `text` (without a leading `$`) written as a `$` sentence with its checksum, when it can be a
/// sentence body: printable ASCII without `*`.
fn wrapped(text: &str) -> Option<String> {
    let body = text.strip_prefix('$').unwrap_or(text);
    let printable = body
        .bytes()
        .all(|b| (0x20..=0x7e).contains(&b) && b != b'*');
    printable.then(|| nmea_sentence(b'$', body))
}

/// The frontseat sentence written back, for the kinds the simulated frontseat sends.
fn written(front: &FromFront) -> Option<String> {
    match front {
        FromFront::Osi(o) => Some(o.sentence()),
        FromFront::Compass(c) => Some(c.sentence()),
        FromFront::Opi(p) => Some(p.sentence()),
        FromFront::Ack(a) => Some(a.sentence()),
        FromFront::Dvl(d) => Some(d.sentence()),
        FromFront::Rmc(_) | FromFront::Other(_) => None,
    }
}

/// Reads `line` every way and checks that what reads also writes back and reads again.
fn check(line: &str) {
    if let Ok(front) = parse_front(line)
        && let Some(out) = written(&front)
    {
        let back = parse_front(&out).unwrap_or_else(|e| panic!("{out:?} does not read: {e}"));
        assert_eq!(
            std::mem::discriminant(&back),
            std::mem::discriminant(&front),
            "{out:?} reads as another kind of sentence"
        );
        if let FromFront::Ack(_) = front {
            assert_eq!(back, front, "$ACK round trip via {out:?}");
        }
    }
    for units in [DepthUnits::Feet, DepthUnits::Metres] {
        let Ok(cmd) = parse_command(line, units) else {
            continue;
        };
        let out = cmd.sentence(units);
        let back =
            parse_command(&out, units).unwrap_or_else(|e| panic!("{out:?} does not read: {e}"));
        assert_eq!(back.ack_code(), cmd.ack_code(), "round trip via {out:?}");
        assert_eq!(back.name(), cmd.name(), "round trip via {out:?}");
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    check(text);
    if check_nmea(text.as_bytes(), ChecksumPolicy::Require).is_err()
        && let Some(line) = wrapped(text)
    {
        check(&line);
    }
});
