//! Properties of the seabus-medium codecs, framers and URLs that every input must keep. Each
//! function panics when an input breaks a property and tells whether the input was a valid one.

use bytes::Bytes;
use seabus_medium::dsaav::wire::Frame as DsaavFrame;
use seabus_medium::lcm::codec;
use seabus_medium::lcm::eventlog;
use seabus_medium::lcm::reassembly::{Reassembler, Step};
use seabus_medium::lcm::types::{MemberType, ResolvedTypes, Size, TypeSet};
use seabus_medium::lcm::wire::{self as lcm_wire, Packet};
use seabus_medium::serial::framing::{ChecksumPolicy, Framer, Framing, Output, check_nmea, encode};
use seabus_medium::udp::wire;
use seabus_medium::url::MediumUrl;
use seabus_medium::{DataMap, Medium, Value, binary, json, xmlform};
use std::sync::OnceLock;

/// The compact binary datamap decoder: any input decodes or is refused without a panic, and every
/// map it accepts encodes back to bytes that decode to the same map. True when `data` decodes.
pub fn datamap_binary(data: &[u8]) -> bool {
    let Ok(map) = binary::decode(data) else {
        return false;
    };
    let bytes = binary::encode(&map)
        .unwrap_or_else(|e| panic!("a decoded datamap has no binary form: {e}"));
    let back = binary::decode(&bytes)
        .unwrap_or_else(|e| panic!("an encoded datamap does not decode: {e}"));
    assert_eq!(back, map, "binary round trip changed the map");
    true
}

/// True when `v` is a NaN float or a list or map holding one at any depth.
fn has_nan(v: &Value) -> bool {
    match v {
        Value::Float(f) => f.is_nan(),
        Value::List(items) => items.iter().any(has_nan),
        Value::Map(map) => map_has_nan(map),
        _ => false,
    }
}

/// True when any value of `map` holds a NaN: JSON writes every NaN as `{"float": "NaN"}`, so the
/// bits of a NaN do not survive a round trip.
fn map_has_nan(map: &DataMap) -> bool {
    map.iter().any(|(_, v)| has_nan(v))
}

/// The JSON form of a datamap: any text reads or is refused without a panic, and every map it reads
/// writes back to JSON that reads as the same map (for maps without a NaN, whose bits JSON does not
/// keep). True when `data` is UTF-8 text that reads as a map.
pub fn datamap_json(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let Ok(map) = json::from_json(text) else {
        return false;
    };
    let written =
        json::to_json(&map).unwrap_or_else(|e| panic!("a read datamap has no JSON form: {e}"));
    let back =
        json::from_json(&written).unwrap_or_else(|e| panic!("written JSON does not read: {e}"));
    if !map_has_nan(&map) {
        assert_eq!(back, map, "JSON round trip changed the map: {written}");
    }
    true
}

/// The XML form of a datamap: any text reads or is refused without a panic, and every map it reads
/// writes back to XML that reads as the same map. True when `data` is UTF-8 text that reads as a
/// map.
pub fn datamap_xml(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let Ok(map) = xmlform::from_xml(text) else {
        return false;
    };
    let xml =
        xmlform::to_xml(&map).unwrap_or_else(|e| panic!("a read datamap has no XML form: {e}"));
    let back = xmlform::from_xml(&xml).unwrap_or_else(|e| panic!("written XML does not read: {e}"));
    assert_eq!(back, map, "XML round trip changed the map: {xml}");
    true
}

/// Medium URLs: any text parses or is refused without a panic, and checking a URL (scheme, options
/// and their values) never panics either; a URL that checks out also parses. True when `data` is
/// UTF-8 text that checks out as a medium URL.
pub fn medium_url(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let parsed = MediumUrl::parse(text);
    let checked = Medium::check_url(text);
    if checked.is_ok() {
        assert!(parsed.is_ok(), "a URL that checks out must parse: {text:?}");
    }
    checked.is_ok()
}

/// The framing, checksum policy, maximum frame length and stream an input describes.
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

/// The stream cut into pieces whose lengths come from the stream: each piece is `b % 17 + 1`
/// bytes long, `b` being its first byte.
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
            "the framer holds {} bytes, more than {max} and a line-ending CR",
            framer.pending()
        );
    }
    got
}

