//! Framing for byte streams: NMEA 0183 sentences, plain lines, COBS and SLIP frames.
//!
//! A [`Framer`] is fed bytes as they arrive, in chunks of any size, and hands out whole frames or
//! rejections, each rejection with a reason from a fixed set so that it can be counted. It never
//! panics and never holds more than its maximum frame length (and the CR of a line ending).
//!
//! NMEA framing: a sentence starts at `$` or `!` and ends at LF (a CR before it is dropped). Bytes
//! outside a sentence are garbage. A new `$`/`!` before the end means the previous sentence was cut
//! short. A sentence holds printable ASCII only, at most `max` bytes. Its checksum (`*hh`, the XOR of
//! the bytes between the start character and `*`) is checked by policy; a sentence accepted without
//! one gets its checksum added, so that every sentence handed out carries a correct `*hh`.
//!
//! A framer counts the bytes it drops ([`Framer::dropped`]): garbage outside frames, the bytes of
//! a rejected frame, the skipped part of one longer than the limit. Line endings (CR, LF) and
//! frame delimiters are never counted.

use std::fmt;

/// How a stream is cut into frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// NMEA 0183 sentences.
    Nmea,
    /// Lines ending in LF (CR LF accepted).
    Lines,
    /// COBS frames, each ended by a zero byte.
    Cobs,
    /// SLIP frames (RFC 1055).
    Slip,
}

/// Reads a framing name: `nmea`, `lines`, `cobs`, `slip`.
impl std::str::FromStr for Framing {
    type Err = ();
    fn from_str(s: &str) -> Result<Framing, ()> {
        Ok(match s {
            "nmea" => Framing::Nmea,
            "lines" | "line" => Framing::Lines,
            "cobs" => Framing::Cobs,
            "slip" => Framing::Slip,
            _ => return Err(()),
        })
    }
}

/// What to do with NMEA checksums.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChecksumPolicy {
    /// A sentence must carry a correct checksum.
    Require,
    /// A sentence without a checksum is accepted (its checksum is added); a wrong one is rejected.
    AllowMissing,
    /// Checksums are not checked (they are corrected on the way in).
    Ignore,
}

/// Reads a policy name: `require`, `allow-missing`, `ignore`.
impl std::str::FromStr for ChecksumPolicy {
    type Err = ();
    fn from_str(s: &str) -> Result<ChecksumPolicy, ()> {
        Ok(match s {
            "require" => ChecksumPolicy::Require,
            "allow-missing" => ChecksumPolicy::AllowMissing,
            "ignore" => ChecksumPolicy::Ignore,
            _ => return Err(()),
        })
    }
}

/// Why bytes were not made into a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    /// Bytes outside any sentence.
    Garbage,
    /// A frame longer than the maximum.
    TooLong,
    /// A sentence cut short by the start of another.
    Truncated,
    /// A checksum that does not match.
    BadChecksum,
    /// No checksum, where one is required.
    NoChecksum,
    /// A byte that may not appear in a sentence.
    BadChar,
    /// A frame with nothing in it.
    Empty,
    /// A COBS or SLIP frame that does not decode.
    BadEncoding,
}

impl Reject {
    /// A short, stable name for counting.
    pub fn reason(self) -> &'static str {
        match self {
            Reject::Garbage => "garbage",
            Reject::TooLong => "too-long",
            Reject::Truncated => "truncated",
            Reject::BadChecksum => "bad-checksum",
            Reject::NoChecksum => "no-checksum",
            Reject::BadChar => "bad-char",
            Reject::Empty => "empty",
            Reject::BadEncoding => "bad-encoding",
        }
    }
}

impl fmt::Display for Reject {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.reason())
    }
}

/// The XOR checksum of an NMEA sentence body (the bytes between `$`/`!` and `*`).
#[inline]
pub fn nmea_checksum(body: &[u8]) -> u8 {
    body.iter().fold(0, |acc, b| acc ^ b)
}

