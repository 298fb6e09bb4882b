//! The slcan (Lawicel) ASCII protocol of serial CAN adapters such as the CANable: lines ending in
//! CR, read by [`Lines`] and parsed by [`parse_line`] without ever panicking, and written by
//! [`encode_frame`] and [`Command::line`].
//!
//! ```text
//! t1232DEAD        standard data frame: id 123, 2 bytes DE AD
//! T18FF50E51AA     extended data frame
//! r1230 / R18FF50E52   remote frames (the digit is the requested length code)
//! d / D, b / B     CAN FD without / with bit-rate switch; length codes 9–F = 12 … 64 bytes
//! t1232DEADEA60    … followed by 4 hex digits: the adapter's timestamp (ms, wrapping at 60 s)
//! S6  O  L  C      bitrate 500 kbit/s, open, open listen-only, close; Z1 timestamps on
//! V  N  F          version, serial number, status flags
//! CR / BEL         the adapter's "done" / "refused"; z / Z after a frame it sent (some firmwares)
//! ```

use super::frame::{CanFrame, DLC_LEN, FrameError, MAX_CLASSIC};
use seabus_medium::WireError;

/// Longest line read: an extended FD frame of 64 bytes with a timestamp is 143 characters.
pub const MAX_LINE: usize = 160;

/// The classic bit rates and their `S` codes (S7 is 750 kbit/s and S9 83.3 kbit/s on the CANable
/// firmware; see [`bitrate_code`]).
pub const BITRATES: [(u32, u8); 9] = [
    (10_000, 0),
    (20_000, 1),
    (50_000, 2),
    (100_000, 3),
    (125_000, 4),
    (250_000, 5),
    (500_000, 6),
    (800_000, 7),
    (1_000_000, 8),
];

/// The CAN FD data bit rates and their `Y` codes (CANable 2 firmware).
pub const DATA_BITRATES: [(u32, u8); 2] = [(2_000_000, 2), (5_000_000, 5)];

/// Which firmware an adapter runs: they differ in a few bit-rate codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Firmware {
    /// The original Lawicel codes.
    #[default]
    Lawicel,
    /// The CANable (slcan) firmware: S7 = 750 kbit/s, S9 = 83.3 kbit/s.
    Canable,
}

/// The `S` code of a classic bit rate on `firmware`.
pub fn bitrate_code(bitrate: u32, firmware: Firmware) -> Result<u8, String> {
    let canable = [(750_000, 7), (83_333, 9)];
    let found = match firmware {
        Firmware::Lawicel => BITRATES.iter().find(|(b, _)| *b == bitrate),
        Firmware::Canable => canable
            .iter()
            .chain(BITRATES.iter().filter(|(_, c)| *c != 7))
            .find(|(b, _)| *b == bitrate),
    };
    found.map(|(_, c)| *c).ok_or_else(|| {
        let list = match firmware {
            Firmware::Lawicel => {
                "10000, 20000, 50000, 100000, 125000, 250000, 500000, 800000, 1000000"
            }
            Firmware::Canable => {
                "10000, 20000, 50000, 83333, 100000, 125000, 250000, 500000, 750000, 1000000"
            }
        };
        format!("{bitrate} bit/s has no slcan code on this firmware; use one of {list}")
    })
}

/// The bit rate of an `S` code on `firmware`.
pub fn bitrate_of(code: u8, firmware: Firmware) -> Option<u32> {
    match (firmware, code) {
        (Firmware::Canable, 7) => Some(750_000),
        (Firmware::Canable, 9) => Some(83_333),
        _ => BITRATES.iter().find(|(_, c)| *c == code).map(|(b, _)| *b),
    }
}

