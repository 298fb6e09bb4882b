//! LCM event logs: the files `lcm-logger` writes and `lcm-logplayer` plays, written and read byte
//! for byte as they do.
//!
//! A log is a run of events, each laid out big-endian as:
//!
//! | bytes | field |
//! |---|---|
//! | 4 | sync word `0xEDA1DA01` ([`SYNC`]) |
//! | 8 | event number (i64), counting from 0 in each file |
//! | 8 | timestamp (i64), microseconds since the Unix epoch |
//! | 4 | channel length (i32), 1 to 999 |
//! | 4 | data length (i32), 0 or more |
//! | channel length | the channel name, UTF-8, no NUL |
//! | data length | the data (on an LCM bus, the message's bytes) |
//!
//! [`Writer`] appends events through a buffer; [`Reader`] reads them one at a time from any
//! [`std::io::Read`], reusing one buffer for every event. Where a log is damaged (cut short, a bad
//! sync word, an impossible length, a channel name that is not UTF-8) the reader stops and says where
//! the damaged event starts and what is wrong with it ([`Damage`]); unlike `lcm-logplayer`, which
//! scans ahead for the next sync word, it never guesses past damage.

use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::Path;
use thiserror::Error;

/// The word that starts every event.
pub const SYNC: u32 = 0xEDA1_DA01;

/// Bytes in an event's fixed header: sync word, event number, timestamp, the two lengths.
pub const HEADER_LEN: usize = 28;

/// Longest channel name an event log holds, in bytes (LCM's readers refuse 1000 and more).
pub const MAX_LOG_CHANNEL_LEN: usize = 999;

/// Above this many bytes of channel and data, a reader that does not know the input's size grows
/// its buffer as the bytes arrive instead of trusting the length up front.
const EAGER_BODY: u64 = 1 << 20;

/// One event of a log, borrowed from the [`Reader`] that read it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Event<'a> {
    /// The event number as written (LCM writers count from 0 in each file).
    pub number: i64,
    /// Microseconds since the Unix epoch.
    pub timestamp: i64,
    /// The channel name.
    pub channel: &'a str,
    /// The data.
    pub data: &'a [u8],
}

impl Event<'_> {
    /// A copy that owns its channel and data.
    pub fn into_owned(self) -> OwnedEvent {
        OwnedEvent {
            number: self.number,
            timestamp: self.timestamp,
            channel: self.channel.to_string(),
            data: self.data.to_vec(),
        }
    }

    /// Bytes the event takes in a log.
    pub fn encoded_len(&self) -> u64 {
        (HEADER_LEN + self.channel.len() + self.data.len()) as u64
    }
}

/// One event of a log, owning its channel and data.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedEvent {
    /// The event number as written.
    pub number: i64,
    /// Microseconds since the Unix epoch.
    pub timestamp: i64,
    /// The channel name.
    pub channel: String,
    /// The data.
    pub data: Vec<u8>,
}

impl OwnedEvent {
    /// The event, borrowed.
    pub fn as_event(&self) -> Event<'_> {
        Event {
            number: self.number,
            timestamp: self.timestamp,
            channel: &self.channel,
            data: &self.data,
        }
    }
}

