//! The command history: every command sent or refused, shown to everyone, `pending` until the
//! drivers' `cmd.status` for its origin and sequence number settles it as `acknowledged` or
//! `refused`, or [`Settings::ack_timeout`](super::Settings::ack_timeout) times it out. At most
//! [`HISTORY`] entries are kept (pending ones stay however old), and every state is appended to
//! the CSV command log.

use super::{Hub, now_s};
use crate::layout::CommandDecl;
use seabus_medium::{DataMap, Topic, Value};
use serde_json::{Value as Json, json};
use std::collections::VecDeque;
use std::io::Write;
use std::path::Path;
use std::time::Duration;
use tokio::time::Instant;

/// Commands kept in the history.
pub const HISTORY: usize = 200;
/// The longest text a refusal keeps of what a page sent.
pub const MAX_TEXT: usize = 256;

/// A command sent (or refused), as the history shows it.
#[derive(Debug, Clone)]
pub(super) struct Entry {
    id: u64,
    user: String,
    time: f64,
    command: String,
    topic: String,
    fields: DataMap,
    pub(super) state: String,
    pub(super) reason: String,
    /// The bus sequence number, while an acknowledgement is awaited.
    seq: Option<u64>,
    sent: Instant,
}

impl Entry {
    /// `command` (on `topic`, with `fields`) sent by `user` now; neither pending nor refused yet.
    pub(super) fn new(user: &str, command: &str, topic: &str, fields: &DataMap) -> Entry {
        Entry {
            id: 0,
            user: user.to_string(),
            time: now_s(),
            command: command.to_string(),
            topic: topic.to_string(),
            fields: fields.clone(),
            state: String::new(),
            reason: String::new(),
            seq: None,
            sent: Instant::now(),
        }
    }

    /// Published as bus message `seq`: pending until it is acknowledged.
    pub(super) fn pending(self, seq: u64) -> Entry {
        Entry {
            state: "pending".into(),
            reason: String::new(),
            seq: Some(seq),
            ..self
        }
    }

    /// Refused for `reason`.
    pub(super) fn refused(self, reason: &str) -> Entry {
        Entry {
            state: "refused".into(),
            reason: reason.to_string(),
            seq: None,
            ..self
        }
    }

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

    /// The line of the command log: `time,user,command,topic,fields,state,reason`.
    fn csv(&self) -> String {
        let cells = [
            format!("{:.3}", self.time),
            self.user.clone(),
            self.command.clone(),
            self.topic.clone(),
            seabus_medium::json::to_json(&self.fields).unwrap_or_default(),
            self.state.clone(),
            self.reason.clone(),
        ];
        cells
            .iter()
            .map(|c| seabus_medium::csv::cell(&Value::from(c.as_str())))
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// A driver's answer to one of the console's commands, read from `cmd.status`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Ack {
    /// The command's sequence number (`request_seq`).
    pub(super) seq: i64,
    /// Its state: `acknowledged`, `refused`, `timed-out`, or a step on the way.
    pub(super) state: String,
    /// The driver's reason (`reason`, or else `error`).
    pub(super) reason: String,
    /// The vehicle it came from: what its topic has before `cmd.status` (`auv1.` of
    /// `auv1.cmd.status`; empty on a vehicle's own bus).
    pub(super) vehicle: String,
}

/// The status topic that answers a command on `topic`: the vehicle's `cmd.status`, its vehicle
/// being what the command's topic has before its first `cmd` segment (`auv1.cmd.course` is
/// answered on `auv1.cmd.status`; `cmd.course`, and a topic without a `cmd` segment, on
/// `cmd.status`).
fn vehicle_of_command(topic: &str) -> &str {
    if topic.starts_with("cmd.") {
        return "";
    }
    match topic.find(".cmd.") {
        Some(i) => &topic[..=i],
        None => "",
    }
}

impl Ack {
    /// The answer in a message on `topic`, when it is a `cmd.status` about a command of `origin`.
    pub(super) fn from_status(topic: &Topic, map: &DataMap, origin: &str) -> Option<Ack> {
        let vehicle = topic.as_str().strip_suffix("cmd.status")?;
        if !(vehicle.is_empty() || vehicle.ends_with('.'))
            || map.get("origin").and_then(Value::as_str) != Some(origin)
        {
            return None;
        }
        let seq = map.get("request_seq").and_then(Value::as_i64)?;
        let state = map.get("state").and_then(Value::as_str).unwrap_or("");
        let reason = ["reason", "error"]
            .iter()
            .filter_map(|k| map.get(k).and_then(Value::as_str))
            .find(|r| !r.is_empty())
            .unwrap_or("");
        Some(Ack {
            seq,
            state: state.to_string(),
            reason: reason.to_string(),
            vehicle: vehicle.to_string(),
        })
    }

