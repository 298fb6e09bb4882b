//! The runtime (the DSAAV "container"): opens a system's media, starts its modules and bridges,
//! delivers their messages and timer ticks, restarts a failed module with back-off, and shuts
//! everything down within [`SHUTDOWN_GRACE`] plus a little.
//!
//! Each module runs on its own task under a supervisor. A module fails when a handler returns an
//! error or panics; the supervisor reports it (log, and a `seabus.module.<name>` status message on
//! the default medium), waits (100 ms, doubling up to 30 s; reset after a minute of good running) and
//! builds a fresh instance with fresh ports.
//!
//! The runtime also publishes every medium's counters ([`MediumStats`], each as
//! [`MediumStats::to_map`]) on [`MEDIA_TOPIC`] on the default medium, at most once every
//! [`MEDIA_EVERY`] and only when what a medium read or lost changed since (received, rejected,
//! bytes dropped, overruns, queue drops, commands refused): a system with no traffic publishes
//! nothing. The health monitor lists the media with losses from it, and any spy sees it.

use crate::datasets::Catalogue;
use crate::module::{Context, Event, Module, ModuleError, TICK};
use crate::registry::{Built, Registry, Service};
use crate::system::{SystemSpec, check};
use seabus_medium::xml::{FileError, Pos};
use seabus_medium::{DataMap, Interface, Kind, Medium, MediumStats, Node, Value};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// How long modules get to stop before they are cut off.
pub const SHUTDOWN_GRACE: Duration = Duration::from_millis(1500);
/// First wait before restarting a failed module.
pub const FIRST_BACKOFF: Duration = Duration::from_millis(100);
/// Longest wait before restarting a failed module.
pub const MAX_BACKOFF: Duration = Duration::from_secs(30);
/// Running this long without failing resets the back-off.
pub const STABLE: Duration = Duration::from_secs(60);
/// The topic every medium's counters are published on (dataset `media-stats`).
pub const MEDIA_TOPIC: &str = "seabus.media";
/// How often, at most, every medium's counters are published.
pub const MEDIA_EVERY: Duration = Duration::from_secs(1);
/// The name of the span the runtime runs each module in; its field `name` is the module's name
/// (log layers name the module an event came from by it).
pub const MODULE_SPAN: &str = "module";

/// A module's state as the runtime sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// Being built and started.
    Starting,
    /// Running.
    Running,
    /// Failed; will be restarted.
    Failed,
    /// Stopped at shutdown.
    Stopped,
}

impl State {
    /// The state's name.
    pub fn name(self) -> &'static str {
        match self {
            State::Starting => "starting",
            State::Running => "running",
            State::Failed => "failed",
            State::Stopped => "stopped",
        }
    }
}

/// What the runtime knows of one module.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnitStatus {
    /// The module's name.
    pub name: String,
    /// Its type.
    pub type_name: String,
    /// Its state.
    pub state: State,
    /// Restarts so far.
    pub restarts: u32,
    /// The last failure.
    pub error: Option<String>,
}

/// Something the runtime runs: a module or a bridge, and how to build a fresh instance of it.
#[derive(Clone)]
pub struct Unit {
    /// Its name.
    pub name: String,
    /// Its type.
    pub type_name: String,
    /// Its media, one port each.
    pub media: Vec<String>,
    /// Period of timer [`TICK`].
    pub tick: Option<Duration>,
    /// Builds a fresh instance.
    pub build: Arc<dyn Fn() -> Result<Built, FileError> + Send + Sync>,
}

struct Shared {
    node: Node,
    catalogue: Arc<Catalogue>,
    media: BTreeMap<String, Medium>,
    board: Mutex<BTreeMap<String, UnitStatus>>,
    status_port: Interface,
}

impl Shared {
    async fn report(&self, unit: &Unit, state: State, restarts: u32, error: Option<String>) {
        let status = UnitStatus {
            name: unit.name.clone(),
            type_name: unit.type_name.clone(),
            state,
            restarts,
            error: error.clone(),
        };
        self.board
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(unit.name.clone(), status);
        let mut map = DataMap::new()
            .with("module", unit.name.as_str())
            .with("type", unit.type_name.as_str())
            .with("state", state.name())
            .with("restarts", i64::from(restarts));
        if let Some(e) = error {
            map.insert("error", e);
        }
        let topic = format!("seabus.module.{}", unit.name);
        if let Err(e) = self.status_port.send(topic, map).await {
            tracing::debug!("module status not published: {e}");
        }
    }
}