/// What is wrong with a damaged event.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum Problem {
    /// The log ends inside the event's 28-byte header.
    #[error("truncated event: the log ends {found} bytes into its {HEADER_LEN}-byte header")]
    TruncatedHeader {
        /// Header bytes present.
        found: usize,
    },
    /// The log ends inside the event's channel name and data.
    #[error(
        "truncated event: its channel and data need {needed} bytes after the header, the log ends after {found}"
    )]
    TruncatedBody {
        /// Bytes of channel and data the header announces.
        needed: u64,
        /// Bytes present.
        found: u64,
    },
    /// The event does not start with the sync word.
    #[error("bad sync word 0x{0:08X} (expected 0x{SYNC:08X})")]
    BadSync(u32),
    /// The channel length is not 1 to 999.
    #[error("channel length {0} (expected 1 to {MAX_LOG_CHANNEL_LEN})")]
    ChannelLength(i32),
    /// The data length is negative.
    #[error("negative data length {0}")]
    DataLength(i32),
    /// The lengths reach past the end of a log of known size.
    #[error(
        "data length {data_len} reaches past the end of the log: channel and data need {needed} bytes after the header, {remaining} remain"
    )]
    PastEnd {
        /// The data length as written.
        data_len: i32,
        /// Bytes of channel and data the header announces.
        needed: u64,
        /// Bytes left in the log after the header.
        remaining: u64,
    },
    /// The channel name is not UTF-8.
    #[error("channel name is not UTF-8 (bad byte {at} bytes into the name)")]
    ChannelNotUtf8 {
        /// Offset of the first bad byte within the name.
        at: usize,
    },
    /// Reading failed.
    #[error("read error: {0}")]
    Io(String),
}

/// Where a log is damaged: the byte offset at which the damaged event starts, and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("byte {offset}: {problem}")]
pub struct Damage {
    /// Byte offset of the damaged event from the start of the log.
    pub offset: u64,
    /// What is wrong with it.
    pub problem: Problem,
}

/// Reads events from a log one at a time.
///
/// The reader reads the log in blocks of up to 128 KiB into one buffer it keeps, and every event it
/// hands out borrows its channel and data from that buffer: nothing is copied or allocated per
/// event. An event larger than the buffer grows it for as long as the events that follow are as
/// large; the first event that fits again gives the memory back. It reads only while the event it
/// is after is not whole, so an input that delivers a little at a time (a pipe, a socket) is not
/// waited on for a whole block. After damage, the reader keeps returning the same [`Damage`].
pub struct Reader<R> {
    input: R,
    /// Offset of the next event.
    offset: u64,
    size: Option<u64>,
    /// Bytes read from the input; `buf[start..end]` are the ones not handed out yet, and the next
    /// event starts at `start`.
    buf: Vec<u8>,
    start: usize,
    end: usize,
    failed: Option<Damage>,
}

/// Bytes a [`Reader`] reads at a time, the size of its buffer while the events fit in it.
const BUF_LEN: usize = 1 << 17;

impl Reader<File> {
    /// Opens a log file; its size (for a regular file) lets the reader catch a length that reaches
    /// past the end before reading it.
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        let file = File::open(path)?;
        let meta = file.metadata()?;
        Ok(match meta.is_file() {
            true => Reader::with_size(file, meta.len()),
            false => Reader::new(file),
        })
    }
}

impl<R: Read> Reader<R> {
    /// Reads from `input`, whose size is not known. The reader reads in large blocks itself: the
    /// input needs no buffer of its own.
    pub fn new(input: R) -> Self {
        Reader {
            input,
            offset: 0,
            size: None,
            buf: Vec::new(),
            start: 0,
            end: 0,
            failed: None,
        }
    }

    /// Reads from `input`, which holds `size` bytes.
    pub fn with_size(input: R, size: u64) -> Self {
        Reader {
            size: Some(size),
            ..Reader::new(input)
        }
    }

    /// Byte offset of the next event: the bytes of whole events read so far.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The size of the input, when known.
    pub fn size(&self) -> Option<u64> {
        self.size
    }