/// A command line (host to adapter) or a reply an adapter sends that is not a frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `Sn`: the classic bit rate code.
    Bitrate(u8),
    /// `Yn`: the CAN FD data bit rate code.
    DataBitrate(u8),
    /// `O`: open the channel.
    Open,
    /// `L`: open listen-only.
    ListenOnly,
    /// `C`: close the channel.
    Close,
    /// `Z0` / `Z1`: timestamps off or on.
    Timestamps(bool),
    /// `V` (a question) or `Vxxxx` (the adapter's answer).
    Version(String),
    /// `N` or `Nxxxx`: serial number.
    Serial(String),
    /// `F` or `Fxx`: status flags.
    Status(String),
    /// An empty line: a CR alone, the adapter's "done" (hosts send one to flush).
    Empty,
    /// BEL: the adapter refused the last command.
    Refused,
    /// `z` / `Z`: the adapter sent a standard / extended frame (some firmwares).
    Sent,
    /// Any other command letter, with what follows it.
    Other(char, String),
}

impl Command {
    /// The line that sends this command, CR included.
    pub fn line(&self) -> Vec<u8> {
        let text = match self {
            Command::Bitrate(n) => format!("S{n}"),
            Command::DataBitrate(n) => format!("Y{n}"),
            Command::Open => "O".into(),
            Command::ListenOnly => "L".into(),
            Command::Close => "C".into(),
            Command::Timestamps(on) => format!("Z{}", u8::from(*on)),
            Command::Version(v) => format!("V{v}"),
            Command::Serial(v) => format!("N{v}"),
            Command::Status(v) => format!("F{v}"),
            Command::Empty => String::new(),
            Command::Refused => return vec![0x07],
            Command::Sent => "z".into(),
            Command::Other(c, rest) => format!("{c}{rest}"),
        };
        let mut v = text.into_bytes();
        v.push(b'\r');
        v
    }
}

/// One line read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// A frame, with the adapter's timestamp (ms) when it sends them.
    Frame(CanFrame, Option<u16>),
    /// A command or a reply.
    Command(Command),
}

fn bad(reason: &'static str, what: impl Into<String>) -> WireError {
    WireError::new(reason, what)
}

fn hex_digit(b: u8, at: usize) -> Result<u8, WireError> {
    (b as char).to_digit(16).map(|d| d as u8).ok_or_else(|| {
        bad(
            "slcan-bad-hex",
            format!("byte {at}: {:?} is not a hex digit", b as char),
        )
    })
}

fn hex_u32(s: &[u8], at: usize) -> Result<u32, WireError> {
    s.iter().enumerate().try_fold(0u32, |acc, (i, &b)| {
        Ok((acc << 4) | u32::from(hex_digit(b, at + i)?))
    })
}

/// Parses one line, without its CR.
pub fn parse_line(line: &[u8]) -> Result<Line, WireError> {
    let Some(&first) = line.first() else {
        return Ok(Line::Command(Command::Empty));
    };
    let text = || String::from_utf8_lossy(&line[1..]).into_owned();
    let frame = |extended: bool, kind: u8| parse_frame(line, extended, kind);
    match first {
        b't' | b'r' | b'd' | b'b' => frame(false, first),
        b'T' | b'R' | b'D' | b'B' => frame(true, first.to_ascii_lowercase()),
        0x07 => Ok(Line::Command(Command::Refused)),
        _ => {
            let arg = &line[1..];
            let code = || -> Result<u8, WireError> {
                match arg {
                    [d] => hex_digit(*d, 1),
                    _ => Err(bad(
                        "slcan-bad-command",
                        format!("`{}` needs one digit", first as char),
                    )),
                }
            };
            let cmd = match first {
                b'S' => Command::Bitrate(code()?),
                b'Y' => Command::DataBitrate(code()?),
                b'O' if arg.is_empty() => Command::Open,
                b'L' if arg.is_empty() => Command::ListenOnly,
                b'C' if arg.is_empty() => Command::Close,
                b'Z' if arg.is_empty() => Command::Sent,
                b'z' if arg.is_empty() => Command::Sent,
                b'Z' => Command::Timestamps(code()? != 0),
                b'V' => Command::Version(text()),
                b'N' => Command::Serial(text()),
                b'F' => Command::Status(text()),
                c if c.is_ascii_alphabetic() => Command::Other(c as char, text()),
                c => {
                    return Err(bad(
                        "slcan-bad-command",
                        format!("byte 0: {:?} starts no slcan line", c as char),
                    ));
                }
            };
            Ok(Line::Command(cmd))
        }
    }
}

