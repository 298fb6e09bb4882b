//! The Foxglove live view: a system file's `<foxglove>` element serves its medium's traffic over
//! the Foxglove WebSocket protocol (the `foxglove` crate's server), so Foxglove, Lichtblick and any
//! client of that protocol open a running vehicle.
//!
//! ```xml
//! <foxglove listen="127.0.0.1:8765" medium="bus" commands="cmd.course cmd.mission"/>
//! ```
//!
//! - Every data topic on the medium (`topics`, a pattern list, default `**`) is a channel, advertised
//!   when its first message comes, with a JSON Schema ([`seabus_modules::schema`]: the topic's
//!   standard dataset — field names, types, units, ranges — or one read off that first message);
//!   messages are JSON (the datamap's JSON form), log time = the message's stamp. A topic that goes
//!   quiet for `unadvertise` (default `10s`) is unadvertised, and advertised again when it speaks.
//! - Foxglove's well-known messages beside them, so the built-in panels work with no setup:
//!   `nav.position` is also `foxglove/nav.position` as `foxglove.LocationFix` (Map panel), with the
//!   heading of `nav.attitude` or `nav.heading` when known; `nav.attitude` is also
//!   `foxglove/tf` as a `foxglove.FrameTransform` from `world` to `vehicle` (3D panel), its
//!   translation the `nav.local` position (metres north, east, down) when there is one.
//!   This program's own log is `foxglove/log` as `foxglove.Log` (Log panel): every record of the
//!   seabus crates at `log` (default `info`; `warn`, `error`, `debug` or `off`) or above, named
//!   after its module or the node, with the source file and line.
//! - Clients may publish only when `commands` names command topics, and then only those: each
//!   message must be a JSON object in the datamap's JSON form, it must satisfy the topic's standard
//!   dataset (required fields, types, ranges) when the catalogue has one, and it goes on the medium
//!   as a command. Anything else is refused with a status message to that client, counted, and
//!   logged at most once a reason every 10 s. A message the protocol does not allow (text that is
//!   not JSON, an unknown binary opcode) is answered by the server with an error status on that
//!   connection alone; what is not WebSocket at all (a frame a client may not send, bytes that are
//!   no frame) closes that connection. Either way the others are unaffected, and the server's
//!   report of it is counted and logged the same way ([`Foxglove::client_faults`]).
//! - `listen` defaults to 127.0.0.1:8765: the live view stays on the machine unless an address is
//!   given. The protocol's two names are both accepted: `foxglove.sdk.v1` (Foxglove's app, the
//!   crate's own) and `foxglove.websocket.v1` (Foxglove's client library, older Lichtblick), see
//!   [`names`]: the crate's server listens on a loopback port behind seabus's own listener.

use foxglove::schemas::{FrameTransform, LocationFix, Log, Quaternion, Timestamp, Vector3};
use foxglove::websocket::{Capability, Client, ClientChannel, ServerListener, Status};
use foxglove::{ChannelBuilder, Context, Encode, PartialMetadata, RawChannel, Schema};
use seabus_medium::tally::Tally;
use seabus_medium::xml::{Element, FileError};
use seabus_medium::{DataMap, Interface, Kind, Medium, Message, Pattern, Payload, Stamp, Topic};
use seabus_modules::logs::{self, Capture, Record, Wants};
use seabus_modules::{Catalogue, SystemSpec, schema};
use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub mod names;
use names::Front;

/// The system file element this module reads.
pub const SECTION: &str = "foxglove";
/// Where the server listens unless told.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8765";
/// How long a quiet topic stays advertised unless told.
pub const DEFAULT_UNADVERTISE: Duration = Duration::from_secs(10);
/// Client commands waiting to go on the medium; more are refused.
const COMMAND_QUEUE: usize = 64;
/// Log records waiting to be served; more are dropped and counted.
const LOG_QUEUE: usize = 1024;
/// The foxglove crate's own targets: its reports of what clients did wrong.
const SERVER_TARGETS: &[&str] = &["foxglove"];

