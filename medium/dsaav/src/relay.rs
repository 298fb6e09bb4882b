//! Relay mode (`dsaav+eth://IFACE?relay`, `dsaav+udp://ADDRESS:PORT?relay`): a DSAAV medium that
//! carries IComms frames as they are — every frame on its backbone, whichever node it is for —
//! for a module that relays frames between backbones (the paper's Wi-Fi bridge, the
//! `dsaav-udp-bridge` module).
//!
//! Each frame read arrives on topic [`TOPIC`] as a datamap: `frame` (its bytes), `from` (the
//! sender: `ADDRESS:PORT` on UDP, the hardware address on Ethernet), `src` (its source node) and
//! `dst` (the node it is addressed to, or -1 for a channel broadcast). Frames that do not read are
//! counted by reason and dropped. A message sent on [`TOPIC`] gives `frame` (checked to read) and,
//! on UDP, `to` (`ADDRESS:PORT`; by default the URL's destinations: its peers, group or
//! broadcast address); on Ethernet a frame to one node goes to that node's hardware address once
//! a frame from it was read, else to everyone. A relay medium has no node of its own: the `node`,
//! `port`, `channel` and `dict` options are not taken.

use crate::eth::{Mac, RawSocket};
use crate::wire::{Destination, Frame};
use crate::{ETHERTYPE, io_send};
use bytes::Bytes;
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::net::{self, UdpEndpoint};
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{
    BoxFuture, DataMap, Ingress, LinkState, Message, OpenError, Opening, Payload, SendError, Topic,
    Transport, Value,
};
use std::net::SocketAddr;
use std::sync::Arc;

/// The topic of the frames a relay medium carries.
pub const TOPIC: &str = "dsaav.frame";

/// The wire model a relay medium declares in its [`Capabilities::native`].
pub const NATIVE: &str = "dsaav-frames";

/// Whether a DSAAV URL asks for relay mode (the `relay` option, taken).
pub fn wanted(url: &mut MediumUrl) -> Result<bool, UrlError> {
    Ok(url.take_flag("relay")?.unwrap_or(false))
}

/// Where a relay medium reads and writes frames.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RelayBackbone {
    /// Raw Ethernet on an interface.
    Ethernet(String),
    /// A UDP endpoint.
    Udp(UdpEndpoint),
}

/// A relay medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RelayConfig {
    /// The backbone.
    pub backbone: RelayBackbone,
}

impl RelayConfig {
    /// Reads the settings of a `dsaav+eth://IFACE?relay` or `dsaav+udp://…?relay` URL (the
    /// `relay` option already taken).
    pub fn from_url(url: &mut MediumUrl) -> Result<RelayConfig, UrlError> {
        let backbone = match url.scheme.as_str() {
            "dsaav+eth" if !url.host.is_empty() => {
                url.finish(&[])?;
                RelayBackbone::Ethernet(url.host.clone())
            }
            "dsaav+udp" => {
                let endpoint = UdpEndpoint::from_url(url)?;
                url.finish(&UdpEndpoint::OPTIONS)?;
                RelayBackbone::Udp(endpoint)
            }
            "dsaav+eth" => return Err(url.error("expected dsaav+eth://INTERFACE?relay")),
            s => {
                return Err(url.error(format!(
                    "option `relay` is for dsaav+eth and dsaav+udp, not `{s}://`"
                )));
            }
        };
        Ok(RelayConfig { backbone })
    }

    /// What a relay medium can do: whole IComms frames (datamaps holding them), without seabus's
    /// provenance; on Ethernet it hears what this host sends too.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: false,
            framing: Framing::Datagram,
            max_frame: Some(crate::wire::MAX_FRAME),
            hears_own: matches!(self.backbone, RelayBackbone::Ethernet(_)),
            carries: Carries::DataMap,
            link_state: false,
            native: Some(NATIVE),
            qos: false,
            lists: false,
        }
    }
}

/// A frame on its way out: its bytes, and where it goes.
#[derive(Clone)]
pub struct RelayFrame {
    bytes: Bytes,
    /// the node it is addressed to (Ethernet: whose hardware address it goes to)
    node: Option<u16>,
    /// the UDP address it goes to, when the message names one
    to: Option<SocketAddr>,
}

enum Link {
    Ethernet(Arc<RawSocket>),
    Udp(Arc<tokio::net::UdpSocket>, Vec<SocketAddr>),
}

/// The transport of a relay medium.
pub struct RelayTransport {
    name: Arc<str>,
    cfg: RelayConfig,
    link: Link,
}

/// Opens a relay medium (the `relay` option already taken from the URL).
pub(crate) fn open(mut o: Opening) -> Result<Arc<RelayTransport>, OpenError> {
    let cfg = RelayConfig::from_url(&mut o.url)?;
    let link = match &cfg.backbone {
        RelayBackbone::Ethernet(iface) => {
            let socket = Arc::new(
                RawSocket::open(iface, ETHERTYPE)
                    .map_err(o.io_error(format!("opening a raw socket on {iface}")))?,
            );
            let task = tokio::spawn(receive_ethernet(socket.clone(), o.ingress.clone()));
            o.ingress.own_task(task.abort_handle());
            Link::Ethernet(socket)
        }
        RelayBackbone::Udp(endpoint) => {
            let (socket, _) =
                net::socket(endpoint).map_err(o.io_error(format!("binding {}", endpoint.bind)))?;
            let dests = endpoint
                .destinations()
                .map_err(o.io_error("resolving the peers"))?;
            let socket = Arc::new(
                tokio::net::UdpSocket::from_std(socket)
                    .map_err(o.io_error("registering the socket"))?,
            );
            let task = tokio::spawn(receive_udp(socket.clone(), o.ingress.clone()));
            o.ingress.own_task(task.abort_handle());
            Link::Udp(socket, dests)
        }
    };
    o.ingress.set_link(LinkState::Up);
    Ok(Arc::new(RelayTransport {
        name: o.name.clone(),
        cfg,
        link,
    }))
}

