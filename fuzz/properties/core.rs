//! Properties of the seabus-medium core codecs, framers and files that every input must keep. Each
//! function panics when an input breaks a property and tells whether the input was a valid one.

use seabus_medium::eventlog;
use seabus_medium::framing::{ChecksumPolicy, Framer, Framing, Output, check_nmea, encode};
use seabus_medium::{DataMap, Value, binary, json, xmlform};

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
