//! The medium: local fan-out to interfaces, a transport to the wire, and the fault stage.
//!
//! A [`Medium`] is shared by every interface attached to it. Sending hands a message to every other
//! local interface whose subscriptions match (sharing the payload, never copying it) and, when the
//! medium has a [`Transport`], encodes it and puts it on the wire; a transport whose receivers read
//! something other than was sent (headers the wire adds, addressing) gives its local interfaces
//! what a receiver on this node would read instead ([`Transport::local_copy`]). Messages the
//! transport reads from the wire come back in through an [`Ingress`] and fan out the same way. Each
//! medium kind only implements its transport: its wire format and its I/O tasks.

use crate::caps::Capabilities;
use crate::datamap::{DataMap, Value};
use crate::fault::{FaultConfig, Faults};
use crate::loss::Losses;
use crate::message::{Kind, Message, Origin, Provenance, Stamp};
use crate::payload::{ConvertError, Format, Payload};
use crate::qos::Qos;
use crate::queue::{Check, DEFAULT_COMMAND_CAPACITY, DEFAULT_DATA_CAPACITY, Pushed, Queue};
use crate::subindex::{Scratch, SubIndex};
use crate::tally::Tally;
use crate::topic::{Pattern, Topic, TopicError};
use crate::url::{MediumUrl, UrlError};
use arc_swap::ArcSwap;
use bytes::Bytes;
use std::any::Any;
use std::collections::{BTreeMap, VecDeque};
use std::fmt;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::task::{Context, Poll};
use thiserror::Error;
use tokio::sync::watch;
use tokio::task::AbortHandle;

/// A boxed future, as returned by [`Transport::transmit`].
pub type BoxFuture<'a, T> = Pin<Box<dyn Future<Output = T> + Send + 'a>>;

/// A node: one running seabus (or one peer), named in provenance records.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    /// The node's name (the system file's `node` attribute, or the host name).
    pub name: Arc<str>,
    /// A number drawn at start-up, so that a restarted node is a new origin.
    pub boot: u32,
}

impl Node {
    /// A node called `name` with a fresh boot number.
    pub fn new(name: &str) -> Node {
        Node {
            name: Arc::from(name),
            boot: fastrand::u32(1..),
        }
    }

    /// A node named after this host.
    pub fn local() -> Node {
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "seabus".to_string());
        Node::new(&host)
    }
}

/// Whether a medium can currently reach its wire.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkState {
    /// Working.
    Up,
    /// Not working, with the reason; the medium keeps trying.
    Down(String),
}

/// Why a message could not be sent.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SendError {
    /// The topic is not valid.
    #[error(transparent)]
    Topic(#[from] TopicError),
    /// The encoded message does not fit in one datagram or frame of the medium.
    #[error("message is {size} bytes on the wire, medium `{medium}` carries at most {max}")]
    TooLarge {
        /// The medium's name.
        medium: String,
        /// Encoded size.
        size: usize,
        /// The medium's limit.
        max: usize,
    },
    /// The payload could not be converted to what the medium carries.
    #[error("medium `{medium}` cannot carry this payload: {source}")]
    Convert {
        /// The medium's name.
        medium: String,
        /// The conversion failure.
        source: ConvertError,
    },
    /// The wire refused the message.
    #[error("medium `{medium}`: {reason}")]
    Io {
        /// The medium's name.
        medium: String,
        /// What the operating system said.
        reason: String,
    },
    /// The medium's link is down (a device unplugged); the medium keeps trying to restore it.
    #[error("medium `{medium}` link is down: {reason}")]
    LinkDown {
        /// The medium's name.
        medium: String,
        /// Why.
        reason: String,
    },
    /// The medium was closed.
    #[error("medium `{0}` is closed")]
    Closed(String),
}

/// Why a medium could not be opened.
#[derive(Debug, Error)]
pub enum OpenError {
    /// The URL is not valid for the medium.
    #[error(transparent)]
    Url(#[from] UrlError),
    /// No medium has this scheme.
    #[error("unknown medium scheme `{scheme}://` in `{url}`; known schemes: {known}")]
    UnknownScheme {
        /// The scheme.
        scheme: String,
        /// The URL.
        url: String,
        /// The schemes there are, comma-separated.
        known: String,
    },
    /// The scheme's medium exists but was left out of this build.
    #[error("medium `{family}` is not compiled into this seabus (feature `{feature}`): `{url}`")]
    NotCompiled {
        /// The medium family (`can`).
        family: String,
        /// The cargo feature that adds it.
        feature: String,
        /// The URL.
        url: String,
    },
    /// The operating system refused.
    #[error("cannot open `{url}`: {context}: {source}")]
    Io {
        /// The URL.
        url: String,
        /// What was being done.
        context: String,
        /// The error.
        source: std::io::Error,
    },
}

/// The wire side of a medium: encoding and transmission, in the transport's own frame type.
/// Reception is done by tasks the transport spawns when it is opened, which hand what they read to
/// an [`Ingress`].
pub trait Transport: Send + Sync + 'static {
    /// What one message becomes on the wire: bytes for most media, a CAN frame for SocketCAN.
    type Frame: Clone + Send + Sync + 'static;
    /// What this transport can do (see [`Capabilities`]).
    fn capabilities(&self) -> Capabilities;
    /// Encodes `msg` for the wire. Errors here (too large, not representable) go back to the sender.
    fn encode(&self, msg: &Message) -> Result<Self::Frame, SendError>;
    /// Puts an encoded frame on the wire.
    fn transmit(&self, frame: Self::Frame) -> BoxFuture<'_, Result<(), SendError>>;
    /// What the medium's local interfaces get of `msg`, just encoded as `frame`: what a receiver on
    /// this node would read of the frame, `None` when it would read nothing. By default `msg` itself.
    fn local_copy(&self, msg: Message, frame: &Self::Frame) -> Option<Message> {
        let _ = frame;
        Some(msg)
    }
    /// Releases the wire (sockets, devices) when the medium is closed.
    fn close(&self) {}
    /// Returns once what was transmitted so far has been written out, for a transport that queues
    /// frames for a task to write (or at once when the link goes down). By default at once.
    fn flush(&self) -> BoxFuture<'_, ()> {
        Box::pin(std::future::ready(()))
    }
    /// A local interface subscribed to `pattern`: a transport that listens to its wire only
    /// while someone here wants what it hears (joining a multicast group) starts listening now,
    /// and one whose wire routes by subscription (Zenoh) asks for what the pattern matches.
    fn subscribed(&self, pattern: &Pattern) {
        let _ = pattern;
    }
    /// A fingerprint of what the wire carries of a message on `topic` with `payload`, the same for
    /// a message sent and that message read back (a CAN frame by its identifier and data, whatever
    /// else its datamap held); `None` (the default) when the topic and payload as they are say it.
    /// A bridge recognises the echo of what it wrote to a wire without provenance by it.
    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64> {
        let _ = (topic, payload);
        None
    }
    /// Messages this medium sends on topics matching `pattern`, of `kind` (`None`: both kinds), go
    /// with `qos` from now on: each attribute it sets replaces the one their kind would have, and of
    /// several declarations matching a topic the first one declared counts. Only a transport whose
    /// [`Capabilities::qos`] says so is asked ([`Medium::set_qos`]); by default nothing changes.
    fn set_qos(&self, pattern: &Pattern, kind: Option<Kind>, qos: Qos) {
        let _ = (pattern, kind, qos);
    }
}

/// A frame encoded by a transport, in the transport's own type, on its way to the wire (through
/// the fault stage, which may hold it back or copy it).
#[derive(Clone)]
pub(crate) enum Frame {
    /// Bytes, the frame of most media: carried as they are, without an allocation of its own.
    Bytes(Bytes),
    /// Any other frame type.
    Other(Arc<dyn Any + Send + Sync>),
}

