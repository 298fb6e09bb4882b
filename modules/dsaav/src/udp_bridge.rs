//! `dsaav-udp-bridge`: lets a control station reach the vehicle's DSAAV services over UDP (the
//! paper's Wi-Fi bridge), relaying IComms frames unchanged between a raw Ethernet interface and a
//! UDP socket, for stations on an allow-list only.
//!
//! ```xml
//! <module name="wifi" type="dsaav-udp-bridge" medium="bus" iface="eth0" bind="10.0.0.1:47900" allow="10.0.0.7 10.0.0.8"/>
//! ```
//! A frame from an allowed station goes onto the vehicle's Ethernet as it is, and the station's
//! node is remembered; frames on the Ethernet addressed to a station's node, and channel broadcasts
//! from the vehicle, go back to the stations. Datagrams from other addresses, and frames that do
//! not read, are refused and counted; the counts are published on `seabus.bridge.<NAME>` at the
//! module's tick.

use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Topic};
use seabus_medium_dsaav::ETHERTYPE;
use seabus_medium_dsaav::eth::RawSocket;
use seabus_medium_dsaav::wire::{Destination, Frame};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// The `dsaav-udp-bridge` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "dsaav-udp-bridge",
    kind: ModuleKind::Bridge,
    summary: "relays DSAAV frames between raw Ethernet and UDP stations on an allow-list",
    build,
};

#[derive(Default)]
struct Counts {
    to_vehicle: AtomicU64,
    to_stations: AtomicU64,
    refused_peers: AtomicU64,
    bad_frames: AtomicU64,
}

struct UdpBridge {
    iface: String,
    bind: SocketAddr,
    allow: Vec<IpAddr>,
    counts: Arc<Counts>,
    report: Topic,
    relay: Option<tokio::task::JoinHandle<()>>,
}

impl Drop for UdpBridge {
    fn drop(&mut self) {
        if let Some(r) = self.relay.take() {
            r.abort();
        }
    }
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let need = |name: &str| {
        p.get(name)
            .ok_or_else(|| cfg.pos.error(format!("a dsaav-udp-bridge needs `{name}`")))
    };
    let iface = need("iface")?.value.trim().to_string();
    let bind_attr = need("bind")?;
    let bind: SocketAddr = bind_attr
        .value
        .trim()
        .parse()
        .map_err(|_| bind_attr.error("expected ADDRESS:PORT to listen on"))?;
    let allow_attr = need("allow")?;
    let allow = allow_attr
        .value
        .split([' ', ','])
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<IpAddr>()
                .map_err(|_| allow_attr.error(format!("`{s}` is not an IP address")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let report = Topic::new(&format!("seabus.bridge.{}", cfg.name))
        .map_err(|e| cfg.pos.error(e.to_string()))?;
    Ok(Built {
        decl: Declaration::new(ModuleKind::Bridge)
            .produces(TopicDecl::topic(report.as_str()))
            .default_tick(Duration::from_secs(1)),
        module: Box::new(UdpBridge {
            iface,
            bind,
            allow,
            counts: Arc::default(),
            report,
            relay: None,
        }),
    })
}

/// Relays frames both ways until aborted.
async fn relay(
    eth: RawSocket,
    udp: tokio::net::UdpSocket,
    allow: Vec<IpAddr>,
    counts: Arc<Counts>,
) {
    let mut stations: HashMap<u16, SocketAddr> = HashMap::new();
    let mut from_udp = vec![0u8; 2048];
    let mut from_eth = vec![0u8; 2048];
    loop {
        tokio::select! {
            r = udp.recv_from(&mut from_udp) => {
                let Ok((n, peer)) = r else { continue };
                if !allow.contains(&peer.ip()) {
                    counts.refused_peers.fetch_add(1, Ordering::Relaxed);
                    tracing::debug!("dsaav-udp-bridge: refused a datagram from {peer}");
                    continue;
                }
                let Ok(frame) = Frame::decode(&from_udp[..n]) else {
                    counts.bad_frames.fetch_add(1, Ordering::Relaxed);
                    continue;
                };
                if stations.len() < 256 || stations.contains_key(&frame.src.node) {
                    stations.insert(frame.src.node, peer);
                }
                let to = match frame.dst {
                    Destination::To(a) => Some(a.node),
                    Destination::Channel(_) => None,
                };
                if eth.send(to, &from_udp[..n]).await.is_ok() {
                    counts.to_vehicle.fetch_add(1, Ordering::Relaxed);
                }
            }
            r = eth.recv(&mut from_eth) => {
                let Ok(Some((mac, n))) = r else { continue };
                let Ok(frame) = Frame::decode(&from_eth[..n]) else { continue };
                // frames of stations that this bridge put on the wire are not sent back
                if stations.contains_key(&frame.src.node) {
                    continue;
                }
                eth.learn(frame.src.node, mac);
                let targets: Vec<SocketAddr> = match frame.dst {
                    Destination::To(a) => stations.get(&a.node).copied().into_iter().collect(),
                    Destination::Channel(_) => stations.values().copied().collect(),
                };
                for t in targets {
                    if udp.send_to(&from_eth[..n], t).await.is_ok() {
                        counts.to_stations.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        }
    }
}

#[async_trait]
impl Module for UdpBridge {
    async fn start(&mut self, _: &mut Context) -> Result<(), ModuleError> {
        let eth = RawSocket::open(&self.iface, ETHERTYPE)
            .map_err(|e| ModuleError::msg(format!("raw socket on {}: {e}", self.iface)))?;
        let udp = tokio::net::UdpSocket::bind(self.bind)
            .await
            .map_err(|e| ModuleError::msg(format!("binding {}: {e}", self.bind)))?;
        if let Some(old) = self.relay.take() {
            old.abort();
        }
        self.relay = Some(tokio::spawn(relay(
            eth,
            udp,
            self.allow.clone(),
            self.counts.clone(),
        )));
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        let c = &self.counts;
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed) as i64;
        let map = DataMap::new()
            .with("to_vehicle", get(&c.to_vehicle))
            .with("to_stations", get(&c.to_stations))
            .with("refused_peers", get(&c.refused_peers))
            .with("bad_frames", get(&c.bad_frames));
        ctx.publish(&self.report, map).await
    }
}
