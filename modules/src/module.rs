//! The module abstraction: what a module declares, the handlers the runtime calls, and the context
//! through which a module reaches its media.
//!
//! A module is described only by the data it produces, the data it consumes and the commands it
//! accepts ([`Declaration`]). The runtime attaches one interface ("port") per medium the module is
//! placed on, subscribes it to what the module consumes and accepts, and then calls
//! [`Module::start`], [`Module::on_message`] for each message, [`Module::on_timer`] at the rates the
//! module asked for, and [`Module::stop`] at shutdown. A handler that returns an error, or panics,
//! fails the module: the runtime reports it and starts a fresh instance after a back-off.

use crate::datasets::Catalogue;
use async_trait::async_trait;
use seabus_medium::{
    DataMap, Format, Interface, IntoTopic, Kind, Message, Node, Payload, SendError, TopicError,
};
use std::fmt;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;
use thiserror::Error;
use tokio::time::Instant;

/// The kinds of module, after the Zagreb design (plus services from DSAAV).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ModuleKind {
    /// Marshals a device's data into standard datasets and unmarshals commands for it.
    Driver,
    /// Conversion, filtering, correction, fusion.
    Supporting,
    /// A user interface.
    Ui,
    /// An interconnection between media.
    Bridge,
    /// A system service: configuration, logging, health, recording.
    Service,
}

impl ModuleKind {
    /// The kind's name.
    pub fn name(self) -> &'static str {
        match self {
            ModuleKind::Driver => "driver",
            ModuleKind::Supporting => "supporting",
            ModuleKind::Ui => "ui",
            ModuleKind::Bridge => "bridge",
            ModuleKind::Service => "service",
        }
    }
}

impl fmt::Display for ModuleKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One field a module produces or takes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldDecl {
    /// Field name.
    pub name: String,
    /// Unit, empty when none.
    pub unit: String,
}

/// A topic a module produces, consumes or accepts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicDecl {
    /// Topic, or pattern for what is consumed.
    pub topic: String,
    /// The standard dataset it carries, when it is one.
    pub dataset: Option<String>,
    /// Fields beyond (or instead of) the dataset's.
    pub fields: Vec<FieldDecl>,
    /// Which of the module's ports (media) it is on.
    pub port: usize,
}

impl TopicDecl {
    /// A topic on port 0.
    pub fn topic(topic: impl AsRef<str>) -> TopicDecl {
        TopicDecl {
            topic: topic.as_ref().to_string(),
            dataset: None,
            fields: Vec::new(),
            port: 0,
        }
    }

    /// A topic carrying a standard dataset.
    pub fn dataset(topic: impl AsRef<str>, dataset: &str) -> TopicDecl {
        TopicDecl {
            dataset: Some(dataset.to_string()),
            ..TopicDecl::topic(topic)
        }
    }

    /// Adds a field.
    pub fn field(mut self, name: &str, unit: &str) -> TopicDecl {
        self.fields.push(FieldDecl {
            name: name.to_string(),
            unit: unit.to_string(),
        });
        self
    }

    /// Places it on another port.
    pub fn on_port(mut self, port: usize) -> TopicDecl {
        self.port = port;
        self
    }
}

/// Everything a module is: its kind, and the topics it produces, consumes and accepts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Declaration {
    /// The module's kind.
    pub kind: ModuleKind,
    /// Data it publishes.
    pub produces: Vec<TopicDecl>,
    /// Data it reads (patterns); the runtime subscribes to data messages on them.
    pub consumes: Vec<TopicDecl>,
    /// Commands it accepts (patterns); the runtime subscribes to command messages on them.
    pub accepts: Vec<TopicDecl>,
    /// The format each port hands to the module (`None`: as sent).
    pub formats: Vec<Option<Format>>,
    /// Period of timer [`TICK`] when the system file gives no `tick`.
    pub tick: Option<Duration>,
}

impl Declaration {
    /// An empty declaration of `kind`; its ports take datamaps.
    pub fn new(kind: ModuleKind) -> Declaration {
        Declaration {
            kind,
            produces: Vec::new(),
            consumes: Vec::new(),
            accepts: Vec::new(),
            formats: Vec::new(),
            tick: None,
        }
    }

    /// Sets the period of timer [`TICK`] used when the system file gives no `tick`.
    pub fn default_tick(mut self, period: Duration) -> Self {
        self.tick = Some(period);
        self
    }

