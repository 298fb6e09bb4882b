//! Properties of the seabus-drivers sentence readers that every input must keep. Each function
//! panics when an input breaks a property and tells whether the input was a valid one.

use seabus_drivers::iver::protocol::{DepthUnits, FromFront, parse_command, parse_front};
use seabus_drivers::nmea::attitude::Table;
use seabus_drivers::nmea::sensors::{Role, Sensor};
use seabus_drivers::nmea::sentence::{Parsed, parse};
use seabus_medium::framing::{self, ChecksumPolicy, check_nmea};
use seabus_modules::{Catalogue, Params};

/// `text` (without a leading `$` or, when `bang` is set, `!`) written as a `$` sentence with its
/// checksum, when it is not already a whole sentence with a correct checksum and can be a sentence
/// body: printable ASCII without `*`.
fn wrapped(text: &str, bang: bool) -> Option<String> {
    if check_nmea(text.as_bytes(), ChecksumPolicy::Require).is_ok() {
        return None;
    }
    let starts: &[char] = if bang { &['$', '!'] } else { &['$'] };
    let body = text.strip_prefix(starts).unwrap_or(text);
    let printable = body
        .bytes()
        .all(|b| (0x20..=0x7e).contains(&b) && b != b'*');
    printable.then(|| framing::nmea_sentence(b'$', body))
}

/// Every NMEA driver reads `parsed`, and each dataset it makes is one the catalogue accepts: no
/// value out of its range (a bearing past 360°, a negative depth, a DOP past 99.99) is published.
fn every_driver_reads(parsed: &Parsed, text: &str) {
    let cat = Catalogue::built_in();
    let none = Params::from_pairs(&[]);
    let now = tokio::time::Instant::now();
    for role in [
        Role::Gps,
        Role::Heading,
        Role::Sounder,
        Role::Wind,
        Role::Log,
        Role::Steering,
    ] {
        let (mut sensor, _) = Sensor::new(&none, &cat, role).expect("a driver with no parameters");
        // twice, so that pitch and roll kept from the first reading meet the second
        for _ in 0..2 {
            for (i, map) in sensor.read(parsed, now) {
                let dataset = sensor.dataset_of(i).expect("an output of the driver");
                if let Err(e) = cat.validate(dataset, &map) {
                    panic!("{text:?} gave a {dataset} the catalogue refuses: {e}: {map:?}");
                }
            }
        }
    }
}

/// The NMEA 0183 sentence parser of the NMEA drivers: any text is read or refused without a panic,
/// and what every driver makes of a sentence that reads is a dataset the catalogue accepts. Text
/// that is not a whole sentence with a correct checksum is also read as the body of one, so that
/// the parsers behind a known address see well-framed sentences too; such a built sentence carries
/// a correct checksum. True when `data` is UTF-8 text that parses as it is.
pub fn nmea_sentence(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let parsed = parse(text);
    if let Ok(p) = &parsed {
        every_driver_reads(p, text);
    }
    if let Some(line) = wrapped(text, true) {
        if line.len() > 4 {
            assert_eq!(
                check_nmea(line.as_bytes(), ChecksumPolicy::Require).as_deref(),
                Ok(line.as_bytes()),
                "a built sentence carries a correct checksum: {line:?}"
            );
        }
        if let Ok(p) = parse(&line) {
            every_driver_reads(&p, &line);
        }
    }
    parsed.is_ok()
}

/// The proprietary attitude table: any text is read as a table or refused with an error placed in
/// the file, without a panic; a table that reads reads any sentence's fields (the text's last line,
/// split at commas, under each of its addresses) without a panic, to finite angles only. True when
/// the text is a table.
pub fn nmea_attitude_table(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let table = match Table::parse("table.xml", text) {
        Ok(t) => t,
        Err(e) => {
            assert!(e.to_string().starts_with("table.xml:"), "{e}");
            return false;
        }
    };
    let fields: Vec<Box<str>> = text
        .lines()
        .last()
        .unwrap_or_default()
        .split(',')
        .map(Box::from)
        .collect();
    for address in table.addresses() {
        if let Some(Ok((angles, _))) = table.read(address, &fields) {
            for a in [angles.pitch, angles.roll, angles.heading]
                .into_iter()
                .flatten()
            {
                assert!(a.is_finite(), "{address}: {a}");
            }
        }
    }
    true
}