    /// The next event; `Ok(None)` at the end of the log (after a whole event), `Err` where the log
    /// is damaged.
    #[inline]
    pub fn next_event(&mut self) -> Result<Option<Event<'_>>, Damage> {
        if self.failed.is_some() {
            return Err(fail(&mut self.failed, self.offset, None));
        }
        let problem = match self.read_event() {
            Ok(None) => return Ok(None),
            Ok(Some((number, timestamp, channel_len, len))) => {
                let event = &self.buf[self.start..self.start + len];
                let (channel, data) = event[HEADER_LEN..].split_at(channel_len);
                let channel = match channel.is_ascii() {
                    // SAFETY: ASCII is UTF-8 (the check spares a full UTF-8 validation, the larger
                    // part of the time an event of a few dozen bytes takes to read)
                    true => Ok(unsafe { std::str::from_utf8_unchecked(channel) }),
                    false => std::str::from_utf8(channel),
                };
                match channel {
                    Ok(channel) => {
                        self.start += len;
                        self.offset += len as u64;
                        return Ok(Some(Event {
                            number,
                            timestamp,
                            channel,
                            data,
                        }));
                    }
                    Err(e) => Problem::ChannelNotUtf8 {
                        at: e.valid_up_to(),
                    },
                }
            }
            Err(problem) => problem,
        };
        Err(fail(&mut self.failed, self.offset, Some(problem)))
    }

    /// Has the next event whole in the buffer at `start`; returns its number, timestamp, channel
    /// length and length in the log.
    #[inline]
    fn read_event(&mut self) -> Result<Option<(i64, i64, usize, usize)>, Problem> {
        if self.end - self.start < HEADER_LEN {
            self.fill(HEADER_LEN, true)?;
            let found = self.end - self.start;
            if found == 0 {
                return Ok(None);
            }
            if found < HEADER_LEN {
                return Err(Problem::TruncatedHeader { found });
            }
        }
        let header: &[u8; HEADER_LEN] = self.buf[self.start..self.start + HEADER_LEN]
            .try_into()
            .expect("a header's bytes");
        let sync = u32::from_be_bytes([header[0], header[1], header[2], header[3]]);
        if sync != SYNC {
            return Err(Problem::BadSync(sync));
        }
        let i64_at = |at: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&header[at..at + 8]);
            i64::from_be_bytes(b)
        };
        let i32_at = |at: usize| {
            i32::from_be_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
        };
        let (number, timestamp) = (i64_at(4), i64_at(12));
        let (channel_len, data_len) = (i32_at(20), i32_at(24));
        if channel_len <= 0 || channel_len as usize > MAX_LOG_CHANNEL_LEN {
            return Err(Problem::ChannelLength(channel_len));
        }
        if data_len < 0 {
            return Err(Problem::DataLength(data_len));
        }
        let needed = channel_len as u64 + data_len as u64;
        if let Some(size) = self.size {
            let remaining = size.saturating_sub(self.offset + HEADER_LEN as u64);
            if needed > remaining {
                return Err(Problem::PastEnd {
                    data_len,
                    needed,
                    remaining,
                });
            }
        }
        // at most 28 + 999 + 2^31 - 1 bytes, which a usize holds
        let len = HEADER_LEN + needed as usize;
        if self.buf.len() > BUF_LEN && len <= BUF_LEN && self.end - self.start <= BUF_LEN {
            // the events fit again: give back what the large ones took
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
            self.buf.truncate(BUF_LEN);
            self.buf.shrink_to_fit();
        }
        if self.end - self.start < len {
            // the length is bounded by the input's size, or small: make room for it at once; a
            // large length from an input of unknown size: grow only as the bytes arrive
            self.fill(len, self.size.is_some() || needed <= EAGER_BODY)?;
            let found = (self.end - self.start - HEADER_LEN) as u64;
            if found < needed {
                return Err(Problem::TruncatedBody { needed, found });
            }
        }
        Ok(Some((number, timestamp, channel_len as usize, len)))
    }

    /// Reads until the buffer holds `want` bytes from `start`, or the input ends. With `eager`,
    /// room for them all is made at once; without, the buffer grows as the bytes arrive.
    #[inline(never)]
    fn fill(&mut self, want: usize, eager: bool) -> Result<(), Problem> {
        if self.buf.len() - self.start < want {
            // move the unread bytes to the front
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
            let base = match self.size {
                // no larger than the input
                Some(size) => (size.saturating_sub(self.offset)).min(BUF_LEN as u64) as usize,
                None => BUF_LEN,
            };
            if self.buf.len() < base {
                self.buf.resize(base, 0);
            }
            if eager && self.buf.len() < want {
                self.buf.resize(want, 0);
            }
        }
        while self.end - self.start < want {
            if self.end == self.buf.len() {
                // only without `eager`, where `start` is 0 and `want` more than the buffer holds
                let grown = self.buf.len().saturating_mul(2).max(BUF_LEN).min(want);
                self.buf.resize(grown, 0);
            }
            // a buffer grown for large events reads no further than the event
            let stop = match self.buf.len() > BUF_LEN {
                true => self.buf.len().min(self.start + want),
                false => self.buf.len(),
            };
            match self.input.read(&mut self.buf[self.end..stop]) {
                Ok(0) => break,
                Ok(n) => self.end += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_problem(e)),
            }
        }
        Ok(())
    }
}

