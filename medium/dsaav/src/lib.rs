//! DSAAV IComms as a seabus medium: key-value messages between numbered nodes and ports, over raw
//! Ethernet, UDP or in-process backbones, the same frames on each ([`wire`]).
//!
//! ```text
//! dsaav+eth://eth0?node=3               raw Ethernet frames, EtherType 0x88B5, on an interface
//! dsaav+udp://239.255.42.2:47900?node=3 UDP multicast (ttl 0 by default) or broadcast
//! dsaav+inproc://vehicle?node=3         in-process: every medium of this program named `vehicle`
//! ```
//! Options: `node` (this medium's node number, required, unique on the backbone), `port` (the
//! source port of messages that do not name one, default 0), `channel` (the channel of messages
//! that name no destination, default 0), `dict` (a dictionary file adding keys and types to the
//! built-in [`dict`]), and for UDP `ttl` and `iface`.
//!
//! A message's topic is `dsaav.TYPE` (a message type of the dictionary, or its number) and its
//! payload a datamap: the parameters by their dictionary names, and the header in keys starting
//! with `@` — `@src` and `@dst` (`NODE:PORT`), `@channel`, `@id`, `@ref`. Sending, `@dst` or
//! `@channel` say where it goes (the `channel` option otherwise), `@port` gives the source port,
//! and `@id` / `@ref` the message and reference ids (ids count up by themselves otherwise). A
//! received key the dictionary does not know arrives as `k<NUMBER>` and is counted
//! (`dsaav-unknown-key`); frames that do not read are counted by reason. A medium receives what is
//! addressed to its node and every channel broadcast, and never its own frames. Its own interfaces
//! see what it sends as a receiver on its node would read it from the wire (with `@src`, `@id`, …),
//! so two ports of one node talk as two nodes do, and a message addressed to another node is not
//! seen here at all.
//!
//! With the `relay` option a `dsaav+eth` or `dsaav+udp` medium has no node of its own and carries
//! every frame of its backbone as it is ([`relay`]), for a module that relays frames.
//!
//! Who may depend on it: the program (to register the schemes) and the DSAAV services, which
//! speak its frames and addresses. It depends on the core only.

pub mod dict;
pub mod relay;
mod sockets;
pub mod wire;

use bytes::Bytes;
use dict::{Dictionary, QuickMap, ValueType};
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::datamap::{DataMap, Value};
use seabus_medium::medium::{
    BoxFuture, Ingress, LinkState, OpenError, Opening, SendError, Transport,
};
use seabus_medium::message::{Kind, Message, Origin, Provenance, Stamp};
use seabus_medium::payload::Payload;
use seabus_medium::schemes::{CheckUrl, OpenTransport};
use seabus_medium::topic::Topic;
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{Opened, Scheme, Schemes};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use tokio::io::Interest;
use tokio::io::unix::AsyncFd;
use wire::{Address, Destination, Frame, Param};

/// The EtherType of DSAAV frames on raw Ethernet (IEEE local experimental).
pub const ETHERTYPE: u16 = 0x88B5;

/// Bytes before the payload in what a UDP socket's filter reads.
const UDP_HEADER: u32 = 8;

/// What the medium puts its frames on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Backbone {
    /// Raw Ethernet on an interface.
    Ethernet(String),
    /// UDP, as the UDP medium reaches its peers (multicast, broadcast or listed peers).
    Udp(seabus_medium::net::UdpEndpoint),
    /// Every medium of this program with the same name.
    InProcess(String),
}

/// A DSAAV medium's settings, read from its URL.
#[derive(Debug, Clone)]
pub struct DsaavConfig {
    /// The backbone.
    pub backbone: Backbone,
    /// This medium's node.
    pub node: u16,
    /// Source port of messages that name none.
    pub port: u16,
    /// Channel of messages that name no destination.
    pub channel: u16,
    /// The keys and types.
    pub dict: Arc<Dictionary>,
}