/// A `<foxglove>` element, read and checked.
#[derive(Debug, Clone)]
pub struct FoxgloveSpec {
    /// Where to listen.
    pub listen: SocketAddr,
    /// The medium whose traffic it serves.
    pub medium: String,
    /// The topics served.
    pub topics: Vec<Pattern>,
    /// The command topics clients may publish.
    pub commands: Vec<Topic>,
    /// How long a quiet topic stays advertised.
    pub unadvertise: Duration,
    /// The most detailed level of this program's log served, if it is served.
    pub log: Option<tracing::Level>,
    /// The node, naming log records that belong to no module.
    pub node: String,
    /// The element, for errors.
    pub element: Element,
}

/// The `<foxglove>` elements of a system file.
pub fn specs(spec: &SystemSpec) -> Result<Vec<FoxgloveSpec>, FileError> {
    let mut out = Vec::new();
    for el in spec.sections(SECTION) {
        el.only_attrs(&[
            "listen",
            "medium",
            "topics",
            "commands",
            "unadvertise",
            "log",
        ])?;
        el.only_children(&[])?;
        let medium = el
            .get("medium")
            .map_or_else(|| spec.default_medium().to_string(), str::to_string);
        if spec.medium(&medium).is_none() {
            let attr = el.required("medium")?;
            return Err(attr.error(format!("no medium called `{medium}`")));
        }
        let listen = match el.attr("listen") {
            None => DEFAULT_LISTEN
                .parse()
                .map_err(|_| el.error("bad default address"))?,
            Some(a) => a.value.trim().parse::<SocketAddr>().map_err(|_| {
                a.error(format!(
                    "`{}` is not an address and port (such as 127.0.0.1:8765)",
                    a.value
                ))
            })?,
        };
        let topics = match el.attr("topics") {
            None => vec![Pattern::new("**").map_err(|e| el.error(e.to_string()))?],
            Some(a) => a
                .value
                .split([',', ' '])
                .filter(|t| !t.is_empty())
                .map(|t| Pattern::new(t).map_err(|e| a.error(format!("`{t}`: {e}"))))
                .collect::<Result<_, _>>()?,
        };
        let commands = match el.attr("commands") {
            None => Vec::new(),
            Some(a) => a
                .value
                .split([',', ' '])
                .filter(|t| !t.is_empty())
                .map(|t| Topic::new(t).map_err(|e| a.error(format!("command `{t}`: {e}"))))
                .collect::<Result<_, _>>()?,
        };
        let unadvertise = match el.attr("unadvertise") {
            None => DEFAULT_UNADVERTISE,
            Some(a) => seabus_medium::parse::parse_duration(&a.value)
                .filter(|d| !d.is_zero())
                .ok_or_else(|| {
                    a.error(format!(
                        "`{}` is not a duration such as 10s or 1min",
                        a.value
                    ))
                })?,
        };
        let log = match el.attr("log") {
            None => Some(tracing::Level::INFO),
            Some(a) if a.value.trim() == "off" => None,
            Some(a) => Some(
                a.value
                    .trim()
                    .parse::<tracing::Level>()
                    .ok()
                    .filter(|l| *l != tracing::Level::TRACE)
                    .ok_or_else(|| {
                        a.error(format!(
                            "`{}` is not a log level: error, warn, info, debug or off",
                            a.value
                        ))
                    })?,
            ),
        };
        out.push(FoxgloveSpec {
            listen,
            medium,
            topics,
            commands,
            unadvertise,
            log,
            node: spec
                .node
                .clone()
                .unwrap_or_else(|| seabus_medium::Node::local().name.to_string()),
            element: el.clone(),
        });
    }
    Ok(out)
}

