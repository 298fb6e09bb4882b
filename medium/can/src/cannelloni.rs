//! cannelloni: CAN frames over UDP between two hosts (the `cannelloni` program's format), read by
//! [`decode`] without ever panicking and written by [`encode`].
//!
//! All numbers are big-endian. A packet is a header — version (2), operation (0: data), sequence
//! number (one byte, counting packets), frame count (two bytes) — and the frames, each: the Linux
//! `can_id` (four bytes: the identifier, with 0x80000000 for an extended one, 0x40000000 for a
//! remote frame, 0x20000000 for an error frame), the length (one byte; 0x80 set for CAN FD, then a
//! byte of FD flags: 0x01 bit-rate switch, 0x02 error-state indicator; other bits, such as the
//! 0x04 newer Linux kernels set on every FD frame, are ignored), and the data (`len & 0x7F` bytes;
//! none for a remote frame, whose length is the requested length).

use super::frame::{CanFrame, FrameKind, LINUX_EFF, LINUX_ERR, LINUX_RTR};
use seabus_medium::WireError;

/// The protocol version.
pub const VERSION: u8 = 2;
/// The data operation.
pub const OP_DATA: u8 = 0;
/// The header's length.
pub const HEADER: usize = 5;
/// The default UDP port.
pub const DEFAULT_PORT: u16 = 20_000;
/// Extended identifier flag of the Linux `can_id`.
pub const EFF: u32 = LINUX_EFF;
/// Remote frame flag.
pub const RTR: u32 = LINUX_RTR;
/// Error frame flag.
pub const ERR: u32 = LINUX_ERR;
/// The CAN FD bit of the length byte.
pub const FD_LEN: u8 = 0x80;
/// Bit-rate switch.
pub const BRS: u8 = 0x01;
/// Error-state indicator.
pub const ESI: u8 = 0x02;

fn bad(offset: usize, reason: &'static str, what: impl Into<String>) -> WireError {
    WireError::at(offset, reason, what)
}

/// A packet read: its sequence number and frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    /// The sender's packet counter.
    pub seq: u8,
    /// The frames, in order.
    pub frames: Vec<CanFrame>,
}

/// Reads a packet. Frames up to a damaged one are not returned: the whole packet is refused.
pub fn decode(d: &[u8]) -> Result<Packet, WireError> {
    if d.len() < HEADER {
        return Err(bad(
            d.len(),
            "cannelloni-short",
            format!(
                "a packet of {} bytes is shorter than its 5-byte header",
                d.len()
            ),
        ));
    }
    if d[0] != VERSION {
        return Err(bad(
            0,
            "cannelloni-version",
            format!("version {} (expected {VERSION})", d[0]),
        ));
    }
    if d[1] != OP_DATA {
        return Err(bad(
            1,
            "cannelloni-operation",
            format!("operation {} (expected 0, data)", d[1]),
        ));
    }
    let seq = d[2];
    let count = usize::from(u16::from_be_bytes([d[3], d[4]]));
    // each frame takes at least 5 bytes: a count past what the packet can hold is a lie
    if count > (d.len() - HEADER) / 5 {
        return Err(bad(
            3,
            "cannelloni-count",
            format!(
                "{count} frames cannot fit in the {} bytes after the header",
                d.len() - HEADER
            ),
        ));
    }
    let mut frames = Vec::with_capacity(count);
    let mut at = HEADER;
    for _ in 0..count {
        let (frame, next) = decode_frame(d, at)?;
        frames.push(frame);
        at = next;
    }
    if at != d.len() {
        return Err(bad(
            at,
            "cannelloni-trailing",
            format!(
                "{} bytes after the {count} frames the header counts",
                d.len() - at
            ),
        ));
    }
    Ok(Packet { seq, frames })
}

fn decode_frame(d: &[u8], start: usize) -> Result<(CanFrame, usize), WireError> {
    let short = |at| bad(at, "cannelloni-short", "the packet ends inside a frame");
    let head = d.get(start..start + 5).ok_or_else(|| short(d.len()))?;
    let can_id = u32::from_be_bytes([head[0], head[1], head[2], head[3]]);
    let len_byte = head[4];
    let len = usize::from(len_byte & !FD_LEN);
    let mut at = start + 5;
    let flags = if len_byte & FD_LEN != 0 {
        let f = *d.get(at).ok_or_else(|| short(d.len()))?;
        at += 1;
        Some(f)
    } else {
        None
    };
    // a remote frame's length is the one it asks for: it carries no data
    let data_len = if can_id & RTR != 0 && can_id & ERR == 0 {
        0
    } else {
        len
    };
    let data = d.get(at..at + data_len).ok_or_else(|| short(d.len()))?;
    let frame = CanFrame::from_linux(can_id, len, data, flags)
        .map_err(|e| bad(start, "cannelloni-bad-frame", e))?;
    Ok((frame, at + data_len))
}