/// The address of an NMEA sentence: the letters after `$`/`!` (`GPGGA` in `$GPGGA,…`, `C` in the
/// Iver compass sentence `$C82.8P…`, which has no comma); empty when there are none.
#[inline]
pub fn nmea_address(sentence: &[u8]) -> &[u8] {
    let body = sentence.get(1..).unwrap_or_default();
    let len = body
        .iter()
        .position(|b| !b.is_ascii_alphabetic())
        .unwrap_or(body.len());
    &body[..len]
}

/// Builds a sentence from its body (`GPGGA,…`, without `$` and checksum): `$body*hh`.
pub fn nmea_sentence(start: u8, body: &str) -> String {
    format!(
        "{}{body}*{:02X}",
        start as char,
        nmea_checksum(body.as_bytes())
    )
}

/// One pass over a line, eight bytes at a time: the XOR of all its bytes, and whether every byte is
/// printable ASCII (0x20..=0x7E).
fn scan(line: &[u8]) -> (u8, bool) {
    const ONES: u64 = u64::from_ne_bytes([0x01; 8]);
    const HIGH: u64 = u64::from_ne_bytes([0x80; 8]);
    let mut xor = 0u64;
    let mut bad = 0u64;
    let mut words = line.chunks_exact(8);
    for w in &mut words {
        let w = u64::from_ne_bytes(w.try_into().unwrap_or_default());
        xor ^= w;
        // a byte below 0x20, or above 0x7E (a high bit after adding 1, or set already)
        bad |= (w.wrapping_sub(ONES * 0x20) & !w) | w.wrapping_add(ONES) | w;
    }
    let mut xor = xor.to_ne_bytes().iter().fold(0u8, |a, b| a ^ b);
    let mut ok = bad & HIGH == 0;
    for &b in words.remainder() {
        xor ^= b;
        ok &= (0x20..=0x7e).contains(&b);
    }
    (xor, ok)
}

fn hex(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'A'..=b'F' => Some(b - b'A' + 10),
        b'a'..=b'f' => Some(b - b'a' + 10),
        _ => None,
    }
}

/// Checks one complete NMEA sentence (`$…` without line ending) against `policy`; returns the
/// sentence with a correct checksum, in a buffer of exactly its size.
pub fn check_nmea(line: &[u8], policy: ChecksumPolicy) -> Result<Vec<u8>, Reject> {
    if line.len() < 2 || !matches!(line[0], b'$' | b'!') {
        return Err(Reject::Empty);
    }
    let (xor_all, printable) = scan(line);
    if !printable {
        return Err(Reject::BadChar);
    }
    // a checksum is `*` followed by exactly two hex digits at the end
    let star = line.len().checked_sub(3).filter(|&i| line[i] == b'*');
    match star {
        Some(i) => {
            let body = &line[1..i];
            if body.is_empty() {
                return Err(Reject::Empty);
            }
            let given = match (hex(line[i + 1]), hex(line[i + 2])) {
                (Some(h), Some(l)) => Some((h << 4) | l),
                _ => None,
            };
            // the body's checksum: the whole line's, less the start, the `*` and the two digits
            let actual = xor_all ^ line[0] ^ line[i] ^ line[i + 1] ^ line[i + 2];
            match (given, policy) {
                (Some(g), _) if g == actual => Ok(line.to_vec()),
                (_, ChecksumPolicy::Ignore) => {
                    let mut out = Vec::with_capacity(line.len());
                    out.extend_from_slice(&line[..i + 1]);
                    out.extend_from_slice(format!("{actual:02X}").as_bytes());
                    Ok(out)
                }
                _ => Err(Reject::BadChecksum),
            }
        }
        None => {
            if line[1..].contains(&b'*') && policy != ChecksumPolicy::Ignore {
                return Err(Reject::BadChecksum);
            }
            if policy == ChecksumPolicy::Require {
                return Err(Reject::NoChecksum);
            }
            let body = &line[1..];
            let body = match body.iter().position(|b| *b == b'*') {
                Some(i) => &body[..i],
                None => body,
            };
            if body.is_empty() {
                return Err(Reject::Empty);
            }
            let mut out = Vec::with_capacity(body.len() + 4);
            out.push(line[0]);
            out.extend_from_slice(body);
            out.extend_from_slice(format!("*{:02X}", nmea_checksum(body)).as_bytes());
            Ok(out)
        }
    }
}