/// Why a client's message was not sent.
fn refusal(
    catalogue: &Catalogue,
    allowed: &[Topic],
    topic: &str,
    payload: &[u8],
) -> Result<(Topic, DataMap), String> {
    let Some(topic) = allowed.iter().find(|t| t.as_str() == topic) else {
        return Err(format!(
            "`{topic}` is not a command this server takes (it takes: {})",
            if allowed.is_empty() {
                "none".to_string()
            } else {
                allowed
                    .iter()
                    .map(Topic::as_str)
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        ));
    };
    let text = std::str::from_utf8(payload)
        .map_err(|e| format!("`{topic}`: the message is not UTF-8 JSON: {e}"))?;
    let map = seabus_medium::json::from_json(text)
        .map_err(|e| format!("`{topic}`: not a JSON object seabus reads: {e}"))?;
    if let Some(d) = catalogue.iter().find(|d| d.topic == topic.as_str()) {
        catalogue
            .validate(&d.name, &map)
            .map_err(|e| format!("`{topic}`: {e}"))?;
    }
    Ok((topic.clone(), map))
}

/// What the server's listener shares with the task that publishes.
struct Shared {
    catalogue: Arc<Catalogue>,
    commands: Vec<Topic>,
    to_bus: mpsc::Sender<(Topic, DataMap)>,
    /// Refused client messages by reason, logged without flooding.
    refused: Tally,
    /// The server's reports of clients' faults by kind (and the front door's), logged without
    /// flooding.
    faults: Arc<Tally>,
}

impl ServerListener for Shared {
    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let (reason, refused) =
            match refusal(&self.catalogue, &self.commands, &channel.topic, payload) {
                Ok(command) => match self.to_bus.try_send(command) {
                    Ok(()) => return,
                    Err(_) => (
                        "busy",
                        format!("`{}`: too many commands waiting; not sent", channel.topic),
                    ),
                },
                Err(reason) => ("refused", reason),
            };
        self.refused.record(
            "foxglove",
            reason,
            format_args!("client {}: {refused}", client.id()),
        );
        client.send_status(Status::error(format!("refused: {refused}")));
    }
}

/// One topic's channel and when it last spoke.
struct Served {
    channel: Arc<RawChannel>,
    last: Instant,
}

/// What the bus task keeps.
struct Feed {
    ctx: Arc<Context>,
    catalogue: Arc<Catalogue>,
    topics: Vec<Pattern>,
    unadvertise: Duration,
    served: HashMap<Topic, Served>,
    fix: Option<Arc<RawChannel>>,
    tf: Option<Arc<RawChannel>>,
    /// The latest heading, degrees.
    heading: Option<f64>,
    /// The latest local position, metres north, east, down.
    local: Option<[f64; 3]>,
    log: Option<Arc<RawChannel>>,
    node: String,
    scratch: Vec<u8>,
}

/// The channel of one of Foxglove's own schemas, `T`, on `topic`.
fn typed<T: Encode>(ctx: &Arc<Context>, topic: &str) -> Arc<RawChannel> {
    ChannelBuilder::new(topic)
        .context(ctx)
        .build::<T>()
        .into_inner()
}

/// Encodes `msg` into `scratch` and logs it on `channel`, when a client listens. (The SDK's own
/// typed `log` encodes into a 256 kB buffer on the stack, which every worker thread would then
/// keep resident.)
fn send<T: Encode>(channel: &RawChannel, msg: &T, scratch: &mut Vec<u8>, meta: PartialMetadata) {
    if !channel.has_sinks() {
        return;
    }
    scratch.clear();
    if msg.encode(scratch).is_ok() {
        channel.log_with_meta(scratch, meta);
    }
}

