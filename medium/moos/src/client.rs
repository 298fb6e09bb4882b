//! The MOOS medium: an asynchronous V10 client of a MOOSDB (`moos://HOST:9000?name=seabus`).
//!
//! It connects, sends the handshake and its name, and on the welcome estimates the clock skew
//! from the handshake's round trip ([`handshake_skew`]); then it registers for what its URL's
//! `register` lists (variable names, or patterns with `*` and `?` registered by wildcard; each may
//! end `:SECONDS`, the minimum interval between notifications). Every second it sends a timing
//! message, which keeps the connection alive and refines the skew from that round trip
//! ([`refined_skew`]). When the DB goes away the link goes down, sends fail at once, and the
//! medium connects again (after `reopen`, doubling up to `reopen_max`; see [`Backoff`]), estimates
//! the skew afresh and registers again.
//!
//! A MOOS variable is a topic of the same name. Values become payloads as [`super`] describes;
//! notifications the medium itself published (the DB sends back what a client registered for) are
//! not delivered again.

use super::wire::{self, MoosMsg, MoosRef, Packet, Visited, data, kind};
use super::{from_moos, to_moos};
use bytes::Bytes;
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::link::{Backoff, Encode, LinkQueue, LinkSender, Linked, link_queue, spawn_link};
use seabus_medium::medium::{Ingress, LinkState, OpenError, Opening, SendError};
use seabus_medium::message::Message;
use seabus_medium::topic::Topic;
use seabus_medium::url::{MediumUrl, UrlError};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Messages waiting to be sent; a sender waits when the connection is this far behind.
const WRITE_QUEUE: usize = 4096;
/// How often a timing message goes to the DB.
const TIMING_EVERY: Duration = Duration::from_secs(1);

/// One registration.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// A variable name, or a pattern with `*` and `?`.
    pub pattern: String,
    /// The minimum interval between notifications, seconds.
    pub interval: f64,
}

/// A MOOS medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq)]
pub struct MoosConfig {
    /// The DB's address.
    pub host: String,
    /// The DB's port.
    pub port: u16,
    /// This client's name (unique among the DB's clients).
    pub name: String,
    /// What it registers for.
    pub register: Vec<Registration>,
    /// Waits between attempts to connect.
    pub reopen: Backoff,
}

impl MoosConfig {
    /// Reads the settings of a `moos://HOST:PORT` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<MoosConfig, UrlError> {
        if url.host.is_empty() {
            return Err(url.error("expected moos://HOST:PORT (the MOOSDB, port 9000 by default)"));
        }
        let name = url.take("name").unwrap_or_else(|| "seabus".to_string());
        if name.is_empty() || name.contains(char::is_whitespace) {
            return Err(url.error(format!(
                "option `name={name}`: a client name without blanks"
            )));
        }
        let register = match url.take("register") {
            None => vec![Registration {
                pattern: "*".into(),
                interval: 0.0,
            }],
            Some(list) => list
                .split(',')
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(|item| {
                    let (pattern, interval) = match item.rsplit_once(':') {
                        Some((p, i)) => {
                            let i: f64 = i.parse().ok().filter(|i: &f64| *i >= 0.0).ok_or_else(|| {
                                url.error(format!(
                                    "option `register`: `{item}`: the interval is seconds, 0 or more"
                                ))
                            })?;
                            (p, i)
                        }
                        None => (item, 0.0),
                    };
                    Ok(Registration {
                        pattern: pattern.to_string(),
                        interval,
                    })
                })
                .collect::<Result<Vec<_>, UrlError>>()?,
        };
        let cfg = MoosConfig {
            host: url.host.clone(),
            port: url.port.unwrap_or(9000),
            name,
            register,
            reopen: Backoff::from_url(url)?,
        };
        url.finish(&[])?;
        Ok(cfg)
    }

    /// What a MOOS medium can do: MOOS variables (doubles, strings of `key=value` pairs, binary
    /// strings: datamaps and bytes) carried on a TCP stream to the DB, without seabus's
    /// provenance; the DB's echo of this client's own writes is not delivered; the connection
    /// comes and goes.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: false,
            framing: Framing::Stream,
            max_frame: Some(wire::MAX_PACKET - wire::PACKET_HEADER),
            hears_own: false,
            carries: Carries::DataMap,
            link_state: true,
            native: None,
            qos: false,
            lists: false,
        }
    }
}

/// The clock skew (MOOS time − local time) as f64 bits, shared with the connection task.
#[derive(Default)]
struct Skew(AtomicU64);