impl Frame {
    /// A transport's frame, hidden.
    fn of<F: Clone + Send + Sync + 'static>(frame: F) -> Frame {
        let mut slot = Some(frame);
        match (&mut slot as &mut dyn Any).downcast_mut::<Option<Bytes>>() {
            Some(bytes) => Frame::Bytes(bytes.take().unwrap_or_default()),
            None => Frame::Other(Arc::new(slot)),
        }
    }

    /// The transport's frame again; `None` when it is of another type.
    fn into<F: Clone + Send + Sync + 'static>(self) -> Option<F> {
        match self {
            Frame::Bytes(b) => {
                let mut slot = Some(b);
                (&mut slot as &mut dyn Any)
                    .downcast_mut::<Option<F>>()
                    .and_then(Option::take)
            }
            Frame::Other(any) => any
                .downcast::<Option<F>>()
                .ok()
                .and_then(Arc::unwrap_or_clone),
        }
    }

    /// The transport's frame, borrowed; `None` when it is of another type.
    fn as_ref<F: 'static>(&self) -> Option<&F> {
        match self {
            Frame::Bytes(b) => (b as &dyn Any).downcast_ref::<F>(),
            Frame::Other(any) => any.downcast_ref::<Option<F>>().and_then(Option::as_ref),
        }
    }
}

/// A [`Transport`] with its frame type hidden, as a medium holds it.
pub(crate) trait Wire: Send + Sync {
    fn capabilities(&self) -> Capabilities;
    fn encode(&self, msg: &Message) -> Result<Frame, SendError>;
    fn transmit(&self, frame: Frame) -> BoxFuture<'_, Result<(), SendError>>;
    fn local_copy(&self, msg: Message, frame: &Frame) -> Option<Message>;
    fn close(&self);
    fn flush(&self) -> BoxFuture<'_, ()>;
    fn subscribed(&self, pattern: &Pattern);
    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64>;
    fn set_qos(&self, pattern: &Pattern, kind: Option<Kind>, qos: Qos);
}

impl<T: Transport> Wire for T {
    fn capabilities(&self) -> Capabilities {
        Transport::capabilities(self)
    }

    fn encode(&self, msg: &Message) -> Result<Frame, SendError> {
        Ok(Frame::of(Transport::encode(self, msg)?))
    }

    fn transmit(&self, frame: Frame) -> BoxFuture<'_, Result<(), SendError>> {
        // a frame comes back only to the transport that encoded it
        match frame.into::<T::Frame>() {
            Some(f) => Transport::transmit(self, f),
            None => Box::pin(std::future::ready(Err(SendError::Io {
                medium: String::new(),
                reason: "a frame reached a transport that did not encode it".to_string(),
            }))),
        }
    }

    fn local_copy(&self, msg: Message, frame: &Frame) -> Option<Message> {
        match frame.as_ref::<T::Frame>() {
            Some(f) => Transport::local_copy(self, msg, f),
            None => Some(msg),
        }
    }

    fn close(&self) {
        Transport::close(self)
    }

    fn flush(&self) -> BoxFuture<'_, ()> {
        Transport::flush(self)
    }

    fn subscribed(&self, pattern: &Pattern) {
        Transport::subscribed(self, pattern)
    }

    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64> {
        Transport::fingerprint(self, topic, payload)
    }

    fn set_qos(&self, pattern: &Pattern, kind: Option<Kind>, qos: Qos) {
        Transport::set_qos(self, pattern, kind, qos)
    }
}

/// A subscription: a topic pattern, for one kind of message or (`None`) both.
pub type Subscription = (Pattern, Option<Kind>);

struct Sub {
    id: u64,
    patterns: Arc<[Subscription]>,
    queue: Arc<Queue>,
}

/// Up to this many subscriptions on a medium, a message tries each; beyond, they are indexed.
const SCAN_UP_TO: usize = 8;

/// A medium's interfaces, with their subscriptions indexed once there are many (the index is
/// made when the first message needs it, so that subscribing many patterns at once costs one).
#[derive(Default)]
struct Subs {
    list: Vec<Sub>,
    index: OnceLock<Option<SubIndex>>,
}

impl Subs {
    fn new(list: Vec<Sub>) -> Subs {
        Subs {
            list,
            index: OnceLock::new(),
        }
    }

    fn index(&self) -> Option<&SubIndex> {
        self.index
            .get_or_init(|| {
                let count: usize = self.list.iter().map(|s| s.patterns.len()).sum();
                (count > SCAN_UP_TO).then(|| {
                    let mut index = SubIndex::default();
                    for (at, s) in self.list.iter().enumerate() {
                        for (p, k) in s.patterns.iter() {
                            index.insert(at as u32, p, *k);
                        }
                    }
                    index
                })
            })
            .as_ref()
    }
}

thread_local! {
    /// What an indexed medium's match uses, kept between messages.
    static SCRATCH: std::cell::Cell<Scratch> = std::cell::Cell::new(Scratch::default());
}

impl Sub {
    fn wants(&self, msg: &Message) -> bool {
        self.patterns
            .iter()
            .any(|(p, k)| k.is_none_or(|k| k == msg.kind) && p.matches(&msg.topic))
    }
}

#[derive(Default)]
struct Counters {
    published: AtomicU64,
    delivered: AtomicU64,
    transmitted: AtomicU64,
    received: AtomicU64,
    tx_errors: AtomicU64,
    commands_refused: AtomicU64,
    dropped_bytes: AtomicU64,
}

pub(crate) struct Inner {
    name: Arc<str>,
    url: String,
    origin: Arc<Origin>,
    node: Node,
    seq: AtomicU64,
    /// read on every message without a lock; replaced whole under `subs_changing`
    subs: ArcSwap<Subs>,
    subs_changing: Mutex<()>,
    next_id: AtomicU64,
    transport: OnceLock<Arc<dyn Wire>>,
    faults: Option<Faults>,
    counters: Counters,
    rejected: Tally,
    /// sends that failed after the sender was told they were on their way (an [`Outbox`]'s)
    ///
    /// [`Outbox`]: crate::outbox::Outbox
    send_failures: Mutex<crate::tally::Limiter>,
    /// Messages receivers' full queues dropped and characters the device lost.
    losses: Arc<Losses>,
    link: watch::Sender<LinkState>,
    tasks: Mutex<Vec<AbortHandle>>,
    closed: AtomicBool,
    /// State shared by everything attached to the medium, one value per type ([`Medium::shared`]).
    shared: Mutex<Vec<Arc<dyn Any + Send + Sync>>>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        for t in self
            .tasks
            .get_mut()
            .unwrap_or_else(|p| p.into_inner())
            .drain(..)
        {
            t.abort();
        }
    }
}

/// A communication medium. Cheap to clone: clones share the medium.
#[derive(Clone)]
pub struct Medium {
    inner: Arc<Inner>,
}

impl fmt::Debug for Medium {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Medium")
            .field("name", &self.inner.name)
            .field("url", &self.inner.url)
            .finish()
    }
}

/// A hash of a topic and a payload's bytes (a datamap's in its binary form).
pub fn fingerprint(topic: &Topic, payload: &Payload) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    topic.as_str().hash(&mut h);
    match payload {
        Payload::Bytes(b) => b.hash(&mut h),
        Payload::Xml(x) => x.hash(&mut h),
        Payload::Map(m) => crate::binary::encode(m).ok().hash(&mut h),
    }
    h.finish()
}

/// What a transport constructor gets: the medium's name, node, the URL with its options, and the
/// ingress for what it reads.
pub struct Opening {
    /// The medium's name.
    pub name: Arc<str>,
    /// This node.
    pub node: Node,
    /// The URL; the transport takes its options and calls [`MediumUrl::finish`].
    pub url: MediumUrl,
    /// Where received messages go.
    pub ingress: Ingress,
}

