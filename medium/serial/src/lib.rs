//! Serial media: a serial device (`serial://`) or a pseudo-terminal that seabus creates (`pty://`),
//! with NMEA, line, COBS or SLIP framing.
//!
//! ```text
//! serial:///dev/ttyUSB0?baud=19200&framing=nmea     a device; NMEA sentences
//! serial:///dev/ttyACM0?baud=115200&framing=lines&topic=ctd.raw
//! pty:///tmp/frontseat?framing=nmea                 a new pseudo-terminal, its other end linked at
//!                                                   /tmp/frontseat for any program to open
//! ```
//! Options: `baud` (default 9600), `data_bits` (5–8), `parity` (`none`, `even`, `odd`),
//! `stop_bits` (1, 2), `flow` (flow control: `none`, `hardware` for RTS/CTS, `software` for
//! XON/XOFF, which text framings only can use: the binary ones carry those bytes), `framing` (`nmea`, `lines`, `cobs`, `slip`; default `nmea`), `checksum`
//! (`require`, `allow-missing`, `ignore`; NMEA only, default `require`), `max` (longest frame in
//! bytes; 256 for NMEA, 4096 otherwise), `topic` (the topic of received frames; for NMEA the prefix
//! of `PREFIX.ADDRESS`, default `nmea`, so that `$GPGGA,…` arrives on `nmea.GPGGA`; otherwise
//! default `serial.line` or `serial.frame`), `reopen` and `reopen_max` (waits between attempts to
//! reopen a lost device: 500ms, doubling up to 5s; see [`Backoff`]).
//!
//! Received frames are byte payloads that originate at the medium (it numbers them). What is sent
//! must be bytes or XML text; NMEA sentences without a checksum get one. When the device goes away
//! the link goes down, sends fail at once with [`SendError::LinkDown`], and the medium keeps trying
//! to reopen it; nothing else waits meanwhile.
//!
//! What is lost is counted in the medium's [`MediumStats`](seabus_medium::MediumStats): input the
//! framing rejects, by reason (`too-long` for a line over `max`), and the bytes it drops; for a
//! serial device, the characters it lost before seabus read them (its overruns, read from the
//! kernel after reads, at most every [`OVERRUN_LOOK`]); and, as on every medium, the sentences a
//! receiver's full queue drops.
//!
//! Who may depend on it: the program, to register the schemes. It depends on the core and
//! `seabus-tty`.

use bytes::Bytes;
use seabus_medium::caps::{Capabilities, Carries, Framing as WireFraming};
use seabus_medium::framing::{self, ChecksumPolicy, Framer, Framing};
use seabus_medium::link::{Backoff, Encode, LinkQueue, LinkSender, Linked, link_queue, spawn_link};
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{
    Ingress, LinkState, Message, OpenError, Opened, Opening, Payload, Scheme, Schemes, SendError,
    Topic,
};
use seabus_tty::{Overruns, PtyLink, device_path};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio_serial::{DataBits, FlowControl, Parity, StopBits};

const OPTIONS: [&str; 11] = [
    "baud",
    "data_bits",
    "parity",
    "stop_bits",
    "framing",
    "checksum",
    "max",
    "topic",
    "reopen",
    "reopen_max",
    "flow",
];

/// Frames waiting to be written; a sender waits when the line is this far behind.
const WRITE_QUEUE: usize = 64;

/// How long after a read a serial device's overrun counters are read (once for all the reads
/// meanwhile): a line that sends nothing costs nothing.
pub const OVERRUN_LOOK: Duration = Duration::from_millis(100);

/// A serial medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialConfig {
    /// The device (or, for `pty://`, where the pseudo-terminal is linked).
    pub path: PathBuf,
    /// Line speed.
    pub baud: u32,
    /// Data bits.
    pub data_bits: DataBits,
    /// Parity.
    pub parity: Parity,
    /// Stop bits.
    pub stop_bits: StopBits,
    /// Flow control.
    pub flow: FlowControl,
    /// How the stream is cut into frames.
    pub framing: Framing,
    /// NMEA checksum policy.
    pub checksum: ChecksumPolicy,
    /// Longest frame.
    pub max: usize,
    /// Topic (or, for NMEA, topic prefix) of received frames.
    pub topic: String,
    /// Waits between attempts to reopen the device.
    pub reopen: Backoff,
}