    /// Whether the command's fate is decided.
    fn settles(&self) -> bool {
        matches!(
            self.state.as_str(),
            "acknowledged" | "refused" | "timed-out"
        )
    }
}

/// Answers kept for a command not yet recorded, at most.
const EARLY: usize = 64;

/// The commands shown in the history, oldest first.
#[derive(Debug, Default)]
pub(super) struct History {
    entries: VecDeque<Entry>,
    next_id: u64,
    /// answers that came before the command they answer was recorded (a driver on the same bus
    /// can answer before the publishing task records what it sent), newest last
    early: VecDeque<Ack>,
    /// the highest sequence number recorded: an answer to one at or below it is not early
    recorded_up_to: u64,
}

impl History {
    /// Adds `entry` with the next id, dropping the oldest settled entries past [`HISTORY`].
    fn push(&mut self, mut entry: Entry) -> Entry {
        if let Some(seq) = entry.seq {
            self.recorded_up_to = self.recorded_up_to.max(seq);
        }
        self.next_id += 1;
        entry.id = self.next_id;
        self.entries.push_back(entry.clone());
        // pending entries stay until answered, however old
        while self.entries.len() > HISTORY {
            match self.entries.iter().position(|e| e.seq.is_none()) {
                Some(i) => {
                    self.entries.remove(i);
                }
                None => break,
            }
        }
        entry
    }

    /// The answers that came for command `seq` before it was recorded, oldest first.
    fn take_early(&mut self, seq: u64) -> Vec<Ack> {
        let (mine, rest): (VecDeque<Ack>, VecDeque<Ack>) = std::mem::take(&mut self.early)
            .into_iter()
            .partition(|a| a.seq == seq as i64);
        self.early = rest;
        mine.into()
    }

    /// The pending entry `ack` answers, changed: settled, or in a new state on the way. An answer
    /// to no entry is kept for a command recorded after its answer came.
    pub(super) fn acknowledge(&mut self, ack: &Ack) -> Option<Entry> {
        let Some(e) = self
            .entries
            .iter_mut()
            .find(|e| e.seq.is_some_and(|s| s as i64 == ack.seq))
        else {
            if ack.seq > self.recorded_up_to as i64 {
                if self.early.len() == EARLY {
                    self.early.pop_front();
                }
                self.early.push_back(ack.clone());
            }
            return None;
        };
        if vehicle_of_command(&e.topic) != ack.vehicle {
            // another vehicle's driver answering the same number: not this command's answer
            tracing::warn!(
                component = "console",
                "{}cmd.status answers command {} on {}: not its vehicle, ignored",
                ack.vehicle,
                e.id,
                e.topic
            );
            return None;
        }
        if !ack.settles() && ack.state == e.state {
            return None;
        }
        e.state = ack.state.clone();
        e.reason = ack.reason.clone();
        if ack.settles() {
            e.seq = None;
        }
        Some(e.clone())
    }

    /// The pending entries older than `ack_timeout` at `now`, timed out.
    pub(super) fn time_out(&mut self, now: Instant, ack_timeout: Duration) -> Vec<Entry> {
        let mut timed_out = Vec::new();
        for e in self.entries.iter_mut() {
            if e.seq.is_some() && now.duration_since(e.sent) > ack_timeout {
                e.seq = None;
                e.state = "timed-out".into();
                e.reason = format!("no acknowledgement within {} ms", ack_timeout.as_millis());
                timed_out.push(e.clone());
            }
        }
        timed_out
    }

    /// The `history` message.
    fn json(&self) -> Json {
        let commands: Vec<Json> = self.entries.iter().map(Entry::json).collect();
        json!({"type": "history", "commands": commands})
    }
}

/// Appends `entry`'s line to the command log at `path`.
fn append(path: &Path, entry: &Entry) -> std::io::Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    writeln!(f, "{}", entry.csv())
}

