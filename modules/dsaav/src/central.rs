//! Every seabus module logging through the DSAAV logging service.
//!
//! seabus code logs with `tracing` (`tracing::warn!("…")`). A program installs [`layer`] beside
//! its own output (the `seabus` command does); it stays idle until a running system with a
//! `<log medium="n1" port="100"/>` element ([`LOG`], a service of the runtime) attaches a
//! [`Forwarder`]. From then on every event of
//! the seabus crates becomes a record of the central log:
//!
//! - its **component** is the event's `component` (or `module`) field when it has one, else the module whose
//!   task logged it (the runtime runs each module inside a [`MODULE_SPAN`] span naming it), else
//!   the system's node name;
//! - its **level**: ERROR → ERROR, WARN → WARNING, INFO → INFO, DEBUG → DEBUG; events with the
//!   target [`DATA_TARGET`] (`tracing::info!(target: "data", …)`) are DATA, sent unreliably. TRACE
//!   stays local;
//! - its **text** is the message followed by the event's other fields (`key=value`); its time is
//!   when the event happened, not when it was sent.
//!
//! The forwarder finds the configuration server by broadcast, asks it where each component's
//! logging server is (`[Logging] Server`, or `Logging.Server` in the component's section) and at
//! which level the component logs (`Logging.LogLevel`, else `[Logging] LogLevel`, else INFO); it
//! asks again every [`REFRESH`], so a level changed at run time (`put` into the application data)
//! takes effect within that. Records below a component's level are not sent.
//!
//! Logging never holds a module up: events go into a queue of [`QUEUE`] records and when the queue
//! is full (the logging server is slow or gone) the newest are dropped and counted
//! ([`dropped`]); records the server never acknowledges are counted too ([`failed`]).

use super::config_service::ConfigClient;
use super::logging::{Level, Recipient, level_from_service};
use super::rpc::{CallOptions, RpcClient};
use seabus_medium::xml::{Element, FileError};
use seabus_medium::{BoxFuture, Medium, Node, Stamp};
use seabus_medium_dsaav::wire::Address;
use seabus_modules::system::SystemSpec;
use seabus_modules::{Registry, Service, ServiceType};
use std::collections::BTreeMap;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::mpsc;
use tracing::field::{Field, Visit};
use tracing::{Event, Metadata, Subscriber};
use tracing_subscriber::Layer;
use tracing_subscriber::filter::{FilterFn, LevelFilter};
use tracing_subscriber::layer::{Context, Filter};
use tracing_subscriber::registry::LookupSpan;

pub use seabus_modules::runtime::MODULE_SPAN;
/// The target that marks an event as a DATA record.
pub const DATA_TARGET: &str = "data";
/// Records waiting to be sent, at most.
pub const QUEUE: usize = 4096;
/// How often each component's logging server and level are asked again.
pub const REFRESH: Duration = Duration::from_secs(5);
/// The forwarder's own span: events inside it are never forwarded (no record about a record).
const FORWARDER_SPAN: &str = "seabus-log-forwarder";

/// One event on its way to the central log.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// When it happened, seconds since 1970.
    pub time: f64,
    /// Its level.
    pub level: Level,
    /// The component it names, if any; else the module or the node.
    pub component: Option<String>,
    /// The message and the other fields.
    pub text: String,
}

/// The attached forwarder's queue, with the number of the forwarder it belongs to.
static SINK: Mutex<Option<(u64, mpsc::Sender<Record>)>> = Mutex::new(None);
static ATTACHED: AtomicBool = AtomicBool::new(false);
static NEXT: AtomicU64 = AtomicU64::new(1);
static DROPPED: AtomicU64 = AtomicU64::new(0);
static FAILED: AtomicU64 = AtomicU64::new(0);

fn sink() -> Option<mpsc::Sender<Record>> {
    let s = SINK.lock().unwrap_or_else(|p| p.into_inner());
    s.as_ref().map(|(_, tx)| tx.clone())
}

fn attached() -> bool {
    ATTACHED.load(Ordering::Relaxed)
}

/// Attaches forwarder `n`'s queue, or detaches forwarder `n` (and only it: a newer one stays).
fn set_sink(n: u64, tx: Option<mpsc::Sender<Record>>) {
    {
        let mut s = SINK.lock().unwrap_or_else(|p| p.into_inner());
        match tx {
            Some(tx) => *s = Some((n, tx)),
            None if s.as_ref().is_some_and(|(m, _)| *m == n) => *s = None,
            None => return,
        }
        ATTACHED.store(s.is_some(), Ordering::Relaxed);
    }
    // the filter's answers depend on whether a forwarder is attached
    tracing::callsite::rebuild_interest_cache();
}

/// Records dropped because the queue was full, since the program started.
pub fn dropped() -> u64 {
    DROPPED.load(Ordering::Relaxed)
}

