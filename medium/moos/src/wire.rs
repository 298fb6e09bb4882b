//! The MOOS V10 wire format: messages and packets, little-endian, read by [`read_packet`] (owned
//! messages) or [`visit_packet`] (messages borrowed where they lie, [`MoosRef`]) without ever
//! panicking (lengths are capped), and written by [`Packet::encode`] or, for a packet built in
//! place, [`seal_packet`].
//!
//! A message is: int32 total length (itself included), int32 id, u8 message type, u8 data type
//! (`D` double, `S` string, `B` binary — carried in the string field), then the strings source,
//! source aux, community and key, the doubles time, value and value 2, and the string value. A
//! string is an int32 length and its bytes. A packet is: int32 total length (its 9-byte header
//! included), int32 message count, one byte of compression flag (always 0), then the messages.

use seabus_medium::WireError;

/// The handshake a client sends first: these bytes, NUL-padded to 32.
pub const HANDSHAKE: &[u8] = b"ELKS CAN'T DANCE 2/8/10";
/// The handshake's length on the wire.
pub const HANDSHAKE_LEN: usize = 32;
/// The packet header's length.
pub const PACKET_HEADER: usize = 9;
/// The smallest message: its fixed fields and five empty strings.
pub const MIN_MESSAGE: usize = 54;
/// The largest packet a reader takes (MOOS itself trusts any length).
pub const MAX_PACKET: usize = 16 << 20;

/// Message types.
pub mod kind {
    /// A variable's new value.
    pub const NOTIFY: u8 = b'N';
    /// Register for a variable (value = minimum interval in seconds).
    pub const REGISTER: u8 = b'R';
    /// Unregister.
    pub const UNREGISTER: u8 = b'U';
    /// Register by pattern.
    pub const WILDCARD_REGISTER: u8 = b'*';
    /// Unregister by pattern.
    pub const WILDCARD_UNREGISTER: u8 = b'/';
    /// A command.
    pub const COMMAND: u8 = b'C';
    /// Nothing.
    pub const NULL: u8 = b'.';
    /// Data (the handshake's introduction).
    pub const DATA: u8 = b'i';
    /// The server refuses the client.
    pub const POISON: u8 = b'K';
    /// The server welcomes the client.
    pub const WELCOME: u8 = b'W';
    /// A request to the server.
    pub const SERVER_REQUEST: u8 = b'Q';
    /// Timing (keep-alive and clock skew).
    pub const TIMING: u8 = b'T';
}

/// Data types.
pub mod data {
    /// A double.
    pub const DOUBLE: u8 = b'D';
    /// A string.
    pub const STRING: u8 = b'S';
    /// Binary data (in the string field).
    pub const BINARY: u8 = b'B';
}

/// One MOOS message.
#[derive(Debug, Clone, PartialEq)]
pub struct MoosMsg {
    /// Message id.
    pub id: i32,
    /// Message type ([`kind`]).
    pub kind: u8,
    /// Data type ([`data`]).
    pub data_type: u8,
    /// The publishing client.
    pub source: Vec<u8>,
    /// More about the source.
    pub source_aux: Vec<u8>,
    /// The originating community.
    pub community: Vec<u8>,
    /// The variable.
    pub key: Vec<u8>,
    /// When (UNIX seconds).
    pub time: f64,
    /// The double value.
    pub value: f64,
    /// A second double.
    pub value2: f64,
    /// The string (or binary) value.
    pub string: Vec<u8>,
}

impl Default for MoosMsg {
    fn default() -> Self {
        MoosMsg {
            id: 0,
            kind: kind::NULL,
            data_type: data::DOUBLE,
            source: Vec::new(),
            source_aux: Vec::new(),
            community: Vec::new(),
            key: Vec::new(),
            time: 0.0,
            value: 0.0,
            value2: 0.0,
            string: Vec::new(),
        }
    }
}

fn bad(offset: usize, reason: &'static str, what: impl Into<String>) -> WireError {
    WireError::at(offset, reason, what)
}

impl MoosMsg {
    /// The message's length on the wire.
    pub fn encoded_len(&self) -> usize {
        self.borrowed().encoded_len()
    }