impl SerialConfig {
    /// Reads the settings from a `serial://` or `pty://` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<SerialConfig, UrlError> {
        let path = device_path(url)?;
        let framing = url
            .take_parsed("framing", "nmea, lines, cobs or slip")?
            .unwrap_or(Framing::Nmea);
        let checksum = url
            .take_parsed("checksum", "require, allow-missing or ignore")?
            .unwrap_or(ChecksumPolicy::Require);
        let baud: u32 = url
            .take_parsed("baud", "a line speed such as 19200")?
            .unwrap_or(9600);
        if baud == 0 {
            return Err(url.error("option `baud=0`: expected a line speed such as 19200"));
        }
        let data_bits = match url.take_parsed::<u8>("data_bits", "5, 6, 7 or 8")? {
            None | Some(8) => DataBits::Eight,
            Some(7) => DataBits::Seven,
            Some(6) => DataBits::Six,
            Some(5) => DataBits::Five,
            Some(n) => {
                return Err(url.error(format!("option `data_bits={n}`: expected 5, 6, 7 or 8")));
            }
        };
        let parity = match url.take("parity").as_deref() {
            None | Some("none") => Parity::None,
            Some("even") => Parity::Even,
            Some("odd") => Parity::Odd,
            Some(p) => {
                return Err(url.error(format!("option `parity={p}`: expected none, even or odd")));
            }
        };
        let stop_bits = match url.take_parsed::<u8>("stop_bits", "1 or 2")? {
            None | Some(1) => StopBits::One,
            Some(2) => StopBits::Two,
            Some(n) => return Err(url.error(format!("option `stop_bits={n}`: expected 1 or 2"))),
        };
        let flow = match url.take("flow").as_deref() {
            None | Some("none") => FlowControl::None,
            Some("hardware") => FlowControl::Hardware,
            Some("software") if matches!(framing, Framing::Cobs | Framing::Slip) => {
                return Err(url.error(
                    "option `flow=software`: XON/XOFF bytes would be taken out of binary \
                     frames; use `flow=hardware` or a text framing",
                ));
            }
            Some("software") => FlowControl::Software,
            Some(f) => {
                return Err(url.error(format!(
                    "option `flow={f}`: expected none, hardware or software"
                )));
            }
        };
        let default_max = if framing == Framing::Nmea { 256 } else { 4096 };
        let max: usize = url
            .take_parsed("max", "a size in bytes")?
            .unwrap_or(default_max);
        if !(8..=1 << 20).contains(&max) {
            return Err(url.error(format!("option `max={max}`: expected 8 to 1048576 bytes")));
        }
        let topic = url.take("topic").unwrap_or_else(|| {
            match framing {
                Framing::Nmea => "nmea",
                Framing::Lines => "serial.line",
                Framing::Cobs | Framing::Slip => "serial.frame",
            }
            .to_string()
        });
        Topic::new(&topic).map_err(|e| url.error(format!("option `topic={topic}`: {e}")))?;
        let reopen = Backoff::from_url(url)?;
        url.finish(&OPTIONS)?;
        Ok(SerialConfig {
            path,
            baud,
            data_bits,
            parity,
            stop_bits,
            flow,
            framing,
            checksum,
            max,
            topic,
            reopen,
        })
    }

    /// What a serial medium with these settings can do: frames without provenance, lines of
    /// text or delimited binary frames of at most `max` bytes, a link that comes and goes.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: false,
            framing: match self.framing {
                Framing::Nmea | Framing::Lines => WireFraming::Line,
                Framing::Cobs | Framing::Slip => WireFraming::Frame,
            },
            max_frame: Some(self.max),
            hears_own: false,
            carries: Carries::Bytes,
            link_state: true,
            native: None,
            qos: false,
            lists: false,
        }
    }

    /// The topic a received frame arrives on: for NMEA, the prefix and the sentence's address
    /// (its leading letters: `$GPGGA,…` → `nmea.GPGGA`, `$C82.8P…` → `nmea.C`).
    pub fn topic_of(&self, frame: &[u8]) -> Option<Topic> {
        if self.framing != Framing::Nmea {
            return Topic::new(&self.topic).ok();
        }
        let address = std::str::from_utf8(framing::nmea_address(frame)).ok()?;
        if address.is_empty() {
            return None;
        }
        Topic::new(&format!("{}.{address}", self.topic)).ok()
    }
}

