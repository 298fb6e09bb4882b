use super::*;
use seabus_medium::{Origin, Provenance, Value};
use std::io::Cursor;

fn msg(topic: &str, kind: Kind, payload: Payload, stamp: i64, seq: u64) -> Message {
    Message {
        topic: Topic::new(topic).unwrap(),
        kind,
        provenance: Provenance {
            origin: Origin::new("auv1", "bus", 7),
            seq,
            hops: 0,
        },
        stamp: Stamp(stamp),
        payload,
    }
}

fn attitude(i: i64) -> DataMap {
    DataMap::new()
        .with("yaw", 10.0 + i as f64)
        .with("pitch", 1.5)
        .with("roll", -2.25)
}

/// A writer's output that the test can look at while the writer has it.
#[derive(Clone, Default)]
struct Shared(std::rc::Rc<std::cell::RefCell<Cursor<Vec<u8>>>>);

impl Write for Shared {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Seek for Shared {
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        self.0.borrow_mut().seek(pos)
    }
}

/// A file of `n` attitudes, a command, bytes and a topic no dataset names, flushed every
/// `flush_every` messages; its bytes and the offsets after each flush.
fn recording(n: i64, flush_every: i64) -> (Vec<u8>, Vec<u64>) {
    let out = Shared::default();
    let mut w = Writer::new(out.clone(), Catalogue::built_in()).unwrap();
    let mut flushed = Vec::new();
    for i in 0..n {
        let m = msg(
            "nav.attitude",
            Kind::Data,
            Payload::from(attitude(i)),
            1_000 + i,
            i as u64 + 1,
        );
        w.write(&m, Stamp(2_000 + i)).unwrap();
        if (i + 1) % flush_every == 0 {
            w.flush().unwrap();
            flushed.push(out.0.borrow().get_ref().len() as u64);
        }
    }
    let course = DataMap::new().with("heading", 90.0).with("depth", 2.0);
    w.write(
        &msg("cmd.course", Kind::Command, Payload::from(course), 5, 1),
        Stamp(6),
    )
    .unwrap();
    w.write(
        &msg("lcm.RAW", Kind::Data, Payload::from(vec![1u8, 2, 3]), 7, 2),
        Stamp(8),
    )
    .unwrap();
    let lab = DataMap::new()
        .with("count", 3i64)
        .with("label", "x")
        .with("blob", Value::Bytes(vec![0, 255]));
    w.write(
        &msg("lab.thing", Kind::Data, Payload::from(lab), 9, 3),
        Stamp(10),
    )
    .unwrap();
    assert_eq!(w.messages(), n as u64 + 3);
    assert_eq!(w.channels(), 4);
    w.finish().unwrap();
    let bytes = out.0.borrow().get_ref().clone();
    (bytes, flushed)
}

fn read_all(bytes: &[u8]) -> (Vec<ReadMessage>, Option<Damage>) {
    let mut r = Reader::new(Cursor::new(bytes.to_vec()));
    let mut out = Vec::new();
    for _ in 0..100_000 {
        match r.next_message() {
            Ok(Some(m)) => out.push(m),
            Ok(None) => return (out, None),
            Err(d) => return (out, Some(d)),
        }
    }
    panic!("the reader never ended");
}

#[test]
fn what_is_written_reads_back_with_channels_schemas_and_times() {
    let (bytes, _) = recording(50, 1000);
    let (messages, damage) = read_all(&bytes);
    assert_eq!(damage, None);
    assert_eq!(messages.len(), 53);
    let first = &messages[0];
    assert_eq!(first.channel.topic, "nav.attitude");
    assert_eq!(first.channel.message_encoding, JSON);
    assert_eq!(first.channel.schema_name, "seabus.attitude");
    assert_eq!(first.channel.schema_encoding, JSON_SCHEMA);
    let schema: serde_json::Value = serde_json::from_slice(&first.channel.schema).unwrap();
    assert_eq!(schema["properties"]["yaw"]["type"], "number");
    assert_eq!((first.log_time, first.publish_time), (2_000, 1_000));
    for (i, m) in messages[..50].iter().enumerate() {
        assert_eq!(m.sequence, i as u32);
        let Payload::Map(map) = payload_of(m).unwrap() else {
            panic!("a map")
        };
        assert_eq!(*map, attitude(i as i64));
    }
    let course = &messages[50];
    assert!(course.channel.is_command());
    assert!(!first.channel.is_command());
    let raw = &messages[51];
    assert_eq!(raw.channel.message_encoding, BYTES);
    assert_eq!(raw.channel.schema_name, "");
    assert_eq!(payload_of(raw).unwrap(), Payload::from(vec![1u8, 2, 3]));
    let lab = &messages[52];
    assert_eq!(lab.channel.schema_name, "lab.thing");
    let Payload::Map(map) = payload_of(lab).unwrap() else {
        panic!("a map")
    };
    assert_eq!(map.get("blob"), Some(&Value::Bytes(vec![0, 255])));
}

