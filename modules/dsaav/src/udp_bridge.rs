//! `dsaav-udp-bridge`: lets a control station reach the vehicle's DSAAV services over UDP (the
//! paper's Wi-Fi bridge), relaying IComms frames unchanged between the vehicle's backbone and the
//! stations, for stations on an allow-list only. Both sides are DSAAV media in relay mode (they
//! carry every frame as it is: `seabus_medium_dsaav::relay`); the module decides what crosses.
//!
//! ```xml
//! <medium name="vehicle" url="dsaav+eth://eth0?relay"/>
//! <medium name="stations" url="dsaav+udp://10.0.0.1:47900?relay"/>
//! <module name="wifi" type="dsaav-udp-bridge" media="vehicle stations bus" allow="10.0.0.7 10.0.0.8"/>
//! ```
//! The first medium is the vehicle's backbone, the second the one stations send to, the third
//! where the bridge's counts are published (`seabus.bridge.<NAME>`, at the module's tick). A frame
//! from an allowed station goes onto the vehicle's backbone as it is, and the station's node is
//! remembered with its address; frames on the backbone addressed to a station's node, and channel
//! broadcasts from the vehicle, go back to the stations. Frames from other addresses are refused
//! and counted.

use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Kind, Message, Topic, Value};
use seabus_medium_dsaav::relay::{NATIVE, TOPIC};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

/// The `dsaav-udp-bridge` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "dsaav-udp-bridge",
    kind: ModuleKind::Bridge,
    summary: "relays DSAAV frames between the vehicle's backbone and UDP stations on an allow-list",
    build,
};

/// The ports: the vehicle's backbone, the stations' medium, the medium reports go to.
const VEHICLE: usize = 0;
const STATIONS: usize = 1;
const REPORTS: usize = 2;

/// Stations remembered, at most (a new one is not remembered past this; known ones move).
const MAX_STATIONS: usize = 256;

#[derive(Default)]
struct Counts {
    to_vehicle: u64,
    to_stations: u64,
    refused_peers: u64,
    bad_frames: u64,
}

struct UdpBridge {
    allow: Vec<IpAddr>,
    /// each station's node and the address it sends from
    stations: HashMap<u16, SocketAddr>,
    counts: Counts,
    report: Topic,
    frame_topic: Topic,
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let allow_attr = p
        .get("allow")
        .ok_or_else(|| cfg.pos.error("a dsaav-udp-bridge needs `allow`"))?;
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
    let frame_topic = Topic::new(TOPIC).map_err(|e| cfg.pos.error(e.to_string()))?;
    let mut decl = Declaration::new(ModuleKind::Bridge)
        .produces(TopicDecl::topic(report.as_str()).on_port(REPORTS))
        .default_tick(Duration::from_secs(1));
    for port in [VEHICLE, STATIONS] {
        decl = decl
            .consumes(TopicDecl::topic(TOPIC).on_port(port))
            .produces(TopicDecl::topic(TOPIC).on_port(port));
    }
    Ok(Built {
        decl,
        module: Box::new(UdpBridge {
            allow,
            stations: HashMap::new(),
            counts: Counts::default(),
            report,
            frame_topic,
        }),
    })
}

/// What a relay medium read: the frame, who sent it, and its source and destination nodes.
struct Read {
    frame: Value,
    from: String,
    src: u16,
    /// `None` for a channel broadcast
    dst: Option<u16>,
}

impl Read {
    fn of(msg: &Message) -> Option<Read> {
        let map = msg.payload.as_map()?;
        let node = |key: &str| map.get_i64(key).and_then(|n| u16::try_from(n).ok());
        Some(Read {
            frame: map.get("frame")?.clone(),
            from: map.get("from")?.as_str()?.to_string(),
            src: node("src")?,
            dst: node("dst"),
        })
    }
}

impl UdpBridge {
    /// A frame from a station: onto the vehicle's backbone when the station is allowed.
    async fn station_frame(&mut self, ctx: &mut Context, read: Read) -> Result<(), ModuleError> {
        let Ok(peer) = read.from.parse::<SocketAddr>() else {
            self.counts.bad_frames += 1;
            return Ok(());
        };
        if !self.allow.contains(&peer.ip()) {
            self.counts.refused_peers += 1;
            tracing::debug!("dsaav-udp-bridge: refused a frame from {peer}");
            return Ok(());
        }
        if self.stations.len() < MAX_STATIONS || self.stations.contains_key(&read.src) {
            self.stations.insert(read.src, peer);
        }
        let out = DataMap::new().with("frame", read.frame);
        self.send(ctx, VEHICLE, out).await;
        Ok(())
    }

    /// A frame on the vehicle's backbone: to the station it is addressed to, or to every station
    /// for a channel broadcast.
    async fn vehicle_frame(&mut self, ctx: &mut Context, read: Read) -> Result<(), ModuleError> {
        // frames of stations that this bridge put on the backbone are not sent back
        if self.stations.contains_key(&read.src) {
            return Ok(());
        }
        let targets: Vec<SocketAddr> = match read.dst {
            Some(node) => self.stations.get(&node).copied().into_iter().collect(),
            None => self.stations.values().copied().collect(),
        };
        for to in targets {
            let out = DataMap::new()
                .with("frame", read.frame.clone())
                .with("to", to.to_string());
            self.send(ctx, STATIONS, out).await;
        }
        Ok(())
    }

    /// Sends a frame on `port`, counting it when it went out.
    async fn send(&mut self, ctx: &mut Context, port: usize, map: DataMap) {
        match ctx
            .publish_on(port, Kind::Data, &self.frame_topic, map)
            .await
        {
            Ok(()) if port == VEHICLE => self.counts.to_vehicle += 1,
            Ok(()) => self.counts.to_stations += 1,
            Err(e) => tracing::debug!("dsaav-udp-bridge: a frame not relayed: {e}"),
        }
    }
}

#[async_trait]
impl Module for UdpBridge {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        for port in [VEHICLE, STATIONS] {
            let Some(p) = ctx.port(port) else {
                return Err(ModuleError::msg(
                    "a dsaav-udp-bridge is placed on three media: the vehicle's, the stations', \
                     and the one its reports go to",
                ));
            };
            let medium = p.medium();
            if !medium.capabilities().is_native(NATIVE) {
                return Err(ModuleError::msg(format!(
                    "medium `{}` ({}) does not relay DSAAV frames: give its URL the `relay` option",
                    medium.name(),
                    medium.url()
                )));
            }
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(read) = Read::of(&msg) else {
            self.counts.bad_frames += 1;
            return Ok(());
        };
        match port {
            STATIONS => self.station_frame(ctx, read).await,
            VEHICLE => self.vehicle_frame(ctx, read).await,
            _ => Ok(()),
        }
    }

    async fn on_timer(&mut self, ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        let c = &self.counts;
        let map = DataMap::new()
            .with("to_vehicle", c.to_vehicle as i64)
            .with("to_stations", c.to_stations as i64)
            .with("refused_peers", c.refused_peers as i64)
            .with("bad_frames", c.bad_frames as i64)
            .with("stations", self.stations.len() as i64);
        ctx.publish_on(REPORTS, Kind::Data, &self.report, map)
            .await
            .map_err(|e| ModuleError::msg(e.to_string()))
    }
}
