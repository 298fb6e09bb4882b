//! Log-in sessions, the file that keeps them across restarts, and the limit on log-in attempts.
//!
//! A session is a random 256-bit token in an HTTP-only cookie, valid until log-out or for
//! [`SESSION_LIFETIME`] from log-in. The console knows a session by a hash of its token ([`Key`]);
//! with a session file ([`Sessions::open`]) it writes each session's hash, user and expiry
//! (wall-clock time) there, so that a restarted console keeps them.
//!
//! [`Limiter`] counts failed log-ins: after [`MAX_FAILURES`] failures within [`WINDOW`] from one
//! address or for one name, attempts are refused for [`WINDOW`]. A right password never counts as
//! a failure, and neither does a log-in answered "busy".

use crate::users::{Users, is_name};
use argon2::{Algorithm, Argon2, Params, Version};
use seabus_medium::tally::Tally;
use seabus_medium::xml::{self, FileError, Pos};
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::io::{self, Read};
use std::net::IpAddr;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::Notify;

/// How long a session lasts from log-in.
pub const SESSION_LIFETIME: Duration = Duration::from_secs(12 * 3600);
/// Failures allowed within [`WINDOW`] before attempts are refused.
pub const MAX_FAILURES: usize = 5;
/// The window failures are counted in, and how long attempts are refused after.
pub const WINDOW: Duration = Duration::from_secs(60);
/// Sessions one user may have at once; a new one ends the oldest.
pub const SESSIONS_PER_USER: usize = 16;
/// The name of the session cookie.
pub const COOKIE: &str = "seabus_session";
/// Log-ins in progress at once (waiting for their turn or being checked); past it a log-in is
/// answered "busy".
pub const QUEUE: usize = 64;
/// The longest a log-in waits for its turn before it is answered "busy".
pub const QUEUE_WAIT: Duration = Duration::from_secs(10);
/// The session file is written at most once in this long while log-ins come (a log-out writes it
/// at once).
pub const WRITE_GAP: Duration = Duration::from_secs(1);
/// The largest session file read; a larger one is refused.
pub const MAX_SESSION_FILE: u64 = 4 << 20;

/// Where a console keeps its sessions unless told: beside its users file, `NAME.sessions` for
/// `NAME.xml` (not `*.xml`, so that a directory of layouts that holds the users file does not
/// take it for a layout).
pub fn sessions_beside(users: &Path) -> PathBuf {
    let mut name = users.file_stem().unwrap_or_default().to_os_string();
    name.push(".sessions");
    users.with_file_name(name)
}

/// A logged-in user: one log-in (a user logged in twice, in two browsers, has two).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    /// The user's name.
    pub user: String,
    /// The user's roles.
    pub roles: Vec<String>,
    /// Which log-in this is, among the console's sessions since it started: what holds control,
    /// and what a page is told of its own (never the token or its hash).
    pub id: u64,
    expires: SystemTime,
}

/// Numbers the sessions of a console's run.
static NEXT_SESSION: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

fn next_session() -> u64 {
    NEXT_SESSION.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

impl Session {
    /// Whether the user has `role`.
    pub fn has(&self, role: &str) -> bool {
        self.roles.iter().any(|r| r == role)
    }
}

/// What a session is known by: a hash of its token, in hex (the token stays with the browser).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Key(String);

/// Bytes in hex.
fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl Key {
    /// The key of `token` (`None` only when hashing fails). The token is 256 random bits, so a
    /// cheap one-way function is enough: argon2id, the users file's hash, at its least cost.
    pub fn of(token: &str) -> Option<Key> {
        let params = Params::new(Params::MIN_M_COST, 1, 1, Some(32)).ok()?;
        let mut out = [0u8; 32];
        Argon2::new(Algorithm::Argon2id, Version::V0x13, params)
            .hash_password_into(token.as_bytes(), b"seabus-session", &mut out)
            .ok()?;
        Some(Key(hex(&out)))
    }
}

/// A fresh random token, hex.
fn token() -> Option<String> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes).ok()?;
    Some(hex(&bytes))
}