impl DsaavConfig {
    /// What a DSAAV medium can do: DSAAV IComms messages (datamaps of the dictionary's keys) in
    /// frames of at most [`wire::MAX_FRAME`] bytes, without seabus's provenance (a receiver
    /// numbers what each node sends); a medium never reads its own frames.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: false,
            framing: Framing::Datagram,
            max_frame: Some(wire::MAX_FRAME),
            hears_own: false,
            carries: Carries::DataMap,
            link_state: false,
            native: Some("dsaav"),
            qos: false,
            lists: false,
        }
    }

    /// Reads the settings from a `dsaav+…://` URL, taking its options.
    pub fn from_url(url: &mut MediumUrl) -> Result<DsaavConfig, UrlError> {
        let node: u16 = url
            .take_parsed("node", "a node number 0–65534")?
            .ok_or_else(|| url.error("needs `node=N`, this medium's node number"))?;
        if node == wire::BROADCAST_NODE {
            return Err(url.error("option `node`: 65535 means broadcast; use 0–65534"));
        }
        let port = url.take_parsed("port", "a port 0–65535")?.unwrap_or(0);
        let channel = url
            .take_parsed("channel", "a channel 0–65535")?
            .unwrap_or(0);
        let mut dictionary = Dictionary::built_in();
        if let Some(path) = url.take("dict") {
            let text = std::fs::read_to_string(&path)
                .map_err(|e| url.error(format!("option `dict={path}`: {e}")))?;
            dictionary
                .add(&path, &text)
                .map_err(|e| url.error(format!("option `dict`: {e}")))?;
        }
        const OPTIONS: [&str; 4] = ["node", "port", "channel", "dict"];
        let backbone = match url.scheme.as_str() {
            "dsaav+eth" if !url.host.is_empty() => {
                url.finish(&OPTIONS)?;
                Backbone::Ethernet(url.host.clone())
            }
            "dsaav+inproc" if !url.host.is_empty() => {
                url.finish(&OPTIONS)?;
                Backbone::InProcess(url.host.clone())
            }
            "dsaav+udp" => {
                // the rest are the UDP medium's options (ttl, iface, broadcast, …)
                let mut udp = url.clone();
                udp.scheme = "udp".to_string();
                let endpoint = seabus_medium::net::UdpEndpoint::from_url(&mut udp)?;
                udp.finish(&seabus_medium::net::UdpEndpoint::OPTIONS)?;
                Backbone::Udp(endpoint)
            }
            s => {
                return Err(url.error(format!(
                    "`{s}://` needs a name: dsaav+eth://INTERFACE or dsaav+inproc://NAME"
                )));
            }
        };
        Ok(DsaavConfig {
            backbone,
            node,
            port,
            channel,
            dict: Arc::new(dictionary),
        })
    }
}

pub(crate) fn io_send(medium: &str, e: impl std::fmt::Display) -> SendError {
    SendError::Io {
        medium: medium.to_string(),
        reason: e.to_string(),
    }
}

/// Turns a seabus message into an IComms frame from `src_node`.
pub fn to_frame(
    dict: &Dictionary,
    src_node: u16,
    default_port: u16,
    default_channel: u16,
    next_id: impl FnOnce() -> u32,
    msg: &Message,
) -> Result<Frame, String> {
    let Some(type_name) = msg.topic.as_str().strip_prefix("dsaav.") else {
        return Err(format!(
            "topic `{}`: a DSAAV medium carries topics dsaav.TYPE",
            msg.topic
        ));
    };
    let kind = dict.type_id(type_name).ok_or_else(|| {
        format!(
            "topic `{}`: `{type_name}` is not a DSAAV message type",
            msg.topic
        )
    })?;
    let map = msg.payload.to_map().map_err(|e| e.to_string())?;
    let int = |key: &str, v: &Value, max: i64| -> Result<i64, String> {
        v.as_i64()
            .filter(|n| (0..=max).contains(n))
            .ok_or_else(|| format!("`{key}` must be an integer 0–{max}, not {v}"))
    };
    let mut dst = Destination::Channel(default_channel);
    let mut port = default_port;
    let mut id = None;
    let mut reference = 0;
    let mut params = Vec::with_capacity(map.len());
    for (key, v) in map.iter() {
        match key {
            "@dst" => {
                let text = v
                    .as_str()
                    .ok_or_else(|| format!("`@dst` must be NODE:PORT, not {v}"))?;
                dst = Destination::To(
                    text.parse()
                        .map_err(|e: wire::AddressError| e.to_string())?,
                );
            }
            "@channel" => dst = Destination::Channel(int(key, v, 65_535)? as u16),
            "@port" => port = int(key, v, 65_535)? as u16,
            "@id" => id = Some(int(key, v, u32::MAX.into())? as u32),
            "@ref" => reference = int(key, v, u32::MAX.into())? as u32,
            // what a received message said of its source: not sent on
            "@src" => {}
            _ => {
                let Some((number, ty)) = dict.key(key) else {
                    return Err(format!("`{key}` is not a key of the DSAAV dictionary"));
                };
                params.push((number, param(key, ty, v)?));
            }
        }
    }
    Ok(Frame {
        src: Address {
            node: src_node,
            port,
        },
        dst,
        id: id.unwrap_or_else(next_id),
        kind,
        reference,
        params,
    })
}

