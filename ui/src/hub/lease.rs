//! The control lease: at most one user holds control, taken and released explicitly by a user
//! with the lease role, and released when its holder's last connection has been closed for
//! [`LEASE_GRACE`]. Every page is told who holds it, and so is the bus ([`CONTROL_TOPIC`]).

use super::{Hub, now_s};
use crate::auth::Session;
use seabus_medium::DataMap;
use serde_json::{Value as Json, json};
use std::collections::HashMap;
use std::time::Duration;
use tokio::time::Instant;

/// How long control stays with a holder whose connections have all closed.
pub const LEASE_GRACE: Duration = Duration::from_secs(10);
/// Where the console publishes who holds control.
pub const CONTROL_TOPIC: &str = "console.control";

/// Why control cannot be taken or released.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LeaseError {
    /// The user lacks the lease role.
    #[error("taking control needs role {0}")]
    RoleNeeded(String),
    /// Another user holds control.
    #[error("{0} has control; they must release it")]
    HeldBy(String),
    /// Only the holder releases control.
    #[error("you do not have control")]
    NotHolder,
}

/// Who holds control, since when, and the open connections of each user.
#[derive(Debug, Default)]
pub(super) struct Lease {
    /// The holder and when they took control (seconds since the epoch).
    holder: Option<(String, f64)>,
    /// Open connections per user.
    connections: HashMap<String, usize>,
    /// When the last connection of a user with none open closed.
    gone_since: HashMap<String, Instant>,
}

impl Lease {
    /// The user holding control.
    pub(super) fn holder(&self) -> Option<&str> {
        self.holder.as_ref().map(|(u, _)| u.as_str())
    }

    /// The `lease` message.
    pub(super) fn json(&self) -> Json {
        match &self.holder {
            Some((u, since)) => json!({"type": "lease", "holder": u, "since": since}),
            None => json!({"type": "lease", "holder": null, "since": null}),
        }
    }

    /// What [`CONTROL_TOPIC`] carries: `holder` (empty when free) and `since`.
    fn control(&self) -> DataMap {
        let (holder, since) = self.holder.clone().unwrap_or_default();
        DataMap::new().with("holder", holder).with("since", since)
    }

    /// A connection of `user` opened.
    pub(super) fn connected(&mut self, user: &str) {
        *self.connections.entry(user.to_string()).or_default() += 1;
        self.gone_since.remove(user);
    }

    /// A connection of `user` closed at `now`.
    pub(super) fn disconnected(&mut self, user: &str, now: Instant) {
        if let Some(n) = self.connections.get_mut(user) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                self.connections.remove(user);
                self.gone_since.insert(user.to_string(), now);
            }
        }
    }

    /// `user` takes control at `since`: true when they did, false when they held it already.
    pub(super) fn take(&mut self, user: &str, since: f64) -> Result<bool, LeaseError> {
        match self.holder() {
            Some(h) if h == user => Ok(false),
            Some(h) => Err(LeaseError::HeldBy(h.to_string())),
            None => {
                self.holder = Some((user.to_string(), since));
                Ok(true)
            }
        }
    }

    /// `user` releases control.
    pub(super) fn release(&mut self, user: &str) -> Result<(), LeaseError> {
        if self.holder() != Some(user) {
            return Err(LeaseError::NotHolder);
        }
        self.holder = None;
        Ok(())
    }

    /// Releases control whose holder has had no connection open for [`LEASE_GRACE`] at `now`;
    /// returns who held it.
    pub(super) fn expire(&mut self, now: Instant) -> Option<String> {
        let holder = self.holder()?;
        let gone = self
            .gone_since
            .get(holder)
            .is_some_and(|t| now.duration_since(*t) >= LEASE_GRACE);
        if !gone {
            return None;
        }
        self.holder.take().map(|(u, _)| u)
    }
}

impl Hub {
    /// The `lease` message.
    pub fn lease_json(&self) -> Json {
        self.state().lease.json()
    }