    /// Appends the message.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        self.borrowed().encode_into(out);
    }

    /// The message as a [`MoosRef`] borrowing this one's strings.
    pub fn borrowed(&self) -> MoosRef<'_> {
        MoosRef {
            id: self.id,
            kind: self.kind,
            data_type: self.data_type,
            source: &self.source,
            source_aux: &self.source_aux,
            community: &self.community,
            key: &self.key,
            time: self.time,
            value: self.value,
            value2: self.value2,
            string: &self.string,
        }
    }

    /// Reads one message from the start of `d` (`at` is its offset in the packet, for errors);
    /// returns it and its length.
    pub fn decode(d: &[u8], at: usize) -> Result<(MoosMsg, usize), WireError> {
        MoosRef::decode(d, at).map(|(m, n)| (m.to_owned(), n))
    }

    /// The key as text (lossy).
    pub fn key_str(&self) -> String {
        self.borrowed().key_str().into_owned()
    }
}

/// One MOOS message whose strings are borrowed from the bytes it was read from (or from a
/// [`MoosMsg`]): what a reader that only looks at a message takes, without copying it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoosRef<'a> {
    /// Message id.
    pub id: i32,
    /// Message type ([`kind`]).
    pub kind: u8,
    /// Data type ([`data`]).
    pub data_type: u8,
    /// The publishing client.
    pub source: &'a [u8],
    /// More about the source.
    pub source_aux: &'a [u8],
    /// The originating community.
    pub community: &'a [u8],
    /// The variable.
    pub key: &'a [u8],
    /// When (UNIX seconds).
    pub time: f64,
    /// The double value.
    pub value: f64,
    /// A second double.
    pub value2: f64,
    /// The string (or binary) value.
    pub string: &'a [u8],
}

impl<'a> MoosRef<'a> {
    /// The message's length on the wire.
    pub fn encoded_len(&self) -> usize {
        MIN_MESSAGE
            + self.source.len()
            + self.source_aux.len()
            + self.community.len()
            + self.key.len()
            + self.string.len()
    }

    /// Appends the message.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        let s = |out: &mut Vec<u8>, v: &[u8]| {
            out.extend_from_slice(&(v.len() as i32).to_le_bytes());
            out.extend_from_slice(v);
        };
        out.reserve(self.encoded_len());
        out.extend_from_slice(&(self.encoded_len() as i32).to_le_bytes());
        out.extend_from_slice(&self.id.to_le_bytes());
        out.push(self.kind);
        out.push(self.data_type);
        s(out, self.source);
        s(out, self.source_aux);
        s(out, self.community);
        s(out, self.key);
        out.extend_from_slice(&self.time.to_le_bytes());
        out.extend_from_slice(&self.value.to_le_bytes());
        out.extend_from_slice(&self.value2.to_le_bytes());
        s(out, self.string);
    }

    /// A [`MoosMsg`] owning copies of the strings.
    pub fn to_owned(&self) -> MoosMsg {
        MoosMsg {
            id: self.id,
            kind: self.kind,
            data_type: self.data_type,
            source: self.source.to_vec(),
            source_aux: self.source_aux.to_vec(),
            community: self.community.to_vec(),
            key: self.key.to_vec(),
            time: self.time,
            value: self.value,
            value2: self.value2,
            string: self.string.to_vec(),
        }
    }

    /// The key as text (lossy).
    pub fn key_str(&self) -> std::borrow::Cow<'a, str> {
        String::from_utf8_lossy(self.key)
    }

    /// Reads one message from the start of `d` (`at` is its offset in the packet, for errors);
    /// returns it and its length.
    pub fn decode(d: &'a [u8], at: usize) -> Result<(MoosRef<'a>, usize), WireError> {
        let short = |pos: usize| bad(at + pos, "moos-short", "the packet ends inside a message");
        let int = |pos: usize| -> Result<i32, WireError> {
            d.get(pos..pos + 4)
                .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .ok_or_else(|| short(pos))
        };
        let double = |pos: usize| -> Result<f64, WireError> {
            d.get(pos..pos + 8)
                .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                .ok_or_else(|| short(pos))
        };
        let len = int(0)?;
        let len = usize::try_from(len)
            .ok()
            .filter(|l| *l >= MIN_MESSAGE)
            .ok_or_else(|| {
                bad(
                    at,
                    "moos-bad-length",
                    format!("a message length of {len} (at least {MIN_MESSAGE})"),
                )
            })?;
        if len > d.len() {
            return Err(bad(
                at,
                "moos-bad-length",
                format!("a message of {len} bytes in the {} left", d.len()),
            ));
        }
        let d = &d[..len];
        let mut pos = 4;
        let id = int(pos)?;
        pos += 4;
        let (kind, data_type) = (d[pos], d[pos + 1]);
        pos += 2;
        let string = |pos: &mut usize| -> Result<&'a [u8], WireError> {
            let n = int(*pos)?;
            let n = usize::try_from(n).map_err(|_| {
                bad(
                    at + *pos,
                    "moos-bad-length",
                    format!("a string length of {n}"),
                )
            })?;
            let start = *pos + 4;
            let v = d.get(start..start.saturating_add(n)).ok_or_else(|| {
                bad(
                    at + *pos,
                    "moos-bad-length",
                    format!("a string of {n} bytes past the message's end"),
                )
            })?;
            *pos = start + n;
            Ok(v)
        };
        let source = string(&mut pos)?;
        let source_aux = string(&mut pos)?;
        let community = string(&mut pos)?;
        let key = string(&mut pos)?;
        let time = double(pos)?;
        let value = double(pos + 8)?;
        let value2 = double(pos + 16)?;
        pos += 24;
        let text = string(&mut pos)?;
        if pos != len {
            return Err(bad(
                at + pos,
                "moos-bad-length",
                format!(
                    "{} bytes after the fields of a {len}-byte message",
                    len - pos
                ),
            ));
        }
        Ok((
            MoosRef {
                id,
                kind,
                data_type,
                source,
                source_aux,
                community,
                key,
                time,
                value,
                value2,
                string: text,
            },
            len,
        ))
    }
}

