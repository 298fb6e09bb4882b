//! Properties of the LCM medium's packets, types and codec that every input must keep.

use seabus_medium_lcm::codec;
use seabus_medium_lcm::reassembly::{Reassembler, Step};
use seabus_medium_lcm::types::{MemberType, ResolvedTypes, Size, TypeSet};
use seabus_medium_lcm::wire::{self as lcm_wire, Packet};
use std::sync::OnceLock;

/// The `.lcm` type reader: any text is read or refused without a panic, every refusal names a
/// place inside the text, and a set that reads and resolves gives every struct a fingerprint by
/// which it is found again, member types that are all in the set, and variable array sizes that
/// name earlier single integer members. True when `data` is UTF-8 text that reads and resolves.
pub fn lcm_types(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let lines = text.split('\n').count();
    let check_place = |e: &seabus_medium::xml::FileError| {
        assert_eq!(&*e.pos.file, "fuzz.lcm", "{e}");
        assert!(
            e.pos.line >= 1 && e.pos.line as usize <= lines && e.pos.col >= 1,
            "{e} is outside a text of {lines} lines"
        );
    };
    let mut set = TypeSet::new();
    if let Err(e) = set.add_text("fuzz.lcm", text) {
        check_place(&e);
        assert!(set.is_empty(), "a refused file added structs");
        return false;
    }
    let read = set.len();
    let types = match set.resolve() {
        Ok(types) => types,
        Err(e) => {
            check_place(&e);
            return false;
        }
    };
    assert_eq!(types.len(), read, "resolving changed the number of structs");
    for s in types.iter() {
        let found = types.get(s.full_name()).map(|t| t.full_name());
        assert_eq!(found, Some(s.full_name()), "lookup by name");
        assert!(
            types
                .with_fingerprint(s.fingerprint())
                .any(|t| t.full_name() == s.full_name()),
            "`{}` is not found by its fingerprint",
            s.full_name()
        );
        for (i, m) in s.members().iter().enumerate() {
            if let MemberType::Struct(name) = &m.ty {
                assert!(types.get(name).is_some(), "member type `{name}` is unknown");
            }
            for d in &m.dims {
                match d.size {
                    Size::Fixed(n) => assert!(n >= 1, "array size {n}"),
                    Size::Member(j) => {
                        assert!(j < i, "`{}` is sized by a later member", m.name);
                        let sizer = &s.members()[j];
                        assert!(
                            sizer.dims.is_empty()
                                && matches!(sizer.ty, MemberType::Primitive(p) if p.is_integer()),
                            "`{}` is sized by `{}`, not a single integer",
                            m.name,
                            sizer.name
                        );
                    }
                }
            }
        }
    }
    true
}

/// LCM packets and their reassembly: the input is a series of datagrams, each a u16 big-endian
/// length and its bytes, from one of two senders (the length's top bit). Every datagram parses or is
/// refused without a panic; a short message re-encodes to the same datagram; fragments go into a
/// reassembler with a small memory cap, which never holds more than the cap, and a message it
/// completes has the size its fragments announced. True when some datagram parsed.
pub fn lcm_packets(data: &[u8]) -> bool {
    use std::net::SocketAddr;
    use std::time::{Duration, Instant};
    const CAP: usize = 1 << 20;
    let mut r = Reassembler::new(Duration::from_secs(1), CAP);
    let start = Instant::now();
    let mut dropped = Vec::new();
    let mut parsed = false;
    let mut rest = data;
    let mut n = 0u64;
    while rest.len() >= 2 {
        let head = u16::from_be_bytes([rest[0], rest[1]]);
        let len = usize::from(head & 0x7fff).min(rest.len() - 2);
        let datagram = &rest[2..2 + len];
        rest = &rest[2 + len..];
        let sender = SocketAddr::from(([127, 0, 0, 1], if head & 0x8000 != 0 { 2 } else { 1 }));
        n += 1;
        let now = start + Duration::from_millis(n * 100);
        match lcm_wire::parse(datagram) {
            Err(e) => assert!(
                e.offset().is_some_and(|o| o <= datagram.len()),
                "error offset past the datagram"
            ),
            Ok(Packet::Short {
                seq,
                channel,
                payload,
            }) => {
                parsed = true;
                let again =
                    lcm_wire::encode(seq, channel, payload).expect("a parsed message encodes");
                if lcm_wire::is_short(channel, payload.len()) {
                    assert_eq!(again, vec![datagram.to_vec()], "short message re-encodes");
                }
            }
            Ok(Packet::Fragment(f)) => {
                parsed = true;
                if let Step::Complete { payload, .. } = r.fragment(now, sender, &f, &mut dropped) {
                    assert_eq!(payload.len(), f.msg_size as usize, "completed size");
                }
                assert!(r.held_bytes() <= CAP, "reassembly over its memory cap");
                r.expire(now, &mut dropped);
            }
        }
    }
    r.expire(start + Duration::from_secs(3600), &mut dropped);
    assert_eq!((r.pending(), r.held_bytes()), (0, 0), "everything expires");
    parsed
}

