//! seabus-medium-zenoh, the Zenoh medium: seabus messages over Eclipse Zenoh, for fleets and shore
//! stations beyond one LAN (routing, discovery across subnets, reconnection through routers).
//!
//! ```text
//! zenoh://?prefix=fleet/auv1&connect=tcp/10.0.0.1:7447          a vehicle, a peer reaching a router
//! zenoh://?mode=client&connect=tcp/shore:7447&prefix=fleet/auv2  a client of a router
//! zenoh://?mode=router&listen=tcp/0.0.0.0:7447&prefix=fleet      a shore station that routes
//! zenoh://?config=zenoh.json5&prefix=fleet                       Zenoh's own configuration file
//! ```
//! Options: `mode` (`peer`, the default, `client` or `router`), `connect` and `listen` (Zenoh
//! endpoints such as `tcp/127.0.0.1:7447`, repeatable or comma-separated), `prefix` (the key
//! space this medium's topics live in, default `seabus`; see [`keys`]), `config` (a Zenoh
//! configuration file, JSON5, relative to the working directory; the other options are applied
//! over it), `scout` (multicast scouting for peers on the LAN, default on unless `connect` is
//! given), `json` (datamaps are published as JSON so that any Zenoh program reads them; default
//! off), `fleet` and `lease` (see [`fleet`]); TLS with `ca`, `cert`, `key` (PEM files: the
//! fleet's certificate authority, this node's certificate and key) and `mtls` (a listener refuses
//! peers without a certificate the authority signed; on when the node has one); user and password
//! authentication with `user` and `password_file`, and for a listener `users` (a file of
//! `user:password` lines).
//!
//! **Wire.** A message is published on its topic's key as a seabus datagram
//! ([`seabus_medium::datagram`]: provenance, kind, stamp, payload) with the encoding
//! `application/octet-stream;seabus`, so bridges stay loop-safe and receivers exactly-once across
//! redundant paths. With `json`, a datamap goes as its JSON object (`application/json`) and the
//! datagram without the payload rides as the sample's attachment. A sample from a program that is
//! not seabus is taken as it is: JSON text as a datamap, anything else as bytes, a command when its
//! encoding's schema says `command` (`application/json;command`), data otherwise; a sample that
//! says it is seabus's but does not decode, or whose key is no topic, is counted by reason and
//! dropped.
//!
//! **Quality of service** from the message kind: a command is sent reliably, blocking when the
//! network is congested, at interactive-high priority and without batching (express); data is
//! dropped under congestion, at data priority, batched. Topics declared with a [`Qos`]
//! ([`seabus_medium::Medium::set_qos`]: a bridge route's `priority`, `congestion` and `express`)
//! take what it sets over their kind's, attribute by attribute; the first declaration matching a
//! topic counts.
//!
//! **Link state**: up while the session is connected to a router or a peer (or is itself a
//! router), down otherwise, checked every second.
//!
//! Who may depend on it: the program, to register `zenoh://` ([`register`]). It depends on the core
//! only.

pub mod fleet;
pub mod keys;

use bytes::Bytes;
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::datagram;
use seabus_medium::qos::{self, Congestion, Qos};
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{
    BoxFuture, Ingress, Kind, LinkState, Message, OpenError, Opened, Opening, Pattern, Payload,
    Scheme, Schemes, SendError, Topic, Transport,
};
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, LazyLock, Mutex, RwLock};
use std::time::Duration;
use tokio::sync::watch;
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::pubsub::Publisher;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::{Locality, Sample};
use zenoh::session::EntityGlobalId;
use zenoh::{Config, Session};
use zenoh_ext::{
    AdvancedPublisher, AdvancedPublisherBuilderExt, AdvancedSubscriber,
    AdvancedSubscriberBuilderExt, CacheConfig, HistoryConfig, Miss, MissDetectionConfig,
    RecoveryConfig,
};

/// How a Zenoh medium connects: its mode and endpoints, prefix and payload form.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ZenohConfig {
    /// `peer`, `client` or `router`.
    pub mode: String,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// The key space of this medium's topics.
    pub prefix: String,
    /// A Zenoh configuration file applied first.
    pub config: Option<String>,
    /// Multicast scouting.
    pub scout: bool,
    /// Datamaps published as JSON.
    pub json: bool,
    /// The fleet's key space, where each node's liveliness token lives.
    pub fleet: String,
    /// How soon a silent connection counts as lost, when no configuration file sets it.
    pub lease: Duration,
    /// TLS: the certificate authority's certificate, and this node's certificate and key (PEM
    /// files), and whether a listener requires its peers' certificates.
    pub tls: Option<Tls>,
    /// User and password authentication: this node's user and the file holding its password,
    /// and for a listener the file of `user:password` lines it accepts.
    pub auth: Auth,
}