    /// Takes or releases control for `session`. Releasing stops the holder's dead-man commands
    /// (their neutral goes once).
    pub async fn lease(&self, session: &Session, take: bool) -> Result<(), LeaseError> {
        let stopped = {
            let mut st = self.state();
            if take {
                if !session.has(&self.settings.lease_role) {
                    return Err(LeaseError::RoleNeeded(self.settings.lease_role.clone()));
                }
                if !st.lease.take(&session.user, now_s())? {
                    return Ok(());
                }
                Vec::new()
            } else {
                st.lease.release(&session.user)?;
                st.drives.take(|_, d| d.user == session.user)
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
        if !take {
            let user = &session.user;
            self.end_kept(|k| &k.user == user, "control released").await;
        }
        Ok(())
    }

    /// Shows the lease to every page, and publishes it on the bus (`console.control`: `holder`,
    /// empty when free, and `since`) for modules that step back while someone has control.
    pub(super) async fn lease_changed(&self) {
        let (message, control) = {
            let st = self.state();
            (st.lease.json(), st.lease.control())
        };
        self.broadcast(&message);
        if let Err(e) = self.port.send(CONTROL_TOPIC, control).await {
            tracing::warn!(component = "console", "{CONTROL_TOPIC}: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{Fixture, control_messages};
    use super::*;
    use std::time::Duration;

    #[test]
    fn control_is_taken_and_released_by_its_holder() {
        let mut lease = Lease::default();
        assert_eq!(lease.take("ana", 1.0), Ok(true));
        assert_eq!(lease.holder(), Some("ana"));
        assert_eq!(
            lease.json(),
            json!({"type": "lease", "holder": "ana", "since": 1.0})
        );
        // taking it again changes nothing, not even since when
        assert_eq!(lease.take("ana", 2.0), Ok(false));
        assert_eq!(lease.json()["since"], 1.0);
        assert_eq!(lease.release("ana"), Ok(()));
        assert_eq!(lease.holder(), None);
        assert_eq!(
            lease.json(),
            json!({"type": "lease", "holder": null, "since": null})
        );
        let again = lease.release("ana").unwrap_err();
        assert_eq!(again, LeaseError::NotHolder);
        assert_eq!(again.to_string(), "you do not have control");
    }

    #[test]
    fn a_second_user_is_refused_until_the_holder_releases() {
        let mut lease = Lease::default();
        lease.take("ana", 1.0).unwrap();
        let refused = lease.take("bo", 2.0).unwrap_err();
        assert_eq!(refused, LeaseError::HeldBy("ana".into()));
        assert_eq!(refused.to_string(), "ana has control; they must release it");
        assert_eq!(lease.release("bo"), Err(LeaseError::NotHolder));
        assert_eq!(lease.holder(), Some("ana"));
        lease.release("ana").unwrap();
        assert_eq!(lease.take("bo", 3.0), Ok(true));
        assert_eq!(lease.holder(), Some("bo"));
    }

    #[tokio::test(start_paused = true)]
    async fn control_is_released_10_s_after_the_holders_last_connection_closes() {
        let mut lease = Lease::default();
        lease.connected("ana");
        lease.connected("ana");
        lease.take("ana", 1.0).unwrap();
        lease.disconnected("ana", Instant::now());
        tokio::time::advance(Duration::from_secs(60)).await;
        // one connection is still open
        assert_eq!(lease.expire(Instant::now()), None);
        lease.disconnected("ana", Instant::now());
        tokio::time::advance(LEASE_GRACE - Duration::from_millis(1)).await;
        assert_eq!(lease.expire(Instant::now()), None);
        assert_eq!(lease.holder(), Some("ana"));
        tokio::time::advance(Duration::from_millis(1)).await;
        assert_eq!(lease.expire(Instant::now()), Some("ana".into()));
        assert_eq!(lease.holder(), None);
        assert_eq!(lease.expire(Instant::now()), None);
    }

    #[tokio::test(start_paused = true)]
    async fn a_holder_back_within_the_grace_keeps_control() {
        let mut lease = Lease::default();
        lease.connected("ana");
        lease.take("ana", 1.0).unwrap();
        lease.disconnected("ana", Instant::now());
        tokio::time::advance(Duration::from_secs(9)).await;
        lease.connected("ana");
        tokio::time::advance(Duration::from_secs(60)).await;
        assert_eq!(lease.expire(Instant::now()), None);
        assert_eq!(lease.holder(), Some("ana"));
    }

    #[tokio::test(start_paused = true)]
    async fn the_hub_releases_a_gone_holder_and_tells_the_pages_and_the_bus() {
        let f = Fixture::new();
        let mut bus = f.listener(CONTROL_TOPIC);
        let mut events = f.hub.events();
        let client = f.hub.connect(f.session("ana"));
        f.hub.lease(&client.session, true).await.unwrap();
        assert_eq!(f.hub.lease_json()["holder"], "ana");
        assert_eq!(control_messages(&mut bus), ["ana"]);
        f.hub.disconnect(&client).await;
        tokio::time::advance(LEASE_GRACE - Duration::from_millis(100)).await;
        f.hub.watch().await;
        assert_eq!(f.hub.lease_json()["holder"], "ana");
        tokio::time::advance(Duration::from_millis(100)).await;
        f.hub.watch().await;
        assert_eq!(f.hub.lease_json()["holder"], Json::Null);
        assert_eq!(control_messages(&mut bus), [""]);
        let shown: Vec<Json> = std::iter::from_fn(|| events.try_recv().ok())
            .map(|t| serde_json::from_str(&t).unwrap())
            .collect();
        assert_eq!(
            shown,
            [
                json!({"type": "lease", "holder": "ana", "since": shown[0]["since"]}),
                json!({"type": "lease", "holder": null, "since": null}),
            ]
        );
    }

    #[tokio::test]
    async fn taking_control_needs_the_lease_role_and_releasing_needs_control() {
        let f = Fixture::new();
        let ivo = f.session("ivo");
        let refused = f.hub.lease(&ivo, true).await.unwrap_err();
        assert_eq!(refused.to_string(), "taking control needs role pilot");
        let bo = f.session("bo");
        assert_eq!(f.hub.lease(&bo, false).await, Err(LeaseError::NotHolder));
        let ana = f.session("ana");
        f.hub.lease(&ana, true).await.unwrap();
        assert_eq!(
            f.hub.lease(&bo, true).await,
            Err(LeaseError::HeldBy("ana".into()))
        );
        assert_eq!(f.hub.lease_json()["holder"], "ana");
    }
}