/// The live sessions.
#[derive(Debug, Default)]
struct Live {
    map: HashMap<Key, Session>,
    /// Counts changes: the file is written only when it is behind.
    version: u64,
}

impl Live {
    /// Ends `user`'s oldest sessions until one more fits.
    fn make_room(&mut self, user: &str) {
        let mut mine: Vec<(Key, SystemTime)> = self
            .map
            .iter()
            .filter(|(_, s)| s.user == user)
            .map(|(k, s)| (k.clone(), s.expires))
            .collect();
        if mine.len() >= SESSIONS_PER_USER {
            mine.sort_by_key(|(_, e)| *e);
            for (k, _) in mine.iter().take(mine.len() + 1 - SESSIONS_PER_USER) {
                self.map.remove(k);
            }
        }
    }
}

/// The session file and the version of the sessions last written to it.
#[derive(Debug)]
struct SessionFile {
    path: PathBuf,
    written: Mutex<u64>,
}

impl SessionFile {
    /// Writes `text`, the sessions at `version`, unless a version as new is written already.
    fn write(&self, version: u64, text: &str) -> io::Result<()> {
        let mut written = self.written.lock().unwrap_or_else(|p| p.into_inner());
        if version <= *written {
            return Ok(());
        }
        seabus_medium::fs::atomic_write_owner_only(&self.path, text.as_bytes())?;
        *written = version;
        Ok(())
    }
}

/// A session as its file holds it.
struct Stored {
    key: Key,
    user: String,
    expires: SystemTime,
}

/// Reads a session file; a missing one holds no sessions.
fn read_file(path: &Path) -> Result<Vec<Stored>, FileError> {
    let name = path.display().to_string();
    let at = |line: u32, message: String| {
        Pos {
            file: Arc::from(name.as_str()),
            line,
            col: 1,
        }
        .error(message)
    };
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(at(1, format!("cannot read: {e}"))),
    };
    // whoever may write the file may log in as anyone: only a private file is trusted
    let mode = file
        .metadata()
        .map_err(|e| at(1, format!("cannot read: {e}")))?
        .permissions()
        .mode();
    if mode & 0o022 != 0 {
        return Err(at(
            1,
            format!(
                "others may write it (mode {:o}): its sessions are not trusted; `chmod 600` it",
                mode & 0o777
            ),
        ));
    }
    let mut bytes = Vec::new();
    file.take(MAX_SESSION_FILE + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| at(1, format!("cannot read: {e}")))?;
    if bytes.len() as u64 > MAX_SESSION_FILE {
        return Err(at(
            1,
            format!("larger than {MAX_SESSION_FILE} bytes: not a session file"),
        ));
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let line = valid.iter().filter(|b| **b == b'\n').count() + 1;
        at(
            u32::try_from(line).unwrap_or(u32::MAX),
            format!("not UTF-8 (byte {})", valid.len()),
        )
    })?;
    parse_file(&name, &text)
}

/// Reads session file text (`file` names it in errors).
fn parse_file(file: &str, text: &str) -> Result<Vec<Stored>, FileError> {
    let root = xml::parse(file, text)?;
    if root.name != "sessions" {
        return Err(root.error(format!(
            "the root element is <{}>; a session file holds <sessions>",
            root.name
        )));
    }
    root.only_attrs(&[])?;
    root.only_children(&["session"])?;
    let mut out = Vec::new();
    for el in &root.children {
        el.only_attrs(&["user", "token_hash", "expires"])?;
        let user = el.required("user")?;
        if !is_name(&user.value) {
            return Err(user.error(format!("`{}` is not a user name", user.value)));
        }
        let hash = el.required("token_hash")?;
        if hash.value.len() != 64
            || !hash
                .value
                .bytes()
                .all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
        {
            return Err(hash.error("not a token hash (64 lower-case hex digits)"));
        }
        let expires_attr = el.required("expires")?;
        let expires = expires_attr
            .parse::<u64>("a time in seconds since 1970")
            .ok()
            .and_then(|s| UNIX_EPOCH.checked_add(Duration::from_secs(s)))
            .ok_or_else(|| {
                expires_attr.error(format!(
                    "`{}` is not a time in seconds since 1970",
                    expires_attr.value
                ))
            })?;
        out.push(Stored {
            key: Key(hash.value.clone()),
            user: user.value.clone(),
            expires,
        });
    }
    Ok(out)
}