/// TLS settings (see [`ZenohConfig::tls`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tls {
    /// The certificate authority's certificate.
    pub ca: String,
    /// This node's certificate.
    pub cert: Option<String>,
    /// This node's private key.
    pub key: Option<String>,
    /// A listener refuses peers without a certificate the authority signed.
    pub mtls: bool,
}

/// User and password settings (see [`ZenohConfig::auth`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Auth {
    /// This node's user name.
    pub user: Option<String>,
    /// The file holding its password.
    pub password_file: Option<String>,
    /// For a listener: the file of `user:password` lines it accepts.
    pub users: Option<String>,
}

const OPTIONS: &[&str] = &[
    "mode", "connect", "listen", "prefix", "config", "scout", "json",
];

/// The encoding of a seabus datagram.
static DATAGRAM: LazyLock<Encoding> =
    LazyLock::new(|| Encoding::APPLICATION_OCTET_STREAM.with_schema("seabus"));

/// Endpoints listed in option `name` (repeated or comma-separated), each checked.
fn endpoints(url: &mut MediumUrl, name: &str) -> Result<Vec<String>, UrlError> {
    let mut out = Vec::new();
    for value in url.take_all(name) {
        for ep in value.split(',').map(str::trim).filter(|e| !e.is_empty()) {
            if ep.parse::<zenoh::config::EndPoint>().is_err() {
                return Err(url.error(format!(
                    "option `{name}={ep}`: not a Zenoh endpoint (such as tcp/127.0.0.1:7447)"
                )));
            }
            out.push(ep.to_string());
        }
    }
    Ok(out)
}

impl ZenohConfig {
    /// Reads the settings from a `zenoh://` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<ZenohConfig, UrlError> {
        if !url.host.is_empty() || url.port.is_some() {
            return Err(url.error(
                "a zenoh:// URL names no host: say where to connect with ?connect=tcp/HOST:PORT",
            ));
        }
        let mode = url.take("mode").unwrap_or_else(|| "peer".to_string());
        if !matches!(mode.as_str(), "peer" | "client" | "router") {
            return Err(url.error(format!(
                "option `mode={mode}`: expected peer, client or router"
            )));
        }
        let connect = endpoints(url, "connect")?;
        let listen = endpoints(url, "listen")?;
        let prefix = url.take("prefix").unwrap_or_else(|| "seabus".to_string());
        let prefix = prefix.trim_matches('/').to_string();
        keys::check_prefix(&prefix).map_err(|e| url.error(format!("option `prefix`: {e}")))?;
        let config = url.take("config");
        let scout = url.take_flag("scout")?.unwrap_or(connect.is_empty());
        let json = url.take_flag("json")?.unwrap_or(false);
        let fleet = match url.take("fleet") {
            Some(f) => f.trim_matches('/').to_string(),
            None => prefix.split('/').next().unwrap_or_default().to_string(),
        };
        keys::check_prefix(&fleet).map_err(|e| url.error(format!("option `fleet`: {e}")))?;
        let lease = match url.take("lease") {
            Some(text) => seabus_medium::parse::parse_duration(&text)
                .filter(|d| *d >= Duration::from_millis(100))
                .ok_or_else(|| {
                    url.error(format!(
                        "option `lease={text}`: expected a duration of 100ms or more"
                    ))
                })?,
            None => Duration::from_secs(3),
        };
        let tls = tls_options(url)?;
        let auth = Auth {
            user: url.take("user"),
            password_file: url.take("password_file"),
            users: url.take("users"),
        };
        if auth.user.is_some() != auth.password_file.is_some() {
            return Err(url.error("`user` and `password_file` go together"));
        }
        if mode == "client" && connect.is_empty() && config.is_none() && !scout {
            return Err(url.error("a client needs a router to connect to: ?connect=tcp/HOST:PORT"));
        }
        url.finish(OPTIONS)?;
        Ok(ZenohConfig {
            mode,
            connect,
            listen,
            prefix,
            config,
            scout,
            json,
            fleet,
            lease,
            tls,
            auth,
        })
    }

    /// What a Zenoh medium can do: whole seabus messages with provenance, any payload, a link
    /// that goes down and up, a quality of service per topic; its own messages never come back to
    /// it.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: true,
            framing: Framing::Datagram,
            max_frame: None,
            hears_own: false,
            carries: Carries::Any,
            link_state: true,
            native: None,
            qos: true,
            lists: true,
        }
    }

    /// The Zenoh configuration: the file's, then these settings over it.
    pub fn zenoh(&self) -> Result<Config, String> {
        let mut c = match &self.config {
            Some(path) => {
                Config::from_file(path).map_err(|e| config_error(path, &e.to_string()))?
            }
            None => Config::default(),
        };
        let json = |v: &[String]| serde_json::to_string(v).unwrap_or_default();
        let mut set = |key: &str, value: String| {
            c.insert_json5(key, &value)
                .map_err(|e| format!("setting {key} = {value}: {e}"))
        };
        set("mode", format!("\"{}\"", self.mode))?;
        if !self.connect.is_empty() {
            set("connect/endpoints", json(&self.connect))?;
        }
        if !self.listen.is_empty() {
            set("listen/endpoints", json(&self.listen))?;
        }
        if self.config.is_none() || !self.scout {
            set("scouting/multicast/enabled", self.scout.to_string())?;
        }
        let quoted = |v: &str| serde_json::to_string(v).unwrap_or_default();
        if let Some(tls) = &self.tls {
            set("transport/link/tls/root_ca_certificate", quoted(&tls.ca))?;
            if let (Some(cert), Some(key)) = (&tls.cert, &tls.key) {
                for side in ["listen", "connect"] {
                    set(
                        &format!("transport/link/tls/{side}_certificate"),
                        quoted(cert),
                    )?;
                    set(
                        &format!("transport/link/tls/{side}_private_key"),
                        quoted(key),
                    )?;
                }
            }
            set("transport/link/tls/enable_mtls", tls.mtls.to_string())?;
        }
        if let (Some(user), Some(file)) = (&self.auth.user, &self.auth.password_file) {
            let password = std::fs::read_to_string(file)
                .map_err(|e| format!("option `password_file`: cannot read {file}: {e}"))?;
            set("transport/auth/usrpwd/user", quoted(user))?;
            set("transport/auth/usrpwd/password", quoted(password.trim()))?;
        }
        if let Some(users) = &self.auth.users {
            set("transport/auth/usrpwd/dictionary_file", quoted(users))?;
        }
        if self.config.is_none() {
            set(
                "transport/link/tx/lease",
                self.lease.as_millis().to_string(),
            )?;
        }
        Ok(c)
    }
}