/// Appends one frame.
fn encode_frame(f: &CanFrame, out: &mut Vec<u8>) {
    let len = match f.kind() {
        FrameKind::Remote { dlc } => dlc,
        _ => f.payload().len() as u8,
    };
    out.extend_from_slice(&f.linux_id().to_be_bytes());
    if f.is_fd() {
        out.push(len | FD_LEN);
        out.push((u8::from(f.brs()) * BRS) | (u8::from(f.esi()) * ESI));
    } else {
        out.push(len);
    }
    if !matches!(f.kind(), FrameKind::Remote { .. }) {
        out.extend_from_slice(f.payload());
    }
}

/// The packet numbered `seq` carrying `frames` (at most 65535 of them).
pub fn encode(seq: u8, frames: &[CanFrame]) -> Vec<u8> {
    let count = frames.len().min(usize::from(u16::MAX));
    let mut out = Vec::with_capacity(HEADER + 14 * count);
    out.extend_from_slice(&[VERSION, OP_DATA, seq]);
    out.extend_from_slice(&(count as u16).to_be_bytes());
    for f in &frames[..count] {
        encode_frame(f, &mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Vectors written from the format notes, byte by byte.
    fn vectors() -> Vec<(Vec<u8>, Packet)> {
        vec![
            (
                // one standard frame 0x123 [DE AD]
                vec![2, 0, 7, 0, 1, 0x00, 0x00, 0x01, 0x23, 2, 0xDE, 0xAD],
                Packet {
                    seq: 7,
                    frames: vec![CanFrame::data(0x123, false, &[0xDE, 0xAD]).unwrap()],
                },
            ),
            (
                // extended 0x18FF50E5 [AA], remote 0x7FF asking 4, FD ext 0x10 BRS+ESI 12 bytes
                [
                    &[2u8, 0, 255, 0, 3][..],
                    &[0x98, 0xFF, 0x50, 0xE5, 1, 0xAA],
                    &[0x40, 0x00, 0x07, 0xFF, 4],
                    &[0x80, 0x00, 0x00, 0x10, 0x8C, 0x03],
                    &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12],
                ]
                .concat(),
                Packet {
                    seq: 255,
                    frames: vec![
                        CanFrame::data(0x18FF_50E5, true, &[0xAA]).unwrap(),
                        CanFrame::remote(0x7FF, false, 4).unwrap(),
                        CanFrame::fd(0x10, true, &(1..=12).collect::<Vec<u8>>(), true, true)
                            .unwrap(),
                    ],
                },
            ),
            (
                // an error frame: class 0x04 (controller), detail bytes
                vec![
                    2, 0, 0, 0, 1, 0x20, 0x00, 0x00, 0x04, 8, 0, 4, 0, 0, 0, 0, 0, 0,
                ],
                Packet {
                    seq: 0,
                    frames: vec![CanFrame::error(0x4, &[0, 4, 0, 0, 0, 0, 0, 0])],
                },
            ),
            (
                vec![2, 0, 1, 0, 0],
                Packet {
                    seq: 1,
                    frames: vec![],
                },
            ),
        ]
    }

    #[test]
    fn packets_read_and_write_as_the_notes_say() {
        for (bytes, packet) in vectors() {
            assert_eq!(decode(&bytes).unwrap(), packet, "{bytes:02x?}");
            assert_eq!(encode(packet.seq, &packet.frames), bytes);
        }
    }

    #[test]
    fn damaged_packets_say_where() {
        let err = |d: &[u8]| decode(d).unwrap_err();
        assert_eq!(
            err(&[2, 0, 0]).to_string(),
            "byte 3: a packet of 3 bytes is shorter than its 5-byte header"
        );
        assert_eq!(err(&[1, 0, 0, 0, 0]).kind(), "cannelloni-version");
        assert_eq!(err(&[2, 1, 0, 0, 0]).kind(), "cannelloni-operation");
        assert_eq!(
            err(&[2, 0, 0, 0xFF, 0xFF, 0, 0, 0, 1, 0]).to_string(),
            "byte 3: 65535 frames cannot fit in the 5 bytes after the header"
        );
        assert_eq!(
            err(&[2, 0, 0, 0, 1, 0, 0, 1, 0x23, 3, 1]).to_string(),
            "byte 11: the packet ends inside a frame"
        );
        assert_eq!(
            err(&[2, 0, 0, 0, 1, 0, 0, 0x08, 0x00, 0]).to_string(),
            "byte 5: identifier 0x800 without the extended flag"
        );
        assert_eq!(
            err(&[2, 0, 0, 0, 1, 0, 0, 1, 0x23, 9, 0, 0, 0, 0, 0, 0, 0, 0, 0]).kind(),
            "cannelloni-bad-frame"
        );
        assert_eq!(
            err(&[2, 0, 0, 0, 1, 0, 0, 1, 0x23, 0, 9]).to_string(),
            "byte 10: 1 bytes after the 1 frames the header counts"
        );
    }
}