/// A running system.
pub struct Runtime {
    shared: Arc<Shared>,
    order: Vec<String>,
    supervisors: Vec<(String, JoinHandle<()>)>,
    shutdown: watch::Sender<bool>,
    /// The services the system's sections started, in order.
    services: Vec<Box<dyn Service>>,
    /// Publishes the media's counters (stopped with the runtime, however it ends).
    media_task: AbortOnDrop,
}

fn open_error(pos: &Pos, e: impl std::fmt::Display) -> FileError {
    pos.error(e.to_string())
}

impl Runtime {
    /// Checks `spec`, opens its media and starts its modules and bridges.
    /// Must be called inside a tokio runtime.
    pub async fn start(
        spec: &SystemSpec,
        registry: &Registry,
        catalogue: Arc<Catalogue>,
    ) -> Result<Runtime, FileError> {
        let report = check(spec, registry, &catalogue)?;
        for w in &report.warnings {
            tracing::warn!("{w}");
        }
        let node = spec.node.as_deref().map_or_else(Node::local, Node::new);
        let mut media = BTreeMap::new();
        for m in &spec.media {
            let medium = registry
                .schemes()
                .open(&m.name, &m.url, &node)
                .map_err(|e| open_error(&m.pos, e))?;
            media.insert(m.name.clone(), medium);
        }
        let mut units = Vec::new();
        for m in &spec.modules {
            let (cfg, reg, cat) = (m.clone(), registry.clone(), catalogue.clone());
            units.push(Unit {
                name: m.name.clone(),
                type_name: m.type_name.clone(),
                media: m.media.clone(),
                tick: m.tick,
                build: Arc::new(move || reg.build_module(&cfg, &cat)),
            });
        }
        for b in &spec.bridges {
            let (bs, reg, cat) = (b.clone(), registry.clone(), catalogue.clone());
            units.push(Unit {
                name: b.name.clone(),
                type_name: format!("bridge/{}", b.type_name),
                media: b.media.to_vec(),
                tick: None,
                build: Arc::new(move || reg.build_bridge(&bs, &cat)),
            });
        }
        // started before any module, so that a service that follows them (the central log)
        // misses nothing
        let mut services = Vec::new();
        for el in &spec.sections {
            if let Some(t) = registry.service(&el.name) {
                services.push((t.start)(el, &media, &node)?);
            }
        }
        // status goes to the first medium whose peers are seabus programs
        let status = spec
            .media
            .iter()
            .map(|m| m.name.as_str())
            .find(|n| media.get(*n).is_some_and(|m| m.capabilities().provenance))
            .unwrap_or(spec.default_medium())
            .to_string();
        let mut runtime = Runtime::with_units(node, media, &status, units, catalogue);
        runtime.services = services;
        Ok(runtime)
    }

    /// Starts `units` on already opened `media`; status (`seabus.module.*`, `seabus.media`) goes
    /// to the medium called `default` when its peers are seabus programs (its wire carries
    /// seabus's provenance: the in-process bus, UDP, Zenoh), and nowhere else: seabus puts none of
    /// its own traffic on a bus whose peers are not seabus (LCM, MOOS, CAN, a serial line, DSAAV).
    /// ([`Runtime::start`] gives it the first medium of the system that has such peers.)
    pub fn with_units(
        node: Node,
        media: BTreeMap<String, Medium>,
        default: &str,
        units: Vec<Unit>,
        catalogue: Arc<Catalogue>,
    ) -> Runtime {
        let status_port = match media.get(default) {
            Some(m) if m.capabilities().provenance => m.attach("runtime"),
            Some(m) => {
                tracing::info!(
                    "module states and media counters are not published: no medium of the \
                     system has seabus programs for peers (`{}`, {}, reads only its own \
                     messages)",
                    m.name(),
                    m.url()
                );
                Medium::in_process("runtime", &node).attach("runtime")
            }
            None => Medium::in_process("runtime", &node).attach("runtime"),
        };
        let shared = Arc::new(Shared {
            node,
            catalogue,
            media,
            board: Mutex::new(BTreeMap::new()),
            status_port,
        });
        let (shutdown, _) = watch::channel(false);
        let media_task = AbortOnDrop(tokio::spawn(publish_media(shared.clone())).abort_handle());
        let mut supervisors = Vec::new();
        let mut order = Vec::new();
        for unit in units {
            order.push(unit.name.clone());
            let name = unit.name.clone();
            let task = tokio::spawn(supervise(unit, shared.clone(), shutdown.subscribe()));
            supervisors.push((name, task));
        }
        Runtime {
            shared,
            order,
            supervisors,
            shutdown,
            services: Vec::new(),
            media_task,
        }
    }

