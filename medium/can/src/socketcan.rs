//! SocketCAN: a Linux CAN interface (`socketcan://can0`) through the `socketcan` crate, with CAN FD
//! frames enabled and the medium's filters given to the kernel. [`to_socketcan`] and
//! [`from_socketcan`] convert frames both ways through the Linux `can_id` word.
//!
//! When the interface is missing or goes down the link goes down and the medium opens it again
//! (after `reopen`, doubling up to `reopen_max`); a kernel without CAN support says so in the
//! link's reason. Frames go from the sender to the socket as the `socketcan` crate holds them.

use super::frame::{CanFrame, FrameKind};
use super::{Filters, Receiver, Topics};
use seabus_medium::caps::Capabilities;
use seabus_medium::link::{Backoff, Encode, LinkQueue, LinkSender, Linked, link_queue, spawn_link};
use seabus_medium::medium::{LinkState, OpenError, Opening, SendError};
use seabus_medium::message::Message;
use seabus_medium::url::{MediumUrl, UrlError};
use socketcan::frame::{can_frame_default, canfd_frame_default};
use socketcan::{CanAnyFrame, EmbeddedFrame, Frame, SocketOptions};
use std::sync::Arc;

/// Frames waiting to be written; a sender waits when the interface is this far behind.
const WRITE_QUEUE: usize = 256;

/// The frame as the `socketcan` crate holds it.
pub fn to_socketcan(f: &CanFrame) -> CanAnyFrame {
    let data = f.payload();
    if f.is_fd() {
        let mut raw = canfd_frame_default();
        raw.can_id = f.linux_id();
        raw.len = data.len() as u8;
        raw.flags = u8::from(f.brs()) | (u8::from(f.esi()) << 1);
        raw.data[..data.len()].copy_from_slice(data);
        CanAnyFrame::from(raw)
    } else {
        let mut raw = can_frame_default();
        raw.can_id = f.linux_id();
        raw.can_dlc = match f.kind() {
            FrameKind::Remote { dlc } => dlc,
            _ => data.len() as u8,
        };
        raw.data[..data.len()].copy_from_slice(data);
        CanAnyFrame::from(raw)
    }
}

/// The frame the `socketcan` crate read.
pub fn from_socketcan(f: &CanAnyFrame) -> Result<CanFrame, String> {
    match f {
        CanAnyFrame::Normal(d) => CanFrame::from_linux(d.id_word(), d.len(), d.data(), None),
        CanAnyFrame::Remote(r) => CanFrame::from_linux(r.id_word(), r.dlc(), &[], None),
        CanAnyFrame::Error(e) => CanFrame::from_linux(e.id_word(), e.len(), e.data(), None),
        CanAnyFrame::Fd(fd) => {
            let flags = u8::from(fd.is_brs()) | (u8::from(fd.is_esi()) << 1);
            CanFrame::from_linux(fd.id_word(), fd.len(), fd.data(), Some(flags))
        }
    }
}

/// A SocketCAN medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq)]
pub struct SocketCanConfig {
    /// The interface (`can0`, `vcan0`).
    pub iface: String,
    /// Waits between attempts to reopen the interface.
    pub reopen: Backoff,
    /// Frames kept (given to the kernel).
    pub filters: Filters,
}

impl SocketCanConfig {
    /// Reads the settings of a `socketcan://IFACE` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<SocketCanConfig, UrlError> {
        let iface = url.host.clone();
        if iface.is_empty() || iface.len() > 15 || !url.path.is_empty() {
            return Err(url.error("expected socketcan://IFACE, an interface name such as can0"));
        }
        let cfg = SocketCanConfig {
            iface,
            reopen: Backoff::from_url(url)?,
            filters: super::take_filters(url)?,
        };
        url.finish(&[])?;
        Ok(cfg)
    }
}

/// What `socketcan://` does with messages: frames in the `socketcan` crate's form, which go to the
/// socket's task as they are.
pub struct SocketCanEncoder;

impl Encode for SocketCanEncoder {
    type Frame = CanAnyFrame;

    fn capabilities(&self) -> Capabilities {
        super::capabilities(true)
    }

    fn fingerprint(
        &self,
        topic: &seabus_medium::Topic,
        payload: &seabus_medium::Payload,
    ) -> Option<u64> {
        super::frame_fingerprint(topic, payload)
    }

    fn encode(
        &self,
        msg: &Message,
        link: &LinkSender<CanAnyFrame>,
    ) -> Result<CanAnyFrame, SendError> {
        Ok(to_socketcan(&super::frame_to_send(link.medium(), msg)?))
    }
}

/// The transport of `socketcan://`.
pub type SocketCanTransport = Linked<SocketCanEncoder>;

