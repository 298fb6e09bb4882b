//! The LCM medium: LCM's UDP multicast protocol, spoken natively, for liblcm peers in any language.
//!
//! ```text
//! udpm://239.255.76.67:7667?ttl=0                 LCM's default group and port
//! udpm://                                         $LCM_DEFAULT_URL, or the default above
//! udpm://239.255.76.67:7667?ttl=1&iface=eth0      a chosen network interface
//! udpm://239.255.76.67:7667?channels=POSE|CAM_.*  only these channels are received
//! ```
//! Options: `ttl` (default 0: nothing leaves this host), `recv_buf_size` (socket receive buffer in
//! bytes, default 8 MiB, granted beyond the system limit when running as root), `iface` (interface
//! name or IPv4 address to join and send on; by default the route's interface, and loopback too,
//! or loopback alone on a host without a multicast route), `channels` (regular expression the whole
//! channel must match to be received), `frag_timeout` (how long a partial message waits for its next
//! fragment, default 2s), `frag_mem` (bytes partial messages may hold, default 300 MiB), `send_gap`
//! (messages handed over in a stream less than this apart go out in batches, default 50us; 0: each
//! at once, [`seabus_medium::outbox`]).
//!
//! The channel is the topic; the payload is the LCM message's bytes. A channel that is not a
//! seabus topic (`POSE.`, `a..b`, `with space`) is delivered as it came
//! ([`Topic::channel`](seabus_medium::Topic::channel)), so that spy and record see it and a replay
//! sends it back as it was. Messages this medium sent are not received back. liblcm's self-test
//! packets are ignored. Packets that do not read and partial messages given up (timeout, memory
//! cap, too many, overlap) are counted in the medium's rejected counters by reason.
//!
//! A large message's fragments go out together, even when several local publishers send at once
//! (liblcm up to 1.4 keeps one partial message per sender). A sender's sequence number jumping
//! back by more than 64 means it started again (LCM never sends a message twice): it becomes a new
//! origin.

use super::reassembly::{self, Dropped, Reassembler, Step};
use super::wire::{self, Packet};
use bytes::{Bytes, BytesMut};
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::medium::{
    BoxFuture, Ingress, LinkState, OpenError, Opening, SendError, Transport,
};
use seabus_medium::message::{Kind, Message, Origin, Provenance, Stamp};
use seabus_medium::net::{self, RECV_CHUNK, RecvBatch};
use seabus_medium::outbox::{self, Outbox, Outgoing};
use seabus_medium::payload::Payload;
use seabus_medium::topic::{ChannelRegex, Pattern, Topic};
use seabus_medium::url::{MediumUrl, UrlError};
use socket2::{Domain, Protocol, SockRef, Socket, Type};
use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, SocketAddrV4};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::Interest;
use tokio::net::UdpSocket;

/// LCM's default URL.
pub const DEFAULT_URL: &str = "udpm://239.255.76.67:7667?ttl=0";
/// The environment variable naming the URL `udpm://` stands for.
pub const ENV_URL: &str = "LCM_DEFAULT_URL";
/// Default socket receive buffer.
pub const DEFAULT_RECV_BUF: usize = 8 << 20;

const OPTIONS: [&str; 7] = [
    "ttl",
    "send_gap",
    "recv_buf_size",
    "iface",
    "channels",
    "frag_timeout",
    "frag_mem",
];

/// An LCM medium's settings, read from its URL.
#[derive(Debug, Clone)]
pub struct LcmConfig {
    /// The multicast group.
    pub group: Ipv4Addr,
    /// The port.
    pub port: u16,
    /// Multicast hop limit.
    pub ttl: u32,
    /// The interface chosen by `iface`, if any.
    pub iface: Option<Ipv4Addr>,
    /// Requested socket receive buffer.
    pub recv_buf: usize,
    /// Only channels matching this are received.
    pub channels: Option<ChannelRegex>,
    /// How long a partial message waits for its next fragment.
    pub frag_timeout: Duration,
    /// Bytes partial messages may hold.
    pub frag_mem: usize,
    /// Messages handed over less than this apart, in a stream, go out in batches.
    pub send_gap: Duration,
}

