//! Property tests: every conversion between the three payload formats (and the JSON form)
//! round-trips, nested lists and maps included, no decoder panics on any input, topic matching agrees with segment-by-segment matching, and duplicate
//! detection agrees with a plain model.

use bytes::Bytes;
use proptest::prelude::*;
use seabus_medium::datagram as wire;
use seabus_medium::datamap::MAX_DEPTH;
use seabus_medium::dedup::{Dedup, Seen, WINDOW};
use seabus_medium::message::{Kind, Message, Origin, Provenance, Stamp};
use seabus_medium::{DataMap, Format, Pattern, Payload, Topic, Value, binary, json, xmlform};
use std::collections::BTreeSet;

fn scalar() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::Int),
        // any bit pattern: NaNs with payloads, infinities, negative zero, subnormals
        any::<u64>().prop_map(|b| Value::Float(f64::from_bits(b))),
        any::<f64>().prop_map(Value::Float),
        ".*".prop_map(Value::from),
        "[\\x00-\\x1f\\u{fffe}\\u{ffff}a<&>\"' \r\n\t]{0,8}".prop_map(Value::from),
        proptest::collection::vec(any::<u8>(), 0..40).prop_map(Value::Bytes),
    ]
}

/// Scalars, and lists and nested maps of values (maps may repeat a key, as decoders keep them).
fn value() -> impl Strategy<Value = Value> {
    scalar().prop_recursive(4, 32, 6, |inner| {
        prop_oneof![
            proptest::collection::vec(inner.clone(), 0..6).prop_map(Value::List),
            proptest::collection::vec((key(), inner), 0..6).prop_map(|entries| {
                Value::Map(DataMap::from_entries(
                    entries.into_iter().map(|(k, v)| (k.into(), v)).collect(),
                ))
            }),
        ]
    })
}

/// A value inside a chain of lists and maps as deep as the payload forms carry.
fn deep_value() -> impl Strategy<Value = Value> {
    chain(0..=MAX_DEPTH)
}

/// A scalar inside a chain of `levels` lists and maps, each picked at random.
fn chain(levels: std::ops::RangeInclusive<usize>) -> impl Strategy<Value = Value> {
    (
        scalar(),
        proptest::collection::vec((any::<bool>(), key()), levels),
    )
        .prop_map(|(leaf, chain)| {
            chain.into_iter().rev().fold(leaf, |v, (map, k)| {
                if map {
                    Value::Map(DataMap::new().with(k, v))
                } else {
                    Value::List(vec![v])
                }
            })
        })
}

fn key() -> impl Strategy<Value = String> {
    prop_oneof![
        "[a-z_][a-z0-9_]{0,12}",
        ".{0,10}",
        "[\\x00-\\x1f \t\n\r\"<>&]{1,5}",
        // the words that open JSON's one-key forms
        prop_oneof![Just("float"), Just("base64"), Just("map")].prop_map(String::from),
    ]
}

fn datamap() -> impl Strategy<Value = DataMap> {
    let entry = prop_oneof![4 => value(), 1 => deep_value()];
    proptest::collection::vec((key(), entry), 0..10)
        .prop_map(|entries| entries.into_iter().collect())
}

/// `v` with every NaN made the default NaN: the JSON form writes each NaN as `{"float": "NaN"}`.
fn nan_as_json_reads_it(v: &Value) -> Value {
    match v {
        Value::Float(f) if f.is_nan() => Value::Float(f64::NAN),
        Value::List(items) => Value::List(items.iter().map(nan_as_json_reads_it).collect()),
        Value::Map(m) => Value::Map(map_as_json_reads_it(m)),
        other => other.clone(),
    }
}

