//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same calls and round-trip checks as the
//! fuzz targets, so that every seed runs with the ordinary tests, without libFuzzer.

use bytes::Bytes;
use seabus_medium::serial::framing::{ChecksumPolicy, Framer, Framing, Output, check_nmea, encode};
use seabus_medium::udp::wire;
use seabus_medium::url::MediumUrl;
use seabus_medium::{DataMap, Medium, Value, binary, json, xmlform};
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

/// True when `v` is a NaN float or a list holding one at any depth.
fn has_nan(v: &Value) -> bool {
    match v {
        Value::Float(f) => f.is_nan(),
        Value::List(items) => items.iter().any(has_nan),
        _ => false,
    }
}

/// True when any value of `map` holds a NaN.
fn map_has_nan(map: &DataMap) -> bool {
    map.iter().any(|(_, v)| has_nan(v))
}

/// Binary datamaps decode or are refused, and accepted maps survive an encode/decode round trip.
#[test]
fn datamap_binary_seeds() {
    replay("datamap_binary", |path, data| {
        let Ok(map) = binary::decode(data) else {
            return false;
        };
        let back = binary::decode(&binary::encode(&map))
            .unwrap_or_else(|e| panic!("{}: re-encoded map does not decode: {e}", path.display()));
        assert_eq!(back, map, "{}: binary round trip", path.display());
        true
    });
}

/// XML datamaps read or are refused, and accepted maps survive a write/read round trip.
#[test]
fn datamap_xml_seeds() {
    replay("datamap_xml", |path, data| {
        let Ok(text) = std::str::from_utf8(data) else {
            return false;
        };
        let Ok(map) = xmlform::from_xml(text) else {
            return false;
        };
        let xml = xmlform::to_xml(&map);
        let back = xmlform::from_xml(&xml)
            .unwrap_or_else(|e| panic!("{}: written XML does not read: {e}", path.display()));
        assert_eq!(back, map, "{}: XML round trip via {xml}", path.display());
        true
    });
}

/// UDP datagrams decode or are rejected, and accepted messages survive an encode/decode round trip.
#[test]
fn udp_datagram_seeds() {
    replay("udp_datagram", |path, data| {
        let mut origins = wire::Origins::default();
        let Ok((sender, msg)) = wire::decode(&Bytes::copy_from_slice(data), &mut origins) else {
            return false;
        };
        let datagram = wire::encode(&msg, sender)
            .unwrap_or_else(|e| panic!("{}: decoded message does not encode: {e}", path.display()));
        let (sender2, back) = wire::decode(&datagram, &mut origins).unwrap_or_else(|e| {
            panic!(
                "{}: re-encoded datagram does not decode: {e}",
                path.display()
            )
        });
        let at = path.display();
        assert_eq!(sender2, sender, "{at}: sender");
        assert_eq!(back.topic, msg.topic, "{at}: topic");
        assert_eq!(back.kind, msg.kind, "{at}: kind");
        assert_eq!(back.provenance, msg.provenance, "{at}: provenance");
        assert_eq!(back.stamp, msg.stamp, "{at}: stamp");
        assert_eq!(back.payload, msg.payload, "{at}: payload");
        true
    });
}

/// Medium URLs parse and check without a panic, and a URL that checks out also parses.
#[test]
fn medium_url_seeds() {
    replay("medium_url", |path, data| {
        let Ok(text) = std::str::from_utf8(data) else {
            return false;
        };
        let parsed = MediumUrl::parse(text);
        let checked = Medium::check_url(text);
        if checked.is_ok() {
            assert!(
                parsed.is_ok(),
                "{}: checks out but does not parse",
                path.display()
            );
        }
        checked.is_ok()
    });
}

/// JSON datamaps read or are refused, and accepted maps without a NaN survive a write/read round trip.
#[test]
fn datamap_json_seeds() {
    replay("datamap_json", |path, data| {
        let Ok(text) = std::str::from_utf8(data) else {
            return false;
        };
        let Ok(map) = json::from_json(text) else {
            return false;
        };
        let written = json::to_json(&map);
        let back = json::from_json(&written)
            .unwrap_or_else(|e| panic!("{}: written JSON does not read: {e}", path.display()));
        if !map_has_nan(&map) {
            assert_eq!(
                back,
                map,
                "{}: JSON round trip via {written}",
                path.display()
            );
        }
        true
    });
}

