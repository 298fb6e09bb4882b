//! The console's state shared by every connection, and every rule the server enforces.
//!
//! The hub reads the bus (the latest value of every topic, and `cmd.status` for
//! acknowledgements), holds the control lease, arms confirmed commands, runs dead-man commands
//! (neutral once when their re-sends stop, their connection closes or control is lost) and keeps
//! the command history. A connection ([`Client`]) asks it for everything; the page is never
//! trusted: commands are looked up in the layout the server itself sent that connection.
//!
//! The rooms: `lease` (who holds control), `commands` (arming, holding, dead-man commands,
//! building and publishing), `history` (pending commands matched to their acknowledgements, the
//! CSV command log), `pages` (what each page is sent: layouts, data) and `save` (the designer's
//! saves).

mod backlog;
mod commands;
mod history;
mod keep;
mod lease;
mod pages;
mod save;

pub use backlog::{SAMPLES, TOPICS};
pub use commands::{ARM_LIFETIME, ARMS_PER_CONNECTION, CommandError, DRIVE_PERIODS};
pub use history::{HISTORY, MAX_TEXT};
pub use keep::COMMANDED_TOPICS;
pub use lease::{CONTROL_TOPIC, LEASE_GRACE, LeaseError};
pub use save::SaveError;

use crate::auth::{Limiter, Session, Sessions};
use crate::layout::{Layout, Offers};
use crate::users::Users;
use backlog::Backlog;
use commands::{Arms, Drives};
use history::{Ack, History};
use keep::{Commanded, Keeps};
use lease::Lease;
use seabus_medium::topic::FLEET;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Interface, Kind, Pattern, Stamp, Topic, Value};
use serde_json::{Value as Json, json};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, SystemTime};
use tokio::sync::broadcast;
use tokio::time::Instant;

/// Password checks at once (each takes ~19 MiB for tens of milliseconds).
pub const PASSWORD_CHECKS: usize = 4;

/// Topics whose latest message the console keeps, at most: beyond, the eighth of them heard
/// from longest ago are forgotten (a page shows them again when they are next heard).
pub const LATEST_TOPICS: usize = 4096;

/// What a `<console>` element sets.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Where the server listens.
    pub listen: SocketAddr,
    /// How long a command waits for its acknowledgement.
    pub ack_timeout: Duration,
    /// The role that may take control.
    pub lease_role: String,
    /// The role that may edit and save layouts.
    pub designer_role: String,
    /// The CSV file every command is appended to.
    pub log: Option<PathBuf>,
    /// The layout files.
    pub layouts: Vec<PathBuf>,
    /// How far back the plotted and tracked variables are kept for pages that open a layout.
    pub history: Duration,
    /// The node the console runs on (the system's `node`): a fleet table leaves it out.
    pub node: Option<String>,
}

/// The latest message of a topic.
#[derive(Debug, Clone)]
struct Latest {
    stamp: f64,
    map: DataMap,
    version: u64,
}

/// Everything the hub's rules hold, under one lock.
#[derive(Default)]
struct State {
    latest: HashMap<Topic, Latest>,
    /// Counts the topics `latest` has taken in: a page works out what it wants of them again
    /// only when it changes.
    topics_known: u64,
    /// Topics forgotten to stay within [`LATEST_TOPICS`], and the warning saying so.
    forgotten: u64,
    forgetting: seabus_medium::tally::Limiter,
    version: u64,
    lease: Lease,
    history: History,
    arms: Arms,
    drives: Drives,
    commanded: Commanded,
    keeps: Keeps,
    backlog: Backlog,
    next_conn: u64,
}

impl State {
    /// Forgets the eighth of the kept topics heard from longest ago (one selection for every
    /// `LATEST_TOPICS / 8` new topics, however many there are).
    fn forget_stalest(&mut self) {
        let mut heard: Vec<(u64, Topic)> = self
            .latest
            .iter()
            .map(|(t, l)| (l.version, t.clone()))
            .collect();
        let n = LATEST_TOPICS / 8;
        heard.select_nth_unstable_by_key(n, |(v, _)| *v);
        for (_, t) in &heard[..n] {
            self.latest.remove(t);
        }
        self.forgotten += n as u64;
        if let Some(held) = self.forgetting.admit(std::time::Instant::now()) {
            tracing::warn!(
                component = "console",
                forgotten = self.forgotten,
                "more than {LATEST_TOPICS} topics heard: the {n} heard from longest ago are \
                 forgotten ({} so far){held}",
                self.forgotten
            );
        }
    }
}