/// A datamap value as the key's wire type.
fn param(key: &str, ty: ValueType, v: &Value) -> Result<Param, String> {
    let wrong = || format!("`{key}` is {} in the DSAAV dictionary, not {v}", ty.name());
    Ok(match ty {
        ValueType::Int => Param::Int(
            v.as_i64()
                .and_then(|n| i32::try_from(n).ok())
                .ok_or_else(wrong)?,
        ),
        ValueType::Float => Param::Float(v.as_f64().ok_or_else(wrong)? as f32),
        ValueType::Double => Param::Double(v.as_f64().ok_or_else(wrong)?),
        ValueType::Str => Param::Str(v.as_str().ok_or_else(wrong)?.to_string()),
    })
}

/// The topic of messages of type `kind`.
pub fn topic_of(dict: &Dictionary, kind: u16) -> String {
    format!("dsaav.{}", dict.type_name(kind))
}

/// Whether node `node` receives frame `f`: addressed to it, or a channel broadcast.
fn is_for(f: &Frame, node: u16) -> bool {
    match f.dst {
        Destination::To(a) => a.node == node,
        Destination::Channel(_) => true,
    }
}

/// Turns a frame into the datamap a seabus receiver gets, with the keys the dictionary did not
/// know.
pub fn from_frame(dict: &Dictionary, f: &Frame) -> (DataMap, Vec<u16>) {
    frame_map(dict, f, f.params.iter().cloned())
}

/// [`from_frame`] for a frame no longer needed: its strings move into the datamap.
fn into_map(dict: &Dictionary, mut f: Frame) -> (DataMap, Vec<u16>) {
    let params = std::mem::take(&mut f.params);
    frame_map(dict, &f, params.into_iter())
}

/// The datamap of frame `f`'s header and `params`.
fn frame_map(
    dict: &Dictionary,
    f: &Frame,
    params: impl ExactSizeIterator<Item = (u16, Param)>,
) -> (DataMap, Vec<u16>) {
    let mut map = DataMap::with_capacity(params.len() + 4);
    map.push("@src", f.src.text());
    match f.dst {
        Destination::To(a) => map.push("@dst", a.text()),
        Destination::Channel(c) => map.push("@channel", i64::from(c)),
    }
    map.push("@id", i64::from(f.id));
    if f.reference != 0 {
        map.push("@ref", i64::from(f.reference));
    }
    let mut unknown = Vec::new();
    for (key, p) in params {
        let value = match p {
            Param::Int(v) => Value::Int(i64::from(v)),
            Param::Float(v) => Value::Float(f64::from(v)),
            Param::Double(v) => Value::Float(v),
            Param::Str(s) => Value::from(s),
        };
        match dict.key_name(key) {
            // the dictionary's own copy of the name: nothing is copied
            Some((name, _)) => map.push(name, value),
            None => {
                unknown.push(key);
                map.push(format!("k{key}"), value);
            }
        }
    }
    (map, unknown)
}

/// The node a frame this medium encoded is addressed to; `None` for a channel broadcast.
fn addressed_node(frame: &[u8]) -> Option<u16> {
    match (frame.get(4), frame.get(10..12)) {
        (Some(flags), Some(&[hi, lo])) if flags & 1 == 0 => Some(u16::from_be_bytes([hi, lo])),
        _ => None,
    }
}

/// The DSAAV transport.
pub struct DsaavTransport {
    name: Arc<str>,
    cfg: DsaavConfig,
    link: Link,
    next_id: AtomicU32,
}

enum Link {
    Udp(Arc<AsyncFd<std::net::UdpSocket>>, Vec<SocketAddr>),
    Ethernet(Arc<eth::RawSocket>),
    InProcess(Hub, u64),
}

/// Checks a DSAAV URL: a medium of a node, or a relay medium ([`relay`]).
fn check(url: &mut MediumUrl) -> Result<Capabilities, UrlError> {
    if relay::wanted(url)? {
        return Ok(relay::RelayConfig::from_url(url)?.capabilities());
    }
    Ok(DsaavConfig::from_url(url)?.capabilities())
}

/// Opens a DSAAV medium: of a node, or a relay medium ([`relay`]).
fn open_any(mut o: Opening) -> Result<Opened, OpenError> {
    if relay::wanted(&mut o.url)? {
        return Ok(Opened::from(relay::open(o)?));
    }
    Ok(Opened::from(open(o)?))
}