    /// The node this system runs as.
    pub fn node(&self) -> &Node {
        &self.shared.node
    }

    /// The medium called `name`.
    pub fn medium(&self, name: &str) -> Option<&Medium> {
        self.shared.media.get(name)
    }

    /// Every medium, by name.
    pub fn media(&self) -> impl Iterator<Item = (&str, &Medium)> {
        self.shared.media.iter().map(|(k, v)| (k.as_str(), v))
    }

    /// The status of every module, in system-file order.
    pub fn status(&self) -> Vec<UnitStatus> {
        let board = self.shared.board.lock().unwrap_or_else(|p| p.into_inner());
        self.order
            .iter()
            .filter_map(|n| board.get(n).cloned())
            .collect()
    }

    /// Stops every module (each gets [`Module::stop`]), cuts off those still running after
    /// [`SHUTDOWN_GRACE`], and closes the media.
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        drop(self.media_task);
        let deadline = Instant::now() + SHUTDOWN_GRACE;
        for (name, mut task) in self.supervisors {
            if tokio::time::timeout_at(deadline, &mut task).await.is_err() {
                tracing::warn!(module = %name, "did not stop in time; cut off");
                task.abort();
            }
        }
        // what services still hold (the modules' last log records) goes out before the media close
        for s in self.services {
            s.finish(SHUTDOWN_GRACE).await;
        }
        for m in self.shared.media.values() {
            m.closing();
        }
        for m in self.shared.media.values() {
            m.close();
        }
    }
}

/// What a medium read and lost: what, when it changes, has the media's counters published again
/// (not what sending them changes: published, delivered, transmitted).
fn heard(s: &MediumStats) -> [u64; 6] {
    [
        s.received,
        s.rejected_total(),
        s.dropped_bytes,
        s.overruns,
        s.queue_dropped_total(),
        s.commands_refused,
    ]
}

/// Every medium's counters, by name, as [`MEDIA_TOPIC`] carries them.
pub fn media_map<'a>(media: impl IntoIterator<Item = (&'a str, &'a MediumStats)>) -> DataMap {
    let by_name: DataMap = media
        .into_iter()
        .map(|(name, st)| (name.to_string(), Value::Map(st.to_map())))
        .collect();
    DataMap::new().with("media", by_name)
}

/// Publishes the media's counters at most every [`MEDIA_EVERY`], when they changed.
async fn publish_media(shared: Arc<Shared>) {
    let mut every = tokio::time::interval(MEDIA_EVERY);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut last: Vec<[u64; 6]> = Vec::new();
    loop {
        every.tick().await;
        let now: Vec<(&str, MediumStats)> = shared
            .media
            .iter()
            .map(|(name, m)| (name.as_str(), m.stats()))
            .collect();
        let seen: Vec<[u64; 6]> = now.iter().map(|(_, s)| heard(s)).collect();
        if seen == last {
            continue;
        }
        last = seen;
        let map = media_map(now.iter().map(|(n, s)| (*n, s)));
        if let Err(e) = shared.status_port.send(MEDIA_TOPIC, map).await {
            tracing::debug!("media counters not published: {e}");
        }
    }
}