/// Parses a frame line: `kind` is `t`, `r`, `d` or `b`.
fn parse_frame(line: &[u8], extended: bool, kind: u8) -> Result<Line, WireError> {
    let id_len = if extended { 8 } else { 3 };
    let short = || {
        bad(
            "slcan-short-frame",
            format!(
                "a {} frame line is {} characters, too short",
                line[0] as char,
                line.len()
            ),
        )
    };
    if line.len() < 2 + id_len {
        return Err(short());
    }
    let id = hex_u32(&line[1..1 + id_len], 1)?;
    let dlc_at = 1 + id_len;
    let dlc = hex_digit(line[dlc_at], dlc_at)?;
    let fd = matches!(kind, b'd' | b'b');
    if !fd && dlc > 8 {
        return Err(bad(
            "slcan-bad-length",
            format!("byte {dlc_at}: length code {dlc:X} is past 8 for a classic frame"),
        ));
    }
    let rest = &line[dlc_at + 1..];
    let frame_error = |e: FrameError| bad("slcan-bad-frame", e.to_string());
    let (frame, rest) = if kind == b'r' {
        (
            CanFrame::remote(id, extended, dlc).map_err(frame_error)?,
            rest,
        )
    } else {
        let len = usize::from(DLC_LEN[usize::from(dlc)]);
        if rest.len() < 2 * len {
            return Err(short());
        }
        let mut data = [0u8; 64];
        for (i, pair) in rest[..2 * len].chunks_exact(2).enumerate() {
            let at = dlc_at + 1 + 2 * i;
            data[i] = (hex_digit(pair[0], at)? << 4) | hex_digit(pair[1], at + 1)?;
        }
        let data = &data[..len];
        let frame = if fd {
            CanFrame::fd(id, extended, data, kind == b'b', false)
        } else {
            debug_assert!(len <= MAX_CLASSIC);
            CanFrame::data(id, extended, data)
        }
        .map_err(frame_error)?;
        (frame, &rest[2 * len..])
    };
    let time = match rest.len() {
        0 => None,
        4 => Some(hex_u32(rest, line.len() - 4)? as u16),
        n => {
            return Err(bad(
                "slcan-bad-length",
                format!(
                    "{n} characters after the data: the length code says {} bytes (a timestamp is 4 digits)",
                    frame.payload().len()
                ),
            ));
        }
    };
    Ok(Line::Frame(frame, time))
}

/// The line that sends `frame`, CR included, with a timestamp when given. Error frames have no
/// slcan form; CAN FD's error-state flag is not carried.
pub fn encode_frame(frame: &CanFrame, time_ms: Option<u16>) -> Result<Vec<u8>, String> {
    use super::frame::FrameKind;
    let letter = match (frame.kind(), frame.is_fd(), frame.brs()) {
        (FrameKind::Error, ..) => return Err("an error frame has no slcan form".into()),
        (FrameKind::Remote { .. }, ..) => b'r',
        (FrameKind::Data, false, _) => b't',
        (FrameKind::Data, true, false) => b'd',
        (FrameKind::Data, true, true) => b'b',
    };
    let letter = if frame.is_extended() {
        letter.to_ascii_uppercase()
    } else {
        letter
    };
    let mut out = Vec::with_capacity(16 + 2 * frame.payload().len());
    out.push(letter);
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let id_len = if frame.is_extended() { 8 } else { 3 };
    for i in (0..id_len).rev() {
        out.push(HEX[((frame.id() >> (4 * i)) & 0xF) as usize]);
    }
    out.push(HEX[usize::from(frame.dlc() & 0xF)]);
    for b in frame.payload() {
        out.push(HEX[usize::from(b >> 4)]);
        out.push(HEX[usize::from(b & 0xF)]);
    }
    if let Some(t) = time_ms {
        for i in (0..4).rev() {
            out.push(HEX[usize::from((t >> (4 * i)) & 0xF)]);
        }
    }
    out.push(b'\r');
    Ok(out)
}