/// The damage a reader keeps returning: `problem`, found at `offset`, or the damage it found
/// before.
#[cold]
#[inline(never)]
fn fail(failed: &mut Option<Damage>, offset: u64, problem: Option<Problem>) -> Damage {
    match problem {
        Some(problem) => failed.insert(Damage { offset, problem }).clone(),
        None => failed.clone().expect("damage found before"),
    }
}

fn io_problem(e: io::Error) -> Problem {
    Problem::Io(e.to_string())
}

/// Why an event could not be written.
#[derive(Debug, Error)]
pub enum WriteError {
    /// The channel name is empty or longer than [`MAX_LOG_CHANNEL_LEN`] bytes.
    #[error("channel name of {0} bytes (a log holds 1 to {MAX_LOG_CHANNEL_LEN})")]
    ChannelLength(usize),
    /// The data is longer than a log's 31-bit length field.
    #[error("{0} bytes of data (a log event holds at most {max})", max = i32::MAX)]
    DataLength(usize),
    /// The output refused.
    #[error(transparent)]
    Io(#[from] io::Error),
}

/// What a payload is in an event's data: bytes as they are (on an LCM medium, the LCM message),
/// a datamap in seabus's binary form (which opens with its magic `SM`), XML as its text.
pub fn event_data(
    payload: &crate::Payload,
) -> Result<std::borrow::Cow<'_, [u8]>, crate::datamap::TooDeep> {
    use std::borrow::Cow;
    Ok(match payload {
        crate::Payload::Bytes(b) => Cow::Borrowed(&b[..]),
        crate::Payload::Xml(x) => Cow::Borrowed(x.as_bytes()),
        crate::Payload::Map(m) => Cow::Owned(crate::binary::encode(m)?),
    })
}

/// Writes events to a log through a buffer, numbering them from 0 as `lcm-logger` does.
///
/// Call [`Writer::flush`] (or [`Writer::finish`]) at the end: events still in the buffer when a
/// writer is dropped are written then, but an error doing so goes unseen.
pub struct Writer<W: Write> {
    out: BufWriter<W>,
    events: u64,
    bytes: u64,
}

impl Writer<File> {
    /// Creates a log file, refusing to overwrite one that exists.
    pub fn create_new(path: impl AsRef<Path>) -> io::Result<Self> {
        Ok(Writer::new(File::create_new(path)?))
    }

    /// Creates a log file, replacing any file of that name.
    pub fn create(path: impl AsRef<Path>) -> io::Result<Self> {
        Ok(Writer::new(File::create(path)?))
    }
}

impl<W: Write> Writer<W> {
    /// Writes a log to `out`.
    pub fn new(out: W) -> Self {
        Writer {
            out: BufWriter::with_capacity(1 << 16, out),
            events: 0,
            bytes: 0,
        }
    }

