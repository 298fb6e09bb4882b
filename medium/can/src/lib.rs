//! CAN media: frames ([`frame`]: 11- and 29-bit identifiers, remote, error and CAN FD frames) as
//! messages on topics `can.ID`, read from and written to the wire by a backend:
//!
//! ```text
//! slcan:///dev/ttyACM0?bitrate=500000               a serial adapter speaking slcan (CANable, …)
//! slcan+pty:///tmp/canable                          a new pseudo-terminal behaving as an slcan adapter,
//!                                                   its other end linked at /tmp/canable for any
//!                                                   CAN tool (python-can, …) to open
//! cannelloni://10.0.0.2:20000                       CAN over UDP with a cannelloni peer
//! socketcan://can0                                  a Linux CAN interface ([`socketcan`])
//! ```
//!
//! [`slcan`] is the adapters' line protocol. Options of every backend: `filter` — identifiers to
//! keep, `ID:MASK` pairs in hex separated by commas (`filter=123:7ff,18ff0000:1fff0000`); a frame
//! passes when `frame_id & MASK == ID & MASK` for one of them (error frames always pass). Options of
//! `slcan://`: `bitrate` (default 500000), `data_bitrate` (CAN FD: 2000000 or 5000000),
//! `firmware` (`lawicel` or `canable`: their codes for 750 k, 800 k and 83.3 k differ),
//! `listen_only`, `timestamps` (ask the adapter for its timestamps, given as `time_ms`), `baud`
//! (the serial line's speed, default 115200; USB adapters ignore it), `reopen` and `reopen_max`
//! (waits between attempts to reopen the device: 500ms doubling up to 5s; [`Backoff`]).
//!
//! Options of `cannelloni://PEER:PORT` (the peer's IPv4 address and port, default port 20000):
//! `bind` (the local address, default `0.0.0.0` on the peer's port). Each frame sent goes in a
//! packet of its own; packets from other addresses than the peer's are counted and dropped
//! ([`cannelloni`] is the packet format).
//!
//! The slcan host opens the adapter with `C`, `S`*n* (and `Y`*n*), `Z0`/`Z1`, then `O` or `L`, and
//! closes it with `C`; an adapter's BEL (refused) is counted and logged. The pseudo-terminal
//! adapter answers a host as an adapter does: commands get CR or BEL (a bit rate only while closed),
//! `V`, `N` and `F` get answers, frames pass only while the channel is open, with timestamps after
//! `Z1`. It accepts what python-can sends to open a channel (`C`, `S6`, an empty line, `O`, `O`).
//!
//! Who may depend on it: the program (to register the schemes), and drivers and bridges that work
//! on CAN frames ([`frame`]). It depends on the core and `seabus-tty`.

pub mod cannelloni;
pub mod frame;
pub mod slcan;
pub mod socketcan;

use bytes::Bytes;
use frame::{CanFrame, FrameKind};
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::link::{Backoff, Encode, LinkQueue, LinkSender, Linked, link_queue, spawn_link};
use seabus_medium::medium::{
    BoxFuture, Ingress, LinkState, OpenError, Opening, SendError, Transport,
};
use seabus_medium::message::Message;
use seabus_medium::payload::Payload;
use seabus_medium::topic::Topic;
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{Opened, Scheme, Schemes};
use seabus_tty::{PtyLink, SerialStream};
use slcan::{Command, Firmware, Line, Lines};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

/// What every CAN medium can do: CAN frames (datamaps on `can.ID`) of up to 64 data bytes, without
/// seabus's provenance; `link_state` says whether the backend's link comes and goes.
pub fn capabilities(link_state: bool) -> Capabilities {
    Capabilities {
        provenance: false,
        framing: Framing::Frame,
        max_frame: Some(frame::MAX_FD),
        hears_own: false,
        carries: Carries::DataMap,
        link_state,
        native: Some("can"),
        qos: false,
        lists: false,
    }
}