impl LcmConfig {
    /// Reads the settings from a `udpm://` URL, taking its options. A URL without a host stands
    /// for `$LCM_DEFAULT_URL` (or LCM's default), whose options the URL's own override.
    pub fn from_url(url: &mut MediumUrl) -> Result<LcmConfig, UrlError> {
        if url.host.is_empty() && url.port.is_none() {
            let text = std::env::var(ENV_URL).unwrap_or_else(|_| DEFAULT_URL.to_string());
            let mut default = MediumUrl::parse(&text)
                .map_err(|e| url.error(format!("${ENV_URL}: {}", e.reason)))?;
            if default.scheme != "udpm" || default.host.is_empty() {
                return Err(url.error(format!(
                    "${ENV_URL}=`{text}`: seabus speaks LCM's udpm://GROUP:PORT provider"
                )));
            }
            let mut cfg = Self::read(&mut default)?;
            Self::options(url, &mut cfg)?;
            return Ok(cfg);
        }
        Self::read(url)
    }

    fn read(url: &mut MediumUrl) -> Result<LcmConfig, UrlError> {
        let group: Ipv4Addr = url
            .host
            .parse()
            .map_err(|_| url.error(format!("`{}` is not an IPv4 address", url.host)))?;
        if !group.is_multicast() {
            return Err(url.error(format!(
                "`{group}` is not a multicast group (224.0.0.0–239.255.255.255)"
            )));
        }
        let mut cfg = LcmConfig {
            group,
            port: url.port.unwrap_or(7667),
            ttl: 0,
            iface: None,
            recv_buf: DEFAULT_RECV_BUF,
            channels: None,
            frag_timeout: reassembly::DEFAULT_TIMEOUT,
            frag_mem: reassembly::DEFAULT_MEMORY,
            send_gap: outbox::QUIET,
        };
        Self::options(url, &mut cfg)?;
        Ok(cfg)
    }

    fn options(url: &mut MediumUrl, cfg: &mut LcmConfig) -> Result<(), UrlError> {
        if let Some(ttl) = url.take_parsed::<u32>("ttl", "a hop count 0–255")? {
            if ttl > 255 {
                return Err(url.error("option `ttl`: expected a hop count 0–255"));
            }
            cfg.ttl = ttl;
        }
        if let Some(n) = url.take_parsed("recv_buf_size", "a size in bytes")? {
            cfg.recv_buf = n;
        }
        if let Some(name) = url.take("iface") {
            cfg.iface = Some(
                name.parse::<Ipv4Addr>()
                    .ok()
                    .or_else(|| seabus_medium::net::interface_address(&name))
                    .ok_or_else(|| {
                        url.error(format!(
                            "option `iface={name}`: no such interface or IPv4 address"
                        ))
                    })?,
            );
        }
        if let Some(re) = url.take("channels") {
            cfg.channels = Some(
                ChannelRegex::new(&re)
                    .map_err(|e| url.error(format!("option `channels={re}`: {e}")))?,
            );
        }
        if let Some(t) = url.take("frag_timeout") {
            cfg.frag_timeout = seabus_medium::parse::parse_duration(&t)
                .filter(|d| !d.is_zero())
                .ok_or_else(|| {
                    url.error(format!(
                        "option `frag_timeout={t}`: expected a duration such as 2s or 500ms"
                    ))
                })?;
        }
        if let Some(n) = url.take_parsed("frag_mem", "a size in bytes")? {
            cfg.frag_mem = n;
        }
        if let Some(gap) = outbox::gap_from_url(url)? {
            cfg.send_gap = gap;
        }
        url.finish(&OPTIONS)
    }

    /// What an LCM medium can do: LCM messages (bytes, typed by LCM's own types) on channels, in
    /// datagrams (fragmented up to LCM's largest message), without seabus's provenance; what it
    /// sends never comes back to it.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: false,
            framing: Framing::Datagram,
            max_frame: Some(wire::MAX_MESSAGE),
            hears_own: false,
            carries: Carries::Bytes,
            link_state: true,
            native: Some("lcm"),
            qos: false,
            lists: true,
        }
    }
}

/// The interface multicast goes out on: the chosen one, the route's (`None`), or loopback on a
/// host without a route to the group.
fn send_interface(cfg: &LcmConfig) -> Option<Ipv4Addr> {
    if cfg.iface.is_some() {
        return cfg.iface;
    }
    let routed = std::net::UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
        .and_then(|s| s.connect((cfg.group, cfg.port)));
    routed.is_err().then_some(Ipv4Addr::LOCALHOST)
}