/// The framing, checksum policy, maximum frame length and stream a framer seed describes: the first
/// byte picks the framing (`b % 4`) and the policy (`b / 4 % 3`), the next two the maximum
/// (little-endian, at least 8).
fn framer_setup(data: &[u8]) -> Option<(Framing, ChecksumPolicy, usize, &[u8])> {
    let [sel, lo, hi, stream @ ..] = data else {
        return None;
    };
    let framing =
        [Framing::Nmea, Framing::Lines, Framing::Cobs, Framing::Slip][usize::from(sel % 4)];
    let policy = [
        ChecksumPolicy::Require,
        ChecksumPolicy::AllowMissing,
        ChecksumPolicy::Ignore,
    ][usize::from(sel / 4 % 3)];
    let max = usize::from(u16::from_le_bytes([*lo, *hi])).max(8);
    Some((framing, policy, max, stream))
}

/// The stream cut into pieces of `b % 17 + 1` bytes, `b` being each piece's first byte.
fn framer_pieces(stream: &[u8]) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let mut rest = stream;
    while let Some(&b) = rest.first() {
        let (piece, tail) = rest.split_at(usize::from(b % 17 + 1).min(rest.len()));
        out.push(piece);
        rest = tail;
    }
    out
}

/// Feeds `chunks` to a new framer in turn, checking after each that it holds at most `max` bytes;
/// returns everything it handed out.
fn framer_run<'a>(
    at: &Path,
    framing: Framing,
    policy: ChecksumPolicy,
    max: usize,
    chunks: impl IntoIterator<Item = &'a [u8]>,
) -> Vec<Output> {
    let mut framer = Framer::new(framing, policy, max);
    let mut got = Vec::new();
    for chunk in chunks {
        framer.push(chunk, &mut |o| got.push(o));
        assert!(
            framer.pending() <= max + 1,
            "{}: the framer holds {} bytes, more than {max}",
            at.display(),
            framer.pending()
        );
    }
    got
}

/// Checks one frame handed out: its length, its checksum (NMEA), and that it encodes back to bytes
/// a fresh framer reads as the same frame.
fn framer_check_frame(
    at: &Path,
    framing: Framing,
    policy: ChecksumPolicy,
    max: usize,
    frame: &[u8],
) {
    let at = at.display();
    match framing {
        Framing::Nmea => {
            assert_eq!(
                check_nmea(frame, ChecksumPolicy::Require).as_deref(),
                Ok(frame),
                "{at}: a framed sentence carries a correct checksum"
            );
            // a sentence accepted without a checksum gets `*hh` added
            let bound = if policy == ChecksumPolicy::Require {
                max
            } else {
                max + 3
            };
            assert!(
                frame.len() <= bound,
                "{at}: sentence of {} bytes",
                frame.len()
            );
        }
        Framing::Lines => {
            assert!(
                !frame.is_empty() && !frame.contains(&b'\n'),
                "{at}: line {frame:?}"
            );
            assert!(frame.len() <= max, "{at}: line of {} bytes", frame.len());
        }
        // a COBS frame of at most `max` bytes decodes to fewer bytes
        Framing::Cobs => assert!(
            frame.len() < max,
            "{at}: COBS frame of {} bytes",
            frame.len()
        ),
        Framing::Slip => {
            assert!(!frame.is_empty(), "{at}: empty SLIP frame");
            assert!(
                frame.len() <= max,
                "{at}: SLIP frame of {} bytes",
                frame.len()
            );
        }
    }
    let wire =
        encode(framing, frame).unwrap_or_else(|e| panic!("{at}: {frame:?} does not encode: {e}"));
    let mut framer = Framer::new(framing, ChecksumPolicy::Require, wire.len());
    let mut back = Vec::new();
    framer.push(&wire, &mut |o| back.push(o));
    assert_eq!(back, [Ok(frame.to_vec())], "{at}: round trip via {wire:?}");
}

/// Framer seeds are framed without a panic and within the maximum, the same whole and in chunks;
/// NMEA sentences handed out carry a correct checksum and every frame survives an encode/frame
/// round trip.
#[test]
fn nmea_framer_seeds() {
    replay("nmea_framer", |path, data| {
        let Some((framing, policy, max, stream)) = framer_setup(data) else {
            return false;
        };
        let whole = framer_run(path, framing, policy, max, [stream]);
        let chunked = framer_run(path, framing, policy, max, framer_pieces(stream));
        assert_eq!(
            chunked,
            whole,
            "{}: chunking changed the output",
            path.display()
        );
        let mut last = 0;
        let mut frames = 0;
        for out in &whole {
            match out {
                Ok(frame) => {
                    framer_check_frame(path, framing, policy, max, frame);
                    frames += 1;
                }
                Err(r) => {
                    assert!(
                        r.offset >= last && r.offset < stream.len() as u64,
                        "{}: rejection at {}",
                        path.display(),
                        r.offset
                    );
                    last = r.offset;
                }
            }
        }
        frames > 0
    });
}
