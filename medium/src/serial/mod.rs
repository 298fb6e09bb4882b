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
//! default `serial.line` or `serial.frame`), `reopen` (wait between attempts to reopen a lost
//! device, default 500ms).
//!
//! Received frames are byte payloads that originate at the medium (it numbers them). What is sent
//! must be bytes or XML text; NMEA sentences without a checksum get one. When the device goes away
//! the link goes down, sends fail at once with [`SendError::LinkDown`], and the medium keeps trying
//! to reopen it; nothing else waits meanwhile.

pub mod framing;

use crate::medium::{BoxFuture, Ingress, LinkState, OpenError, Opening, SendError, Transport};
use crate::message::Message;
use crate::payload::Payload;
use crate::topic::Topic;
use crate::url::{MediumUrl, UrlError};
use bytes::Bytes;
use framing::{ChecksumPolicy, Framer, Framing};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPortBuilderExt, SerialStream, StopBits};

const OPTIONS: [&str; 10] = [
    "baud",
    "data_bits",
    "parity",
    "stop_bits",
    "framing",
    "checksum",
    "max",
    "topic",
    "reopen",
    "flow",
];

/// Frames waiting to be written; a sender waits when the line is this far behind.
const WRITE_QUEUE: usize = 64;

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
    /// Wait between attempts to reopen the device.
    pub reopen: Duration,
}

/// The device path of a `SCHEME:///path` URL.
pub(crate) fn device_path(url: &MediumUrl) -> Result<PathBuf, UrlError> {
    if !url.host.is_empty() || url.path.len() < 2 {
        return Err(url.error(format!(
            "expected {}:///path/to/device (three slashes, an absolute path)",
            url.scheme
        )));
    }
    Ok(PathBuf::from(&url.path))
}

/// The `reopen` option: the wait between attempts to reopen a lost device (default 500 ms).
pub(crate) fn take_reopen(url: &mut MediumUrl) -> Result<Duration, UrlError> {
    match url.take("reopen") {
        None => Ok(Duration::from_millis(500)),
        Some(r) => crate::parse::parse_duration(&r)
            .filter(|d| !d.is_zero())
            .ok_or_else(|| {
                url.error(format!(
                    "option `reopen={r}`: expected a duration such as 500ms"
                ))
            }),
    }
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
        let reopen = take_reopen(url)?;
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

/// The writing side of a line (a serial device or a pseudo-terminal): whether it is up, the queue
/// of frames its task writes, and for a pseudo-terminal the link to remove when the medium closes.
/// The serial and slcan transports share it.
pub(crate) struct LineWriter {
    name: Arc<str>,
    path: String,
    /// Whether the line is open; its task sets it.
    pub(crate) up: Arc<AtomicBool>,
    writer: mpsc::Sender<Bytes>,
    link: std::sync::Mutex<Option<PathBuf>>,
}

impl LineWriter {
    /// A writer for medium `name` on `path`, queueing into `writer`; `link` is a pseudo-terminal's.
    pub(crate) fn new(
        name: Arc<str>,
        path: String,
        up: Arc<AtomicBool>,
        writer: mpsc::Sender<Bytes>,
        link: Option<PathBuf>,
    ) -> LineWriter {
        LineWriter {
            name,
            path,
            up,
            writer,
            link: std::sync::Mutex::new(link),
        }
    }

    /// An I/O error of this medium.
    pub(crate) fn error(&self, reason: impl Into<String>) -> SendError {
        SendError::Io {
            medium: self.name.to_string(),
            reason: reason.into(),
        }
    }

    /// Queues an encoded frame; fails at once while the line is down.
    pub(crate) fn transmit(&self, frame: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            if !self.up.load(Ordering::Acquire) {
                return Err(SendError::LinkDown {
                    medium: self.name.to_string(),
                    reason: format!("{} is not open", self.path),
                });
            }
            self.writer
                .send(frame)
                .await
                .map_err(|_| SendError::Closed(self.name.to_string()))
        })
    }

    /// Marks the line down and removes a pseudo-terminal's link.
    pub(crate) fn close(&self) {
        self.up.store(false, Ordering::Release);
        if let Some(link) = self.link.lock().unwrap_or_else(|p| p.into_inner()).take() {
            let _ = std::fs::remove_file(link);
        }
    }
}

