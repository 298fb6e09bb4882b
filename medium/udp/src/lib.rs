//! seabus-medium-udp, the UDP medium: seabus's own datagram format over unicast, broadcast or
//! multicast.
//!
//! ```text
//! udp://239.255.42.1:47800?ttl=0            multicast group (joined on loopback when ttl is 0)
//! udp://239.255.42.1:47800?ttl=1&iface=eth0 multicast on a chosen interface
//! udp://255.255.255.255:47800               broadcast (or any address with ?broadcast)
//! udp://0.0.0.0:47801?peer=10.0.0.2:47801   unicast to listed peers, listening on the bound port
//! ```
//! Options: `ttl` (multicast hop limit, default 0), `iface` (interface name or IPv4 address),
//! `peer` (repeatable, or comma-separated), `bind` (address to bind instead of the default),
//! `broadcast`, `loop` (multicast loopback, default on), `recv_buf` (socket receive buffer in bytes,
//! default 4 MiB), `max` (largest datagram, default 65507), `send_gap` (datagrams handed over in a
//! stream less than this apart go out in batches, default 50us; 0: each at once,
//! [`seabus_medium::outbox`]). A message that encodes larger than `max` is refused at send. A datagram that does not decode is counted by reason and dropped. A node
//! never receives its own datagrams back (multicast loopback): each carries its sender's id.
//!
//! Who may depend on it: the program, to register `udp://` ([`register`]). It depends on the core
//! only.

use bytes::{Bytes, BytesMut};
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::datagram as wire;
use seabus_medium::net::{self, MAX_DATAGRAM, RECV_CHUNK, RecvBatch, UdpEndpoint};
use seabus_medium::outbox::{self, Outbox, Outgoing};
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{
    BoxFuture, Ingress, LinkState, Message, OpenError, Opened, Opening, Scheme, Schemes, SendError,
    Transport,
};
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::io::Interest;
use tokio::net::UdpSocket;

/// A UDP medium's settings, read from its URL: the endpoint and the largest datagram sent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UdpConfig {
    /// Where it listens and whom it reaches.
    pub endpoint: UdpEndpoint,
    /// Largest datagram sent.
    pub max: usize,
    /// Datagrams handed over less than this apart, in a stream, go out in batches.
    pub send_gap: std::time::Duration,
}

impl UdpConfig {
    /// Reads the settings from a `udp://` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<UdpConfig, UrlError> {
        let endpoint = UdpEndpoint::from_url(url)?;
        let max = url
            .take_parsed("max", "a size in bytes")?
            .unwrap_or(MAX_DATAGRAM);
        if !(wire::FIXED + 3..=MAX_DATAGRAM).contains(&max) {
            return Err(url.error(format!(
                "option `max={max}`: expected {}–{MAX_DATAGRAM}",
                wire::FIXED + 3
            )));
        }
        let send_gap = outbox::gap_from_url(url)?.unwrap_or(outbox::QUIET);
        let mut options = UdpEndpoint::OPTIONS.to_vec();
        options.extend(["max", "send_gap"]);
        url.finish(&options)?;
        Ok(UdpConfig {
            endpoint,
            max,
            send_gap,
        })
    }

    /// What a UDP medium can do: whole seabus messages with provenance in datagrams of at most
    /// `max` bytes; its own datagrams never come back to it.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: true,
            framing: Framing::Datagram,
            max_frame: Some(self.max),
            hears_own: false,
            carries: Carries::Any,
            link_state: false,
            native: None,
            qos: false,
            lists: true,
        }
    }
}

/// Adds `udp://`.
pub fn register(schemes: &mut Schemes) {
    schemes.add(Scheme {
        name: "udp",
        family: "udp",
        summary: "seabus datagrams over UDP unicast, broadcast or multicast",
        check: |url| Ok(UdpConfig::from_url(url)?.capabilities()),
        open: |o| Ok(Opened::from(open(o)?)),
    });
}

/// A registry with `udp://` and the in-process medium, for a program or test that uses only these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}

/// The UDP transport.
pub struct UdpTransport {
    name: Arc<str>,
    /// sends on the socket until the medium is closed
    outbox: outbox::Held,
    sender: u64,
    dests: Vec<SocketAddr>,
    max: usize,
    caps: Capabilities,
}

