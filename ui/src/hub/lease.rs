//! The control lease: at most one user holds control, taken and released explicitly by a user
//! with the lease role, and released when its holder's last connection has been closed for
//! [`LEASE_GRACE`]. Every page is told who holds it, and so is the bus ([`CONTROL_TOPIC`]).
//!
//! A fleet console holds one lease per vehicle: a layout written for one vehicle
//! (`<layout vehicle="${vehicle}">`) sends its commands under that vehicle's control, which is
//! taken and released on its own (one pilot may fly auv1 while another flies auv2). Layouts
//! without a vehicle share the console's one control (the vehicle `""` here).

use super::{Hub, now_s};
use crate::auth::Session;
use seabus_medium::DataMap;
use serde_json::{Value as Json, json};
use std::collections::{BTreeMap, HashMap};
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

/// Who holds control of each vehicle, since when, and the open connections of each user.
#[derive(Debug, Default)]
pub(super) struct Lease {
    /// For each vehicle held (`""`: the console's one control), the holder and when they took
    /// control (seconds since the epoch).
    holders: BTreeMap<String, (String, f64)>,
    /// Open connections per user.
    connections: HashMap<String, usize>,
    /// When the last connection of a user with none open closed.
    gone_since: HashMap<String, Instant>,
}

/// The vehicle a lease message names: `null` for the console's one control.
fn vehicle_json(vehicle: &str) -> Json {
    if vehicle.is_empty() {
        Json::Null
    } else {
        json!(vehicle)
    }
}

/// Where the control of `vehicle` is published: [`CONTROL_TOPIC`], under the vehicle's name for
/// one vehicle (`auv1.console.control`).
pub(super) fn control_topic(vehicle: &str) -> String {
    if vehicle.is_empty() {
        CONTROL_TOPIC.to_string()
    } else {
        format!("{vehicle}.{CONTROL_TOPIC}")
    }
}

impl Lease {
    /// The user holding control of `vehicle` (`""`: the console's one control).
    pub(super) fn holder(&self, vehicle: &str) -> Option<&str> {
        self.holders.get(vehicle).map(|(u, _)| u.as_str())
    }

    /// The `lease` message of `vehicle`.
    pub(super) fn json(&self, vehicle: &str) -> Json {
        let v = vehicle_json(vehicle);
        match self.holders.get(vehicle) {
            Some((u, since)) => {
                json!({"type": "lease", "vehicle": v, "holder": u, "since": since})
            }
            None => json!({"type": "lease", "vehicle": v, "holder": null, "since": null}),
        }
    }

    /// The `lease` messages of every vehicle held.
    pub(super) fn all_json(&self) -> Vec<Json> {
        self.holders.keys().map(|v| self.json(v)).collect()
    }

    /// What [`CONTROL_TOPIC`] carries for `vehicle`: `holder` (empty when free) and `since`.
    fn control(&self, vehicle: &str) -> DataMap {
        let (holder, since) = self.holders.get(vehicle).cloned().unwrap_or_default();
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

    /// `user` takes control of `vehicle` at `since`: true when they did, false when they held it
    /// already.
    pub(super) fn take(
        &mut self,
        vehicle: &str,
        user: &str,
        since: f64,
    ) -> Result<bool, LeaseError> {
        match self.holder(vehicle) {
            Some(h) if h == user => Ok(false),
            Some(h) => Err(LeaseError::HeldBy(h.to_string())),
            None => {
                self.holders
                    .insert(vehicle.to_string(), (user.to_string(), since));
                Ok(true)
            }
        }
    }

    /// `user` releases control of `vehicle`.
    pub(super) fn release(&mut self, vehicle: &str, user: &str) -> Result<(), LeaseError> {
        if self.holder(vehicle) != Some(user) {
            return Err(LeaseError::NotHolder);
        }
        self.holders.remove(vehicle);
        Ok(())
    }

    /// The vehicles `user` controls.
    pub(super) fn held_by(&self, user: &str) -> Vec<String> {
        self.holders
            .iter()
            .filter(|(_, (u, _))| u == user)
            .map(|(v, _)| v.clone())
            .collect()
    }

    /// Releases the control held by users who have had no connection open for [`LEASE_GRACE`]
    /// at `now`; returns each vehicle released with who held it.
    pub(super) fn expire(&mut self, now: Instant) -> Vec<(String, String)> {
        let gone = |user: &str| {
            self.gone_since
                .get(user)
                .is_some_and(|t| now.duration_since(*t) >= LEASE_GRACE)
        };
        let released: Vec<(String, String)> = self
            .holders
            .iter()
            .filter(|(_, (u, _))| gone(u))
            .map(|(v, (u, _))| (v.clone(), u.clone()))
            .collect();
        for (v, _) in &released {
            self.holders.remove(v);
        }
        released
    }
}

impl Hub {
    /// The `lease` message of the console's one control.
    pub fn lease_json(&self) -> Json {
        self.state().lease.json("")
    }