/// A Zenoh configuration file's error as `FILE:LINE:COL: what was expected` where Zenoh's message
/// places it (` --> LINE:COL` … `= expected …`), else `FILE: the message's first line`.
pub fn config_error(path: &str, message: &str) -> String {
    let place = message.split(" --> ").nth(1).and_then(|rest| {
        let pos = rest.split_whitespace().next()?;
        let (line, col) = pos.split_once(':')?;
        Some((line.parse::<u32>().ok()?, col.parse::<u32>().ok()?))
    });
    let what = message
        .lines()
        .find_map(|l| l.trim().strip_prefix("= "))
        .unwrap_or_else(|| message.lines().next().unwrap_or_default().trim());
    // (Zenoh ends some messages with the place in its own source: not the user's business)
    let what = what
        .split(" at /")
        .next()
        .unwrap_or(what)
        .trim_end_matches('.');
    match place {
        Some((line, col)) => format!("{path}:{line}:{col}: {what}"),
        None => format!("{path}: {what}"),
    }
}

/// The TLS options: `ca` (required for TLS), `cert` and `key` together, `mtls` (default on when this
/// node has a certificate).
fn tls_options(url: &mut MediumUrl) -> Result<Option<Tls>, UrlError> {
    let (ca, cert, key) = (url.take("ca"), url.take("cert"), url.take("key"));
    let mtls = url.take_flag("mtls")?;
    if cert.is_some() != key.is_some() {
        return Err(url.error("`cert` and `key` go together: this node's certificate and its key"));
    }
    let Some(ca) = ca else {
        if cert.is_some() || mtls.is_some() {
            return Err(url.error("TLS needs `ca`, the certificate authority's certificate"));
        }
        return Ok(None);
    };
    let mtls = mtls.unwrap_or(cert.is_some());
    Ok(Some(Tls {
        ca,
        cert,
        key,
        mtls,
    }))
}

/// Adds `zenoh://`.
pub fn register(schemes: &mut Schemes) {
    schemes.add(Scheme {
        name: "zenoh",
        family: "zenoh",
        summary: "seabus messages over Eclipse Zenoh (peer, client or router): fleets and shore",
        check: |url| {
            let cfg = ZenohConfig::from_url(url)?;
            cfg.zenoh().map_err(|e| url.error(e))?;
            Ok(cfg.capabilities())
        },
        open: |o| Ok(Opened::from(open(o)?)),
    });
}

/// A registry with `zenoh://` and the in-process medium, for a program or test that uses only
/// these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}

/// What a message becomes: the bytes, and the outlet of its topic and kind.
#[derive(Clone)]
pub struct Frame {
    outlet: Arc<Outlet>,
    payload: Bytes,
    /// `Some(datagram without payload)` for a datamap sent as JSON
    attachment: Option<Bytes>,
}