/// A rejection and where in the stream it happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rejected {
    /// Why.
    pub reason: Reject,
    /// Bytes read from the stream before the byte that settled it.
    pub offset: u64,
}

/// What a framer hands out.
pub type Output = Result<Vec<u8>, Rejected>;

#[derive(Debug)]
enum State {
    /// Between frames (NMEA: outside a sentence).
    Idle,
    /// Inside a frame.
    In,
    /// Skipping an over-long frame until its end.
    Skipping,
    /// NMEA: in a run of garbage, already reported.
    Garbage,
    /// SLIP: after an escape byte.
    Escaped,
}

/// A streaming framer.
#[derive(Debug)]
pub struct Framer {
    framing: Framing,
    policy: ChecksumPolicy,
    max: usize,
    buf: Vec<u8>,
    state: State,
    offset: u64,
    dropped: u64,
}

const SLIP_END: u8 = 0xC0;
const SLIP_ESC: u8 = 0xDB;
const SLIP_ESC_END: u8 = 0xDC;
const SLIP_ESC_ESC: u8 = 0xDD;

impl Framer {
    /// A framer cutting frames of at most `max` bytes.
    pub fn new(framing: Framing, policy: ChecksumPolicy, max: usize) -> Framer {
        Framer {
            framing,
            policy,
            max: max.max(8),
            buf: Vec::with_capacity(128),
            state: State::Idle,
            offset: 0,
            dropped: 0,
        }
    }

    /// Feeds bytes; `out` gets each frame or rejection, in order.
    pub fn push(&mut self, bytes: &[u8], out: &mut impl FnMut(Output)) {
        let mut i = 0;
        while i < bytes.len() {
            // a whole sentence within `bytes` is checked where it lies, without copying it in
            if self.framing == Framing::Nmea
                && matches!(self.state, State::Idle | State::Garbage | State::Skipping)
                && let Some(len) = self.whole_sentence(&bytes[i..])
            {
                let line = trim_cr(&bytes[i..i + len]);
                let offset = self.offset + len as u64;
                let checked = check_nmea(line, self.policy);
                if checked.is_err() {
                    self.dropped += line.len() as u64;
                }
                out(checked.map_err(|reason| Rejected { reason, offset }));
                self.state = State::Idle;
                self.offset += len as u64 + 1;
                i += len + 1;
                continue;
            }
            // inside a sentence, plain bytes are copied a run at a time
            if self.framing == Framing::Nmea && matches!(self.state, State::In) {
                let rest = &bytes[i..];
                let run = memchr::memchr3(b'\n', b'$', b'!', rest).unwrap_or(rest.len());
                if run > 0 && run <= self.max.saturating_sub(self.buf.len()) {
                    self.buf.extend_from_slice(&rest[..run]);
                    self.offset += run as u64;
                    i += run;
                    continue;
                }
            }
            let b = bytes[i];
            i += 1;
            let offset = self.offset;
            let mut emit =
                |r: Result<Vec<u8>, Reject>| out(r.map_err(|reason| Rejected { reason, offset }));
            match self.framing {
                Framing::Nmea => self.nmea(b, &mut emit),
                Framing::Lines => self.line(b, &mut emit),
                Framing::Cobs => self.cobs(b, &mut emit),
                Framing::Slip => self.slip(b, &mut emit),
            }
            self.offset += 1;
        }
    }

    /// The length (to its `\n`, not included) of a whole NMEA sentence at the start of `rest`: one
    /// that is neither cut short by another start nor longer than the limit (as the byte-by-byte
    /// path would take it: a CR may follow a sentence of the full length).
    fn whole_sentence(&self, rest: &[u8]) -> Option<usize> {
        if !matches!(rest.first(), Some(b'$' | b'!')) {
            return None;
        }
        let end = 1 + memchr::memchr3(b'\n', b'$', b'!', &rest[1..])?;
        let line = trim_cr(&rest[..end]);
        (rest[end] == b'\n' && line.len() <= self.max).then_some(end)
    }