/// Names received frames, remembering the topic of each NMEA address it has seen (a line carries a
/// handful of sentence types; making their topic again for every sentence would be waste).
pub struct FrameTopics {
    cfg: SerialConfig,
    /// the one topic of every frame, when the framing is not NMEA
    fixed: Option<Topic>,
    /// addresses of up to eight letters, packed into a word, and their topics
    known: Vec<(u64, Topic)>,
}

impl FrameTopics {
    /// Topics for frames of a medium with these settings.
    pub fn new(cfg: &SerialConfig) -> FrameTopics {
        FrameTopics {
            cfg: cfg.clone(),
            fixed: (cfg.framing != Framing::Nmea)
                .then(|| cfg.topic_of(&[]))
                .flatten(),
            known: Vec::new(),
        }
    }

    /// The topic of a received frame ([`SerialConfig::topic_of`]).
    pub fn topic_of(&mut self, frame: &[u8]) -> Option<Topic> {
        if self.cfg.framing != Framing::Nmea {
            return self.fixed.clone();
        }
        // (letters are never zero bytes, so packing keeps addresses apart)
        let address = framing::nmea_address(frame);
        let key = Some(address).filter(|a| a.len() <= 8).map(|a| {
            let mut word = [0u8; 8];
            word[..a.len()].copy_from_slice(a);
            u64::from_le_bytes(word)
        });
        if let Some(key) = key
            && let Some((_, t)) = self.known.iter().find(|(k, _)| *k == key)
        {
            return Some(t.clone());
        }
        let topic = self.cfg.topic_of(frame)?;
        if let Some(key) = key
            && self.known.len() < 64
        {
            self.known.push((key, topic.clone()));
        }
        Some(topic)
    }
}

/// What both serial schemes do with messages: frame them for the line.
pub struct SerialEncoder {
    cfg: SerialConfig,
    /// a pseudo-terminal's link, removed on close
    pty: Option<PtyLink>,
}

impl Encode for SerialEncoder {
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        self.cfg.capabilities()
    }

    fn encode(&self, msg: &Message, line: &LinkSender<Bytes>) -> Result<Bytes, SendError> {
        let raw: &[u8] = match &msg.payload {
            Payload::Bytes(b) => b,
            Payload::Xml(x) => x.as_bytes(),
            Payload::Map(_) => {
                return Err(line.error("a serial line carries bytes or text, not a datamap"));
            }
        };
        framing::encode(self.cfg.framing, raw)
            .map(Bytes::from)
            .map_err(|reason| line.error(reason))
    }

    fn close(&self) {
        if let Some(p) = &self.pty {
            p.remove();
        }
    }
}

/// The transport of both serial schemes.
pub type SerialTransport = Linked<SerialEncoder>;

/// Adds `serial://` and `pty://`.
pub fn register(schemes: &mut Schemes) {
    let check = |url: &mut MediumUrl| Ok(SerialConfig::from_url(url)?.capabilities());
    schemes
        .add(Scheme {
            name: "serial",
            family: "serial",
            summary: "a serial device, reopened when it comes back",
            check,
            open: |o| Ok(Opened::from(open_serial(o)?)),
        })
        .add(Scheme {
            name: "pty",
            family: "serial",
            summary: "a new pseudo-terminal, linked at the URL's path for another program to open",
            check,
            open: |o| Ok(Opened::from(open_pty(o)?)),
        });
}

/// A registry with these schemes and the in-process medium, for a program or test that uses only
/// serial media.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}

