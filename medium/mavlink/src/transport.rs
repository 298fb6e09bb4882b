//! The `mavlink://` transport: its I/O task (UDP, TCP or a serial line), its heartbeat, the
//! vehicles it hears, and what messages become on the wire.

use crate::config::{Address, MavlinkConfig};
use crate::convert::HEADER_FIELDS;
use crate::frame::{self, Item, StreamReader};
use crate::vehicles::{self, Changes, Vehicles};
use bytes::Bytes;
use mavlink::MavHeader;
use seabus_medium::caps::Capabilities;
use seabus_medium::link::{LinkQueue, LinkSender, link_queue};
use seabus_medium::tally::Limiter;
use seabus_medium::{
    BoxFuture, DataMap, Ingress, LinkState, Message, OpenError, Opening, Payload, SendError, Topic,
    Transport, Value, WireError,
};
use std::collections::HashMap;
use std::future::Future;
use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::time::Interval;

/// Frames waiting for a TCP connection or a serial line; a sender waits when it is this far behind.
const WRITE_QUEUE: usize = 1024;
/// How long a `udpin` medium keeps sending to a peer it no longer hears.
pub const PEER_TTL: Duration = Duration::from_secs(30);
/// How many peers a `udpin` medium sends to; the one heard least recently is dropped for a new one.
pub const MAX_PEERS: usize = 16;
/// How long connecting over TCP may take.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// Where a UDP medium sends.
enum Targets {
    /// One address (`udpout`, `udpbcast`).
    Fixed(SocketAddr),
    /// Every peer heard lately (`udpin`), with when it was last heard.
    Heard(Mutex<Vec<(SocketAddr, Instant)>>),
}

impl Targets {
    /// Notes a datagram from `from` (for `udpin`).
    fn heard(&self, from: SocketAddr, now: Instant) {
        if let Targets::Heard(peers) = self {
            let mut peers = peers.lock().unwrap_or_else(|p| p.into_inner());
            match peers.iter_mut().find(|(a, _)| *a == from) {
                Some(p) => p.1 = now,
                None => {
                    if peers.len() >= MAX_PEERS
                        && let Some(i) = (0..peers.len()).min_by_key(|i| peers[*i].1)
                    {
                        peers.swap_remove(i);
                    }
                    peers.push((from, now));
                }
            }
        }
    }

    /// Where to send now.
    fn now(&self, now: Instant) -> Vec<SocketAddr> {
        match self {
            Targets::Fixed(a) => vec![*a],
            Targets::Heard(peers) => {
                let mut peers = peers.lock().unwrap_or_else(|p| p.into_inner());
                peers.retain(|(_, t)| now.saturating_duration_since(*t) < PEER_TTL);
                peers.iter().map(|(a, _)| *a).collect()
            }
        }
    }
}

/// The wire's sending side.
enum Sender {
    /// A UDP socket, written at once.
    Udp {
        sock: Arc<UdpSocket>,
        targets: Arc<Targets>,
        /// the `udpin` address, for the error when no peer was heard
        listen: String,
    },
    /// A connection or a device, written by the I/O task.
    Link(LinkSender<Bytes>),
}

/// The transport of `mavlink://`.
pub struct MavlinkTransport {
    cfg: Arc<MavlinkConfig>,
    name: Arc<str>,
    seq: Arc<AtomicU8>,
    sender: Sender,
}

/// The message name of a topic `mavlink.SYSID.NAME`.
pub fn message_name(topic: &str) -> Result<&str, String> {
    let mut parts = topic.split('.');
    match (parts.next(), parts.next(), parts.next(), parts.next()) {
        (Some("mavlink"), Some(sys), Some(name), None) if sys.parse::<u8>().is_ok() => Ok(name),
        _ => Err(format!(
            "`{topic}` names no MAVLink message: a MAVLink medium sends topics \
             mavlink.SYSID.MESSAGE_NAME (such as mavlink.1.COMMAND_LONG)"
        )),
    }
}

impl MavlinkTransport {
    fn error(&self, reason: impl Into<String>) -> SendError {
        SendError::Io {
            medium: self.name.to_string(),
            reason: reason.into(),
        }
    }
}