/// Opens a `socketcan://` medium: a task keeps the interface open.
pub(crate) fn open_socketcan(mut o: Opening) -> Result<Arc<SocketCanTransport>, OpenError> {
    let cfg = SocketCanConfig::from_url(&mut o.url)?;
    let (link, queue) = link_queue(&o.name, cfg.iface.clone(), WRITE_QUEUE);
    o.ingress
        .init_link(LinkState::Down(format!("{} not opened yet", cfg.iface)));
    let (opening, running) = (cfg.clone(), cfg.clone());
    let ingress = o.ingress.clone();
    spawn_link(
        &o.ingress,
        cfg.reopen,
        queue,
        move || {
            let cfg = opening.clone();
            Box::pin(async move { open_socket(&cfg) })
        },
        move |socket, queue| {
            let mut receiver = Receiver {
                ingress: ingress.clone(),
                filters: running.filters.clone(),
                topics: Topics::default(),
            };
            let iface = running.iface.clone();
            Box::pin(async move { session(socket, &iface, queue, &mut receiver).await })
        },
    );
    Ok(Arc::new(Linked::new(SocketCanEncoder, link)))
}

/// Whether this kernel makes CAN sockets at all.
pub fn kernel_has_can() -> bool {
    // SAFETY: a socket made and closed at once
    unsafe {
        let fd = libc::socket(libc::AF_CAN, libc::SOCK_RAW, libc::CAN_RAW);
        if fd < 0 {
            return false;
        }
        libc::close(fd);
        true
    }
}

fn open_socket(cfg: &SocketCanConfig) -> Result<socketcan::tokio::CanFdSocket, String> {
    let socket = socketcan::tokio::CanFdSocket::open(&cfg.iface).map_err(|e| {
        if kernel_has_can() {
            format!("cannot open {}: {e}", cfg.iface)
        } else {
            format!(
                "{}: this kernel has no SocketCAN support (no AF_CAN sockets); use slcan or cannelloni",
                cfg.iface
            )
        }
    })?;
    if !cfg.filters.0.is_empty() {
        let filters: Vec<socketcan::CanFilter> = cfg
            .filters
            .0
            .iter()
            .map(|f| socketcan::CanFilter::new(f.id, f.mask))
            .collect();
        socket
            .set_filters(&filters)
            .map_err(|e| format!("{}: setting filters: {e}", cfg.iface))?;
    }
    Ok(socket)
}

/// Carries frames both ways until the socket fails; returns why.
async fn session(
    socket: socketcan::tokio::CanFdSocket,
    iface: &str,
    queue: &mut LinkQueue<CanAnyFrame>,
    receiver: &mut Receiver,
) -> String {
    loop {
        tokio::select! {
            read = socket.read_frame() => match read {
                Ok(f) => match from_socketcan(&f) {
                    Ok(frame) => receiver.frame(&frame, None),
                    Err(e) => receiver
                        .ingress
                        .reject("socketcan-bad-frame", format_args!("{iface}: {e}")),
                },
                Err(e) => return format!("{iface}: {e}"),
            },
            frame = queue.recv() => match frame {
                Some(f) => {
                    if let Err(reason) = queue.write(iface, socket.write_frame(&f)).await {
                        return reason;
                    }
                }
                None => return format!("{iface}: closed"),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<CanFrame> {
        vec![
            CanFrame::data(0x123, false, &[1, 2, 3]).unwrap(),
            CanFrame::data(0x18FF_50E5, true, &[0xAA; 8]).unwrap(),
            CanFrame::remote(0x7FF, false, 4).unwrap(),
            CanFrame::remote(0x1ABC, true, 0).unwrap(),
            CanFrame::fd(0x10, true, &[7; 64], true, true).unwrap(),
            CanFrame::fd(0x11, false, &[], false, false).unwrap(),
            CanFrame::error(0x4, &[0, 4, 0, 0, 0, 0, 0, 0]),
        ]
    }

    #[test]
    fn frames_convert_to_socketcan_and_back() {
        for f in frames() {
            let any = to_socketcan(&f);
            assert_eq!(any.id_word(), f.linux_id(), "{f}");
            match (&any, f.kind(), f.is_fd()) {
                (CanAnyFrame::Normal(_), FrameKind::Data, false)
                | (CanAnyFrame::Remote(_), FrameKind::Remote { .. }, false)
                | (CanAnyFrame::Error(_), FrameKind::Error, false)
                | (CanAnyFrame::Fd(_), FrameKind::Data, true) => {}
                other => panic!("{f}: {other:?}"),
            }
            assert_eq!(from_socketcan(&any).unwrap(), f);
        }
    }

    #[test]
    fn urls_name_an_interface() {
        let cfg = |u: &str| SocketCanConfig::from_url(&mut MediumUrl::parse(u).unwrap());
        let c = cfg("socketcan://can0?filter=123:7ff").unwrap();
        assert_eq!((c.iface.as_str(), c.filters.0.len()), ("can0", 1));
        assert!(cfg("socketcan:///can0").is_err());
        assert!(cfg("socketcan://averyveryverylongname0").is_err());
        assert!(cfg("socketcan://can0?bitrate=1").is_err());
    }
}