/// Adds `slcan://`, `slcan+pty://`, `cannelloni://` and `socketcan://`.
pub fn register(schemes: &mut Schemes) {
    schemes
        .add(Scheme {
            name: "slcan",
            family: "can",
            summary: "an slcan CAN adapter on a serial device (CANable, Lawicel, ...)",
            check: |url| SlcanConfig::from_url(url).map(|_| capabilities(true)),
            open: |o| Ok(Opened::from(open_slcan(o)?)),
        })
        .add(Scheme {
            name: "slcan+pty",
            family: "can",
            summary: "a new pseudo-terminal behaving as an slcan adapter, for CAN tools to open",
            check: |url| SlcanConfig::from_url(url).map(|_| capabilities(true)),
            open: |o| Ok(Opened::from(open_slcan(o)?)),
        })
        .add(Scheme {
            name: "cannelloni",
            family: "can",
            summary: "CAN frames over UDP with a cannelloni peer",
            check: |url| CannelloniConfig::from_url(url).map(|_| capabilities(false)),
            open: |o| Ok(Opened::from(open_cannelloni(o)?)),
        })
        .add(Scheme {
            name: "socketcan",
            family: "can",
            summary: "a Linux SocketCAN interface",
            check: |url| socketcan::SocketCanConfig::from_url(url).map(|_| capabilities(true)),
            open: |o| Ok(Opened::from(socketcan::open_socketcan(o)?)),
        });
}

/// What every CAN transport says of a message for echo recognition: the frame's identifier, kind
/// and data, whatever else its datamap held (`None` when it is not a frame).
pub fn frame_fingerprint(topic: &Topic, payload: &Payload) -> Option<u64> {
    use std::hash::{Hash, Hasher};
    let frame = CanFrame::from_message(topic.as_str(), payload).ok()?;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    frame.to_string().hash(&mut h);
    Some(h.finish())
}

/// A registry with the CAN schemes and the in-process medium, for a program or test that uses
/// only these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}

/// Frames waiting to be written; a sender waits when the line is this far behind.
const WRITE_QUEUE: usize = 256;

/// One `ID:MASK` filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Filter {
    /// The identifier bits wanted.
    pub id: u32,
    /// Which bits are compared.
    pub mask: u32,
}

/// Which frames a CAN medium keeps: all when empty.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Filters(pub Vec<Filter>);

impl Filters {
    /// Reads `ID:MASK,ID:MASK…` (hex).
    pub fn parse(text: &str) -> Result<Filters, String> {
        text.split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(|pair| {
                let (id, mask) = pair
                    .split_once(':')
                    .ok_or_else(|| format!("`{pair}` is not ID:MASK"))?;
                let hex = |s: &str| {
                    u32::from_str_radix(s.trim().trim_start_matches("0x"), 16)
                        .ok()
                        .filter(|v| *v <= frame::MAX_EXTENDED_ID)
                        .ok_or_else(|| format!("`{s}` in `{pair}` is not a hex identifier"))
                };
                Ok(Filter {
                    id: hex(id)?,
                    mask: hex(mask)?,
                })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Filters)
    }

    /// Whether `frame` passes.
    pub fn pass(&self, frame: &CanFrame) -> bool {
        self.0.is_empty()
            || frame.kind() == FrameKind::Error
            || self.0.iter().any(|f| frame.id() & f.mask == f.id & f.mask)
    }
}

/// The settings every CAN backend reads from its URL.
fn take_filters(url: &mut MediumUrl) -> Result<Filters, UrlError> {
    match url.take("filter") {
        None => Ok(Filters::default()),
        Some(text) => Filters::parse(&text).map_err(|e| url.error(format!("option `filter`: {e}"))),
    }
}

/// Whether the medium talks to an adapter or is one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// `slcan://`: seabus is the host of an adapter on a serial device.
    Host,
    /// `slcan+pty://`: seabus is the adapter, on a pseudo-terminal it makes.
    Adapter,
}