impl Opening {
    /// Turns an I/O error met while opening into an [`OpenError::Io`] naming the URL and what was
    /// being done: `.map_err(o.io_error("binding 0.0.0.0:5000"))`.
    pub fn io_error(&self, context: impl Into<String>) -> impl FnOnce(std::io::Error) -> OpenError {
        let url = self.url.to_string();
        let context = context.into();
        move |source| OpenError::Io {
            url,
            context,
            source,
        }
    }
}

/// Builds media one step at a time: the in-process constructor and the scheme registry share it.
pub(crate) struct Builder {
    pub(crate) name: Arc<str>,
    pub(crate) url: String,
    pub(crate) node: Node,
    pub(crate) faults: Option<FaultConfig>,
    /// Whether rejected input is logged at DEBUG (`rejects=debug`).
    pub(crate) quiet_rejects: bool,
}

impl Builder {
    /// Builds the medium, then its transport (which gets a working ingress), then joins the two.
    pub(crate) fn build<F>(self, make_transport: F) -> Result<Medium, OpenError>
    where
        F: FnOnce(Ingress) -> Result<Option<Arc<dyn Wire>>, OpenError>,
    {
        let (link, _) = watch::channel(LinkState::Up);
        let inner = Arc::new(Inner {
            origin: Origin::new(&self.node.name, &self.name, self.node.boot),
            losses: Losses::new(self.name.clone()),
            name: self.name,
            url: self.url,
            node: self.node,
            seq: AtomicU64::new(0),
            subs: ArcSwap::from_pointee(Subs::default()),
            subs_changing: Mutex::new(()),
            next_id: AtomicU64::new(1),
            transport: OnceLock::new(),
            faults: self.faults.map(Faults::new),
            counters: Counters::default(),
            rejected: if self.quiet_rejects {
                Tally::logged_at_debug()
            } else {
                Tally::new()
            },
            send_failures: Mutex::new(crate::tally::Limiter::default()),
            link,
            tasks: Mutex::new(Vec::new()),
            closed: AtomicBool::new(false),
            shared: Mutex::new(Vec::new()),
        });
        let medium = Medium { inner };
        if let Some(t) = make_transport(medium.ingress())? {
            let _ = medium.inner.transport.set(t);
        }
        Ok(medium)
    }
}

impl Medium {
    /// An in-process medium: the default bus. Messages are shared between interfaces, never copied.
    pub fn in_process(name: &str, node: &Node) -> Medium {
        Medium::local(name, node, None)
    }

    fn local(name: &str, node: &Node, faults: Option<FaultConfig>) -> Medium {
        Builder {
            name: Arc::from(name),
            url: "inproc://".to_string(),
            node: node.clone(),
            faults,
            quiet_rejects: false,
        }
        .build(|_| Ok(None))
        .expect("an in-process medium has nothing that can fail")
    }

    /// Adds the fault stage (loss, duplication, reordering, delay) to a medium being built in code.
    pub fn in_process_with_faults(name: &str, node: &Node, faults: FaultConfig) -> Medium {
        Medium::local(name, node, Some(faults))
    }

    /// The medium's name in its system.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// The URL it was opened with.
    pub fn url(&self) -> &str {
        &self.inner.url
    }

    /// The node it belongs to.
    pub fn node(&self) -> &Node {
        &self.inner.node
    }

    /// What the medium's wire can do; an in-process medium's are [`Capabilities::IN_PROCESS`].
    pub fn capabilities(&self) -> Capabilities {
        self.inner
            .transport
            .get()
            .map_or(Capabilities::IN_PROCESS, |t| t.capabilities())
    }

    /// A fingerprint of what this medium's wire carries of a message on `topic` with `payload`
    /// (see [`Transport::fingerprint`]): by default a hash of the topic and the payload's bytes.
    pub fn fingerprint(&self, topic: &Topic, payload: &Payload) -> u64 {
        self.inner
            .transport
            .get()
            .and_then(|t| t.fingerprint(topic, payload))
            .unwrap_or_else(|| fingerprint(topic, payload))
    }

    /// Declares that the messages this medium sends on topics matching `pattern`, of `kind`
    /// (`None`: both kinds), go with `qos`: each attribute it sets replaces the one the medium
    /// gives their kind, the others stay; of several declarations matching a topic, the first one
    /// declared counts (declaring the same one again changes nothing). A bridge route's
    /// `priority`, `congestion` and `express` are declared so when the bridge starts. Returns
    /// false, changing nothing, when the medium's wire has no such thing
    /// ([`Capabilities::qos`]).
    pub fn set_qos(&self, pattern: &Pattern, kind: Option<Kind>, qos: Qos) -> bool {
        match self.inner.transport.get() {
            Some(t) if t.capabilities().qos => {
                t.set_qos(pattern, kind, qos);
                true
            }
            _ => false,
        }
    }

    /// The origin of messages first published here.
    pub fn origin(&self) -> &Arc<Origin> {
        &self.inner.origin
    }

    /// Attaches a new passive interface. It receives nothing until it subscribes.
    pub fn attach(&self, label: &str) -> Interface {
        self.attach_with(label, DEFAULT_DATA_CAPACITY, DEFAULT_COMMAND_CAPACITY)
    }

    /// Attaches a new passive interface with the given queue capacities.
    pub fn attach_with(
        &self,
        label: &str,
        data_capacity: usize,
        command_capacity: usize,
    ) -> Interface {
        let id = self.inner.next_id.fetch_add(1, Ordering::Relaxed);
        let label: Arc<str> = Arc::from(label);
        let queue = Arc::new(
            Queue::new(data_capacity, command_capacity)
                .counted_in(self.inner.losses.clone(), label.clone()),
        );
        self.inner.update_subs(|subs| {
            subs.push(Sub {
                id,
                patterns: Arc::from(Vec::new()),
                queue: queue.clone(),
            })
        });
        // checked after joining the list, so that a close running meanwhile cannot miss it
        if self.inner.closed.load(Ordering::Acquire) {
            queue.close();
        }
        Interface {
            medium: self.clone(),
            id,
            label,
            queue,
            patterns: Vec::new(),
            accept: None,
            counters: IfaceCounters::default(),
            batch: VecDeque::new(),
        }
    }

    /// The medium's counters.
    pub fn stats(&self) -> MediumStats {
        let c = &self.inner.counters;
        let f = self
            .inner
            .faults
            .as_ref()
            .map(Faults::stats)
            .unwrap_or_default();
        MediumStats {
            published: c.published.load(Ordering::Relaxed),
            delivered: c.delivered.load(Ordering::Relaxed),
            transmitted: c.transmitted.load(Ordering::Relaxed),
            received: c.received.load(Ordering::Relaxed),
            tx_errors: c.tx_errors.load(Ordering::Relaxed),
            commands_refused: c.commands_refused.load(Ordering::Relaxed),
            fault_lost: f.0,
            fault_duplicated: f.1,
            fault_delayed: f.2,
            rejected: self.inner.rejected.counts(),
            dropped_bytes: c.dropped_bytes.load(Ordering::Relaxed),
            overruns: self.inner.losses.overruns(),
            queue_dropped: self.inner.losses.by_receiver(),
            missed: self.inner.losses.missed_by_topic(),
        }
    }

    /// The current link state.
    pub fn link_state(&self) -> LinkState {
        self.inner.link.borrow().clone()
    }

    /// A receiver that sees every change of the link state. (Its `wait_for` guard holds the
    /// state's lock while kept: clone what it gives and let it go, as [`Medium::link_within`]
    /// does, or the medium's link task cannot change the state.)
    pub fn watch_link(&self) -> watch::Receiver<LinkState> {
        self.inner.link.subscribe()
    }