impl Skew {
    fn get(&self) -> f64 {
        f64::from_bits(self.0.load(Ordering::Relaxed))
    }
    fn set(&self, s: f64) {
        self.0.store(s.to_bits(), Ordering::Relaxed);
    }
}

fn local_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// What `moos://` does with messages: notifications in the MOOS wire format, from this client,
/// stamped with the DB's time.
pub struct MoosEncoder {
    cfg: MoosConfig,
    client: Arc<str>,
    skew: Arc<Skew>,
}

impl Encode for MoosEncoder {
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        self.cfg.capabilities()
    }

    fn encode(&self, msg: &Message, link: &LinkSender<Bytes>) -> Result<Bytes, SendError> {
        let (data_type, value, string) = to_moos(&msg.payload).map_err(|e| link.error(e))?;
        let m = MoosRef {
            id: 0,
            kind: kind::NOTIFY,
            data_type,
            source: self.client.as_bytes(),
            source_aux: b"",
            community: b"",
            key: msg.topic.as_str().as_bytes(),
            time: local_now() + self.skew.get(),
            value,
            value2: 0.0,
            string: &string,
        };
        if m.encoded_len() + wire::PACKET_HEADER > wire::MAX_PACKET {
            return Err(SendError::TooLarge {
                medium: link.medium().to_string(),
                size: m.encoded_len(),
                max: wire::MAX_PACKET - wire::PACKET_HEADER,
            });
        }
        let mut out = Vec::with_capacity(m.encoded_len());
        m.encode_into(&mut out);
        Ok(Bytes::from(out))
    }
}

/// The transport of `moos://`.
pub type MoosTransport = Linked<MoosEncoder>;

/// Opens a `moos://` medium: a task keeps the connection to the DB.
pub(crate) fn open(mut o: Opening) -> Result<Arc<MoosTransport>, OpenError> {
    let cfg = MoosConfig::from_url(&mut o.url)?;
    let skew = Arc::new(Skew::default());
    let db = format!("{}:{}", cfg.host, cfg.port);
    let (link, queue) = link_queue(&o.name, format!("the MOOSDB at {db}"), WRITE_QUEUE);
    o.ingress.init_link(LinkState::Down(format!(
        "not connected to the MOOSDB at {db} yet"
    )));
    let (connecting, running) = ((cfg.clone(), skew.clone()), (cfg.clone(), skew.clone()));
    let ingress = o.ingress.clone();
    spawn_link(
        &o.ingress,
        cfg.reopen,
        queue,
        move || {
            let (cfg, skew) = connecting.clone();
            Box::pin(async move {
                let db = format!("{}:{}", cfg.host, cfg.port);
                connect(&cfg, &skew)
                    .await
                    .map_err(|reason| format!("MOOSDB at {db}: {reason}"))
            })
        },
        move |(sock, buf), queue| {
            let ((cfg, skew), ingress) = (running.clone(), ingress.clone());
            Box::pin(async move {
                let db = format!("{}:{}", cfg.host, cfg.port);
                let reason = session(sock, buf, &cfg, &skew, queue, &ingress).await;
                format!("MOOSDB at {db}: {reason}")
            })
        },
    );
    Ok(Arc::new(Linked::new(
        MoosEncoder {
            client: Arc::from(cfg.name.as_str()),
            cfg,
            skew,
        },
        link,
    )))
}