impl Transport for MavlinkTransport {
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        self.cfg.capabilities()
    }

    fn encode(&self, msg: &Message) -> Result<Bytes, SendError> {
        let name = message_name(msg.topic.as_str()).map_err(|e| self.error(e))?;
        let map = msg.payload.to_map().map_err(|e| SendError::Convert {
            medium: self.name.to_string(),
            source: e,
        })?;
        let header = MavHeader {
            system_id: u32::from(self.cfg.sysid),
            component_id: self.cfg.compid,
            sequence: self.seq.fetch_add(1, Ordering::Relaxed),
        };
        self.cfg
            .dialect
            .encode(self.cfg.version, header, name, &map)
            .map(Bytes::from)
            .map_err(|e| self.error(e))
    }

    fn transmit(&self, frame: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            match &self.sender {
                Sender::Link(link) => link.send(frame).await,
                Sender::Udp {
                    sock,
                    targets,
                    listen,
                } => {
                    let to = targets.now(Instant::now());
                    if to.is_empty() {
                        return Err(SendError::LinkDown {
                            medium: self.name.to_string(),
                            reason: format!(
                                "no peer heard on {listen} within {} s to send to",
                                PEER_TTL.as_secs()
                            ),
                        });
                    }
                    for addr in to {
                        sock.send_to(&frame, addr)
                            .await
                            .map_err(|e| self.error(format!("sending to {addr}: {e}")))?;
                    }
                    Ok(())
                }
            }
        })
    }

    fn flush(&self) -> BoxFuture<'_, ()> {
        match &self.sender {
            Sender::Link(link) => Box::pin(link.flush()),
            Sender::Udp { .. } => Box::pin(std::future::ready(())),
        }
    }

    fn close(&self) {
        if let Sender::Link(link) = &self.sender {
            link.close();
        }
    }
}

/// What the I/O task keeps across connections: the medium's ingress, the vehicles heard, its
/// heartbeat, what it knows of each sender.
struct Session {
    cfg: Arc<MavlinkConfig>,
    ingress: Ingress,
    seq: Arc<AtomicU8>,
    vehicles: Vehicles,
    /// topics by sender and message
    topics: HashMap<(u32, &'static str), Topic>,
    /// the last sequence number heard from each sender
    last_seq: HashMap<(u32, u8), u8>,
    /// this medium's own heartbeat's fields
    own_heartbeat: DataMap,
    /// errors of the wire's reading and writing that are not a lost connection
    io_errors: Limiter,
    vehicles_topic: Topic,
}

impl Session {
    fn new(cfg: Arc<MavlinkConfig>, ingress: Ingress, seq: Arc<AtomicU8>) -> Session {
        let own_heartbeat = DataMap::new()
            .and("custom_mode", 0i64)
            .and("type", cfg.role.mav_type())
            .and("autopilot", "MAV_AUTOPILOT_INVALID")
            .and("base_mode", 0i64)
            .and("system_status", "MAV_STATE_ACTIVE")
            .and("mavlink_version", 3i64);
        Session {
            vehicles: Vehicles::new(cfg.timeout, Instant::now(), "no vehicle heard yet"),
            cfg,
            ingress,
            seq,
            topics: HashMap::new(),
            last_seq: HashMap::new(),
            own_heartbeat,
            io_errors: Limiter::default(),
            vehicles_topic: Topic::new(vehicles::TOPIC).expect("a valid topic"),
        }
    }

    /// This medium's heartbeat, framed.
    fn heartbeat(&self) -> Option<Bytes> {
        let header = MavHeader {
            system_id: u32::from(self.cfg.sysid),
            component_id: self.cfg.compid,
            sequence: self.seq.fetch_add(1, Ordering::Relaxed),
        };
        match self
            .cfg
            .dialect
            .encode(self.cfg.version, header, "HEARTBEAT", &self.own_heartbeat)
        {
            Ok(b) => Some(Bytes::from(b)),
            Err(e) => {
                tracing::error!("cannot make this medium's heartbeat: {e}");
                None
            }
        }
    }

