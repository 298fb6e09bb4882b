//! One parse per sentence for every NMEA driver reading a line.
//!
//! A multiplexer's line carries the GPS, the compass and the sounder; each of their drivers gets
//! every sentence. The drivers on one medium share a [`Reader`] (through
//! [`seabus_medium::Medium::shared`]): the first driver to meet a sentence parses it, the others
//! take that parse. A sentence no driver reads is not parsed at all. A sentence that cannot be
//! read is counted once on the medium (reason `unreadable`) and logged once, not once per driver.

use super::sentence::{NmeaError, Parsed, address, parse, standard};
use seabus_medium::{Ingress, Message};
use std::sync::{Arc, Mutex};

/// How many recent sentences are kept for the drivers that have not met them yet. The drivers on
/// a line read at about the same pace; one that falls further behind parses for itself.
const KEPT: usize = 64;

/// The parse of one sentence, shared.
pub type Read = Arc<Result<Parsed, NmeaError>>;

/// The sentences of one medium, parsed once for all the drivers reading it.
#[derive(Debug, Default)]
pub struct Reader {
    state: Mutex<State>,
}

#[derive(Debug, Default)]
struct State {
    /// Formatters (`GGA`) and non-standard addresses (`PRDID`) some driver reads.
    wanted: Vec<Box<str>>,
    /// Recent sentences by sequence number (slot `seq % KEPT`), with their origin id and parse
    /// (`None`: no driver read it when it came, while `wanted` was that long).
    recent: Vec<Option<Recent>>,
}

/// A recent sentence: origin id, sequence number, parse, and how many kinds were wanted then.
type Recent = (u64, u64, Option<Read>, usize);

/// The formatter of a sentence as the drivers name it: the three letters after the talker of a
/// standard address (`GPGGA` → `GGA`), or the whole address otherwise (`PRDID`, `OSI`).
pub fn formatter_of(line: &str) -> &str {
    let addr = address(line);
    standard(line, addr).map_or(addr, |(_, formatter)| formatter)
}

impl Reader {
    /// Adds sentence formatters (`GGA`) or whole non-standard addresses (`PRDID`) to those read.
    pub fn want<'a>(&self, formatters: impl IntoIterator<Item = &'a str>) {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        for f in formatters {
            if !st.wanted.iter().any(|w| &**w == f) {
                st.wanted.push(f.into());
            }
        }
    }

    /// The parse of the sentence `line` carried by `msg`: `None` when no driver reads its kind.
    /// The first caller parses it (and counts it on `ingress` when it cannot be read); later
    /// callers for the same message share that parse.
    pub fn read(&self, msg: &Message, line: &str, ingress: &Ingress) -> Option<Read> {
        let (origin, seq) = (msg.provenance.origin.id, msg.provenance.seq);
        let slot = (seq % KEPT as u64) as usize;
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if st.recent.is_empty() {
            st.recent.resize(KEPT, None);
        }
        // (a sentence no driver read is looked at again once a driver that started since wants more)
        if let Some((o, s, read, wanted)) = &st.recent[slot]
            && (*o, *s) == (origin, seq)
            && (read.is_some() || *wanted == st.wanted.len())
        {
            return read.clone();
        }
        let formatter = formatter_of(line);
        let read = if st.wanted.iter().any(|w| &**w == formatter) {
            // parsed under the lock, so that a sentence is parsed (and an unreadable one
            // counted) once even when two drivers meet it at the same moment
            let read = Arc::new(parse(line));
            if let Err(e) = &*read {
                ingress.reject("unreadable", e);
            }
            Some(read)
        } else {
            None
        };
        let wanted = st.wanted.len();
        st.recent[slot] = Some((origin, seq, read.clone(), wanted));
        read
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use seabus_medium::framing::nmea_sentence;
    use seabus_medium::{Medium, Node, Payload, Topic};

    fn message(medium: &Medium, body: &str) -> (Message, String) {
        let line = nmea_sentence(b'$', body);
        let mut rx = medium.attach("rx").subscribed("**").expect("pattern");
        let topic = Topic::new("nmea.x").expect("topic");
        assert!(
            medium
                .ingress()
                .originate(topic, Payload::Bytes(line.clone().into()))
        );
        (rx.try_recv().expect("delivered"), line)
    }

    #[test]
    fn a_sentence_is_parsed_once_for_all_and_only_when_wanted() {
        let medium = Medium::in_process("line", &Node::new("n"));
        let reader = medium.shared::<Reader>();
        let (gsv, line) = message(&medium, "GPGSV,1,1,01,07,79,048,42");
        assert!(reader.read(&gsv, &line, &medium.ingress()).is_none());
        reader.want(["GGA", "HDT"]);
        reader.want(["GGA", "PRDID"]);
        let (gga, line) = message(
            &medium,
            "GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
        );
        let first = reader.read(&gga, &line, &medium.ingress()).expect("wanted");
        let again = medium
            .shared::<Reader>()
            .read(&gga, &line, &medium.ingress())
            .expect("wanted");
        assert!(Arc::ptr_eq(&first, &again), "one parse for both");
        assert_eq!(first.as_ref().as_ref().unwrap().formatter(), "GGA");
        let (bad, line) = message(&medium, "HEHDT,north,T");
        let _ = reader.read(&bad, &line, &medium.ingress());
        let _ = reader.read(&bad, &line, &medium.ingress());
        let _ = reader.read(&bad, &line, &medium.ingress());
        assert_eq!(
            medium.stats().rejected.get("unreadable"),
            Some(&1),
            "counted once, however many drivers read it"
        );
        let (prd, line) = message(&medium, "PRDID,-1.5,2.0,180.0");
        assert!(reader.read(&prd, &line, &medium.ingress()).is_some());
    }

    #[test]
    fn formatters_are_named_as_the_drivers_name_them() {
        assert_eq!(formatter_of("$GPGGA,1*00"), "GGA");
        assert_eq!(formatter_of("$PRDID,1*00"), "PRDID");
        assert_eq!(formatter_of("!AIVDM,1*00"), "AIVDM");
        assert_eq!(formatter_of("$OSI,1*00"), "OSI");
    }
}