/// An slcan medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq)]
pub struct SlcanConfig {
    /// The device, or where the pseudo-terminal is linked.
    pub path: PathBuf,
    /// Host or adapter.
    pub role: Role,
    /// The classic bit rate.
    pub bitrate: u32,
    /// The CAN FD data bit rate.
    pub data_bitrate: Option<u32>,
    /// The adapter's firmware.
    pub firmware: Firmware,
    /// Open listen-only.
    pub listen_only: bool,
    /// Ask for the adapter's timestamps.
    pub timestamps: bool,
    /// The serial line's speed.
    pub baud: u32,
    /// Waits between attempts to reopen the device.
    pub reopen: Backoff,
    /// Frames kept.
    pub filters: Filters,
}

impl SlcanConfig {
    /// Reads the settings of an `slcan://` or `slcan+pty://` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<SlcanConfig, UrlError> {
        let path = seabus_tty::device_path(url)?;
        let role = if url.scheme == "slcan+pty" {
            Role::Adapter
        } else {
            Role::Host
        };
        let firmware = match url.take("firmware").as_deref() {
            None | Some("lawicel") => Firmware::Lawicel,
            Some("canable") => Firmware::Canable,
            Some(f) => {
                return Err(url.error(format!(
                    "option `firmware={f}`: expected lawicel or canable"
                )));
            }
        };
        let bitrate: u32 = url
            .take_parsed("bitrate", "a bit rate such as 500000")?
            .unwrap_or(500_000);
        slcan::bitrate_code(bitrate, firmware)
            .map_err(|e| url.error(format!("option `bitrate`: {e}")))?;
        let data_bitrate: Option<u32> = url.take_parsed("data_bitrate", "2000000 or 5000000")?;
        if let Some(d) = data_bitrate
            && !slcan::DATA_BITRATES.iter().any(|(b, _)| *b == d)
        {
            return Err(url.error(format!(
                "option `data_bitrate={d}`: expected 2000000 or 5000000"
            )));
        }
        let baud: u32 = url
            .take_parsed("baud", "a line speed such as 115200")?
            .unwrap_or(115_200);
        let reopen = Backoff::from_url(url)?;
        let cfg = SlcanConfig {
            path,
            role,
            bitrate,
            data_bitrate,
            firmware,
            listen_only: url.take_flag("listen_only")?.unwrap_or(false),
            timestamps: url.take_flag("timestamps")?.unwrap_or(false),
            baud,
            reopen,
            filters: take_filters(url)?,
        };
        url.finish(&[])?;
        Ok(cfg)
    }

    /// What a host sends to open the adapter.
    pub fn opening(&self) -> Vec<Command> {
        let mut v = vec![
            Command::Close,
            Command::Bitrate(slcan::bitrate_code(self.bitrate, self.firmware).unwrap_or(6)),
        ];
        if let Some(code) = self
            .data_bitrate
            .and_then(|d| slcan::DATA_BITRATES.iter().find(|(b, _)| *b == d))
        {
            v.push(Command::DataBitrate(code.1));
        }
        v.push(Command::Timestamps(self.timestamps));
        v.push(if self.listen_only {
            Command::ListenOnly
        } else {
            Command::Open
        });
        v
    }
}

/// Topics of received frames, made once per identifier.
#[derive(Default)]
struct Topics(HashMap<(u32, bool, bool), Topic>);

impl Topics {
    fn of(&mut self, f: &CanFrame) -> Option<Topic> {
        let key = (f.id(), f.is_extended(), f.kind() == FrameKind::Error);
        if let Some(t) = self.0.get(&key) {
            return Some(t.clone());
        }
        if self.0.len() > 8192 {
            self.0.clear();
        }
        let t = Topic::new(&f.topic()).ok()?;
        self.0.insert(key, t.clone());
        Some(t)
    }
}

/// Delivers received frames that pass the filters.
struct Receiver {
    ingress: Ingress,
    filters: Filters,
    topics: Topics,
}

impl Receiver {
    fn frame(&mut self, f: &CanFrame, time_ms: Option<u32>) {
        if !self.filters.pass(f) {
            return;
        }
        if let Some(topic) = self.topics.of(f) {
            self.ingress
                .originate(topic, Payload::from(f.to_map(time_ms)));
        }
    }
}

/// What the slcan schemes do with messages: frames as slcan lines.
pub struct SlcanEncoder {
    /// the adapter's pseudo-terminal link, removed on close
    pty: Option<PtyLink>,
}