/// Adds `dsaav+eth://`, `dsaav+udp://` and `dsaav+inproc://`.
pub fn register(schemes: &mut Schemes) {
    let (check, open) = (check as CheckUrl, open_any as OpenTransport);
    schemes
        .add(Scheme {
            name: "dsaav+eth",
            family: "dsaav",
            summary: "DSAAV IComms in raw Ethernet frames on an interface",
            check,
            open,
        })
        .add(Scheme {
            name: "dsaav+udp",
            family: "dsaav",
            summary: "DSAAV IComms over UDP multicast or broadcast",
            check,
            open,
        })
        .add(Scheme {
            name: "dsaav+inproc",
            family: "dsaav",
            summary: "DSAAV IComms between media of this program",
            check,
            open,
        });
}

/// A registry with the DSAAV schemes and the in-process medium, for a program or test that uses
/// only these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}

/// Opens a DSAAV medium.
fn open(mut o: Opening) -> Result<Arc<DsaavTransport>, OpenError> {
    let cfg = DsaavConfig::from_url(&mut o.url)?;
    let rx = Receiver::new(&o, &cfg);
    let link = match &cfg.backbone {
        Backbone::Udp(ucfg) => {
            let (socket, dests) = seabus_medium::net::bind(ucfg)
                .map_err(o.io_error(format!("binding {}", ucfg.bind)))?;
            // what this medium sends comes back to it (multicast loopback): the kernel drops it
            sockets::set_filter(
                std::os::fd::AsRawFd::as_raw_fd(&socket),
                &sockets::skip_own(UDP_HEADER, cfg.node, u32::MAX),
            )
            .map_err(o.io_error("filtering the socket"))?;
            // watched for reading only: see `sockets`
            // SAFETY: the socket is owned by the AsyncFd from here on and closed only by it
            let socket = unsafe { AsyncFd::register_with_interest(socket, Interest::READABLE) }
                .map_err(std::io::Error::from)
                .map_err(o.io_error("registering the socket"))?;
            let socket = Arc::new(socket);
            let task = tokio::spawn(rx.udp(socket.clone()));
            o.ingress.own_task(task.abort_handle());
            Link::Udp(socket, dests)
        }
        Backbone::Ethernet(iface) => {
            let socket = Arc::new(
                eth::RawSocket::open_node(iface, ETHERTYPE, cfg.node)
                    .map_err(o.io_error(format!("opening a raw socket on {iface}")))?,
            );
            let task = tokio::spawn(rx.ethernet(socket.clone()));
            o.ingress.own_task(task.abort_handle());
            Link::Ethernet(socket)
        }
        Backbone::InProcess(name) => {
            let hub = hub(name);
            let me = fastrand::u64(1..);
            let task = tokio::spawn(rx.in_process(hub.subscribe(), me));
            o.ingress.own_task(task.abort_handle());
            Link::InProcess(hub, me)
        }
    };
    o.ingress.set_link(LinkState::Up);
    Ok(Arc::new(DsaavTransport {
        name: o.name.clone(),
        cfg,
        link,
        next_id: AtomicU32::new(1),
    }))
}

/// An in-process backbone: frames with the id of the medium that sent them.
type Hub = tokio::sync::broadcast::Sender<(u64, Bytes)>;

/// The in-process backbone called `name`, made on first use.
fn hub(name: &str) -> Hub {
    static HUBS: OnceLock<Mutex<HashMap<String, Hub>>> = OnceLock::new();
    let mut hubs = HUBS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    hubs.entry(name.to_string())
        .or_insert_with(|| tokio::sync::broadcast::channel(4096).0)
        .clone()
}