    /// Bytes held for an unfinished frame.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Bytes dropped so far: garbage outside frames, rejected frames, the skipped parts of frames
    /// longer than the limit (line endings and delimiters not counted).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Counts byte `b` as dropped, unless it ends a line.
    fn drop_byte(&mut self, b: u8) {
        if !matches!(b, b'\r' | b'\n') {
            self.dropped += 1;
        }
    }

    fn start(&mut self, b: u8) {
        self.buf.clear();
        self.buf.push(b);
        self.state = State::In;
    }

    /// The frame in hand, in a buffer of exactly its size (it becomes a payload as it is); the
    /// framer's own buffer is kept for the next frame.
    fn take(&mut self) -> Vec<u8> {
        self.state = State::Idle;
        let frame = self.buf.to_vec();
        self.buf.clear();
        frame
    }

    /// Whether byte `b` would make the frame in hand longer than the limit. In text framings a CR
    /// right after a frame of the full length may be its line ending, and does not count.
    fn overflows(&self, b: u8, text: bool) -> bool {
        self.buf.len() >= self.max && !(text && b == b'\r' && self.buf.len() == self.max)
    }

    /// Drops the frame in hand as too long, with the byte that did not fit, and skips the rest of
    /// it.
    fn skip_too_long(&mut self, out: &mut impl FnMut(Result<Vec<u8>, Reject>)) {
        self.dropped += self.buf.len() as u64 + 1;
        self.buf.clear();
        self.state = State::Skipping;
        out(Err(Reject::TooLong));
    }

    fn nmea(&mut self, b: u8, out: &mut impl FnMut(Result<Vec<u8>, Reject>)) {
        let starts = matches!(b, b'$' | b'!');
        match self.state {
            State::Idle | State::Garbage if starts => self.start(b),
            State::Idle => {
                if !matches!(b, b'\r' | b'\n') {
                    self.state = State::Garbage;
                    self.dropped += 1;
                    out(Err(Reject::Garbage));
                }
            }
            State::Garbage | State::Skipping if b == b'\n' => self.state = State::Idle,
            State::Garbage => self.drop_byte(b),
            State::Skipping => {
                if starts {
                    self.start(b);
                } else {
                    self.drop_byte(b);
                }
            }
            State::In | State::Escaped => {
                if starts {
                    self.dropped += self.buf.len() as u64;
                    out(Err(Reject::Truncated));
                    self.start(b);
                } else if b == b'\n' {
                    self.state = State::Idle;
                    let line = trim_cr(&self.buf);
                    let checked = check_nmea(line, self.policy);
                    if checked.is_err() {
                        self.dropped += line.len() as u64;
                    }
                    out(checked);
                    self.buf.clear();
                } else if self.overflows(b, true) {
                    self.skip_too_long(out);
                } else {
                    self.buf.push(b);
                }
            }
        }
    }

    fn line(&mut self, b: u8, out: &mut impl FnMut(Result<Vec<u8>, Reject>)) {
        match self.state {
            State::Skipping if b == b'\n' => self.state = State::Idle,
            State::Skipping => self.drop_byte(b),
            _ if b == b'\n' => {
                // CRs at the end are line-ending noise: a line cannot carry them (see `encode`)
                while self.buf.last() == Some(&b'\r') {
                    self.buf.pop();
                }
                let line = self.take();
                if !line.is_empty() {
                    out(Ok(line));
                }
            }
            _ if self.overflows(b, true) => self.skip_too_long(out),
            _ => {
                self.buf.push(b);
                self.state = State::In;
            }
        }
    }