/// The frontseat sentence written back, for the kinds the simulated frontseat sends.
fn written(front: &FromFront) -> Option<String> {
    match front {
        FromFront::Osi(o) => Some(o.sentence()),
        FromFront::Compass(c) => Some(c.sentence()),
        FromFront::Opi(p) => Some(p.sentence()),
        FromFront::Ack(a) => Some(a.sentence()),
        FromFront::Dvl(d) => Some(d.sentence()),
        FromFront::Rmc(_) | FromFront::Other(_) => None,
    }
}

/// Reads `line` as a frontseat sentence and as a command in both depth units, checks that what
/// reads also writes back and reads again, and tells whether anything read that writes back.
fn remote_helm_check(line: &str) -> bool {
    let mut read = false;
    if let Ok(front) = parse_front(line)
        && let Some(out) = written(&front)
    {
        let back = parse_front(&out).unwrap_or_else(|e| panic!("{out:?} does not read: {e}"));
        assert_eq!(
            std::mem::discriminant(&back),
            std::mem::discriminant(&front),
            "{out:?} reads as another kind of sentence"
        );
        if let FromFront::Ack(_) = front {
            assert_eq!(back, front, "$ACK round trip via {out:?}");
        }
        read = true;
    }
    for units in [DepthUnits::Feet, DepthUnits::Metres] {
        let Ok(cmd) = parse_command(line, units) else {
            continue;
        };
        let out = cmd.sentence(units);
        let back =
            parse_command(&out, units).unwrap_or_else(|e| panic!("{out:?} does not read: {e}"));
        assert_eq!(back.ack_code(), cmd.ack_code(), "round trip via {out:?}");
        assert_eq!(back.name(), cmd.name(), "round trip via {out:?}");
        read = true;
    }
    read
}

/// The Iver Remote Helm protocol: any text is read as a frontseat sentence and as a backseat command
/// (in feet and in metres) without a panic, and every sentence read is written back to a sentence
/// that reads as the same kind of sentence. Text that is not a whole sentence with a correct
/// checksum is also read as the body of one. True when `data` is UTF-8 text that, as it is or as a
/// sentence body, reads as a sentence or command that writes back.
pub fn remote_helm(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let mut read = remote_helm_check(text);
    if let Some(line) = wrapped(text, false) {
        read |= remote_helm_check(&line);
    }
    read
}

/// CAN signals: a signal made from the first five bytes (start bit, size, byte order, raw type,
/// factor, offset) that fits in the rest (the frame data) decodes without a panic; its raw bits
/// written into empty data read back the same; and its physical value encodes back to the same raw
/// bits (integer fields of up to 52 bits, whose values a float holds exactly). True when the
/// signal fits.
pub fn dbc_signals(data: &[u8]) -> bool {
    use seabus_drivers::can::dbc::{Mux, RawType, Signal, fits};
    if data.len() < 6 {
        return false;
    }
    let (head, frame) = data.split_at(5);
    let frame = &frame[..frame.len().min(64)];
    let start = u32::from(head[0]);
    let size = 1 + u32::from(head[1] % 64);
    let little = head[2] & 1 == 1;
    let raw_type = match (head[2] >> 1) & 3 {
        2 if size == 32 => RawType::Float,
        3 if size == 64 => RawType::Double,
        1 | 3 => RawType::Signed,
        _ => RawType::Unsigned,
    };
    let factor = [1.0, 2.0, -1.0, 0.5, 0.25][usize::from(head[3] % 5)];
    let offset = f64::from(head[4] as i8);
    if !fits(start.into(), size.into(), little, frame.len()) {
        return false;
    }
    let signal = Signal {
        name: "S".into(),
        start,
        size,
        little_endian: little,
        raw_type,
        factor,
        offset,
        min: 0.0,
        max: 0.0,
        unit: String::new(),
        mux: Mux::Plain,
        values: Default::default(),
        start_value: 0,
    };
    let raw = signal.raw_bits(frame);
    let mut empty = vec![0u8; frame.len()];
    signal.put_bits(&mut empty, raw);
    assert_eq!(signal.raw_bits(&empty), raw, "raw bits do not read back");
    let value = signal.decode(frame);
    if matches!(raw_type, RawType::Signed | RawType::Unsigned) && size <= 52 {
        let back = signal
            .encode_value(&value)
            .unwrap_or_else(|e| panic!("a decoded value does not encode: {e}"));
        assert_eq!(back, raw, "{value} encodes to other raw bits");
    }
    true
}