/// Connects, shakes hands and registers; returns the connection and what it read beyond.
async fn connect(cfg: &MoosConfig, skew: &Skew) -> Result<(TcpStream, Vec<u8>), String> {
    let mut sock = tokio::time::timeout(
        Duration::from_secs(5),
        TcpStream::connect((cfg.host.as_str(), cfg.port)),
    )
    .await
    .map_err(|_| "no connection within 5 s".to_string())?
    .map_err(|e| format!("cannot connect: {e}"))?;
    let _ = sock.set_nodelay(true);
    let asked = local_now();
    sock.write_all(&wire::hello(&cfg.name, asked))
        .await
        .map_err(|e| format!("handshake: {e}"))?;
    let mut buf = Vec::new();
    let answer = wire::next_packet(&mut sock, &mut buf, Duration::from_secs(5)).await?;
    let answered = local_now();
    let Some(first) = answer.messages.first() else {
        return Err("an empty answer to the handshake".into());
    };
    match first.kind {
        kind::WELCOME => {
            // the DB's time when it welcomed; a DB that leaves it out gives it as the skew it
            // measured against the time the client sent
            let db_time = if first.time.is_finite() && first.time > 0.0 {
                first.time
            } else {
                asked + first.value
            };
            skew.set(handshake_skew(asked, db_time, answered));
        }
        kind::POISON => {
            return Err(format!(
                "refused: {}",
                String::from_utf8_lossy(&first.string)
            ));
        }
        k => {
            return Err(format!(
                "answered the handshake with a `{}` message",
                k as char
            ));
        }
    }
    let mut registrations = Vec::new();
    for r in &cfg.register {
        registrations.push(if r.pattern.contains(['*', '?']) {
            MoosMsg {
                kind: kind::WILDCARD_REGISTER,
                data_type: data::STRING,
                // a MOOSDB subscribes the client the source names
                source: cfg.name.as_bytes().to_vec(),
                key: cfg.name.as_bytes().to_vec(),
                string: format!(
                    "AppPattern=*,VarPattern={},Interval={}",
                    r.pattern, r.interval
                )
                .into_bytes(),
                time: local_now() + skew.get(),
                ..MoosMsg::default()
            }
        } else {
            MoosMsg {
                kind: kind::REGISTER,
                data_type: data::DOUBLE,
                source: cfg.name.as_bytes().to_vec(),
                key: r.pattern.as_bytes().to_vec(),
                value: r.interval,
                time: local_now() + skew.get(),
                ..MoosMsg::default()
            }
        });
    }
    sock.write_all(
        &Packet {
            messages: registrations,
        }
        .encode(),
    )
    .await
    .map_err(|e| format!("registering: {e}"))?;
    Ok((sock, buf))
}

/// Bytes a session keeps for reading and for writing between packets (room for a packet of
/// [`BATCH`] and a message more); a larger buffer, left by a larger packet, is given back.
const KEPT_BUFFER: usize = 2 * BATCH;
/// What a session reads at a time, at least.
const READ_CHUNK: usize = 64 << 10;
/// A packet written takes what waits up to this size.
const BATCH: usize = 1 << 20;

/// Carries messages both ways until the connection fails; returns why.
async fn session(
    mut sock: TcpStream,
    mut buf: Vec<u8>,
    cfg: &MoosConfig,
    skew: &Skew,
    queue: &mut LinkQueue<Bytes>,
    ingress: &Ingress,
) -> String {
    let (mut reader, mut writer) = sock.split();
    let mut timing = tokio::time::interval(TIMING_EVERY);
    let mut topics: HashMap<Vec<u8>, Option<Topic>> = HashMap::new();
    let mut packet = Vec::new();
    // a frame taken from the queue that did not fit the last packet
    let mut carried: Option<Bytes> = None;
    // a timing request is waiting for its answer
    let mut asked = false;
    loop {
        // the packets read, each message looked at where it lies in the buffer
        let mut used = 0;
        // the bytes the packet begun at `used` takes
        let needed = loop {
            let mut timed = None;
            let read = wire::visit_packet(&buf[used..], |m| match m.kind {
                kind::NOTIFY => deliver(&m, cfg, &mut topics, ingress),
                // the DB sends back the timing message with its own time as the value; the
                // time is still the request's
                kind::TIMING if std::mem::take(&mut asked) => timed = Some((m.time, m.value)),
                _ => {}
            });
            if let Some((rq, tx)) = timed {
                skew.set(refined_skew(skew.get(), rq, tx, local_now()));
            }
            match read {
                Ok(Visited::Packet(n)) => used += n,
                Ok(Visited::Incomplete(n)) => break n,
                Err(e) => {
                    ingress.reject(e.kind(), format_args!("from the MOOSDB: {e}"));
                    return format!("malformed packet: {e}");
                }
            }
        };
        buf.drain(..used);
        if buf.capacity() > KEPT_BUFFER && buf.len() < READ_CHUNK {
            buf.shrink_to(READ_CHUNK);
        }
        // room for the rest of a packet begun at once, else for a read
        buf.reserve(needed.saturating_sub(buf.len()).max(READ_CHUNK));
        if let Some(first) = carried.take() {
            carried = match write_batch(&mut writer, queue, first, &mut packet).await {
                Ok(c) => c,
                Err(e) => return e,
            };
            continue;
        }
        tokio::select! {
            read = reader.read_buf(&mut buf) => match read {
                Ok(0) => return "the connection closed".into(),
                Ok(_) => {}
                Err(e) => return e.to_string(),
            },
            first = queue.recv() => {
                let Some(first) = first else { return "closed".into() };
                carried = match write_batch(&mut writer, queue, first, &mut packet).await {
                    Ok(c) => c,
                    Err(e) => return e,
                };
            }
            _ = timing.tick() => {
                let now = local_now();
                asked = true;
                let t = MoosMsg {
                    kind: kind::TIMING,
                    data_type: data::DOUBLE,
                    key: b"_async_timing".to_vec(),
                    time: now,
                    ..MoosMsg::default()
                };
                if let Err(e) = writer.write_all(&Packet { messages: vec![t] }.encode()).await {
                    return e.to_string();
                }
            }
        }
    }
}

