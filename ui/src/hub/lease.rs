//! The control lease: at most one log-in holds control, taken and released explicitly by a user
//! with the lease role, and released when that log-in ends or its last connection has been
//! closed for [`LEASE_GRACE`] (a page reloaded keeps it). Another log-in of the same user (another
//! browser) does not hold it: control belongs to the session that took it. Every page is told
//! who holds it, and so is the bus ([`CONTROL_TOPIC`]).
//!
//! Taking control may keep what the vehicle was last commanded (the page shows it first, and the
//! pilot confirms): a helm that steps back while someone has control then leaves the vehicle on
//! the course it was on, held by the console, instead of letting its keep-alive lapse.
//!
//! A fleet console holds one lease per vehicle: a layout written for one vehicle
//! (`<layout vehicle="${vehicle}">`) sends its commands under that vehicle's control, which is
//! taken and released on its own (one pilot may fly auv1 while another flies auv2). Layouts
//! without a vehicle share the console's one control (the vehicle `""` here).

use super::{Client, Hub, now_s};
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
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LeaseError {
    /// The user lacks the lease role.
    #[error("taking control needs role {0}")]
    RoleNeeded(String),
    /// Another user holds control.
    #[error("{0} has control; they must release it")]
    HeldBy(String),
    /// The same user holds control in another log-in (another browser, another machine).
    #[error("you have control in another log-in; release it there")]
    HeldElsewhere,
    /// Only the holder releases control.
    #[error("you do not have control")]
    NotHolder,
    /// What the page showed would be kept is no longer what the vehicle was last commanded.
    #[error("control not taken: {command} changed while you confirmed (now {now}); look again")]
    Changed {
        /// The command the page showed.
        command: String,
        /// What it would keep now.
        now: String,
    },
    /// What the page asked to keep is not a kept command of its layout.
    #[error("control not taken: {0}")]
    NotKept(String),
}

/// Who holds control: one log-in of a user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Holder {
    pub(super) user: String,
    pub(super) session: u64,
}

impl Holder {
    pub(super) fn of(session: &Session) -> Holder {
        Holder {
            user: session.user.clone(),
            session: session.id,
        }
    }
}

/// Who holds control of each vehicle, since when, and the open connections of each log-in.
#[derive(Debug, Default)]
pub(super) struct Lease {
    /// For each vehicle held (`""`: the console's one control), the holder and when they took
    /// control (seconds since the epoch).
    holders: BTreeMap<String, (Holder, f64)>,
    /// Open connections per session.
    connections: HashMap<u64, usize>,
    /// When the last connection of a session with none open closed.
    gone_since: HashMap<u64, Instant>,
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
    #[cfg(test)]
    pub(super) fn holder(&self, vehicle: &str) -> Option<&str> {
        self.holders.get(vehicle).map(|(h, _)| h.user.as_str())
    }

    /// Who holds control of `vehicle`.
    pub(super) fn holding(&self, vehicle: &str) -> Option<&Holder> {
        self.holders.get(vehicle).map(|(h, _)| h)
    }

    /// Whether session `session` holds control of `vehicle`.
    pub(super) fn holds(&self, vehicle: &str, session: u64) -> bool {
        self.holding(vehicle).is_some_and(|h| h.session == session)
    }

    /// The `lease` message of `vehicle`: its holder's name and log-in (`session`, which a page
    /// compares with its own).
    pub(super) fn json(&self, vehicle: &str) -> Json {
        let v = vehicle_json(vehicle);
        match self.holders.get(vehicle) {
            Some((h, since)) => json!({"type": "lease", "vehicle": v, "holder": h.user,
                                       "session": h.session, "since": since}),
            None => json!({"type": "lease", "vehicle": v, "holder": null, "session": null,
                           "since": null}),
        }
    }

    /// The `lease` messages of every vehicle held.
    pub(super) fn all_json(&self) -> Vec<Json> {
        self.holders.keys().map(|v| self.json(v)).collect()
    }

    /// What [`CONTROL_TOPIC`] carries for `vehicle`: `holder` (empty when free) and `since`.
    fn control(&self, vehicle: &str) -> DataMap {
        let (holder, since) = self
            .holders
            .get(vehicle)
            .map(|(h, since)| (h.user.clone(), *since))
            .unwrap_or_default();
        DataMap::new().with("holder", holder).with("since", since)
    }

    /// A connection of session `session` opened.
    pub(super) fn connected(&mut self, session: u64) {
        *self.connections.entry(session).or_default() += 1;
        self.gone_since.remove(&session);
    }