    /// Waits at most `within` for the link state to be one `want` takes; the state then, or
    /// `None` when the wait ended first (or the medium is gone).
    pub async fn link_within(
        &self,
        within: std::time::Duration,
        want: impl FnMut(&LinkState) -> bool,
    ) -> Option<LinkState> {
        let mut link = self.watch_link();
        tokio::time::timeout(within, async move {
            link.wait_for(want).await.ok().map(|state| state.clone())
        })
        .await
        .ok()
        .flatten()
    }

    /// Returns once what was sent on the medium so far has been written to the wire, as far as
    /// the transport can tell (see [`Transport::flush`]).
    pub async fn flush(&self) {
        if let Some(t) = self.inner.transport.get() {
            t.flush().await;
        }
    }

    /// Marks the medium as closing: sends are refused and its link going down is expected. A
    /// system that stops marks all its media first, so that one closing (a pseudo-terminal's
    /// end) is no alarm on another (the serial line reading it).
    pub fn closing(&self) {
        self.inner.closed.store(true, Ordering::Release);
    }

    /// Closes the medium: its I/O tasks stop, sends fail, interfaces drain then see the end.
    pub fn close(&self) {
        self.closing();
        for t in self
            .inner
            .tasks
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .drain(..)
        {
            t.abort();
        }
        if let Some(t) = self.inner.transport.get() {
            t.close();
        }
        for s in self.inner.snapshot().list.iter() {
            s.queue.close();
        }
    }

    /// The one value of type `T` shared by everything attached to this medium, made with
    /// `T::default()` the first time it is asked for. Modules reading the same wire use it to do
    /// once what each would otherwise repeat (the NMEA drivers parse each sentence once for all).
    pub fn shared<T: Default + Send + Sync + 'static>(&self) -> Arc<T> {
        let mut all = self.inner.shared.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(found) = all.iter().find_map(|v| Arc::clone(v).downcast::<T>().ok()) {
            return found;
        }
        let made = Arc::new(T::default());
        all.push(made.clone());
        made
    }

    /// The ingress of this medium, for code that feeds it messages from outside (tests, adapters).
    pub fn ingress(&self) -> Ingress {
        Ingress {
            inner: Arc::downgrade(&self.inner),
        }
    }
}

/// A snapshot of a medium's counters.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MediumStats {
    /// Messages sent by local interfaces.
    pub published: u64,
    /// Messages put into local interfaces' queues.
    pub delivered: u64,
    /// Frames put on the wire.
    pub transmitted: u64,
    /// Messages read from the wire.
    pub received: u64,
    /// Frames the wire refused.
    pub tx_errors: u64,
    /// Commands from the wire refused because a receiver's command queue was full.
    pub commands_refused: u64,
    /// Messages the fault stage lost on purpose.
    pub fault_lost: u64,
    /// Extra copies the fault stage made.
    pub fault_duplicated: u64,
    /// Messages the fault stage delayed or held back.
    pub fault_delayed: u64,
    /// Input rejected from the wire, by reason (a serial line's `garbage`, `too-long`,
    /// `bad-checksum`, …: one count per run of garbage or per frame).
    pub rejected: BTreeMap<String, u64>,
    /// Bytes read from the wire that went into no message: garbage between frames, the skipped
    /// part of a frame longer than the limit, the bytes of a rejected frame, a frame cut off when
    /// the link went down. Line endings and frame delimiters are not counted.
    pub dropped_bytes: u64,
    /// Characters the device lost before seabus read them: a serial device's overruns (in its
    /// hardware and in the kernel's buffer, as the kernel counts them). A device that does not
    /// count them (a pseudo-terminal) leaves it 0.
    pub overruns: u64,
    /// Data messages dropped because a receiver's queue was full (the oldest first), by receiver:
    /// the name its interface was attached with (a module's name).
    pub queue_dropped: BTreeMap<String, u64>,
    /// Messages a sender published that never arrived, by topic, as a wire that numbers each
    /// sender's messages tells (Zenoh's).
    pub missed: BTreeMap<String, u64>,
}

/// A count as a datamap value.
fn count(n: u64) -> Value {
    Value::Int(i64::try_from(n).unwrap_or(i64::MAX))
}

/// Counts by name as a datamap.
fn counts(by: &BTreeMap<String, u64>) -> Value {
    Value::Map(by.iter().map(|(k, n)| (k.clone(), count(*n))).collect())
}

impl MediumStats {
    /// Total input rejected from the wire.
    pub fn rejected_total(&self) -> u64 {
        self.rejected.values().sum()
    }

    /// Total data messages dropped from full queues.
    pub fn queue_dropped_total(&self) -> u64 {
        self.queue_dropped.values().sum()
    }

    /// Whether anything read from the wire was lost or refused: rejected input, bytes dropped,
    /// overruns, messages dropped from full queues, commands refused.
    pub fn has_losses(&self) -> bool {
        self.rejected_total() > 0
            || self.dropped_bytes > 0
            || self.overruns > 0
            || self.queue_dropped_total() > 0
            || self.missed.values().sum::<u64>() > 0
            || self.commands_refused > 0
    }

    /// The counters as a datamap, each field named as here (`rejected` and `queue_dropped` as
    /// maps of counts by name): what `seabus.media` carries and `seabus spy --stats` prints.
    pub fn to_map(&self) -> DataMap {
        DataMap::new()
            .and("received", count(self.received))
            .and("rejected", counts(&self.rejected))
            .and("dropped_bytes", count(self.dropped_bytes))
            .and("overruns", count(self.overruns))
            .and("queue_dropped", counts(&self.queue_dropped))
            .and("missed", counts(&self.missed))
            .and("commands_refused", count(self.commands_refused))
            .and("published", count(self.published))
            .and("delivered", count(self.delivered))
            .and("transmitted", count(self.transmitted))
            .and("tx_errors", count(self.tx_errors))
            .and("fault_lost", count(self.fault_lost))
            .and("fault_duplicated", count(self.fault_duplicated))
            .and("fault_delayed", count(self.fault_delayed))
    }

    /// The counters of a datamap made by [`to_map`](Self::to_map); a field absent or of another
    /// type reads as 0 (or none).
    pub fn from_map(map: &DataMap) -> MediumStats {
        let n = |k: &str| map.get_i64(k).map_or(0, |v| u64::try_from(v).unwrap_or(0));
        let by = |k: &str| -> BTreeMap<String, u64> {
            map.get(k)
                .and_then(Value::as_map)
                .map(|m| {
                    m.iter()
                        .filter_map(|(k, v)| {
                            Some((k.to_string(), u64::try_from(v.as_i64()?).ok()?))
                        })
                        .collect()
                })
                .unwrap_or_default()
        };
        MediumStats {
            published: n("published"),
            delivered: n("delivered"),
            transmitted: n("transmitted"),
            received: n("received"),
            tx_errors: n("tx_errors"),
            commands_refused: n("commands_refused"),
            fault_lost: n("fault_lost"),
            fault_duplicated: n("fault_duplicated"),
            fault_delayed: n("fault_delayed"),
            rejected: by("rejected"),
            dropped_bytes: n("dropped_bytes"),
            overruns: n("overruns"),
            queue_dropped: by("queue_dropped"),
            missed: by("missed"),
        }
    }
}

impl Inner {
    fn snapshot(&self) -> arc_swap::Guard<Arc<Subs>> {
        self.subs.load()
    }

    fn update_subs(&self, f: impl FnOnce(&mut Vec<Sub>)) {
        let _changing = self.subs_changing.lock().unwrap_or_else(|p| p.into_inner());
        let mut subs: Vec<Sub> = self
            .subs
            .load()
            .list
            .iter()
            .map(|s| Sub {
                id: s.id,
                patterns: s.patterns.clone(),
                queue: s.queue.clone(),
            })
            .collect();
        f(&mut subs);
        self.subs.store(Arc::new(Subs::new(subs)));
    }

    /// Registers a task so that closing the medium stops it (at once when already closed).
    pub(crate) fn own_task(&self, handle: AbortHandle) {
        let mut tasks = self.tasks.lock().unwrap_or_else(|p| p.into_inner());
        if self.closed.load(Ordering::Acquire) {
            handle.abort();
        } else {
            tasks.push(handle);
        }
    }