/// Joins the group on the chosen interface, or on the route's interface (where liblcm joins, so
/// its packets are heard) and on loopback (where a host without a network, or a peer choosing
/// it, sends).
fn join(s: SockRef<'_>, cfg: &LcmConfig) -> std::io::Result<()> {
    if let Some(iface) = cfg.iface {
        return s.join_multicast_v4(&cfg.group, &iface);
    }
    let routed = s.join_multicast_v4(&cfg.group, &Ipv4Addr::UNSPECIFIED);
    let looped = s.join_multicast_v4(&cfg.group, &Ipv4Addr::LOCALHOST);
    routed.or(looped)
}

/// Stops a socket from hearing groups it did not join itself (Linux delivers every group any
/// socket of the host joined to a socket bound to the port, unless told not to).
fn own_groups_only(s: &Socket) -> std::io::Result<()> {
    seabus_medium::net::set_int_option(s, libc::IPPROTO_IP, libc::IP_MULTICAST_ALL, 0)
}

/// The LCM transport.
pub struct LcmTransport {
    name: Arc<str>,
    /// The receive socket, which joins the group when something here first subscribes; `None`
    /// once the medium is closed
    listen: Mutex<Option<Arc<UdpSocket>>>,
    joined: std::sync::Once,
    cfg: LcmConfig,
    ingress: Ingress,
    /// Sends on the send socket until the medium is closed
    outbox: outbox::Held,
    /// Held while a message goes out in fragments, so that the fragments of two messages never
    /// interleave: liblcm up to 1.4 keeps one partial message per sender, and drops it when a
    /// fragment of another comes
    fragmenting: tokio::sync::Mutex<()>,
    dest: SocketAddr,
    seq: AtomicU32,
}

/// Opens an LCM medium.
pub(crate) fn open(mut o: Opening) -> Result<Arc<LcmTransport>, OpenError> {
    let cfg = LcmConfig::from_url(&mut o.url)?;
    let bind = SocketAddrV4::new(cfg.group, cfg.port);
    let rx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
        .map_err(o.io_error("creating the receive socket"))?;
    rx.set_reuse_address(true)
        .map_err(o.io_error("sharing the port"))?;
    let granted = seabus_medium::net::set_recv_buffer(&rx, cfg.recv_buf);
    // asked for in the URL, or too small for a burst of large messages: worth a warning
    if granted < cfg.recv_buf && (o.url.as_str().contains("recv_buf_size") || granted < 1 << 20) {
        let raise = if seabus_medium::net::may_force_buffers() {
            "the kernel would not give more, even to root"
        } else {
            "raise net.core.rmem_max, or run as root"
        };
        tracing::warn!(
            medium = %o.name,
            "receive buffer is {granted} bytes, asked for {} ({raise}): large messages may be lost",
            cfg.recv_buf
        );
    }
    // bound to the group, not to every address, and deaf to groups it did not join: other
    // groups on the same port stay out
    rx.bind(&SocketAddr::V4(bind).into())
        .map_err(o.io_error(format!("binding {bind}")))?;
    own_groups_only(&rx).map_err(o.io_error("configuring the receive socket"))?;
    let send_iface = send_interface(&cfg);
    rx.set_nonblocking(true)
        .map_err(o.io_error("configuring the receive socket"))?;

    let tx = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
        .map_err(o.io_error("creating the send socket"))?;
    let setup = |tx: &Socket| -> std::io::Result<()> {
        tx.set_multicast_ttl_v4(cfg.ttl)?;
        tx.set_multicast_loop_v4(true)?;
        seabus_medium::net::set_send_buffer(tx);
        if let Some(iface) = send_iface {
            tx.set_multicast_if_v4(&iface)?;
        }
        tx.bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)).into())?;
        // connected: the route is looked up once, not for every packet
        tx.connect(&SocketAddr::V4(bind).into())?;
        tx.set_nonblocking(true)
    };
    setup(&tx).map_err(o.io_error("configuring the send socket"))?;
    let own_port = tx
        .local_addr()
        .ok()
        .and_then(|a| a.as_socket())
        .map_or(0, |a| a.port());

    let rx = Arc::new(
        UdpSocket::from_std(rx.into()).map_err(o.io_error("registering the receive socket"))?,
    );
    let tx = Arc::new(
        UdpSocket::from_std(tx.into()).map_err(o.io_error("registering the send socket"))?,
    );
    let receiver = Receiver {
        ingress: o.ingress.clone(),
        medium: o.name.clone(),
        own_port,
        local: seabus_medium::net::interface_addresses()
            .into_iter()
            .map(|(_, a)| IpAddr::V4(a))
            .collect(),
        channels: cfg.channels.clone(),
        reassembler: Reassembler::new(cfg.frag_timeout, cfg.frag_mem),
        senders: Senders::default(),
        topics: HashMap::new(),
        dropped: Vec::new(),
    };
    let task = tokio::spawn(receiver.run(rx.clone()));
    o.ingress.own_task(task.abort_handle());
    o.ingress.set_link(LinkState::Up);
    tracing::debug!(medium = %o.name, group = %cfg.group, port = cfg.port, ttl = cfg.ttl, "lcm medium open");
    let outbox = outbox::Held::new(Outbox::new(tx, &o.ingress, cfg.send_gap));
    Ok(Arc::new(LcmTransport {
        name: o.name.clone(),
        listen: Mutex::new(Some(rx)),
        joined: std::sync::Once::new(),
        cfg,
        ingress: o.ingress.clone(),
        outbox,
        fragmenting: tokio::sync::Mutex::new(()),
        dest: SocketAddr::V4(bind),
        seq: AtomicU32::new(0),
    }))
}