    /// Adds a produced topic.
    pub fn produces(mut self, t: TopicDecl) -> Self {
        self.produces.push(t);
        self
    }

    /// Adds a consumed topic pattern.
    pub fn consumes(mut self, t: TopicDecl) -> Self {
        self.consumes.push(t);
        self
    }

    /// Adds an accepted command topic.
    pub fn accepts(mut self, t: TopicDecl) -> Self {
        self.accepts.push(t);
        self
    }

    /// Sets the format port `port` hands to the module (`None`: as sent). Unset ports take datamaps.
    pub fn format(mut self, port: usize, format: Option<Format>) -> Self {
        if self.formats.len() <= port {
            self.formats.resize(port + 1, Some(Format::Map));
        }
        self.formats[port] = format;
        self
    }

    /// The format port `port` hands to the module.
    pub fn format_of(&self, port: usize) -> Option<Format> {
        self.formats.get(port).copied().unwrap_or(Some(Format::Map))
    }
}

/// Why a module failed.
#[derive(Debug, Error)]
pub enum ModuleError {
    /// A send failed.
    #[error(transparent)]
    Send(#[from] SendError),
    /// A topic was not valid.
    #[error(transparent)]
    Topic(#[from] TopicError),
    /// Anything else, said in words.
    #[error("{0}")]
    Failed(String),
}

impl ModuleError {
    /// A failure described in words.
    pub fn msg(text: impl fmt::Display) -> ModuleError {
        ModuleError::Failed(text.to_string())
    }
}

/// Identifies a timer a module set.
pub type TimerId = u32;

/// The timer the runtime sets from the system file's `tick` attribute.
pub const TICK: TimerId = 0;

/// A module. The runtime calls its handlers one at a time, never concurrently.
#[async_trait]
pub trait Module: Send + 'static {
    /// Called once the ports are attached, before anything else.
    async fn start(&mut self, _ctx: &mut Context) -> Result<(), ModuleError> {
        Ok(())
    }

    /// Called with each message on port `port`, in that port's declared format.
    async fn on_message(
        &mut self,
        _ctx: &mut Context,
        _port: usize,
        _msg: Message,
    ) -> Result<(), ModuleError> {
        Ok(())
    }

    /// Called when timer `timer` is due.
    async fn on_timer(&mut self, _ctx: &mut Context, _timer: TimerId) -> Result<(), ModuleError> {
        Ok(())
    }

    /// Called at shutdown; it has a short time to finish.
    async fn stop(&mut self, _ctx: &mut Context) {}
}

struct Timer {
    id: TimerId,
    period: Duration,
    due: Instant,
}

/// What a module works through: its ports (one interface per medium), timers, and the catalogue.
pub struct Context {
    name: Arc<str>,
    node: Node,
    ports: Vec<Interface>,
    timers: Vec<Timer>,
    catalogue: Arc<Catalogue>,
    next_port: usize,
    /// the wait for the earliest timer, kept between events (set again only when that changes)
    alarm: Option<Pin<Box<tokio::time::Sleep>>>,
}

/// Something that happened for a module.
pub(crate) enum Event {
    Message(usize, Message),
    Timer(TimerId),
    Closed,
}

impl Context {
    /// A context over `ports`.
    pub fn new(
        name: &str,
        node: Node,
        ports: Vec<Interface>,
        catalogue: Arc<Catalogue>,
    ) -> Context {
        Context {
            name: Arc::from(name),
            node,
            ports,
            timers: Vec::new(),
            catalogue,
            next_port: 0,
            alarm: None,
        }
    }

    /// The module's name in its system.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The node the module runs on.
    pub fn node(&self) -> &Node {
        &self.node
    }

    /// The standard datasets.
    pub fn catalogue(&self) -> &Catalogue {
        &self.catalogue
    }

    /// Port `i` (the interface on the module's `i`-th medium).
    pub fn port(&self, i: usize) -> Option<&Interface> {
        self.ports.get(i)
    }

    /// Port `i`, mutably (to change subscriptions).
    pub fn port_mut(&mut self, i: usize) -> Option<&mut Interface> {
        self.ports.get_mut(i)
    }

    /// Number of ports.
    pub fn ports(&self) -> usize {
        self.ports.len()
    }

    fn port_or_err(&self, i: usize) -> Result<&Interface, ModuleError> {
        self.ports
            .get(i)
            .ok_or_else(|| ModuleError::msg(format!("module `{}` has no port {i}", self.name)))
    }