/// Opens a `serial://` medium: a task keeps the device open, reopening it when it goes away.
fn open_serial(mut o: Opening) -> Result<Arc<SerialTransport>, OpenError> {
    let cfg = SerialConfig::from_url(&mut o.url)?;
    let path = cfg.path.display().to_string();
    let (line, queue) = link_queue(&o.name, path.clone(), WRITE_QUEUE);
    o.ingress
        .init_link(LinkState::Down(format!("{path} not opened yet")));
    let (opening, running) = (cfg.clone(), cfg.clone());
    let ingress = o.ingress.clone();
    spawn_link(
        &o.ingress,
        cfg.reopen,
        queue,
        move || {
            let c = opening.clone();
            Box::pin(async move {
                seabus_tty::open_device(&c.path, c.baud, |b| {
                    b.data_bits(c.data_bits)
                        .parity(c.parity)
                        .stop_bits(c.stop_bits)
                        .flow_control(c.flow)
                })
            })
        },
        move |port, queue| {
            let (cfg, ingress) = (running.clone(), ingress.clone());
            // a device that keeps overrun counters (not a pseudo-terminal) has them read
            let overruns = Overruns::of(&port);
            // each opening starts framing afresh
            Box::pin(async move { pump(port, &cfg, queue, &ingress, overruns).await })
        },
    );
    Ok(Arc::new(Linked::new(
        SerialEncoder { cfg, pty: None },
        line,
    )))
}

/// Reads frames into the medium and writes queued frames out, until the stream fails; returns why.
/// The device's `overruns`, when it keeps them, are read [`OVERRUN_LOOK`] after a read.
async fn pump<P: AsyncRead + AsyncWrite>(
    port: P,
    cfg: &SerialConfig,
    queue: &mut LinkQueue<Bytes>,
    ingress: &Ingress,
    mut overruns: Option<Overruns>,
) -> String {
    let (mut reader, mut writer) = tokio::io::split(port);
    let mut framer = Framer::new(cfg.framing, cfg.checksum, cfg.max);
    let mut buf = vec![0u8; 4096];
    let mut topics = FrameTopics::new(cfg);
    let path = cfg.path.display();
    // bytes the framer dropped, as counted in the medium so far
    let mut dropped = 0;
    // when the overrun counters are next read, while reads have not been followed by a look
    let mut look: Option<tokio::time::Instant> = None;
    let reason = loop {
        tokio::select! {
            n = reader.read(&mut buf) => match n {
                Ok(0) => break format!("{path}: end of stream"),
                Ok(n) => {
                    framer.push(&buf[..n], &mut |out| match out {
                        Ok(frame) => match topics.topic_of(&frame) {
                            Some(topic) => {
                                ingress.originate(topic, Payload::from(frame));
                            }
                            None => {
                                ingress.dropped(frame.len() as u64);
                                ingress.reject("no-address", format_args!("{path}: a sentence without an address"));
                            }
                        },
                        Err(r) => ingress.reject(r.reason.reason(), format_args!("{path} at byte {}", r.offset)),
                    });
                    if framer.dropped() != dropped {
                        ingress.dropped(framer.dropped() - dropped);
                        dropped = framer.dropped();
                    }
                    if overruns.is_some() && look.is_none() {
                        look = Some(tokio::time::Instant::now() + OVERRUN_LOOK);
                    }
                }
                Err(e) => break format!("{path}: {e}"),
            },
            _ = async { tokio::time::sleep_until(look.unwrap_or_else(tokio::time::Instant::now)).await }, if look.is_some() => {
                look = None;
                if let Some(o) = overruns.as_mut() {
                    ingress.overrun(o.take());
                }
            }
            frame = queue.recv() => match frame {
                Some(frame) => {
                    if let Err(reason) = queue.write(&path, writer.write_all(&frame)).await {
                        break reason;
                    }
                }
                None => break format!("{path}: closed"),
            },
        }
    };
    // what the device lost last, and the frame the link's end cut off
    if let Some(o) = overruns.as_mut() {
        ingress.overrun(o.take());
    }
    if framer.pending() > 0 {
        ingress.dropped(framer.pending() as u64);
    }
    reason
}