impl Transport for DsaavTransport {
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        self.cfg.capabilities()
    }

    fn encode(&self, msg: &Message) -> Result<Bytes, SendError> {
        let frame = to_frame(
            &self.cfg.dict,
            self.cfg.node,
            self.cfg.port,
            self.cfg.channel,
            || self.next_id.fetch_add(1, Ordering::Relaxed),
            msg,
        )
        .map_err(|e| io_send(&self.name, e))?;
        let len = frame.encoded_len();
        if len > wire::MAX_FRAME {
            return Err(SendError::TooLarge {
                medium: self.name.to_string(),
                size: len,
                max: wire::MAX_FRAME,
            });
        }
        frame
            .encode()
            .map(Bytes::from)
            .map_err(|e| io_send(&self.name, e))
    }

    /// What a receiver on this node reads of the frame: the header keys the wire gives (`@src`,
    /// `@id`, …), the values as the wire carries them; nothing for a frame to another node.
    fn local_copy(&self, msg: Message, frame: &Bytes) -> Option<Message> {
        // a frame to another node: its header says so, nothing to read
        if addressed_node(frame).is_some_and(|node| node != self.cfg.node) {
            return None;
        }
        let f = match Frame::decode(frame) {
            Ok(f) => f,
            Err(e) => {
                tracing::error!(
                    medium = %self.name,
                    "a frame this medium encoded does not read: {e}"
                );
                return None;
            }
        };
        if !is_for(&f, self.cfg.node) {
            return None;
        }
        let named = self.cfg.dict.named_type(f.kind);
        let topic = if named.is_some() && msg.topic.as_str().strip_prefix("dsaav.") == named {
            msg.topic
        } else {
            Topic::new(&topic_of(&self.cfg.dict, f.kind)).ok()?
        };
        let (map, _) = into_map(&self.cfg.dict, f);
        Some(Message {
            topic,
            // the wire carries no kind: what it delivers is data
            kind: Kind::Data,
            payload: Payload::from(map),
            ..msg
        })
    }

    fn transmit(&self, frame: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            match &self.link {
                Link::Udp(socket, dests) => {
                    for dest in dests {
                        sockets::send_to(socket, &frame, *dest)
                            .await
                            .map_err(|e| io_send(&self.name, format!("sending to {dest}: {e}")))?;
                    }
                    Ok(())
                }
                Link::Ethernet(socket) => {
                    // a frame to one node goes to its hardware address once it is known
                    let to =
                        (frame[4] & 1 == 0).then(|| u16::from_be_bytes([frame[10], frame[11]]));
                    socket
                        .send(to, &frame)
                        .await
                        .map_err(|e| io_send(&self.name, e))
                }
                Link::InProcess(hub, me) => {
                    // no receiver yet is not an error: nobody is listening
                    let _ = hub.send((*me, frame));
                    Ok(())
                }
            }
        })
    }
}

/// Receives frames from a backbone and delivers what is for this node.
struct Receiver {
    ingress: Ingress,
    medium: Arc<str>,
    node: u16,
    dict: Arc<Dictionary>,
    origins: QuickMap<u16, (Arc<Origin>, u64)>,
    topics: QuickMap<u16, Option<Topic>>,
}

impl Receiver {
    fn new(o: &Opening, cfg: &DsaavConfig) -> Receiver {
        Receiver {
            ingress: o.ingress.clone(),
            medium: o.name.clone(),
            node: cfg.node,
            dict: cfg.dict.clone(),
            origins: QuickMap::default(),
            topics: QuickMap::default(),
        }
    }

    /// Handles one frame from `from` (for messages); false once the medium is gone.
    fn frame(&mut self, from: &dyn std::fmt::Display, d: &[u8]) -> (bool, Option<u16>) {
        let f = match Frame::decode(d) {
            Ok(f) => f,
            Err(e) => {
                self.ingress
                    .reject(e.kind(), format_args!("frame from {from}: {e}"));
                return (true, None);
            }
        };
        let src = f.src.node;
        if src == self.node || !is_for(&f, self.node) {
            return (true, Some(src));
        }
        let kind = f.kind;
        let (map, unknown) = into_map(&self.dict, f);
        for key in unknown {
            self.ingress.reject(
                "dsaav-unknown-key",
                format_args!(
                    "frame from {from}: key {key} is not in the dictionary (kept as k{key})"
                ),
            );
        }
        let topic = match self.topics.get(&kind) {
            Some(t) => t.clone(),
            None => {
                // made once per message type
                let t = Topic::new(&topic_of(&self.dict, kind)).ok();
                self.topics.insert(kind, t.clone());
                t
            }
        };
        let Some(topic) = topic else {
            self.ingress.reject(
                "dsaav-bad-type",
                format_args!("frame from {from}: message type gives no topic"),
            );
            return (true, Some(src));
        };
        if self.origins.len() > 4096 && !self.origins.contains_key(&src) {
            self.origins.clear();
        }
        let medium = &self.medium;
        let (origin, seq) = self
            .origins
            .entry(src)
            .or_insert_with(|| (Origin::new(&format!("dsaav@{src}"), medium, 1), 0));
        *seq += 1;
        let msg = Message {
            topic,
            kind: Kind::Data,
            provenance: Provenance {
                origin: origin.clone(),
                seq: *seq,
                hops: 0,
            },
            stamp: Stamp::now(),
            payload: Payload::from(map),
        };
        (self.ingress.deliver(msg), Some(src))
    }