/// A packet: messages sent together.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Packet {
    /// The messages, in order.
    pub messages: Vec<MoosMsg>,
}

impl Packet {
    /// The packet's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let len = PACKET_HEADER
            + self
                .messages
                .iter()
                .map(MoosMsg::encoded_len)
                .sum::<usize>();
        let mut out = Vec::with_capacity(len);
        out.resize(PACKET_HEADER, 0);
        for m in &self.messages {
            m.encode_into(&mut out);
        }
        seal_packet(&mut out, self.messages.len());
        out
    }
}

/// What the start of a byte stream holds.
#[derive(Debug, Clone, PartialEq)]
pub enum Read {
    /// A whole packet, and the bytes it took.
    Packet(Packet, usize),
    /// Not all of it yet: at least this many bytes in all are needed.
    Incomplete(usize),
}

/// Reads a packet from the start of `d`: complete, incomplete, or malformed (the stream cannot be
/// trusted after that).
pub fn read_packet(d: &[u8]) -> Result<Read, WireError> {
    let mut messages = Vec::new();
    Ok(match visit_packet(d, |m| messages.push(m.to_owned()))? {
        Visited::Packet(n) => Read::Packet(Packet { messages }, n),
        Visited::Incomplete(n) => Read::Incomplete(n),
    })
}

/// What [`visit_packet`] found at the start of a byte stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Visited {
    /// A whole packet, its messages visited, and the bytes it took.
    Packet(usize),
    /// Not all of it yet: at least this many bytes in all are needed (nothing visited).
    Incomplete(usize),
}

/// Reads a packet from the start of `d` as [`read_packet`] does, handing each message to `each`
/// borrowed from `d`, in order, once the whole packet has proved well formed (nothing of a
/// malformed packet is handed on).
pub fn visit_packet<'a>(
    d: &'a [u8],
    mut each: impl FnMut(MoosRef<'a>),
) -> Result<Visited, WireError> {
    if d.len() < PACKET_HEADER {
        return Ok(Visited::Incomplete(PACKET_HEADER));
    }
    let len = i32::from_le_bytes([d[0], d[1], d[2], d[3]]);
    let count = i32::from_le_bytes([d[4], d[5], d[6], d[7]]);
    let len = usize::try_from(len)
        .ok()
        .filter(|l| (PACKET_HEADER..=MAX_PACKET).contains(l))
        .ok_or_else(|| {
            bad(
                0,
                "moos-bad-length",
                format!("a packet length of {len} (from {PACKET_HEADER} to {MAX_PACKET})"),
            )
        })?;
    let count = usize::try_from(count)
        .ok()
        .filter(|c| *c <= (len - PACKET_HEADER) / MIN_MESSAGE)
        .ok_or_else(|| {
            bad(
                4,
                "moos-bad-count",
                format!("{count} messages cannot fit in a {len}-byte packet"),
            )
        })?;
    if d.len() < len {
        return Ok(Visited::Incomplete(len));
    }
    let body = &d[..len];
    // checked whole first, then handed out: decoding a borrowed message copies nothing
    let mut at = PACKET_HEADER;
    for _ in 0..count {
        at += MoosRef::decode(&body[at..], at)?.1;
    }
    if at != len {
        return Err(bad(
            at,
            "moos-bad-length",
            format!(
                "{} bytes after the {count} messages of the packet",
                len - at
            ),
        ));
    }
    let mut at = PACKET_HEADER;
    for _ in 0..count {
        let (m, n) = MoosRef::decode(&body[at..], at)?;
        each(m);
        at += n;
    }
    Ok(Visited::Packet(len))
}