impl Drop for LineWriter {
    fn drop(&mut self) {
        self.close();
    }
}

/// The transport of both serial schemes.
pub struct SerialTransport {
    framing: Framing,
    line: LineWriter,
}

impl Transport for SerialTransport {
    fn encode(&self, msg: &Message) -> Result<Bytes, SendError> {
        let raw: &[u8] = match &msg.payload {
            Payload::Bytes(b) => b,
            Payload::Xml(x) => x.as_bytes(),
            Payload::Map(_) => {
                return Err(self
                    .line
                    .error("a serial line carries bytes or text, not a datamap"));
            }
        };
        framing::encode(self.framing, raw)
            .map(Bytes::from)
            .map_err(|reason| self.line.error(reason))
    }

    fn transmit(&self, frame: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        self.line.transmit(frame)
    }

    fn close(&self) {
        self.line.close();
    }
}

/// Opens a `serial://` medium: a task keeps the device open, reopening it when it goes away.
pub(crate) fn open_serial(mut o: Opening) -> Result<Arc<SerialTransport>, OpenError> {
    let cfg = SerialConfig::from_url(&mut o.url)?;
    let (writer, rx) = mpsc::channel(WRITE_QUEUE);
    let up = Arc::new(AtomicBool::new(false));
    let path = cfg.path.display().to_string();
    o.ingress
        .init_link(LinkState::Down(format!("{path} not opened yet")));
    let framing = cfg.framing;
    let ingress = o.ingress.clone();
    let task = tokio::spawn(keep_open(
        {
            let cfg = cfg.clone();
            move || open_device(&cfg)
        },
        cfg.reopen,
        up.clone(),
        rx,
        o.ingress.clone(),
        move |port, rx| {
            let (cfg, ingress) = (cfg.clone(), ingress.clone());
            Box::pin(async move {
                // each opening starts framing afresh
                let mut framer = Framer::new(cfg.framing, cfg.checksum, cfg.max);
                pump(port, &cfg, &mut framer, rx, &ingress).await
            })
        },
    ));
    o.ingress.own_task(task.abort_handle());
    Ok(Arc::new(SerialTransport {
        framing,
        line: LineWriter::new(o.name.clone(), path, up, writer, None),
    }))
}

fn open_device(cfg: &SerialConfig) -> Result<SerialStream, String> {
    let path = cfg.path.to_string_lossy();
    tokio_serial::new(path.as_ref(), cfg.baud)
        .data_bits(cfg.data_bits)
        .parity(cfg.parity)
        .stop_bits(cfg.stop_bits)
        .flow_control(cfg.flow)
        .open_native_async()
        .map_err(|e| format!("cannot open {path}: {e}"))
}

/// Keeps a device open with `open`, running `pump` on it while it is (the line `up`), and after it
/// fails waits `reopen` and opens it again, until the medium closes. Frames queued while the line
/// was lost are dropped with it.
pub(crate) async fn keep_open(
    open: impl Fn() -> Result<SerialStream, String>,
    reopen: Duration,
    up: Arc<AtomicBool>,
    mut rx: mpsc::Receiver<Bytes>,
    ingress: Ingress,
    mut pump: impl for<'r> FnMut(SerialStream, &'r mut mpsc::Receiver<Bytes>) -> BoxFuture<'r, String>,
) {
    loop {
        let reason = match open() {
            Ok(port) => {
                up.store(true, Ordering::Release);
                ingress.set_link(LinkState::Up);
                let reason = pump(port, &mut rx).await;
                up.store(false, Ordering::Release);
                reason
            }
            Err(e) => e,
        };
        if !ingress.is_open() {
            return;
        }
        ingress.set_link(LinkState::Down(reason));
        while rx.try_recv().is_ok() {}
        tokio::time::sleep(reopen).await;
    }
}