    fn next_seq(&self) -> u64 {
        self.seq.fetch_add(1, Ordering::Relaxed) + 1
    }

    fn closed_error(&self) -> SendError {
        SendError::Closed(self.name.to_string())
    }

    /// Sends a message from a local interface (`from`), through the fault stage when there is one.
    /// With `wait`, a full command queue holds the sender back; without, the command is refused.
    /// `fresh`: this medium has just numbered the message (a publication, not a forwarded one).
    async fn send(
        self: &Arc<Self>,
        msg: Message,
        from: u64,
        wait: bool,
        fresh: bool,
    ) -> Result<(), SendError> {
        if self.closed.load(Ordering::Acquire) {
            return Err(self.closed_error());
        }
        if self.faults.is_none() && self.transport.get().is_none() {
            // in-process: handed out at once, waiting only for room in full command queues
            self.counters.published.fetch_add(1, Ordering::Relaxed);
            let check = self.check(&msg, fresh);
            let blocked = self.fan_out(msg, Some(from), wait, check);
            if !blocked.is_empty() {
                self.wait_for_room(blocked, check).await;
            }
            return Ok(());
        }
        let (msg, frame) = match self.transport.get() {
            Some(t) => {
                let frame = t.encode(&msg)?;
                // the local copy is handed out at once (a fault stage may hand it out later, to
                // whoever subscribes meanwhile): with nobody else here subscribed, there is none
                let local = if self.faults.is_none() && !self.others_subscribe(from) {
                    None
                } else {
                    t.local_copy(msg, &frame)
                };
                (local, Some(frame))
            }
            None => (Some(msg), None),
        };
        self.counters.published.fetch_add(1, Ordering::Relaxed);
        match &self.faults {
            Some(f) => f.apply(self, msg, frame, from, wait).await,
            None => self.dispatch(msg, frame, Some(from), wait, fresh).await,
        }
    }

    /// Whether any local interface but `from` subscribes to anything.
    fn others_subscribe(&self, from: u64) -> bool {
        self.subs
            .load()
            .list
            .iter()
            .any(|s| s.id != from && !s.patterns.is_empty())
    }

    /// How the queues check `msg` for duplicates. One this medium has just numbered (`fresh`)
    /// cannot be one. Without a fault stage (which may hand a message out twice, or late), every
    /// message of this medium's own numbering was handed out when it was numbered, so a later
    /// sighting — back through a bridge, or from the wire — is one. Any other goes through the
    /// queues' windows.
    fn check(&self, msg: &Message, fresh: bool) -> Check {
        if fresh {
            Check::Fresh
        } else if self.faults.is_none() && msg.provenance.origin.id == self.origin.id {
            Check::Echo
        } else {
            Check::Window
        }
    }

    /// Puts a message into the queue of every matching local interface but `from`, without
    /// waiting. Commands that met a full queue are handed back when the sender may `wait` for
    /// room, and refused and counted otherwise (forwarded, or read from the wire).
    fn fan_out(
        &self,
        msg: Message,
        from: Option<u64>,
        wait: bool,
        check: Check,
    ) -> Vec<(Arc<Queue>, Message)> {
        let subs = self.snapshot();
        let mut blocked = Vec::new();
        let mut delivered = 0u64;
        let mut put = |s: &Sub, m: Message| match s.queue.push(m, check) {
            Pushed::Queued | Pushed::DroppedOldest => delivered += 1,
            Pushed::Closed | Pushed::Duplicate => {}
            Pushed::Full(m) if wait => blocked.push((s.queue.clone(), m)),
            Pushed::Full(m) => {
                s.queue
                    .counters
                    .commands_refused
                    .fetch_add(1, Ordering::Relaxed);
                self.counters
                    .commands_refused
                    .fetch_add(1, Ordering::Relaxed);
                tracing::error!(
                    medium = %self.name,
                    topic = %m.topic,
                    origin = %m.provenance.origin,
                    "command refused: a receiver's command queue is full"
                );
            }
        };
        // every matching interface but the last gets a copy (sharing the payload); the last gets
        // the message itself
        let mut previous: Option<&Sub> = None;
        match subs.index() {
            None => {
                for s in subs.list.iter() {
                    if Some(s.id) == from || !s.wants(&msg) {
                        continue;
                    }
                    if let Some(p) = previous.replace(s) {
                        put(p, msg.clone());
                    }
                }
            }
            Some(index) => {
                let mut scratch = SCRATCH.take();
                index.matching(&msg.topic, msg.kind, &mut scratch);
                for &at in &scratch.found {
                    let s = &subs.list[at as usize];
                    if Some(s.id) == from {
                        continue;
                    }
                    if let Some(p) = previous.replace(s) {
                        put(p, msg.clone());
                    }
                }
                SCRATCH.set(scratch);
            }
        }
        if let Some(last) = previous {
            put(last, msg);
        }
        if delivered > 0 {
            self.counters
                .delivered
                .fetch_add(delivered, Ordering::Relaxed);
        }
        blocked
    }