fn timestamp(s: Stamp) -> Timestamp {
    let ns = s.0.max(0);
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

/// The quaternion of a yaw, pitch and roll in degrees (ZYX, as the attitude dataset means them).
fn quaternion(yaw: f64, pitch: f64, roll: f64) -> Quaternion {
    let (y, p, r) = (
        yaw.to_radians() / 2.0,
        pitch.to_radians() / 2.0,
        roll.to_radians() / 2.0,
    );
    let (cy, sy, cp, sp, cr, sr) = (y.cos(), y.sin(), p.cos(), p.sin(), r.cos(), r.sin());
    Quaternion {
        w: cr * cp * cy + sr * sp * sy,
        x: sr * cp * cy - cr * sp * sy,
        y: cr * sp * cy + sr * cp * sy,
        z: cr * cp * sy - sr * sp * cy,
    }
}

impl Feed {
    fn wants(&self, topic: &Topic) -> bool {
        self.topics.iter().any(|p| p.matches(topic))
    }

    /// Serves `msg` on its topic's channel, and on the well-known channels it feeds.
    fn take(&mut self, msg: &Message) {
        let map = match &msg.payload {
            Payload::Bytes(b) => {
                Arc::new(DataMap::new().with("data", seabus_medium::Value::Bytes(b.to_vec())))
            }
            p => match p.to_map() {
                Ok(m) => m,
                Err(_) => return,
            },
        };
        self.well_known(msg, &map);
        if !self.wants(&msg.topic) {
            return;
        }
        if !self.served.contains_key(&msg.topic) {
            let s = schema::for_topic(&self.catalogue, msg.topic.as_str(), &map);
            let built = ChannelBuilder::new(msg.topic.as_str())
                .context(&self.ctx)
                .message_encoding("json")
                .schema(Schema::new(s.name, "jsonschema", s.text.into_bytes()))
                .build_raw();
            let channel = match built {
                Ok(c) => c,
                Err(e) => {
                    tracing::warn!(topic = %msg.topic, "foxglove: cannot advertise: {e}");
                    return;
                }
            };
            self.served.insert(
                msg.topic.clone(),
                Served {
                    channel,
                    last: Instant::now(),
                },
            );
        }
        let Some(served) = self.served.get_mut(&msg.topic) else {
            return;
        };
        served.last = Instant::now();
        self.scratch.clear();
        // as its schema says: a non-finite float under `$nonfinite`, never in a number's place
        if schema::write_message(&map, &mut self.scratch).is_err() {
            return;
        }
        served.channel.log_with_meta(
            &self.scratch,
            PartialMetadata {
                log_time: u64::try_from(msg.stamp.0).ok(),
            },
        );
    }

    fn well_known(&mut self, msg: &Message, map: &DataMap) {
        let meta = PartialMetadata {
            log_time: u64::try_from(msg.stamp.0).ok(),
        };
        match msg.topic.as_str() {
            "nav.heading" => self.heading = map.get_f64("heading"),
            "nav.local" => {
                if let (Some(n), Some(e)) = (map.get_f64("north"), map.get_f64("east")) {
                    self.local = Some([n, e, map.get_f64("down").unwrap_or(0.0)]);
                }
            }
            "nav.attitude" => {
                let (Some(yaw), Some(pitch), Some(roll)) = (
                    map.get_f64("yaw"),
                    map.get_f64("pitch"),
                    map.get_f64("roll"),
                ) else {
                    return;
                };
                self.heading = Some(yaw);
                let ctx = &self.ctx;
                let tf = self
                    .tf
                    .get_or_insert_with(|| typed::<FrameTransform>(ctx, "foxglove/tf"));
                // north-east-down as Foxglove's x-y-z: the vehicle seen from above
                let [n, e, d] = self.local.unwrap_or([0.0; 3]);
                send(
                    tf,
                    &FrameTransform {
                        timestamp: Some(timestamp(msg.stamp)),
                        parent_frame_id: "world".into(),
                        child_frame_id: "vehicle".into(),
                        translation: Some(Vector3 { x: n, y: e, z: d }),
                        rotation: Some(quaternion(yaw, pitch, roll)),
                    },
                    &mut self.scratch,
                    meta,
                );
            }
            "nav.position" => {
                let (Some(lat), Some(lon)) = (map.get_f64("lat"), map.get_f64("lon")) else {
                    return;
                };
                let ctx = &self.ctx;
                let fix = self
                    .fix
                    .get_or_insert_with(|| typed::<LocationFix>(ctx, "foxglove/nav.position"));
                send(
                    fix,
                    &LocationFix {
                        timestamp: Some(timestamp(msg.stamp)),
                        frame_id: "vehicle".into(),
                        latitude: lat,
                        longitude: lon,
                        altitude: map.get_f64("alt").unwrap_or(0.0),
                        position_covariance: vec![0.0; 9],
                        position_covariance_type: 0,
                        heading: self.heading.map(f64::to_radians),
                        ..Default::default()
                    },
                    &mut self.scratch,
                    meta,
                );
            }
            _ => {}
        }
    }

    /// Serves a record of this program's log.
    fn log(&mut self, rec: Record) {
        use foxglove::schemas::log::Level as L;
        let level = match rec.level {
            tracing::Level::ERROR => L::Error,
            tracing::Level::WARN => L::Warning,
            tracing::Level::INFO => L::Info,
            _ => L::Debug,
        };
        let ctx = &self.ctx;
        let channel = self
            .log
            .get_or_insert_with(|| typed::<Log>(ctx, "foxglove/log"));
        let (file, line) = rec.file.unwrap_or(("", 0));
        send(
            channel,
            &Log {
                timestamp: Some(timestamp(rec.time)),
                level: level as i32,
                message: rec.text,
                name: rec.component.unwrap_or_else(|| self.node.clone()),
                file: file.to_string(),
                line,
            },
            &mut self.scratch,
            PartialMetadata {
                log_time: u64::try_from(rec.time.0).ok(),
            },
        );
    }

    /// Unadvertises the topics quiet for longer than `unadvertise`.
    fn sweep(&mut self) {
        let quiet = self.unadvertise;
        self.served.retain(|_, s| {
            let keep = s.last.elapsed() < quiet;
            if !keep {
                s.channel.close();
            }
            keep
        });
    }
}

/// The next record of the log served, if one is.
async fn next_record(log: &mut Option<Capture>) -> Option<Record> {
    match log {
        Some(c) => c.recv().await,
        None => std::future::pending().await,
    }
}

/// A running Foxglove server; dropping it stops it.
pub struct Foxglove {
    front: Front,
    server: Option<foxglove::WebSocketServerHandle>,
    task: JoinHandle<()>,
    shared: Arc<Shared>,
}

impl Foxglove {
    /// Starts the server of `spec` on `medium`, its schemas from `catalogue`. A port in use is an
    /// error naming it.
    pub async fn start(
        spec: &FoxgloveSpec,
        medium: &Medium,
        catalogue: Arc<Catalogue>,
    ) -> Result<Foxglove, String> {
        let ctx = Context::new();
        let (to_bus, mut commands) = mpsc::channel(COMMAND_QUEUE);
        let shared = Arc::new(Shared {
            catalogue: catalogue.clone(),
            commands: spec.commands.clone(),
            to_bus,
            refused: Tally::new(),
            faults: Arc::new(Tally::new()),
        });
        let mut server = foxglove::WebSocketServer::new()
            .name("seabus")
            .context(&ctx)
            .bind(Ipv4Addr::LOCALHOST.to_string(), 0)
            .listener(shared.clone());
        if !spec.commands.is_empty() {
            server = server
                .capabilities([Capability::ClientPublish])
                .supported_encodings(["json"]);
        }
        let handle = server.start().await.map_err(|e| {
            format!(
                "{}: the Foxglove server cannot start on a loopback port: {e}",
                spec.element.pos
            )
        })?;
        let inner = SocketAddr::new(Ipv4Addr::LOCALHOST.into(), handle.port());
        let front = Front::start(spec.listen, inner, shared.faults.clone())
            .await
            .map_err(|e| {
                format!(
                    "{}: the Foxglove server cannot listen on {}: {e}",
                    spec.element.pos, spec.listen
                )
            })?;
        let port: Interface = medium.attach_with("foxglove", 1 << 12, 1 << 6);
        let mut feed = Feed {
            ctx,
            catalogue,
            topics: spec.topics.clone(),
            unadvertise: spec.unadvertise,
            served: HashMap::new(),
            fix: None,
            tf: None,
            heading: None,
            local: None,
            log: None,
            node: spec.node.clone(),
            scratch: Vec::new(),
        };
        let mut log = spec.log.map(|level| {
            logs::attach(Wants {
                level,
                targets: Wants::SEABUS,
                queue: LOG_QUEUE,
            })
        });
        let mut server_log = logs::attach(Wants {
            level: tracing::Level::WARN,
            targets: SERVER_TARGETS,
            queue: LOG_QUEUE,
        });
        let faults = shared.clone();
        let task = tokio::spawn(async move {
            let mut port = port;
            if let Err(e) = port.subscribe_kind("**", Some(Kind::Data)) {
                tracing::error!("foxglove: cannot subscribe: {e}");
                return;
            }
            let mut sweep = tokio::time::interval(Duration::from_secs(1));
            sweep.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tokio::select! {
                    m = port.recv() => match m {
                        Some(m) => feed.take(&m),
                        None => break,
                    },
                    c = commands.recv() => {
                        let Some((topic, map)) = c else { break };
                        if let Err(e) = port.publish(Kind::Command, topic.clone(), Payload::from(map)).await {
                            tracing::warn!(%topic, "foxglove: a client's command not sent: {e}");
                        }
                    }
                    _ = sweep.tick(), if !feed.served.is_empty() => feed.sweep(),
                    Some(r) = next_record(&mut log) => feed.log(r),
                    Some(r) = server_log.recv() => {
                        let kind = if r.text.starts_with("Invalid message") {
                            "malformed message"
                        } else if r.text.starts_with("Error receiving") {
                            "broken connection"
                        } else {
                            "server"
                        };
                        faults.faults.record("foxglove", kind, format_args!("{}", r.text));
                    }
                }
            }
        });
        Ok(Foxglove {
            front,
            server: Some(handle),
            task,
            shared,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.front.addr()
    }

    /// The URL a Foxglove client opens.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr())
    }

    /// Client messages refused so far.
    pub fn refused(&self) -> u64 {
        self.shared.refused.counts().values().sum()
    }

    /// What the server reported of its clients so far (malformed messages, broken connections),
    /// by kind.
    pub fn client_faults(&self) -> std::collections::BTreeMap<String, u64> {
        self.shared.faults.counts()
    }
}

impl Drop for Foxglove {
    fn drop(&mut self) {
        if let Some(s) = self.server.take() {
            drop(s.stop());
        }
        self.task.abort();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_refused_unless_allowed_well_formed_and_in_range() {
        let cat = Catalogue::built_in();
        let allowed = vec![Topic::new("cmd.course").unwrap()];
        let e = refusal(&cat, &allowed, "cmd.mission", b"{}").unwrap_err();
        assert_eq!(
            e,
            "`cmd.mission` is not a command this server takes (it takes: cmd.course)"
        );
        let e = refusal(&cat, &allowed, "cmd.course", b"[1,2]").unwrap_err();
        assert!(e.starts_with("`cmd.course`: not a JSON object"), "{e}");
        let e = refusal(
            &cat,
            &allowed,
            "cmd.course",
            br#"{"heading": 400.0, "depth": 2.0, "speed": 1.0}"#,
        )
        .unwrap_err();
        assert!(e.contains("heading"), "{e}");
        let e = refusal(&cat, &allowed, "cmd.course", br#"{"heading": 90.0}"#).unwrap_err();
        assert!(e.contains("depth") && e.contains("speed"), "{e}");
        let (t, m) = refusal(
            &cat,
            &allowed,
            "cmd.course",
            br#"{"heading": 90.0, "depth": 2.0, "speed": 1.0}"#,
        )
        .unwrap();
        assert_eq!(t.as_str(), "cmd.course");
        assert_eq!(m.get_f64("heading"), Some(90.0));
    }

    #[test]
    fn an_attitude_turns_into_the_quaternion_of_its_angles() {
        let q = quaternion(90.0, 0.0, 0.0);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q.w - h).abs() < 1e-12 && (q.z - h).abs() < 1e-12);
        assert!(q.x.abs() < 1e-12 && q.y.abs() < 1e-12);
        let q = quaternion(0.0, 0.0, 180.0);
        assert!(q.w.abs() < 1e-12 && (q.x - 1.0).abs() < 1e-12);
    }
}