    /// The `lease` message of `vehicle` (`""`: the console's one control).
    pub fn vehicle_lease_json(&self, vehicle: &str) -> Json {
        self.state().lease.json(vehicle)
    }

    /// The `leases` message: who controls what, whole (the page forgets any other holder).
    pub fn leases_json(&self) -> Json {
        json!({"type": "leases", "held": self.state().lease.all_json()})
    }

    /// Takes or releases control of `vehicle` (`""`: the console's one control) for `session`.
    /// Releasing stops the holder's dead-man and kept commands of that vehicle (their neutral
    /// goes once).
    pub async fn lease(
        &self,
        session: &Session,
        vehicle: &str,
        take: bool,
    ) -> Result<(), LeaseError> {
        let stopped = {
            let mut st = self.state();
            if take {
                if !session.has(&self.settings.lease_role) {
                    return Err(LeaseError::RoleNeeded(self.settings.lease_role.clone()));
                }
                if !st.lease.take(vehicle, &session.user, now_s())? {
                    return Ok(());
                }
                Vec::new()
            } else {
                st.lease.release(vehicle, &session.user)?;
                st.drives
                    .take(|_, d| d.user == session.user && d.vehicle() == vehicle)
            }
        };
        tracing::info!(
            component = "console",
            user = %session.user,
            vehicle,
            "{} control",
            if take { "took" } else { "released" }
        );
        self.lease_changed(vehicle).await;
        self.neutral(stopped, "control released").await;
        if !take {
            let user = &session.user;
            self.end_kept(
                // not one kept since under control taken again
                |k, lease| &k.user == user && k.vehicle() == vehicle && !k.in_control(lease),
                "control released",
            )
            .await;
        }
        Ok(())
    }

    /// Releases every vehicle `session`'s user controls (a log-out).
    pub async fn release_everything(&self, session: &Session) {
        let held = self.state().lease.held_by(&session.user);
        for vehicle in held {
            let _ = self.lease(session, &vehicle, false).await;
        }
    }