/// Delivers a frame read from `from`; false once the medium is gone.
fn deliver(ingress: &Ingress, topic: &Topic, from: String, d: &[u8]) -> bool {
    let f = match Frame::decode(d) {
        Ok(f) => f,
        Err(e) => {
            ingress.reject(e.kind(), format_args!("frame from {from}: {e}"));
            return true;
        }
    };
    let dst = match f.dst {
        Destination::To(a) => i64::from(a.node),
        Destination::Channel(_) => -1,
    };
    let map = DataMap::with_capacity(4)
        .with("frame", Value::Bytes(d.to_vec()))
        .with("from", from)
        .with("src", i64::from(f.src.node))
        .with("dst", dst);
    ingress.originate(topic.clone(), Payload::from(map))
}

fn topic() -> Topic {
    Topic::new(TOPIC).unwrap_or_else(|_| unreachable!("`{TOPIC}` is a topic"))
}

async fn receive_ethernet(socket: Arc<RawSocket>, ingress: Ingress) {
    let topic = topic();
    let mut buf = vec![0u8; 2048];
    loop {
        match socket.recv(&mut buf).await {
            Ok(Some((mac, n))) => {
                if let Ok(f) = Frame::decode(&buf[..n]) {
                    socket.learn(f.src.node, mac);
                }
                if !deliver(&ingress, &topic, Mac(mac).to_string(), &buf[..n]) {
                    return;
                }
            }
            Ok(None) => {}
            Err(e) => {
                tracing::debug!("dsaav relay receive: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(10)).await;
            }
        }
    }
}

async fn receive_udp(socket: Arc<tokio::net::UdpSocket>, ingress: Ingress) {
    let topic = topic();
    let mut buf = vec![0u8; 65_536];
    loop {
        match socket.recv_from(&mut buf).await {
            Ok((n, from)) => {
                if !deliver(&ingress, &topic, from.to_string(), &buf[..n]) {
                    return;
                }
            }
            Err(e) => {
                tracing::debug!("dsaav relay receive: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(10)).await;
            }
        }
    }
}

impl Transport for RelayTransport {
    type Frame = RelayFrame;

    fn capabilities(&self) -> Capabilities {
        self.cfg.capabilities()
    }

    fn encode(&self, msg: &Message) -> Result<RelayFrame, SendError> {
        let refuse = |why: String| io_send(&self.name, format!("topic `{}`: {why}", msg.topic));
        if msg.topic.as_str() != TOPIC {
            return Err(refuse(format!("a relay medium carries `{TOPIC}` only")));
        }
        let map = msg.payload.to_map().map_err(|e| refuse(e.to_string()))?;
        let Some(Value::Bytes(bytes)) = map.get("frame") else {
            return Err(refuse("needs `frame`, the frame's bytes".into()));
        };
        let f = Frame::decode(bytes).map_err(|e| refuse(format!("`frame`: {e}")))?;
        let to = match map.get("to") {
            None => None,
            Some(v) => Some(
                v.as_str()
                    .and_then(|t| t.parse::<SocketAddr>().ok())
                    .ok_or_else(|| refuse(format!("`to` must be ADDRESS:PORT, not {v}")))?,
            ),
        };
        Ok(RelayFrame {
            bytes: Bytes::copy_from_slice(bytes),
            node: match f.dst {
                Destination::To(a) => Some(a.node),
                Destination::Channel(_) => None,
            },
            to,
        })
    }

    fn transmit(&self, frame: RelayFrame) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            match &self.link {
                Link::Ethernet(socket) => socket
                    .send(frame.node, &frame.bytes)
                    .await
                    .map_err(|e| io_send(&self.name, e)),
                Link::Udp(socket, dests) => {
                    let to = frame.to.map_or_else(|| dests.clone(), |t| vec![t]);
                    for dest in to {
                        socket
                            .send_to(&frame.bytes, dest)
                            .await
                            .map_err(|e| io_send(&self.name, format!("sending to {dest}: {e}")))?;
                    }
                    Ok(())
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(url: &str) -> Result<RelayConfig, UrlError> {
        let mut url = MediumUrl::parse(url).unwrap();
        assert!(wanted(&mut url).unwrap());
        RelayConfig::from_url(&mut url)
    }

    #[test]
    fn relay_urls_name_a_backbone_and_no_node() {
        assert_eq!(
            cfg("dsaav+eth://eth0?relay").unwrap().backbone,
            RelayBackbone::Ethernet("eth0".into())
        );
        let udp = cfg("dsaav+udp://10.0.0.1:47900?relay").unwrap();
        assert!(matches!(udp.backbone, RelayBackbone::Udp(_)));
        assert_eq!(udp.capabilities().native, Some(NATIVE));
        let e = cfg("dsaav+eth://eth0?relay&node=3").unwrap_err();
        assert!(e.reason.contains("unknown option `node`"), "{e}");
        let e = cfg("dsaav+inproc://v?relay").unwrap_err();
        assert!(e.reason.contains("for dsaav+eth and dsaav+udp"), "{e}");
    }
}
