//! The console's state shared by every connection, and every rule the server enforces.
//!
//! The hub reads the bus (the latest value of every topic, and `cmd.status` for
//! acknowledgements), holds the control lease, arms confirmed commands, runs dead-man commands
//! (neutral once when their re-sends stop, their connection closes or control is lost) and keeps
//! the command history. A connection ([`Client`]) asks it for everything; the page is never
//! trusted: commands are looked up in the layout the server itself sent that connection.

use crate::auth::{Limiter, Session, Sessions};
use crate::layout::{CommandDecl, Confirm, Layout};
use crate::users::Users;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Interface, Kind, Pattern, Stamp, Topic, Value};
use serde_json::{Value as Json, json};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::io::Write;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};
use tokio::sync::broadcast;

/// Commands kept in the history.
pub const HISTORY: usize = 200;
/// How long an armed command may wait for its send.
pub const ARM_LIFETIME: Duration = Duration::from_secs(10);
/// Confirmations one connection may have waiting.
pub const ARMS_PER_CONNECTION: usize = 8;
/// How long control stays with a holder whose connections have all closed.
pub const LEASE_GRACE: Duration = Duration::from_secs(10);
/// The longest text a refusal keeps of what a page sent.
pub const MAX_TEXT: usize = 256;
/// Password checks at once (each takes ~19 MiB for tens of milliseconds).
pub const PASSWORD_CHECKS: usize = 4;
/// Where the console publishes who holds control.
pub const CONTROL_TOPIC: &str = "console.control";
/// Dead-man re-sends may be this many periods late before the neutral command goes.
pub const DRIVE_PERIODS: u32 = 3;

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
}

/// The latest message of a topic.
#[derive(Debug, Clone)]
struct Latest {
    stamp: f64,
    map: DataMap,
    version: u64,
}

/// A command sent (or refused), as the history shows it.
#[derive(Debug, Clone)]
struct Entry {
    id: u64,
    user: String,
    time: f64,
    command: String,
    topic: String,
    fields: DataMap,
    state: String,
    reason: String,
    /// The bus sequence number, while an acknowledgement is awaited.
    seq: Option<u64>,
    sent: Instant,
}

impl Entry {
    fn json(&self) -> Json {
        json!({
            "type": "command",
            "id": self.id,
            "user": self.user,
            "time": self.time,
            "command": self.command,
            "topic": self.topic,
            "fields": self.fields,
            "state": self.state,
            "reason": self.reason,
        })
    }
}

/// A command armed for confirmation.
#[derive(Debug)]
struct Arm {
    conn: u64,
    layout: String,
    command: String,
    at: Instant,
}

/// A dead-man command being driven.
#[derive(Debug)]
struct Drive {
    user: String,
    name: String,
    topic: Topic,
    neutral: DataMap,
    period: Duration,
    /// The last re-send from the page.
    last: Instant,
    /// The last one published.
    sent: Instant,
}

#[derive(Default)]
struct State {
    latest: HashMap<Topic, Latest>,
    version: u64,
    lease: Option<(String, f64)>,
    /// Open connections per user, and when the last one of each closed.
    connections: HashMap<String, usize>,
    gone_since: HashMap<String, Instant>,
    history: VecDeque<Entry>,
    next_id: u64,
    arms: HashMap<u64, Arm>,
    next_arm: u64,
    drives: HashMap<(u64, String, String), Drive>,
    next_conn: u64,
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
    events: broadcast::Sender<Arc<str>>,
    /// Layout files as last read without variables, with the time they were modified.
    layouts: Mutex<LayoutCache>,
}

/// Layouts read, by file: when the file was modified, and what reading it gave.
type LayoutCache = HashMap<PathBuf, (Option<SystemTime>, Result<Layout, FileError>)>;

/// One connection's view: its user, the layout it opened and the values its inputs set.
pub struct Client {
    /// The connection's number.
    pub conn: u64,
    /// Who is connected.
    pub session: Session,
    /// The layout opened, as the server sent it.
    pub layout: Option<Layout>,
    /// The fields of each command as last set.
    values: HashMap<String, DataMap>,
    /// What the layout binds: topic patterns and the fields wanted (`None`: all).
    interest: Vec<(Pattern, Option<Vec<String>>)>,
    /// The data version last sent.
    seen: u64,
}

fn now_s() -> f64 {
    Stamp::now().as_secs_f64()
}