    /// A connection of session `session` closed at `now`.
    pub(super) fn disconnected(&mut self, session: u64, now: Instant) {
        if let Some(n) = self.connections.get_mut(&session) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                self.connections.remove(&session);
                self.gone_since.insert(session, now);
            }
        }
    }

    /// `holder` takes control of `vehicle` at `since`: true when they did, false when they held
    /// it already.
    pub(super) fn take(
        &mut self,
        vehicle: &str,
        holder: &Holder,
        since: f64,
    ) -> Result<bool, LeaseError> {
        match self.holding(vehicle) {
            Some(h) if h == holder => Ok(false),
            Some(h) if h.user == holder.user => Err(LeaseError::HeldElsewhere),
            Some(h) => Err(LeaseError::HeldBy(h.user.clone())),
            None => {
                self.holders
                    .insert(vehicle.to_string(), (holder.clone(), since));
                Ok(true)
            }
        }
    }

    /// `holder` releases control of `vehicle`.
    pub(super) fn release(&mut self, vehicle: &str, holder: &Holder) -> Result<(), LeaseError> {
        if self.holding(vehicle) != Some(holder) {
            return Err(LeaseError::NotHolder);
        }
        self.holders.remove(vehicle);
        Ok(())
    }

    /// The vehicles `holder` controls.
    pub(super) fn held_by(&self, holder: &Holder) -> Vec<String> {
        self.holders
            .iter()
            .filter(|(_, (h, _))| h == holder)
            .map(|(v, _)| v.clone())
            .collect()
    }

    /// Releases the control held by sessions that have had no connection open for
    /// [`LEASE_GRACE`] at `now`; returns each vehicle released with who held it.
    pub(super) fn expire(&mut self, now: Instant) -> Vec<(String, Holder)> {
        let gone = |session: u64| {
            self.gone_since
                .get(&session)
                .is_some_and(|t| now.duration_since(*t) >= LEASE_GRACE)
        };
        let released: Vec<(String, Holder)> = self
            .holders
            .iter()
            .filter(|(_, (h, _))| gone(h.session))
            .map(|(v, (h, _))| (v.clone(), h.clone()))
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

    /// Takes or releases control of `vehicle` (`""`: the console's one control) for `session`'s
    /// log-in, keeping nothing. Releasing stops the holder's dead-man and kept commands of that
    /// vehicle (their neutral goes once).
    pub async fn lease(
        &self,
        session: &Session,
        vehicle: &str,
        take: bool,
    ) -> Result<(), LeaseError> {
        if take {
            return self.take_control(session, None, vehicle, &[]).await;
        }
        let holder = Holder::of(session);
        let stopped = {
            let mut st = self.state();
            st.lease.release(vehicle, &holder)?;
            st.drives
                .take(|_, d| d.session == session.id && d.vehicle() == vehicle)
        };
        tracing::info!(component = "console", user = %session.user, vehicle, "released control");
        self.lease_changed(vehicle).await;
        self.neutral(stopped, "control released").await;
        self.end_kept(
            // not one kept since under control taken again
            |k, lease| k.session == session.id && k.vehicle() == vehicle && !k.in_control(lease),
            "control released",
        )
        .await;
        Ok(())
    }

    /// Takes control of `vehicle` for `client`'s log-in and keeps what the vehicle was last
    /// commanded on each of `keep`'s commands (kept commands of the client's layout), so that
    /// the vehicle goes on as it was when whatever commanded it steps back. `keep` holds the
    /// values the page showed the pilot before they confirmed: when the vehicle's last commanded
    /// values are no longer those, control is not taken (the page shows them again).
    pub async fn take_keeping(
        &self,
        client: &Client,
        vehicle: &str,
        keep: &[(String, DataMap)],
    ) -> Result<(), LeaseError> {
        self.take_control(&client.session, Some(client), vehicle, keep)
            .await
    }

    async fn take_control(
        &self,
        session: &Session,
        client: Option<&Client>,
        vehicle: &str,
        keep: &[(String, DataMap)],
    ) -> Result<(), LeaseError> {
        if !session.has(&self.settings.lease_role) {
            return Err(LeaseError::RoleNeeded(self.settings.lease_role.clone()));
        }
        // what is kept goes out before anything else can be decided (a take keeping nothing does
        // not wait for commands on their way)
        let _sending = if keep.is_empty() {
            None
        } else {
            Some(self.sending.lock().await)
        };
        let kept = {
            let mut st = self.state();
            let mut kept = Vec::new();
            for (name, shown) in keep {
                let decl = client
                    .and_then(|c| c.layout.as_ref())
                    .and_then(|l| l.commands.get(name))
                    .filter(|d| d.keep.is_some() && d.lease && d.vehicle() == vehicle)
                    .ok_or_else(|| {
                        LeaseError::NotKept(format!(
                            "`{name}` is not a kept command of this layout under this control"
                        ))
                    })?;
                let chosen = client
                    .and_then(|c| c.offers.get(name))
                    .map(|o| o.free.clone())
                    .unwrap_or_default();
                let now = st
                    .commanded
                    .get(&decl.topic)
                    .and_then(|c| decl.build(c, &DataMap::new(), &chosen).ok());
                // each field as the page showed it, and no other
                let same = |now: &DataMap| {
                    now.len() == shown.len()
                        && shown
                            .iter()
                            .all(|(k, v)| decl.fit(k, v).is_ok_and(|v| now.get(k) == Some(&v)))
                };
                match now {
                    Some(now) if same(&now) => kept.push((decl.clone(), now)),
                    now => {
                        return Err(LeaseError::Changed {
                            command: name.clone(),
                            now: now.map_or("nothing commanded".to_string(), |n| n.to_string()),
                        });
                    }
                }
            }
            if !st.lease.take(vehicle, &Holder::of(session), now_s())? {
                return Ok(());
            }
            kept
        };
        tracing::info!(component = "console", user = %session.user, vehicle, "took control");
        self.lease_changed(vehicle).await;
        for (decl, fields) in kept {
            self.sending_instead(&decl);
            match self
                .publish(&session.user, &decl.name, &decl.topic, fields.clone())
                .await
            {
                Ok((_, seq)) => self.sent(session, &decl, &fields, seq),
                Err(e) => tracing::warn!(
                    component = "console",
                    user = %session.user,
                    command = %decl.name,
                    "not kept on taking control: {e}"
                ),
            }
        }
        Ok(())
    }

    /// Releases every vehicle `session`'s log-in controls (its log-out): another log-in of the
    /// same user keeps what it holds.
    pub async fn release_everything(&self, session: &Session) {
        let held = self.state().lease.held_by(&Holder::of(session));
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

    /// `ana` (session 1) or `bo` (session 2).
    fn holder(user: &str) -> Holder {
        let session = if user == "ana" { 1 } else { 2 };
        Holder {
            user: user.to_string(),
            session,
        }
    }

    #[test]
    fn control_is_taken_and_released_by_its_holder() {
        let mut lease = Lease::default();
        assert_eq!(lease.take("", &holder("ana"), 1.0), Ok(true));
        assert_eq!(lease.holder(""), Some("ana"));
        assert_eq!(
            lease.json(""),
            json!({"type": "lease", "vehicle": null, "holder": "ana", "session": 1, "since": 1.0})
        );
        // taking it again changes nothing, not even since when
        assert_eq!(lease.take("", &holder("ana"), 2.0), Ok(false));
        assert_eq!(lease.json("")["since"], 1.0);
        assert_eq!(lease.release("", &holder("ana")), Ok(()));
        assert_eq!(lease.holder(""), None);
        assert_eq!(
            lease.json(""),
            json!({"type": "lease", "vehicle": null, "holder": null, "session": null, "since": null})
        );
        let again = lease.release("", &holder("ana")).unwrap_err();
        assert_eq!(again, LeaseError::NotHolder);
        assert_eq!(again.to_string(), "you do not have control");
    }

    #[test]
    fn a_second_user_is_refused_until_the_holder_releases() {
        let mut lease = Lease::default();
        lease.take("", &holder("ana"), 1.0).unwrap();
        let refused = lease.take("", &holder("bo"), 2.0).unwrap_err();
        assert_eq!(refused, LeaseError::HeldBy("ana".into()));
        assert_eq!(refused.to_string(), "ana has control; they must release it");
        assert_eq!(lease.release("", &holder("bo")), Err(LeaseError::NotHolder));
        assert_eq!(lease.holder(""), Some("ana"));
        lease.release("", &holder("ana")).unwrap();
        assert_eq!(lease.take("", &holder("bo"), 3.0), Ok(true));
        assert_eq!(lease.holder(""), Some("bo"));
    }

    #[tokio::test(start_paused = true)]
    async fn control_is_released_10_s_after_the_holders_last_connection_closes() {
        let mut lease = Lease::default();
        lease.connected(1);
        lease.connected(1);
        lease.take("", &holder("ana"), 1.0).unwrap();
        lease.disconnected(1, Instant::now());
        tokio::time::advance(Duration::from_secs(60)).await;
        // one connection is still open
        assert!(lease.expire(Instant::now()).is_empty());
        lease.disconnected(1, Instant::now());
        tokio::time::advance(LEASE_GRACE - Duration::from_millis(1)).await;
        assert!(lease.expire(Instant::now()).is_empty());
        assert_eq!(lease.holder(""), Some("ana"));
        tokio::time::advance(Duration::from_millis(1)).await;
        assert_eq!(
            lease.expire(Instant::now()),
            [(String::new(), holder("ana"))]
        );
        assert_eq!(lease.holder(""), None);
        assert!(lease.expire(Instant::now()).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn a_holder_back_within_the_grace_keeps_control() {
        let mut lease = Lease::default();
        lease.connected(1);
        lease.take("", &holder("ana"), 1.0).unwrap();
        lease.disconnected(1, Instant::now());
        tokio::time::advance(Duration::from_secs(9)).await;
        lease.connected(1);
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
                json!({"type": "lease", "vehicle": null, "holder": "ana",
                       "session": client.session.id, "since": shown[0]["since"]}),
                json!({"type": "lease", "vehicle": null, "holder": null, "session": null, "since": null}),
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
                   "session": ana.session.id,
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