/// Checks one frame handed out: its length, its checksum (NMEA), and that it encodes back to bytes
/// a fresh framer reads as the same frame.
fn framer_check_frame(framing: Framing, policy: ChecksumPolicy, max: usize, frame: &[u8]) {
    match framing {
        Framing::Nmea => {
            assert_eq!(
                check_nmea(frame, ChecksumPolicy::Require).as_deref(),
                Ok(frame),
                "a framed sentence carries a correct checksum"
            );
            // a sentence accepted without a checksum gets `*hh` added
            let bound = if policy == ChecksumPolicy::Require {
                max
            } else {
                max + 3
            };
            assert!(frame.len() <= bound, "sentence of {} bytes", frame.len());
        }
        Framing::Lines => {
            assert!(
                !frame.is_empty() && !frame.contains(&b'\n'),
                "line {frame:?}"
            );
            assert!(frame.len() <= max, "line of {} bytes", frame.len());
        }
        // a COBS frame of at most `max` bytes decodes to fewer bytes
        Framing::Cobs => assert!(frame.len() < max, "COBS frame of {} bytes", frame.len()),
        Framing::Slip => {
            assert!(!frame.is_empty(), "empty SLIP frame");
            assert!(frame.len() <= max, "SLIP frame of {} bytes", frame.len());
        }
    }
    let wire = encode(framing, frame).unwrap_or_else(|e| panic!("{frame:?} does not encode: {e}"));
    let back = framer_run(
        framing,
        ChecksumPolicy::Require,
        wire.len(),
        [wire.as_slice()],
    );
    assert_eq!(back, [Ok(frame.to_vec())], "round trip via {wire:?}");
}

/// The stream framer of serial media (NMEA, lines, COBS, SLIP): any byte stream is framed without a
/// panic and within the maximum frame length, cutting the stream into chunks changes nothing, every
/// NMEA sentence handed out carries a correct checksum, every frame handed out encodes back to
/// bytes that a fresh framer reads as the same frame, and rejections come in stream order.
///
/// Input: the first byte picks the framing (`b % 4`: NMEA, lines, COBS, SLIP) and the checksum
/// policy (`b / 4 % 3`: require, allow-missing, ignore), the next two the maximum frame length
/// (little-endian, at least 8); the rest is the stream. True when the framer hands out at least one
/// frame.
pub fn nmea_framer(data: &[u8]) -> bool {
    let Some((framing, policy, max, stream)) = framer_setup(data) else {
        return false;
    };
    let whole = framer_run(framing, policy, max, [stream]);
    let chunked = framer_run(framing, policy, max, framer_pieces(stream));
    assert_eq!(chunked, whole, "chunking changed the output");
    let mut last = 0;
    let mut frames = 0;
    for out in &whole {
        match out {
            Ok(frame) => {
                framer_check_frame(framing, policy, max, frame);
                frames += 1;
            }
            Err(r) => {
                assert!(
                    r.offset >= last && r.offset < stream.len() as u64,
                    "rejection at {} after one at {last}, in a stream of {} bytes",
                    r.offset,
                    stream.len()
                );
                last = r.offset;
            }
        }
    }
    frames > 0
}

/// The UDP datagram decoder: any datagram decodes or is rejected without a panic, and every message
/// it accepts encodes back to a datagram that decodes to the same message. True when `data`
/// decodes.
pub fn udp_datagram(data: &[u8]) -> bool {
    let mut origins = wire::Origins::default();
    let Ok((sender, msg)) = wire::decode(&Bytes::copy_from_slice(data), &mut origins) else {
        return false;
    };
    let datagram = wire::encode(&msg, sender)
        .unwrap_or_else(|e| panic!("a decoded message does not encode: {e}"));
    let (sender2, back) = wire::decode(&datagram, &mut origins)
        .unwrap_or_else(|e| panic!("an encoded message does not decode: {e}"));
    assert_eq!(sender2, sender, "sender");
    assert_eq!(back.topic, msg.topic, "topic");
    assert_eq!(back.kind, msg.kind, "kind");
    assert_eq!(back.provenance, msg.provenance, "provenance");
    assert_eq!(back.stamp, msg.stamp, "stamp");
    assert_eq!(back.payload, msg.payload, "payload");
    true
}

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
            Err(e) => assert!(e.offset <= datagram.len(), "error offset past the datagram"),
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

/// What reading a whole LCM event log gave: its events and the damage that stopped it, if any.
type LogRead = (Vec<eventlog::OwnedEvent>, Option<eventlog::Damage>);