impl Encode for SlcanEncoder {
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        capabilities(true)
    }

    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64> {
        frame_fingerprint(topic, payload)
    }

    fn encode(&self, msg: &Message, line: &LinkSender<Bytes>) -> Result<Bytes, SendError> {
        let frame = frame_to_send(line.medium(), msg)?;
        slcan::encode_frame(&frame, None)
            .map(Bytes::from)
            .map_err(|reason| line.error(reason))
    }

    fn close(&self) {
        if let Some(p) = &self.pty {
            p.remove();
        }
    }
}

/// The transport of the slcan schemes.
pub type SlcanTransport = Linked<SlcanEncoder>;

/// Runs the line on an opened port: a fresh receiver and the pump.
fn run_line<'q>(
    port: SerialStream,
    cfg: SlcanConfig,
    ingress: Ingress,
    queue: &'q mut LinkQueue<Bytes>,
) -> BoxFuture<'q, String> {
    Box::pin(async move {
        let mut receiver = Receiver {
            ingress,
            filters: cfg.filters.clone(),
            topics: Topics::default(),
        };
        pump(port, &cfg, queue, &mut receiver).await
    })
}

/// Opens an `slcan://` (host) or `slcan+pty://` (adapter) medium.
fn open_slcan(mut o: Opening) -> Result<Arc<SlcanTransport>, OpenError> {
    let cfg = SlcanConfig::from_url(&mut o.url)?;
    let path = cfg.path.display().to_string();
    let (line, queue) = link_queue(&o.name, path.clone(), WRITE_QUEUE);
    let ingress = o.ingress.clone();
    let pty = match cfg.role {
        Role::Host => {
            o.ingress
                .init_link(LinkState::Down(format!("{path} not opened yet")));
            let (device, baud, running) = (cfg.path.clone(), cfg.baud, cfg.clone());
            spawn_link(
                &o.ingress,
                cfg.reopen,
                queue,
                move || {
                    let device = device.clone();
                    Box::pin(async move { seabus_tty::open_device(&device, baud, |b| b) })
                },
                move |port, queue| run_line(port, running.clone(), ingress.clone(), queue),
            );
            None
        }
        Role::Adapter => {
            let running = cfg.clone();
            Some(seabus_tty::run_pty(
                &o,
                &cfg.path,
                queue,
                move |port, queue| run_line(port, running, ingress, queue),
            )?)
        }
    };
    Ok(Arc::new(Linked::new(SlcanEncoder { pty }, line)))
}

/// The adapter side's state: whether its channel is open, with timestamps.
#[derive(Debug, Default)]
struct AdapterState {
    open: bool,
    timestamps: bool,
    started: Option<std::time::Instant>,
}

impl AdapterState {
    /// The reply to a host's command (CR done, BEL refused, or an answer).
    fn command(&mut self, c: &Command) -> Option<Vec<u8>> {
        let ok = || Some(b"\r".to_vec());
        let refused = || Some(vec![0x07]);
        match c {
            Command::Open | Command::ListenOnly => {
                self.open = true;
                ok()
            }
            Command::Close => {
                self.open = false;
                ok()
            }
            Command::Bitrate(n) if !self.open && *n <= 9 => ok(),
            Command::DataBitrate(_) if !self.open => ok(),
            Command::Timestamps(on) if !self.open => {
                self.timestamps = *on;
                ok()
            }
            Command::Version(v) if v.is_empty() => Some(Command::Version("1013".into()).line()),
            Command::Serial(v) if v.is_empty() => Some(Command::Serial("SB01".into()).line()),
            Command::Status(v) if v.is_empty() => Some(Command::Status("00".into()).line()),
            // a host's flush, and the acknowledgements adapters send, need no answer
            Command::Empty | Command::Sent | Command::Refused => None,
            _ => refused(),
        }
    }

    fn stamp(&mut self) -> Option<u16> {
        let t = self.started.get_or_insert_with(std::time::Instant::now);
        self.timestamps
            .then(|| (t.elapsed().as_millis() % 60_000) as u16)
    }
}

