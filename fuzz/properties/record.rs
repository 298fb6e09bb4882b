//! Properties of seabus's MCAP reading (`seabus-record`), checked by the fuzz target `mcap_reader`
//! and by the seed-replay test of the `seabus-record` crate.

use seabus_record::{Damage, ReadMessage, Reader};

/// Hands out its bytes a few at a time, as a slow file or pipe would.
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

/// Every message of a file up to its end or damage; a reader that neither ends nor fails within
/// one message per byte (and a few more) breaks a property.
fn read_all(mut r: Reader<impl std::io::Read>, len: usize) -> (Vec<ReadMessage>, Option<Damage>) {
    let mut messages = Vec::new();
    for _ in 0..=len + 8 {
        match r.next_message() {
            Ok(Some(m)) => messages.push(m),
            Ok(None) => return (messages, None),
            Err(d) => {
                // after damage, the reader says the same again
                let again = r.next_message();
                assert_eq!(again.as_ref().err(), Some(&d), "after damage: {again:?}");
                return (messages, Some(d));
            }
        }
    }
    panic!("the reader neither ended nor failed after {len} bytes");
}

/// What a message is, for comparing two readings.
fn key(m: &ReadMessage) -> (String, String, u32, u64, u64, Vec<u8>) {
    (
        m.channel.topic.clone(),
        m.channel.message_encoding.clone(),
        m.sequence,
        m.log_time,
        m.publish_time,
        m.data.clone(),
    )
}

/// Any bytes read as an MCAP file: no panic, an end or damage within the file, damage at an
/// offset inside it, the same messages and damage read whole and a few bytes at a time, and every
/// message's payload read or refused with a reason. True when the file read to its proper end.
pub fn mcap_reader(data: &[u8]) -> bool {
    let (messages, damage) = read_all(Reader::new(data), data.len());
    let (trickled, trickled_damage) = read_all(Reader::new(Trickle { data, calls: 0 }), data.len());
    assert_eq!(
        trickled.iter().map(key).collect::<Vec<_>>(),
        messages.iter().map(key).collect::<Vec<_>>(),
        "messages read a few bytes at a time"
    );
    assert_eq!(
        trickled_damage.as_ref().map(|d| d.offset),
        damage.as_ref().map(|d| d.offset),
        "damage found a few bytes at a time"
    );
    if let Some(d) = &damage {
        assert!(
            d.offset <= data.len() as u64,
            "damage at {} past the end",
            d.offset
        );
        assert!(!d.problem.is_empty());
    }
    for m in &messages {
        assert!(m.data.len() <= data.len(), "a message longer than the file");
        if let Err(e) = seabus_record::payload_of(m) {
            assert!(!e.to_string().is_empty());
        }
    }
    damage.is_none()
}