impl LcmTransport {
    fn io_error(&self, e: std::io::Error) -> SendError {
        SendError::Io {
            medium: self.name.to_string(),
            reason: format!("sending to {}: {e}", self.dest),
        }
    }
}

impl Transport for LcmTransport {
    /// The channel, a NUL and the message's bytes (a topic has no NUL: the first one ends the
    /// channel).
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        self.cfg.capabilities()
    }

    /// The frame is the channel, a NUL, and the message bytes; headers are added as it is sent.
    fn encode(&self, msg: &Message) -> Result<Bytes, SendError> {
        let channel = msg.topic.as_str();
        let bytes = msg
            .payload
            .to_bytes()
            .map_err(|source| SendError::Convert {
                medium: self.name.to_string(),
                source,
            })?;
        wire::check(channel, bytes.len()).map_err(|e| match e {
            wire::EncodeError::TooLarge(size) => SendError::TooLarge {
                medium: self.name.to_string(),
                size,
                max: wire::MAX_MESSAGE,
            },
            e => SendError::Io {
                medium: self.name.to_string(),
                reason: e.to_string(),
            },
        })?;
        let mut frame = BytesMut::with_capacity(channel.len() + 1 + bytes.len());
        frame.extend_from_slice(channel.as_bytes());
        frame.extend_from_slice(&[0]);
        frame.extend_from_slice(&bytes);
        Ok(frame.freeze())
    }

    fn transmit(&self, data: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            let outbox = self
                .outbox
                .get()
                .ok_or_else(|| SendError::Closed(self.name.to_string()))?;
            // the frame is `channel NUL payload`, as encode made it
            let Some(nul) = data.iter().position(|b| *b == 0) else {
                return Err(self.io_error(std::io::Error::other("a frame without its channel")));
            };
            let payload_at = nul + 1;
            let channel = std::str::from_utf8(&data[..payload_at - 1]).unwrap_or_default();
            let payload_len = data.len() - payload_at;
            if wire::is_short(channel, payload_len) {
                let header = wire::short_header(self.seq.fetch_add(1, Ordering::Relaxed));
                return outbox
                    .send(&[Outgoing::connected(&header, data)])
                    .await
                    .map_err(|e| self.io_error(e));
            }
            // one message's fragments at a time, numbered in the order they go out; the first
            // carries the channel, each a slice of the frame
            let _fragmenting = self.fragmenting.lock().await;
            let seq = self.seq.fetch_add(1, Ordering::Relaxed);
            let fragments: Vec<Outgoing> = wire::fragments(seq, channel, payload_len)
                .map(|(header, range)| {
                    let from = if range.start == 0 {
                        0
                    } else {
                        payload_at + range.start
                    };
                    Outgoing::connected(&header, data.slice(from..payload_at + range.end))
                })
                .collect();
            outbox.send(&fragments).await.map_err(|e| self.io_error(e))
        })
    }

    /// Returns once the datagrams of a stream still queued have gone to the socket.
    fn flush(&self) -> BoxFuture<'_, ()> {
        Box::pin(self.outbox.flush())
    }

    /// Releases both sockets (the receive task, which holds the receive socket too, is stopped
    /// by the medium), leaving the group.
    fn close(&self) {
        self.outbox.close();
        self.listen.lock().unwrap_or_else(|p| p.into_inner()).take();
    }

    /// Joins the group, unless the medium is closed: a medium only publishing never makes the
    /// kernel copy the group's traffic to it.
    fn subscribed(&self, _pattern: &Pattern) {
        let listen = self.listen.lock().unwrap_or_else(|p| p.into_inner());
        let Some(socket) = listen.as_deref() else {
            return;
        };
        self.joined.call_once(|| {
            if let Err(e) = join(SockRef::from(socket), &self.cfg) {
                self.ingress.set_link(LinkState::Down(format!(
                    "cannot join {} to receive: {e}",
                    self.cfg.group
                )));
            }
        });
    }
}