#[test]
fn a_file_cut_short_reads_up_to_its_last_flushed_chunk_and_says_where() {
    let (bytes, flushed) = recording(40, 10);
    assert_eq!(flushed.len(), 4);
    // cut in the middle of the chunk after the second flush
    let cut = (flushed[1] + flushed[2]) / 2;
    let (messages, damage) = read_all(&bytes[..cut as usize]);
    assert_eq!(messages.len(), 20, "the two flushed chunks read whole");
    let damage = damage.expect("the cut is reported");
    assert_eq!(damage.offset, flushed[1], "{damage}");
    assert!(
        damage.problem.contains(&format!(
            "the file ends at byte {cut} inside a chunk record"
        )),
        "{damage}"
    );
    // cut exactly after a flush: every flushed message, and the footer missing
    let (messages, damage) = read_all(&bytes[..flushed[3] as usize]);
    assert_eq!(messages.len(), 40);
    let damage = damage.unwrap();
    assert_eq!(damage.offset, flushed[3]);
    assert!(damage.problem.contains("without its footer"), "{damage}");
}

#[test]
fn bad_magic_and_a_corrupt_chunk_are_reported_at_their_byte() {
    let (mut bytes, flushed) = recording(30, 10);
    let (_, damage) = read_all(b"LCM log, not MCAP");
    assert_eq!(damage.unwrap().offset, 0);
    let (_, damage) = read_all(b"\x89MCAP0\r\nabc");
    let d = damage.unwrap();
    assert!(d.problem.contains("inside a record's header"), "{d}");
    assert_eq!(d.offset, 8);
    // flip a byte inside the second chunk's compressed records (past its 57-byte header: opcode,
    // length, times, sizes, CRC, "zstd"): it no longer decompresses to what its CRC says
    let inside = flushed[0] + 70;
    bytes[inside as usize] ^= 0x55;
    let (messages, damage) = read_all(&bytes);
    assert_eq!(messages.len(), 10, "the first chunk reads");
    let d = damage.unwrap();
    assert_eq!(d.offset, flushed[0], "{d}");
}

#[test]
fn a_chunk_the_writer_never_closed_is_reported_as_unfinished() {
    let out = Shared::default();
    let mut w = Writer::new(out.clone(), Catalogue::built_in()).unwrap();
    let write = |w: &mut Writer<Shared>, i: i64| {
        let m = msg(
            "nav.attitude",
            Kind::Data,
            Payload::from(attitude(i)),
            i,
            i as u64 + 1,
        );
        w.write(&m, Stamp(i)).unwrap();
    };
    for i in 0..10 {
        write(&mut w, i);
    }
    w.flush().unwrap();
    let flushed = out.0.borrow().get_ref().len() as u64;
    for i in 10..15 {
        write(&mut w, i);
    }
    // the process dies here: what is in the file is all there is
    let bytes = out.0.borrow().get_ref().clone();
    assert!(
        bytes.len() as u64 > flushed,
        "the open chunk is in the file"
    );
    let (messages, damage) = read_all(&bytes);
    assert_eq!(messages.len(), 10);
    let d = damage.unwrap();
    assert_eq!(d.offset, flushed, "{d}");
    assert!(d.problem.starts_with("an unfinished chunk"), "{d}");
}