/// `map` with every NaN made the default NaN, at any depth.
fn map_as_json_reads_it(map: &DataMap) -> DataMap {
    DataMap::from_entries(
        map.iter()
            .map(|(k, v)| (k.to_string().into(), nan_as_json_reads_it(v)))
            .collect(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn binary_round_trips(m in datamap()) {
        let bytes = binary::encode(&m).unwrap();
        prop_assert_eq!(binary::encoded_len(&m), bytes.len());
        prop_assert_eq!(binary::decode(&bytes).unwrap(), m);
    }

    #[test]
    fn xml_round_trips(m in datamap()) {
        let xml = xmlform::to_xml(&m).unwrap();
        prop_assert_eq!(xmlform::from_xml(&xml).unwrap(), m);
    }

    #[test]
    fn json_round_trips(m in datamap()) {
        let text = json::to_json(&m).unwrap();
        prop_assert_eq!(json::from_json(&text).unwrap(), map_as_json_reads_it(&m), "{}", text);
    }

    #[test]
    fn one_level_past_the_limit_has_no_form(v in chain(MAX_DEPTH + 1..=MAX_DEPTH + 1), k in key()) {
        let m = DataMap::new().with(k, v);
        prop_assert!(binary::encode(&m).is_err());
        prop_assert!(xmlform::to_xml(&m).is_err());
        prop_assert!(json::to_json(&m).is_err());
        prop_assert!(Payload::from(m).convert(Format::Bytes).is_err());
    }

    #[test]
    fn every_conversion_chain_round_trips(m in datamap(), path in proptest::collection::vec(0u8..3, 1..6)) {
        let fmt = |i: u8| [Format::Bytes, Format::Map, Format::Xml][i as usize];
        let mut p = Payload::from(m.clone());
        for step in path {
            p = p.convert(fmt(step)).unwrap();
            prop_assert_eq!(p.format(), fmt(step));
        }
        prop_assert_eq!(&*p.to_map().unwrap(), &m);
        // and the binary form is the same whichever way it was reached
        let direct = binary::encode(&m).unwrap();
        let via_xml = Payload::from(m.clone()).convert(Format::Xml).unwrap().convert(Format::Bytes).unwrap();
        prop_assert_eq!(via_xml.as_bytes().unwrap().as_ref(), &direct[..]);
    }

    #[test]
    fn udp_datagrams_round_trip(m in datamap(), topic in "[a-z]{1,8}(\\.[a-z0-9_]{1,8}){0,4}",
                                seq in any::<u64>(), hops in any::<u8>(), stamp in any::<i64>(),
                                command in any::<bool>(), boot in any::<u32>(), sender in any::<u64>()) {
        let msg = Message {
            topic: Topic::new(&topic).unwrap(),
            kind: if command { Kind::Command } else { Kind::Data },
            provenance: Provenance { origin: Origin::new("node-1", "bus", boot), seq, hops },
            stamp: Stamp(stamp),
            payload: Payload::from(m.clone()),
        };
        let d = wire::encode(&msg, sender).unwrap();
        let (s, back) = wire::decode(&d, &mut wire::Origins::default()).unwrap();
        prop_assert_eq!(s, sender);
        prop_assert_eq!(back.topic, msg.topic);
        prop_assert_eq!(back.kind, msg.kind);
        prop_assert_eq!(back.provenance, msg.provenance);
        prop_assert_eq!(back.stamp, msg.stamp);
        prop_assert_eq!(&*back.payload.to_map().unwrap(), &m);
    }

    #[test]
    fn binary_decoder_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = binary::decode(&bytes);
        let mut with_magic = b"SM\x01".to_vec();
        with_magic.extend_from_slice(&bytes);
        let _ = binary::decode(&with_magic);
    }

    #[test]
    fn xml_reader_never_panics(text in ".{0,200}", tail in "[<>/=\"a-z &;#x0-9]{0,80}") {
        let _ = xmlform::from_xml(&text);
        let _ = xmlform::from_xml(&format!("<datamap>{tail}"));
        let _ = seabus_medium::xml::parse("f.xml", &format!("<a>{tail}"));
    }

    #[test]
    fn wire_decoder_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..120)) {
        let _ = wire::decode(&Bytes::from(bytes.clone()), &mut wire::Origins::default());
        let mut framed = b"SB\x01".to_vec();
        framed.extend_from_slice(&bytes);
        let _ = wire::decode(&Bytes::from(framed), &mut wire::Origins::default());
    }

    #[test]
    fn pattern_fast_paths_agree_with_segment_matching(
        pat in proptest::collection::vec(prop_oneof!["a", "b", "c", "\\*", "\\*\\*"], 1..5),
        topic in proptest::collection::vec(prop_oneof!["a", "b", "c", "ab"], 1..6),
    ) {
        let p = Pattern::new(&pat.join(".")).unwrap();
        let t = topic.join(".");
        // captures() always goes segment by segment
        prop_assert_eq!(p.matches(&t), p.captures(&t).is_some(), "{} vs {}", p, t);
    }

    #[test]
    fn duplicate_detection_agrees_with_a_model(seqs in proptest::collection::vec(1u64..3000, 1..400)) {
        let mut d = Dedup::new();
        let mut seen = BTreeSet::new();
        let mut highest = 0u64;
        for s in seqs {
            let expected = if highest >= WINDOW && s <= highest - WINDOW {
                Seen::Late
            } else if seen.contains(&s) {
                Seen::Duplicate
            } else {
                Seen::New
            };
            prop_assert_eq!(d.check_raw(7, s), expected, "seq {}", s);
            if expected == Seen::New {
                seen.insert(s);
                highest = highest.max(s);
            }
        }
    }
}
