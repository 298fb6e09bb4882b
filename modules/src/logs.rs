//! This program's own log, taken as records for the services that send it somewhere else.
//!
//! seabus code logs with `tracing` (`tracing::warn!("…")`). A program installs [`layer`] once,
//! beside its own output (the `seabus` command does). It stays idle until a service asks for
//! records with [`attach`] — the DSAAV central log's forwarder, the Foxglove live view's Log
//! panel — and from then on every event that service [`Wants`] becomes a [`Record`] in the
//! service's own bounded queue:
//!
//! - its **component** is the event's `component` (or `module`) field when it has one, else the
//!   module whose task logged it (the runtime runs each module inside a [`MODULE_SPAN`] span
//!   naming it), else none (the service names it after its node);
//! - its **level** is the event's; events with the target [`DATA_TARGET`]
//!   (`tracing::info!(target: "data", …)`) are marked [`Record::data`];
//! - its **text** is the message followed by the event's other fields (`key=value`); its time is
//!   when the event happened, not when it was taken.
//!
//! Logging never holds a module up: when a service's queue is full (it is slow, or what it sends
//! to is gone) the newest records are dropped and counted ([`Capture::dropped`]). Events logged
//! inside a capture's own [`Capture::span`] are never given back to it (no record about sending a
//! record).
//!
//! Who may depend on it: the services and live views that send this program's log elsewhere.

use crate::runtime::MODULE_SPAN;
use seabus_medium::Stamp;
use std::fmt::Write as _;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::mpsc;
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Metadata, Subscriber};
use tracing_subscriber::Layer;
use tracing_subscriber::filter::{FilterFn, LevelFilter};
use tracing_subscriber::layer::{Context, Filter};
use tracing_subscriber::registry::LookupSpan;

/// The target that marks an event as data rather than a message (a DATA record of the central
/// log).
pub const DATA_TARGET: &str = "data";
/// The span a capture's own work runs in.
const SINK_SPAN: &str = "seabus-log-sink";

/// One event of this program's log.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// When it happened.
    pub time: Stamp,
    /// Its level.
    pub level: Level,
    /// Logged with the target [`DATA_TARGET`].
    pub data: bool,
    /// The component it names, if any, else the module whose task logged it.
    pub component: Option<String>,
    /// Where it was logged (the event's target: the crate and module of the code, or `data`).
    pub target: String,
    /// The source file and line that logged it, when known.
    pub file: Option<(&'static str, u32)>,
    /// The message and the other fields.
    pub text: String,
}

/// Which events a capture takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wants {
    /// The most detailed level taken (`DEBUG` takes ERROR to DEBUG).
    pub level: Level,
    /// Events whose target starts with one of these are taken; [`Wants::SEABUS`] are seabus's
    /// own crates and data.
    pub targets: &'static [&'static str],
    /// Records waiting to be taken, at most.
    pub queue: usize,
}

impl Wants {
    /// The targets of seabus's own crates, and data.
    pub const SEABUS: &'static [&'static str] = &["seabus", DATA_TARGET];

    fn takes(&self, meta: &Metadata<'_>) -> bool {
        *meta.level() <= self.level && self.targets.iter().any(|t| meta.target().starts_with(t))
    }
}

/// An attached capture, as the layer sees it.
struct Sink {
    id: u64,
    wants: Wants,
    tx: mpsc::Sender<Record>,
    dropped: Arc<AtomicU64>,
}

static SINKS: Mutex<Vec<Sink>> = Mutex::new(Vec::new());
static ANY: AtomicBool = AtomicBool::new(false);
static NEXT: AtomicU64 = AtomicU64::new(1);

fn sinks() -> std::sync::MutexGuard<'static, Vec<Sink>> {
    SINKS.lock().unwrap_or_else(|p| p.into_inner())
}

/// Changes the attached captures, then lets the layer's filter answer anew.
fn change(f: impl FnOnce(&mut Vec<Sink>)) {
    {
        let mut s = sinks();
        f(&mut s);
        ANY.store(!s.is_empty(), Ordering::Relaxed);
    }
    tracing::callsite::rebuild_interest_cache();
}

/// A service's share of this program's log: records come out of [`Capture::recv`] until it is
/// dropped, which detaches it.
#[derive(Debug)]
pub struct Capture {
    id: u64,
    rx: mpsc::Receiver<Record>,
    dropped: Arc<AtomicU64>,
}

/// Starts taking the events `wants` names, alongside any other capture.
pub fn attach(wants: Wants) -> Capture {
    let (tx, rx) = mpsc::channel(wants.queue.max(1));
    let id = NEXT.fetch_add(1, Ordering::Relaxed);
    let dropped = Arc::new(AtomicU64::new(0));
    let sink = Sink {
        id,
        wants,
        tx,
        dropped: dropped.clone(),
    };
    change(|s| s.push(sink));
    Capture { id, rx, dropped }
}

impl Capture {
    /// The next record; `None` once detached.
    pub async fn recv(&mut self) -> Option<Record> {
        self.rx.recv().await
    }

    /// The span to run this capture's own work in: what is logged inside it never comes back.
    pub fn span(&self) -> tracing::Span {
        tracing::info_span!(SINK_SPAN, sink = self.id)
    }

    /// Records dropped because this capture's queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// A counter of the records dropped, to read after the capture is gone.
    pub fn dropped_counter(&self) -> Arc<AtomicU64> {
        self.dropped.clone()
    }

    /// Stops taking records; those already queued can still be received.
    pub fn detach(&mut self) {
        let id = self.id;
        change(|s| s.retain(|k| k.id != id));
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        self.detach();
    }
}