/// Every finite-number and list check of a decoded NMEA 2000 datamap: no NaN or infinity
/// anywhere in it.
fn n2k_finite(what: &str, v: &seabus_medium::Value) {
    use seabus_medium::Value;
    match v {
        Value::Float(x) => assert!(x.is_finite(), "{what}: {x}"),
        Value::List(items) => items.iter().for_each(|i| n2k_finite(what, i)),
        Value::Map(m) => m
            .iter()
            .for_each(|(k, v)| n2k_finite(&format!("{what}.{k}"), v)),
        _ => {}
    }
}

/// NMEA 2000 frames through the `nmea2000` driver: the input is a sequence of frames, each a
/// flags byte (bit 0 extended, bit 1 remote, bits 2–7 the milliseconds since the previous frame,
/// ×16), four bytes of identifier (big-endian), a length byte (its value modulo 10, so that
/// lengths past 8 occur) and that many data bytes. Any sequence is read without a panic; every
/// message it gives is at most 1785 bytes; every value decoded is finite; every dataset made is
/// one the catalogue accepts; at most `max_partial` messages are ever under way. Each message
/// longer than a frame that came out of a fast packet, framed again by [`fast_frames`], comes out
/// of a fresh assembler as the same bytes. True when at least one frame was whole.
pub fn n2k_frames(data: &[u8]) -> bool {
    use seabus_drivers::n2k::builtin;
    use seabus_drivers::n2k::driver::Nmea2000;
    use seabus_drivers::n2k::frame::{Assembler, Header, Limits, TP_DT, fast_frames};
    use seabus_drivers::n2k::pgn::Packet;
    use seabus_medium_can::frame::CanFrame;
    use std::time::Duration;
    let params = Params::from_pairs(&[("max_partial", "8")]);
    let cat = Catalogue::built_in();
    let (mut driver, _) = Nmea2000::new(&params, &cat).expect("a driver with no parameters");
    let db = builtin::database();
    let mut assembler = Assembler::new(Limits {
        max_partial: 8,
        ..Limits::default()
    });
    let mut now = tokio::time::Instant::now();
    let mut rest = data;
    let mut whole = false;
    while rest.len() >= 6 {
        let flags = rest[0];
        let id = u32::from_be_bytes([rest[1], rest[2], rest[3], rest[4]]) & 0x1FFF_FFFF;
        let len = usize::from(rest[5] % 10).min(rest.len() - 6);
        let payload = &rest[6..6 + len];
        rest = &rest[6 + len..];
        now += Duration::from_millis(u64::from(flags >> 2) * 16);
        let extended = flags & 1 == 1;
        let frame = if flags & 2 == 2 {
            CanFrame::remote(
                if extended { id } else { id & 0x7FF },
                extended,
                len.min(8) as u8,
            )
        } else if len > 8 {
            CanFrame::fd(
                if extended { id } else { id & 0x7FF },
                extended,
                &[0; 12],
                false,
                false,
            )
        } else {
            CanFrame::data(if extended { id } else { id & 0x7FF }, extended, payload)
        };
        let Ok(frame) = frame else { continue };
        whole = true;
        for (topic, dataset, map) in driver.take(&frame, now) {
            for (k, v) in map.iter() {
                n2k_finite(&format!("{topic}.{k}"), v);
            }
            if !dataset.is_empty()
                && let Err(e) = cat.validate(dataset, &map)
            {
                panic!("{topic}: a {dataset} the catalogue refuses: {e}: {map:?}");
            }
        }
        // the assembler alone, to look at what it gives
        if let Some(m) = assembler.push(
            frame.id(),
            frame.is_extended(),
            !matches!(frame.kind(), seabus_medium_can::frame::FrameKind::Data),
            frame.payload(),
            |pgn| db.packet(pgn),
            now,
        ) {
            assert!(m.data.len() <= 1785, "a message of {} bytes", m.data.len());
            let via_tp = Header::from_id(frame.id()).pgn == TP_DT;
            let fast = db.packet(m.header.pgn) == Packet::Fast && !via_tp;
            if fast && !m.data.is_empty() {
                assert!(
                    m.data.len() <= 223,
                    "a fast packet of {} bytes",
                    m.data.len()
                );
                let mut fresh = Assembler::new(Limits::default());
                let again: Vec<_> = fast_frames(3, &m.data)
                    .iter()
                    .filter_map(|f| {
                        fresh.push(m.header.id(), true, false, f, |pgn| db.packet(pgn), now)
                    })
                    .collect();
                assert_eq!(again.len(), 1, "{:?} framed again", m.data);
                assert_eq!(again[0].data, m.data, "framed again");
                assert!(fresh.counts().is_empty(), "{:?}", fresh.counts());
            }
            // every definition of the set reads any message
            for def in db.iter() {
                for (k, v) in def.decode(&m.data).map.iter() {
                    n2k_finite(&format!("{}.{k}", def.id), v);
                }
            }
        }
        assert!(
            assembler.under_way() <= 8,
            "{} under way",
            assembler.under_way()
        );
        assembler.take_rejections();
    }
    whole
}

