//! Commands: who may send what (roles, control), confirmations (an arm used once, within
//! [`ARM_LIFETIME`], no sooner than its hold time), dead-man commands (re-sends published at the
//! command's rate, neutral once when they stop), and building and publishing a command the
//! layout opened by the connection declares.

use super::history::Entry;
use super::{Client, Hub};
use crate::auth::Session;
use crate::layout::{CommandDecl, Confirm};
use seabus_medium::{DataMap, SendError, Topic};
use std::collections::HashMap;
use std::time::Duration;
use tokio::time::Instant;

/// How long an armed command may wait for its send.
pub const ARM_LIFETIME: Duration = Duration::from_secs(10);
/// Confirmations one connection may have waiting.
pub const ARMS_PER_CONNECTION: usize = 8;
/// Dead-man re-sends may be this many periods late before the neutral command goes.
pub const DRIVE_PERIODS: u32 = 3;

/// Why a command is not sent (or armed); the text is what the page and the history show.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommandError {
    /// The connection has not opened that layout.
    #[error("layout `{0}` is not open")]
    LayoutNotOpen(String),
    /// The layout declares no such command.
    #[error("layout `{layout}` has no command `{command}`")]
    UnknownCommand {
        /// The layout.
        layout: String,
        /// The command asked for.
        command: String,
    },
    /// The user lacks the command's role.
    #[error("role {0} needed")]
    RoleNeeded(String),
    /// Another user holds control.
    #[error("no control: {0} has it")]
    ControlHeldBy(String),
    /// The same user holds control in another log-in.
    #[error("no control: you have it in another log-in")]
    ControlElsewhere,
    /// No one holds control.
    #[error("no control: take control first")]
    NoControl,
    /// Only confirmed commands are armed.
    #[error("`{0}` needs no confirmation")]
    NeedsNoConfirmation(String),
    /// The connection has [`ARMS_PER_CONNECTION`] arms waiting.
    #[error("too many commands waiting for confirmation")]
    TooManyArmed,
    /// A confirmed command sent without an arm.
    #[error("not confirmed")]
    NotConfirmed,
    /// The arm given is not one of this connection's for this command (or was used).
    #[error("not confirmed: arm it first")]
    NotArmed,
    /// The arm is older than [`ARM_LIFETIME`].
    #[error("not confirmed: the confirmation expired")]
    ArmExpired,
    /// A held command sent before its hold time.
    #[error("not confirmed: held {} ms of {} ms", .held.as_millis(), .hold.as_millis())]
    HeldTooShort {
        /// How long it was held.
        held: Duration,
        /// How long it must be held.
        hold: Duration,
    },
    /// The fields do not fit the command (the reason from [`CommandDecl::build`]).
    #[error("{0}")]
    Fields(String),
    /// A value no control of the layout sends, in a field its buttons or keys fix.
    #[error("field `{field}` is set by the layout's controls, and none of them sends {value}")]
    NotOffered {
        /// The field.
        field: String,
        /// The value the page proposed.
        value: String,
    },
    /// A dead-man re-send of a command without a rate.
    #[error("`{0}` is not a dead-man command (no rate)")]
    NotDeadMan(String),
    /// A dead-man re-send of a confirmed command.
    #[error("`{0}` needs confirmation")]
    NeedsConfirmation(String),
    /// The bus refused it.
    #[error("not sent: {0}")]
    NotSent(#[source] SendError),
}

/// A command armed for confirmation.
#[derive(Debug)]
struct Arm {
    conn: u64,
    layout: String,
    command: String,
    at: Instant,
}

/// The commands armed for confirmation, by id.
#[derive(Debug, Default)]
pub(super) struct Arms {
    armed: HashMap<u64, Arm>,
    next: u64,
}

impl Arms {
    /// Arms `command` of `layout` for connection `conn` at `now`; returns the arm's id. Arms older
    /// than [`ARM_LIFETIME`] are dropped; a connection has at most [`ARMS_PER_CONNECTION`].
    fn arm(
        &mut self,
        conn: u64,
        layout: &str,
        command: &str,
        now: Instant,
    ) -> Result<u64, CommandError> {
        self.armed
            .retain(|_, a| now.duration_since(a.at) < ARM_LIFETIME);
        if self.armed.values().filter(|a| a.conn == conn).count() >= ARMS_PER_CONNECTION {
            return Err(CommandError::TooManyArmed);
        }
        self.next += 1;
        let arm = Arm {
            conn,
            layout: layout.to_string(),
            command: command.to_string(),
            at: now,
        };
        self.armed.insert(self.next, arm);
        Ok(self.next)
    }