    /// Appends an event: `timestamp` in microseconds since the Unix epoch. Returns its number.
    pub fn write(&mut self, timestamp: i64, channel: &str, data: &[u8]) -> Result<i64, WriteError> {
        if channel.is_empty() || channel.len() > MAX_LOG_CHANNEL_LEN {
            return Err(WriteError::ChannelLength(channel.len()));
        }
        let data_len = i32::try_from(data.len()).map_err(|_| WriteError::DataLength(data.len()))?;
        let number = self.events as i64;
        let mut header = [0u8; HEADER_LEN];
        header[0..4].copy_from_slice(&SYNC.to_be_bytes());
        header[4..12].copy_from_slice(&number.to_be_bytes());
        header[12..20].copy_from_slice(&timestamp.to_be_bytes());
        header[20..24].copy_from_slice(&(channel.len() as i32).to_be_bytes());
        header[24..28].copy_from_slice(&data_len.to_be_bytes());
        self.out.write_all(&header)?;
        self.out.write_all(channel.as_bytes())?;
        self.out.write_all(data)?;
        self.events += 1;
        self.bytes += (HEADER_LEN + channel.len() + data.len()) as u64;
        Ok(number)
    }

    /// Passes the buffered events on to the output and flushes it.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }

    /// Events written so far.
    pub fn events(&self) -> u64 {
        self.events
    }

    /// Bytes written so far (buffered ones included).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Flushes and returns the output.
    pub fn finish(self) -> io::Result<W> {
        self.out.into_inner().map_err(|e| e.into_error())
    }
}

impl<W: Write> fmt::Debug for Writer<W> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Writer")
            .field("events", &self.events)
            .field("bytes", &self.bytes)
            .finish()
    }
}