    fn cobs(&mut self, b: u8, out: &mut impl FnMut(Result<Vec<u8>, Reject>)) {
        match self.state {
            State::Skipping if b == 0 => self.state = State::Idle,
            State::Skipping => self.dropped += 1,
            _ if b == 0 => {
                self.state = State::Idle;
                if !self.buf.is_empty() {
                    let decoded = cobs_decode(&self.buf);
                    if decoded.is_none() {
                        self.dropped += self.buf.len() as u64;
                    }
                    out(decoded.ok_or(Reject::BadEncoding));
                    self.buf.clear();
                }
            }
            _ if self.overflows(b, false) => self.skip_too_long(out),
            _ => {
                self.buf.push(b);
                self.state = State::In;
            }
        }
    }

    fn slip(&mut self, b: u8, out: &mut impl FnMut(Result<Vec<u8>, Reject>)) {
        match self.state {
            State::Skipping if b == SLIP_END => self.state = State::Idle,
            State::Skipping => self.dropped += 1,
            State::Escaped => match b {
                SLIP_ESC_END | SLIP_ESC_ESC => {
                    self.buf.push(if b == SLIP_ESC_END {
                        SLIP_END
                    } else {
                        SLIP_ESC
                    });
                    self.state = State::In;
                }
                // the frame as decoded so far, and the escape byte (and the byte after it)
                SLIP_END => {
                    self.dropped += self.buf.len() as u64 + 1;
                    self.buf.clear();
                    self.state = State::Idle;
                    out(Err(Reject::BadEncoding));
                }
                _ => {
                    self.dropped += self.buf.len() as u64 + 2;
                    self.buf.clear();
                    self.state = State::Skipping;
                    out(Err(Reject::BadEncoding));
                }
            },
            _ if b == SLIP_END => {
                let frame = self.take();
                if !frame.is_empty() {
                    out(Ok(frame));
                }
            }
            _ if self.overflows(b, false) => self.skip_too_long(out),
            _ if b == SLIP_ESC => self.state = State::Escaped,
            _ => {
                self.buf.push(b);
                self.state = State::In;
            }
        }
    }
}

/// Encodes a frame for the wire: NMEA sentences get a checksum when they lack one and CR LF;
/// lines get LF; COBS frames are stuffed and end in a zero; SLIP frames are escaped and wrapped in
/// END bytes.
pub fn encode(framing: Framing, frame: &[u8]) -> Result<Vec<u8>, &'static str> {
    match framing {
        Framing::Nmea => {
            let mut s = check_nmea(frame, ChecksumPolicy::AllowMissing).map_err(|r| match r {
                Reject::BadChar => "an NMEA sentence holds printable ASCII only",
                Reject::BadChecksum => "the sentence's checksum is wrong",
                _ => "an NMEA sentence starts with `$` or `!` and has a body",
            })?;
            s.extend_from_slice(b"\r\n");
            Ok(s)
        }
        Framing::Lines => {
            if frame.contains(&b'\n') {
                return Err("a line cannot hold a line feed");
            }
            if frame.last() == Some(&b'\r') {
                return Err("a line cannot end in a carriage return");
            }
            let mut s = Vec::with_capacity(frame.len() + 1);
            s.extend_from_slice(frame);
            s.push(b'\n');
            Ok(s)
        }
        Framing::Cobs => {
            let mut s = cobs_encode(frame);
            s.push(0);
            Ok(s)
        }
        Framing::Slip => {
            let mut s = Vec::with_capacity(frame.len() + 2);
            s.push(SLIP_END);
            for &b in frame {
                match b {
                    SLIP_END => s.extend_from_slice(&[SLIP_ESC, SLIP_ESC_END]),
                    SLIP_ESC => s.extend_from_slice(&[SLIP_ESC, SLIP_ESC_ESC]),
                    _ => s.push(b),
                }
            }
            s.push(SLIP_END);
            Ok(s)
        }
    }
}