/// Seconds since 1970.
fn unix(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs())
}

/// The sessions of a console.
#[derive(Debug, Default)]
pub struct Sessions {
    live: Mutex<Live>,
    file: Option<Arc<SessionFile>>,
    changed: Notify,
    problems: Tally,
}

impl Sessions {
    /// Sessions kept in the file at `path` (written when sessions start and end). The file's
    /// sessions are loaded except those expired and those of users `users` no longer has; the
    /// others take their roles from `users`. A file that cannot be read is warned of (with its
    /// place) and counted, and the sessions start empty: the console starts all the same.
    pub fn open(path: &Path, users: &Users) -> Sessions {
        let sessions = Sessions {
            file: Some(Arc::new(SessionFile {
                path: path.to_path_buf(),
                written: Mutex::new(0),
            })),
            ..Sessions::default()
        };
        let mut stored = read_file(path).unwrap_or_else(|e| {
            sessions.problems.record(
                "console",
                "session-file",
                format!("{e}; the console starts with no sessions"),
            );
            Vec::new()
        });
        let now = SystemTime::now();
        let found = stored.len();
        stored.sort_by_key(|s| s.expires);
        {
            let mut live = sessions.live();
            for s in stored {
                let Some(user) = users.get(&s.user).filter(|_| s.expires > now) else {
                    continue;
                };
                live.make_room(&s.user);
                // no session outlives its lifetime from now, whatever the file says
                let expires = s.expires.min(now + SESSION_LIFETIME);
                let roles = user.roles.clone();
                live.map.insert(
                    s.key,
                    Session {
                        user: s.user,
                        roles,
                        id: next_session(),
                        expires,
                    },
                );
            }
            if live.map.len() < found {
                // the file is rewritten without them
                live.version += 1;
                sessions.changed.notify_one();
            }
            tracing::info!(
                component = "console",
                file = %path.display(),
                "{} sessions kept, {} expired or of users no longer in the users file",
                live.map.len(),
                found - live.map.len()
            );
        }
        sessions
    }

    fn live(&self) -> MutexGuard<'_, Live> {
        self.live.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Starts a session; returns its token (`None` when the system has no randomness).
    pub fn start(&self, user: &str, roles: &[String]) -> Option<String> {
        let t = token()?;
        let key = Key::of(&t)?;
        let mut live = self.live();
        let now = SystemTime::now();
        live.map.retain(|_, s| s.expires > now);
        live.make_room(user);
        live.map.insert(
            key,
            Session {
                user: user.to_string(),
                roles: roles.to_vec(),
                id: next_session(),
                expires: now + SESSION_LIFETIME,
            },
        );
        live.version += 1;
        self.changed.notify_one();
        Some(t)
    }

    /// The session of `token`, if it is live.
    pub fn get(&self, token: &str) -> Option<Session> {
        self.find(&Key::of(token)?)
    }

    /// The session known by `key`, if it is live.
    pub fn find(&self, key: &Key) -> Option<Session> {
        let live = self.live();
        live.map
            .get(key)
            .filter(|s| s.expires > SystemTime::now())
            .cloned()
    }

    /// Ends the session known by `key`; returns its user. [`save`](Self::save) writes the end.
    pub fn end(&self, key: &Key) -> Option<String> {
        let mut live = self.live();
        let user = live.map.remove(key).map(|s| s.user)?;
        live.version += 1;
        self.changed.notify_one();
        Some(user)
    }