/// Reads lines into the medium and writes frames out, until the stream fails; returns why.
async fn pump<P: AsyncRead + AsyncWrite>(
    port: P,
    cfg: &SlcanConfig,
    queue: &mut LinkQueue<Bytes>,
    receiver: &mut Receiver,
) -> String {
    let (mut reader, mut writer) = tokio::io::split(port);
    let path = cfg.path.display().to_string();
    let mut adapter = AdapterState::default();
    if cfg.role == Role::Host {
        let opening: Vec<u8> = cfg.opening().iter().flat_map(Command::line).collect();
        if let Err(e) = writer.write_all(&opening).await {
            return format!("{path}: {e}");
        }
    }
    let mut lines = Lines::new();
    let mut buf = vec![0u8; 4096];
    let mut replies: Vec<u8> = Vec::new();
    loop {
        tokio::select! {
            n = reader.read(&mut buf) => match n {
                Ok(0) => return format!("{path}: end of stream"),
                Ok(n) => {
                    lines.push(&buf[..n], &mut |line| {
                        let line = match line {
                            Ok(l) => l,
                            Err(offset) => {
                                receiver.ingress.reject(
                                    "slcan-line-too-long",
                                    format_args!("{path} at byte {offset}: a line longer than {} characters", slcan::MAX_LINE),
                                );
                                return;
                            }
                        };
                        match (slcan::parse_line(line), cfg.role) {
                            (Ok(Line::Frame(f, t)), Role::Host) => receiver.frame(&f, t.map(u32::from)),
                            (Ok(Line::Frame(f, _)), Role::Adapter) => {
                                if adapter.open {
                                    receiver.frame(&f, None);
                                    // frames are acknowledged as the CANable firmware does
                                    replies.extend_from_slice(if f.is_extended() { b"Z\r" } else { b"z\r" });
                                } else {
                                    receiver.ingress.reject("slcan-channel-closed", format_args!("{path}: a frame while the channel is closed (send O first)"));
                                    replies.push(0x07);
                                }
                            }
                            (Ok(Line::Command(Command::Refused)), Role::Host) => receiver.ingress.reject(
                                "slcan-refused",
                                format_args!("{path}: the adapter refused a command (BEL)"),
                            ),
                            (Ok(Line::Command(Command::Other(c, _))), Role::Host) => receiver.ingress.reject(
                                "slcan-unknown-line",
                                format_args!("{path}: a line starting {c:?} is neither a frame nor a reply"),
                            ),
                            (Ok(Line::Command(_)), Role::Host) => {}
                            (Ok(Line::Command(c)), Role::Adapter) => {
                                if let Some(r) = adapter.command(&c) {
                                    replies.extend_from_slice(&r);
                                }
                            }
                            (Err(e), _) => {
                                receiver.ingress.reject(e.kind(), format_args!("{path}: {e}"));
                                if cfg.role == Role::Adapter {
                                    replies.push(0x07);
                                }
                            }
                        }
                    });
                    if !replies.is_empty() {
                        if let Err(e) = writer.write_all(&replies).await {
                            return format!("{path}: {e}");
                        }
                        replies.clear();
                    }
                }
                Err(e) => return format!("{path}: {e}"),
            },
            line = queue.recv() => match line {
                Some(line) => {
                    queue.written(1);
                    if cfg.role == Role::Adapter && !adapter.open {
                        // nobody has opened the channel: the frame has nowhere to go
                        continue;
                    }
                    let stamped;
                    let line = match adapter.stamp() {
                        Some(t) if cfg.role == Role::Adapter => {
                            stamped = slcan::with_timestamp(&line, t);
                            &stamped[..]
                        }
                        _ => &line[..],
                    };
                    if let Err(e) = writer.write_all(line).await {
                        return format!("{path}: {e}");
                    }
                }
                None => {
                    if cfg.role == Role::Host {
                        let _ = writer.write_all(&Command::Close.line()).await;
                    }
                    return format!("{path}: closed");
                }
            },
        }
    }
}