/// Records the logging server did not acknowledge, since the program started.
pub fn failed() -> u64 {
    FAILED.load(Ordering::Relaxed)
}

/// The layer that hands seabus events to the attached forwarder; idle while none is attached.
pub fn layer<S>() -> impl Layer<S>
where
    S: Subscriber + for<'a> LookupSpan<'a>,
{
    Central.with_filter(filter())
}

/// Which events the layer takes: spans always (they name the modules), events of the seabus
/// crates up to DEBUG and DATA events while a forwarder is attached.
fn filter<S>() -> impl Filter<S> {
    FilterFn::new(|meta: &Metadata<'_>| {
        meta.is_span()
            || (*meta.level() <= tracing::Level::DEBUG
                && (meta.target().starts_with("seabus") || meta.target() == DATA_TARGET)
                && attached())
    })
    .with_max_level_hint(LevelFilter::DEBUG)
}

struct Central;

/// What a span tells the layer: the module it runs, or that it is the forwarder.
enum SpanRole {
    Module(String),
    Forwarder,
}

#[derive(Default)]
struct Fields {
    message: String,
    component: Option<String>,
    name: Option<String>,
    rest: String,
}

impl Visit for Fields {
    fn record_str(&mut self, field: &Field, value: &str) {
        match field.name() {
            "component" | "module" => self.component = Some(value.to_string()),
            "name" => self.name = Some(value.to_string()),
            "message" => self.message = value.to_string(),
            other => {
                let _ = write!(self.rest, " {other}={value}");
            }
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        match field.name() {
            "component" | "module" => self.component = Some(format!("{value:?}")),
            "name" => self.name = Some(format!("{value:?}")),
            "message" => self.message = format!("{value:?}"),
            other => {
                let _ = write!(self.rest, " {other}={value:?}");
            }
        }
    }
}

impl<S> Layer<S> for Central
where
    S: Subscriber + for<'a> LookupSpan<'a>,
{
    fn on_new_span(
        &self,
        attrs: &tracing::span::Attributes<'_>,
        id: &tracing::span::Id,
        ctx: Context<'_, S>,
    ) {
        let role = match attrs.metadata().name() {
            MODULE_SPAN => {
                let mut f = Fields::default();
                attrs.record(&mut f);
                f.name.map(SpanRole::Module)
            }
            FORWARDER_SPAN => Some(SpanRole::Forwarder),
            _ => None,
        };
        if let (Some(role), Some(span)) = (role, ctx.span(id)) {
            span.extensions_mut().insert(role);
        }
    }

    fn on_event(&self, event: &Event<'_>, ctx: Context<'_, S>) {
        let Some(tx) = sink() else {
            return;
        };
        let mut module = None;
        if let Some(scope) = ctx.event_scope(event) {
            for span in scope {
                match span.extensions().get::<SpanRole>() {
                    Some(SpanRole::Forwarder) => return,
                    Some(SpanRole::Module(m)) if module.is_none() => module = Some(m.clone()),
                    _ => {}
                }
            }
        }
        let meta = event.metadata();
        let level = if meta.target() == DATA_TARGET {
            Level::Data
        } else {
            match *meta.level() {
                tracing::Level::ERROR => Level::Error,
                tracing::Level::WARN => Level::Warning,
                tracing::Level::INFO => Level::Info,
                _ => Level::Debug,
            }
        };
        let mut f = Fields::default();
        event.record(&mut f);
        let mut text = f.message;
        if let Some(n) = f.name {
            // `name` means something only on a module's span
            let _ = write!(text, " name={n}");
        }
        text.push_str(&f.rest);
        let record = Record {
            time: Stamp::now().as_secs_f64(),
            level,
            component: f.component.or(module),
            text,
        };
        if tx.try_send(record).is_err() {
            DROPPED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Sends the records of this program to the central log while it lives; dropping it detaches it.
pub struct Forwarder {
    n: u64,
    task: Option<tokio::task::JoinHandle<()>>,
}

impl Forwarder {
    /// Attaches a forwarder sending from `port` of `medium`'s node; `node` names records that
    /// belong to no module. Replaces any forwarder attached before. Must be called inside a tokio
    /// runtime.
    pub fn attach(medium: &Medium, port: u16, node: &str) -> Forwarder {
        let (tx, rx) = mpsc::channel(QUEUE);
        let span = tracing::info_span!(FORWARDER_SPAN);
        let task = tokio::spawn(tracing::Instrument::instrument(
            forward(medium.clone(), port, node.to_string(), rx),
            span,
        ));
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        set_sink(n, Some(tx));
        Forwarder {
            n,
            task: Some(task),
        }
    }

    /// Detaches the forwarder and lets it send what is queued, for at most `within`.
    pub async fn finish(mut self, within: Duration) {
        set_sink(self.n, None);
        if let Some(mut task) = self.task.take()
            && tokio::time::timeout(within, &mut task).await.is_err()
        {
            task.abort();
        }
    }
}

impl Service for Forwarder {
    fn finish(self: Box<Self>, within: Duration) -> BoxFuture<'static, ()> {
        Box::pin(Forwarder::finish(*self, within))
    }
}

/// The port records are sent from when `<log>` gives none.
pub const DEFAULT_LOG_PORT: u16 = 100;

/// `<log medium="n1" port="100"/>`: every module of the system logs through the DSAAV logging
/// service reached on the DSAAV medium `medium`, from `port` of its node (default
/// [`DEFAULT_LOG_PORT`]). A system has one.
pub const LOG: ServiceType = ServiceType {
    tag: "log",
    check: check_log,
    start: start_log,
};

/// The medium and port of a `<log>`.
fn read_log(el: &Element) -> Result<(String, u16), FileError> {
    el.only_attrs(&["medium", "port"])?;
    el.only_children(&[])?;
    Ok((
        el.required("medium")?.value.trim().to_string(),
        el.parsed("port", "a port 0–65535")?
            .unwrap_or(DEFAULT_LOG_PORT),
    ))
}

fn check_log(el: &Element, spec: &SystemSpec, registry: &Registry) -> Result<(), FileError> {
    let (medium, _) = read_log(el)?;
    if let Some(first) = spec.sections.iter().find(|e| e.name == "log")
        && !std::ptr::eq(first, el)
    {
        return Err(el.error(format!(
            "a system has one <log>; the first is at line {}",
            first.pos.line
        )));
    }
    let m = spec.medium_at(&medium, &el.pos)?;
    if !registry.capabilities(&m.url, &m.pos)?.is_native("dsaav") {
        return Err(el.error(format!(
            "<log> sends to the DSAAV logging service: `{medium}` is not a DSAAV medium (dsaav+eth, dsaav+udp or dsaav+inproc)"
        )));
    }
    Ok(())
}

fn start_log(
    el: &Element,
    media: &BTreeMap<String, Medium>,
    node: &Node,
) -> Result<Box<dyn Service>, FileError> {
    let (medium, port) = read_log(el)?;
    let m = media
        .get(&medium)
        .ok_or_else(|| el.error(format!("no medium called `{medium}`")))?;
    Ok(Box::new(Forwarder::attach(m, port, &node.name)))
}

impl Drop for Forwarder {
    fn drop(&mut self) {
        set_sink(self.n, None);
        if let Some(task) = &self.task {
            task.abort();
        }
    }
}

/// Each component's logging server and level, as last asked.
struct Route {
    server: Address,
    level: Level,
    asked: tokio::time::Instant,
}

/// How the forwarder's calls wait: long enough for a loaded server, short enough that a dead one
/// costs little.
fn opts() -> CallOptions {
    CallOptions {
        timeout: Duration::from_secs(1),
        ..CallOptions::default()
    }
}

async fn forward(medium: Medium, port: u16, node: String, mut rx: mpsc::Receiver<Record>) {
    let cfg = {
        let mut wait = Duration::from_millis(100);
        loop {
            match ConfigClient::discover(&medium, port, opts()).await {
                Ok(c) => break c,
                Err(e) => {
                    tracing::warn!(
                        "central log: no configuration server yet ({e}); records wait, the newest dropped when {QUEUE} wait"
                    );
                    tokio::time::sleep(wait).await;
                    wait = (wait * 2).min(Duration::from_secs(5));
                }
            }
        }
    };
    let rpc = RpcClient::new(&medium, port);
    let mut routes: HashMap<String, Route> = HashMap::new();
    let mut unsent_log = seabus_medium::tally::Limiter::default();
    while let Some(rec) = rx.recv().await {
        let component = rec.component.unwrap_or_else(|| node.clone());
        let stale = routes
            .get(&component)
            .is_none_or(|r| r.asked.elapsed() >= REFRESH);
        if stale {
            match cfg.server_of(&component, "Logging").await {
                Ok(server) => {
                    let level = level_from_service(&cfg, &component).await;
                    routes.insert(
                        component.clone(),
                        Route {
                            server,
                            level,
                            asked: tokio::time::Instant::now(),
                        },
                    );
                }
                Err(e) if !routes.contains_key(&component) => {
                    FAILED.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!("central log: {component}: no logging server: {e}");
                    continue;
                }
                // the last answer stands while the configuration server does not answer
                Err(_) => {}
            }
        }
        let Some(route) = routes.get(&component) else {
            continue;
        };
        if rec.level > route.level {
            continue;
        }
        let to = Recipient {
            rpc: &rpc,
            server: route.server,
            opts: opts(),
        };
        if let Err(e) = to.send(&component, rec.time, rec.level, &rec.text).await {
            let n = FAILED.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(held) = unsent_log.admit(std::time::Instant::now()) {
                tracing::warn!(
                    "central log: record of {component} not logged ({n} so far): {e}{held}"
                );
            }
        }
    }
}