    /// Uses arm `id` (gone whatever the answer) for `command` of `layout` sent by `conn` at `now`:
    /// it must be theirs, younger than [`ARM_LIFETIME`] and at least `hold` old.
    fn confirm(
        &mut self,
        id: u64,
        (conn, layout, command): (u64, &str, &str),
        hold: Duration,
        now: Instant,
    ) -> Result<(), CommandError> {
        let mine = self
            .armed
            .get(&id)
            .is_some_and(|a| a.conn == conn && a.layout == layout && a.command == command);
        let arm = self
            .armed
            .remove(&id)
            .filter(|_| mine)
            .ok_or(CommandError::NotArmed)?;
        let held = now.duration_since(arm.at);
        if held > ARM_LIFETIME {
            return Err(CommandError::ArmExpired);
        }
        if held < hold {
            return Err(CommandError::HeldTooShort { held, hold });
        }
        Ok(())
    }
}

/// A dead-man command being driven: by a connection, in a layout, by name.
pub(super) type DriveKey = (u64, String, String);

/// A dead-man command being driven.
#[derive(Debug, Clone)]
pub(super) struct Drive {
    pub(super) user: String,
    /// The log-in it is sent under.
    pub(super) session: u64,
    /// The vehicle whose control it is sent under (`""`: the console's one control).
    vehicle: String,
    name: String,
    topic: Topic,
    neutral: DataMap,
    period: Duration,
    /// The last re-send from the page.
    last: Instant,
    /// The last one published.
    sent: Instant,
}

/// The dead-man commands being driven.
#[derive(Debug, Default)]
pub(super) struct Drives {
    running: HashMap<DriveKey, Drive>,
}

impl Drive {
    /// The vehicle whose control it is sent under (`""`: the console's one control).
    pub(super) fn vehicle(&self) -> &str {
        &self.vehicle
    }
}

impl Drives {
    fn running(&self, key: &DriveKey) -> bool {
        self.running.contains_key(key)
    }

    /// Whether a dead-man command is being driven on `topic`.
    pub(super) fn driving(&self, topic: &Topic) -> bool {
        self.running.values().any(|d| &d.topic == topic)
    }

    /// Records a re-send (`drive.last`): whether it is the first, and whether it is due to be
    /// published (re-sends faster than the command's rate keep it alive but are not all
    /// published).
    fn renew(&mut self, key: DriveKey, mut drive: Drive) -> (bool, bool) {
        let now = drive.last;
        let previous = self.running.get(&key).map(|d| d.sent);
        let due = previous.is_none_or(|t| now.duration_since(t) >= drive.period.mul_f64(0.8));
        drive.sent = if due { now } else { previous.unwrap_or(now) };
        self.running.insert(key, drive);
        (previous.is_none(), due)
    }

    /// Removes and returns the drives `stop` picks.
    pub(super) fn take(&mut self, stop: impl Fn(&DriveKey, &Drive) -> bool) -> Vec<Drive> {
        super::take_where(&mut self.running, stop)
    }

    /// Removes and returns the drives whose re-sends stopped [`DRIVE_PERIODS`] periods ago.
    pub(super) fn stale(&mut self, now: Instant) -> Vec<Drive> {
        self.take(|_, d| now.duration_since(d.last) > d.period * DRIVE_PERIODS)
    }
}