/// Writes `first` and what waits behind it in one packet (up to [`BATCH`] bytes, never past
/// [`wire::MAX_PACKET`]), built in `packet`; returns a frame taken that did not fit, to go first
/// in the next packet, or why the connection failed.
async fn write_batch(
    writer: &mut (impl tokio::io::AsyncWrite + Unpin),
    queue: &mut LinkQueue<Bytes>,
    first: Bytes,
    packet: &mut Vec<u8>,
) -> Result<Option<Bytes>, String> {
    packet.clear();
    packet.resize(wire::PACKET_HEADER, 0);
    packet.extend_from_slice(&first);
    let mut count = 1;
    let mut carried = None;
    while packet.len() < BATCH
        && let Some(m) = queue.try_recv()
    {
        if packet.len() + m.len() > wire::MAX_PACKET {
            carried = Some(m);
            break;
        }
        packet.extend_from_slice(&m);
        count += 1;
    }
    wire::seal_packet(packet, count);
    let sent = writer.write_all(packet).await;
    // a frame carried to the next packet is lost with the connection
    let lost = u64::from(sent.is_err() && carried.is_some());
    queue.written(count as u64 + lost);
    if sent.is_err() {
        // the DB had none of the packet, or some of it: MOOS does not say which
        queue.lost(count as u64 + lost);
    }
    if packet.capacity() > KEPT_BUFFER {
        *packet = Vec::new();
    }
    sent.map(|()| carried).map_err(|e| e.to_string())
}

/// What one round trip to the DB says about the skew (MOOS time − local time): `rq` when the
/// request left (local time), `tx` the DB's time in its answer, `rx` when the answer came (local
/// time). The DB took its time between the two, so the skew lies between `tx − rx` and `tx − rq`;
/// `None` when the times are not finite or out of order.
fn skew_bounds(rq: f64, tx: f64, rx: f64) -> Option<(f64, f64)> {
    let (low, high) = (tx - rx, tx - rq);
    (low.is_finite() && high.is_finite() && low <= high).then_some((low, high))
}

/// The skew the handshake gives: `rq` when the client's name left (local time), `tx` the DB's
/// time in its welcome, `rx` when the welcome came (local time). Of the skews the round trip
/// allows, the one nearest zero: clocks the round trip cannot tell apart are taken as equal, so on
/// one host the skew is 0 however late the DB reads the client's name (a MOOSDB's welcome alone
/// says about 0.1 s there, which is why a MOOS client on the DB's host leaves its skew at 0), and
/// a DB on another host with a clock further off than the round trip is within a round trip of
/// the truth at once. Times not in order give 0, to be refined.
pub fn handshake_skew(rq: f64, tx: f64, rx: f64) -> f64 {
    skew_bounds(rq, tx, rx).map_or(0.0, |(low, high)| 0.0f64.clamp(low, high))
}

/// The skew after a timing reply (`rq`, `tx`, `rx` as for [`handshake_skew`]). A skew the round
/// trip allows stays as it is; one it rules out moves a tenth of the way to the nearest skew it
/// allows (a MOOS client smooths its measurements the same way, new = 0.9·old + 0.1·measured), so
/// one slow reply never throws the clock off and a skew never settles outside what the round trips
/// allow. A reply whose times are not finite or out of order leaves the skew as it was.
pub fn refined_skew(old: f64, rq: f64, tx: f64, rx: f64) -> f64 {
    match skew_bounds(rq, tx, rx) {
        Some((low, high)) => 0.9 * old + 0.1 * old.clamp(low, high),
        None => old,
    }
}