    /// Writes the session file whenever sessions change, at most once in [`WRITE_GAP`]; runs
    /// for as long as the console (returns at once without a file).
    pub async fn keep(&self) {
        if self.file.is_none() {
            return;
        }
        loop {
            self.changed.notified().await;
            self.save().await;
            tokio::time::sleep(WRITE_GAP).await;
        }
    }

    /// The file, the version and the text to write, when there is a file.
    fn snapshot(&self) -> Option<(Arc<SessionFile>, u64, String)> {
        let file = self.file.clone()?;
        let mut live = self.live();
        let now = SystemTime::now();
        live.map.retain(|_, s| s.expires > now);
        let mut list: Vec<(&Key, &Session)> = live.map.iter().collect();
        list.sort_by(|a, b| (a.1.expires, &a.0.0).cmp(&(b.1.expires, &b.0.0)));
        let mut text = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<sessions>\n");
        for (key, s) in list {
            text += &format!(
                "  <session user=\"{}\" token_hash=\"{}\" expires=\"{}\"/>\n",
                s.user,
                key.0,
                unix(s.expires)
            );
        }
        text += "</sessions>\n";
        Some((file, live.version, text))
    }

    fn report(&self, file: &SessionFile, written: io::Result<()>) {
        if let Err(e) = written {
            self.problems.record(
                "console",
                "session-file",
                format!("{}: cannot write the sessions: {e}", file.path.display()),
            );
        }
    }

    /// Writes the session file now when it is behind (off the async threads).
    pub async fn save(&self) {
        let Some((file, version, text)) = self.snapshot() else {
            return;
        };
        let writer = file.clone();
        let written = tokio::task::spawn_blocking(move || writer.write(version, &text))
            .await
            .unwrap_or_else(|e| Err(io::Error::other(e)));
        self.report(&file, written);
    }

    /// Writes the session file now when it is behind, on this thread (when the console stops).
    pub fn save_now(&self) {
        if let Some((file, version, text)) = self.snapshot() {
            let written = file.write(version, &text);
            self.report(&file, written);
        }
    }

    /// Problems with the session file so far, by reason (`session-file`).
    pub fn problems(&self) -> BTreeMap<String, u64> {
        self.problems.counts()
    }
}

/// Why a log-in is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Too many failures from the address or for the name: try again after this long.
    Limited(Duration),
    /// Too many log-ins at once: try again (not a failure).
    Busy,
    /// The name and password do not match (a failure).
    Wrong,
}

/// Failures and log-ins in progress.
#[derive(Debug, Default)]
struct Counts {
    /// Recent failures by key (the last [`MAX_FAILURES`] of each).
    failures: HashMap<String, VecDeque<Instant>>,
    /// Passwords being checked, by key.
    checking: HashMap<String, usize>,
    /// Log-ins waiting for their turn or being checked.
    in_progress: usize,
}

impl Counts {
    fn recent(&self, key: &str, now: Instant) -> impl Iterator<Item = &Instant> {
        self.failures
            .get(key)
            .into_iter()
            .flatten()
            .filter(move |t| now.duration_since(**t) < WINDOW)
    }

    /// `Err(wait)` while attempts for any of `keys` are refused.
    fn limited(&self, keys: &[String; 2], now: Instant) -> Result<(), Duration> {
        let mut wait = Duration::ZERO;
        for k in keys {
            if self.recent(k, now).count() >= MAX_FAILURES
                && let Some(last) = self.recent(k, now).last()
            {
                wait = wait.max(WINDOW.saturating_sub(now.duration_since(*last)));
            }
        }
        if wait.is_zero() { Ok(()) } else { Err(wait) }
    }

