//! Every seabus module logging through the DSAAV logging service.
//!
//! seabus code logs with `tracing`; the program installs [`seabus_modules::logs::layer`] (the
//! `seabus` command does). A running system with a `<log medium="n1" port="100"/>` element
//! ([`LOG`], a service of the runtime) attaches a [`Forwarder`], which takes the records of the
//! seabus crates ([`seabus_modules::logs`]) and sends each to the central log:
//!
//! - its **component** is the record's (the event's `component` field, else the module that
//!   logged it), else the system's node name;
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
//! Logging never holds a module up: records wait in a queue of [`QUEUE`] and when the queue
//! is full (the logging server is slow or gone) the newest are dropped and counted
//! ([`Forwarder::dropped`]); records the server never acknowledges are counted too ([`failed`]).

use super::config_service::ConfigClient;
use super::logging::{Level, Recipient, level_from_service};
use super::rpc::{CallOptions, RpcClient};
use seabus_medium::xml::{Element, FileError};
use seabus_medium::{BoxFuture, Medium, Node};
use seabus_medium_dsaav::wire::Address;
use seabus_modules::logs::{self, Capture, Record, Wants};
use seabus_modules::system::SystemSpec;
use seabus_modules::{Registry, Service, ServiceType};
use std::collections::BTreeMap;
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::oneshot;

pub use seabus_modules::logs::DATA_TARGET;
pub use seabus_modules::runtime::MODULE_SPAN;
/// Records waiting to be sent, at most.
pub const QUEUE: usize = 4096;
/// How often each component's logging server and level are asked again.
pub const REFRESH: Duration = Duration::from_secs(5);

static FAILED: AtomicU64 = AtomicU64::new(0);

/// Records the logging server did not acknowledge, since the program started.
pub fn failed() -> u64 {
    FAILED.load(Ordering::Relaxed)
}

/// The central log's level of a record.
fn level_of(rec: &Record) -> Level {
    if rec.data {
        return Level::Data;
    }
    match rec.level {
        tracing::Level::ERROR => Level::Error,
        tracing::Level::WARN => Level::Warning,
        tracing::Level::INFO => Level::Info,
        _ => Level::Debug,
    }
}

/// Sends the records of this program to the central log while it lives; dropping it detaches it.
pub struct Forwarder {
    stop: Option<oneshot::Sender<()>>,
    dropped: Arc<AtomicU64>,
    task: Option<tokio::task::JoinHandle<()>>,
}

impl Forwarder {
    /// Attaches a forwarder sending from `port` of `medium`'s node; `node` names records that
    /// belong to no module. Must be called inside a tokio runtime.
    pub fn attach(medium: &Medium, port: u16, node: &str) -> Forwarder {
        let capture = logs::attach(Wants {
            level: tracing::Level::DEBUG,
            targets: Wants::SEABUS,
            queue: QUEUE,
        });
        let dropped = capture.dropped_counter();
        let span = capture.span();
        let (stop, stopped) = oneshot::channel();
        let task = tokio::spawn(tracing::Instrument::instrument(
            forward(medium.clone(), port, node.to_string(), capture, stopped),
            span,
        ));
        Forwarder {
            stop: Some(stop),
            dropped,
            task: Some(task),
        }
    }

    /// Records dropped because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Detaches the forwarder and lets it send what is queued, for at most `within`.
    pub async fn finish(mut self, within: Duration) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
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
        // the task owns the capture: ending it detaches it
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

/// Takes one record, or none once the capture is detached (at `stop`) and emptied.
async fn next(capture: &mut Capture, stop: &mut Option<oneshot::Receiver<()>>) -> Option<Record> {
    loop {
        let Some(s) = stop.as_mut() else {
            return capture.recv().await;
        };
        tokio::select! {
            rec = capture.recv() => return rec,
            _ = s => {
                capture.detach();
                *stop = None;
            }
        }
    }
}

async fn forward(
    medium: Medium,
    port: u16,
    node: String,
    mut capture: Capture,
    stopped: oneshot::Receiver<()>,
) {
    let mut stop = Some(stopped);
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
    while let Some(rec) = next(&mut capture, &mut stop).await {
        let component = rec.component.clone().unwrap_or_else(|| node.clone());
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
        let level = level_of(&rec);
        if level > route.level {
            continue;
        }
        let to = Recipient {
            rpc: &rpc,
            server: route.server,
            opts: opts(),
        };
        if let Err(e) = to
            .send(&component, rec.time.as_secs_f64(), level, &rec.text)
            .await
        {
            let n = FAILED.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(held) = unsent_log.admit(std::time::Instant::now()) {
                tracing::warn!(
                    "central log: record of {component} not logged ({n} so far): {e}{held}"
                );
            }
        }
    }
}