    /// Puts commands that met full queues into them as room is made.
    async fn wait_for_room(&self, blocked: Vec<(Arc<Queue>, Message)>, check: Check) {
        for (queue, m) in blocked {
            if let Pushed::Queued = queue.push_wait(m, check).await {
                self.counters.delivered.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Hands the local copy of a message, if any, to local interfaces (all but `from`) and the frame
    /// to the wire. A local sender (`from` set) waits for room in full command queues; the wire's
    /// reader never waits.
    pub(crate) async fn dispatch(
        &self,
        msg: Option<Message>,
        frame: Option<Frame>,
        from: Option<u64>,
        wait: bool,
        fresh: bool,
    ) -> Result<(), SendError> {
        if self.closed.load(Ordering::Acquire) {
            return Err(self.closed_error());
        }
        if let Some(msg) = msg {
            let check = self.check(&msg, fresh);
            let blocked = self.fan_out(msg, from, wait, check);
            self.wait_for_room(blocked, check).await;
        }
        if let (Some(frame), Some(t)) = (frame, self.transport.get()) {
            match t.transmit(frame).await {
                Ok(()) => {
                    self.counters.transmitted.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    self.counters.tx_errors.fetch_add(1, Ordering::Relaxed);
                    return Err(e);
                }
            }
        }
        Ok(())
    }
}

/// The way into a medium for what its transport reads from the wire.
#[derive(Clone)]
pub struct Ingress {
    inner: Weak<Inner>,
}

impl Ingress {
    /// Delivers a message read from the wire to every matching local interface.
    /// Returns false once the medium is gone or closed, so the reader can stop.
    pub fn deliver(&self, msg: Message) -> bool {
        self.hand_out(msg, false)
    }

    /// [`Ingress::deliver`]; `fresh`: this medium has just numbered the message.
    fn hand_out(&self, msg: Message, fresh: bool) -> bool {
        let Some(inner) = self.inner.upgrade() else {
            return false;
        };
        if inner.closed.load(Ordering::Acquire) {
            return false;
        }
        inner.counters.received.fetch_add(1, Ordering::Relaxed);
        // from the wire nothing waits: a full command queue refuses
        let check = inner.check(&msg, fresh);
        inner.fan_out(msg, None, false, check);
        true
    }

    /// Delivers a message that starts on this medium (a frame from a wire without headers, such
    /// as a serial line): it gets this medium's origin and next sequence number.
    pub fn originate(&self, topic: Topic, payload: Payload) -> bool {
        self.originate_as(Kind::Data, topic, payload)
    }

    /// [`Ingress::originate`] for a message of `kind` (a command from a program that writes the
    /// wire without seabus's header but says what it sends).
    pub fn originate_as(&self, kind: Kind, topic: Topic, payload: Payload) -> bool {
        let Some(inner) = self.inner.upgrade() else {
            return false;
        };
        let msg = Message {
            topic,
            kind,
            provenance: Provenance {
                origin: inner.origin.clone(),
                seq: inner.next_seq(),
                hops: 0,
            },
            stamp: Stamp::now(),
            payload,
        };
        self.hand_out(msg, true)
    }

    /// True while the medium exists and is open.
    pub fn is_open(&self) -> bool {
        self.inner
            .upgrade()
            .is_some_and(|i| !i.closed.load(Ordering::Acquire))
    }

    /// Counts an input rejected from the wire and logs it (the first of each reason in 10 s, then
    /// the next with the count of those not logged: [`Tally`]).
    pub fn reject(&self, reason: &str, detail: impl fmt::Display) {
        if let Some(inner) = self.inner.upgrade() {
            inner.rejected.record(
                &inner.name,
                reason,
                format_args!("rejected input: {detail}"),
            );
        }
    }

    /// Counts a send that failed after the sender was told it was on its way (one from a queue of
    /// datagrams) as a transmit error, and logs it (the first in 10 s, then the next with the count
    /// of those not logged).
    pub fn send_failed(&self, detail: impl fmt::Display) {
        self.tx_failed(1, |held| format!("not sent: {detail}{held}"));
    }

    /// Counts `n` transmit errors and logs `say(held)` (the first in 10 s, then the next with the
    /// count of those not logged, `held`).
    fn tx_failed(&self, n: u64, say: impl FnOnce(&crate::tally::Held) -> String) {
        if let Some(inner) = self.inner.upgrade() {
            inner.counters.tx_errors.fetch_add(n, Ordering::Relaxed);
            let held = inner
                .send_failures
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .admit(std::time::Instant::now());
            if let Some(held) = held {
                tracing::warn!(medium = %inner.name, "{}", say(&held));
            }
        }
    }

    /// Counts `n` messages that were on their way out when the link was lost (its peer never had
    /// them) as transmit errors, and logs it (rate-limited as [`Ingress::send_failed`] is).
    pub fn lost_with_link(&self, n: u64) {
        self.tx_failed(n, |held| {
            format!("{n} message(s) on their way out were lost with the link{held}")
        });
    }

    /// Counts `bytes` read from the wire that went into no message (see
    /// [`MediumStats::dropped_bytes`]).
    pub fn dropped(&self, bytes: u64) {
        if let Some(inner) = self.inner.upgrade() {
            inner
                .counters
                .dropped_bytes
                .fetch_add(bytes, Ordering::Relaxed);
        }
    }

    /// Counts `n` characters the device lost before they were read (see
    /// [`MediumStats::overruns`]); a burst of them is logged once it ends.
    pub fn overrun(&self, n: u64) {
        if let Some(inner) = self.inner.upgrade() {
            inner.losses.overrun(n);
        }
    }

    /// Counts `n` messages of `topic` that were sent and never arrived (see
    /// [`MediumStats::missed`]); a burst of them is logged once it ends.
    pub fn missed(&self, topic: &str, n: u64) {
        if let Some(inner) = self.inner.upgrade() {
            inner.losses.missed(topic, n);
        }
    }

    /// Sets the state the link starts in, without logging it (a transport that has not reached its
    /// wire yet starts down).
    pub fn init_link(&self, state: LinkState) {
        if let Some(inner) = self.inner.upgrade() {
            inner.link.send_replace(state);
        }
    }

    /// Sets the link state (logged on change).
    pub fn set_link(&self, state: LinkState) {
        let Some(inner) = self.inner.upgrade() else {
            return;
        };
        inner.link.send_if_modified(|cur| {
            if *cur == state {
                return false;
            }
            match &state {
                LinkState::Up => tracing::info!(medium = %inner.name, "link up"),
                // a medium closing (the system stopping) loses its wire as it should
                LinkState::Down(why) if inner.closed.load(Ordering::Acquire) => {
                    tracing::debug!(medium = %inner.name, "link down while closing: {why}")
                }
                LinkState::Down(why) => tracing::warn!(medium = %inner.name, "link down: {why}"),
            }
            *cur = state;
            true
        });
    }

    /// Registers an I/O task so that closing the medium stops it.
    pub fn own_task(&self, handle: AbortHandle) {
        match self.inner.upgrade() {
            Some(inner) => inner.own_task(handle),
            None => handle.abort(),
        }
    }
}

/// Something that names a topic: `&str`, `String` or [`Topic`].
pub trait IntoTopic {
    /// Converts, checking the name.
    fn into_topic(self) -> Result<Topic, TopicError>;
}

impl IntoTopic for Topic {
    fn into_topic(self) -> Result<Topic, TopicError> {
        Ok(self)
    }
}

impl IntoTopic for &Topic {
    fn into_topic(self) -> Result<Topic, TopicError> {
        Ok(self.clone())
    }
}

impl IntoTopic for &str {
    fn into_topic(self) -> Result<Topic, TopicError> {
        Topic::new(self)
    }
}

impl IntoTopic for String {
    fn into_topic(self) -> Result<Topic, TopicError> {
        Topic::new(&self)
    }
}

impl IntoTopic for &String {
    fn into_topic(self) -> Result<Topic, TopicError> {
        Topic::new(self)
    }
}

#[derive(Default)]
struct IfaceCounters {
    received: u64,
    conversion_errors: u64,
}

/// A snapshot of an interface's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InterfaceStats {
    /// Messages handed to the module.
    pub received: u64,
    /// Messages waiting in the queues.
    pub pending: u64,
    /// Data messages dropped because the queue was full (oldest first).
    pub dropped_oldest: u64,
    /// Commands from the wire refused because the command queue was full.
    pub commands_refused: u64,
    /// Duplicates dropped (same origin and sequence number seen before).
    pub duplicates: u64,
    /// Messages older than the duplicate window, dropped.
    pub late: u64,
    /// Messages dropped because they could not be converted to the accepted format.
    pub conversion_errors: u64,
}

/// A module's attachment to a medium, in passive mode: the module polls ([`Interface::recv`],
/// [`Interface::try_recv`]) and pushes ([`Interface::send`], [`Interface::command`]).
/// The runtime of `seabus-modules` builds the active mode on it: it calls a module's handlers with
/// what arrives and when the module's timers fire.
pub struct Interface {
    medium: Medium,
    id: u64,
    label: Arc<str>,
    queue: Arc<Queue>,
    patterns: Vec<Subscription>,
    accept: Option<Format>,
    counters: IfaceCounters,
    /// a batch taken from the queue, read before the queue is looked at again
    batch: VecDeque<Message>,
}

/// Why [`Interface::try_recv`] returned nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum TryRecvError {
    /// Nothing is waiting.
    #[error("nothing waiting")]
    Empty,
    /// The medium was closed and everything was read.
    #[error("medium closed")]
    Closed,
}

impl Interface {
    /// The medium this interface is attached to.
    pub fn medium(&self) -> &Medium {
        &self.medium
    }

    /// The label given at attach time (the module's name).
    pub fn label(&self) -> &str {
        &self.label
    }

    /// The format this interface hands out, `None` for "as sent".
    pub fn accept(&self) -> Option<Format> {
        self.accept
    }

    /// States the one format this interface's receiver accepts; payloads are converted to it.
    pub fn set_accept(&mut self, format: Option<Format>) {
        self.accept = format;
    }

    /// Builder form of [`Interface::set_accept`].
    pub fn accepting(mut self, format: Format) -> Self {
        self.accept = Some(format);
        self
    }

    /// Adds a subscription. Messages matching any subscription are received, data and commands alike.
    pub fn subscribe(&mut self, pattern: &str) -> Result<(), TopicError> {
        self.subscribe_kind(pattern, None)
    }