    /// Publishes data on port 0.
    pub async fn publish(
        &self,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<(), ModuleError> {
        self.publish_on(0, Kind::Data, topic, payload).await
    }

    /// Publishes a command on port 0.
    pub async fn command(
        &self,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<(), ModuleError> {
        self.publish_on(0, Kind::Command, topic, payload).await
    }

    /// Publishes on a given port.
    pub async fn publish_on(
        &self,
        port: usize,
        kind: Kind,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<(), ModuleError> {
        Ok(self
            .port_or_err(port)?
            .publish(kind, topic, payload)
            .await?)
    }

    /// Publishes a standard dataset as data on port 0 after checking it; an invalid map is not sent.
    pub async fn publish_dataset(
        &self,
        dataset: &str,
        topic: impl IntoTopic,
        map: DataMap,
    ) -> Result<(), ModuleError> {
        self.dataset_on(0, Kind::Data, dataset, topic, map).await
    }

    /// Sends a standard dataset as a command on port 0 after checking it.
    pub async fn command_dataset(
        &self,
        dataset: &str,
        topic: impl IntoTopic,
        map: DataMap,
    ) -> Result<(), ModuleError> {
        self.dataset_on(0, Kind::Command, dataset, topic, map).await
    }

    /// Checks `map` against `dataset`, then publishes it on `port`.
    pub async fn dataset_on(
        &self,
        port: usize,
        kind: Kind,
        dataset: &str,
        topic: impl IntoTopic,
        map: DataMap,
    ) -> Result<(), ModuleError> {
        self.catalogue
            .validate(dataset, &map)
            .map_err(|e| ModuleError::msg(format!("module `{}`: {e}", self.name)))?;
        self.publish_on(port, kind, topic, map).await
    }

    /// Calls [`Module::on_timer`] with `id` every `period`, starting one period from now.
    pub fn every(&mut self, id: TimerId, period: Duration) {
        let period = period.max(Duration::from_micros(100));
        self.timers.retain(|t| t.id != id);
        self.timers.push(Timer {
            id,
            period,
            due: Instant::now() + period,
        });
    }

    /// Stops timer `id`.
    pub fn cancel(&mut self, id: TimerId) {
        self.timers.retain(|t| t.id != id);
    }

    /// Waits for the next message on any port, or the next timer.
    pub(crate) async fn next_event(&mut self) -> Event {
        let due = self
            .timers
            .iter()
            .min_by_key(|t| t.due)
            .map(|t| (t.id, t.due));
        let alarm = due.map(|(_, at)| {
            let sleep = self
                .alarm
                .get_or_insert_with(|| Box::pin(tokio::time::sleep_until(at)));
            if sleep.deadline() != at {
                sleep.as_mut().reset(at);
            }
            sleep.as_mut()
        });
        let n = self.ports.len();
        let start = self.next_port;
        let ports = &mut self.ports;
        let recv = std::future::poll_fn(|cx| {
            let mut closed = 0;
            for k in 0..n {
                let i = (start + k) % n;
                match ports[i].poll_recv(cx) {
                    std::task::Poll::Ready(Some(m)) => return std::task::Poll::Ready(Some((i, m))),
                    std::task::Poll::Ready(None) => closed += 1,
                    std::task::Poll::Pending => {}
                }
            }
            if n > 0 && closed == n {
                std::task::Poll::Ready(None)
            } else {
                std::task::Poll::Pending
            }
        });
        let event = tokio::select! {
            biased;
            _ = async {
                match alarm {
                    Some(sleep) => sleep.await,
                    None => std::future::pending().await,
                }
            } => {
                let (id, _) = due.expect("a timer was due");
                Event::Timer(id)
            }
            m = recv => match m {
                Some((i, m)) => Event::Message(i, m),
                None => Event::Closed,
            },
        };
        match &event {
            Event::Timer(id) => {
                let now = Instant::now();
                if let Some(t) = self.timers.iter_mut().find(|t| t.id == *id) {
                    t.due += t.period;
                    // skip ticks missed while busy rather than firing them in a burst
                    if t.due <= now {
                        t.due = now + t.period;
                    }
                }
            }
            Event::Message(i, _) => self.next_port = (i + 1) % n.max(1),
            Event::Closed => {}
        }
        event
    }
}