impl<R> fmt::Debug for Reader<R> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Reader")
            .field("offset", &self.offset)
            .field("size", &self.size)
            .field("failed", &self.failed)
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads every event of `log` (size known or not); returns them and the damage, if any.
    fn read_all(log: &[u8], sized: bool) -> (Vec<OwnedEvent>, Option<Damage>) {
        let mut r = if sized {
            Reader::with_size(log, log.len() as u64)
        } else {
            Reader::new(log)
        };
        let mut events = Vec::new();
        for _ in 0..=log.len() {
            match r.next_event() {
                Ok(Some(e)) => events.push(e.into_owned()),
                Ok(None) => return (events, None),
                Err(d) => return (events, Some(d)),
            }
        }
        panic!("more events than bytes");
    }

    fn sample() -> Vec<u8> {
        let mut w = Writer::new(Vec::new());
        assert_eq!(w.write(1_000_000, "POSE", b"\x01\x02\x03").unwrap(), 0);
        assert_eq!(w.write(1_000_500, "nav.depth", b"").unwrap(), 1);
        assert_eq!(w.write(1_001_000, "POSE", &[0xff; 40]).unwrap(), 2);
        w.finish().unwrap()
    }

    #[test]
    fn an_event_is_laid_out_as_lcm_logger_writes_it() {
        let mut w = Writer::new(Vec::new());
        w.write(0x0102_0304_0506_0708, "CH", b"hello").unwrap();
        w.write(-1, "X", b"").unwrap();
        assert_eq!(w.events(), 2);
        assert_eq!(w.bytes(), 28 + 7 + 28 + 1);
        let log = w.finish().unwrap();
        let mut want = Vec::new();
        want.extend_from_slice(&[0xED, 0xA1, 0xDA, 0x01]);
        want.extend_from_slice(&0i64.to_be_bytes());
        want.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
        want.extend_from_slice(&[0, 0, 0, 2, 0, 0, 0, 5]);
        want.extend_from_slice(b"CHhello");
        want.extend_from_slice(&[0xED, 0xA1, 0xDA, 0x01]);
        want.extend_from_slice(&1i64.to_be_bytes());
        want.extend_from_slice(&[0xff; 8]);
        want.extend_from_slice(&[0, 0, 0, 1, 0, 0, 0, 0]);
        want.extend_from_slice(b"X");
        assert_eq!(log, want);
    }

    #[test]
    fn written_logs_read_back() {
        let log = sample();
        for sized in [true, false] {
            let (events, damage) = read_all(&log, sized);
            assert_eq!(damage, None);
            let got: Vec<_> = events
                .iter()
                .map(|e| (e.number, e.timestamp, e.channel.as_str(), e.data.len()))
                .collect();
            assert_eq!(
                got,
                [
                    (0, 1_000_000, "POSE", 3),
                    (1, 1_000_500, "nav.depth", 0),
                    (2, 1_001_000, "POSE", 40)
                ]
            );
            assert_eq!(events[0].data, b"\x01\x02\x03");
        }
        let (none, damage) = read_all(b"", true);
        assert!(none.is_empty() && damage.is_none());
    }

    #[test]
    fn a_cut_anywhere_stops_at_the_cut_event() {
        let log = sample();
        let ends = [0u64, 35, 35 + 37, log.len() as u64];
        for cut in 0..log.len() {
            let whole = ends.iter().filter(|&&e| e <= cut as u64).count() - 1;
            for sized in [true, false] {
                let (events, damage) = read_all(&log[..cut], sized);
                assert_eq!(events.len(), whole, "cut at {cut}");
                if ends.contains(&(cut as u64)) {
                    assert_eq!(damage, None, "cut at {cut}");
                } else {
                    let d = damage.unwrap_or_else(|| panic!("no damage for a cut at {cut}"));
                    assert_eq!(d.offset, ends[whole], "cut at {cut}");
                    let header_left = cut as u64 - ends[whole] < HEADER_LEN as u64;
                    match d.problem {
                        Problem::TruncatedHeader { .. } => assert!(header_left),
                        Problem::PastEnd { .. } => assert!(sized && !header_left),
                        Problem::TruncatedBody { .. } => assert!(!sized && !header_left),
                        p => panic!("cut at {cut}: {p}"),
                    }
                }
            }
        }
    }

    #[test]
    fn damage_says_where_and_what() {
        let log = sample();
        let second = 35;
        let damaged = |at: usize, bytes: &[u8]| {
            let mut l = log.clone();
            l[second + at..second + at + bytes.len()].copy_from_slice(bytes);
            let (events, damage) = read_all(&l, true);
            assert_eq!(events.len(), 1);
            let d = damage.expect("damage");
            assert_eq!(d.offset, second as u64);
            d.problem
        };
        assert_eq!(damaged(0, &[0xEC]), Problem::BadSync(0xECA1_DA01));
        assert_eq!(damaged(20, &[0, 0, 0, 0]), Problem::ChannelLength(0));
        assert_eq!(damaged(20, &[0, 0, 3, 0xE8]), Problem::ChannelLength(1000));
        assert_eq!(damaged(20, &[0xff; 4]), Problem::ChannelLength(-1));
        assert_eq!(damaged(24, &[0x80, 0, 0, 0]), Problem::DataLength(i32::MIN));
        assert!(matches!(
            damaged(24, &[0x7f, 0xff, 0xff, 0xff]),
            Problem::PastEnd {
                data_len: i32::MAX,
                ..
            }
        ));
        assert_eq!(damaged(28 + 2, &[0xC3]), Problem::ChannelNotUtf8 { at: 2 });
        let text = Damage {
            offset: 35,
            problem: Problem::BadSync(0),
        }
        .to_string();
        assert_eq!(
            text,
            "byte 35: bad sync word 0x00000000 (expected 0xEDA1DA01)"
        );
    }

    #[test]
    fn a_huge_length_from_an_unsized_input_allocates_only_what_arrives() {
        let mut log = Vec::new();
        log.extend_from_slice(&SYNC.to_be_bytes());
        log.extend_from_slice(&[0; 16]);
        log.extend_from_slice(&1i32.to_be_bytes());
        log.extend_from_slice(&i32::MAX.to_be_bytes());
        log.extend_from_slice(b"C0123456789");
        let mut r = Reader::new(&log[..]);
        let d = r.next_event().unwrap_err();
        assert_eq!(
            d.problem,
            Problem::TruncatedBody {
                needed: 1 + i32::MAX as u64,
                found: 11
            }
        );
        assert!(r.buf.capacity() <= BUF_LEN, "{}", r.buf.capacity());
        // the damage is kept
        assert_eq!(r.next_event().unwrap_err(), d);

        // three times the buffer arrives: the buffer holds no more than twice what arrived
        let arrived = 3 * BUF_LEN;
        log.truncate(HEADER_LEN + 1);
        log.resize(HEADER_LEN + 1 + arrived, 7);
        let mut r = Reader::new(&log[..]);
        assert_eq!(
            r.next_event().unwrap_err().problem,
            Problem::TruncatedBody {
                needed: 1 + i32::MAX as u64,
                found: 1 + arrived as u64
            }
        );
        assert!(r.buf.capacity() <= 2 * (HEADER_LEN + 1 + arrived));
    }

    /// An input that hands out at most `most` bytes a read.
    struct Dribble<'a> {
        data: &'a [u8],
        most: usize,
    }

    impl Read for Dribble<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let n = self.most.min(buf.len()).min(self.data.len());
            buf[..n].copy_from_slice(&self.data[..n]);
            self.data = &self.data[n..];
            Ok(n)
        }
    }

    #[test]
    fn events_larger_than_the_buffer_read_and_the_memory_is_given_back() {
        // small events across many refills, then large ones in a row, then small ones again
        let sizes: Vec<usize> = (0..3000)
            .map(|i| i * 37 % 300)
            .chain([
                BUF_LEN,
                3 * BUF_LEN + 5,
                BUF_LEN - HEADER_LEN - 4,
                2 * BUF_LEN,
            ])
            .chain((0..3000).map(|i| i * 53 % 5000))
            .collect();
        let mut w = Writer::new(Vec::new());
        for (i, &n) in sizes.iter().enumerate() {
            let data: Vec<u8> = (0..n).map(|b| (b * 31 + i) as u8).collect();
            w.write(i as i64, &format!("CH{}", i % 17), &data).unwrap();
        }
        let log = w.finish().unwrap();
        for name in ["sized", "unsized", "dribbled"] {
            let mut r: Reader<Box<dyn Read + '_>> = match name {
                "sized" => Reader::with_size(Box::new(&log[..]), log.len() as u64),
                "unsized" => Reader::new(Box::new(&log[..])),
                _ => Reader::new(Box::new(Dribble {
                    data: &log,
                    most: 4093,
                })),
            };
            let (mut offset, mut run) = (0, 0);
            for (i, &n) in sizes.iter().enumerate() {
                let e = r.next_event().unwrap().unwrap();
                assert_eq!((e.number, e.timestamp), (i as i64, i as i64), "{name}");
                assert_eq!(e.channel, format!("CH{}", i % 17), "{name}");
                assert_eq!(e.data.len(), n, "{name}");
                assert!(
                    e.data
                        .iter()
                        .enumerate()
                        .all(|(b, &v)| v == (b * 31 + i) as u8),
                    "{name}: event {i}"
                );
                let len = e.encoded_len() as usize;
                offset += len as u64;
                assert_eq!(r.offset(), offset, "{name}");
                // the buffer holds the largest of a run of events larger than it, and no more
                run = if len > BUF_LEN { run.max(len) } else { 0 };
                assert!(
                    r.buf.len() <= BUF_LEN.max(run),
                    "{name}: event {i}: {} bytes",
                    r.buf.len()
                );
            }
            assert_eq!(r.next_event(), Ok(None), "{name}");
            assert!(r.buf.capacity() <= BUF_LEN, "{name}: {}", r.buf.capacity());
        }
    }

    #[test]
    fn the_writer_refuses_what_a_log_cannot_hold() {
        let mut w = Writer::new(Vec::new());
        assert!(matches!(
            w.write(0, "", b""),
            Err(WriteError::ChannelLength(0))
        ));
        let long = "c".repeat(1000);
        assert!(matches!(
            w.write(0, &long, b""),
            Err(WriteError::ChannelLength(1000))
        ));
        w.write(0, &long[..999], b"").unwrap();
        assert_eq!(w.events(), 1);
    }
}