/// The URL a program that only sends (`seabus pub`) uses for `url`: a unicast `udp://HOST:PORT`
/// without `peer` names where the datagrams go, so it becomes `udp://0.0.0.0:0?peer=HOST:PORT`
/// (any free port of its own, the other options kept); any other URL is kept as written.
pub fn sending_url(url: &str) -> String {
    let Ok(parsed) = MediumUrl::parse(url) else {
        return url.to_string();
    };
    let (Ok(host), Some(port)) = (parsed.host.parse::<std::net::Ipv4Addr>(), parsed.port) else {
        return url.to_string();
    };
    let query = url.split_once('?').map_or("", |(_, q)| q);
    let has = |k: &str| query.split('&').any(|kv| kv.split('=').next() == Some(k));
    let unicast = !host.is_multicast() && !host.is_broadcast() && !host.is_unspecified();
    if parsed.scheme != "udp" || !unicast || has("peer") || has("broadcast") || has("bind") {
        return url.to_string();
    }
    let rest = if query.is_empty() {
        String::new()
    } else {
        format!("&{query}")
    };
    format!("udp://0.0.0.0:0?peer={host}:{port}{rest}")
}

/// Opens a UDP medium.
fn open(mut o: Opening) -> Result<Arc<UdpTransport>, OpenError> {
    let cfg = UdpConfig::from_url(&mut o.url)?;
    let ep = &cfg.endpoint;
    let in_use = |e: &std::io::Error| e.kind() == std::io::ErrorKind::AddrInUse;
    let (std_socket, recv_buf) = match net::socket(ep) {
        Ok(s) => s,
        // a unicast address names where this medium listens; another program listens there
        Err(e) if in_use(&e) && matches!(ep.mode, net::Mode::Unicast(_)) => {
            let hint = format!(
                "binding {}: another program listens there; to send to it, name it as the \
                 peer and bind any free port: udp://0.0.0.0:0?peer={} (`seabus pub` does so \
                 by itself)",
                ep.bind, ep.bind
            );
            return Err(o.io_error(hint)(e));
        }
        Err(e) => return Err(o.io_error(format!("binding {}", ep.bind))(e)),
    };
    let socket =
        Arc::new(UdpSocket::from_std(std_socket).map_err(o.io_error("registering the socket"))?);
    if recv_buf < ep.recv_buf {
        tracing::debug!(medium = %o.name, "receive buffer is {recv_buf} bytes (asked for {})", ep.recv_buf);
    }
    let sender = fastrand::u64(1..);
    let transport = Arc::new(UdpTransport {
        name: o.name.clone(),
        outbox: outbox::Held::new(Outbox::new(socket.clone(), &o.ingress, cfg.send_gap)),
        sender,
        caps: cfg.capabilities(),
        dests: ep
            .destinations()
            .map_err(o.io_error("resolving the peers"))?,
        max: cfg.max,
    });
    let task = tokio::spawn(receive(socket, sender, o.ingress.clone()));
    o.ingress.own_task(task.abort_handle());
    o.ingress.set_link(LinkState::Up);
    tracing::debug!(medium = %o.name, mode = ?ep.mode, bind = %ep.bind, "udp medium open");
    Ok(transport)
}

impl Transport for UdpTransport {
    type Frame = Bytes;

    fn capabilities(&self) -> Capabilities {
        self.caps
    }

    fn encode(&self, msg: &Message) -> Result<Bytes, SendError> {
        let frame = wire::encode(msg, self.sender).map_err(|reason| SendError::Io {
            medium: self.name.to_string(),
            reason: reason.to_string(),
        })?;
        if frame.len() > self.max {
            return Err(SendError::TooLarge {
                medium: self.name.to_string(),
                size: frame.len(),
                max: self.max,
            });
        }
        Ok(frame)
    }

    fn transmit(&self, frame: Bytes) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            let outbox = self
                .outbox
                .get()
                .ok_or_else(|| SendError::Closed(self.name.to_string()))?;
            let sent = match &self.dests[..] {
                [to] => outbox.send(&[Outgoing::new(&[], frame, *to)]).await,
                dests => {
                    let ds: Vec<Outgoing> = dests
                        .iter()
                        .map(|to| Outgoing::new(&[], frame.clone(), *to))
                        .collect();
                    outbox.send(&ds).await
                }
            };
            sent.map_err(|e| SendError::Io {
                medium: self.name.to_string(),
                reason: format!("sending {e}"),
            })
        })
    }

    /// Returns once the datagrams of a stream still queued have gone to the socket.
    fn flush(&self) -> BoxFuture<'_, ()> {
        Box::pin(self.outbox.flush())
    }

    fn close(&self) {
        // the receive and outbox tasks, which hold the other references, are stopped by the medium
        self.outbox.close();
    }
}