/// What is known of one sender: its origin and the last sequence number, widened to 64 bits.
struct Sender {
    origin: Arc<Origin>,
    last: Option<u64>,
}

/// Senders and channels remembered before the tables are cleared (a flood of new ones).
const MAX_REMEMBERED: usize = 4096;
/// A sequence number at most this far behind the last one is a message that came late; farther
/// behind, the sender started again (LCM never sends a message twice).
const REORDER_WINDOW: i64 = 64;

/// The senders heard, each with its origin and last sequence number.
#[derive(Default)]
struct Senders {
    table: HashMap<SocketAddr, Sender>,
    /// Origins made so far: each sender, and each start of a sender, gets the next number as its
    /// boot, so that no origin is ever used twice (not even after the table is cleared).
    boots: u32,
}

impl Senders {
    /// The origin of `from` on medium `medium` and its sequence number widened to 64 bits; a
    /// sender whose numbers jump back beyond [`REORDER_WINDOW`] started again, and becomes a new
    /// origin.
    fn sequence(&mut self, medium: &str, from: SocketAddr, seq: u32) -> (Arc<Origin>, u64) {
        if !self.table.contains_key(&from) && self.table.len() >= MAX_REMEMBERED {
            self.table.clear();
        }
        let boots = &mut self.boots;
        let mut origin = || {
            *boots = boots.wrapping_add(1);
            Origin::new(&format!("lcm@{from}"), medium, *boots)
        };
        let s = self.table.entry(from).or_insert_with(|| Sender {
            origin: origin(),
            last: None,
        });
        let wide = match s.last {
            None => u64::from(seq),
            Some(last) => {
                let step = i64::from(seq.wrapping_sub(last as u32) as i32);
                if step < -REORDER_WINDOW {
                    s.origin = origin();
                    s.last = None;
                    u64::from(seq)
                } else {
                    last.saturating_add_signed(step)
                }
            }
        };
        if s.last.is_none_or(|l| wide > l) {
            s.last = Some(wide);
        }
        (s.origin.clone(), wide)
    }
}

struct Receiver {
    ingress: Ingress,
    medium: Arc<str>,
    own_port: u16,
    local: Vec<IpAddr>,
    channels: Option<ChannelRegex>,
    reassembler: Reassembler,
    senders: Senders,
    topics: HashMap<Box<str>, Option<Topic>>,
    dropped: Vec<Dropped>,
}

/// Datagrams taken from the socket in one recvmmsg(2) call.
const RECV_BATCH: usize = 32;
/// Room for the largest UDP datagram.
const SLOT: usize = 1 << 16;