    /// Lets a password be checked when, for each key, the failures so far and the checks under
    /// way are fewer than [`MAX_FAILURES`] (so that checks made together cannot go past the limit
    /// together); `Ok(false)`: wait for a check to end.
    fn admit(&mut self, keys: &[String; 2], now: Instant) -> Result<bool, Duration> {
        self.limited(keys, now)?;
        let room = keys.iter().all(|k| {
            self.recent(k, now).count() + self.checking.get(k).copied().unwrap_or(0) < MAX_FAILURES
        });
        if room {
            for k in keys {
                *self.checking.entry(k.clone()).or_default() += 1;
            }
        }
        Ok(room)
    }

    fn checked(&mut self, keys: &[String; 2]) {
        for k in keys {
            if let Some(n) = self.checking.get_mut(k) {
                *n -= 1;
                if *n == 0 {
                    self.checking.remove(k);
                }
            }
        }
    }

    fn fail(&mut self, keys: &[String; 2], now: Instant) {
        // bounded: stale entries go, and each key keeps its last few failures
        if self.failures.len() > 10_000 {
            self.failures
                .retain(|_, v| v.back().is_some_and(|t| now.duration_since(*t) < WINDOW));
        }
        for k in keys {
            let times = self.failures.entry(k.clone()).or_default();
            times.push_back(now);
            while times.len() > MAX_FAILURES {
                times.pop_front();
            }
        }
    }
}

/// Limits log-ins: counts failures by address and by name, and lets log-ins wait their turn.
#[derive(Debug, Default)]
pub struct Limiter {
    counts: Mutex<Counts>,
    /// Woken when an attempt ends.
    turn: Notify,
    refusals: Tally,
}

/// A log-in under way, from [`Limiter::attempt`]; ends as [`succeed`](Self::succeed),
/// [`fail`](Self::fail) or [`busy`](Self::busy). Dropped otherwise, it counts as nothing.
#[derive(Debug)]
pub struct Attempt<'a> {
    limiter: &'a Limiter,
    keys: [String; 2],
    addr: IpAddr,
    name: String,
    checking: bool,
}

impl Limiter {
    fn keys(addr: IpAddr, name: &str) -> [String; 2] {
        [format!("addr {addr}"), format!("name {name}")]
    }

    fn lock(&self) -> MutexGuard<'_, Counts> {
        self.counts.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn refused(&self, why: Refused, addr: IpAddr, name: &str) -> Refused {
        let (reason, what) = match why {
            Refused::Limited(_) => ("limited", "log-in refused: too many failures"),
            Refused::Busy => ("busy", "log-in refused: too many log-ins at once"),
            Refused::Wrong => ("failed", "log-in failed: wrong name or password"),
        };
        self.refusals.record(
            "console",
            reason,
            format!("{what} (address {addr}, user {name})"),
        );
        why
    }

    /// Starts a log-in from `addr` for `name`. Refused at once while limited, or when [`QUEUE`]
    /// log-ins are in progress ("busy"); otherwise it waits (at most [`QUEUE_WAIT`], then "busy")
    /// until its password may be checked: while the failures and the checks under way for its
    /// address or name reach [`MAX_FAILURES`], it waits for one of them to end.
    pub async fn attempt(&self, addr: IpAddr, name: &str) -> Result<Attempt<'_>, Refused> {
        let keys = Limiter::keys(addr, name);
        {
            let mut c = self.lock();
            if let Err(wait) = c.limited(&keys, Instant::now()) {
                drop(c);
                return Err(self.refused(Refused::Limited(wait), addr, name));
            }
            if c.in_progress >= QUEUE {
                drop(c);
                return Err(self.refused(Refused::Busy, addr, name));
            }
            c.in_progress += 1;
        }
        let mut attempt = Attempt {
            limiter: self,
            keys,
            addr,
            name: name.to_string(),
            checking: false,
        };
        let deadline = tokio::time::Instant::now() + QUEUE_WAIT;
        loop {
            let turn = self.turn.notified();
            tokio::pin!(turn);
            // listening before looking: an attempt that ends in between still wakes this one
            turn.as_mut().enable();
            let admitted = self.lock().admit(&attempt.keys, Instant::now());
            match admitted {
                Ok(true) => {
                    attempt.checking = true;
                    return Ok(attempt);
                }
                Ok(false) => {}
                Err(wait) => return Err(attempt.refuse(Refused::Limited(wait))),
            }
            if tokio::time::timeout_at(deadline, turn).await.is_err() {
                return Err(attempt.busy());
            }
        }
    }

    /// Refusals and failures so far, by reason (`limited`, `busy`, `failed`).
    pub fn refusals(&self) -> BTreeMap<String, u64> {
        self.refusals.counts()
    }
}