/// The outlets of the topics sent: `[data, commands]`.
type Outlets = [HashMap<Topic, Arc<Outlet>>; 2];

/// How one topic of one kind goes out: its key, made once; its quality of service (its kind's, or
/// what was declared for its topic); and its publisher, declared with the first message.
pub struct Outlet {
    key: String,
    command: bool,
    qos: SendQos,
    /// whether it is one of the medium's kept outlets (past [`MAX_PUBLISHERS`], messages are put
    /// without a publisher of their own)
    kept: bool,
    /// the samples its publisher keeps for subscribers that missed some (data only)
    history: usize,
    publisher: tokio::sync::OnceCell<Publishing>,
}

/// A message's quality of service on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SendQos {
    priority: Priority,
    congestion: CongestionControl,
    express: bool,
}

/// What a message of a kind gets unless its topic was declared with something else: a command
/// blocks under congestion, at interactive-high priority, express; data is dropped, at data
/// priority, batched.
fn kind_qos(command: bool) -> Qos {
    if command {
        Qos {
            priority: Some(qos::Priority::InteractiveHigh),
            congestion: Some(Congestion::Block),
            express: Some(true),
        }
    } else {
        Qos {
            priority: Some(qos::Priority::Data),
            congestion: Some(Congestion::Drop),
            express: Some(false),
        }
    }
}

/// Whether `topic` carries what became of commands (`cmd.status`, a vehicle's `auv1.cmd.status`):
/// an operator waits for those as for the command itself, so they go with a command's quality of
/// service. Under congestion, a dropped `pending` would leave the console without the command's
/// first answer.
fn answers_commands(topic: &Topic) -> bool {
    let t = topic.as_str();
    t == "cmd.status" || t.ends_with(".cmd.status")
}

impl SendQos {
    /// `qos` over the defaults of the kind (`command` or data).
    fn of(qos: Qos, command: bool) -> SendQos {
        let q = qos.over(kind_qos(command));
        SendQos {
            priority: match q.priority.unwrap_or(qos::Priority::Data) {
                qos::Priority::Realtime => Priority::RealTime,
                qos::Priority::InteractiveHigh => Priority::InteractiveHigh,
                qos::Priority::InteractiveLow => Priority::InteractiveLow,
                qos::Priority::DataHigh => Priority::DataHigh,
                qos::Priority::Data => Priority::Data,
                qos::Priority::DataLow => Priority::DataLow,
                qos::Priority::Background => Priority::Background,
            },
            congestion: match q.congestion.unwrap_or(Congestion::Drop) {
                Congestion::Block => CongestionControl::Block,
                Congestion::Drop => CongestionControl::Drop,
            },
            express: q.express.unwrap_or(false),
        }
    }
}

/// The qualities of service declared for topics, in the order declared.
type Overrides = Vec<(Pattern, Option<Kind>, Qos)>;

/// Samples a command-status publisher keeps, so that a subscriber that missed some (a link lost
/// and made again) gets them back in order: a command's `pending` as well as its outcome.
const STATUS_HISTORY: usize = 32;
/// Publishers kept per key and kind; beyond this many, messages are put without one.
const MAX_PUBLISHERS: usize = 4096;
/// How soon after a data sample its publisher says how many it sent, so that a subscriber
/// knows what it missed (only while samples are sent: an idle publisher says nothing).
const HEARTBEAT: Duration = Duration::from_millis(500);
/// How long a send waits for the session to open.
const OPEN_WAIT: Duration = Duration::from_secs(5);

/// The Zenoh transport.
pub struct ZenohTransport {
    name: Arc<str>,
    prefix: Arc<str>,
    /// where this node's own status (`seabus.*`) goes when the prefix is the whole fleet's key
    /// space (a shore's): `<fleet>/<node>`, the node's own place there, as its token's
    own_status: Option<Arc<str>>,
    json: bool,
    /// this medium instance, to know its own datagrams
    sender: u64,
    caps: Capabilities,
    session: watch::Receiver<Option<Session>>,
    /// the session once open (it is opened once), taken without a lock or a count
    opened: Arc<std::sync::OnceLock<Session>>,
    /// the outlet of each topic sent, data's and commands'; dropped when a quality of service is
    /// declared, so that each is made again with it
    outlets: Mutex<Outlets>,
    /// the qualities of service declared for topics ([`Transport::set_qos`])
    overrides: RwLock<Overrides>,
    hearing: Hearing,
}