impl Hub {
    /// The `history` message.
    pub fn history(&self) -> Json {
        self.state().history.json()
    }

    /// Adds `entry` to the history and shows it, then any answer that came for it first; returns
    /// its id.
    pub(super) fn record(&self, entry: Entry) -> u64 {
        let (entry, early) = {
            let mut st = self.state();
            let entry = st.history.push(entry);
            let early = entry
                .seq
                .map(|s| st.history.take_early(s))
                .unwrap_or_default();
            (entry, early)
        };
        self.changed(&entry);
        for ack in early {
            let answered = self.state().history.acknowledge(&ack);
            if let Some(e) = answered {
                self.changed(&e);
            }
        }
        entry.id
    }

    /// Records a refusal of a declared command; of what the page proposed, only the command's own
    /// fields are kept, and text no longer than [`MAX_TEXT`].
    pub(super) fn record_refusal(
        &self,
        user: &str,
        decl: &CommandDecl,
        set: &DataMap,
        reason: &impl std::fmt::Display,
    ) {
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
        let reason: String = reason.to_string().chars().take(MAX_TEXT).collect();
        let command = decl.name.as_str();
        tracing::warn!(
            component = "console",
            user,
            command,
            "command refused: {reason}"
        );
        let entry = Entry::new(user, command, decl.topic.as_str(), &fields).refused(&reason);
        self.record(entry);
    }

