//! A small MOOSDB: the server side of the V10 protocol as the protocol notes describe it — the
//! handshake and welcome (or refusal of a name already taken), notifications with each variable's
//! type fixed by its first write, registration with a minimum interval, wildcard registration by
//! application and variable pattern, the current value sent on registration, timing replies, and
//! disconnection after five seconds of silence. It stands in for a real MOOSDB in tests and lets a
//! user try MOOS clients without installing MOOS.

use super::wire::{self, MoosMsg, Packet, Read, data, kind};
use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;

/// How long a client may stay silent before the server drops it.
pub const SILENCE: Duration = Duration::from_secs(5);
/// Messages waiting for a slow client, at most; past that a publisher waits up to 1 s for room.
const CLIENT_QUEUE: usize = 65_536;

/// `*` any run of characters, `?` any one.
pub fn glob(pattern: &str, text: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pattern.chars().collect(), text.chars().collect());
    let (mut pi, mut ti, mut star, mut mark) = (0, 0, None, 0);
    while ti < t.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == t[ti]) {
            pi += 1;
            ti += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some(pi);
            mark = ti;
            pi += 1;
        } else if let Some(s) = star {
            pi = s + 1;
            mark += 1;
            ti = mark;
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|c| *c == '*')
}

/// What a client asked for.
#[derive(Debug, Clone)]
enum Sub {
    Exact {
        key: String,
        interval: f64,
    },
    Pattern {
        app: String,
        var: String,
        interval: f64,
        /// Variables unregistered since: the pattern still takes variables written later.
        except: HashSet<String>,
    },
}

impl Sub {
    fn interval_for(&self, key: &str, source: &str) -> Option<f64> {
        match self {
            Sub::Exact { key: k, interval } => (k == key).then_some(*interval),
            Sub::Pattern {
                app,
                var,
                interval,
                except,
            } => {
                (glob(var, key) && glob(app, source) && !except.contains(key)).then_some(*interval)
            }
        }
    }
}

/// Notifications for other clients' queues.
type Deliveries = Vec<(mpsc::Sender<MoosMsg>, MoosMsg)>;

struct Client {
    tx: mpsc::Sender<MoosMsg>,
    subs: Vec<Sub>,
    /// When each variable was last sent to it.
    last: HashMap<String, Instant>,
}

/// How the DB's clock and its answer to a handshake behave, to try a client's clock estimate
/// against: a DB on another computer has its own clock, and a busy MOOSDB reads a client's name
/// late (about 0.1 s on one host), so the skew its welcome carries is that much too large.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Clock {
    /// The DB's clock runs this many seconds ahead of this host's (negative: behind).
    pub ahead: f64,
    /// How long after the client's name arrives the DB takes its time for the welcome.
    pub welcome_delay: Duration,
}

impl Clock {
    /// The DB's time now, UNIX seconds.
    fn now(&self) -> f64 {
        now_s() + self.ahead
    }
}

#[derive(Default)]
struct State {
    clock: Clock,
    vars: HashMap<String, MoosMsg>,
    clients: HashMap<String, Client>,
    refused_writes: u64,
}

impl State {
    /// Adds `m` for every client whose registrations want it now: to `own` for the client
    /// called `name` (written back at once), to `out` for the others.
    fn deliver(&mut self, m: &MoosMsg, name: &str, own: &mut Vec<MoosMsg>, out: &mut Deliveries) {
        let key = m.key_str();
        let source = String::from_utf8_lossy(&m.source).into_owned();
        let now = Instant::now();
        for (cname, c) in self.clients.iter_mut() {
            let Some(interval) = c
                .subs
                .iter()
                .filter_map(|s| s.interval_for(&key, &source))
                .reduce(f64::min)
            else {
                continue;
            };
            let due = c
                .last
                .get(&key)
                .is_none_or(|t| now.duration_since(*t).as_secs_f64() >= interval);
            if due {
                c.last.insert(key.clone(), now);
                if cname == name {
                    own.push(m.clone());
                } else {
                    out.push((c.tx.clone(), m.clone()));
                }
            }
        }
    }
}

