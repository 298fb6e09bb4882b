//! Fuzzes the stream framer of serial media (NMEA, lines, COBS, SLIP): any byte stream is framed
//! without a panic and within the maximum frame length, cutting the stream into chunks changes
//! nothing, every NMEA sentence handed out carries a correct checksum, and every frame handed out
//! encodes back to bytes that a fresh framer reads as the same frame.
//!
//! Input: the first byte picks the framing (`b % 4`: NMEA, lines, COBS, SLIP) and the checksum
//! policy (`b / 4 % 3`: require, allow-missing, ignore), the next two the maximum frame length
//! (little-endian, at least 8); the rest is the stream.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_medium::serial::framing::{ChecksumPolicy, Framer, Framing, Output, check_nmea, encode};

/// The framing, checksum policy, maximum frame length and stream an input describes.
fn setup(data: &[u8]) -> Option<(Framing, ChecksumPolicy, usize, &[u8])> {
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
fn pieces(stream: &[u8]) -> Vec<&[u8]> {
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
fn run<'a>(
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
fn check_frame(framing: Framing, policy: ChecksumPolicy, max: usize, frame: &[u8]) {
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
            assert!(!frame.is_empty() && !frame.contains(&b'\n'));
            assert!(frame.len() <= max, "line of {} bytes", frame.len());
        }
        // a COBS frame of at most `max` bytes decodes to fewer bytes
        Framing::Cobs => assert!(frame.len() < max, "COBS frame of {} bytes", frame.len()),
        Framing::Slip => {
            assert!(!frame.is_empty());
            assert!(frame.len() <= max, "SLIP frame of {} bytes", frame.len());
        }
    }
    let wire = encode(framing, frame).expect("a frame handed out encodes");
    let back = run(
        framing,
        ChecksumPolicy::Require,
        wire.len(),
        [wire.as_slice()],
    );
    assert_eq!(back, [Ok(frame.to_vec())], "round trip via {wire:?}");
}

fuzz_target!(|data: &[u8]| {
    let Some((framing, policy, max, stream)) = setup(data) else {
        return;
    };
    let whole = run(framing, policy, max, [stream]);
    let chunked = run(framing, policy, max, pieces(stream));
    assert_eq!(chunked, whole, "chunking changed the output");
    let mut last = 0;
    for out in &whole {
        match out {
            Ok(frame) => check_frame(framing, policy, max, frame),
            Err(r) => {
                assert!(r.offset >= last && r.offset < stream.len() as u64);
                last = r.offset;
            }
        }
    }
});