/// COBS-encodes `data` (without the trailing zero).
pub fn cobs_encode(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len() + data.len() / 254 + 2);
    let mut code_at = 0;
    out.push(0);
    let mut code = 1u8;
    for &b in data {
        if b == 0 {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(b);
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out
}

/// Decodes a COBS frame (without its trailing zero); `None` when it is malformed.
pub fn cobs_decode(data: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(data.len());
    let mut i = 0;
    while i < data.len() {
        let code = data[i] as usize;
        if code == 0 || i + code > data.len() {
            return None;
        }
        out.extend_from_slice(&data[i + 1..i + code]);
        i += code;
        if code < 0xFF && i < data.len() {
            out.push(0);
        }
    }
    Some(out)
}

/// `line` without the carriage returns that end it (devices end lines `\r\n`, some `\r\r\n`).
fn trim_cr(line: &[u8]) -> &[u8] {
    let end = line.iter().rposition(|&b| b != b'\r').map_or(0, |i| i + 1);
    &line[..end]
}

#[cfg(test)]
mod tests {
    use super::*;

    type Got = Result<Vec<u8>, Reject>;

    fn frames(framing: Framing, policy: ChecksumPolicy, input: &[u8]) -> Vec<Got> {
        let mut f = Framer::new(framing, policy, 100);
        let mut got = Vec::new();
        f.push(input, &mut |o| got.push(o.map_err(|r| r.reason)));
        got
    }

    fn ok(s: &str) -> Got {
        Ok(s.as_bytes().to_vec())
    }

    #[test]
    fn checksums_are_computed_not_copied() {
        // body "GPGGA,1" XORs to this value, worked out byte by byte
        let body = b"GPGGA,1";
        let x = body.iter().fold(0u8, |a, b| a ^ b);
        assert_eq!(nmea_checksum(body), x);
        assert_eq!(nmea_sentence(b'$', "GPGGA,1"), format!("$GPGGA,1*{x:02X}"));
        // the example from goby's comments
        assert_eq!(
            nmea_sentence(b'$', "C82.8P-3.89R-2.63T20.3D3.2"),
            "$C82.8P-3.89R-2.63T20.3D3.2*78"
        );
    }

    #[test]
    fn the_word_scan_agrees_with_a_byte_by_byte_one() {
        let naive = |l: &[u8]| {
            (
                l.iter().fold(0u8, |a, b| a ^ b),
                l.iter().all(|b| (0x20..=0x7e).contains(b)),
            )
        };
        // every byte value at every place of a word and of the tail, beside every kind of neighbour
        for len in [1, 8, 13, 24] {
            for at in 0..len {
                for b in 0..=255u8 {
                    for fill in [b' ', b'~', b'A', 0x7f, 0xff, 0x00] {
                        let mut line = vec![fill; len];
                        line[at] = b;
                        assert_eq!(scan(&line), naive(&line), "{line:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn sentences_end_at_lf_with_or_without_cr() {
        let a = nmea_sentence(b'$', "GPHDT,1.0,T");
        let b = nmea_sentence(b'!', "AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0");
        let input = format!("{a}\r\n{b}\n");
        assert_eq!(
            frames(Framing::Nmea, ChecksumPolicy::Require, input.as_bytes()),
            [ok(&a), ok(&b)]
        );
    }

    #[test]
    fn garbage_truncation_and_bad_checksums_are_rejected_and_the_next_sentence_survives() {
        let good = nmea_sentence(b'$', "GPHDT,2.0,T");
        let bad = "$GPHDT,2.0,T*00";
        let input =
            format!("\x00\x7fjunk\r\n$GPGGA,cut{good}\r\n{bad}\r\n$GPHDT,3.0,T\r\n{good}\r\n");
        let got = frames(Framing::Nmea, ChecksumPolicy::Require, input.as_bytes());
        assert_eq!(
            got,
            [
                Err(Reject::Garbage),
                Err(Reject::Truncated),
                ok(&good),
                Err(Reject::BadChecksum),
                Err(Reject::NoChecksum),
                ok(&good)
            ]
        );
        // allowing a missing checksum adds it
        let got = frames(
            Framing::Nmea,
            ChecksumPolicy::AllowMissing,
            b"$GPHDT,3.0,T\r\n",
        );
        assert_eq!(got, [ok(&nmea_sentence(b'$', "GPHDT,3.0,T"))]);
        let got = frames(Framing::Nmea, ChecksumPolicy::AllowMissing, bad.as_bytes());
        assert!(got.is_empty(), "no line end yet");
        let got = frames(
            Framing::Nmea,
            ChecksumPolicy::Ignore,
            format!("{bad}\n").as_bytes(),
        );
        assert_eq!(got, [ok(&good)]);
    }

    #[test]
    fn long_lines_without_a_newline_are_dropped_and_bounded() {
        let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 82);
        let mut got = Vec::new();
        let long = vec![b'A'; 10_000];
        f.push(b"$", &mut |o| got.push(o));
        f.push(&long, &mut |o| got.push(o));
        assert!(f.pending() <= 82);
        let good = nmea_sentence(b'$', "GPHDT,4.0,T");
        f.push(format!("{good}\r\n").as_bytes(), &mut |o| got.push(o));
        assert_eq!(
            got,
            [
                Err(Rejected {
                    reason: Reject::TooLong,
                    offset: 82
                }),
                Ok(good.into_bytes())
            ]
        );
    }

    #[test]
    fn dropped_bytes_are_counted_whatever_the_chunking() {
        let good = nmea_sentence(b'$', "GPHDT,2.0,T");
        // 6 bytes of garbage, a sentence of 10 cut short, one of 15 with a wrong checksum, one of
        // 12 without: 43 bytes; the good sentences and the line endings are not counted
        let input = format!(
            "\x00\x7fjunk\r\n$GPGGA,cut{good}\r\n$GPHDT,2.0,T*00\r\n$GPHDT,3.0,T\r\n{good}\r\n\r\n"
        );
        for chunk in [1, 2, 3, 7, 64, input.len()] {
            let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 100);
            let mut good_ones = 0;
            for piece in input.as_bytes().chunks(chunk) {
                f.push(piece, &mut |o| good_ones += usize::from(o.is_ok()));
            }
            assert_eq!((f.dropped(), good_ones), (43, 2), "chunks of {chunk}");
        }
        // an over-long sentence: all of it, the part kept before the limit too
        let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 82);
        f.push(b"$", &mut |_| {});
        f.push(&[b'A'; 10_000], &mut |_| {});
        f.push(format!("\r\n{good}\r\n").as_bytes(), &mut |_| {});
        assert_eq!(f.dropped(), 10_001);
        // the other framings
        let dropped = |framing, max, input: &[u8]| {
            let mut f = Framer::new(framing, ChecksumPolicy::Require, max);
            f.push(input, &mut |_| {});
            f.dropped()
        };
        assert_eq!(dropped(Framing::Lines, 8, b"ABCDEFGHIJ\r\nok\n"), 10);
        assert_eq!(dropped(Framing::Cobs, 100, &[5, 1, 0, 2, 7, 0]), 2);
        let slip = [SLIP_END, 1, 2, SLIP_ESC, 7, 8, SLIP_END, 3, SLIP_END];
        assert_eq!(dropped(Framing::Slip, 100, &slip), 5);
    }

    #[test]
    fn any_chunking_gives_the_same_frames() {
        let a = nmea_sentence(b'$', "GPHDT,5.0,T");
        let input = format!("xx{a}\r\n$GPGGA{a}\r\n");
        let whole = frames(Framing::Nmea, ChecksumPolicy::Require, input.as_bytes());
        for chunk in 1..8 {
            let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 100);
            let mut got = Vec::new();
            for piece in input.as_bytes().chunks(chunk) {
                f.push(piece, &mut |o| got.push(o.map_err(|r| r.reason)));
            }
            assert_eq!(got, whole, "chunks of {chunk}");
        }
    }

    #[test]
    fn regression_a_full_frame_may_end_in_cr_lf_and_lines_shed_trailing_crs() {
        // found by the nmea_framer fuzz target
        let s = nmea_sentence(b'$', "A,1");
        let max = s.len();
        let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, max);
        let mut got = Vec::new();
        f.push(format!("{s}\r\n").as_bytes(), &mut |o| {
            got.push(o.map_err(|r| r.reason))
        });
        assert_eq!(got, [Ok(s.into_bytes())]);
        let mut f = Framer::new(Framing::Lines, ChecksumPolicy::Require, 8);
        let mut got = Vec::new();
        f.push(b"ABCDEFGH\r\nx\r\r\n", &mut |o| {
            got.push(o.map_err(|r| r.reason))
        });
        assert_eq!(got, [Ok(b"ABCDEFGH".to_vec()), Ok(b"x".to_vec())]);
        // a CR held at the limit and more bytes after it: too long, not a crash
        let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 8);
        let mut got = Vec::new();
        f.push(b"$ABCDEFG\rXYZ\n", &mut |o| {
            got.push(o.map_err(|r| r.reason))
        });
        assert_eq!(got, [Err(Reject::TooLong)]);
    }

    #[test]
    fn a_line_ending_in_two_carriage_returns_is_a_sentence() {
        let s = nmea_sentence(b'$', "GPHDT,274.1,T");
        let input = format!("{s}\r\r\n{s}\r\n{s}\n");
        let want = vec![ok(&s), ok(&s), ok(&s)];
        assert_eq!(
            frames(Framing::Nmea, ChecksumPolicy::Require, input.as_bytes()),
            want
        );
        // byte by byte (the slow path) too
        let mut f = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 100);
        let mut got = Vec::new();
        for b in input.as_bytes() {
            f.push(std::slice::from_ref(b), &mut |o| {
                got.push(o.map_err(|r| r.reason))
            });
        }
        assert_eq!(got, want);
    }

    #[test]
    fn non_printable_bytes_inside_a_sentence_are_rejected() {
        let got = frames(
            Framing::Nmea,
            ChecksumPolicy::Ignore,
            b"$GP\x01HDT,1*00\r\n",
        );
        assert_eq!(got, [Err(Reject::BadChar)]);
    }

    #[test]
    fn lines_cobs_and_slip_round_trip() {
        for framing in [Framing::Lines, Framing::Cobs, Framing::Slip] {
            let payloads: Vec<Vec<u8>> = if framing == Framing::Lines {
                vec![b"hello".to_vec(), b"a\rb".to_vec(), vec![0xff, 0x00, 0x41]]
            } else {
                vec![
                    vec![0, 0, 1],
                    vec![SLIP_END, SLIP_ESC, 7],
                    (0..=255).collect(),
                    vec![1; 600],
                ]
            };
            let mut wire = Vec::new();
            for p in &payloads {
                wire.extend(encode(framing, p).unwrap());
            }
            let mut f = Framer::new(framing, ChecksumPolicy::Require, 2048);
            let mut got = Vec::new();
            f.push(&wire, &mut |o| got.push(o.unwrap()));
            assert_eq!(got, payloads, "{framing:?}");
        }
    }

    #[test]
    fn cobs_vectors() {
        assert_eq!(cobs_encode(&[0]), [1, 1]);
        assert_eq!(
            cobs_encode(&[0x11, 0x22, 0x00, 0x33]),
            [3, 0x11, 0x22, 2, 0x33]
        );
        assert_eq!(
            cobs_decode(&[3, 0x11, 0x22, 2, 0x33]).unwrap(),
            [0x11, 0x22, 0x00, 0x33]
        );
        assert_eq!(cobs_decode(&[5, 1]), None);
        assert_eq!(cobs_decode(&[0]), None);
        let long: Vec<u8> = vec![7; 254];
        let enc = cobs_encode(&long);
        assert_eq!(enc[0], 0xFF);
        assert_eq!(cobs_decode(&enc).unwrap(), long);
    }

    #[test]
    fn encoding_refuses_what_the_framing_cannot_carry() {
        assert!(encode(Framing::Nmea, b"GPGGA,1").is_err());
        assert!(encode(Framing::Nmea, b"$GP\x01").is_err());
        assert_eq!(
            encode(Framing::Nmea, b"$OSD,G,C,S,P,,,,").unwrap(),
            format!("{}\r\n", nmea_sentence(b'$', "OSD,G,C,S,P,,,,")).into_bytes()
        );
        assert!(encode(Framing::Lines, b"a\nb").is_err());
        assert!(encode(Framing::Lines, b"a\r").is_err());
    }
}