/// Reads every event of `reader`, at most one per byte of `len` (and one more for the end).
fn lcm_read_all<R: std::io::Read>(mut reader: eventlog::Reader<R>, len: usize) -> LogRead {
    let mut events = Vec::new();
    for _ in 0..=len {
        match reader.next_event() {
            Ok(Some(e)) => events.push(e.into_owned()),
            Ok(None) => return (events, None),
            Err(d) => {
                assert_eq!(
                    reader.next_event().err().as_ref(),
                    Some(&d),
                    "the reader repeats its damage"
                );
                return (events, Some(d));
            }
        }
    }
    panic!("more events than bytes in a log of {len} bytes");
}

/// An input that hands out a few bytes at a time (1 to 13, varying), as a pipe or socket might.
struct Trickle<'a> {
    data: &'a [u8],
    calls: usize,
}

impl std::io::Read for Trickle<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.calls += 1;
        let n = (self.calls * 7 % 13 + 1)
            .min(buf.len())
            .min(self.data.len());
        let (head, tail) = self.data.split_at(n);
        buf[..n].copy_from_slice(head);
        self.data = tail;
        Ok(n)
    }
}

/// Writes `events` with a fresh writer (numbering them from 0) and returns the log.
fn lcm_write_all(events: &[eventlog::OwnedEvent]) -> Vec<u8> {
    let mut w = eventlog::Writer::new(Vec::new());
    for e in events {
        w.write(e.timestamp, &e.channel, &e.data)
            .unwrap_or_else(|err| panic!("an event read from a log does not write: {err}"));
    }
    w.finish()
        .unwrap_or_else(|err| panic!("a log in memory does not flush: {err}"))
}