/// Reads frames into the medium and writes queued frames out, until the stream fails; returns why.
async fn pump<P: AsyncRead + AsyncWrite>(
    port: P,
    cfg: &SerialConfig,
    framer: &mut Framer,
    rx: &mut mpsc::Receiver<Bytes>,
    ingress: &Ingress,
) -> String {
    let (mut reader, mut writer) = tokio::io::split(port);
    let mut buf = vec![0u8; 4096];
    let mut topics = FrameTopics::new(cfg);
    let path = cfg.path.display();
    loop {
        tokio::select! {
            n = reader.read(&mut buf) => match n {
                Ok(0) => return format!("{path}: end of stream"),
                Ok(n) => {
                    framer.push(&buf[..n], &mut |out| match out {
                        Ok(frame) => match topics.topic_of(&frame) {
                            Some(topic) => {
                                ingress.originate(topic, Payload::from(frame));
                            }
                            None => ingress.reject("no-address", format_args!("{path}: a sentence without an address")),
                        },
                        Err(r) => ingress.reject(r.reason.reason(), format_args!("{path} at byte {}", r.offset)),
                    });
                }
                Err(e) => return format!("{path}: {e}"),
            },
            frame = rx.recv() => match frame {
                Some(frame) => {
                    if let Err(e) = writer.write_all(&frame).await {
                        return format!("{path}: {e}");
                    }
                }
                None => return format!("{path}: closed"),
            },
        }
    }
}

/// Opens a `pty://` medium: a new pseudo-terminal whose other end is linked at the URL's path.
pub(crate) fn open_pty(mut o: Opening) -> Result<Arc<SerialTransport>, OpenError> {
    let cfg = SerialConfig::from_url(&mut o.url)?;
    let (writer, rx) = mpsc::channel(WRITE_QUEUE);
    let up = Arc::new(AtomicBool::new(true));
    let framing = cfg.framing;
    let path = cfg.path.display().to_string();
    let link = cfg.path.clone();
    let ingress = o.ingress.clone();
    run_pty(&o, &link, up.clone(), rx, move |port, rx| {
        Box::pin(async move {
            let mut framer = Framer::new(cfg.framing, cfg.checksum, cfg.max);
            pump(port, &cfg, &mut framer, rx, &ingress).await
        })
    })?;
    Ok(Arc::new(SerialTransport {
        framing,
        line: LineWriter::new(o.name.clone(), path, up, writer, Some(link)),
    }))
}

/// Makes a pseudo-terminal linked at `at` and runs `pump` on its master side until it fails (the
/// line `up` meanwhile; the link down with the reason after).
pub(crate) fn run_pty(
    o: &Opening,
    at: &Path,
    up: Arc<AtomicBool>,
    mut rx: mpsc::Receiver<Bytes>,
    pump: impl for<'r> FnOnce(SerialStream, &'r mut mpsc::Receiver<Bytes>) -> BoxFuture<'r, String>
    + Send
    + 'static,
) -> Result<(), OpenError> {
    let (master, held) = new_pty(o, at)?;
    let ingress = o.ingress.clone();
    let task = tokio::spawn(async move {
        let _held = held;
        let reason = pump(master, &mut rx).await;
        up.store(false, Ordering::Release);
        ingress.set_link(LinkState::Down(reason));
    });
    o.ingress.own_task(task.abort_handle());
    o.ingress.set_link(LinkState::Up);
    Ok(())
}

/// A new pseudo-terminal whose other end is linked at `at`: its master side, and the other end
/// held open (by a plain file, without the lock a serial port takes, so that any program can open
/// it) so that the terminal lives while nobody has it open.
pub(crate) fn new_pty(o: &Opening, at: &Path) -> Result<(SerialStream, std::fs::File), OpenError> {
    let (master, slave) = SerialStream::pair()
        .map_err(|e| std::io::Error::other(e.to_string()))
        .map_err(o.io_error("creating a pseudo-terminal"))?;
    let slave_path = tokio_serial::SerialPort::name(&slave)
        .ok_or_else(|| std::io::Error::other("the pseudo-terminal has no name"))
        .map_err(o.io_error("naming the pseudo-terminal"))?;
    let held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&slave_path)
        .map_err(o.io_error(format!("opening {slave_path}")))?;
    drop(slave);
    link(at, Path::new(&slave_path)).map_err(o.io_error(format!("linking {}", at.display())))?;
    Ok((master, held))
}

/// Links `at` to `target`, replacing an earlier link but never a file or directory.
fn link(at: &Path, target: &Path) -> std::io::Result<()> {
    match std::fs::symlink_metadata(at) {
        Ok(m) if m.file_type().is_symlink() => std::fs::remove_file(at)?,
        Ok(_) => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "something other than a link is there; seabus only replaces its own links",
            ));
        }
        Err(_) => {}
    }
    std::os::unix::fs::symlink(target, at)
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