/// A cannelloni medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq)]
pub struct CannelloniConfig {
    /// The peer frames are sent to, and the only one they are taken from.
    pub peer: std::net::SocketAddr,
    /// The local address.
    pub bind: std::net::SocketAddr,
    /// Frames kept.
    pub filters: Filters,
}

impl CannelloniConfig {
    /// Reads the settings of a `cannelloni://PEER:PORT` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<CannelloniConfig, UrlError> {
        let ip: std::net::Ipv4Addr = url.host.parse().map_err(|_| {
            url.error(format!(
                "`{}` is not the peer's IPv4 address (cannelloni://10.0.0.2:20000)",
                url.host
            ))
        })?;
        let port = url.port.unwrap_or(cannelloni::DEFAULT_PORT);
        let bind = match url.take("bind") {
            None => std::net::SocketAddr::from(([0, 0, 0, 0], port)),
            Some(b) => b.parse().map_err(|_| {
                url.error(format!(
                    "option `bind={b}`: expected an address and port such as 0.0.0.0:20000"
                ))
            })?,
        };
        let cfg = CannelloniConfig {
            peer: std::net::SocketAddr::from((ip, port)),
            bind,
            filters: take_filters(url)?,
        };
        url.finish(&[])?;
        Ok(cfg)
    }
}

/// The frame a message sent on CAN medium `medium` stands for, or why it stands for none.
pub(crate) fn frame_to_send(medium: &str, msg: &Message) -> Result<CanFrame, SendError> {
    CanFrame::from_message(msg.topic.as_str(), &msg.payload).map_err(|reason| SendError::Io {
        medium: medium.to_string(),
        reason,
    })
}

/// The transport of `cannelloni://`.
pub struct CannelloniTransport {
    name: Arc<str>,
    socket: Arc<tokio::net::UdpSocket>,
    peer: std::net::SocketAddr,
    seq: std::sync::atomic::AtomicU8,
}

impl Transport for CannelloniTransport {
    type Frame = Bytes;

    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64> {
        frame_fingerprint(topic, payload)
    }

    fn capabilities(&self) -> Capabilities {
        capabilities(false)
    }

    fn encode(&self, msg: &Message) -> Result<Bytes, SendError> {
        let frame = frame_to_send(&self.name, msg)?;
        let seq = self.seq.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(Bytes::from(cannelloni::encode(seq, &[frame])))
    }

    fn transmit(&self, packet: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            self.socket
                .send_to(&packet, self.peer)
                .await
                .map(|_| ())
                .map_err(|e| SendError::Io {
                    medium: self.name.to_string(),
                    reason: format!("sending to {}: {e}", self.peer),
                })
        })
    }
}

