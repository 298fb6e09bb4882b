//! Replays the fuzz seed corpus (`fuzz/corpus/`) through the same calls and round-trip checks as the
//! fuzz targets, so that every seed runs with the ordinary tests, without libFuzzer.

use bytes::Bytes;
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
