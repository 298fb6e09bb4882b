//! Properties of the MAVLink medium's frame reading that every input must keep.

use seabus_medium_mavlink::Dialect;
use seabus_medium_mavlink::frame::{self, Item, StreamReader};

/// What reading found: the good frames (their bytes), the refusals counted (their kinds), the
/// bytes dropped, and the bytes left waiting for more.
#[derive(Debug, PartialEq)]
struct Found {
    frames: Vec<Vec<u8>>,
    refused: Vec<&'static str>,
    dropped: usize,
    pending: usize,
}

impl Found {
    fn new() -> Found {
        Found {
            frames: Vec::new(),
            refused: Vec::new(),
            dropped: 0,
            pending: 0,
        }
    }

    fn take(&mut self, item: Item, len: usize) {
        match item {
            Item::Frame(f) => {
                assert_eq!(f.bytes().len(), f.len, "a frame's bytes are its length");
                self.frames.push(f.bytes().to_vec());
            }
            Item::Rejected(e, n, counted) => {
                assert!(n >= 1, "a refusal skips nothing: {e}");
                assert!(
                    e.offset().is_some_and(|o| o < len),
                    "offset past the input: {e}"
                );
                self.dropped += n;
                if counted {
                    self.refused.push(e.kind());
                }
            }
        }
    }
}

fn as_datagram(dialect: Dialect, data: &[u8]) -> Found {
    let mut found = Found::new();
    frame::datagram(dialect, data, |item| found.take(item, data.len()));
    found
}

fn as_stream(dialect: Dialect, data: &[u8], chunk: usize) -> Found {
    let mut found = Found::new();
    let mut reader = StreamReader::default();
    for piece in data.chunks(chunk) {
        // offsets are in the reader's buffer, which never holds more than what came
        reader.push(dialect, piece, |item| found.take(item, data.len() + 1));
    }
    found.pending = reader.pending();
    found
}

/// MAVLink frames: any bytes read as good frames and refusals (each skipping at least a byte, every
/// byte a frame's or dropped) without a panic, as a datagram and as a stream, and a stream reads
/// the same however its bytes come; every good frame decodes or is refused for its payload, and a
/// decoded message encodes back to a frame that reads as one and decodes to the same fields. True
/// when `data` holds a good frame.
pub fn mavlink_frames(data: &[u8]) -> bool {
    use mavlink::{MavHeader, MavlinkVersion};
    let dialect = if data.first().is_some_and(|b| b & 1 == 1) {
        Dialect::Common
    } else {
        Dialect::ArduPilotMega
    };
    let whole = as_datagram(dialect, data);
    let framed: usize = whole.frames.iter().map(Vec::len).sum();
    assert_eq!(
        framed + whole.dropped,
        data.len(),
        "bytes neither framed nor dropped"
    );
    let stream = as_stream(dialect, data, data.len().max(1));
    let framed: usize = stream.frames.iter().map(Vec::len).sum();
    assert_eq!(
        framed + stream.dropped + stream.pending,
        data.len(),
        "bytes of a stream neither framed, dropped nor waiting"
    );
    for chunk in [1, 3, 64] {
        assert_eq!(
            as_stream(dialect, data, chunk),
            stream,
            "read in pieces of {chunk} bytes"
        );
    }
    for bytes in &whole.frames {
        let raw = &frame_of(dialect, bytes).raw;
        let Ok((name, map)) = dialect.decode(raw) else {
            continue;
        };
        let header = MavHeader {
            system_id: raw.system_id(),
            component_id: raw.component_id(),
            sequence: raw.sequence(),
        };
        // MAVLink 2 carries every field (MAVLink 1 frames leave extensions out)
        let again = dialect
            .encode(MavlinkVersion::V2, header, name, &map)
            .unwrap_or_else(|e| panic!("{name} {map} does not encode: {e}"));
        let back = frame_of(dialect, &again);
        assert_eq!(back.len, again.len(), "{name} encodes to one frame");
        let (name2, map2) = dialect
            .decode(&back.raw)
            .expect("an encoded message decodes");
        assert_eq!(
            (name2, &map2),
            (name, &map),
            "{name} decodes to other fields"
        );
        if raw.version() == MavlinkVersion::V1 {
            let v1 = dialect
                .encode(MavlinkVersion::V1, header, name, &map)
                .unwrap_or_else(|e| panic!("{name} does not encode in MAVLink 1: {e}"));
            assert_eq!(frame_of(dialect, &v1).len, v1.len());
        }
    }
    !whole.frames.is_empty()
}

/// The one good frame `bytes` is.
fn frame_of(dialect: Dialect, bytes: &[u8]) -> frame::Frame {
    match frame::read(dialect, bytes, 0, frame::End::Datagram) {
        frame::Read::Frame(f) => f,
        _ => panic!("not a good frame: {bytes:02x?}"),
    }
}