/// Opens a `cannelloni://` medium.
fn open_cannelloni(mut o: Opening) -> Result<Arc<CannelloniTransport>, OpenError> {
    let cfg = CannelloniConfig::from_url(&mut o.url)?;
    let socket = std::net::UdpSocket::bind(cfg.bind)
        .and_then(|s| {
            s.set_nonblocking(true)?;
            tokio::net::UdpSocket::from_std(s)
        })
        .map_err(o.io_error(format!("binding {}", cfg.bind)))?;
    let socket = Arc::new(socket);
    let mut receiver = Receiver {
        ingress: o.ingress.clone(),
        filters: cfg.filters.clone(),
        topics: Topics::default(),
    };
    let (rx_socket, peer) = (socket.clone(), cfg.peer);
    let task = tokio::spawn(async move {
        let mut buf = vec![0u8; 65_536];
        loop {
            let (n, from) = match rx_socket.recv_from(&mut buf).await {
                Ok(r) => r,
                Err(e) => {
                    tracing::debug!("cannelloni receive: {e}");
                    continue;
                }
            };
            if from.ip() != peer.ip() {
                receiver.ingress.reject(
                    "cannelloni-unknown-peer",
                    format_args!("a packet from {from}, not the peer {peer}"),
                );
                continue;
            }
            match cannelloni::decode(&buf[..n]) {
                Ok(p) => {
                    for f in &p.frames {
                        receiver.frame(f, None);
                    }
                }
                Err(e) => receiver
                    .ingress
                    .reject(e.kind(), format_args!("packet from {from}: {e}")),
            }
        }
    });
    o.ingress.own_task(task.abort_handle());
    o.ingress.set_link(LinkState::Up);
    Ok(Arc::new(CannelloniTransport {
        name: o.name.clone(),
        socket,
        peer: cfg.peer,
        seq: std::sync::atomic::AtomicU8::new(0),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(url: &str) -> Result<SlcanConfig, UrlError> {
        SlcanConfig::from_url(&mut MediumUrl::parse(url).unwrap())
    }

    #[test]
    fn slcan_options_are_read_and_checked() {
        let c = cfg("slcan:///dev/ttyACM0?bitrate=250000&timestamps=true&filter=123:7ff").unwrap();
        assert_eq!(
            (c.bitrate, c.role, c.timestamps),
            (250_000, Role::Host, true)
        );
        assert_eq!(
            c.opening(),
            [
                Command::Close,
                Command::Bitrate(5),
                Command::Timestamps(true),
                Command::Open
            ]
        );
        let c = cfg("slcan+pty:///tmp/can0").unwrap();
        assert_eq!((c.bitrate, c.role), (500_000, Role::Adapter));
        let fd = cfg(
            "slcan:///dev/x?firmware=canable&bitrate=750000&data_bitrate=2000000&listen_only=1",
        )
        .unwrap();
        assert_eq!(
            fd.opening(),
            [
                Command::Close,
                Command::Bitrate(7),
                Command::DataBitrate(2),
                Command::Timestamps(false),
                Command::ListenOnly
            ]
        );
        for (url, want) in [
            (
                "slcan:///dev/x?bitrate=750000",
                "750000 bit/s has no slcan code",
            ),
            (
                "slcan:///dev/x?firmware=peak",
                "expected lawicel or canable",
            ),
            (
                "slcan:///dev/x?data_bitrate=4000000",
                "expected 2000000 or 5000000",
            ),
            ("slcan:///dev/x?filter=12", "`12` is not ID:MASK"),
            (
                "slcan:///dev/x?filter=1:zz",
                "`zz` in `1:zz` is not a hex identifier",
            ),
            ("slcan://dev/x", "three slashes"),
            ("slcan:///dev/x?speed=1", "speed"),
        ] {
            let e = cfg(url).unwrap_err().to_string();
            assert!(e.contains(want), "{url}: {e}");
        }
    }

    #[test]
    fn filters_keep_matching_identifiers() {
        let f = Filters::parse("123:7ff, 18ff0000:1fff0000").unwrap();
        let d = |id, ext| CanFrame::data(id, ext, &[]).unwrap();
        assert!(f.pass(&d(0x123, false)));
        assert!(!f.pass(&d(0x124, false)));
        assert!(f.pass(&d(0x18FF_50E5, true)));
        assert!(!f.pass(&d(0x18FE_50E5, true)));
        assert!(f.pass(&CanFrame::error(0x4, &[])));
        assert!(Filters::default().pass(&d(0x124, false)));
    }

    #[test]
    fn the_adapter_answers_as_adapters_do() {
        let mut a = AdapterState::default();
        // python-can's opening: C, S6, an empty line, O, O
        let replies: Vec<Option<Vec<u8>>> = [
            Command::Close,
            Command::Bitrate(6),
            Command::Empty,
            Command::Open,
            Command::Open,
        ]
        .iter()
        .map(|c| a.command(c))
        .collect();
        assert_eq!(
            replies,
            [
                Some(b"\r".to_vec()),
                Some(b"\r".to_vec()),
                None,
                Some(b"\r".to_vec()),
                Some(b"\r".to_vec())
            ]
        );
        assert!(a.open);
        // no bit rate change while open
        assert_eq!(a.command(&Command::Bitrate(4)), Some(vec![0x07]));
        assert_eq!(
            a.command(&Command::Version(String::new())),
            Some(b"V1013\r".to_vec())
        );
        assert_eq!(
            a.command(&Command::Other('X', String::new())),
            Some(vec![0x07])
        );
    }
}