    /// Publishes the vehicles that changed and sets the link.
    fn apply(&mut self, c: Changes) {
        for map in c.publish {
            self.ingress
                .originate(self.vehicles_topic.clone(), Payload::from(map));
        }
        if let Some(state) = c.link {
            self.ingress.set_link(state);
        }
    }

    fn tick(&mut self) {
        let c = self.vehicles.tick(Instant::now());
        self.apply(c);
    }

    /// The wire was lost, for `why`.
    fn lost(&mut self, why: String) {
        let c = self.vehicles.lost(why);
        self.apply(c);
    }

    /// Logs an error of the wire that is not a lost connection, at most once in 10 s.
    fn io_error(&mut self, what: impl std::fmt::Display) {
        if let Some(held) = self.io_errors.admit(Instant::now()) {
            tracing::warn!(address = %self.cfg.address, "{what}{held}");
        }
    }

    /// What the frame reader found, from `from`.
    fn item(&mut self, item: Item, from: &dyn std::fmt::Display) {
        match item {
            Item::Frame(f) => self.frame(f, from),
            Item::Rejected(e, n, counted) => {
                self.ingress.dropped(n as u64);
                if counted {
                    self.ingress
                        .reject(e.kind(), format_args!("from {from}: {e}"));
                }
            }
        }
    }

    /// Counts the messages a sender's sequence numbers say were lost on the way.
    fn sequence(&mut self, sysid: u32, compid: u8, seq: u8) {
        if self.last_seq.len() > 4096 {
            self.last_seq.clear();
        }
        if let Some(last) = self.last_seq.insert((sysid, compid), seq) {
            let gap = seq.wrapping_sub(last.wrapping_add(1));
            // a gap of half the range or more is a restart or a frame come late, not a loss
            if gap > 0 && gap < 128 {
                self.ingress
                    .missed(&format!("mavlink.{sysid}"), u64::from(gap));
            }
        }
    }

