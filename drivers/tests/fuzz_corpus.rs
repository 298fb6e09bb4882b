//! Replays the NMEA sentence and Remote Helm seeds of the fuzz corpus (`fuzz/corpus/`) through the
//! same calls and round-trip checks as the fuzz targets, so that every seed runs with the ordinary
//! tests, without libFuzzer.

use seabus_drivers::iver::protocol::{DepthUnits, FromFront, parse_command, parse_front};
use seabus_drivers::nmea::sentence::parse;
use seabus_medium::serial::framing::{ChecksumPolicy, check_nmea, nmea_sentence};
use std::path::{Path, PathBuf};

/// The seed files of fuzz target `target`, sorted by name; fails when there are none.
fn seeds(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus")
        .join(target);
    let entries =
        std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()));
    let mut out = Vec::new();
    for entry in entries {
        let path = entry.expect("a readable directory entry").path();
        let hidden = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if path.is_file() && !hidden {
            let data = std::fs::read(&path)
                .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
            out.push((path, data));
        }
    }
    out.sort();
    assert!(!out.is_empty(), "no seed files in {}", dir.display());
    out
}

/// Runs `check` on every seed of `target` and fails unless at least one seed was accepted.
fn replay(target: &str, check: impl Fn(&Path, &[u8]) -> bool) {
    let mut accepted = 0;
    for (path, data) in seeds(target) {
        if check(&path, &data) {
            accepted += 1;
        }
    }
    assert!(accepted > 0, "no seed of {target} is a valid input");
}

/// `text` (without a leading `$` or, when `bang` is set, `!`) written as a `$` sentence with its
/// checksum, when it is not already a whole sentence with a correct checksum and can be a sentence
/// body: printable ASCII without `*`.
fn wrapped(text: &str, bang: bool) -> Option<String> {
    if check_nmea(text.as_bytes(), ChecksumPolicy::Require).is_ok() {
        return None;
    }
    let starts: &[char] = if bang { &['$', '!'] } else { &['$'] };
    let body = text.strip_prefix(starts).unwrap_or(text);
    let printable = body
        .bytes()
        .all(|b| (0x20..=0x7e).contains(&b) && b != b'*');
    printable.then(|| nmea_sentence(b'$', body))
}

/// NMEA sentences parse or are refused without a panic, as they are and as the body of a sentence;
/// a built sentence carries a correct checksum.
#[test]
fn nmea_sentence_seeds() {
    replay("nmea_sentence", |path, data| {
        let Ok(text) = std::str::from_utf8(data) else {
            return false;
        };
        let parsed = parse(text);
        if let Some(line) = wrapped(text, true) {
            if line.len() > 4 {
                assert_eq!(
                    check_nmea(line.as_bytes(), ChecksumPolicy::Require).as_deref(),
                    Ok(line.as_bytes()),
                    "{}: built sentence {line:?}",
                    path.display()
                );
            }
            let _ = parse(&line);
        }
        parsed.is_ok()
    });
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

/// Reads `line` as a frontseat sentence and as a command in both depth units, checks that what
/// reads also writes back and reads again, and tells whether anything but an unknown sentence read.
fn remote_helm_check(at: &Path, line: &str) -> bool {
    let at = at.display();
    let mut read = false;
    if let Ok(front) = parse_front(line) {
        if let Some(out) = written(&front) {
            let back =
                parse_front(&out).unwrap_or_else(|e| panic!("{at}: {out:?} does not read: {e}"));
            assert_eq!(
                std::mem::discriminant(&back),
                std::mem::discriminant(&front),
                "{at}: {out:?} reads as another kind of sentence"
            );
            if let FromFront::Ack(_) = front {
                assert_eq!(back, front, "{at}: $ACK round trip via {out:?}");
            }
            read = true;
        }
    }
    for units in [DepthUnits::Feet, DepthUnits::Metres] {
        let Ok(cmd) = parse_command(line, units) else {
            continue;
        };
        let out = cmd.sentence(units);
        let back = parse_command(&out, units)
            .unwrap_or_else(|e| panic!("{at}: {out:?} does not read: {e}"));
        assert_eq!(
            back.ack_code(),
            cmd.ack_code(),
            "{at}: round trip via {out:?}"
        );
        assert_eq!(back.name(), cmd.name(), "{at}: round trip via {out:?}");
        read = true;
    }
    read
}

/// Remote Helm sentences read as frontseat sentences and as commands without a panic, as they are
/// and as the body of a sentence, and what reads survives a write/read round trip.
#[test]
fn remote_helm_seeds() {
    replay("remote_helm", |path, data| {
        let Ok(text) = std::str::from_utf8(data) else {
            return false;
        };
        let mut read = remote_helm_check(path, text);
        if let Some(line) = wrapped(text, false) {
            read |= remote_helm_check(path, &line);
        }
        read
    });
}