/// A running MOOSDB.
pub struct MoosDb {
    addr: SocketAddr,
    state: Arc<Mutex<State>>,
    task: tokio::task::JoinHandle<()>,
}

fn now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

impl MoosDb {
    /// Starts serving on `bind` (port 0 for any free one). Must be called inside a tokio runtime.
    pub async fn start(bind: SocketAddr) -> std::io::Result<MoosDb> {
        MoosDb::start_with(bind, Clock::default()).await
    }

    /// Starts serving on `bind` with its clock and handshake as `clock` says.
    pub async fn start_with(bind: SocketAddr, clock: Clock) -> std::io::Result<MoosDb> {
        let listener = TcpListener::bind(bind).await?;
        let addr = listener.local_addr()?;
        let state = Arc::new(Mutex::new(State {
            clock,
            ..State::default()
        }));
        let st = state.clone();
        let task = tokio::spawn(async move {
            let mut conns = tokio::task::JoinSet::new();
            loop {
                tokio::select! {
                    accepted = listener.accept() => {
                        if let Ok((sock, _)) = accepted {
                            let _ = sock.set_nodelay(true);
                            conns.spawn(serve(sock, st.clone()));
                        }
                    }
                    Some(_) = conns.join_next(), if !conns.is_empty() => {}
                }
            }
        });
        Ok(MoosDb { addr, state, task })
    }

    /// Where it listens.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The names of the clients connected now.
    pub fn clients(&self) -> Vec<String> {
        let st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let mut v: Vec<String> = st.clients.keys().cloned().collect();
        v.sort();
        v
    }

    /// A variable's last value.
    pub fn value(&self, key: &str) -> Option<MoosMsg> {
        let st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        st.vars.get(key).cloned()
    }

    /// Writes refused because they changed a variable's type.
    pub fn refused_writes(&self) -> u64 {
        self.state
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .refused_writes
    }
}

impl Drop for MoosDb {
    fn drop(&mut self) {
        // the listener and every connection go with the server's task
        self.task.abort();
    }
}

async fn send(sock: &mut TcpStream, messages: Vec<MoosMsg>) -> std::io::Result<()> {
    sock.write_all(&Packet { messages }.encode()).await
}

/// One client's connection, from the handshake until it goes.
async fn serve(mut sock: TcpStream, state: Arc<Mutex<State>>) {
    let mut hello = [0u8; wire::HANDSHAKE_LEN];
    let shook = tokio::time::timeout(SILENCE, sock.read_exact(&mut hello)).await;
    let expected = wire::handshake();
    if !matches!(shook, Ok(Ok(_))) || !hello.eq_ignore_ascii_case(&expected) {
        return;
    }
    let mut buf = Vec::new();
    let Ok(intro) = wire::next_packet(&mut sock, &mut buf, SILENCE).await else {
        return;
    };
    let Some(first) = intro.messages.first().filter(|m| m.kind == kind::DATA) else {
        return;
    };
    let name = String::from_utf8_lossy(&first.string).into_owned();
    let (tx, mut rx) = mpsc::channel(CLIENT_QUEUE);
    let taken = {
        let mut st = state.lock().unwrap_or_else(|p| p.into_inner());
        if st.clients.contains_key(&name) || name.is_empty() {
            true
        } else {
            st.clients.insert(
                name.clone(),
                Client {
                    tx,
                    subs: Vec::new(),
                    last: HashMap::new(),
                },
            );
            false
        }
    };
    if taken {
        let poison = MoosMsg {
            kind: kind::POISON,
            data_type: data::STRING,
            string: format!("a client called `{name}` is already connected").into_bytes(),
            ..MoosMsg::default()
        };
        let _ = send(&mut sock, vec![poison]).await;
        return;
    }
    let clock = state.lock().unwrap_or_else(|p| p.into_inner()).clock;
    tokio::time::sleep(clock.welcome_delay).await;
    // as a MOOSDB: its time when it welcomes, and that time less the client's as the skew
    let now = clock.now();
    let welcome = MoosMsg {
        id: -1,
        kind: kind::WELCOME,
        data_type: data::DOUBLE,
        source_aux: b"hostname=seabus-moosdb".to_vec(),
        community: b"#1".to_vec(),
        time: now,
        value: now - first.time,
        string: b"asynchronous".to_vec(),
        ..MoosMsg::default()
    };
    let reason = if send(&mut sock, vec![welcome]).await.is_err() {
        "closed".to_string()
    } else {
        run(&mut sock, &mut buf, &name, &state, &mut rx).await
    };
    tracing::debug!(client = %name, "moosdb: client gone: {reason}");
    state
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .clients
        .remove(&name);
}