    /// Delivers a good frame as a message on `mavlink.SYSID.NAME`.
    fn frame(&mut self, f: frame::Frame, from: &dyn std::fmt::Display) {
        let raw = &f.raw;
        let (sysid, compid) = (raw.system_id(), raw.component_id());
        // this medium's own frames, come back through a router
        if (sysid, compid) == (u32::from(self.cfg.sysid), self.cfg.compid) {
            return;
        }
        self.sequence(sysid, compid, raw.sequence());
        let (name, mut map) = match self.cfg.dialect.decode(raw) {
            Ok(decoded) => decoded,
            Err(e) => {
                self.ingress.dropped(f.len as u64);
                let e = WireError::new("bad-value", e);
                self.ingress.reject(
                    e.kind(),
                    format_args!(
                        "from {from}: message {} of system {sysid}, component {compid}: {e}",
                        raw.message_id()
                    ),
                );
                return;
            }
        };
        if name == "HEARTBEAT" {
            let c = self
                .vehicles
                .heartbeat(sysid, compid, &map, Instant::now(), SystemTime::now());
            self.apply(c);
        }
        for (field, id) in HEADER_FIELDS.into_iter().zip([sysid, u32::from(compid)]) {
            if map.get(field).is_none() {
                map.push(field, Value::Int(id.into()));
            }
        }
        if self.topics.len() > 4096 {
            self.topics.clear();
        }
        let topic = self
            .topics
            .entry((sysid, name))
            .or_insert_with(|| {
                Topic::new(&format!("mavlink.{sysid}.{name}")).expect("a valid topic")
            })
            .clone();
        self.ingress.originate(topic, Payload::from(map));
    }
}

/// Waits for a heartbeat to be due (never, without one).
async fn beat(timer: &mut Option<Interval>) {
    match timer {
        Some(t) => {
            t.tick().await;
        }
        None => std::future::pending().await,
    }
}

fn heartbeat_timer(cfg: &MavlinkConfig) -> Option<Interval> {
    cfg.heartbeat.map(|period| {
        let mut t = tokio::time::interval(period);
        t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        t
    })
}

/// Opens a `mavlink://` medium: binds or starts connecting, and starts its I/O task.
pub(crate) fn open(mut o: Opening) -> Result<Arc<MavlinkTransport>, OpenError> {
    let cfg = Arc::new(MavlinkConfig::from_url(&mut o.url)?);
    let seq = Arc::new(AtomicU8::new(0));
    let session = Session::new(cfg.clone(), o.ingress.clone(), seq.clone());
    o.ingress
        .init_link(LinkState::Down("no vehicle heard yet".to_string()));
    let (sender, task) = match &cfg.address {
        Address::UdpIn(addr) => {
            let sock = bind_udp(*addr, false).map_err(o.io_error(format!("binding {addr}")))?;
            let targets = Arc::new(Targets::Heard(Mutex::new(Vec::new())));
            let sender = Sender::Udp {
                sock: sock.clone(),
                targets: targets.clone(),
                listen: cfg.address.to_string(),
            };
            (sender, tokio::spawn(run_udp(sock, targets, session)))
        }
        Address::UdpOut(host, port) => {
            let to = resolve(host, *port).map_err(o.io_error(format!("resolving {host}")))?;
            let sock =
                bind_udp(unspecified(to), false).map_err(o.io_error("binding a UDP socket"))?;
            let targets = Arc::new(Targets::Fixed(to));
            let sender = Sender::Udp {
                sock: sock.clone(),
                targets: targets.clone(),
                listen: cfg.address.to_string(),
            };
            (sender, tokio::spawn(run_udp(sock, targets, session)))
        }
        Address::UdpBcast(to) => {
            let to = SocketAddr::V4(*to);
            let sock =
                bind_udp(unspecified(to), true).map_err(o.io_error("binding a UDP socket"))?;
            let targets = Arc::new(Targets::Fixed(to));
            let sender = Sender::Udp {
                sock: sock.clone(),
                targets: targets.clone(),
                listen: cfg.address.to_string(),
            };
            (sender, tokio::spawn(run_udp(sock, targets, session)))
        }
        Address::TcpOut(host, port) => {
            let (link, queue) = link_queue(
                &o.name,
                format!("the connection to {host}:{port}"),
                WRITE_QUEUE,
            );
            let target = format!("{host}:{port}");
            let connect = move || {
                let target = target.clone();
                async move {
                    match tokio::time::timeout(CONNECT_TIMEOUT, TcpStream::connect(&target)).await {
                        Ok(Ok(s)) => {
                            let _ = s.set_nodelay(true);
                            Ok((s, None))
                        }
                        Ok(Err(e)) => Err(format!("cannot connect to {target}: {e}")),
                        Err(_) => Err(format!(
                            "cannot connect to {target}: no answer within {CONNECT_TIMEOUT:?}"
                        )),
                    }
                }
            };
            let reopen = cfg.reopen;
            (
                Sender::Link(link),
                tokio::spawn(run_stream(connect, reopen, queue, session)),
            )
        }
        Address::TcpIn(addr) => {
            let listener = bind_tcp(*addr).map_err(o.io_error(format!("listening on {addr}")))?;
            let listener = Arc::new(listener);
            let (link, queue) = link_queue(
                &o.name,
                format!("a client's connection on {addr}"),
                WRITE_QUEUE,
            );
            let connect = move || {
                let listener = listener.clone();
                async move {
                    match listener.accept().await {
                        Ok((s, _)) => {
                            let _ = s.set_nodelay(true);
                            Ok((s, None))
                        }
                        Err(e) => Err(format!("accepting a client: {e}")),
                    }
                }
            };
            // waiting for the next client is no failure; a failure to accept is tried again soon
            let reopen = seabus_medium::link::Backoff {
                first: Duration::from_millis(10),
                max: Duration::from_secs(1),
            };
            (
                Sender::Link(link),
                tokio::spawn(run_stream(connect, reopen, queue, session)),
            )
        }
        Address::Serial(path, baud) => {
            let (link, queue) = link_queue(&o.name, path.display().to_string(), WRITE_QUEUE);
            let (path, baud) = (path.clone(), *baud);
            let connect = move || {
                let opened = seabus_tty::open_device(&path, baud, |b| b).map(|port| {
                    let overruns = seabus_tty::Overruns::of(&port);
                    (port, overruns)
                });
                std::future::ready(opened)
            };
            let reopen = cfg.reopen;
            (
                Sender::Link(link),
                tokio::spawn(run_stream(connect, reopen, queue, session)),
            )
        }
    };
    o.ingress.own_task(task.abort_handle());
    Ok(Arc::new(MavlinkTransport {
        cfg,
        name: o.name.clone(),
        seq,
        sender,
    }))
}

/// The first address `host` names, IPv4 first.
fn resolve(host: &str, port: u16) -> std::io::Result<SocketAddr> {
    let all: Vec<SocketAddr> = (host, port).to_socket_addrs()?.collect();
    all.iter()
        .find(|a| a.is_ipv4())
        .or(all.first())
        .copied()
        .ok_or_else(|| std::io::Error::other(format!("`{host}` names no address")))
}

/// Any local address of the family of `to`, on a port the system picks.
fn unspecified(to: SocketAddr) -> SocketAddr {
    match to {
        SocketAddr::V4(_) => "0.0.0.0:0".parse().expect("an address"),
        SocketAddr::V6(_) => "[::]:0".parse().expect("an address"),
    }
}

fn bind_udp(addr: SocketAddr, broadcast: bool) -> std::io::Result<Arc<UdpSocket>> {
    let sock = std::net::UdpSocket::bind(addr)?;
    sock.set_broadcast(broadcast)?;
    sock.set_nonblocking(true)?;
    Ok(Arc::new(UdpSocket::from_std(sock)?))
}

fn bind_tcp(addr: SocketAddr) -> std::io::Result<TcpListener> {
    let l = std::net::TcpListener::bind(addr)?;
    l.set_nonblocking(true)?;
    TcpListener::from_std(l)
}

/// Reads and writes a UDP socket until the medium closes.
async fn run_udp(sock: Arc<UdpSocket>, targets: Arc<Targets>, mut s: Session) {
    let mut buf = vec![0u8; 65_536];
    let mut timer = heartbeat_timer(&s.cfg);
    loop {
        let deadline = tokio::time::Instant::from_std(s.vehicles.next_deadline());
        tokio::select! {
            r = sock.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    targets.heard(from, Instant::now());
                    frame::datagram(s.cfg.dialect, &buf[..n], |item| s.item(item, &from));
                }
                Err(e) => {
                    s.io_error(format_args!("reading: {e}"));
                    // an error that lasts is not read again at once
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            },
            _ = beat(&mut timer) => {
                if let Some(hb) = s.heartbeat() {
                    for addr in targets.now(Instant::now()) {
                        if let Err(e) = sock.send_to(&hb, addr).await {
                            s.io_error(format_args!("sending the heartbeat to {addr}: {e}"));
                        }
                    }
                }
            }
            _ = tokio::time::sleep_until(deadline) => s.tick(),
        }
    }
}