/// A packet of `count` messages whose encodings follow a [`PACKET_HEADER`] of room at the start
/// of `packet`: writes its header there.
pub fn seal_packet(packet: &mut [u8], count: usize) {
    let len = packet.len() as i32;
    packet[..4].copy_from_slice(&len.to_le_bytes());
    packet[4..8].copy_from_slice(&(count as i32).to_le_bytes());
    packet[8] = 0;
}

/// The 32 handshake bytes.
pub fn handshake() -> [u8; HANDSHAKE_LEN] {
    let mut h = [0u8; HANDSHAKE_LEN];
    h[..HANDSHAKE.len()].copy_from_slice(HANDSHAKE);
    h
}

/// What a client sends first: the handshake, then a packet with its `name` (and its clock, `time`,
/// from which the DB works out the skew).
pub fn hello(name: &str, time: f64) -> Vec<u8> {
    let intro = MoosMsg {
        id: -1,
        kind: kind::DATA,
        data_type: data::STRING,
        key: b"asynchronous".to_vec(),
        time,
        string: name.as_bytes().to_vec(),
        ..MoosMsg::default()
    };
    let mut out = handshake().to_vec();
    out.extend(
        Packet {
            messages: vec![intro],
        }
        .encode(),
    );
    out
}

/// Reads from `sock` until `buf` holds a whole packet (waiting at most `silence` for each read);
/// takes the packet out of `buf`. The error says why: closed, silent, or malformed.
pub async fn next_packet(
    sock: &mut (impl tokio::io::AsyncRead + Unpin),
    buf: &mut Vec<u8>,
    silence: std::time::Duration,
) -> Result<Packet, String> {
    use tokio::io::AsyncReadExt;
    loop {
        match read_packet(buf) {
            Ok(Read::Packet(p, n)) => {
                buf.drain(..n);
                return Ok(p);
            }
            Ok(Read::Incomplete(_)) => {}
            Err(e) => return Err(format!("malformed packet: {e}")),
        }
        let mut chunk = [0u8; 65_536];
        match tokio::time::timeout(silence, sock.read(&mut chunk)).await {
            Err(_) => return Err(format!("silent for {silence:?}")),
            Ok(Ok(0)) => return Err("the connection closed".into()),
            Ok(Ok(n)) => buf.extend_from_slice(&chunk[..n]),
            Ok(Err(e)) => return Err(e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn notify() -> MoosMsg {
        MoosMsg {
            id: 7,
            kind: kind::NOTIFY,
            data_type: data::DOUBLE,
            source: b"pNav".to_vec(),
            key: b"NAV_DEPTH".to_vec(),
            time: 1_795_000_000.5,
            value: 12.25,
            ..MoosMsg::default()
        }
    }

    #[test]
    fn a_message_is_laid_out_as_the_notes_say() {
        let m = notify();
        let mut out = Vec::new();
        m.encode_into(&mut out);
        assert_eq!(out.len(), 54 + 4 + 9);
        assert_eq!(&out[..4], &(67i32).to_le_bytes());
        assert_eq!(&out[4..8], &7i32.to_le_bytes());
        assert_eq!(&out[8..10], b"ND");
        assert_eq!(&out[10..18], b"\x04\0\0\0pNav");
        // aux and community empty, then the key
        assert_eq!(&out[18..26], &[0; 8]);
        assert_eq!(&out[26..39], b"\x09\0\0\0NAV_DEPTH");
        assert_eq!(&out[39..47], &1_795_000_000.5f64.to_le_bytes());
        assert_eq!(&out[47..55], &12.25f64.to_le_bytes());
        assert_eq!(&out[63..67], &[0; 4]);
        assert_eq!(MoosMsg::decode(&out, 0).unwrap(), (m, 67));
    }

    #[test]
    fn packets_read_whole_in_pieces_and_refuse_lies() {
        let p = Packet {
            messages: vec![
                notify(),
                MoosMsg {
                    kind: kind::NOTIFY,
                    data_type: data::STRING,
                    key: b"NODE_REPORT".to_vec(),
                    string: b"NAME=auv1,X=10,Y=-4".to_vec(),
                    ..MoosMsg::default()
                },
            ],
        };
        let bytes = p.encode();
        assert_eq!(&bytes[..4], &(bytes.len() as i32).to_le_bytes());
        assert_eq!(&bytes[4..9], &[2, 0, 0, 0, 0]);
        assert_eq!(read_packet(&bytes).unwrap(), Read::Packet(p, bytes.len()));
        assert_eq!(read_packet(&bytes[..5]).unwrap(), Read::Incomplete(9));
        assert_eq!(
            read_packet(&bytes[..20]).unwrap(),
            Read::Incomplete(bytes.len())
        );
        let mut lie = bytes.clone();
        lie[0..4].copy_from_slice(&i32::MAX.to_le_bytes());
        assert_eq!(read_packet(&lie).unwrap_err().kind(), "moos-bad-length");
        let mut lie = bytes.clone();
        lie[4..8].copy_from_slice(&1000i32.to_le_bytes());
        assert_eq!(
            read_packet(&lie).unwrap_err().to_string(),
            format!(
                "byte 4: 1000 messages cannot fit in a {}-byte packet",
                bytes.len()
            )
        );
        let mut lie = bytes.clone();
        // the first message's key says 9000 bytes
        lie[9 + 26..9 + 30].copy_from_slice(&9000i32.to_le_bytes());
        assert_eq!(
            read_packet(&lie).unwrap_err().to_string(),
            "byte 35: a string of 9000 bytes past the message's end"
        );
    }

    #[test]
    fn a_packet_visited_hands_out_its_messages_borrowed_in_order() {
        let p = Packet {
            messages: vec![
                notify(),
                MoosMsg {
                    kind: kind::NOTIFY,
                    data_type: data::BINARY,
                    key: b"IMAGE".to_vec(),
                    string: vec![0, 255, 7],
                    ..MoosMsg::default()
                },
            ],
        };
        let mut bytes = p.encode();
        let whole = bytes.len();
        // a second packet behind it is not touched
        bytes.extend_from_slice(&Packet::default().encode());
        let mut seen = Vec::new();
        let read = visit_packet(&bytes, |m| seen.push(m)).unwrap();
        assert_eq!(read, Visited::Packet(whole));
        assert_eq!(seen.len(), 2);
        assert_eq!(seen[0], p.messages[0].borrowed());
        assert_eq!(seen[1].string, &[0, 255, 7]);
        assert_eq!(seen[1].to_owned(), p.messages[1]);
        // nothing of a malformed packet is handed out: here its second message's key runs past
        // the message
        let mut bad = bytes[..whole].to_vec();
        let second = PACKET_HEADER + p.messages[0].encoded_len();
        bad[second + 22..second + 26].copy_from_slice(&9000i32.to_le_bytes());
        let mut none = 0;
        assert!(visit_packet(&bad, |_| none += 1).is_err());
        assert_eq!(none, 0);
        // nor of a packet not all there
        let mut none = 0;
        let read = visit_packet(&bytes[..whole - 1], |_| none += 1).unwrap();
        assert_eq!((read, none), (Visited::Incomplete(whole), 0));
        // a packet sealed over room left at its start is the one encoded
        let mut sealed = vec![0xAA; PACKET_HEADER];
        p.messages.iter().for_each(|m| m.encode_into(&mut sealed));
        seal_packet(&mut sealed, 2);
        assert_eq!(sealed, p.encode());
    }

    #[test]
    fn the_handshake_is_32_bytes() {
        let h = handshake();
        assert_eq!(&h[..23], b"ELKS CAN'T DANCE 2/8/10");
        assert!(h[23..].iter().all(|b| *b == 0));
    }
}