impl Attempt<'_> {
    fn refuse(self, why: Refused) -> Refused {
        self.limiter.refused(why, self.addr, &self.name)
    }

    /// The password was right: forgets the failures for the name (not those of the address).
    pub fn succeed(self) {
        self.limiter.lock().failures.remove(&self.keys[1]);
    }

    /// The password was wrong: counts a failure for the address and for the name.
    pub fn fail(mut self) -> Refused {
        {
            let mut c = self.limiter.lock();
            // counted as the check ends, in one step: a waiting attempt sees both at once
            c.fail(&self.keys, Instant::now());
            c.checked(&self.keys);
        }
        self.checking = false;
        self.refuse(Refused::Wrong)
    }

    /// The log-in could not be checked in time: answered "busy", not a failure.
    pub fn busy(self) -> Refused {
        self.refuse(Refused::Busy)
    }
}

impl Drop for Attempt<'_> {
    fn drop(&mut self) {
        {
            let mut c = self.limiter.lock();
            c.in_progress = c.in_progress.saturating_sub(1);
            if self.checking {
                c.checked(&self.keys);
            }
        }
        self.limiter.turn.notify_waiters();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_user_has_a_bounded_number_of_sessions() {
        let s = Sessions::default();
        let first = s.start("ana", &[]).unwrap();
        for _ in 0..SESSIONS_PER_USER {
            s.start("ana", &[]).unwrap();
        }
        assert!(s.get(&first).is_none(), "the oldest ended");
    }

    #[test]
    fn sessions_start_and_end() {
        let s = Sessions::default();
        let t = s.start("ana", &["pilot".into()]).unwrap();
        assert_eq!(t.len(), 64);
        assert!(s.get(&t).unwrap().has("pilot"));
        assert!(s.get("forged").is_none());
        assert_eq!(s.end(&Key::of(&t).unwrap()).as_deref(), Some("ana"));
        assert!(s.get(&t).is_none());
    }

    fn users() -> Users {
        Users::with_passwords(&[("ana", &["observer"], "ana-password")]).unwrap()
    }

    #[test]
    fn the_file_keeps_token_hashes_and_drops_what_no_longer_holds() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.xml");
        let s = Sessions::open(&path, &users());
        let ana = s.start("ana", &["pilot".into()]).unwrap();
        let bo = s.start("bo", &[]).unwrap();
        s.save_now();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            !text.contains(&ana) && text.contains(&Key::of(&ana).unwrap().0),
            "{text}"
        );
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
        // reopened: ana's session, with the roles the users file gives now; bo is gone
        let again = Sessions::open(&path, &users());
        assert_eq!(again.get(&ana).unwrap().roles, ["observer"]);
        assert!(again.get(&bo).is_none());
        assert!(again.problems().is_empty());
        // an expiry in the past is not a session; one too far ahead is cut to the lifetime
        let key = Key::of(&ana).unwrap().0;
        let past = unix(SystemTime::now()) - 1;
        std::fs::write(
            &path,
            format!("<sessions><session user=\"ana\" token_hash=\"{key}\" expires=\"{past}\"/></sessions>"),
        )
        .unwrap();
        assert!(Sessions::open(&path, &users()).get(&ana).is_none());
        let far = unix(SystemTime::now()) + 10 * SESSION_LIFETIME.as_secs();
        std::fs::write(
            &path,
            format!("<sessions><session user=\"ana\" token_hash=\"{key}\" expires=\"{far}\"/></sessions>"),
        )
        .unwrap();
        let cut = Sessions::open(&path, &users()).get(&ana).unwrap();
        assert!(cut.expires <= SystemTime::now() + SESSION_LIFETIME);
    }

    #[test]
    fn a_bad_file_is_named_with_its_place_and_holds_no_sessions() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.xml");
        let bad =
            "<sessions>\n  <session user=\"ana\" token_hash=\"xyz\" expires=\"1\"/>\n</sessions>";
        std::fs::write(&path, bad).unwrap();
        let e = read_file(&path).err().unwrap().to_string();
        assert!(
            e.starts_with(&format!("{}:2:", path.display())) && e.contains("token_hash"),
            "{e}"
        );
        let s = Sessions::open(&path, &users());
        assert_eq!(s.problems().get("session-file"), Some(&1));
        let e = parse_file("s.xml", "<sessions><session user=\"ana\" token_hash=\"00\"")
            .err()
            .unwrap();
        assert!(e.to_string().starts_with("s.xml:1:"), "{e}");
        std::fs::write(&path, b"<sessions>\n\xff</sessions>").unwrap();
        let e = read_file(&path).err().unwrap().to_string();
        assert!(e.contains(":2:1: not UTF-8 (byte 11)"), "{e}");
        let e = parse_file("s.xml", "<sessions><session user=\"ana\" token_hash=\"0000000000000000000000000000000000000000000000000000000000000000\" expires=\"99999999999999999999\"/></sessions>")
            .err()
            .unwrap();
        assert!(e.to_string().contains("seconds since 1970"), "{e}");
        // a missing file is no sessions, and no problem
        let s = Sessions::open(&dir.path().join("none.xml"), &users());
        assert!(s.problems().is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn log_ins_in_a_burst_are_written_together() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.xml");
        let s = Arc::new(Sessions::open(&path, &users()));
        let keeper = tokio::spawn({
            let s = s.clone();
            async move { s.keep().await }
        });
        let written = || *s.file.as_ref().unwrap().written.lock().unwrap();
        let until = async |version: u64| {
            for _ in 0..1000 {
                if written() == version {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
            panic!("version {version} not written: {}", written());
        };
        // the first log-in is written at once
        s.start("ana", &[]).unwrap();
        until(1).await;
        // fifty more within the gap: none is written until it ends, then all at once
        for _ in 0..50 {
            s.start("ana", &[]).unwrap();
        }
        tokio::time::sleep(WRITE_GAP / 2).await;
        assert_eq!(written(), 1);
        tokio::time::sleep(WRITE_GAP / 2).await;
        until(51).await;
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text.matches("<session ").count(),
            SESSIONS_PER_USER,
            "{text}"
        );
        keeper.abort();
    }

    fn addr(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[tokio::test]
    async fn only_failures_count_and_checks_made_together_stay_under_the_limit() {
        let l = Arc::new(Limiter::default());
        let a = addr("10.0.0.1");
        // 12 at once, all right: none is limited, none counted
        let mut tasks = Vec::new();
        for _ in 0..12 {
            let shared = l.clone();
            tasks.push(tokio::spawn(async move {
                let at = shared.attempt(a, "ana").await?;
                tokio::time::sleep(Duration::from_millis(20)).await;
                at.succeed();
                Ok::<(), Refused>(())
            }));
        }
        for t in tasks {
            assert_eq!(t.await.unwrap(), Ok(()));
        }
        assert!(l.refusals().is_empty(), "{:?}", l.refusals());
        {
            let c = l.lock();
            assert!(c.failures.is_empty() && c.checking.is_empty() && c.in_progress == 0);
        }
        // five checks under way for one name: a sixth waits until one ends
        let b = addr("10.0.0.2");
        let mut five = Vec::new();
        for _ in 0..MAX_FAILURES {
            five.push(l.attempt(b, "bo").await.unwrap());
        }
        let sixth = l.attempt(b, "bo");
        tokio::pin!(sixth);
        assert!(
            tokio::time::timeout(Duration::from_millis(50), sixth.as_mut())
                .await
                .is_err(),
            "the sixth waits"
        );
        // they all fail: the sixth is limited, having waited
        for at in five {
            assert_eq!(at.fail(), Refused::Wrong);
        }
        let wait = match sixth.await {
            Err(Refused::Limited(wait)) => wait,
            other => panic!("{other:?}"),
        };
        assert!(wait > Duration::from_secs(59), "{wait:?}");
        assert_eq!(l.refusals().get("failed"), Some(&5));
        assert_eq!(l.refusals().get("limited"), Some(&1));
        // the name is limited from any address, the address for any name
        assert!(matches!(l.attempt(a, "bo").await, Err(Refused::Limited(_))));
        assert!(matches!(
            l.attempt(b, "ivo").await,
            Err(Refused::Limited(_))
        ));
        assert!(l.attempt(addr("10.0.0.3"), "ivo").await.is_ok());
    }

    #[tokio::test]
    async fn a_success_forgets_the_name_s_failures_and_busy_is_not_a_failure() {
        let l = Limiter::default();
        let a = addr("10.0.0.1");
        for _ in 0..MAX_FAILURES - 1 {
            l.attempt(a, "ana").await.unwrap().fail();
        }
        l.attempt(a, "ana").await.unwrap().succeed();
        // the name starts again; the address keeps its four
        l.attempt(addr("10.0.0.9"), "ana").await.unwrap().fail();
        assert!(l.attempt(addr("10.0.0.9"), "ana").await.is_ok());
        l.attempt(a, "ivo").await.unwrap().fail();
        assert!(matches!(
            l.attempt(a, "zed").await,
            Err(Refused::Limited(_))
        ));
        // busy, or dropped unchecked (the client went away): nothing counted
        let c = addr("10.0.0.4");
        for _ in 0..20 {
            assert_eq!(l.attempt(c, "bo").await.unwrap().busy(), Refused::Busy);
            drop(l.attempt(c, "bo").await.unwrap());
        }
        assert!(l.attempt(c, "bo").await.is_ok());
        assert_eq!(l.refusals().get("busy"), Some(&20));
    }

    #[tokio::test(start_paused = true)]
    async fn past_the_queue_a_log_in_is_busy_and_a_long_wait_ends_busy() {
        let l = Limiter::default();
        let mut held = Vec::new();
        for i in 0..QUEUE {
            // each from its own address and name: none waits
            let a = IpAddr::from([10, 1, (i / 256) as u8, (i % 256) as u8]);
            held.push(l.attempt(a, &format!("u{i}")).await.unwrap());
        }
        let x = addr("10.2.0.1");
        assert_eq!(l.attempt(x, "x").await.unwrap_err(), Refused::Busy);
        drop(held.drain(..MAX_FAILURES + 1));
        // the same address five times over: the sixth waits its turn, then gives up busy
        let mut five = Vec::new();
        for _ in 0..MAX_FAILURES {
            five.push(l.attempt(x, "x").await.unwrap());
        }
        let t0 = tokio::time::Instant::now();
        assert_eq!(l.attempt(x, "x").await.unwrap_err(), Refused::Busy);
        assert!(t0.elapsed() >= QUEUE_WAIT, "{:?}", t0.elapsed());
        assert!(
            l.lock()
                .limited(&Limiter::keys(x, "x"), Instant::now())
                .is_ok()
        );
    }

    #[test]
    fn failures_limit_for_a_window() {
        let mut c = Counts::default();
        let keys = Limiter::keys(addr("10.0.0.1"), "ana");
        let t0 = Instant::now();
        for _ in 0..MAX_FAILURES {
            assert!(c.limited(&keys, t0).is_ok());
            c.fail(&keys, t0);
        }
        assert!(c.limited(&keys, t0).is_err());
        // a minute later, attempts are allowed again
        assert!(c.limited(&keys, t0 + WINDOW).is_ok());
    }
}