/// Waits `wait` while keeping the vehicles list.
async fn pause(s: &mut Session, wait: Duration) {
    let until = tokio::time::Instant::now() + wait;
    loop {
        let deadline = tokio::time::Instant::from_std(s.vehicles.next_deadline());
        tokio::select! {
            _ = tokio::time::sleep_until(until) => return,
            _ = tokio::time::sleep_until(deadline) => s.tick(),
        }
    }
}

/// Keeps a connection or a device (`connect` makes one, with the serial device's overrun
/// counters when it has them) and carries frames both ways on it until the medium closes.
async fn run_stream<S, C, F>(
    mut connect: C,
    reopen: seabus_medium::link::Backoff,
    mut queue: LinkQueue<Bytes>,
    mut s: Session,
) where
    S: AsyncRead + AsyncWrite + Send + Unpin,
    C: FnMut() -> F,
    F: Future<Output = Result<(S, Option<seabus_tty::Overruns>), String>>,
{
    let mut wait = reopen.first;
    loop {
        let attempt = connect();
        tokio::pin!(attempt);
        let connected = loop {
            let deadline = tokio::time::Instant::from_std(s.vehicles.next_deadline());
            tokio::select! {
                r = &mut attempt => break r,
                _ = tokio::time::sleep_until(deadline) => s.tick(),
            }
        };
        match connected {
            Ok((stream, overruns)) => {
                wait = reopen.first;
                queue.set_up(true);
                let why = session(stream, overruns, &mut queue, &mut s).await;
                queue.set_up(false);
                queue.drop_waiting();
                s.lost(why);
            }
            Err(why) => {
                s.lost(why);
                pause(&mut s, wait).await;
                wait = reopen.next(wait);
            }
        }
    }
}

