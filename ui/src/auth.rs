//! Log-in sessions and the limit on log-in attempts.
//!
//! A session is a random 256-bit token in an HTTP-only cookie, valid until log-out or
//! [`SESSION_LIFETIME`]. [`Limiter`] refuses attempts for a minute after [`MAX_FAILURES`] failures
//! within a minute from one address or for one name.

use std::collections::{HashMap, VecDeque};
use std::net::IpAddr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How long a session lasts.
pub const SESSION_LIFETIME: Duration = Duration::from_secs(12 * 3600);
/// Failures allowed within [`WINDOW`] before attempts are refused.
pub const MAX_FAILURES: usize = 5;
/// The window failures are counted in, and how long attempts are refused after.
pub const WINDOW: Duration = Duration::from_secs(60);
/// Sessions one user may have at once; a new one ends the oldest.
pub const SESSIONS_PER_USER: usize = 16;
/// The name of the session cookie.
pub const COOKIE: &str = "seabus_session";

/// A logged-in user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    /// The user's name.
    pub user: String,
    /// The user's roles.
    pub roles: Vec<String>,
    expires: Instant,
}

impl Session {
    /// Whether the user has `role`.
    pub fn has(&self, role: &str) -> bool {
        self.roles.iter().any(|r| r == role)
    }
}

/// The sessions of a console.
#[derive(Debug, Default)]
pub struct Sessions {
    map: Mutex<HashMap<String, Session>>,
}

/// A fresh random token, hex.
fn token() -> Option<String> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes).ok()?;
    Some(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

impl Sessions {
    /// Starts a session; returns its token (`None` when the system has no randomness).
    pub fn start(&self, user: &str, roles: &[String]) -> Option<String> {
        let t = token()?;
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        let now = Instant::now();
        map.retain(|_, s| s.expires > now);
        // a user's oldest sessions end past the limit
        let mut mine: Vec<(String, Instant)> = map
            .iter()
            .filter(|(_, s)| s.user == user)
            .map(|(t, s)| (t.clone(), s.expires))
            .collect();
        if mine.len() >= SESSIONS_PER_USER {
            mine.sort_by_key(|(_, e)| *e);
            for (t, _) in mine.iter().take(mine.len() + 1 - SESSIONS_PER_USER) {
                map.remove(t);
            }
        }
        map.insert(
            t.clone(),
            Session {
                user: user.to_string(),
                roles: roles.to_vec(),
                expires: now + SESSION_LIFETIME,
            },
        );
        Some(t)
    }

    /// The session of `token`, if it is live.
    pub fn get(&self, token: &str) -> Option<Session> {
        let map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        map.get(token)
            .filter(|s| s.expires > Instant::now())
            .cloned()
    }

    /// Ends the session of `token`; returns its user.
    pub fn end(&self, token: &str) -> Option<String> {
        let mut map = self.map.lock().unwrap_or_else(|p| p.into_inner());
        map.remove(token).map(|s| s.user)
    }
}

/// Counts failed log-ins by address and by name.
#[derive(Debug, Default)]
pub struct Limiter {
    failures: Mutex<HashMap<String, VecDeque<Instant>>>,
    /// Held while an attempt is checked and counted.
    attempts: Mutex<()>,
}

impl Limiter {
    fn keys(addr: IpAddr, name: &str) -> [String; 2] {
        [format!("addr {addr}"), format!("name {name}")]
    }

    /// `Err(wait)` when attempts from `addr` or for `name` are refused for now.
    pub fn check(&self, addr: IpAddr, name: &str) -> Result<(), Duration> {
        self.check_at(addr, name, Instant::now())
    }

    fn check_at(&self, addr: IpAddr, name: &str, now: Instant) -> Result<(), Duration> {
        let map = self.failures.lock().unwrap_or_else(|p| p.into_inner());
        let mut wait = Duration::ZERO;
        for k in Limiter::keys(addr, name) {
            if let Some(times) = map.get(&k) {
                let recent: Vec<&Instant> = times
                    .iter()
                    .filter(|t| now.duration_since(**t) < WINDOW)
                    .collect();
                if recent.len() >= MAX_FAILURES
                    && let Some(last) = recent.last()
                {
                    wait = wait.max(WINDOW.saturating_sub(now.duration_since(**last)));
                }
            }
        }
        if wait.is_zero() { Ok(()) } else { Err(wait) }
    }

    /// Starts an attempt: refused (`Err(wait)`) while limited; otherwise counted as a failure at
    /// once, in the same step, so attempts made together cannot all pass the check before any is
    /// counted. [`succeed`](Self::succeed) takes it back.
    pub fn attempt(&self, addr: IpAddr, name: &str) -> Result<(), Duration> {
        let now = Instant::now();
        let _guard = self.attempts.lock().unwrap_or_else(|p| p.into_inner());
        self.check_at(addr, name, now)?;
        self.fail_at(addr, name, now);
        Ok(())
    }

    /// Counts a failed attempt.
    pub fn fail(&self, addr: IpAddr, name: &str) {
        self.fail_at(addr, name, Instant::now());
    }

    fn fail_at(&self, addr: IpAddr, name: &str, now: Instant) {
        let mut map = self.failures.lock().unwrap_or_else(|p| p.into_inner());
        // bounded: stale entries go, and each key keeps its last few failures
        if map.len() > 10_000 {
            map.retain(|_, v| v.back().is_some_and(|t| now.duration_since(*t) < WINDOW));
        }
        for k in Limiter::keys(addr, name) {
            let times = map.entry(k).or_default();
            times.push_back(now);
            while times.len() > MAX_FAILURES {
                times.pop_front();
            }
        }
    }

    /// A successful log-in: forgets the failures for `name`, and takes back the address's count
    /// of this attempt.
    pub fn succeed(&self, addr: IpAddr, name: &str) {
        let mut map = self.failures.lock().unwrap_or_else(|p| p.into_inner());
        map.remove(&format!("name {name}"));
        if let Some(times) = map.get_mut(&format!("addr {addr}")) {
            times.pop_back();
        }
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
        assert_eq!(s.end(&t).as_deref(), Some("ana"));
        assert!(s.get(&t).is_none());
    }

    #[test]
    fn five_failures_block_an_address_and_a_name_for_a_minute() {
        let l = Limiter::default();
        let (a, b) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        let t0 = Instant::now();
        for i in 0..MAX_FAILURES {
            assert!(l.check_at(a, "ana", t0).is_ok(), "attempt {i}");
            l.fail_at(a, "ana", t0);
        }
        // attempts are counted as they start, so many at once cannot pass together
        let l2 = Limiter::default();
        let passed = (0..20).filter(|_| l2.attempt(b, "bo").is_ok()).count();
        assert_eq!(passed, MAX_FAILURES);
        // the address, for any name; and the name, from any address
        assert!(l.check_at(a, "ivo", t0).is_err());
        let wait = l.check_at(b, "ana", t0).unwrap_err();
        assert!(wait > Duration::from_secs(59), "{wait:?}");
        assert!(l.check_at(b, "ivo", t0).is_ok());
        // a minute later, attempts are allowed again
        assert!(l.check_at(a, "ana", t0 + WINDOW).is_ok());
    }
}