/// The LCM event-log reader and writer: any input reads without a panic, event by event, up to its
/// end or to the damage that stops it, the same whether its size is known or it arrives a few bytes
/// at a time; the damage is reported where the last whole event ends; the events read, written
/// again, are the log's bytes up to the damage (exactly, when the log numbers its events from 0),
/// and read back identically, stopping at the same damage when the damaged rest follows them. True
/// when `data` is a whole log without damage.
pub fn lcm_eventlog(data: &[u8]) -> bool {
    let (events, damage) = lcm_read_all(
        eventlog::Reader::with_size(data, data.len() as u64),
        data.len(),
    );
    let trickled = lcm_read_all(
        eventlog::Reader::new(Trickle { data, calls: 0 }),
        data.len(),
    );
    assert_eq!(trickled.0, events, "events read a few bytes at a time");
    assert_eq!(
        trickled.1.as_ref().map(|d| d.offset),
        damage.as_ref().map(|d| d.offset),
        "damage found a few bytes at a time: {:?}, size known: {damage:?}",
        trickled.1
    );
    let end: u64 = events.iter().map(|e| e.as_event().encoded_len()).sum();
    match &damage {
        Some(d) => assert_eq!(d.offset, end, "damage reported where the last event ends"),
        None => assert_eq!(end, data.len() as u64, "a clean end after every byte"),
    }
    let end = end as usize;
    let written = lcm_write_all(&events);
    let numbered = events.iter().zip(0i64..).all(|(e, n)| e.number == n);
    if numbered {
        assert_eq!(
            written,
            data[..end],
            "the events written again are the log's bytes"
        );
    }
    assert_eq!(
        written.len(),
        end,
        "the events written again take as many bytes"
    );
    let mut again = written;
    again.extend_from_slice(&data[end..]);
    let (back, back_damage) = lcm_read_all(
        eventlog::Reader::with_size(&again[..], again.len() as u64),
        again.len(),
    );
    assert_eq!(back.len(), events.len(), "events read back");
    for ((b, e), n) in back.iter().zip(&events).zip(0i64..) {
        assert_eq!(b.number, n, "event numbers count from 0");
        assert_eq!(
            (b.timestamp, &b.channel, &b.data),
            (e.timestamp, &e.channel, &e.data),
            "event {n} read back"
        );
    }
    assert_eq!(
        back_damage, damage,
        "the same damage after the events written again"
    );
    damage.is_none()
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
/// decodes encodes back to the same bytes.
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
        Ok(map) => map,
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

/// DSAAV IComms frames: any bytes decode or are refused without a panic, naming an offset inside
/// them, and a frame that decodes encodes back to the same bytes (up to its stated length). True
/// when `data` decodes.
pub fn dsaav_frame(data: &[u8]) -> bool {
    match DsaavFrame::decode(data) {
        Err(e) => {
            assert!(
                e.offset <= data.len().max(2),
                "error offset past the input: {e}"
            );
            false
        }
        Ok(frame) => {
            let again = frame.encode().expect("a decoded frame encodes");
            assert!(again.len() <= data.len(), "encoded longer than read");
            // float values keep their bits both ways, NaNs included
            assert!(
                data.get(..again.len()) == Some(again.as_slice()),
                "decoded frame encodes to other bytes"
            );
            true
        }
    }
}

/// slcan lines: any byte stream splits into lines the same whole and in pieces, every line parses
/// or is refused without a panic, a frame line's frame encodes to a line that parses to the same
/// frame and timestamp, and the frame's message form gives it back. True when some line held a
/// frame.
pub fn slcan_lines(data: &[u8]) -> bool {
    use seabus_medium::Payload;
    use seabus_medium::can::frame::CanFrame;
    use seabus_medium::can::slcan::{self, Line, Lines};
    let split = |pieces: &mut dyn Iterator<Item = &[u8]>| {
        let mut lines = Lines::new();
        let mut out: Vec<Result<Vec<u8>, u64>> = Vec::new();
        for p in pieces {
            lines.push(p, &mut |l| out.push(l.map(<[u8]>::to_vec)));
        }
        out
    };
    let whole = split(&mut std::iter::once(data));
    let bytewise = split(&mut data.chunks(3));
    assert_eq!(
        whole, bytewise,
        "lines differ when the bytes come in pieces"
    );
    let mut frames = false;
    for line in whole.into_iter().flatten() {
        assert!(line.len() <= slcan::MAX_LINE, "a line past the maximum");
        let Ok(Line::Frame(frame, time)) = slcan::parse_line(&line) else {
            continue;
        };
        frames = true;
        let encoded = slcan::encode_frame(&frame, time).expect("a parsed frame encodes");
        let again =
            slcan::parse_line(&encoded[..encoded.len() - 1]).expect("an encoded line parses");
        assert_eq!(
            again,
            Line::Frame(frame.clone(), time),
            "slcan round trip changed the frame"
        );
        let back = CanFrame::from_message(&frame.topic(), &Payload::from(frame.to_map(None)))
            .expect("a frame's message gives it back");
        assert_eq!(back, frame, "message round trip changed the frame");
    }
    frames
}

/// cannelloni packets: any bytes decode or are refused without a panic, naming an offset inside
/// them, and a packet that decodes encodes back to as many bytes, which decode to the same packet
/// (FD flag bits other than BRS and ESI are not kept). True when `data` decodes.
pub fn cannelloni_packets(data: &[u8]) -> bool {
    use seabus_medium::can::cannelloni;
    match cannelloni::decode(data) {
        Err(e) => {
            assert!(e.offset <= data.len(), "error offset past the packet: {e}");
            false
        }
        Ok(p) => {
            let again = cannelloni::encode(p.seq, &p.frames);
            assert_eq!(again.len(), data.len(), "re-encoded to another length");
            let back = cannelloni::decode(&again).expect("an encoded packet decodes");
            assert_eq!(back, p, "a decoded packet encodes to another packet");
            true
        }
    }
}

/// MOOS packets: any bytes read as a packet, as incomplete, or are refused without a panic, naming
/// an offset inside them; a packet read encodes back to the same bytes (but its compression flag,
/// which readers ignore), also when the stream is read a few bytes at a time. True when `data`
/// starts with a packet.
pub fn moos_packets(data: &[u8]) -> bool {
    use seabus_medium::moos::wire::{Read, read_packet};
    match read_packet(data) {
        Err(e) => {
            assert!(e.offset <= data.len(), "error offset past the input: {e}");
            false
        }
        Ok(Read::Incomplete(n)) => {
            assert!(n > data.len(), "incomplete, yet {n} bytes are there");
            false
        }
        Ok(Read::Packet(p, n)) => {
            let mut again = p.encode();
            assert_eq!(again.len(), n, "re-encoded to another length");
            again[8] = data[8];
            assert_eq!(
                &again[..],
                &data[..n],
                "a packet read encodes to other bytes"
            );
            // every shorter prefix is incomplete, never malformed
            for cut in [0, 8, n / 2, n - 1] {
                assert!(
                    matches!(read_packet(&data[..cut]), Ok(Read::Incomplete(_))),
                    "a prefix of {cut} bytes is not incomplete"
                );
            }
            true
        }
    }
}