/// Carries frames both ways on a connection or device until it fails; returns why.
async fn session<S: AsyncRead + AsyncWrite + Unpin>(
    stream: S,
    mut overruns: Option<seabus_tty::Overruns>,
    queue: &mut LinkQueue<Bytes>,
    s: &mut Session,
) -> String {
    let what = s.cfg.address.to_string();
    let (mut rd, mut wr) = tokio::io::split(stream);
    let mut reader = StreamReader::default();
    let mut chunk = vec![0u8; 4096];
    let mut timer = heartbeat_timer(&s.cfg);
    let why = loop {
        let deadline = tokio::time::Instant::from_std(s.vehicles.next_deadline());
        tokio::select! {
            r = rd.read(&mut chunk) => match r {
                Ok(0) => break format!("{what}: the other end closed the connection"),
                Ok(n) => {
                    if let Some(o) = overruns.as_mut() {
                        let lost = o.take();
                        if lost > 0 {
                            s.ingress.overrun(lost);
                        }
                    }
                    let dialect = s.cfg.dialect;
                    reader.push(dialect, &chunk[..n], |item| s.item(item, &what));
                }
                Err(e) => break format!("{what}: {e}"),
            },
            f = queue.recv() => {
                let Some(f) = f else { break "the medium is closed".to_string() };
                if let Err(e) = queue.write(&what, wr.write_all(&f)).await {
                    break e;
                }
            }
            _ = beat(&mut timer) => {
                if let Some(hb) = s.heartbeat()
                    && let Err(e) = wr.write_all(&hb).await
                {
                    break format!("{what}: {e}");
                }
            }
            _ = tokio::time::sleep_until(deadline) => s.tick(),
        }
    };
    let pending = reader.clear();
    if pending > 0 {
        s.ingress.dropped(pending as u64);
    }
    why
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_mavlink_topics_are_sent() {
        assert_eq!(message_name("mavlink.1.COMMAND_LONG"), Ok("COMMAND_LONG"));
        assert_eq!(message_name("mavlink.0.HEARTBEAT"), Ok("HEARTBEAT"));
        for bad in [
            "mavlink.vehicles",
            "mavlink.256.HEARTBEAT",
            "nav.attitude",
            "mavlink.1.COMMAND_LONG.x",
        ] {
            let e = message_name(bad).unwrap_err();
            assert!(e.contains("mavlink.SYSID.MESSAGE_NAME"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_udpin_medium_sends_to_the_peers_heard_lately() {
        let t0 = Instant::now();
        let targets = Targets::Heard(Mutex::new(Vec::new()));
        assert!(targets.now(t0).is_empty());
        let a: SocketAddr = "127.0.0.1:1000".parse().unwrap();
        let b: SocketAddr = "127.0.0.1:1001".parse().unwrap();
        targets.heard(a, t0);
        targets.heard(b, t0 + Duration::from_secs(10));
        targets.heard(a, t0 + Duration::from_secs(1));
        assert_eq!(targets.now(t0 + Duration::from_secs(20)), vec![a, b]);
        assert_eq!(targets.now(t0 + PEER_TTL + Duration::from_secs(2)), vec![b]);
        for i in 0..(MAX_PEERS as u16 + 4) {
            targets.heard(
                SocketAddr::from(([127, 0, 0, 1], 2000 + i)),
                t0 + Duration::from_secs(20) + Duration::from_millis(u64::from(i)),
            );
        }
        let now = targets.now(t0 + Duration::from_secs(21));
        assert_eq!(now.len(), MAX_PEERS);
        assert!(now.contains(&SocketAddr::from((
            [127, 0, 0, 1],
            2000 + MAX_PEERS as u16 + 3
        ))));
    }
}