    /// Shows an entry's new state to everyone and appends it to the command log.
    pub(super) fn changed(&self, e: &Entry) {
        self.broadcast(&e.json());
        if let Some(path) = &self.settings.log
            && let Err(err) = append(path, e)
        {
            tracing::warn!(
                component = "console",
                "command log {}: {err}",
                path.display()
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{ACK_TIMEOUT, Fixture, waiting};
    use super::*;
    use seabus_medium::Stamp;

    /// A `cmd.status` from `origin` about command `seq`.
    fn status(origin: &str, seq: i64, state: &str) -> DataMap {
        DataMap::new()
            .with("origin", origin)
            .with("request_seq", seq)
            .with("state", state)
    }

    fn cmd_status() -> Topic {
        Topic::new("cmd.status").unwrap()
    }

    /// The answer in `map`, for the console of origin `o1`.
    fn ack(map: &DataMap) -> Ack {
        Ack::from_status(&cmd_status(), map, "o1").unwrap()
    }

    fn sent(command: &str) -> Entry {
        Entry::new(
            "ana",
            command,
            "cmd.mission",
            &DataMap::new().with("action", command),
        )
    }

    /// The ids and states of the history, oldest first.
    fn states(h: &History) -> Vec<(u64, &str)> {
        h.entries.iter().map(|e| (e.id, e.state.as_str())).collect()
    }

    #[test]
    fn an_answer_that_comes_before_its_command_is_recorded_settles_it() {
        let mut h = History::default();
        assert!(
            h.acknowledge(&ack(&status("o1", 4, "acknowledged")))
                .is_none()
        );
        let e = h.push(sent("start").pending(4));
        let early = h.take_early(4);
        assert_eq!(early.len(), 1);
        let settled = h.acknowledge(&early[0]).unwrap();
        assert_eq!((settled.id, settled.state.as_str()), (e.id, "acknowledged"));
        // a repeat of the answer to a command already recorded is not kept for later
        assert!(
            h.acknowledge(&ack(&status("o1", 4, "acknowledged")))
                .is_none()
        );
        assert!(h.early.is_empty());
        // the answers kept are bounded, the oldest going first
        for seq in 10..10 + EARLY as i64 + 5 {
            h.acknowledge(&ack(&status("o1", seq, "acknowledged")));
        }
        assert_eq!(h.early.len(), EARLY);
        assert!(h.take_early(10).is_empty());
        assert_eq!(h.take_early(14 + EARLY as u64).len(), 1);
    }

    #[test]
    fn only_status_about_the_consoles_own_commands_is_an_answer() {
        let mine = status("o1", 2, "acknowledged");
        assert_eq!(
            Ack::from_status(&cmd_status(), &mine, "o1"),
            Some(Ack {
                seq: 2,
                state: "acknowledged".into(),
                reason: String::new(),
                vehicle: String::new(),
            })
        );
        assert_eq!(Ack::from_status(&cmd_status(), &mine, "o2"), None);
        let elsewhere = Topic::new("cmd.other").unwrap();
        assert_eq!(Ack::from_status(&elsewhere, &mine, "o1"), None);
        let unnumbered = DataMap::new().with("origin", "o1").with("state", "refused");
        assert_eq!(Ack::from_status(&cmd_status(), &unnumbered, "o1"), None);
        let refused = status("o1", 3, "refused")
            .with("reason", "")
            .with("error", "depth limit");
        assert_eq!(ack(&refused).reason, "depth limit");
    }

    #[test]
    fn a_vehicles_command_is_answered_only_by_that_vehicle() {
        let mut h = History::default();
        let course =
            |topic: &str| Entry::new("ana", "course", topic, &DataMap::new().with("heading", 90));
        let to_auv2 = h.push(course("auv2.cmd.course").pending(7));
        let on = |topic: &str, state: &str| {
            Ack::from_status(&Topic::new(topic).unwrap(), &status("o1", 7, state), "o1").unwrap()
        };
        // auv1's driver numbering a command of its own 7 is not auv2's answer
        assert_eq!(on("auv1.cmd.status", "refused").vehicle, "auv1.");
        assert!(h.acknowledge(&on("auv1.cmd.status", "refused")).is_none());
        assert!(h.acknowledge(&on("cmd.status", "refused")).is_none());
        assert_eq!(states(&h), [(to_auv2.id, "pending")]);
        let answered = h
            .acknowledge(&on("auv2.cmd.status", "acknowledged"))
            .unwrap();
        assert_eq!(
            (answered.id, answered.state.as_str()),
            (to_auv2.id, "acknowledged")
        );
        // a topic that only ends like a status topic is none
        let like = Topic::new("auv2.xcmd.status").unwrap();
        assert_eq!(
            Ack::from_status(&like, &status("o1", 8, "refused"), "o1"),
            None
        );
        // a console's own vehicle answers on cmd.status
        let local = h.push(course("cmd.course").pending(9));
        let ack = Ack::from_status(&cmd_status(), &status("o1", 9, "acknowledged"), "o1");
        let settled = h.acknowledge(&ack.unwrap()).unwrap();
        assert_eq!(
            (settled.id, settled.state.as_str()),
            (local.id, "acknowledged")
        );
    }

    #[test]
    fn an_acknowledgement_settles_the_entry_with_its_sequence_number() {
        let mut h = History::default();
        h.push(sent("start").pending(1));
        h.push(sent("stop").pending(2));
        let settled = h
            .acknowledge(&ack(&status("o1", 2, "acknowledged")))
            .unwrap();
        assert_eq!((settled.id, settled.command.as_str()), (2, "stop"));
        assert_eq!(states(&h), [(1, "pending"), (2, "acknowledged")]);
        // settled once: a repeated answer changes nothing
        assert!(h.acknowledge(&ack(&status("o1", 2, "refused"))).is_none());
        assert!(
            h.acknowledge(&ack(&status("o1", 7, "acknowledged")))
                .is_none()
        );
        let refused = status("o1", 1, "refused").with("reason", "busy");
        let settled = h.acknowledge(&ack(&refused)).unwrap();
        assert_eq!(
            (settled.state.as_str(), settled.reason.as_str()),
            ("refused", "busy")
        );
        assert_eq!(states(&h), [(1, "refused"), (2, "acknowledged")]);
    }

    #[test]
    fn a_step_on_the_way_is_shown_once_and_the_entry_stays_pending_for_its_answer() {
        let mut h = History::default();
        h.push(sent("start").pending(5));
        let step = ack(&status("o1", 5, "accepted"));
        assert_eq!(
            h.acknowledge(&step).map(|e| e.state),
            Some("accepted".into())
        );
        assert!(h.acknowledge(&step).is_none());
        let done = h.acknowledge(&ack(&status("o1", 5, "acknowledged")));
        assert_eq!(done.map(|e| e.state), Some("acknowledged".into()));
    }

    #[tokio::test(start_paused = true)]
    async fn a_command_unanswered_for_the_ack_timeout_is_timed_out_once() {
        let mut h = History::default();
        h.push(sent("start").pending(1));
        h.push(sent("stop").refused("not confirmed"));
        tokio::time::advance(ACK_TIMEOUT).await;
        assert!(h.time_out(Instant::now(), ACK_TIMEOUT).is_empty());
        tokio::time::advance(Duration::from_millis(1)).await;
        let timed_out = h.time_out(Instant::now(), ACK_TIMEOUT);
        assert_eq!(timed_out.len(), 1);
        assert_eq!(
            (timed_out[0].id, timed_out[0].reason.as_str()),
            (1, "no acknowledgement within 5000 ms")
        );
        assert_eq!(states(&h), [(1, "timed-out"), (2, "refused")]);
        assert!(h.time_out(Instant::now(), ACK_TIMEOUT).is_empty());
        // a late answer no longer changes it
        assert!(
            h.acknowledge(&ack(&status("o1", 1, "acknowledged")))
                .is_none()
        );
    }

    #[test]
    fn the_history_keeps_200_entries_and_every_pending_one() {
        let mut h = History::default();
        h.push(sent("start").pending(1));
        for _ in 0..250 {
            h.push(sent("stop").refused("no control: take control first"));
        }
        assert_eq!(h.entries.len(), HISTORY);
        let ids: Vec<u64> = h.entries.iter().map(|e| e.id).collect();
        // the pending one, then the 199 newest
        assert_eq!(ids[0], 1);
        assert_eq!(ids[1..], (53..=251).collect::<Vec<u64>>()[..]);
        assert_eq!(h.json()["commands"].as_array().map(Vec::len), Some(HISTORY));
    }

    #[test]
    fn the_history_grows_past_200_only_with_pending_entries() {
        let mut h = History::default();
        for seq in 1..=(HISTORY as u64 + 5) {
            h.push(sent("start").pending(seq));
        }
        assert_eq!(h.entries.len(), HISTORY + 5);
        h.acknowledge(&ack(&status("o1", 3, "acknowledged")));
        h.push(sent("stop").refused("not confirmed"));
        // the settled one goes first, then the newest refusal itself: only pending ones are left
        assert_eq!(h.entries.len(), HISTORY + 4);
        assert!(h.entries.iter().all(|e| e.id != 3 && e.state == "pending"));
        assert_eq!(h.entries.back().map(|e| e.id), Some(HISTORY as u64 + 5));
    }

    #[test]
    fn a_log_line_has_time_user_command_topic_fields_state_and_reason() {
        let mut e = sent("stop").refused("no control: bo has it");
        e.time = 1700000000.25;
        assert_eq!(
            e.csv(),
            r#"1700000000.250,ana,stop,cmd.mission,"{""action"":""stop""}",refused,no control: bo has it"#
        );
    }

    #[tokio::test]
    async fn the_hub_matches_the_drivers_answer_and_logs_every_state() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut events = f.hub.events();
        let mut bo = f.client("bo");
        let on = DataMap::new().with("on", true);
        let id = f
            .hub
            .send(&mut bo, "pilot", "camera", &on, None)
            .await
            .unwrap();
        let command = waiting(&mut driver).remove(0);
        let seq = command.provenance.seq as i64;
        // the same number from another console is not an answer to this one
        let other = status("another-console", seq, "refused");
        f.hub.observe(&cmd_status(), Stamp::now(), &other);
        assert_eq!(f.hub.history()["commands"][0]["state"], "pending");
        let answer = status(&f.hub.origin, seq, "acknowledged");
        f.hub.observe(&cmd_status(), Stamp::now(), &answer);
        let shown: Vec<Json> = std::iter::from_fn(|| events.try_recv().ok())
            .map(|t| serde_json::from_str::<Json>(&t).unwrap())
            .filter(|e| e["type"] == "command")
            .collect();
        let states: Vec<(u64, &str)> = shown
            .iter()
            .map(|e| (e["id"].as_u64().unwrap(), e["state"].as_str().unwrap()))
            .collect();
        assert_eq!(states, [(id, "pending"), (id, "acknowledged")]);
        let log = f.log();
        assert_eq!(log.len(), 2);
        assert!(
            log[0].ends_with(
                ",bo,camera,cmd.camera,\"{\"\"on\"\":true,\"\"note\"\":\"\"x\"\"}\",pending,"
            ),
            "{}",
            log[0]
        );
        assert!(log[1].ends_with(",acknowledged,"), "{}", log[1]);
    }
}