impl Hub {
    /// The declaration of `command` in the layout the client opened as `layout`.
    fn decl<'a>(
        client: &'a Client,
        layout: &str,
        command: &str,
    ) -> Result<&'a CommandDecl, CommandError> {
        let l = client
            .layout
            .as_ref()
            .filter(|l| l.name == layout)
            .ok_or_else(|| CommandError::LayoutNotOpen(layout.to_string()))?;
        l.commands
            .get(command)
            .ok_or_else(|| CommandError::UnknownCommand {
                layout: layout.to_string(),
                command: command.to_string(),
            })
    }

    /// Refuses a value the layout's controls would never send (a page that fixes a button's
    /// field to something else): what a command carries is the pilot's choice or the layout's —
    /// a control's, or the value the command itself declares.
    fn offered(client: &Client, decl: &CommandDecl, set: &DataMap) -> Result<(), CommandError> {
        let Some(offers) = client.offers.get(&decl.name) else {
            return Ok(());
        };
        for (field, value) in set.iter() {
            let fitted = decl.fit(field, value).map_err(CommandError::Fields)?;
            let same = |fixed: &seabus_medium::Value, v: &seabus_medium::Value| {
                decl.fit(field, fixed).is_ok_and(|f| &f == v)
            };
            let declared = decl.fields.get(field).is_some_and(|d| same(d, &fitted));
            if !declared && !offers.allows(field, &fitted, same) {
                tracing::warn!(
                    component = "console",
                    user = %client.session.user,
                    command = %decl.name,
                    "refused `{field}` = {value}: no control of the layout sends it"
                );
                return Err(CommandError::NotOffered {
                    field: field.to_string(),
                    value: value.to_string(),
                });
            }
        }
        Ok(())
    }

    /// What stops `session` from sending `decl` now.
    fn allowed(&self, session: &Session, decl: &CommandDecl) -> Result<(), CommandError> {
        let role = decl.role.as_deref().unwrap_or(&self.settings.lease_role);
        if !session.has(role) {
            return Err(CommandError::RoleNeeded(role.to_string()));
        }
        if decl.lease {
            match self.state().lease.holding(decl.vehicle()) {
                Some(h) if h.session == session.id => {}
                Some(h) if h.user == session.user => return Err(CommandError::ControlElsewhere),
                Some(h) => return Err(CommandError::ControlHeldBy(h.user.clone())),
                None => return Err(CommandError::NoControl),
            }
        }
        Ok(())
    }

    /// Arms a confirmed command; returns the arm id.
    pub fn arm(&self, client: &Client, layout: &str, command: &str) -> Result<u64, CommandError> {
        let decl = Hub::decl(client, layout, command)?;
        self.allowed(&client.session, decl)?;
        if matches!(decl.confirm, Confirm::None) {
            return Err(CommandError::NeedsNoConfirmation(command.to_string()));
        }
        self.state()
            .arms
            .arm(client.conn, layout, command, Instant::now())
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
    ) -> Result<u64, CommandError> {
        let checked = self.checked(client, layout, command, set, confirmed);
        match checked {
            Ok((topic, fields)) => {
                let decl = Hub::decl(client, layout, command)?;
                let _sending = self.sending.lock().await;
                self.sending_instead(decl);
                let user = &client.session.user;
                let (id, seq) = self.publish(user, command, &topic, fields.clone()).await?;
                self.sent(&client.session, decl, &fields, seq);
                Ok(id)
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
    ) -> Result<(Topic, DataMap), CommandError> {
        let decl = Hub::decl(client, layout, command)?;
        self.allowed(&client.session, decl)?;
        Hub::offered(client, decl, set)?;
        let hold = match decl.confirm {
            Confirm::None => None,
            Confirm::Dialog => Some(Duration::ZERO),
            Confirm::Hold(d) => Some(d),
        };
        if let Some(hold) = hold {
            let id = confirmed.ok_or(CommandError::NotConfirmed)?;
            let sender = (client.conn, layout, command);
            self.state()
                .arms
                .confirm(id, sender, hold, Instant::now())?;
        }
        let chosen = client
            .offers
            .get(command)
            .map(|o| o.free.clone())
            .unwrap_or_default();
        let fields = decl
            .build(&self.current(decl), set, &chosen)
            .map_err(CommandError::Fields)?;
        Ok((decl.topic.clone(), fields))
    }

    /// Publishes a command and records it as pending (or, when the bus refuses it, refused):
    /// its id in the history and its sequence number on the bus. Callers hold
    /// [`Hub::sending`].
    pub(super) async fn publish(
        &self,
        user: &str,
        command: &str,
        topic: &Topic,
        fields: DataMap,
    ) -> Result<(u64, u64), CommandError> {
        let seq = self
            .emit(topic, &fields)
            .await
            .map_err(CommandError::NotSent);
        let entry = Entry::new(user, command, topic.as_str(), &fields);
        let entry = match &seq {
            Ok(s) => entry.pending(*s),
            Err(e) => entry.refused(&e.to_string()),
        };
        let (state, reason) = (entry.state.clone(), entry.reason.clone());
        let id = self.record(entry);
        tracing::info!(component = "console", user, command, topic = %topic, "command {id}: {state} {reason}");
        Ok((id, seq?))
    }

    /// A dead-man command's re-send (`drive`).
    pub async fn drive(
        &self,
        client: &mut Client,
        layout: &str,
        command: &str,
        set: &DataMap,
    ) -> Result<(), CommandError> {
        let decl = Hub::decl(client, layout, command)?;
        let Some(rate) = decl.rate_hz else {
            return Err(CommandError::NotDeadMan(command.to_string()));
        };
        if !matches!(decl.confirm, Confirm::None) {
            return Err(CommandError::NeedsConfirmation(command.to_string()));
        }
        let key = (client.conn, layout.to_string(), command.to_string());
        let (topic, fields) = match self.checked(client, layout, command, set, None) {
            Ok(x) => x,
            Err(reason) => {
                // a refusal once, not at every re-send
                let running = self.state().drives.running(&key);
                if !running {
                    self.record_refusal(&client.session.user, decl, set, &reason);
                }
                return Err(reason);
            }
        };
        let neutral = super::keep::overlay(&fields, &decl.neutral);
        let now = Instant::now();
        let drive = Drive {
            user: client.session.user.clone(),
            session: client.session.id,
            vehicle: decl.vehicle().to_string(),
            name: command.to_string(),
            topic,
            neutral,
            period: Duration::from_secs_f64(1.0 / rate.max(0.01)),
            last: now,
            sent: now,
        };
        let (first, due) = self.state().drives.renew(key.clone(), drive.clone());
        let sent = self.drive_send(&drive, fields, first, due).await;
        // stopped while this was being sent (released, control lost): its neutral may have gone
        // first, so it goes again after
        let stopped = due && !self.state().drives.running(&key);
        if stopped {
            self.neutral(vec![drive], "stopped while sending").await;
        }
        sent
    }

    /// Publishes a re-send of `drive` with `fields` when it is due: the first into the history
    /// (re-sends are not acknowledged one by one), the others straight to the bus.
    async fn drive_send(
        &self,
        drive: &Drive,
        fields: DataMap,
        first: bool,
        due: bool,
    ) -> Result<(), CommandError> {
        if !first && !due {
            return Ok(());
        }
        let _sending = self.sending.lock().await;
        if first {
            // the stick takes the topic over from a kept command
            self.stop_keeping(
                |k| k.topic == drive.topic,
                &format!("{} driven", drive.name),
            );
            self.publish(&drive.user, &drive.name, &drive.topic, fields)
                .await
                .map(|_| ())
        } else {
            self.emit(&drive.topic, &fields)
                .await
                .map(|_| ())
                .map_err(CommandError::NotSent)
        }
    }

    /// The end of a dead-man command (`release`): neutral once.
    pub async fn release(&self, client: &Client, layout: &str, command: &str) {
        let key = (client.conn, layout.to_string(), command.to_string());
        let stopped = self.state().drives.take(|k, _| *k == key);
        self.neutral(stopped, "released").await;
    }

    /// Sends each stopped drive's neutral command once.
    pub(super) async fn neutral(&self, stopped: Vec<Drive>, why: &str) {
        if stopped.is_empty() {
            return;
        }
        let _sending = self.sending.lock().await;
        for d in stopped {
            tracing::info!(component = "console", user = %d.user, command = %d.name, "neutral: {why}");
            // nothing kept on the topic goes on after the neutral
            self.stop_keeping(|k| k.topic == d.topic, &format!("{} stopped", d.name));
            let _ = self.publish(&d.user, &d.name, &d.topic, d.neutral).await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{Fixture, field, waiting};
    use super::*;
    use seabus_medium::{Message, Value};

    /// The fields `k=v`.
    fn set(k: &'static str, v: impl Into<Value>) -> DataMap {
        DataMap::new().with(k, v)
    }

    /// Sends `command` of the pilot layout with `fields`.
    async fn send(
        f: &Fixture,
        client: &mut Client,
        command: &str,
        fields: DataMap,
        confirmed: Option<u64>,
    ) -> Result<u64, CommandError> {
        f.hub
            .send(client, "pilot", command, &fields, confirmed)
            .await
    }

    /// Drives `command` of the pilot layout with `fields`.
    async fn drive(
        f: &Fixture,
        client: &mut Client,
        command: &str,
        fields: DataMap,
    ) -> Result<(), CommandError> {
        f.hub.drive(client, "pilot", command, &fields).await
    }

    /// The commands, states and reasons of the history, oldest first.
    fn history(f: &Fixture) -> Vec<(String, String, String)> {
        let h = f.hub.history();
        h["commands"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                let s = |k: &str| c[k].as_str().unwrap().to_string();
                (s("command"), s("state"), s("reason"))
            })
            .collect()
    }

    /// How many of `sent` are the course's neutral (`speed=0`).
    fn neutrals(sent: &[Message]) -> usize {
        sent.iter()
            .filter(|m| field(m, "speed") == Some(Value::Int(0)))
            .count()
    }

    #[tokio::test]
    async fn an_unarmed_confirmed_command_is_refused_and_everyone_sees_it() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        let refused = send(&f, &mut ana, "abort", DataMap::new(), None).await;
        assert_eq!(refused, Err(CommandError::NotConfirmed));
        assert_eq!(refused.unwrap_err().to_string(), "not confirmed");
        // an arm of another command does not confirm it either
        let start = f.hub.arm(&ana, "pilot", "start").unwrap();
        let refused = send(&f, &mut ana, "abort", DataMap::new(), Some(start)).await;
        assert_eq!(
            refused.unwrap_err().to_string(),
            "not confirmed: arm it first"
        );
        assert!(waiting(&mut driver).is_empty());
        let refusal = |reason: &str| {
            (
                "abort".to_string(),
                "refused".to_string(),
                reason.to_string(),
            )
        };
        assert_eq!(
            history(&f),
            [
                refusal("not confirmed"),
                refusal("not confirmed: arm it first")
            ]
        );
    }

    #[tokio::test]
    async fn an_arm_is_used_once() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        let arm = f.hub.arm(&ana, "pilot", "abort").unwrap();
        send(&f, &mut ana, "abort", DataMap::new(), Some(arm))
            .await
            .unwrap();
        let sent = waiting(&mut driver);
        assert_eq!(sent.len(), 1);
        assert_eq!(field(&sent[0], "action"), Some(Value::from("abort")));
        let again = send(&f, &mut ana, "abort", DataMap::new(), Some(arm)).await;
        assert_eq!(again, Err(CommandError::NotArmed));
        assert!(waiting(&mut driver).is_empty());
    }

    #[tokio::test]
    async fn a_value_no_control_sends_is_refused_and_nothing_reaches_the_vehicle() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        // the abort button sends the declared `action=abort`; a page that fixes `surface` is refused
        let arm = f.hub.arm(&ana, "pilot", "abort").unwrap();
        let forged = send(
            &f,
            &mut ana,
            "abort",
            DataMap::new().with("action", "surface"),
            Some(arm),
        )
        .await;
        assert_eq!(
            forged.unwrap_err().to_string(),
            "field `action` is set by the layout's controls, and none of them sends \"surface\""
        );
        assert!(
            waiting(&mut driver).is_empty(),
            "nothing reaches the vehicle"
        );
        // the camera's note has no control on this layout; its `on` has a toggle
        let note = send(
            &f,
            &mut ana,
            "camera",
            DataMap::new().with("note", "y"),
            None,
        )
        .await;
        assert!(
            matches!(note, Err(CommandError::NotOffered { ref field, .. }) if field == "note"),
            "{note:?}"
        );
        send(
            &f,
            &mut ana,
            "camera",
            DataMap::new().with("on", true),
            None,
        )
        .await
        .unwrap();
        let sent = waiting(&mut driver);
        assert_eq!(sent.len(), 1);
        assert_eq!(field(&sent[0], "on"), Some(Value::from(true)));
        assert_eq!(field(&sent[0], "note"), Some(Value::from("x")));
        // the refusals are in everyone's history
        let refused: Vec<String> = f.hub.history()["commands"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| c["state"] == "refused")
            .map(|c| c["command"].as_str().unwrap().to_string())
            .collect();
        assert_eq!(refused, ["abort", "camera"]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_held_command_goes_no_sooner_than_its_hold_nor_after_the_arms_lifetime() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        let early = f.hub.arm(&ana, "pilot", "start").unwrap();
        tokio::time::advance(Duration::from_millis(100)).await;
        let refused = send(&f, &mut ana, "start", DataMap::new(), Some(early)).await;
        assert_eq!(
            refused.unwrap_err().to_string(),
            "not confirmed: held 100 ms of 300 ms"
        );
        // the early send used the arm up
        tokio::time::advance(Duration::from_millis(300)).await;
        let reused = send(&f, &mut ana, "start", DataMap::new(), Some(early)).await;
        assert_eq!(reused, Err(CommandError::NotArmed));
        let held = f.hub.arm(&ana, "pilot", "start").unwrap();
        tokio::time::advance(Duration::from_millis(300)).await;
        send(&f, &mut ana, "start", DataMap::new(), Some(held))
            .await
            .unwrap();
        assert_eq!(waiting(&mut driver).len(), 1);
        let late = f.hub.arm(&ana, "pilot", "start").unwrap();
        tokio::time::advance(ARM_LIFETIME + Duration::from_millis(1)).await;
        let refused = send(&f, &mut ana, "start", DataMap::new(), Some(late)).await;
        assert_eq!(
            refused.unwrap_err().to_string(),
            "not confirmed: the confirmation expired"
        );
        assert!(waiting(&mut driver).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn arms_are_for_confirmed_commands_and_capped_per_connection() {
        let f = Fixture::new();
        let ana = f.pilot("ana").await;
        let refused = f.hub.arm(&ana, "pilot", "course").unwrap_err();
        assert_eq!(refused.to_string(), "`course` needs no confirmation");
        for _ in 0..ARMS_PER_CONNECTION {
            f.hub.arm(&ana, "pilot", "abort").unwrap();
        }
        let refused = f.hub.arm(&ana, "pilot", "abort").unwrap_err();
        assert_eq!(
            refused.to_string(),
            "too many commands waiting for confirmation"
        );
        // another connection of the same log-in has arms of its own
        let mut other = f.hub.connect(ana.session.clone());
        f.hub.open(&mut other, "pilot", &Default::default());
        f.hub.arm(&other, "pilot", "abort").unwrap();
        // expired arms make room
        tokio::time::advance(ARM_LIFETIME).await;
        f.hub.arm(&ana, "pilot", "abort").unwrap();
    }

    #[tokio::test]
    async fn commands_need_their_role_and_control_and_a_declaration() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut bo = f.client("bo");
        // no control needed for the camera
        send(&f, &mut bo, "camera", set("on", true), None)
            .await
            .unwrap();
        assert_eq!(waiting(&mut driver).len(), 1);
        let refused = send(&f, &mut bo, "course", set("speed", 1), None).await;
        assert_eq!(
            refused.unwrap_err().to_string(),
            "no control: take control first"
        );
        let mut ana = f.pilot("ana").await;
        let refused = send(&f, &mut bo, "course", set("speed", 1), None).await;
        assert_eq!(refused.unwrap_err().to_string(), "no control: ana has it");
        let anchor = send(&f, &mut ana, "anchor", DataMap::new(), None).await;
        assert_eq!(anchor.unwrap_err().to_string(), "role captain needed");
        let mut ivo = f.client("ivo");
        let refused = send(&f, &mut ivo, "camera", set("on", true), None).await;
        assert_eq!(refused.unwrap_err().to_string(), "role pilot needed");
        let too_fast = send(&f, &mut ana, "course", set("speed", 4), None).await;
        assert_eq!(
            too_fast.unwrap_err().to_string(),
            "field `speed`: 4 is above the maximum 3"
        );
        assert!(waiting(&mut driver).is_empty());
        let before = history(&f).len();
        let unknown = send(&f, &mut ana, "nope", DataMap::new(), None).await;
        assert_eq!(
            unknown.unwrap_err().to_string(),
            "layout `pilot` has no command `nope`"
        );
        let fields = set("speed", 1);
        let closed = f.hub.send(&mut ana, "watch", "course", &fields, None).await;
        assert_eq!(
            closed.unwrap_err().to_string(),
            "layout `watch` is not open"
        );
        // what the layout does not declare stays out of everyone's history
        assert_eq!(history(&f).len(), before);
    }

    #[tokio::test]
    async fn a_field_not_set_goes_as_last_commanded_never_as_the_layouts_value() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        // nothing commanded yet: the speed is unknown, and the layout's 0 does not stand in
        let refused = send(&f, &mut ana, "course", set("heading", 90), None).await;
        assert_eq!(
            refused.unwrap_err().to_string(),
            "`speed` has no known value (nothing commanded yet): set it"
        );
        assert!(waiting(&mut driver).is_empty());
        let both = DataMap::new().with("heading", 90).with("speed", 2);
        send(&f, &mut ana, "course", both, None).await.unwrap();
        // another page of another pilot starts from what was commanded, not from its layout
        f.hub.lease(&ana.session, "", false).await.unwrap();
        let mut bo = f.pilot("bo").await;
        send(&f, &mut bo, "course", set("heading", 45), None)
            .await
            .unwrap();
        let sent = waiting(&mut driver);
        let courses: Vec<_> = sent
            .iter()
            .filter(|m| m.topic.as_str() == "cmd.course")
            .collect();
        assert_eq!(courses.len(), 2);
        assert_eq!(field(courses[1], "heading"), Some(Value::Int(45)));
        assert_eq!(field(courses[1], "speed"), Some(Value::Int(2)));
    }

    #[tokio::test(start_paused = true)]
    async fn a_dead_man_command_goes_neutral_once_when_its_re_sends_stop() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        let ahead = || DataMap::new().with("heading", 45).with("speed", 2);
        drive(&f, &mut ana, "course", ahead()).await.unwrap();
        assert_eq!(waiting(&mut driver).len(), 1);
        // at the command's rate (5 Hz) each re-send is published; faster ones keep it alive only
        tokio::time::advance(Duration::from_millis(200)).await;
        drive(&f, &mut ana, "course", ahead()).await.unwrap();
        assert_eq!(waiting(&mut driver).len(), 1);
        tokio::time::advance(Duration::from_millis(50)).await;
        drive(&f, &mut ana, "course", ahead()).await.unwrap();
        assert!(waiting(&mut driver).is_empty());
        // three periods without a re-send are allowed
        tokio::time::advance(Duration::from_millis(600)).await;
        f.hub.watch().await;
        assert!(waiting(&mut driver).is_empty());
        tokio::time::advance(Duration::from_millis(1)).await;
        f.hub.watch().await;
        let neutral = waiting(&mut driver);
        assert_eq!(neutral.len(), 1);
        assert_eq!(field(&neutral[0], "speed"), Some(Value::Int(0)));
        assert_eq!(field(&neutral[0], "heading"), Some(Value::Int(45)));
        tokio::time::advance(Duration::from_secs(1)).await;
        f.hub.watch().await;
        f.hub.release(&ana, "pilot", "course").await;
        assert!(waiting(&mut driver).is_empty());
    }

    #[tokio::test]
    async fn release_control_loss_and_closing_each_send_neutral_once() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        let ahead = || DataMap::new().with("heading", 1).with("speed", 2);
        drive(&f, &mut ana, "course", ahead()).await.unwrap();
        f.hub.release(&ana, "pilot", "course").await;
        f.hub.release(&ana, "pilot", "course").await;
        assert_eq!(neutrals(&waiting(&mut driver)), 1);
        drive(&f, &mut ana, "course", ahead()).await.unwrap();
        f.hub.lease(&ana.session, "", false).await.unwrap();
        f.hub.release(&ana, "pilot", "course").await;
        assert_eq!(neutrals(&waiting(&mut driver)), 1);
        f.hub.lease(&ana.session, "", true).await.unwrap();
        drive(&f, &mut ana, "course", ahead()).await.unwrap();
        f.hub.disconnect(&ana).await;
        f.hub.release(&ana, "pilot", "course").await;
        assert_eq!(neutrals(&waiting(&mut driver)), 1);
    }

    #[tokio::test]
    async fn a_bad_re_send_of_a_running_drive_is_refused_without_a_history_entry() {
        let f = Fixture::new();
        let mut ana = f.pilot("ana").await;
        let stop = drive(&f, &mut ana, "abort", DataMap::new()).await;
        assert_eq!(
            stop.unwrap_err().to_string(),
            "`abort` is not a dead-man command (no rate)"
        );
        let ahead = DataMap::new().with("heading", 10).with("speed", 2);
        drive(&f, &mut ana, "course", ahead).await.unwrap();
        let before = history(&f).len();
        let too_fast = drive(&f, &mut ana, "course", set("speed", 9)).await;
        assert_eq!(
            too_fast.unwrap_err().to_string(),
            "field `speed`: 9 is above the maximum 3"
        );
        assert_eq!(history(&f).len(), before);
        // a drive that is not running has its refusal recorded
        let mut bo = f.client("bo");
        let refused = drive(&f, &mut bo, "course", set("speed", 1)).await;
        assert_eq!(refused.unwrap_err().to_string(), "no control: ana has it");
        let last = history(&f).pop();
        let want = ("course", "refused", "no control: ana has it");
        assert_eq!(last, Some((want.0.into(), want.1.into(), want.2.into())));
    }
}