/// The layer that hands events to the attached captures; idle while none is attached.
pub fn layer<S>() -> impl Layer<S>
where
    S: Subscriber + for<'a> LookupSpan<'a>,
{
    Taker.with_filter(filter())
}

/// Which events the layer looks at: spans always (they name the modules and the captures' own
/// work), events some attached capture wants.
fn filter<S>() -> impl Filter<S> {
    FilterFn::new(|meta: &Metadata<'_>| {
        meta.is_span()
            || (ANY.load(Ordering::Relaxed) && sinks().iter().any(|s| s.wants.takes(meta)))
    })
    .with_max_level_hint(LevelFilter::TRACE)
}

struct Taker;

/// What a span tells the layer: the module it runs, or the capture whose work it is.
enum SpanRole {
    Module(String),
    Sink(u64),
}

#[derive(Default)]
struct Fields {
    message: String,
    component: Option<String>,
    name: Option<String>,
    sink: Option<u64>,
    rest: String,
}

impl Visit for Fields {
    fn record_u64(&mut self, field: &Field, value: u64) {
        if field.name() == "sink" {
            self.sink = Some(value);
        } else {
            self.record_debug(field, &value);
        }
    }

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

impl<S> Layer<S> for Taker
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
            MODULE_SPAN | SINK_SPAN => {
                let mut f = Fields::default();
                attrs.record(&mut f);
                f.sink.map(SpanRole::Sink).or(f.name.map(SpanRole::Module))
            }
            _ => None,
        };
        if let (Some(role), Some(span)) = (role, ctx.span(id)) {
            span.extensions_mut().insert(role);
        }
    }

    fn on_event(&self, event: &Event<'_>, ctx: Context<'_, S>) {
        let meta = event.metadata();
        let mut module = None;
        let mut within = None;
        if let Some(scope) = ctx.event_scope(event) {
            for span in scope {
                match span.extensions().get::<SpanRole>() {
                    Some(SpanRole::Sink(n)) => within = Some(*n),
                    Some(SpanRole::Module(m)) if module.is_none() => module = Some(m.clone()),
                    _ => {}
                }
            }
        }
        let sinks = sinks();
        let mut takers = sinks
            .iter()
            .filter(|s| Some(s.id) != within && s.wants.takes(meta))
            .peekable();
        if takers.peek().is_none() {
            return;
        }
        let mut f = Fields::default();
        event.record(&mut f);
        let mut text = f.message;
        if let Some(n) = f.name {
            // `name` means something only on a module's span
            let _ = write!(text, " name={n}");
        }
        text.push_str(&f.rest);
        let record = Record {
            time: Stamp::now(),
            level: *meta.level(),
            data: meta.target() == DATA_TARGET,
            component: f.component.or(module),
            target: meta.target().to_string(),
            file: meta.file().zip(meta.line()),
            text,
        };
        for s in takers {
            if s.tx.try_send(record.clone()).is_err() {
                s.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing_subscriber::prelude::*;

    fn wants(level: Level, targets: &'static [&'static str]) -> Wants {
        Wants {
            level,
            targets,
            queue: 16,
        }
    }

    // one test: the attached captures are the program's
    #[tokio::test(flavor = "current_thread")]
    async fn captures_take_what_they_want_never_their_own_work_and_drop_when_full() {
        let _guard = tracing_subscriber::registry().with(layer()).set_default();
        let mut info = attach(wants(Level::INFO, Wants::SEABUS));
        let mut foreign = attach(wants(Level::WARN, &["foxglove"]));
        tracing::info_span!(MODULE_SPAN, name = "gps").in_scope(|| {
            tracing::warn!(target: "seabus_drivers::gps", fix = 0, "no fix");
            tracing::debug!(target: "seabus_drivers::gps", "searching");
        });
        tracing::info!(target: DATA_TARGET, component = "ctd", "t=4.1");
        tracing::error!(target: "foxglove::websocket", "invalid message");
        tracing::info!(target: "foxglove::websocket", "connected");
        tracing::warn!(target: "other", "nobody's");

        let r = info.recv().await.unwrap();
        assert_eq!(
            (r.level, r.data, r.component.as_deref(), r.text.as_str()),
            (Level::WARN, false, Some("gps"), "no fix fix=0")
        );
        let r = info.recv().await.unwrap();
        assert_eq!(
            (r.level, r.data, r.component.as_deref(), r.text.as_str()),
            (Level::INFO, true, Some("ctd"), "t=4.1")
        );
        assert!(info.rx.try_recv().is_err(), "nothing else was taken");
        let r = foreign.recv().await.unwrap();
        assert_eq!(
            (r.level, r.target.as_str(), r.text.as_str()),
            (Level::ERROR, "foxglove::websocket", "invalid message")
        );
        assert!(foreign.rx.try_recv().is_err());
        drop((info, foreign));

        // a capture's own work is not given back to it, and a full queue drops
        let mut a = attach(wants(Level::INFO, Wants::SEABUS));
        let mut b = attach(wants(Level::INFO, Wants::SEABUS));
        a.span()
            .in_scope(|| tracing::warn!(target: "seabus", "sending failed"));
        let r = b.recv().await.unwrap();
        assert_eq!(r.text, "sending failed");
        assert!(a.rx.try_recv().is_err(), "a's own warning stays out of a");
        for i in 0..40 {
            tracing::info!(target: "seabus", "event {i}");
        }
        assert_eq!((a.dropped(), b.dropped()), (24, 24));
        drop(a);
        tracing::info!(target: "seabus", "after a is gone");
        assert_eq!(b.dropped(), 25);
        assert_eq!(sinks().len(), 1);
    }
}