impl Receiver {
    async fn run(mut self, socket: Arc<UdpSocket>) {
        let mut batch = RecvBatch::new(RECV_BATCH, SLOT);
        let mut chunk = BytesMut::with_capacity(RECV_CHUNK);
        loop {
            let fd = std::os::fd::AsRawFd::as_raw_fd(&*socket);
            let wait = socket.async_io(Interest::READABLE, || batch.receive(fd));
            let received = match self.reassembler.next_deadline() {
                None => wait.await,
                Some(deadline) => {
                    let deadline = tokio::time::Instant::from_std(deadline);
                    match tokio::time::timeout_at(deadline, wait).await {
                        Ok(r) => r,
                        Err(_) => {
                            self.reassembler
                                .expire(std::time::Instant::now(), &mut self.dropped);
                            self.report_dropped();
                            continue;
                        }
                    }
                }
            };
            let n = match received {
                Ok(n) => n,
                Err(e) => {
                    tracing::debug!(medium = %self.medium, "lcm receive: {e}");
                    tokio::time::sleep(Duration::from_millis(10)).await;
                    continue;
                }
            };
            for i in 0..n {
                let (from, d) = batch.get(i);
                let Some(from) = net::inet(from) else {
                    continue;
                };
                if !self.datagram(from, d, &mut chunk) {
                    return;
                }
            }
            // once a batch: a partial message times out even while other traffic keeps the
            // socket busy
            self.reassembler
                .expire(std::time::Instant::now(), &mut self.dropped);
            self.report_dropped();
        }
    }

    /// Handles one datagram, cutting a short message's payload from `chunk`; false once the
    /// medium is gone.
    fn datagram(&mut self, from: SocketAddr, d: &[u8], chunk: &mut BytesMut) -> bool {
        if from.port() == self.own_port && self.local.contains(&from.ip()) {
            return true;
        }
        match wire::parse(d) {
            Err(e) => {
                self.ingress
                    .reject(e.kind(), format_args!("packet from {from}: {e}"));
                true
            }
            Ok(Packet::Short {
                seq,
                channel,
                payload,
            }) => {
                if chunk.capacity() - chunk.len() < payload.len() {
                    *chunk = BytesMut::with_capacity(RECV_CHUNK.max(payload.len()));
                }
                chunk.extend_from_slice(payload);
                let payload = chunk.split().freeze();
                self.deliver(from, seq, channel, payload)
            }
            Ok(Packet::Fragment(f)) => {
                let now = std::time::Instant::now();
                let step = self.reassembler.fragment(now, from, &f, &mut self.dropped);
                self.report_dropped();
                match step {
                    Step::Complete {
                        seq,
                        channel,
                        payload,
                    } => self.deliver(from, seq, &channel, payload),
                    Step::Pending | Step::GivenUp => true,
                    Step::Duplicate => {
                        self.ingress.reject(
                            "lcm-duplicate-fragment",
                            format_args!(
                                "fragment {} of message {} from {from} seen twice",
                                f.no, f.seq
                            ),
                        );
                        true
                    }
                }
            }
        }
    }

    fn deliver(&mut self, from: SocketAddr, seq: u32, channel: &str, payload: Bytes) -> bool {
        if channel == wire::SELF_TEST_CHANNEL
            || self.channels.as_ref().is_some_and(|c| !c.matches(channel))
        {
            return true;
        }
        let topic = match self.topics.get(channel) {
            Some(t) => t.clone(),
            None => {
                if self.topics.len() >= MAX_REMEMBERED {
                    self.topics.clear();
                }
                // every channel liblcm sends, as it came (`POSE.`, `with space` too)
                let t = Topic::channel(channel).ok();
                self.topics.insert(channel.into(), t.clone());
                t
            }
        };
        let Some(topic) = topic else {
            self.ingress.reject(
                "lcm-bad-channel",
                format_args!("channel {channel:?} from {from} is empty or too long"),
            );
            return true;
        };
        let (origin, seq) = self.senders.sequence(&self.medium, from, seq);
        self.ingress.deliver(Message {
            topic,
            kind: Kind::Data,
            provenance: Provenance {
                origin,
                seq,
                hops: 0,
            },
            stamp: Stamp::now(),
            payload: Payload::from(payload),
        })
    }