/// The console's shared state.
pub struct Hub {
    /// The console's settings.
    pub settings: Settings,
    /// Who may log in.
    pub users: Users,
    /// Live sessions.
    pub sessions: Sessions,
    /// Failed log-ins.
    pub limiter: Limiter,
    /// Password checks running at once, at most [`PASSWORD_CHECKS`].
    pub checks: tokio::sync::Semaphore,
    port: Interface,
    origin: String,
    produced: Vec<Pattern>,
    state: Mutex<State>,
    /// Held while a command is decided and published: one at a time, so that nothing decided
    /// before a command ended goes out after what ended it.
    sending: tokio::sync::Mutex<()>,
    events: broadcast::Sender<Arc<str>>,
    /// Layout files as last read without variables, with the time they were modified.
    layouts: Mutex<LayoutCache>,
}

/// Layouts read, by file: when the file was modified, and what reading it gave.
type LayoutCache = HashMap<PathBuf, (Option<SystemTime>, Result<Layout, FileError>)>;

/// One connection's view: its user, the layout it opened and what its controls offer.
pub struct Client {
    /// The connection's number.
    pub conn: u64,
    /// Who is connected.
    pub session: Session,
    /// The layout opened, as the server sent it.
    pub layout: Option<Layout>,
    /// What the layout's controls let a page put in each command (made when it is opened).
    offers: HashMap<String, Offers>,
    /// What the layout binds: topic patterns and the fields wanted (`None`: all).
    interest: Vec<(Pattern, Option<Vec<String>>)>,
    /// The topics seen that the layout binds, with the fields wanted of each (`None`: all),
    /// worked out from `interest` when the hub had taken in `wants_at` topics.
    wants: Vec<(Topic, Option<Vec<String>>)>,
    wants_at: Option<u64>,
    /// The data version last sent.
    seen: u64,
}

fn now_s() -> f64 {
    Stamp::now().as_secs_f64()
}

impl Hub {
    /// A hub sending on `port` (whose medium's origin names its commands); `produced` are the
    /// topics the system's modules declare.
    pub fn new(settings: Settings, users: Users, port: Interface, produced: Vec<Pattern>) -> Hub {
        let origin = port.medium().origin().to_string();
        let backlog = Backlog::new(settings.history);
        Hub {
            settings,
            users,
            sessions: Sessions::default(),
            limiter: Limiter::default(),
            checks: tokio::sync::Semaphore::new(PASSWORD_CHECKS),
            port,
            origin,
            produced,
            state: Mutex::new(State {
                backlog,
                ..State::default()
            }),
            sending: tokio::sync::Mutex::new(()),
            events: broadcast::channel(1024).0,
            layouts: Mutex::new(HashMap::new()),
        }
    }