/// What the NMEA 2000 driver sends: the input's first byte picks a built-in PGN, the second says
/// how many entries (modulo 16) follow, and entries of 10 bytes each make its datamap — a byte
/// picking the field (past the fields: `list`, or a key the PGN has not), a byte picking the
/// value's type (integer, float from the 8 bytes' bits, a string, a bool, a list of strings,
/// bytes, a list of maps) and 8 value bytes. The encoder takes or refuses any map without a
/// panic; what it takes fits its framing (8 bytes for a single frame, 223 for a fast packet) and
/// decodes back to every number given, within one raw step (a bearing just below a full turn
/// may come back as 0). Then the rest of the input, as messages heard in chunks of 11 bytes (a
/// byte of source, one of destination, one choosing a claim, a request or another PGN, and 8
/// data bytes, the first of which gives the length modulo 10), goes to an address claimer: the
/// address it gives is always one a device may hold (0–251) or the null address (254), and every
/// frame it answers with is a claim from that address or a request from 254. True when the map
/// encoded.
pub fn n2k_send(data: &[u8]) -> bool {
    use seabus_drivers::n2k::builtin;
    use seabus_drivers::n2k::claim::{self, Claimer, Name, State};
    use seabus_drivers::n2k::frame::{GLOBAL, Header, Message};
    use seabus_drivers::n2k::pgn::{Kind, Packet};
    use seabus_medium::{DataMap, Value};
    let db = builtin::database();
    let defs: Vec<_> = db.iter().cloned().collect();
    let Some((&pick, mut rest)) = data.split_first() else {
        return false;
    };
    let def = &defs[usize::from(pick) % defs.len()];
    let Some((&entries, tail)) = rest.split_first() else {
        return false;
    };
    rest = tail;
    let mut map = DataMap::new();
    for _ in 0..entries % 16 {
        if rest.len() < 10 {
            break;
        }
        let (entry, tail) = rest.split_at(10);
        rest = tail;
        let mut b = [0u8; 8];
        b.copy_from_slice(&entry[2..]);
        let n = u64::from_le_bytes(b);
        let key = match usize::from(entry[0]) {
            i if i < def.fields.len() => def.fields[i].id.to_string(),
            i if i == def.fields.len() => "list".to_string(),
            _ => "nonsense".to_string(),
        };
        let text =
            || String::from_utf8_lossy(&entry[2..2 + usize::from(entry[2] % 7)]).into_owned();
        let value = match entry[1] % 8 {
            0 => Value::Int(n as i64 >> (entry[1] >> 3)),
            1 => Value::Float(f64::from_bits(n)),
            2 => Value::Float((n as i64 >> 40) as f64 / 1000.0),
            3 => Value::from(text()),
            4 => Value::Bool(n & 1 == 1),
            5 => Value::List(vec![Value::from(text())]),
            6 => Value::Bytes(entry[2..].to_vec()),
            _ => Value::List(vec![Value::Map(
                DataMap::new().and(
                    def.fields
                        .get(usize::from(entry[2]) % def.fields.len().max(1))
                        .map_or("x".to_string(), |f| f.id.to_string()),
                    Value::Int(i64::from(entry[3])),
                ),
            )]),
        };
        map.insert(key, value);
    }
    let encoded = match def.encode(&map) {
        Ok(bytes) => {
            let most = match def.packet {
                Packet::Single => 8,
                Packet::Fast => 223,
                Packet::Iso => 1785,
            };
            assert!(
                bytes.len() <= most,
                "{} bytes of PGN {}",
                bytes.len(),
                def.pgn
            );
            let back = def.decode(&bytes).map;
            for f in &def.fields {
                let (Kind::Number, Some(given)) = (&f.kind, map.get(&f.id).and_then(Value::as_f64))
                else {
                    continue;
                };
                let got = back.get(&f.id).and_then(Value::as_f64).unwrap_or_else(|| {
                    panic!(
                        "PGN {} {}: {given} was sent, nothing came back",
                        def.pgn, f.id
                    )
                });
                let step = (f.to_seabus(f.resolution) - f.to_seabus(0.0)).abs();
                let near = (got - given).abs() <= step * 0.5001 + 1e-9 * given.abs().max(1.0);
                let wrapped = got == 0.0 && (given - 360.0).abs() <= step;
                assert!(
                    near || wrapped,
                    "PGN {} {}: {given} sent, {got} back",
                    def.pgn,
                    f.id
                );
            }
            true
        }
        Err(e) => {
            assert!(e.reason.starts_with("n2k-send-"), "{e:?}");
            assert!(!e.detail.is_empty());
            false
        }
    };
    // the claimer, on what the rest of the input says was heard
    let name = Name {
        unique_number: u32::from(pick) * 1000,
        manufacturer_code: 2046,
        device_instance: 0,
        device_function: 130,
        device_class: 25,
        system_instance: 0,
        industry_group: 4,
        arbitrary_address_capable: pick & 1 == 0,
    };
    let mut now = tokio::time::Instant::now();
    let mut c = Claimer::new(name, pick % 252, now);
    // what a claimer sends must come from where it is when it sends it
    let check = |c: &Claimer, out: Vec<(Header, Vec<u8>)>| {
        for (h, d) in out {
            match h.pgn {
                claim::ADDRESS_CLAIM => {
                    assert_eq!(h.source, c.address(), "a claim from another address");
                    assert_eq!(d, c.name().to_le_bytes());
                }
                claim::REQUEST => assert_eq!(h.source, claim::NULL),
                other => panic!("the claimer sent PGN {other}"),
            }
        }
    };
    let started = c.start(now);
    assert_eq!(started.len(), 2);
    check(&c, started);
    for chunk in rest.chunks(11) {
        if chunk.len() < 3 {
            break;
        }
        let pgn = match chunk[2] % 3 {
            0 => claim::ADDRESS_CLAIM,
            1 => claim::REQUEST,
            _ => 127250,
        };
        let body = &chunk[3..];
        let len = usize::from(body.first().copied().unwrap_or(0) % 10).min(body.len());
        let msg = Message {
            header: Header {
                priority: 6,
                pgn,
                source: chunk[0],
                destination: if chunk[1] & 1 == 0 { GLOBAL } else { chunk[1] },
            },
            data: body[..len].to_vec(),
        };
        now += std::time::Duration::from_millis(u64::from(chunk[1]));
        let answer = c.take(&msg, now);
        check(&c, answer);
        c.take_events();
        let a = c.address();
        assert!(a <= claim::MAX_ADDRESS || a == claim::NULL, "address {a}");
        assert_eq!(c.state() == State::CannotClaim, a == claim::NULL);
        assert!(c.devices().len() <= 252);
        if let Some(s) = c.source(now) {
            assert_eq!(s, a);
        }
    }
    encoded
}