    fn report_dropped(&mut self) {
        for d in self.dropped.drain(..) {
            self.ingress.reject(d.reason, &d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(url: &str) -> Result<LcmConfig, UrlError> {
        LcmConfig::from_url(&mut MediumUrl::parse(url).unwrap())
    }

    #[test]
    fn urls_read_as_liblcm_reads_them() {
        let c = cfg("udpm://239.255.76.67:7667?ttl=0&recv_buf_size=2097152").unwrap();
        assert_eq!(
            (c.group, c.port, c.ttl, c.recv_buf),
            (Ipv4Addr::new(239, 255, 76, 67), 7667, 0, 2_097_152)
        );
        let c = cfg("udpm://239.1.2.3:9000?iface=lo&channels=POSE.*&frag_timeout=500ms").unwrap();
        assert_eq!(c.iface, Some(Ipv4Addr::LOCALHOST));
        assert!(c.channels.unwrap().matches("POSE_EST"));
        assert_eq!(c.frag_timeout, Duration::from_millis(500));
        for (url, says) in [
            ("udpm://10.0.0.1:7667", "not a multicast group"),
            ("udpm://239.1.1.1:7667?ttl=256", "hop count"),
            ("udpm://239.1.1.1:7667?channels=(", "option `channels=(`"),
            ("udpm://239.1.1.1:7667?iface=nosuch0", "no such interface"),
            (
                "udpm://239.1.1.1:7667?provider=x",
                "unknown option `provider`",
            ),
        ] {
            let e = cfg(url).unwrap_err();
            assert!(e.reason.contains(says), "{url}: {}", e.reason);
        }
    }

    #[test]
    fn a_sender_jumping_back_started_again_and_origins_are_never_reused() {
        let mut senders = Senders::default();
        let a = SocketAddr::from(([10, 0, 0, 1], 7000));
        let first = senders.sequence("lcm", a, 0).0;
        for seq in 1..=2000 {
            assert_eq!(
                senders.sequence("lcm", a, seq),
                (first.clone(), u64::from(seq))
            );
        }
        // late by a little: the same sender
        assert_eq!(senders.sequence("lcm", a, 1940), (first.clone(), 1940));
        // back by more than the reorder window: started again
        let (second, seq) = senders.sequence("lcm", a, 1935);
        assert_ne!(second.id, first.id);
        assert_eq!(seq, 1935);
        let (again, seq) = senders.sequence("lcm", a, 0);
        assert_ne!(again.id, second.id);
        assert_eq!(seq, 0);
        // a wrap of the 32-bit number is no start
        let b = SocketAddr::from(([10, 0, 0, 2], 7000));
        let (ob, _) = senders.sequence("lcm", b, u32::MAX);
        assert_eq!(senders.sequence("lcm", b, 0), (ob, 1 << 32));
        // the table is cleared after a flood of senders: `a` comes back as an origin never seen
        let mut seen = vec![first.id, second.id, again.id];
        for port in 0..MAX_REMEMBERED as u16 + 1 {
            let (o, _) = senders.sequence("lcm", SocketAddr::from(([10, 0, 1, 1], port)), 0);
            seen.push(o.id);
        }
        let (back, _) = senders.sequence("lcm", a, 5);
        assert!(!seen.contains(&back.id), "origin {back:?} used before");
    }

    #[tokio::test]
    async fn a_batch_takes_several_datagrams_each_in_its_slot() {
        let rx = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).await.unwrap();
        let to = rx.local_addr().unwrap();
        let tx = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        // the largest: the largest UDP payload over IPv4
        let sizes = [1usize, 3000, 65_507, 7];
        for (i, n) in sizes.iter().enumerate() {
            tx.send_to(&vec![i as u8 + 1; *n], to).unwrap();
        }
        let mut batch = RecvBatch::new(RECV_BATCH, SLOT);
        let mut got = Vec::new();
        for _ in 0..100 {
            match batch.receive(std::os::fd::AsRawFd::as_raw_fd(&rx)) {
                Ok(n) => got.extend((0..n).map(|i| {
                    let (from, d) = batch.get(i);
                    (net::inet(from), d.to_vec())
                })),
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) => panic!("{e}"),
            }
            if got.len() == sizes.len() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        let want: Vec<_> = sizes
            .iter()
            .enumerate()
            .map(|(i, n)| (tx.local_addr().ok(), vec![i as u8 + 1; *n]))
            .collect();
        assert_eq!(got, want);
    }

    #[test]
    fn an_empty_url_is_the_default() {
        // the environment variable is read when set; without it the default applies
        if std::env::var(ENV_URL).is_err() {
            let c = cfg("udpm://?ttl=1").unwrap();
            assert_eq!(
                (c.group, c.port, c.ttl),
                (Ipv4Addr::new(239, 255, 76, 67), 7667, 1)
            );
        }
    }
}