    /// Adds a subscription to one kind of message (`None`: both).
    pub fn subscribe_kind(&mut self, pattern: &str, kind: Option<Kind>) -> Result<(), TopicError> {
        let sub = (Pattern::new(pattern)?, kind);
        if !self.patterns.contains(&sub) {
            if let Some(t) = self.medium.inner.transport.get() {
                t.subscribed(&sub.0);
            }
            self.patterns.push(sub);
            self.publish_patterns();
        }
        Ok(())
    }

    /// Builder form of [`Interface::subscribe`].
    pub fn subscribed(mut self, pattern: &str) -> Result<Self, TopicError> {
        self.subscribe(pattern)?;
        Ok(self)
    }

    /// Removes the subscriptions to `pattern`; returns false when there was none.
    pub fn unsubscribe(&mut self, pattern: &str) -> bool {
        let before = self.patterns.len();
        self.patterns.retain(|(p, _)| p.as_str() != pattern);
        let removed = self.patterns.len() != before;
        if removed {
            self.publish_patterns();
        }
        removed
    }

    /// The current subscriptions.
    pub fn subscriptions(&self) -> &[Subscription] {
        &self.patterns
    }

    fn publish_patterns(&self) {
        let patterns: Arc<[Subscription]> = Arc::from(self.patterns.clone());
        let id = self.id;
        self.medium.inner.update_subs(|subs| {
            if let Some(s) = subs.iter_mut().find(|s| s.id == id) {
                s.patterns = patterns;
            }
        });
    }