    /// Shows the lease of `vehicle` to every page, and publishes it on the bus
    /// ([`control_topic`]: `holder`, empty when free, and `since`) for modules that step back
    /// while someone has control.
    pub(super) async fn lease_changed(&self, vehicle: &str) {
        let (message, control) = {
            let st = self.state();
            (st.lease.json(vehicle), st.lease.control(vehicle))
        };
        self.broadcast(&message);
        let topic = control_topic(vehicle);
        if let Err(e) = self.port.send(topic.as_str(), control).await {
            tracing::warn!(component = "console", "{topic}: {e}");
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
        assert_eq!(lease.take("", "ana", 1.0), Ok(true));
        assert_eq!(lease.holder(""), Some("ana"));
        assert_eq!(
            lease.json(""),
            json!({"type": "lease", "vehicle": null, "holder": "ana", "since": 1.0})
        );
        // taking it again changes nothing, not even since when
        assert_eq!(lease.take("", "ana", 2.0), Ok(false));
        assert_eq!(lease.json("")["since"], 1.0);
        assert_eq!(lease.release("", "ana"), Ok(()));
        assert_eq!(lease.holder(""), None);
        assert_eq!(
            lease.json(""),
            json!({"type": "lease", "vehicle": null, "holder": null, "since": null})
        );
        let again = lease.release("", "ana").unwrap_err();
        assert_eq!(again, LeaseError::NotHolder);
        assert_eq!(again.to_string(), "you do not have control");
    }

    #[test]
    fn a_second_user_is_refused_until_the_holder_releases() {
        let mut lease = Lease::default();
        lease.take("", "ana", 1.0).unwrap();
        let refused = lease.take("", "bo", 2.0).unwrap_err();
        assert_eq!(refused, LeaseError::HeldBy("ana".into()));
        assert_eq!(refused.to_string(), "ana has control; they must release it");
        assert_eq!(lease.release("", "bo"), Err(LeaseError::NotHolder));
        assert_eq!(lease.holder(""), Some("ana"));
        lease.release("", "ana").unwrap();
        assert_eq!(lease.take("", "bo", 3.0), Ok(true));
        assert_eq!(lease.holder(""), Some("bo"));
    }

    #[tokio::test(start_paused = true)]
    async fn control_is_released_10_s_after_the_holders_last_connection_closes() {
        let mut lease = Lease::default();
        lease.connected("ana");
        lease.connected("ana");
        lease.take("", "ana", 1.0).unwrap();
        lease.disconnected("ana", Instant::now());
        tokio::time::advance(Duration::from_secs(60)).await;
        // one connection is still open
        assert!(lease.expire(Instant::now()).is_empty());
        lease.disconnected("ana", Instant::now());
        tokio::time::advance(LEASE_GRACE - Duration::from_millis(1)).await;
        assert!(lease.expire(Instant::now()).is_empty());
        assert_eq!(lease.holder(""), Some("ana"));
        tokio::time::advance(Duration::from_millis(1)).await;
        assert_eq!(
            lease.expire(Instant::now()),
            [(String::new(), "ana".to_string())]
        );
        assert_eq!(lease.holder(""), None);
        assert!(lease.expire(Instant::now()).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn a_holder_back_within_the_grace_keeps_control() {
        let mut lease = Lease::default();
        lease.connected("ana");
        lease.take("", "ana", 1.0).unwrap();
        lease.disconnected("ana", Instant::now());
        tokio::time::advance(Duration::from_secs(9)).await;
        lease.connected("ana");
        tokio::time::advance(Duration::from_secs(60)).await;
        assert!(lease.expire(Instant::now()).is_empty());
        assert_eq!(lease.holder(""), Some("ana"));
    }

    #[tokio::test(start_paused = true)]
    async fn the_hub_releases_a_gone_holder_and_tells_the_pages_and_the_bus() {
        let f = Fixture::new();
        let mut bus = f.listener(CONTROL_TOPIC);
        let mut events = f.hub.events();
        let client = f.hub.connect(f.session("ana"));
        f.hub.lease(&client.session, "", true).await.unwrap();
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
                json!({"type": "lease", "vehicle": null, "holder": "ana", "since": shown[0]["since"]}),
                json!({"type": "lease", "vehicle": null, "holder": null, "since": null}),
            ]
        );
    }

    #[tokio::test]
    async fn taking_control_needs_the_lease_role_and_releasing_needs_control() {
        let f = Fixture::new();
        let ivo = f.session("ivo");
        let refused = f.hub.lease(&ivo, "", true).await.unwrap_err();
        assert_eq!(refused.to_string(), "taking control needs role pilot");
        let bo = f.session("bo");
        assert_eq!(
            f.hub.lease(&bo, "", false).await,
            Err(LeaseError::NotHolder)
        );
        let ana = f.session("ana");
        f.hub.lease(&ana, "", true).await.unwrap();
        assert_eq!(
            f.hub.lease(&bo, "", true).await,
            Err(LeaseError::HeldBy("ana".into()))
        );
        assert_eq!(f.hub.lease_json()["holder"], "ana");
    }

    /// A fleet console's layout for one vehicle, opened for `vehicle`.
    const VEHICLE: &str = r#"<layout name="vehicle" roles="pilot">
  <var name="vehicle" default="auv1"/>
  <layout-vehicle/>
</layout>"#;

    fn vehicle_layout() -> String {
        VEHICLE.replace(
            "<layout-vehicle/>",
            r#"<command name="course" topic="${vehicle}.cmd.course" fields="heading=0, speed=0"/>
  <slider command="course.heading" min="0" max="360"/>"#,
        )
        .replace(r#"roles="pilot">"#, r#"roles="pilot" vehicle="${vehicle}">"#)
    }

    async fn open_for(f: &Fixture, user: &str, vehicle: &str) -> super::super::Client {
        let mut c = f.hub.connect(f.session(user));
        let vars = [("vehicle".to_string(), vehicle.to_string())].into();
        let opened = f.hub.open(&mut c, "vehicle", &vars);
        assert_eq!(opened["layout"]["vehicle"], vehicle, "{opened}");
        c
    }

    #[tokio::test]
    async fn each_vehicle_is_controlled_on_its_own_and_commands_go_to_that_vehicle_only() {
        let layout = vehicle_layout();
        let f = Fixture::with_layouts(&[("vehicle.xml", &layout)]);
        let mut driver = f.bus.attach("drivers");
        driver
            .subscribe_kind("*.cmd.**", Some(seabus_medium::Kind::Command))
            .unwrap();
        let mut auv1_control = f.listener("auv1.console.control");
        let mut ana = open_for(&f, "ana", "auv1").await;
        let mut bo = open_for(&f, "bo", "auv2").await;
        let heading = seabus_medium::DataMap::new().with("heading", 90);
        // no control of auv1 yet
        let refused = f
            .hub
            .send(&mut ana, "vehicle", "course", &heading, None)
            .await;
        assert_eq!(refused, Err(super::super::CommandError::NoControl));
        f.hub.lease(&ana.session, "auv1", true).await.unwrap();
        f.hub.lease(&bo.session, "auv2", true).await.unwrap();
        assert_eq!(control_messages(&mut auv1_control), ["ana"]);
        // the console's one control is still free, and each vehicle has its own holder
        assert_eq!(f.hub.lease_json()["holder"], Json::Null);
        assert_eq!(
            f.hub.vehicle_lease_json("auv1"),
            json!({"type": "lease", "vehicle": "auv1", "holder": "ana",
                   "since": f.hub.vehicle_lease_json("auv1")["since"]})
        );
        assert_eq!(f.hub.vehicle_lease_json("auv2")["holder"], "bo");
        let leases = f.hub.leases_json();
        let held: Vec<&str> = leases["held"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| l["vehicle"].as_str().unwrap())
            .collect();
        assert_eq!(held, ["auv1", "auv2"]);
        // bo cannot take auv1 while ana holds it
        assert_eq!(
            f.hub.lease(&bo.session, "auv1", true).await,
            Err(LeaseError::HeldBy("ana".into()))
        );
        f.hub
            .send(&mut ana, "vehicle", "course", &heading, None)
            .await
            .unwrap();
        f.hub
            .send(&mut bo, "vehicle", "course", &heading, None)
            .await
            .unwrap();
        let topics: Vec<String> = super::super::testing::waiting(&mut driver)
            .iter()
            .map(|m| m.topic.to_string())
            .collect();
        assert_eq!(topics, ["auv1.cmd.course", "auv2.cmd.course"]);
        // ana's page for auv2 commands nothing: bo controls auv2
        let mut ana_auv2 = open_for(&f, "ana", "auv2").await;
        let refused = f
            .hub
            .send(&mut ana_auv2, "vehicle", "course", &heading, None)
            .await;
        assert_eq!(
            refused,
            Err(super::super::CommandError::ControlHeldBy("bo".into()))
        );
        // releasing auv1 leaves auv2 with bo; a log-out releases everything its user holds
        f.hub.lease(&ana.session, "auv1", false).await.unwrap();
        assert_eq!(control_messages(&mut auv1_control), [""]);
        assert_eq!(f.hub.vehicle_lease_json("auv2")["holder"], "bo");
        f.hub.lease(&bo.session, "auv1", true).await.unwrap();
        f.hub.release_everything(&bo.session).await;
        assert_eq!(f.hub.leases_json()["held"], json!([]));
        assert!(super::super::testing::waiting(&mut driver).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn a_gone_holder_loses_every_vehicle_it_controlled() {
        let layout = vehicle_layout();
        let f = Fixture::with_layouts(&[("vehicle.xml", &layout)]);
        let ana = open_for(&f, "ana", "auv1").await;
        f.hub.lease(&ana.session, "auv1", true).await.unwrap();
        f.hub.lease(&ana.session, "auv3", true).await.unwrap();
        let bo = open_for(&f, "bo", "auv2").await;
        f.hub.lease(&bo.session, "auv2", true).await.unwrap();
        f.hub.disconnect(&ana).await;
        tokio::time::advance(LEASE_GRACE).await;
        f.hub.watch().await;
        let held: Vec<(String, String)> = f.hub.leases_json()["held"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| (l["vehicle"].to_string(), l["holder"].to_string()))
            .collect();
        assert_eq!(held, [("\"auv2\"".to_string(), "\"bo\"".to_string())]);
    }
}