/// A frame line (CR included) with the timestamp `time_ms` put before its CR.
pub fn with_timestamp(line: &[u8], time_ms: u16) -> Vec<u8> {
    let body = line.strip_suffix(b"\r").unwrap_or(line);
    let mut out = Vec::with_capacity(body.len() + 5);
    out.extend_from_slice(body);
    out.extend_from_slice(format!("{time_ms:04X}\r").as_bytes());
    out
}

/// Takes each line [`Lines`] finds: the line, or the byte offset where an overlong one began.
pub type LineSink<'a> = dyn FnMut(Result<&[u8], u64>) + 'a;

/// Splits a byte stream into slcan lines: at CR (an LF is ignored), and BEL as a line of its own.
/// A line longer than [`MAX_LINE`] is reported once and skipped to the next CR.
#[derive(Debug, Default)]
pub struct Lines {
    buf: Vec<u8>,
    overlong: bool,
    /// Bytes taken so far, for offsets in errors.
    offset: u64,
}

impl Lines {
    /// An empty splitter.
    pub fn new() -> Lines {
        Lines::default()
    }

    /// Takes `bytes`; calls `out` with each complete line (without CR), or with the byte offset
    /// where an overlong line started.
    pub fn push(&mut self, bytes: &[u8], out: &mut LineSink<'_>) {
        for &b in bytes {
            self.offset += 1;
            match b {
                b'\r' => {
                    if !self.overlong {
                        out(Ok(&self.buf));
                    }
                    self.buf.clear();
                    self.overlong = false;
                }
                b'\n' => {}
                0x07 => {
                    out(Ok(&[0x07]));
                }
                _ if self.overlong => {}
                _ if self.buf.len() >= MAX_LINE => {
                    self.overlong = true;
                    out(Err(self.offset - self.buf.len() as u64 - 1));
                    self.buf.clear();
                }
                _ => self.buf.push(b),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(line: &str) -> (CanFrame, Option<u16>) {
        match parse_line(line.as_bytes()) {
            Ok(Line::Frame(f, t)) => (f, t),
            other => panic!("{line}: {other:?}"),
        }
    }

    #[test]
    fn frame_lines_are_read_and_written_back() {
        let cases: [(&str, CanFrame, Option<u16>); 7] = [
            (
                "t1232DEAD",
                CanFrame::data(0x123, false, &[0xDE, 0xAD]).unwrap(),
                None,
            ),
            (
                "T18FF50E51AA",
                CanFrame::data(0x18FF_50E5, true, &[0xAA]).unwrap(),
                None,
            ),
            ("r1230", CanFrame::remote(0x123, false, 0).unwrap(), None),
            (
                "R18FF50E52",
                CanFrame::remote(0x18FF_50E5, true, 2).unwrap(),
                None,
            ),
            (
                "t0010EA60",
                CanFrame::data(1, false, &[]).unwrap(),
                Some(0xEA60),
            ),
            (
                "d7FF9000102030405060708090A0B",
                CanFrame::fd(
                    0x7FF,
                    false,
                    &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
                    false,
                    false,
                )
                .unwrap(),
                None,
            ),
            (
                "B000000010",
                CanFrame::fd(1, true, &[], true, false).unwrap(),
                None,
            ),
        ];
        for (line, want, time) in cases {
            assert_eq!(frame(line), (want.clone(), time), "{line}");
            let back = encode_frame(&want, time).unwrap();
            assert_eq!(back, format!("{line}\r").into_bytes(), "{line}");
        }
        // lower-case hex is read too
        assert_eq!(frame("t12a1ff").0.payload(), [0xFF]);
        // a 64-byte FD frame
        let long = format!("b123F{}", "AB".repeat(64));
        assert_eq!(frame(&long).0.payload().len(), 64);
    }

    #[test]
    fn commands_and_replies() {
        let cmd = |s: &str| match parse_line(s.as_bytes()) {
            Ok(Line::Command(c)) => c,
            other => panic!("{s}: {other:?}"),
        };
        assert_eq!(cmd("S6"), Command::Bitrate(6));
        assert_eq!(cmd("Y2"), Command::DataBitrate(2));
        assert_eq!(cmd("O"), Command::Open);
        assert_eq!(cmd("L"), Command::ListenOnly);
        assert_eq!(cmd("C"), Command::Close);
        assert_eq!(cmd("Z1"), Command::Timestamps(true));
        assert_eq!(cmd("Z"), Command::Sent);
        assert_eq!(cmd("z"), Command::Sent);
        assert_eq!(cmd(""), Command::Empty);
        assert_eq!(cmd("\u{7}"), Command::Refused);
        assert_eq!(cmd("V1013"), Command::Version("1013".into()));
        assert_eq!(cmd("V"), Command::Version(String::new()));
        assert_eq!(cmd("F00"), Command::Status("00".into()));
        for c in [
            Command::Bitrate(8),
            Command::Open,
            Command::Close,
            Command::Timestamps(false),
            Command::Version("1013".into()),
        ] {
            let line = c.line();
            assert_eq!(line.last(), Some(&b'\r'));
            assert_eq!(
                parse_line(&line[..line.len() - 1]).unwrap(),
                Line::Command(c)
            );
        }
    }

    #[test]
    fn bad_lines_name_the_byte() {
        let err = |s: &str| parse_line(s.as_bytes()).unwrap_err();
        assert_eq!(err("t12G0").detail(), "byte 3: 'G' is not a hex digit");
        assert_eq!(err("t12G0").kind(), "slcan-bad-hex");
        assert_eq!(
            err("t1239").detail(),
            "byte 4: length code 9 is past 8 for a classic frame"
        );
        assert_eq!(
            err("t1232DE").detail(),
            "a t frame line is 7 characters, too short"
        );
        assert_eq!(
            err("t1231DEAD").detail(),
            "2 characters after the data: the length code says 1 bytes (a timestamp is 4 digits)"
        );
        assert_eq!(err("T200000000").kind(), "slcan-bad-frame");
        assert_eq!(err("S").detail(), "`S` needs one digit");
        assert_eq!(err("#").detail(), "byte 0: '#' starts no slcan line");
    }

    #[test]
    fn lines_split_at_cr_with_bel_alone_and_overlong_ones_skipped() {
        let mut lines = Lines::new();
        let mut got: Vec<Result<Vec<u8>, u64>> = Vec::new();
        let mut take = |r: Result<&[u8], u64>| got.push(r.map(<[u8]>::to_vec));
        lines.push(b"C\rS6\r\rO\r\x07t12", &mut take);
        lines.push(b"30\r\n", &mut take);
        let long = vec![b'1'; MAX_LINE + 5];
        lines.push(b"t", &mut take);
        lines.push(&long, &mut take);
        lines.push(b"\rO\r", &mut take);
        let want: Vec<Result<Vec<u8>, u64>> = vec![
            Ok(b"C".to_vec()),
            Ok(b"S6".to_vec()),
            Ok(b"".to_vec()),
            Ok(b"O".to_vec()),
            Ok(vec![0x07]),
            Ok(b"t1230".to_vec()),
            Err(16),
            Ok(b"O".to_vec()),
        ];
        assert_eq!(got, want);
    }

    #[test]
    fn bitrates_by_firmware() {
        assert_eq!(bitrate_code(500_000, Firmware::Lawicel), Ok(6));
        assert_eq!(bitrate_code(800_000, Firmware::Lawicel), Ok(7));
        assert!(bitrate_code(750_000, Firmware::Lawicel).is_err());
        assert_eq!(bitrate_code(750_000, Firmware::Canable), Ok(7));
        assert_eq!(bitrate_code(83_333, Firmware::Canable), Ok(9));
        assert!(bitrate_code(800_000, Firmware::Canable).is_err());
        assert_eq!(bitrate_of(7, Firmware::Canable), Some(750_000));
        assert_eq!(bitrate_of(7, Firmware::Lawicel), Some(800_000));
        assert!(
            bitrate_code(300_000, Firmware::Lawicel)
                .unwrap_err()
                .contains("300000 bit/s has no slcan code")
        );
    }
}