async fn run(
    sock: &mut TcpStream,
    buf: &mut Vec<u8>,
    name: &str,
    state: &Arc<Mutex<State>>,
    rx: &mut mpsc::Receiver<MoosMsg>,
) -> String {
    let (reader, mut writer) = sock.split();
    let mut reader = reader;
    let mut chunk = vec![0u8; 65_536];
    loop {
        // whole packets already read are handled before reading more
        loop {
            match wire::read_packet(buf) {
                Ok(Read::Packet(p, n)) => {
                    buf.drain(..n);
                    let (replies, deliveries) = handle(p, name, state);
                    // a subscriber slower than its publisher holds the publisher back (as TCP
                    // would); one that takes nothing for a second misses the message
                    for (tx, m) in deliveries {
                        let _ = tx.send_timeout(m, Duration::from_secs(1)).await;
                    }
                    if !replies.is_empty()
                        && writer
                            .write_all(&Packet { messages: replies }.encode())
                            .await
                            .is_err()
                    {
                        return "closed".into();
                    }
                }
                Ok(Read::Incomplete(_)) => break,
                Err(e) => return format!("malformed packet: {e}"),
            }
        }
        tokio::select! {
            read = tokio::time::timeout(SILENCE, reader.read(&mut chunk)) => match read {
                Err(_) => return "silent for 5 s".into(),
                Ok(Ok(0)) => return "closed".into(),
                Ok(Ok(n)) => buf.extend_from_slice(&chunk[..n]),
                Ok(Err(e)) => return e.to_string(),
            },
            Some(first) = rx.recv() => {
                let mut messages = vec![first];
                while let Ok(m) = rx.try_recv() {
                    messages.push(m);
                }
                if writer.write_all(&Packet { messages }.encode()).await.is_err() {
                    return "closed".into();
                }
            }
        }
    }
}