    async fn udp(mut self, socket: Arc<AsyncFd<std::net::UdpSocket>>) {
        use std::os::fd::AsRawFd;
        let mut batch = sockets::batch(65_536);
        loop {
            let mut ready = match socket.readable().await {
                Ok(r) => r,
                Err(e) => {
                    tracing::debug!(medium = %self.medium, "dsaav receive: {e}");
                    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                    continue;
                }
            };
            let read = batch.receive(socket.as_raw_fd());
            // a batch that is not full emptied the socket, as a read that would block says: the
            // next read waits for a new datagram instead of trying
            if !matches!(read, Ok(n) if !batch.drained(n)) {
                ready.clear_ready();
            }
            if let Err(e) = read
                && e.kind() != std::io::ErrorKind::WouldBlock
            {
                tracing::debug!(medium = %self.medium, "dsaav receive: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                continue;
            }
            for i in 0..batch.taken() {
                let (from, d) = batch.get(i);
                let from = seabus_medium::net::inet(from);
                let from: &dyn std::fmt::Display = match &from {
                    Some(a) => a,
                    None => &"an address of another family",
                };
                if !self.frame(from, d).0 {
                    return;
                }
            }
        }
    }

    async fn ethernet(mut self, socket: Arc<eth::RawSocket>) {
        let mut batch = sockets::batch(2048);
        loop {
            if let Err(e) = socket.recv_batch(&mut batch).await {
                tracing::debug!(medium = %self.medium, "dsaav receive: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                continue;
            }
            for i in 0..batch.taken() {
                // the Ethernet header, then the frame
                let (_, d) = batch.get(i);
                if d.len() < 14 {
                    continue;
                }
                let mut mac = [0u8; 6];
                mac.copy_from_slice(&d[6..12]);
                let (open, src) = self.frame(&eth::Mac(mac), &d[14..]);
                if let Some(node) = src {
                    socket.learn(node, mac);
                }
                if !open {
                    return;
                }
            }
        }
    }

    async fn in_process(mut self, mut rx: tokio::sync::broadcast::Receiver<(u64, Bytes)>, me: u64) {
        use tokio::sync::broadcast::error::RecvError;
        loop {
            match rx.recv().await {
                Ok((sender, frame)) if sender != me => {
                    if !self.frame(&"this program", &frame).0 {
                        return;
                    }
                }
                Ok(_) => {}
                Err(RecvError::Lagged(n)) => self.ingress.reject(
                    "dsaav-overrun",
                    format_args!("{n} frames passed by while this medium was busy"),
                ),
                Err(RecvError::Closed) => return,
            }
        }
    }
}

/// Raw Ethernet frames through an AF_PACKET socket.
pub mod eth {
    use std::collections::HashMap;
    use std::fmt;
    use std::io;
    use std::os::fd::{AsFd, AsRawFd, FromRawFd, OwnedFd};
    use std::sync::Mutex;
    use tokio::io::Interest;
    use tokio::io::unix::AsyncFd;

    /// A hardware (MAC) address.
    pub struct Mac(pub [u8; 6]);

    impl fmt::Display for Mac {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            let m = self.0;
            write!(
                f,
                "{:02x}:{:02x}:{:02x}:{:02x}:{:02x}:{:02x}",
                m[0], m[1], m[2], m[3], m[4], m[5]
            )
        }
    }

    /// An AF_PACKET socket bound to one interface and EtherType, learning which hardware address
    /// each node has.
    pub struct RawSocket {
        fd: AsyncFd<OwnedFd>,
        ifindex: i32,
        mac: [u8; 6],
        ethertype: u16,
        peers: Mutex<HashMap<u16, [u8; 6]>>,
        /// whether the runtime watches the socket for writing (else a full socket is waited on
        /// through a copy of its descriptor)
        writes_watched: bool,
    }

    impl RawSocket {
        /// Opens the socket on interface `iface` for frames of `ethertype`.
        pub fn open(iface: &str, ethertype: u16) -> io::Result<RawSocket> {
            RawSocket::open_with(iface, ethertype, None)
        }

        /// Opens the socket on interface `iface` for the DSAAV frames of `ethertype` of a medium
        /// that is node `node`: the kernel drops the frames from `node` (what the medium sends
        /// itself, seen as it leaves) before they are read, and the socket is watched for reading
        /// only (a send that finds it full waits for room by itself).
        pub fn open_node(iface: &str, ethertype: u16, node: u16) -> io::Result<RawSocket> {
            let socket = RawSocket::open_with(iface, ethertype, Some(node))?;
            // a frame to this node goes to this interface, as when its own frames were read
            socket.learn(node, socket.mac);
            Ok(socket)
        }

        fn open_with(iface: &str, ethertype: u16, skip: Option<u16>) -> io::Result<RawSocket> {
            let name = std::ffi::CString::new(iface)
                .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "bad interface name"))?;
            // SAFETY: if_nametoindex reads a NUL-terminated string
            let ifindex = unsafe { libc::if_nametoindex(name.as_ptr()) } as i32;
            if ifindex == 0 {
                return Err(io::Error::new(
                    io::ErrorKind::NotFound,
                    format!("no interface {iface}"),
                ));
            }
            let mac = read_mac(iface)?;
            // SAFETY: socket(2) with constant arguments; the result is checked
            let fd = unsafe {
                libc::socket(
                    libc::AF_PACKET,
                    libc::SOCK_RAW | libc::SOCK_NONBLOCK | libc::SOCK_CLOEXEC,
                    // nothing is received until the filter is on and the socket bound
                    0,
                )
            };
            if fd < 0 {
                return Err(io::Error::last_os_error());
            }
            // SAFETY: fd is a new descriptor we own
            let fd = unsafe { OwnedFd::from_raw_fd(fd) };
            attach_filter(&fd, ethertype, skip)?;
            // every frame of the interface, the ones this host sends included (other media of
            // this host are other nodes), and the filter keeps those of `ethertype`
            let addr = sockaddr(ifindex, libc::ETH_P_ALL as u16, [0; 6]);
            // SAFETY: bind(2) reads a sockaddr_ll of the size given
            let r = unsafe {
                libc::bind(
                    fd.as_raw_fd(),
                    (&addr as *const libc::sockaddr_ll).cast(),
                    std::mem::size_of::<libc::sockaddr_ll>() as libc::socklen_t,
                )
            };
            if r < 0 {
                return Err(io::Error::last_os_error());
            }
            let interest = match skip {
                Some(_) => Interest::READABLE,
                None => Interest::READABLE | Interest::WRITABLE,
            };
            // SAFETY: the descriptor is owned by the AsyncFd from here on and closed only by it
            let fd = unsafe { AsyncFd::register_with_interest(fd, interest) }
                .map_err(io::Error::from)?;
            Ok(RawSocket {
                fd,
                ifindex,
                mac,
                ethertype,
                peers: Mutex::new(HashMap::new()),
                writes_watched: skip.is_none(),
            })
        }