    /// Publishes data on `topic`.
    pub async fn send(
        &self,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<(), SendError> {
        self.publish(Kind::Data, topic, payload).await
    }

    /// Publishes a command on `topic`. Waits while a local receiver's command queue is full.
    pub async fn command(
        &self,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<(), SendError> {
        self.publish(Kind::Command, topic, payload).await
    }

    /// Publishes a new message of `kind` from this node.
    pub async fn publish(
        &self,
        kind: Kind,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<(), SendError> {
        self.publish_numbered(kind, topic, payload)
            .await
            .map(|_| ())
    }

    /// Publishes like [`publish`](Self::publish) and returns the message's sequence number, which
    /// with the medium's [`origin`](Medium::origin) names it (drivers quote both in
    /// acknowledgements).
    pub async fn publish_numbered(
        &self,
        kind: Kind,
        topic: impl IntoTopic,
        payload: impl Into<Payload>,
    ) -> Result<u64, SendError> {
        let inner = &self.medium.inner;
        let seq = inner.next_seq();
        let msg = Message {
            topic: topic.into_topic()?,
            kind,
            provenance: Provenance {
                origin: inner.origin.clone(),
                seq,
                hops: 0,
            },
            stamp: Stamp::now(),
            payload: payload.into(),
        };
        inner.send(msg, self.id, true, true).await.map(|()| seq)
    }

    /// Sends a message that already has a provenance (a bridge forwarding it), keeping it. A
    /// forwarded command never waits for room: like one read from the wire, it is refused and
    /// counted when a receiver's command queue is full (so bridges can never wait on each other).
    pub async fn forward(&self, msg: Message) -> Result<(), SendError> {
        self.medium.inner.send(msg, self.id, false, false).await
    }

    /// Sends a copy of a message a bridge has already forwarded into this medium under another
    /// route (a second name, other fields): numbered anew as this medium's own, so that receivers,
    /// which take one origin's number once, take it too; its stamp and hops are kept. Returns its
    /// sequence number (its origin is the medium's [`origin`](Medium::origin)).
    pub async fn forward_anew(&self, mut msg: Message) -> Result<u64, SendError> {
        let inner = &self.medium.inner;
        let seq = inner.next_seq();
        msg.provenance.origin = inner.origin.clone();
        msg.provenance.seq = seq;
        inner.send(msg, self.id, false, true).await.map(|()| seq)
    }

    /// Waits for the next message; `None` once the medium is closed and the queue drained.
    pub async fn recv(&mut self) -> Option<Message> {
        std::future::poll_fn(|cx| self.poll_recv(cx)).await
    }

    /// Takes the next message if one is waiting.
    pub fn try_recv(&mut self) -> Result<Message, TryRecvError> {
        loop {
            // closed before the look: every push made before the close is in, so finding
            // nothing is the end
            let closed = self.queue.is_closed();
            match self.queue.next(&mut self.batch) {
                Some(m) => {
                    if let Some(m) = self.admit(m) {
                        return Ok(m);
                    }
                }
                None if closed => return Err(TryRecvError::Closed),
                None => return Err(TryRecvError::Empty),
            }
        }
    }

    /// Polls for the next message (for code that waits on several interfaces at once).
    pub fn poll_recv(&mut self, cx: &mut Context<'_>) -> Poll<Option<Message>> {
        loop {
            match self.queue.poll_next(cx, &mut self.batch) {
                Poll::Ready(Some(m)) => {
                    if let Some(m) = self.admit(m) {
                        return Poll::Ready(Some(m));
                    }
                }
                other => return other,
            }
        }
    }

    /// Converts to the accepted format; `None` when the message cannot be taken in it.
    fn admit(&mut self, mut m: Message) -> Option<Message> {
        if let Some(f) = self.accept
            && m.payload.format() != f
        {
            match m.payload.convert(f) {
                Ok(p) => m.payload = p,
                Err(e) => {
                    self.counters.conversion_errors += 1;
                    tracing::warn!(
                        interface = %self.label,
                        medium = %self.medium.name(),
                        topic = %m.topic,
                        origin = %m.provenance.origin,
                        "dropped a {} message this interface cannot take as {f}: {e}",
                        m.payload.format()
                    );
                    return None;
                }
            }
        }
        self.counters.received += 1;
        Some(m)
    }

    /// This interface's counters.
    pub fn stats(&self) -> InterfaceStats {
        InterfaceStats {
            received: self.counters.received,
            pending: (self.queue.len() + self.batch.len()) as u64,
            dropped_oldest: self.queue.counters.dropped_oldest.load(Ordering::Relaxed),
            commands_refused: self.queue.counters.commands_refused.load(Ordering::Relaxed),
            duplicates: self.queue.counters.duplicates.load(Ordering::Relaxed),
            late: self.queue.counters.late.load(Ordering::Relaxed),
            conversion_errors: self.counters.conversion_errors,
        }
    }
}

impl Drop for Interface {
    fn drop(&mut self) {
        let id = self.id;
        self.queue.close();
        self.medium
            .inner
            .update_subs(|subs| subs.retain(|s| s.id != id));
    }
}

impl fmt::Debug for Interface {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Interface")
            .field("label", &self.label)
            .field("medium", &self.medium.name())
            .field("subscriptions", &self.patterns)
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_keep_their_type_and_bytes_need_no_allocation_of_their_own() {
        let bytes = Bytes::from_static(b"frame");
        let f = Frame::of(bytes.clone());
        assert!(matches!(&f, Frame::Bytes(b) if *b == bytes));
        assert_eq!(f.as_ref::<Bytes>(), Some(&bytes));
        assert_eq!(f.as_ref::<u32>(), None);
        assert_eq!(f.clone().into::<Bytes>(), Some(bytes));
        assert_eq!(f.into::<u32>(), None, "a frame of another type");
        let other = Frame::of(7u32);
        assert!(matches!(other, Frame::Other(_)));
        assert_eq!(other.as_ref::<u32>(), Some(&7));
        let copy = other.clone();
        assert_eq!(other.into::<u32>(), Some(7));
        assert_eq!(copy.into::<u32>(), Some(7), "a copy the fault stage made");
        assert_eq!(Frame::of(7u32).into::<Bytes>(), None);
    }

    #[test]
    fn one_shared_value_per_type_and_medium() {
        #[derive(Default)]
        struct Count(AtomicU64);
        let node = Node::new("n");
        let a = Medium::in_process("a", &node);
        a.shared::<Count>().0.fetch_add(1, Ordering::Relaxed);
        a.clone()
            .shared::<Count>()
            .0
            .fetch_add(1, Ordering::Relaxed);
        assert_eq!(a.shared::<Count>().0.load(Ordering::Relaxed), 2);
        assert_eq!(*a.shared::<Mutex<String>>().lock().unwrap(), "");
        let b = Medium::in_process("b", &node);
        assert_eq!(b.shared::<Count>().0.load(Ordering::Relaxed), 0);
    }

    #[tokio::test]
    async fn many_subscriptions_are_indexed_and_deliver_as_few_do() {
        // a message goes to the same interfaces whether the medium tries each pattern or looks
        // the topic up in its index (more than SCAN_UP_TO subscriptions)
        let node = Node::new("n");
        let bus = Medium::in_process("bus", &node);
        let sender = bus.attach("sender");
        let mut wanted = Vec::new();
        for (p, k) in [
            ("nav.attitude", None),
            ("nav.**", None),
            ("nav.*", Some(Kind::Data)),
            ("*.attitude", None),
            ("cmd.**", Some(Kind::Command)),
            ("**", Some(Kind::Command)),
        ] {
            let mut port = bus.attach(p);
            port.subscribe_kind(p, k).unwrap();
            wanted.push(port);
        }
        let mut idle: Vec<Interface> = (0..20)
            .map(|i| {
                let mut port = bus.attach(&format!("idle{i}"));
                port.subscribe(&format!("other{i}.**")).unwrap();
                port.subscribe(&format!("x.other{i}")).unwrap();
                port
            })
            .collect();
        assert!(bus.inner.snapshot().index().is_some(), "indexed");
        let mut nav = bus.attach("nav-sender");
        nav.subscribe("nav.attitude").unwrap();
        nav.send("nav.attitude", DataMap::new().with("yaw", 1.0))
            .await
            .unwrap();
        sender
            .command("cmd.course", DataMap::new().with("heading", 2.0))
            .await
            .unwrap();
        sender
            .send("power.battery", DataMap::new().with("v", 3.0))
            .await
            .unwrap();
        let got: Vec<Vec<String>> = wanted
            .iter_mut()
            .map(|p| {
                std::iter::from_fn(|| p.try_recv().ok())
                    .map(|m| m.topic.as_str().to_string())
                    .collect()
            })
            .collect();
        let want: Vec<Vec<&str>> = vec![
            vec!["nav.attitude"],
            vec!["nav.attitude"],
            vec!["nav.attitude"],
            vec!["nav.attitude"],
            vec!["cmd.course"],
            vec!["cmd.course"],
        ];
        assert_eq!(got, want);
        assert!(nav.try_recv().is_err(), "not back to its sender");
        assert!(idle.iter_mut().all(|p| p.try_recv().is_err()));
    }

    #[tokio::test]
    async fn a_message_of_this_mediums_numbering_seen_again_is_a_duplicate() {
        // what a medium numbers is handed out once, unchecked; the same message back (through a
        // bridge that forwards it home, or from the wire) is dropped and counted as a duplicate,
        // while one of another medium's numbering goes through the receivers' windows
        let node = Node::new("n");
        let bus = Medium::in_process("bus", &node);
        let other = Medium::in_process("other", &node);
        let tx = bus.attach("tx");
        let bridge = bus.attach("bridge");
        let mut rx = bus.attach("rx").subscribed("**").unwrap();
        let mut there = other.attach("there").subscribed("**").unwrap();
        for i in 0..3i64 {
            tx.send("d", DataMap::new().with("i", i)).await.unwrap();
        }
        let mine: Vec<Message> = (0..3).map(|_| rx.try_recv().unwrap()).collect();
        for m in &mine {
            bridge.forward(m.clone()).await.unwrap();
        }
        assert_eq!(rx.try_recv().unwrap_err(), TryRecvError::Empty);
        assert_eq!(rx.stats().duplicates, 3);
        // another medium's message: new once, then a duplicate by the window
        other.attach("o").send("e", DataMap::new()).await.unwrap();
        let foreign = there.try_recv().unwrap();
        bridge.forward(foreign.clone()).await.unwrap();
        assert_eq!(rx.try_recv().unwrap().provenance, foreign.provenance);
        bridge.forward(foreign).await.unwrap();
        assert_eq!(rx.try_recv().unwrap_err(), TryRecvError::Empty);
        assert_eq!(rx.stats().duplicates, 4);
        // a fresh message from the wire side (a frame without a header) is handed out
        bus.ingress()
            .originate(Topic::new("w").unwrap(), DataMap::new().into());
        assert_eq!(rx.try_recv().unwrap().provenance.seq, 4);
    }

    #[tokio::test]
    async fn a_topic_sent_again_reaches_whoever_subscribes_meanwhile_and_not_who_left() {
        let bus = Medium::in_process("bus", &Node::new("n"));
        let tx = bus.attach("tx");
        let depth = Topic::new("nav.depth").unwrap();
        let data = || DataMap::new().with("m", 3.5);
        let mut a = bus.attach("a").subscribed("nav.*").unwrap();
        tx.send(&depth, data()).await.unwrap();
        assert!(a.try_recv().is_ok());
        let mut b = bus.attach("b");
        b.subscribe_kind("nav.depth", Some(Kind::Command)).unwrap();
        tx.send(&depth, data()).await.unwrap();
        assert!(a.try_recv().is_ok());
        assert!(b.try_recv().is_err(), "b takes commands only");
        tx.command(&depth, data()).await.unwrap();
        assert_eq!(a.try_recv().unwrap().kind, Kind::Command);
        assert_eq!(b.try_recv().unwrap().kind, Kind::Command);
        assert!(a.unsubscribe("nav.*"));
        tx.send(&depth, data()).await.unwrap();
        assert!(a.try_recv().is_err(), "a left");
        // the same name made apart is the same topic; another is not
        b.subscribe("nav.depth").unwrap();
        tx.send(Topic::new("nav.depth").unwrap(), data())
            .await
            .unwrap();
        assert_eq!(b.try_recv().unwrap().topic, depth);
        tx.send("nav.depths", data()).await.unwrap();
        assert!(b.try_recv().is_err());
        drop(b);
        tx.send(&depth, data()).await.unwrap();
        assert_eq!(bus.stats().delivered, 5);
    }

    #[test]
    fn a_receiver_that_parks_is_woken_by_every_push_from_another_thread() {
        // the receiver keeps catching up and waiting on one runtime while a thread of its own
        // publishes, pausing now and then: a push that misses a waiting receiver leaves it
        // asleep with messages waiting, and it has not taken them all 5 s after the last
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let bus = Medium::in_process("bus", &Node::new("n"));
        let n = 20_000u64;
        let mut port = bus
            .attach_with("rx", n as usize, 16)
            .subscribed("t")
            .unwrap();
        let receiver = rt.spawn(async move {
            let mut got = 0u64;
            while got < n {
                let Some(m) = port.recv().await else { break };
                got += 1;
                assert_eq!(m.provenance.seq, got, "in order, none lost");
            }
            got
        });
        let publisher = bus.attach("tx");
        std::thread::spawn(move || {
            let local = tokio::runtime::Builder::new_current_thread()
                .build()
                .unwrap();
            local.block_on(async {
                for i in 0..n {
                    publisher
                        .send("t", Payload::from(Vec::new()))
                        .await
                        .unwrap();
                    if i % 64 == 0 {
                        std::thread::yield_now();
                    }
                    if i % 2_000 == 0 {
                        std::thread::sleep(std::time::Duration::from_millis(1));
                    }
                }
            });
        })
        .join()
        .unwrap();
        let got = rt.block_on(async {
            tokio::time::timeout(std::time::Duration::from_secs(5), receiver).await
        });
        assert_eq!(got.expect("every message taken").unwrap(), n);
    }
}