/// Declares the publisher of outlet `o`: for data, one that keeps its latest sample for late
/// joiners (command statuses their last [`STATUS_HISTORY`], for subscribers that missed some)
/// and numbers its samples; for commands, a plain one.
async fn declare(session: &Session, o: &Outlet) -> zenoh::Result<Publishing> {
    let builder = session
        .declare_publisher(o.key.clone())
        .congestion_control(o.qos.congestion)
        .priority(o.qos.priority)
        .express(o.qos.express);
    Ok(if o.command {
        Publishing::Command(builder.await?)
    } else {
        Publishing::Data(
            builder
                .cache(CacheConfig::default().max_samples(o.history))
                .sample_miss_detection(MissDetectionConfig::default().sporadic_heartbeat(HEARTBEAT))
                .publisher_detection()
                .await?,
        )
    })
}

/// A publisher of one key: data keeps its latest sample for late joiners and numbers its samples so
/// that a subscriber knows what it missed; a command does neither (a command is never replayed).
enum Publishing {
    Data(AdvancedPublisher<'static>),
    Command(Publisher<'static>),
}

/// What the medium hears: the key expressions asked for, their subscribers once the session is
/// open, and where what they hear goes.
#[derive(Clone)]
struct Hearing {
    prefix: Arc<str>,
    /// this medium instance, to know its own datagrams
    sender: u64,
    ingress: Ingress,
    subscriptions: Arc<Mutex<Subscriptions>>,
    /// the fleet's members, as their liveliness tokens come and go
    fleet: fleet::Fleet,
    /// what reading samples keeps from one to the next, under one lock
    heard: Arc<Mutex<Heard>>,
}

/// Publishers whose topic is kept, at most; past this the map starts again.
const MAX_SOURCES: usize = 4096;
/// Keys whose topic is kept, at most; past this the map starts again.
const MAX_KEYS: usize = 4096;

/// What reading one sample leaves for the next: the topic of each key heard (a key is turned into
/// a topic once), the topic of each publisher heard (for the samples it says were missed) and
/// the origins of the datagrams heard (shared rather than made again for each one).
#[derive(Default)]
struct Heard {
    topics: HashMap<Box<str>, Topic>,
    sources: HashMap<EntityGlobalId, Topic>,
    origins: datagram::Origins,
}

impl Heard {
    /// The topic of `key`, under `prefix`.
    fn topic(&mut self, prefix: &str, key: &str) -> Result<Topic, keys::KeyError> {
        if let Some(t) = self.topics.get(key) {
            return Ok(t.clone());
        }
        let topic = keys::key_topic(prefix, key)?;
        if self.topics.len() >= MAX_KEYS {
            self.topics.clear();
        }
        self.topics.insert(Box::from(key), topic.clone());
        Ok(topic)
    }
}

#[derive(Default)]
struct Subscriptions {
    keys: HashSet<String>,
    declared: Vec<AdvancedSubscriber<()>>,
}

impl Hearing {
    fn heard(&self) -> std::sync::MutexGuard<'_, Heard> {
        self.heard.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn subscriptions(&self) -> std::sync::MutexGuard<'_, Subscriptions> {
        self.subscriptions.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Declares a subscriber on `key` that hands what it hears to the medium: it asks each
    /// publisher it did not hear from the start (there before it, or first heard later, as when a
    /// vehicle's link was lost while a publisher of its was made) for what that publisher keeps: a
    /// data publisher's latest sample (a late joiner gets the current state at once), a
    /// command-status publisher's last [`STATUS_HISTORY`] (a command's `pending` as well as its
    /// outcome). It counts on the medium, by topic, the samples a publisher's numbering says it
    /// missed (asking for them again while the publisher still has them).
    async fn declare(&self, session: &Session, key: String) {
        let me = self.clone();
        let declared = session
            .declare_subscriber(key.clone())
            .history(
                HistoryConfig::default()
                    .detect_late_publishers()
                    .max_samples(STATUS_HISTORY),
            )
            .recovery(RecoveryConfig::default().heartbeat())
            .subscriber_detection()
            .allowed_origin(Locality::Remote)
            .callback(move |sample| me.receive(&sample))
            .await;
        let sub = match declared {
            Ok(s) => s,
            Err(e) => {
                return self
                    .ingress
                    .set_link(LinkState::Down(format!("cannot subscribe to {key}: {e}")));
            }
        };
        let me = self.clone();
        let listened = sub
            .sample_miss_listener()
            .callback(move |miss| me.missed(&miss))
            .background()
            .await;
        if let Err(e) = listened {
            tracing::warn!(key, "missed samples of {key} will not be counted: {e}");
        }
        self.subscriptions().declared.push(sub);
    }

    /// Samples a publisher sent and this medium never got: counted under the publisher's topic.
    fn missed(&self, miss: &Miss) {
        let topic = self.heard().sources.get(&miss.source()).cloned();
        let topic = topic
            .as_ref()
            .map_or("(a publisher not heard yet)", Topic::as_str);
        self.ingress.missed(topic, u64::from(miss.nb()));
    }

    /// Declares the subscribers asked for before the session opened.
    async fn declare_pending(&self, session: &Session) {
        let keys: Vec<String> = self.subscriptions().keys.iter().cloned().collect();
        for key in keys {
            self.declare(session, key).await;
        }
    }

    /// Hands a sample to the medium, or counts why it cannot be.
    fn receive(&self, sample: &Sample) {
        if let Err((reason, why)) = read_sample(sample, self) {
            self.ingress.reject(
                reason,
                format_args!("sample on {}: {why}", sample.key_expr()),
            );
        }
    }
}

/// Opens a Zenoh medium: the session opens in the background (the link is down until it has).
fn open(mut o: Opening) -> Result<Arc<ZenohTransport>, OpenError> {
    let cfg = ZenohConfig::from_url(&mut o.url)?;
    let zconfig = cfg.zenoh().map_err(|e| OpenError::Url(o.url.error(e)))?;
    let (tx, rx) = watch::channel(None);
    let prefix: Arc<str> = Arc::from(cfg.prefix.as_str());
    let sender = fastrand::u64(1..);
    let own_status = (cfg.prefix == cfg.fleet)
        .then(|| Arc::from(format!("{}/{}", cfg.fleet, o.node.name).as_str()));
    let transport = Arc::new(ZenohTransport {
        name: o.name.clone(),
        prefix: prefix.clone(),
        own_status,
        json: cfg.json,
        sender,
        caps: cfg.capabilities(),
        session: rx,
        opened: Arc::default(),
        outlets: Mutex::default(),
        overrides: RwLock::new(Vec::new()),
        hearing: Hearing {
            prefix,
            sender,
            ingress: o.ingress.clone(),
            subscriptions: Arc::default(),
            fleet: fleet::Fleet::new(&cfg.fleet, o.ingress.clone()),
            heard: Arc::default(),
        },
    });
    o.ingress
        .init_link(LinkState::Down("the Zenoh session is opening".to_string()));
    let hearing = transport.hearing.clone();
    let router = cfg.mode == "router";
    let token = format!("{}/{}", cfg.fleet, o.node.name);
    let members = transport.hearing.fleet.clone();
    let opened = transport.opened.clone();
    // The session's task is not aborted when the medium closes: a Zenoh session dropped while it
    // opens would keep what it had bound. It ends by itself, closing the session, once the
    // medium is closed.
    tokio::spawn(async move {
        let Some(session) = open_session(zconfig, &hearing.ingress).await else {
            return;
        };
        if hearing.ingress.is_open() {
            let _ = opened.set(session.clone());
            let _ = tx.send(Some(session.clone()));
            hearing.declare_pending(&session).await;
            // (held while the session lasts: dropped, it tells the fleet this node is gone)
            let _membership = members.join(&session, &token).await;
            watch_link(&session, &hearing.ingress, router, &members).await;
        }
        let _ = session.close().await;
    });
    Ok(transport)
}

/// Opens the session, trying again while it cannot be (a client started before its router, a
/// port still held): the link says why meanwhile, logged once. `None` once the medium is closed.
async fn open_session(config: Config, ingress: &Ingress) -> Option<Session> {
    let mut wait = Duration::from_millis(250);
    let mut said = false;
    loop {
        match zenoh::open(config.clone()).await {
            Ok(s) => return Some(s),
            Err(e) => {
                let why = e.to_string();
                let why = why.split(" at /").next().unwrap_or(&why).trim().to_string();
                let down = LinkState::Down(format!(
                    "cannot open the Zenoh session (trying again): {why}"
                ));
                if said {
                    ingress.init_link(down);
                } else {
                    ingress.set_link(down);
                    said = true;
                }
            }
        }
        if !ingress.is_open() {
            return None;
        }
        tokio::time::sleep(wait).await;
        wait = (wait * 2).min(Duration::from_secs(4));
    }
}

/// Keeps the link state: up while connected to a router or a peer (a router is up by itself).
/// Waiting for the first connection is no alarm; losing one is.
/// Every [`fleet::EVERY`] it also says who is in the fleet.
async fn watch_link(session: &Session, ingress: &Ingress, router: bool, members: &fleet::Fleet) {
    let (mut was_up, mut waiting) = (false, false);
    let mut ticks = 0u32;
    loop {
        ticks = ticks.wrapping_add(1);
        if ticks.is_multiple_of(fleet::EVERY_TICKS) {
            members.announce_all();
        }
        let connected = router
            || session.info().routers_zid().await.next().is_some()
            || session.info().peers_zid().await.next().is_some();
        if connected {
            ingress.set_link(LinkState::Up);
            was_up = true;
        } else {
            let down = LinkState::Down("no Zenoh router or peer connected".to_string());
            if was_up {
                ingress.set_link(down);
            } else if !waiting {
                ingress.init_link(down);
                waiting = true;
            }
        }
        if !ingress.is_open() {
            return;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

impl ZenohTransport {
    /// The open session, waiting for it to open at most [`OPEN_WAIT`].
    async fn session(&self) -> Result<&Session, SendError> {
        // (once open, no timer and no lock: the session is taken as it is)
        if let Some(s) = self.opened.get() {
            return Ok(s);
        }
        let mut rx = self.session.clone();
        let got = tokio::time::timeout(OPEN_WAIT, rx.wait_for(Option::is_some)).await;
        match (got, self.opened.get()) {
            (Ok(Ok(_)), Some(s)) => Ok(s),
            _ => Err(SendError::LinkDown {
                medium: self.name.to_string(),
                reason: "the Zenoh session is not open".to_string(),
            }),
        }
    }

    /// How a message of `kind` on `topic` is sent: the first quality of service declared for it
    /// over its kind's.
    fn qos_of(&self, topic: &Topic, kind: Kind) -> SendQos {
        let command = kind == Kind::Command || answers_commands(topic);
        let overrides = self.overrides.read().unwrap_or_else(|p| p.into_inner());
        let declared = overrides
            .iter()
            .find(|(p, k, _)| k.is_none_or(|k| k == kind) && p.matches(topic))
            .map_or_else(Qos::default, |(_, _, q)| *q);
        SendQos::of(declared, command)
    }

    fn outlets(&self) -> std::sync::MutexGuard<'_, Outlets> {
        self.outlets.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The outlet of `topic` for `kind`: made with the first message, kept (at most
    /// [`MAX_PUBLISHERS`]).
    fn outlet(&self, topic: &Topic, kind: Kind) -> Result<Arc<Outlet>, SendError> {
        let command = kind == Kind::Command;
        if let Some(o) = self.outlets()[usize::from(command)].get(topic) {
            return Ok(o.clone());
        }
        // on the whole fleet's key space, the first segment names a node: seabus's own status
        // goes under this node's name, never as a node called `seabus`
        let base = match &self.own_status {
            Some(own) if topic.as_str().starts_with("seabus.") => own,
            _ => &self.prefix,
        };
        let key = keys::topic_key(base, topic).map_err(|e| self.send_error(e))?;
        let qos = self.qos_of(topic, kind);
        let mut outlets = self.outlets();
        let kept = outlets[0].len() + outlets[1].len() < MAX_PUBLISHERS;
        let outlet = Arc::new(Outlet {
            key,
            command,
            qos,
            kept,
            history: if answers_commands(topic) {
                STATUS_HISTORY
            } else {
                1
            },
            publisher: tokio::sync::OnceCell::new(),
        });
        if kept {
            outlets[usize::from(command)].insert(topic.clone(), outlet.clone());
        }
        Ok(outlet)
    }

    fn send_error(&self, reason: impl std::fmt::Display) -> SendError {
        SendError::Io {
            medium: self.name.to_string(),
            reason: reason.to_string(),
        }
    }
}

/// Why a sample was dropped: a reason to count under, and what was wrong.
type Dropped = (&'static str, String);

/// Reads a sample: a seabus datagram (its own are skipped), a datamap seabus sent as JSON, or
/// what a program that is not seabus sent.
fn read_sample(sample: &Sample, hearing: &Hearing) -> Result<(), Dropped> {
    let (prefix, me, ingress) = (&*hearing.prefix, hearing.sender, &hearing.ingress);
    let bytes = Bytes::from(sample.payload().to_bytes().into_owned());
    let encoding = sample.encoding();
    let datagram = *encoding == *DATAGRAM;
    // (one lock for what samples share: the key's topic, the publisher's, the datagram's origin)
    let (topic, decoded) = {
        let mut heard = hearing.heard();
        let topic = heard
            .topic(prefix, sample.key_expr().as_str())
            .map_err(|e| ("bad-key", e.to_string()))?;
        if let Some(info) = sample.source_info()
            && !heard.sources.contains_key(info.source_id())
        {
            if heard.sources.len() >= MAX_SOURCES {
                heard.sources.clear();
            }
            heard.sources.insert(*info.source_id(), topic.clone());
        }
        let decoded = datagram.then(|| datagram::decode(&bytes, &mut heard.origins));
        (topic, decoded)
    };
    if let Some(decoded) = decoded {
        let (sender, mut msg) = decoded.map_err(|e| (e.kind(), e.to_string()))?;
        if sender != me {
            hearing.fleet.heard(&msg);
            msg.topic = topic;
            ingress.deliver(msg);
        }
        return Ok(());
    }
    let json = *encoding == Encoding::APPLICATION_JSON
        || encoding.to_string().starts_with("application/json");
    // a datamap sent as JSON by seabus: its provenance in the attachment
    if let Some(att) = sample.attachment() {
        let att = Bytes::from(att.to_bytes().into_owned());
        let decoded = datagram::decode(&att, &mut hearing.heard().origins);
        if let Ok((sender, mut msg)) = decoded {
            if sender == me {
                return Ok(());
            }
            let text = std::str::from_utf8(&bytes).map_err(|e| ("bad-json", e.to_string()))?;
            let map =
                seabus_medium::json::from_json(text).map_err(|e| ("bad-json", e.to_string()))?;
            msg.topic = topic;
            msg.payload = Payload::from(map);
            ingress.deliver(msg);
            return Ok(());
        }
    }
    // a program that is not seabus
    let kind = if encoding.to_string().ends_with(";command") {
        Kind::Command
    } else {
        Kind::Data
    };
    let payload = match std::str::from_utf8(&bytes) {
        Ok(text) if json || text.trim_start().starts_with('{') => {
            match seabus_medium::json::from_json(text) {
                Ok(map) => Payload::from(map),
                Err(e) if json => return Err(("bad-json", e.to_string())),
                Err(_) => Payload::Bytes(bytes),
            }
        }
        _ => Payload::Bytes(bytes),
    };
    ingress.originate_as(kind, topic, payload);
    Ok(())
}

impl Transport for ZenohTransport {
    type Frame = Frame;

    fn capabilities(&self) -> Capabilities {
        self.caps
    }

    fn encode(&self, msg: &Message) -> Result<Frame, SendError> {
        let outlet = self.outlet(&msg.topic, msg.kind)?;
        if self.json
            && let Payload::Map(map) = &msg.payload
        {
            let text = seabus_medium::json::to_json(map).map_err(|e| self.send_error(e))?;
            let mut header = msg.clone();
            header.payload = Payload::Bytes(Bytes::new());
            let attachment =
                datagram::encode(&header, self.sender).map_err(|e| self.send_error(e))?;
            return Ok(Frame {
                outlet,
                payload: Bytes::from(text),
                attachment: Some(attachment),
            });
        }
        let payload = datagram::encode(msg, self.sender).map_err(|e| self.send_error(e))?;
        Ok(Frame {
            outlet,
            payload,
            attachment: None,
        })
    }

    fn transmit(&self, frame: Frame) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(async move {
            let session = self.session().await?;
            let encoding = if frame.attachment.is_some() {
                Encoding::APPLICATION_JSON
            } else {
                DATAGRAM.clone()
            };
            let o = &frame.outlet;
            let (payload, attachment) = (ZBytes::from(frame.payload), frame.attachment);
            let attachment = attachment.map(ZBytes::from);
            let publisher = if o.kept {
                let declared = o.publisher.get_or_try_init(|| declare(session, o)).await;
                Some(declared.map_err(|e| self.send_error(e))?)
            } else {
                None
            };
            let put = match publisher {
                Some(Publishing::Data(p)) => {
                    p.put(payload)
                        .encoding(encoding)
                        .attachment(attachment)
                        .await
                }
                Some(Publishing::Command(p)) => {
                    p.put(payload)
                        .encoding(encoding)
                        .attachment(attachment)
                        .await
                }
                None => {
                    session
                        .put(o.key.as_str(), payload)
                        .encoding(encoding)
                        .attachment(attachment)
                        .congestion_control(o.qos.congestion)
                        .priority(o.qos.priority)
                        .express(o.qos.express)
                        .await
                }
            };
            put.map_err(|e| self.send_error(format!("publishing on {}: {e}", o.key)))
        })
    }

    fn subscribed(&self, pattern: &Pattern) {
        let key = match keys::pattern_key(&self.prefix, pattern) {
            Ok(k) => k,
            Err(e) => {
                self.hearing.ingress.reject("bad-pattern", e);
                return;
            }
        };
        let fresh = self.hearing.subscriptions().keys.insert(key.clone());
        // (before the session opens, it declares what was asked for when it does)
        let session = self.session.borrow().clone();
        if let (true, Some(session)) = (fresh, session) {
            let hearing = self.hearing.clone();
            tokio::spawn(async move { hearing.declare(&session, key).await });
        }
    }

    fn set_qos(&self, pattern: &Pattern, kind: Option<Kind>, qos: Qos) {
        let mut overrides = self.overrides.write().unwrap_or_else(|p| p.into_inner());
        let declared = (pattern.clone(), kind, qos);
        if !overrides.contains(&declared) {
            overrides.push(declared);
            // each topic's outlet is made again with the first message after, its publisher
            // declared with what now holds for it
            *self.outlets() = Outlets::default();
        }
    }

    fn close(&self) {
        self.hearing.subscriptions().declared.clear();
        // (a session still opening is closed by its task when it has opened)
        if let Some(session) = self.session.borrow().clone() {
            tokio::spawn(async move {
                let _ = session.close().await;
            });
        }
    }
}