/// Delivers a notification as a message on the variable's topic.
fn deliver(
    m: &MoosRef<'_>,
    cfg: &MoosConfig,
    topics: &mut HashMap<Vec<u8>, Option<Topic>>,
    ingress: &Ingress,
) {
    // the DB sends back what this client published when it registered for it
    if m.source == cfg.name.as_bytes() {
        return;
    }
    let topic = match topics.get(m.key) {
        Some(t) => t.clone(),
        None => {
            if topics.len() > 65_536 {
                topics.clear();
            }
            let t = std::str::from_utf8(m.key)
                .ok()
                .and_then(|k| Topic::new(k).ok());
            topics.insert(m.key.to_vec(), t.clone());
            t
        }
    };
    let Some(topic) = topic else {
        ingress.reject(
            "moos-bad-key",
            format_args!("variable `{}` is not a topic name", m.key_str()),
        );
        return;
    };
    match from_moos(m) {
        Ok(payload) => {
            ingress.originate(topic, payload);
        }
        Err(e) => ingress.reject(
            "moos-bad-value",
            format_args!("variable `{}`: {e}", m.key_str()),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Packets read back from `bytes`: each one's messages' values.
    fn packets(bytes: &[u8]) -> Vec<Vec<f64>> {
        let mut out = Vec::new();
        let mut at = 0;
        while at < bytes.len() {
            let mut values = Vec::new();
            match wire::visit_packet(&bytes[at..], |m| values.push(m.value)).unwrap() {
                Visited::Packet(n) => at += n,
                Visited::Incomplete(n) => panic!("a packet cut short: {n} bytes needed"),
            }
            out.push(values);
        }
        out
    }

    fn frame(value: f64, string: Vec<u8>) -> Bytes {
        let mut out = Vec::new();
        MoosMsg {
            kind: kind::NOTIFY,
            data_type: data::BINARY,
            key: b"X".to_vec(),
            value,
            string,
            ..MoosMsg::default()
        }
        .encode_into(&mut out);
        Bytes::from(out)
    }

    #[tokio::test]
    async fn what_waits_goes_in_one_packet_that_never_passes_the_largest() {
        let medium: Arc<str> = Arc::from("moos");
        let (link, mut queue) = link_queue(&medium, "the MOOSDB", 16);
        queue.set_up(true);
        for (i, size) in [10usize, 20, wire::MAX_PACKET - 200, 30].iter().enumerate() {
            link.send(frame(i as f64 + 1.0, vec![7; *size]))
                .await
                .unwrap();
        }
        let mut wrote = Vec::new();
        let mut packet = Vec::new();
        let first = frame(0.0, Vec::new());
        let carried = write_batch(&mut wrote, &mut queue, first, &mut packet)
            .await
            .unwrap()
            .expect("the large frame waits for the next packet");
        // the large frame goes first in the next packet, which is full with it
        let none = write_batch(&mut wrote, &mut queue, carried, &mut packet)
            .await
            .unwrap();
        assert!(none.is_none());
        let last = queue.try_recv().expect("the last frame still waits");
        write_batch(&mut wrote, &mut queue, last, &mut packet)
            .await
            .unwrap();
        assert_eq!(
            packets(&wrote),
            vec![vec![0.0, 1.0, 2.0], vec![3.0], vec![4.0]]
        );
        // the packet's buffer is not kept at that size
        assert!(packet.capacity() <= KEPT_BUFFER, "{}", packet.capacity());
    }

    #[test]
    fn the_handshake_takes_the_skew_nearest_zero_that_the_round_trip_allows() {
        // one host, the DB reading the name 0.1 s late: its time is 0.1 s past the request
        assert_eq!(handshake_skew(100.0, 100.1, 100.1002), 0.0);
        // a DB clock 5 s ahead, 2 ms round trip: within the round trip of 5 s
        let s = handshake_skew(100.0, 105.001, 100.002);
        assert!((s - 4.999).abs() < 1e-9, "{s}");
        // and 5 s behind
        let s = handshake_skew(100.0, 95.001, 100.002);
        assert!((s + 4.999).abs() < 1e-9, "{s}");
        // times out of order or not finite
        assert_eq!(handshake_skew(100.0, 100.0, 99.0), 0.0);
        assert_eq!(handshake_skew(100.0, f64::NAN, 100.0), 0.0);
    }

    #[test]
    fn a_timing_reply_moves_only_a_skew_it_rules_out() {
        // allowed: kept as it is, however late the DB answered
        assert_eq!(refined_skew(0.0, 10.0, 10.08, 10.1), 0.0);
        assert_eq!(refined_skew(0.05, 10.0, 10.08, 10.1), 0.05);
        // ruled out (the DB is 5 s ahead): a tenth of the way to the nearest allowed
        let s = refined_skew(0.0, 10.0, 15.0005, 10.001);
        assert!((s - 0.49995).abs() < 1e-9, "{s}");
        assert_eq!(refined_skew(0.3, 10.0, f64::INFINITY, 10.1), 0.3);
    }
}