fn text(v: &Json) -> Arc<str> {
    Arc::from(v.to_string())
}

impl Hub {
    /// A hub sending on `port` (whose medium's origin names its commands); `produced` are the
    /// topics the system's modules declare.
    pub fn new(settings: Settings, users: Users, port: Interface, produced: Vec<Pattern>) -> Hub {
        let origin = port.medium().origin().to_string();
        Hub {
            settings,
            users,
            sessions: Sessions::default(),
            limiter: Limiter::default(),
            checks: tokio::sync::Semaphore::new(PASSWORD_CHECKS),
            port,
            origin,
            produced,
            state: Mutex::new(State::default()),
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
        let _ = self.events.send(text(v));
    }

    /// Registers a new connection of `session`'s user.
    pub fn connect(&self, session: Session) -> Client {
        let mut st = self.state();
        st.next_conn += 1;
        *st.connections.entry(session.user.clone()).or_default() += 1;
        st.gone_since.remove(&session.user);
        Client {
            conn: st.next_conn,
            session,
            layout: None,
            values: HashMap::new(),
            interest: Vec::new(),
            seen: 0,
        }
    }

    /// A connection closed: its dead-man commands go neutral; control waits [`LEASE_GRACE`].
    pub async fn disconnect(&self, client: &Client) {
        let stopped = {
            let mut st = self.state();
            let user = &client.session.user;
            if let Some(n) = st.connections.get_mut(user) {
                *n = n.saturating_sub(1);
                if *n == 0 {
                    st.connections.remove(user);
                    st.gone_since.insert(user.clone(), Instant::now());
                }
            }
            take_drives(&mut st, |k, _| k.0 == client.conn)
        };
        self.neutral(stopped, "the connection closed").await;
    }

    /// Layout file `path` read with `vars`; without variables it is read again only when the
    /// file has changed since (every connection lists every layout).
    fn load(&self, path: &Path, vars: &BTreeMap<String, String>) -> Result<Layout, FileError> {
        if !vars.is_empty() {
            return Layout::load(path, vars);
        }
        let modified = std::fs::metadata(path).and_then(|m| m.modified()).ok();
        let mut cache = self.layouts.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((when, read)) = cache.get(path)
            && modified.is_some()
            && *when == modified
        {
            return read.clone();
        }
        let read = Layout::load(path, vars);
        cache.insert(path.to_path_buf(), (modified, read.clone()));
        read
    }

    /// The `lease` message.
    pub fn lease_json(&self) -> Json {
        let st = self.state();
        lease_json(&st.lease)
    }

    /// The layouts `session`'s user may open: (name, title) or, for a file that does not read,
    /// its error.
    pub fn layouts_for(&self, session: &Session) -> Vec<Json> {
        let mut out = Vec::new();
        for path in &self.settings.layouts {
            match self.load(path, &BTreeMap::new()) {
                Ok(l) if l.visible_to(&session.roles) => {
                    out.push(json!({"name": l.name, "title": l.title}))
                }
                Ok(_) => {}
                Err(e) => out.push(json!({
                    "name": path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
                    "error": error_json(&e),
                })),
            }
        }
        out
    }

    /// The `hello` message for a new connection.
    pub fn hello(&self, client: &Client) -> Json {
        json!({
            "type": "hello",
            "user": client.session.user,
            "roles": client.session.roles,
            "layouts": self.layouts_for(&client.session),
            "lease": self.lease_json(),
            "lease_role": self.settings.lease_role,
            "designer_role": self.settings.designer_role,
        })
    }

    /// The `history` message.
    pub fn history(&self) -> Json {
        let st = self.state();
        let commands: Vec<Json> = st.history.iter().map(Entry::json).collect();
        json!({"type": "history", "commands": commands})
    }

    /// Whether a module declares producing `topic`, or data on it has been seen.
    fn produced(&self, topic: &str, st: &State) -> bool {
        self.produced.iter().any(|p| p.matches(topic))
            || Topic::new(topic).is_ok_and(|t| st.latest.contains_key(&t))
            || Pattern::new(topic).is_ok_and(|p| st.latest.keys().any(|t| p.matches(t.as_str())))
    }

    /// Opens layout `name` with `vars` for `client`: the `layout` message (with the layout, or the
    /// error that stops it loading).
    pub fn open(&self, client: &mut Client, name: &str, vars: &BTreeMap<String, String>) -> Json {
        for path in &self.settings.layouts {
            let layout = match self.load(path, vars) {
                Ok(l) => l,
                Err(e) => {
                    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
                    if stem.as_deref() == Some(name) {
                        return json!({"type": "layout", "name": name, "error": error_json(&e)});
                    }
                    continue;
                }
            };
            if layout.name != name {
                continue;
            }
            if !layout.visible_to(&client.session.roles) {
                break;
            }
            let mut interest: Vec<(Pattern, Option<Vec<String>>)> = Vec::new();
            let mut producers = serde_json::Map::new();
            {
                let st = self.state();
                for b in layout.bindings() {
                    producers.insert(b.topic.clone(), Json::Bool(self.produced(&b.topic, &st)));
                    let Ok(p) = Pattern::new(&b.topic) else {
                        continue;
                    };
                    match interest.iter_mut().find(|(q, _)| q.as_str() == p.as_str()) {
                        Some((_, fields)) => match (fields.as_mut(), &b.field) {
                            (Some(list), Some(f)) => list.push(f.clone()),
                            _ => *fields = None,
                        },
                        None => interest.push((p, b.field.clone().map(|f| vec![f]))),
                    }
                }
            }
            let message = json!({
                "type": "layout",
                "name": name,
                "layout": layout.to_json(),
                "producers": producers,
            });
            client.values = layout
                .commands
                .iter()
                .map(|(n, c)| (n.clone(), c.fields.clone()))
                .collect();
            client.interest = interest;
            client.seen = 0;
            client.layout = Some(layout);
            return message;
        }
        json!({"type": "error", "message": format!("no layout `{name}` for you")})
    }

    /// The `data` message with what changed since the client's last one, if anything did.
    pub fn data_for(&self, client: &mut Client) -> Option<Json> {
        if client.interest.is_empty() {
            return None;
        }
        let st = self.state();
        if st.version == client.seen {
            return None;
        }
        let mut topics = serde_json::Map::new();
        for (topic, latest) in &st.latest {
            if latest.version <= client.seen {
                continue;
            }
            let mut wanted: Option<DataMap> = None;
            for (p, fields) in &client.interest {
                if !p.matches(topic.as_str()) {
                    continue;
                }
                let out = wanted.get_or_insert_with(DataMap::new);
                match fields {
                    None => {
                        *out = latest.map.clone();
                        break;
                    }
                    Some(list) => {
                        for f in list {
                            if let Some(v) = latest.map.get(f) {
                                out.insert(f.clone(), v.clone());
                            }
                        }
                    }
                }
            }
            if let Some(fields) = wanted {
                topics.insert(
                    topic.to_string(),
                    json!({"stamp": latest.stamp, "fields": fields}),
                );
            }
        }
        client.seen = st.version;
        (!topics.is_empty()).then(|| json!({"type": "data", "topics": topics, "now": now_s()}))
    }

    /// Takes or releases control for `session`.
    pub async fn lease(&self, session: &Session, take: bool) -> Result<(), String> {
        let stopped = {
            let mut st = self.state();
            let holder = st.lease.as_ref().map(|(u, _)| u.clone());
            if take {
                if !session.has(&self.settings.lease_role) {
                    return Err(format!(
                        "taking control needs role {}",
                        self.settings.lease_role
                    ));
                }
                match holder {
                    Some(h) if h == session.user => return Ok(()),
                    Some(h) => return Err(format!("{h} has control; they must release it")),
                    None => st.lease = Some((session.user.clone(), now_s())),
                }
                Vec::new()
            } else {
                if holder.as_deref() != Some(&session.user) {
                    return Err("you do not have control".into());
                }
                st.lease = None;
                let user = session.user.clone();
                take_drives(&mut st, |_, d| d.user == user)
            }
        };
        tracing::info!(
            component = "console",
            user = %session.user,
            "{} control",
            if take { "took" } else { "released" }
        );
        self.lease_changed().await;
        self.neutral(stopped, "control released").await;
        Ok(())
    }

    /// Shows the lease to every page, and publishes it on the bus (`console.control`: `holder`,
    /// empty when free, and `since`) for modules that step back while someone has control.
    async fn lease_changed(&self) {
        let lease = self.state().lease.clone();
        self.broadcast(&lease_json(&lease));
        let (holder, since) = lease.unwrap_or_default();
        let map = DataMap::new().with("holder", holder).with("since", since);
        if let Err(e) = self.port.send(CONTROL_TOPIC, map).await {
            tracing::warn!(component = "console", "{CONTROL_TOPIC}: {e}");
        }
    }

    /// The declaration of `command` in the layout the client opened as `layout`.
    fn decl<'a>(
        client: &'a Client,
        layout: &str,
        command: &str,
    ) -> Result<&'a CommandDecl, String> {
        let l = client
            .layout
            .as_ref()
            .filter(|l| l.name == layout)
            .ok_or_else(|| format!("layout `{layout}` is not open"))?;
        l.commands
            .get(command)
            .ok_or_else(|| format!("layout `{layout}` has no command `{command}`"))
    }

    /// What stops `session` from sending `decl` now.
    fn allowed(&self, session: &Session, decl: &CommandDecl) -> Result<(), String> {
        let role = decl.role.as_deref().unwrap_or(&self.settings.lease_role);
        if !session.has(role) {
            return Err(format!("role {role} needed"));
        }
        if decl.lease {
            let st = self.state();
            match &st.lease {
                Some((u, _)) if *u == session.user => {}
                Some((u, _)) => return Err(format!("no control: {u} has it")),
                None => return Err("no control: take control first".into()),
            }
        }
        Ok(())
    }

    /// Arms a confirmed command; returns the arm id.
    pub fn arm(&self, client: &Client, layout: &str, command: &str) -> Result<u64, String> {
        let decl = Hub::decl(client, layout, command)?;
        self.allowed(&client.session, decl)?;
        if matches!(decl.confirm, Confirm::None) {
            return Err(format!("`{command}` needs no confirmation"));
        }
        let mut st = self.state();
        let now = Instant::now();
        st.arms
            .retain(|_, a| now.duration_since(a.at) < ARM_LIFETIME);
        if st.arms.values().filter(|a| a.conn == client.conn).count() >= ARMS_PER_CONNECTION {
            return Err("too many commands waiting for confirmation".into());
        }
        st.next_arm += 1;
        let id = st.next_arm;
        st.arms.insert(
            id,
            Arm {
                conn: client.conn,
                layout: layout.to_string(),
                command: command.to_string(),
                at: now,
            },
        );
        Ok(id)
    }

    /// Sends a command (`send`): checks everything, publishes it and records it. A refusal is
    /// recorded and shown to everyone too. Returns the command's id.
    pub async fn send(
        &self,
        client: &mut Client,
        layout: &str,
        command: &str,
        set: &DataMap,
        confirmed: Option<u64>,
    ) -> Result<u64, String> {
        let checked = self.checked(client, layout, command, set, confirmed);
        match checked {
            Ok((topic, fields)) => {
                client.values.insert(command.to_string(), fields.clone());
                self.publish(&client.session.user, command, &topic, fields)
                    .await
            }
            Err(reason) => {
                // a command the layout declares is refused in everyone's history; anything
                // else is only answered to the page that sent it
                if let Ok(decl) = Hub::decl(client, layout, command) {
                    self.record_refusal(&client.session.user, decl, set, &reason);
                }
                Err(reason)
            }
        }
    }

    /// The topic and full fields of a command the client may send now.
    fn checked(
        &self,
        client: &Client,
        layout: &str,
        command: &str,
        set: &DataMap,
        confirmed: Option<u64>,
    ) -> Result<(Topic, DataMap), String> {
        let decl = Hub::decl(client, layout, command)?;
        self.allowed(&client.session, decl)?;
        let hold = match decl.confirm {
            Confirm::None => None,
            Confirm::Dialog => Some(Duration::ZERO),
            Confirm::Hold(d) => Some(d),
        };
        if let Some(hold) = hold {
            let id = confirmed.ok_or("not confirmed")?;
            let mut st = self.state();
            let mine = st.arms.get(&id).is_some_and(|a| {
                a.conn == client.conn && a.layout == layout && a.command == command
            });
            let arm = st
                .arms
                .remove(&id)
                .filter(|_| mine)
                .ok_or("not confirmed: arm it first")?;
            let age = arm.at.elapsed();
            if age > ARM_LIFETIME {
                return Err("not confirmed: the confirmation expired".into());
            }
            if age < hold {
                return Err(format!(
                    "not confirmed: held {} ms of {} ms",
                    age.as_millis(),
                    hold.as_millis()
                ));
            }
        }
        let current = client.values.get(command).unwrap_or(&decl.fields);
        let fields = decl.build(current, set)?;
        Ok((decl.topic.clone(), fields))
    }

    /// Publishes a command and records it as pending.
    async fn publish(
        &self,
        user: &str,
        command: &str,
        topic: &Topic,
        fields: DataMap,
    ) -> Result<u64, String> {
        let seq = self
            .port
            .publish_numbered(Kind::Command, topic.clone(), fields.clone())
            .await
            .map_err(|e| format!("not sent: {e}"));
        let (state, reason, seq) = match seq {
            Ok(s) => ("pending", String::new(), Some(s)),
            Err(e) => ("refused", e, None),
        };
        let id = self.record(user, command, topic.as_str(), &fields, state, &reason, seq);
        tracing::info!(component = "console", user, command, topic = %topic, "command {id}: {state} {reason}");
        if seq.is_none() {
            return Err(reason);
        }
        Ok(id)
    }

    /// Records a refusal of a declared command; of what the page proposed, only the command's own
    /// fields are kept, and text no longer than [`MAX_TEXT`].
    fn record_refusal(&self, user: &str, decl: &CommandDecl, set: &DataMap, reason: &str) {
        let mut fields = DataMap::new();
        for (k, v) in set.iter() {
            if decl.fields.get(k).is_none() {
                continue;
            }
            let v = match v {
                Value::Str(t) if t.len() > MAX_TEXT => {
                    Value::from(t.chars().take(MAX_TEXT).collect::<String>())
                }
                Value::Bytes(_) | Value::List(_) | Value::Map(_) => Value::from("…"),
                other => other.clone(),
            };
            fields.insert(k.to_string(), v);
        }
        let reason: String = reason.chars().take(MAX_TEXT).collect();
        let command = decl.name.as_str();
        tracing::warn!(
            component = "console",
            user,
            command,
            "command refused: {reason}"
        );
        self.record(
            user,
            command,
            decl.topic.as_str(),
            &fields,
            "refused",
            &reason,
            None,
        );
    }

    #[allow(clippy::too_many_arguments)]
    fn record(
        &self,
        user: &str,
        command: &str,
        topic: &str,
        fields: &DataMap,
        state: &str,
        reason: &str,
        seq: Option<u64>,
    ) -> u64 {
        let entry = {
            let mut st = self.state();
            st.next_id += 1;
            let entry = Entry {
                id: st.next_id,
                user: user.to_string(),
                time: now_s(),
                command: command.to_string(),
                topic: topic.to_string(),
                fields: fields.clone(),
                state: state.to_string(),
                reason: reason.to_string(),
                seq,
                sent: Instant::now(),
            };
            st.history.push_back(entry.clone());
            // pending entries stay until answered, however old
            while st.history.len() > HISTORY {
                match st.history.iter().position(|e| e.seq.is_none()) {
                    Some(i) => {
                        st.history.remove(i);
                    }
                    None => break,
                }
            }
            entry
        };
        self.changed(&entry);
        entry.id
    }

    /// Shows an entry's new state to everyone and appends it to the command log.
    fn changed(&self, e: &Entry) {
        self.broadcast(&e.json());
        if let Some(path) = &self.settings.log {
            let cells = [
                format!("{:.3}", e.time),
                e.user.clone(),
                e.command.clone(),
                e.topic.clone(),
                seabus_medium::json::to_json(&e.fields).unwrap_or_default(),
                e.state.clone(),
                e.reason.clone(),
            ];
            let line = cells
                .iter()
                .map(|c| seabus_medium::csv::cell(&Value::from(c.as_str())))
                .collect::<Vec<_>>()
                .join(",");
            let written = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)
                .and_then(|mut f| writeln!(f, "{line}"));
            if let Err(err) = written {
                tracing::warn!(
                    component = "console",
                    "command log {}: {err}",
                    path.display()
                );
            }
        }
    }

    /// A dead-man command's re-send (`drive`).
    pub async fn drive(
        &self,
        client: &mut Client,
        layout: &str,
        command: &str,
        set: &DataMap,
    ) -> Result<(), String> {
        let decl = Hub::decl(client, layout, command)?;
        let Some(rate) = decl.rate_hz else {
            return Err(format!("`{command}` is not a dead-man command (no rate)"));
        };
        if !matches!(decl.confirm, Confirm::None) {
            return Err(format!("`{command}` needs confirmation"));
        }
        let (topic, fields) = match self.checked(client, layout, command, set, None) {
            Ok(x) => x,
            Err(reason) => {
                let key = (client.conn, layout.to_string(), command.to_string());
                let running = self.state().drives.contains_key(&key);
                // a refusal once, not at every re-send
                if !running {
                    self.record_refusal(&client.session.user, decl, set, &reason);
                }
                return Err(reason);
            }
        };
        let mut neutral = fields.clone();
        for (k, v) in decl.neutral.iter() {
            neutral.insert(k.to_string(), v.clone());
        }
        client.values.insert(command.to_string(), fields.clone());
        let key = (client.conn, layout.to_string(), command.to_string());
        let period = Duration::from_secs_f64(1.0 / rate.max(0.01));
        let now = Instant::now();
        let (first, due) = {
            let mut st = self.state();
            let previous = st.drives.get(&key).map(|d| d.sent);
            // re-sends faster than the command's rate keep it alive but are not all published
            let due = previous.is_none_or(|t| now.duration_since(t) >= period.mul_f64(0.8));
            st.drives.insert(
                key.clone(),
                Drive {
                    user: client.session.user.clone(),
                    name: command.to_string(),
                    topic: topic.clone(),
                    neutral: neutral.clone(),
                    period,
                    last: now,
                    sent: if due { now } else { previous.unwrap_or(now) },
                },
            );
            (previous.is_none(), due)
        };
        let sent = if first {
            // the history shows the start of a drive; re-sends are not acknowledged one by one
            self.publish(&client.session.user, command, &topic, fields)
                .await
                .map(|_| ())
        } else if due {
            self.port
                .command(topic.clone(), fields)
                .await
                .map_err(|e| format!("not sent: {e}"))
        } else {
            Ok(())
        };
        // stopped while this was being sent (released, control lost): its neutral may have gone
        // first, so it goes again after
        if due && !self.state().drives.contains_key(&key) {
            let stopped = Drive {
                user: client.session.user.clone(),
                name: command.to_string(),
                topic,
                neutral,
                period,
                last: now,
                sent: now,
            };
            self.neutral(vec![stopped], "stopped while sending").await;
        }
        sent
    }

    /// The end of a dead-man command (`release`): neutral once.
    pub async fn release(&self, client: &Client, layout: &str, command: &str) {
        let key = (client.conn, layout.to_string(), command.to_string());
        let stopped = {
            let mut st = self.state();
            take_drives(&mut st, |k, _| *k == key)
        };
        self.neutral(stopped, "released").await;
    }

    /// Sends each stopped drive's neutral command once.
    async fn neutral(&self, stopped: Vec<Drive>, why: &str) {
        for d in stopped {
            tracing::info!(component = "console", user = %d.user, command = %d.name, "neutral: {why}");
            let _ = self.publish(&d.user, &d.name, &d.topic, d.neutral).await;
        }
    }

    /// Drives whose re-sends stopped go neutral; commands unanswered for the acknowledgement
    /// timeout are timed out; control whose holder has been gone [`LEASE_GRACE`] is released.
    pub async fn watch(&self) {
        let now = Instant::now();
        let (stale, timed_out, lease_gone) = {
            let mut st = self.state();
            let stale = take_drives(&mut st, |_, d| {
                now.duration_since(d.last) > d.period * DRIVE_PERIODS
            });
            let mut timed_out = Vec::new();
            for e in st.history.iter_mut() {
                if e.seq.is_some() && now.duration_since(e.sent) > self.settings.ack_timeout {
                    e.seq = None;
                    e.state = "timed-out".into();
                    e.reason = format!(
                        "no acknowledgement within {} ms",
                        self.settings.ack_timeout.as_millis()
                    );
                    timed_out.push(e.clone());
                }
            }
            let gone = match &st.lease {
                Some((u, _)) => st
                    .gone_since
                    .get(u)
                    .is_some_and(|t| now.duration_since(*t) >= LEASE_GRACE),
                None => false,
            };
            let mut released = Vec::new();
            if gone && let Some((u, _)) = st.lease.take() {
                released = take_drives(&mut st, |_, d| d.user == u);
                tracing::info!(component = "console", user = %u, "control released: disconnected");
            }
            (stale, timed_out, gone.then_some(released))
        };
        self.neutral(stale, "re-sends stopped").await;
        for e in &timed_out {
            self.changed(e);
        }
        if let Some(released) = lease_gone {
            self.lease_changed().await;
            self.neutral(released, "control released").await;
        }
    }

    /// Takes in a message read from the bus.
    pub fn observe(&self, topic: &Topic, stamp: Stamp, map: &DataMap) {
        let mut changed = None;
        {
            let mut st = self.state();
            if topic.as_str() == "cmd.status"
                && map.get("origin").and_then(Value::as_str) == Some(self.origin.as_str())
                && let Some(seq) = map.get("request_seq").and_then(Value::as_i64)
            {
                let state = map.get("state").and_then(Value::as_str).unwrap_or("");
                let reason = ["reason", "error"]
                    .iter()
                    .filter_map(|k| map.get(k).and_then(Value::as_str))
                    .find(|r| !r.is_empty())
                    .unwrap_or("")
                    .to_string();
                let settled = matches!(state, "acknowledged" | "refused" | "timed-out");
                if let Some(e) = st
                    .history
                    .iter_mut()
                    .find(|e| e.seq.is_some_and(|s| s as i64 == seq))
                    && (settled || state != e.state)
                {
                    e.state = state.to_string();
                    e.reason = reason;
                    if settled {
                        e.seq = None;
                    }
                    changed = Some(e.clone());
                }
            }
            st.version += 1;
            let version = st.version;
            st.latest.insert(
                topic.clone(),
                Latest {
                    stamp: stamp.as_secs_f64(),
                    map: map.clone(),
                    version,
                },
            );
        }
        if let Some(e) = changed {
            self.changed(&e);
        }
    }

    /// Reads the bus until it closes.
    pub async fn read(&self, mut port: Interface) {
        while let Some(msg) = port.recv().await {
            if let Some(map) = msg.payload.as_map() {
                self.observe(&msg.topic, msg.stamp, map);
            }
        }
    }

    /// Saves a layout edited in the designer: it must read; the old file is kept as `.bak`.
    pub fn save(&self, session: &Session, name: &str, xml: &str) -> Result<(), Json> {
        if !session.has(&self.settings.designer_role) {
            return Err(
                json!({"message": format!("saving layouts needs role {}", self.settings.designer_role)}),
            );
        }
        let (path, old) = self
            .settings
            .layouts
            .iter()
            .find_map(|p| {
                self.load(p, &BTreeMap::new())
                    .ok()
                    .filter(|l| l.name == name && l.visible_to(&session.roles))
                    .map(|l| (p, l))
            })
            .ok_or_else(|| json!({"message": format!("no layout `{name}` for you")}))?;
        let file = path.display().to_string();
        let layout = Layout::parse(&file, xml, &BTreeMap::new()).map_err(|e| error_json(&e))?;
        // what may be sent and by whom is for those who may take control, not for designers alone
        let json = (old.to_json(), layout.to_json());
        let rules_changed = json.0["commands"] != json.1["commands"] || old.roles != layout.roles;
        if rules_changed && !session.has(&self.settings.lease_role) {
            return Err(json!({"message": format!(
                "changing a layout's commands or roles needs role {}",
                self.settings.lease_role
            )}));
        }
        if layout.name != name {
            return Err(
                json!({"message": format!("the layout is called `{}`, not `{name}`", layout.name)}),
            );
        }
        let io = |e: std::io::Error| json!({"message": format!("{file}: {e}")});
        let bak = PathBuf::from(format!("{file}.bak"));
        std::fs::copy(path, &bak).map_err(io)?;
        seabus_medium::fs::atomic_write(path, xml.as_bytes()).map_err(io)?;
        tracing::info!(component = "console", user = %session.user, "saved layout {name} to {file}");
        Ok(())
    }
}

fn lease_json(lease: &Option<(String, f64)>) -> Json {
    match lease {
        Some((u, since)) => json!({"type": "lease", "holder": u, "since": since}),
        None => json!({"type": "lease", "holder": null, "since": null}),
    }
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

/// Removes and returns the drives `stop` picks.
fn take_drives(
    st: &mut State,
    stop: impl Fn(&(u64, String, String), &Drive) -> bool,
) -> Vec<Drive> {
    let keys: Vec<(u64, String, String)> = st
        .drives
        .iter()
        .filter(|(k, d)| stop(k, d))
        .map(|(k, _)| k.clone())
        .collect();
    keys.into_iter()
        .filter_map(|k| st.drives.remove(&k))
        .collect()
}