/// Acts on a client's packet; returns what is sent back to it at once.
///
/// As in a MOOSDB, registrations are for the client the message's source names (a MOOS client
/// puts its own name there; an empty source subscribes no one), and a timing message is answered
/// only when it opens the packet: the same message back, its time still the request's, with the
/// DB's time as the value.
/// Also returns the notifications for other clients, to be queued once the state is unlocked.
fn handle(p: Packet, name: &str, state: &Arc<Mutex<State>>) -> (Vec<MoosMsg>, Deliveries) {
    let mut st = state.lock().unwrap_or_else(|p| p.into_inner());
    let mut replies = Vec::new();
    let mut deliveries = Vec::new();
    for (i, mut m) in p.messages.into_iter().enumerate() {
        let key = m.key_str();
        let source = String::from_utf8_lossy(&m.source).into_owned();
        match m.kind {
            kind::NOTIFY => {
                if let Some(old) = st.vars.get(&key)
                    && old.data_type != m.data_type
                {
                    st.refused_writes += 1;
                    continue;
                }
                if m.community.is_empty() {
                    m.community = b"#1".to_vec();
                }
                st.vars.insert(key, m.clone());
                st.deliver(&m, name, &mut replies, &mut deliveries);
            }
            kind::REGISTER | kind::WILDCARD_REGISTER => {
                let text = String::from_utf8_lossy(&m.string).into_owned();
                let sub = if m.kind == kind::REGISTER {
                    Sub::Exact {
                        key: key.clone(),
                        interval: m.value.max(0.0),
                    }
                } else {
                    Sub::Pattern {
                        app: field(&text, "AppPattern").unwrap_or_else(|| "*".into()),
                        var: field(&text, "VarPattern").unwrap_or_else(|| "*".into()),
                        interval: field(&text, "Interval")
                            .and_then(|i| i.parse().ok())
                            .unwrap_or(0.0f64)
                            .max(0.0),
                        except: HashSet::new(),
                    }
                };
                // the current values it now wants go at once
                let current: Vec<MoosMsg> = st
                    .vars
                    .values()
                    .filter(|v| {
                        sub.interval_for(&v.key_str(), &String::from_utf8_lossy(&v.source))
                            .is_some()
                    })
                    .cloned()
                    .collect();
                let Some(c) = st.clients.get_mut(&source) else {
                    tracing::debug!(client = %name, "moosdb: a registration for `{source}`, not connected");
                    continue;
                };
                c.subs.push(sub);
                let now = Instant::now();
                for v in &current {
                    c.last.insert(v.key_str(), now);
                }
                if source == name {
                    replies.extend(current);
                } else {
                    deliveries.extend(current.into_iter().map(|v| (c.tx.clone(), v)));
                }
            }
            // as in a MOOSDB: unregistering stops the variables written so far (for a
            // pattern, those it matches now); a pattern registered stays for new variables
            kind::UNREGISTER | kind::WILDCARD_UNREGISTER => {
                let text = String::from_utf8_lossy(&m.string).into_owned();
                let stopped: Vec<String> = if m.kind == kind::UNREGISTER {
                    vec![key]
                } else {
                    let app = field(&text, "AppPattern").unwrap_or_default();
                    let var = field(&text, "VarPattern").unwrap_or_default();
                    st.vars
                        .values()
                        .filter(|v| {
                            glob(&var, &v.key_str())
                                && glob(&app, &String::from_utf8_lossy(&v.source))
                        })
                        .map(MoosMsg::key_str)
                        .collect()
                };
                if let Some(c) = st.clients.get_mut(&source) {
                    c.subs
                        .retain(|s| !matches!(s, Sub::Exact { key, .. } if stopped.contains(key)));
                    for s in &mut c.subs {
                        if let Sub::Pattern { except, .. } = s {
                            except.extend(stopped.iter().cloned());
                        }
                    }
                }
            }
            kind::TIMING if i == 0 => {
                m.value = st.clock.now();
                m.value2 = 0.0;
                replies.insert(0, m);
            }
            _ => {}
        }
    }
    (replies, deliveries)
}

/// The value of `name` in a `name=value,name=value` string.
fn field(text: &str, name: &str) -> Option<String> {
    text.split(',')
        .filter_map(|kv| kv.split_once('='))
        .find(|(k, _)| k.trim() == name)
        .map(|(_, v)| v.trim().to_string())
}

#[cfg(test)]
mod tests {
    use super::glob;

    #[test]
    fn globs() {
        assert!(glob("*", "NAV_X"));
        assert!(glob("NAV_*", "NAV_X"));
        assert!(!glob("NAV_*", "DESIRED_X"));
        assert!(glob("NAV_?", "NAV_X"));
        assert!(!glob("NAV_?", "NAV_XY"));
        assert!(glob("*_X", "NAV_X"));
        assert!(glob("N*V*X", "NAV_X"));
        assert!(glob("", ""));
        assert!(!glob("", "A"));
    }
}