/// The LCM types the codec property decodes against: every primitive, fixed, variable and
/// two-dimensional arrays, byte vectors and matrices, a struct that encodes to nothing, and
/// recursive types (one directly, two through each other).
pub const LCM_CODEC_TYPES: &str = "package fz;\n\
    struct point_t { double x; float y; int8_t a; int16_t b; int32_t c; int64_t d; byte e;\n\
                     boolean f; string s; }\n\
    struct node_t { int8_t n; node_t children[n]; string name; }\n\
    struct empty_t { }\n\
    struct all_t {\n\
        byte raw[3]; int8_t n; byte blob[n]; int16_t rows; int64_t cols;\n\
        float grid[rows][cols]; point_t pts[2]; string names[n]; boolean flags[n][2];\n\
        byte planes[2][n]; empty_t nothing[n][n]; node_t tree;\n\
    }\n\
    struct even_t { int8_t n; odd_t next[n]; }\n\
    struct odd_t { int16_t n; even_t next[n]; byte tag; }\n";

/// The structs of [`LCM_CODEC_TYPES`] an input picks from, by full name.
pub const LCM_CODEC_PICKS: [&str; 5] = [
    "fz.all_t",
    "fz.node_t",
    "fz.point_t",
    "fz.even_t",
    "fz.empty_t",
];

/// [`LCM_CODEC_TYPES`], read once.
fn lcm_codec_types() -> &'static ResolvedTypes {
    static TYPES: OnceLock<ResolvedTypes> = OnceLock::new();
    TYPES.get_or_init(|| {
        let mut set = TypeSet::new();
        set.add_text("fuzz.lcm", LCM_CODEC_TYPES)
            .unwrap_or_else(|e| panic!("the codec's types do not read: {e}"));
        set.resolve()
            .unwrap_or_else(|e| panic!("the codec's types do not resolve: {e}"))
    })
}

/// The LCM message codec: any bytes decode or are refused without a panic, and every message that
/// decodes encodes back to the same bytes (but for any after its end).
///
/// Input: the first byte picks the type (`b % 5` in [`LCM_CODEC_PICKS`]); when below 0x80 the
/// message is that type's fingerprint followed by the rest of the input, else the rest of the
/// input alone (its own fingerprint, usually wrong). True when the message decodes.
pub fn lcm_codec(data: &[u8]) -> bool {
    let Some((&sel, rest)) = data.split_first() else {
        return false;
    };
    let types = lcm_codec_types();
    let name = LCM_CODEC_PICKS[usize::from(sel) % LCM_CODEC_PICKS.len()];
    let ty = types
        .get(name)
        .unwrap_or_else(|| panic!("no struct {name}"));
    let message = if sel < 0x80 {
        let mut m = ty.fingerprint().to_be_bytes().to_vec();
        m.extend_from_slice(rest);
        m
    } else {
        rest.to_vec()
    };
    let map = match codec::decode(types, ty, &message) {
        Ok((map, lenient)) if lenient.is_exact() => map,
        Ok((map, first)) => {
            // read as liblcm reads it: encoded again, its booleans and strings are the bytes
            // they were, nothing follows it, and it reads the same
            let bytes = codec::encode(types, ty, &map)
                .unwrap_or_else(|e| panic!("a decoded {name} does not encode: {e}"));
            let (again, lenient) = codec::decode(types, ty, &bytes)
                .unwrap_or_else(|e| panic!("a re-encoded {name} does not decode: {e}"));
            assert!(
                lenient.trailing == 0
                    && (lenient.bools, lenient.first_bool) == (first.bools, first.first_bool)
                    && lenient.strings == first.strings,
                "{name} re-encoded: {lenient:?} after {first:?}"
            );
            assert!(again == map, "{name} re-encoded reads otherwise");
            assert!(
                message.get(..first.end) == Some(&bytes[..]),
                "{name} re-encoded is not the bytes of the message it was read from"
            );
            return true;
        }
        Err(e) => {
            assert!(!e.to_string().is_empty(), "an error without a message");
            return false;
        }
    };
    let bytes = codec::encode(types, ty, &map)
        .unwrap_or_else(|e| panic!("a decoded {name} does not encode: {e}"));
    assert!(
        bytes == message,
        "{name} decodes and encodes to other bytes"
    );
    true
}