    fn state(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Events for every connection (lease changes, commands), as JSON text.
    pub fn events(&self) -> broadcast::Receiver<Arc<str>> {
        self.events.subscribe()
    }

    fn broadcast(&self, v: &Json) {
        let _ = self.events.send(Arc::from(v.to_string()));
    }

    /// Registers a new connection of `session`'s user.
    pub fn connect(&self, session: Session) -> Client {
        let mut st = self.state();
        st.next_conn += 1;
        st.lease.connected(session.id);
        Client {
            conn: st.next_conn,
            session,
            layout: None,
            offers: HashMap::new(),
            interest: Vec::new(),
            wants: Vec::new(),
            wants_at: None,
            seen: 0,
        }
    }

    /// A connection closed: its dead-man commands go neutral; control waits [`LEASE_GRACE`].
    pub async fn disconnect(&self, client: &Client) {
        let stopped = {
            let mut st = self.state();
            st.lease.disconnected(client.session.id, Instant::now());
            st.drives.take(|k, _| k.0 == client.conn)
        };
        self.neutral(stopped, "the connection closed").await;
    }

    /// Drives whose re-sends stopped go neutral; commands unanswered for the acknowledgement
    /// timeout are timed out; control whose holder has been gone [`LEASE_GRACE`] is released.
    pub async fn watch(&self) {
        let now = Instant::now();
        let (stale, timed_out, lease_gone) = {
            let mut st = self.state();
            let stale = st.drives.stale(now);
            let timed_out = st.history.time_out(now, self.settings.ack_timeout);
            let released: Vec<(String, Vec<_>)> = st
                .lease
                .expire(now)
                .into_iter()
                .map(|(vehicle, holder)| {
                    // its kept commands end in `keep`, which sees no holder
                    let drives = st
                        .drives
                        .take(|_, d| d.session == holder.session && d.vehicle() == vehicle);
                    tracing::info!(component = "console", user = %holder.user, vehicle, "control released: disconnected");
                    (vehicle, drives)
                })
                .collect();
            (stale, timed_out, released)
        };
        self.neutral(stale, "re-sends stopped").await;
        for e in &timed_out {
            self.changed(e);
        }
        for (vehicle, released) in lease_gone {
            self.lease_changed(&vehicle).await;
            self.neutral(released, "control released").await;
        }
    }

    /// Takes in a message read from the bus.
    pub fn observe(&self, topic: &Topic, stamp: Stamp, map: &DataMap) {
        let ack = Ack::from_status(topic, map, &self.origin);
        if let Some(ack) = &ack {
            self.kept_answered(ack);
        }
        let changed = {
            let mut st = self.state();
            let changed = ack.and_then(|ack| st.history.acknowledge(&ack));
            st.version += 1;
            let version = st.version;
            st.backlog.record(topic, stamp.as_secs_f64(), map);
            let map = if topic.as_str() == FLEET {
                fleet_table(st.latest.get(topic).map(|l| &l.map), map)
            } else {
                map.clone()
            };
            let new = st
                .latest
                .insert(
                    topic.clone(),
                    Latest {
                        stamp: stamp.as_secs_f64(),
                        map,
                        version,
                    },
                )
                .is_none();
            if new {
                st.topics_known += 1;
                if st.latest.len() > LATEST_TOPICS {
                    st.forget_stalest();
                }
            }
            changed
        };
        if let Some(e) = changed {
            self.changed(&e);
        }
    }

    /// Reads the bus until it closes.
    pub async fn read(&self, mut port: Interface) {
        while let Some(msg) = port.recv().await {
            if let Some(map) = msg.payload.as_map() {
                if msg.kind == Kind::Command {
                    self.heard_command(&msg.topic, &msg.origin().to_string(), msg.seq(), map);
                }
                self.observe(&msg.topic, msg.stamp, map);
            }
        }
    }
}

/// Nodes a fleet table keeps, at most (those heard first).
pub const FLEET_NODES: usize = 256;

/// The fleet's table after `said` (one node's `seabus.fleet` message): each node's latest message
/// under its name, so a page shows every vehicle however many spoke since it was last sent data.
fn fleet_table(table: Option<&DataMap>, said: &DataMap) -> DataMap {
    let mut table = table.cloned().unwrap_or_default();
    let Some(node) = said.get("node").and_then(Value::as_str) else {
        return table;
    };
    if table.get(node).is_some() || table.len() < FLEET_NODES {
        table.insert(node.to_string(), said.clone());
    }
    table
}

/// Removes and returns the values of `map` that `pick` picks.
fn take_where<K: Clone + Eq + std::hash::Hash, V>(
    map: &mut HashMap<K, V>,
    pick: impl Fn(&K, &V) -> bool,
) -> Vec<V> {
    let keys: Vec<K> = map
        .iter()
        .filter(|(k, v)| pick(k, v))
        .map(|(k, _)| k.clone())
        .collect();
    keys.iter().filter_map(|k| map.remove(k)).collect()
}

/// A layout error for the page: file, line, column and message.
pub fn error_json(e: &FileError) -> Json {
    json!({
        "file": &*e.pos.file,
        "line": e.pos.line,
        "col": e.pos.col,
        "message": e.message,
        "text": e.to_string(),
    })
}

#[cfg(test)]
mod testing;