async fn supervise(unit: Unit, shared: Arc<Shared>, mut shutdown: watch::Receiver<bool>) {
    let mut restarts = 0u32;
    let mut backoff = FIRST_BACKOFF;
    loop {
        if *shutdown.borrow() {
            break;
        }
        shared.report(&unit, State::Starting, restarts, None).await;
        let started = Instant::now();
        // building, starting and running all happen on the module's own task, so that a panic
        // anywhere in them is a failure like any other
        let task = tokio::spawn({
            let (unit, shared, shutdown) = (unit.clone(), shared.clone(), shutdown.clone());
            let span = tracing::info_span!(MODULE_SPAN, name = %unit.name);
            tracing::Instrument::instrument(
                async move {
                    let (module, ctx) = instance(&unit, &shared)?;
                    shared.report(&unit, State::Running, restarts, None).await;
                    run(module, ctx, shutdown).await.map_err(|e| e.to_string())
                },
                span,
            )
        });
        // when the supervisor is cut off at shutdown, the module goes with it
        let _guard = AbortOnDrop(task.abort_handle());
        let outcome = match task.await {
            Ok(r) => r,
            Err(e) if e.is_panic() => Err(format!("panicked: {}", panic_text(e.into_panic()))),
            Err(_) => Err("cancelled".to_string()),
        };
        match outcome {
            Ok(()) => {
                shared.report(&unit, State::Stopped, restarts, None).await;
                tracing::debug!(module = %unit.name, "stopped");
                return;
            }
            Err(e) => {
                if *shutdown.borrow() {
                    shared
                        .report(&unit, State::Stopped, restarts, Some(e))
                        .await;
                    return;
                }
                if started.elapsed() >= STABLE {
                    backoff = FIRST_BACKOFF;
                }
                tracing::error!(module = %unit.name, "failed: {e}; restarting in {} ms", backoff.as_millis());
                shared.report(&unit, State::Failed, restarts, Some(e)).await;
                tokio::select! {
                    _ = tokio::time::sleep(backoff) => {}
                    _ = shutdown.changed() => {}
                }
                backoff = (backoff * 2).min(MAX_BACKOFF);
                restarts += 1;
            }
        }
    }
    shared.report(&unit, State::Stopped, restarts, None).await;
}

/// Aborts a task when dropped (a module's helper task goes with the module).
pub struct AbortOnDrop(pub tokio::task::AbortHandle);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// Builds a fresh module instance and its context: one port per medium, subscribed to the data
/// the module consumes and the commands it accepts, in the format it declared.
fn instance(unit: &Unit, shared: &Shared) -> Result<(Box<dyn Module>, Context), String> {
    let built = (unit.build)().map_err(|e| e.to_string())?;
    let mut ports = Vec::with_capacity(unit.media.len());
    for (i, name) in unit.media.iter().enumerate() {
        let medium = shared
            .media
            .get(name)
            .ok_or_else(|| format!("no medium called `{name}`"))?;
        let mut port = medium.attach(&unit.name);
        port.set_accept(built.decl.format_of(i));
        let wanted = [
            (&built.decl.consumes, Kind::Data),
            (&built.decl.accepts, Kind::Command),
        ];
        for (decls, kind) in wanted {
            for t in decls.iter().filter(|t| t.port == i) {
                port.subscribe_kind(&t.topic, Some(kind))
                    .map_err(|e| format!("subscription `{}`: {e}", t.topic))?;
            }
        }
        ports.push(port);
    }
    let mut ctx = Context::new(
        &unit.name,
        shared.node.clone(),
        ports,
        shared.catalogue.clone(),
    );
    if let Some(t) = unit.tick.or(built.decl.tick) {
        ctx.every(TICK, t);
    }
    Ok((built.module, ctx))
}

async fn run(
    mut module: Box<dyn Module>,
    mut ctx: Context,
    mut shutdown: watch::Receiver<bool>,
) -> Result<(), ModuleError> {
    let body = async {
        module.start(&mut ctx).await?;
        loop {
            match ctx.next_event().await {
                Event::Message(port, msg) => module.on_message(&mut ctx, port, msg).await?,
                Event::Timer(id) => module.on_timer(&mut ctx, id).await?,
                Event::Closed => return Ok(()),
            }
        }
    };
    let result = tokio::select! {
        r = body => r,
        _ = shutdown.wait_for(|stop| *stop) => Ok(()),
    };
    module.stop(&mut ctx).await;
    result
}

fn panic_text(p: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = p.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = p.downcast_ref::<String>() {
        s.clone()
    } else {
        "a non-text panic".to_string()
    }
}