#[test]
fn a_channel_whose_topic_claims_gigabytes_is_damage_not_an_allocation() {
    // a channel record: id 1, schema 0, a topic said to be 0xFFFFFFF0 bytes long
    let mut record = vec![1u8, 0, 0, 0];
    record.extend_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    record.extend_from_slice(b"nav");
    let e = lengths_fit(mcap::records::op::CHANNEL, &record).unwrap_err();
    assert_eq!(
        e,
        "its topic of 4294967280 bytes is longer than the 3 bytes left in it"
    );
    // a well-formed channel record passes
    let mut good = vec![1u8, 0, 0, 0];
    for text in [&b"nav.depth"[..], b"json"] {
        good.extend_from_slice(&(text.len() as u32).to_le_bytes());
        good.extend_from_slice(text);
    }
    let mut meta = Vec::new();
    for text in [&b"seabus.kind"[..], b"command"] {
        meta.extend_from_slice(&(text.len() as u32).to_le_bytes());
        meta.extend_from_slice(text);
    }
    good.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    good.extend_from_slice(&meta);
    assert_eq!(lengths_fit(mcap::records::op::CHANNEL, &good), Ok(()));
    assert!(lengths_fit(mcap::records::op::CHANNEL, &good[..good.len() - 1]).is_err());
}

/// An MCAP record: its opcode, its length and `body`.
fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![opcode];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

/// An MCAP string: its length and its bytes.
fn string(s: &str) -> Vec<u8> {
    let mut out = (s.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(s.as_bytes());
    out
}

/// The body of an uncompressed chunk record holding `records`, with no CRC.
fn plain_chunk(records: &[u8]) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend_from_slice(&0u64.to_le_bytes()); // start time
    body.extend_from_slice(&0u64.to_le_bytes()); // end time
    body.extend_from_slice(&(records.len() as u64).to_le_bytes()); // uncompressed size
    body.extend_from_slice(&0u32.to_le_bytes()); // uncompressed CRC: none
    body.extend_from_slice(&string("")); // compression: none
    body.extend_from_slice(&(records.len() as u64).to_le_bytes()); // records' size
    body.extend_from_slice(records);
    body
}

/// A channel record (id 1, no schema) and a message on it, as a chunk holds them.
fn channel_and_message() -> Vec<u8> {
    use mcap::records::op;
    let mut channel = vec![1, 0, 0, 0];
    channel.extend_from_slice(&string("nav.depth"));
    channel.extend_from_slice(&string(BYTES));
    channel.extend_from_slice(&0u32.to_le_bytes()); // metadata: none
    let mut message = vec![1, 0];
    message.extend_from_slice(&7u32.to_le_bytes()); // sequence
    message.extend_from_slice(&5u64.to_le_bytes()); // log time
    message.extend_from_slice(&4u64.to_le_bytes()); // publish time
    message.extend_from_slice(&[1, 2, 3]);
    let mut records = record(op::CHANNEL, &channel);
    records.extend_from_slice(&record(op::MESSAGE, &message));
    records
}

/// An MCAP file: its header, `chunk` (a chunk record's body), data end, footer.
fn file_with_chunk(chunk: &[u8]) -> (Vec<u8>, u64) {
    use mcap::records::op;
    let mut file = MAGIC.to_vec();
    let mut header = string("");
    header.extend_from_slice(&string("seabus tests"));
    file.extend_from_slice(&record(op::HEADER, &header));
    let at = file.len() as u64;
    file.extend_from_slice(&record(op::CHUNK, chunk));
    file.extend_from_slice(&record(op::DATA_END, &0u32.to_le_bytes()));
    file.extend_from_slice(&record(op::FOOTER, &[0; 20]));
    file.extend_from_slice(MAGIC);
    (file, at)
}