/// Datagrams taken from the socket in one recvmmsg(2) call.
const RECV_BATCH: usize = 32;

async fn receive(socket: Arc<UdpSocket>, me: u64, ingress: Ingress) {
    let mut batch = RecvBatch::new(RECV_BATCH, MAX_DATAGRAM + 1);
    let mut chunk = BytesMut::with_capacity(RECV_CHUNK);
    let mut origins = wire::Origins::default();
    let fd = std::os::fd::AsRawFd::as_raw_fd(&*socket);
    loop {
        let n = match socket
            .async_io(Interest::READABLE, || batch.receive(fd))
            .await
        {
            Ok(n) => n,
            Err(e) => {
                tracing::debug!("udp receive: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                continue;
            }
        };
        for i in 0..n {
            let (from, d) = batch.get(i);
            // the payloads cut from a datagram share the chunk it is copied into
            if chunk.capacity() - chunk.len() < d.len() {
                chunk = BytesMut::with_capacity(RECV_CHUNK.max(d.len()));
            }
            chunk.extend_from_slice(d);
            let datagram = chunk.split().freeze();
            match wire::decode(&datagram, &mut origins) {
                Ok((sender, _)) if sender == me => {}
                Ok((_, msg)) => {
                    if !ingress.deliver(msg) {
                        return;
                    }
                }
                Err(e) => {
                    let from = net::inet(from).map_or_else(|| "?".to_string(), |a| a.to_string());
                    ingress.reject(e.kind(), format_args!("datagram from {from}: {e}"))
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_largest_datagram_is_checked() {
        let cfg = |u: &str| UdpConfig::from_url(&mut MediumUrl::parse(u).unwrap());
        assert_eq!(cfg("udp://1.2.3.4:1?max=100").unwrap().max, 100);
        assert!(
            cfg("udp://1.2.3.4:1?max=10")
                .unwrap_err()
                .reason
                .contains("max=10")
        );
        assert!(
            cfg("udp://1.2.3.4:1?maxi=10")
                .unwrap_err()
                .reason
                .contains("unknown option")
        );
        assert_eq!(
            cfg("udp://1.2.3.4:1").unwrap().capabilities().max_frame,
            Some(MAX_DATAGRAM)
        );
    }

    #[test]
    fn a_unicast_address_is_where_a_sender_sends() {
        assert_eq!(
            sending_url("udp://127.0.0.1:47811"),
            "udp://0.0.0.0:0?peer=127.0.0.1:47811"
        );
        assert_eq!(
            sending_url("udp://10.0.0.2:47811?max=1400"),
            "udp://0.0.0.0:0?peer=10.0.0.2:47811&max=1400"
        );
        for kept in [
            "udp://239.255.42.1:47800?ttl=0",
            "udp://255.255.255.255:47800",
            "udp://0.0.0.0:47801?peer=10.0.0.2:47801",
            "udp://127.0.0.1:47811?bind=127.0.0.1",
            "serial:///dev/ttyUSB0",
        ] {
            assert_eq!(sending_url(kept), kept);
        }
    }

    #[tokio::test]
    async fn a_unicast_port_in_use_says_how_to_send_to_it() {
        let taken = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let port = taken.local_addr().unwrap().port();
        let url = format!("udp://127.0.0.1:{port}");
        let err = schemes()
            .open("m", &url, &seabus_medium::Node::new("n"))
            .unwrap_err()
            .to_string();
        let want = format!(
            "another program listens there; to send to it, name it as the peer and bind any \
             free port: udp://0.0.0.0:0?peer=127.0.0.1:{port}"
        );
        assert!(err.contains(&want), "{err}");
        // and the sender's form of the same URL opens
        assert!(
            schemes()
                .open("m", &sending_url(&url), &seabus_medium::Node::new("n"))
                .is_ok()
        );
    }
}