/// Opens a `pty://` medium: a new pseudo-terminal whose other end is linked at the URL's path.
fn open_pty(mut o: Opening) -> Result<Arc<SerialTransport>, OpenError> {
    let cfg = SerialConfig::from_url(&mut o.url)?;
    let path = cfg.path.display().to_string();
    let (line, queue) = link_queue(&o.name, path, WRITE_QUEUE);
    let (running, ingress) = (cfg.clone(), o.ingress.clone());
    let pty = seabus_tty::run_pty(&o, &cfg.path, queue, move |port, queue| {
        Box::pin(async move { pump(port, &running, queue, &ingress, None).await })
    })?;
    Ok(Arc::new(Linked::new(
        SerialEncoder {
            cfg,
            pty: Some(pty),
        },
        line,
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(url: &str) -> Result<SerialConfig, UrlError> {
        SerialConfig::from_url(&mut MediumUrl::parse(url).unwrap())
    }

    #[test]
    fn options_are_read_and_checked() {
        let c =
            cfg("serial:///dev/ttyUSB0?baud=19200&framing=nmea&checksum=allow-missing").unwrap();
        assert_eq!(
            (
                c.path.to_str().unwrap(),
                c.baud,
                c.framing,
                c.checksum,
                c.max
            ),
            (
                "/dev/ttyUSB0",
                19200,
                Framing::Nmea,
                ChecksumPolicy::AllowMissing,
                256
            )
        );
        let c =
            cfg("serial:///dev/ttyS1?framing=lines&topic=ctd.raw&parity=even&stop_bits=2").unwrap();
        assert_eq!(
            (c.topic.as_str(), c.parity, c.stop_bits),
            ("ctd.raw", Parity::Even, StopBits::Two)
        );
        assert!(
            cfg("serial://dev/ttyUSB0")
                .unwrap_err()
                .reason
                .contains("three slashes")
        );
        assert!(
            cfg("serial:///dev/x?framing=xml")
                .unwrap_err()
                .reason
                .contains("nmea, lines, cobs or slip")
        );
        assert_eq!(cfg("serial:///dev/x").unwrap().flow, FlowControl::None);
        assert_eq!(
            cfg("serial:///dev/x?flow=hardware&framing=cobs")
                .unwrap()
                .flow,
            FlowControl::Hardware
        );
        assert_eq!(
            cfg("serial:///dev/x?flow=software").unwrap().flow,
            FlowControl::Software
        );
        let e = cfg("serial:///dev/x?flow=software&framing=slip").unwrap_err();
        assert!(e.reason.contains("XON/XOFF bytes"), "{e}");
        let e = cfg("serial:///dev/x?flow=rts").unwrap_err();
        assert!(
            e.reason.contains("expected none, hardware or software"),
            "{e}"
        );
        assert!(cfg("serial:///dev/x?baud=fast").is_err());
        assert!(cfg("serial:///dev/x?parity=mark").is_err());
        assert!(cfg("serial:///dev/x?topic=a..b").is_err());
        assert!(
            cfg("serial:///dev/x?bauds=9600")
                .unwrap_err()
                .reason
                .contains("unknown option `bauds`")
        );
    }

    #[test]
    fn nmea_topics_come_from_the_address() {
        let c = cfg("serial:///dev/x").unwrap();
        let t = |s: &str| c.topic_of(s.as_bytes()).map(|t| t.to_string());
        assert_eq!(t("$GPGGA,1*00").as_deref(), Some("nmea.GPGGA"));
        assert_eq!(
            t("$C82.8P-3.89R-2.63T20.3D3.2*78").as_deref(),
            Some("nmea.C")
        );
        assert_eq!(t("!AIVDM,1*00").as_deref(), Some("nmea.AIVDM"));
        assert_eq!(t("$OMSTART,0*00").as_deref(), Some("nmea.OMSTART"));
        assert_eq!(t("$,1*00"), None);
    }
}