#[test]
fn an_uncompressed_chunk_whose_record_runs_past_its_end_is_damage_at_the_chunk() {
    use mcap::records::op;
    // the chunk well formed: its message reads
    let (file, _) = file_with_chunk(&plain_chunk(&channel_and_message()));
    let (messages, damage) = read_all(&file);
    assert_eq!(damage, None);
    assert_eq!(messages.len(), 1);
    assert_eq!(
        (messages[0].sequence, &messages[0].data[..]),
        (7, &[1u8, 2, 3][..])
    );

    // a message record that says it is 40 bytes long with 20 left in the chunk: the `mcap` crate
    // would read on into the records after the chunk
    let mut records = channel_and_message();
    let bad_at = records.len();
    let mut bad = vec![op::MESSAGE];
    bad.extend_from_slice(&40u64.to_le_bytes());
    bad.extend_from_slice(&[0; 20]);
    records.extend_from_slice(&bad);
    let (file, chunk_at) = file_with_chunk(&plain_chunk(&records));
    let (messages, damage) = read_all(&file);
    assert!(
        messages.is_empty(),
        "none of the chunk's messages: {messages:?}"
    );
    let d = damage.expect("the overlong record is damage");
    assert_eq!(d.offset, chunk_at, "{d}");
    assert_eq!(
        d.problem,
        format!(
            "a chunk record: the message record at byte {bad_at} of its records is 40 bytes \
             long, longer than the 20 bytes left in them"
        )
    );

    // the records end 5 bytes into a record's header
    let mut records = channel_and_message();
    let cut_at = records.len();
    records.extend_from_slice(&[op::MESSAGE, 1, 0, 0, 0]);
    let (file, chunk_at) = file_with_chunk(&plain_chunk(&records));
    let d = read_all(&file).1.expect("the cut header is damage");
    assert_eq!(d.offset, chunk_at, "{d}");
    assert_eq!(
        d.problem,
        format!(
            "a chunk record: its records end inside the header of the record at byte {cut_at} \
             of them (5 of 9 bytes)"
        )
    );

    // records said to be longer than the chunk
    let mut chunk = plain_chunk(&channel_and_message());
    let records = chunk.len() as u64 - 40;
    // the records' size: the body's bytes 32 to 40, after the compression's empty name
    chunk[32..40].copy_from_slice(&(records + 1).to_le_bytes());
    let (file, chunk_at) = file_with_chunk(&chunk);
    let d = read_all(&file).1.expect("the overlong records are damage");
    assert_eq!(d.offset, chunk_at, "{d}");
    assert_eq!(
        d.problem,
        format!(
            "a chunk record: its records of {} bytes are longer than the {records} bytes left \
             in it",
            records + 1
        )
    );
}

/// What walking `chunk` (a chunk record's body) says when it comes in pieces of `size` bytes.
fn walk_in_pieces(chunk: &[u8], size: usize) -> Result<(), String> {
    let mut walk = ChunkWalk::new(chunk.len() as u64);
    chunk.chunks(size).try_for_each(|piece| walk.pass(piece))
}

#[test]
fn a_chunk_is_walked_the_same_whole_and_in_pieces() {
    use mcap::records::op;
    let good = plain_chunk(&channel_and_message());
    let mut records = channel_and_message();
    records.extend_from_slice(&record(op::MESSAGE, &[0; 30])[..20]);
    let bad = plain_chunk(&records);
    let said = format!(
        "the message record at byte {} of its records is 30 bytes long, longer than the 11 bytes \
         left in them",
        channel_and_message().len()
    );
    for size in 1..=bad.len() {
        assert_eq!(walk_in_pieces(&good, size), Ok(()), "pieces of {size}");
        assert_eq!(
            walk_in_pieces(&bad, size),
            Err(said.clone()),
            "pieces of {size}"
        );
    }
    // a compressed chunk's records are left to the `mcap` crate
    let mut zstd = bad[..28].to_vec();
    zstd.extend_from_slice(&string("zstd"));
    zstd.extend_from_slice(&bad[32..]);
    assert_eq!(walk_in_pieces(&zstd, 7), Ok(()));
    // padding after the records is passed over
    let mut padded = good.clone();
    padded.extend_from_slice(&[0xFF; 5]);
    assert_eq!(walk_in_pieces(&padded, 3), Ok(()));

    // a chunk longer than the reader's pieces (64 KiB) reads whole
    let mut records = channel_and_message();
    let mut message = vec![1, 0];
    message.extend_from_slice(&[0; 20]);
    message.extend_from_slice(&vec![9; 100_000]);
    records.extend_from_slice(&record(op::MESSAGE, &message));
    let (file, _) = file_with_chunk(&plain_chunk(&records));
    let (messages, damage) = read_all(&file);
    assert_eq!(damage, None);
    assert_eq!(messages.len(), 2);
    assert_eq!(messages[1].data, vec![9; 100_000]);
}