        /// This interface's hardware address.
        pub fn mac(&self) -> [u8; 6] {
            self.mac
        }

        /// Remembers that `node` sends from `mac`.
        pub fn learn(&self, node: u16, mac: [u8; 6]) {
            let mut peers = self.peers.lock().unwrap_or_else(|p| p.into_inner());
            if peers.len() > 4096 && !peers.contains_key(&node) {
                peers.clear();
            }
            peers.insert(node, mac);
        }

        /// Sends `payload` to the hardware address of node `to` when known, else to everyone.
        pub async fn send(&self, to: Option<u16>, payload: &[u8]) -> io::Result<()> {
            let dst = to
                .and_then(|n| {
                    self.peers
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .get(&n)
                        .copied()
                })
                .unwrap_or([0xff; 6]);
            let mut frame = Vec::with_capacity(14 + payload.len());
            frame.extend_from_slice(&dst);
            frame.extend_from_slice(&self.mac);
            frame.extend_from_slice(&self.ethertype.to_be_bytes());
            frame.extend_from_slice(payload);
            let addr = sockaddr(self.ifindex, self.ethertype, dst);
            let send = || {
                // SAFETY: sendto(2) reads the frame and a sockaddr_ll of the sizes given
                let n = unsafe {
                    libc::sendto(
                        self.fd.as_raw_fd(),
                        frame.as_ptr().cast(),
                        frame.len(),
                        0,
                        (&addr as *const libc::sockaddr_ll).cast(),
                        std::mem::size_of::<libc::sockaddr_ll>() as libc::socklen_t,
                    )
                };
                if n < 0 {
                    Err(io::Error::last_os_error())
                } else {
                    Ok(())
                }
            };
            if self.writes_watched {
                return self.fd.async_io(Interest::WRITABLE, |_| send()).await;
            }
            loop {
                match send() {
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                        super::sockets::writable(self.fd.as_fd()).await?
                    }
                    sent => return sent,
                }
            }
        }

        /// Receives one frame: the sender's hardware address and the payload's length in `buf`
        /// (moved to its start); `None` for one too short.
        pub async fn recv(&self, buf: &mut [u8]) -> io::Result<Option<([u8; 6], usize)>> {
            let n = self
                .fd
                .async_io(Interest::READABLE, |fd| {
                    // SAFETY: sockaddr_ll is plain data
                    let mut from: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
                    let mut len = std::mem::size_of::<libc::sockaddr_ll>() as libc::socklen_t;
                    // SAFETY: recvfrom(2) writes at most buf.len() bytes and a sockaddr_ll
                    let n = unsafe {
                        libc::recvfrom(
                            fd.as_raw_fd(),
                            buf.as_mut_ptr().cast(),
                            buf.len(),
                            0,
                            (&mut from as *mut libc::sockaddr_ll).cast(),
                            &mut len,
                        )
                    };
                    if n < 0 {
                        Err(io::Error::last_os_error())
                    } else {
                        Ok(n as usize)
                    }
                })
                .await?;
            // frames this host sends are seen too (PACKET_OUTGOING): another medium of this host
            // on the same interface is another node, and a medium skips its own frames by node
            if n < 14 {
                return Ok(None);
            }
            let mut mac = [0u8; 6];
            mac.copy_from_slice(&buf[6..12]);
            buf.copy_within(14..n, 0);
            Ok(Some((mac, n - 14)))
        }

        /// Waits for frames and takes those waiting, up to a batch, with their Ethernet headers.
        pub(super) async fn recv_batch(
            &self,
            batch: &mut seabus_medium::net::RecvBatch,
        ) -> io::Result<()> {
            loop {
                let mut ready = self.fd.readable().await?;
                match batch.receive(self.fd.as_raw_fd()) {
                    Ok(n) => {
                        // a batch that is not full emptied the socket: the next call waits for
                        // a new frame instead of trying a read that would block
                        if batch.drained(n) {
                            ready.clear_ready();
                        }
                        return Ok(());
                    }
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => ready.clear_ready(),
                    Err(e) => return Err(e),
                }
            }
        }
    }

    /// Keeps only frames of `ethertype` (a classic BPF program: load the EtherType, compare,
    /// accept or drop), so the socket sees none of the interface's other traffic; with `skip`, also
    /// drops the DSAAV frames whose source is that node.
    fn attach_filter(fd: &OwnedFd, ethertype: u16, skip: Option<u16>) -> io::Result<()> {
        let op = |code: u16, jt: u8, jf: u8, k: u32| libc::sock_filter { code, jt, jf, k };
        let tail = match skip {
            Some(node) => super::sockets::skip_own(14, node, 0xffff),
            // ret #65535; ret #0
            None => vec![op(0x06, 0, 0, 0xffff), op(0x06, 0, 0, 0)],
        };
        let mut program = vec![
            // ldh [12]
            op(0x28, 0, 0, 12),
            // jeq #ethertype, next, drop (the last instruction)
            op(0x15, 0, (tail.len() - 1) as u8, u32::from(ethertype)),
        ];
        program.extend(tail);
        super::sockets::set_filter(fd.as_raw_fd(), &program)
    }

    fn sockaddr(ifindex: i32, ethertype: u16, dst: [u8; 6]) -> libc::sockaddr_ll {
        // SAFETY: sockaddr_ll is plain data
        let mut a: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
        a.sll_family = libc::AF_PACKET as u16;
        a.sll_protocol = ethertype.to_be();
        a.sll_ifindex = ifindex;
        a.sll_halen = 6;
        a.sll_addr[..6].copy_from_slice(&dst);
        a
    }

    /// The hardware address of `iface`, asked of the kernel (right in any network namespace).
    fn read_mac(iface: &str) -> io::Result<[u8; 6]> {
        // SAFETY: ifreq is plain data
        let mut req: libc::ifreq = unsafe { std::mem::zeroed() };
        let name = iface.as_bytes();
        if name.len() >= req.ifr_name.len() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("interface name {iface} is too long"),
            ));
        }
        for (d, s) in req.ifr_name.iter_mut().zip(name) {
            *d = *s as libc::c_char;
        }
        // SAFETY: a datagram socket used only for the ioctl below, closed by OwnedFd
        let fd = unsafe { libc::socket(libc::AF_INET, libc::SOCK_DGRAM | libc::SOCK_CLOEXEC, 0) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: fd is a new descriptor we own
        let fd = unsafe { OwnedFd::from_raw_fd(fd) };
        // SAFETY: SIOCGIFHWADDR reads the name and writes the address into the ifreq we own
        if unsafe { libc::ioctl(fd.as_raw_fd(), libc::SIOCGIFHWADDR, &mut req) } < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: after SIOCGIFHWADDR the union holds the hardware address
        let data = unsafe { req.ifr_ifru.ifru_hwaddr.sa_data };
        let mut mac = [0u8; 6];
        for (m, d) in mac.iter_mut().zip(data) {
            *m = d as u8;
        }
        Ok(mac)
    }
}
