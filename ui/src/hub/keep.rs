//! What the vehicle was last commanded, and commands the console keeps for their sender.
//!
//! The values last commanded on each command topic (by the console, or seen on the bus from
//! another console or a module) are what a page's inputs start from, and what a command's
//! unchosen fields are sent as: a layout's declared value never stands in for the vehicle's.
//!
//! A command declared with `keep` is sent again every `keep` period while its sender holds
//! control, so that the vehicle holds it (a frontseat's keep-alive never lapses) until another
//! command goes on its topic, the vehicle refuses it (every page is told why), or control ends:
//! released, taken over, or its holder gone for the lease's grace time. Then its `neutral` goes
//! once, when it declares one; without one the re-sends stop and the vehicle's own time-out
//! applies (an Iver2 stops).

use super::history::Ack;
use super::{Hub, now_s};
use crate::layout::CommandDecl;
use seabus_medium::{DataMap, Kind, Topic, Value};
use serde_json::{Value as Json, json};
use std::collections::{HashMap, VecDeque};
use std::time::Duration;
use tokio::time::Instant;

/// Command topics whose last values are kept, at most (the oldest is forgotten first).
pub const COMMANDED_TOPICS: usize = 256;
/// Sequence numbers of a kept command's sends remembered for matching the vehicle's answers.
const SENDS_REMEMBERED: usize = 8;

/// The values last commanded on each topic, with the order they were last changed in.
#[derive(Debug, Default)]
pub(super) struct Commanded {
    values: HashMap<Topic, DataMap>,
    order: VecDeque<Topic>,
}

impl Commanded {
    /// Records `fields` commanded on `topic`: whether they differ from the last.
    pub(super) fn record(&mut self, topic: &Topic, fields: &DataMap) -> bool {
        if self.values.get(topic) == Some(fields) {
            return false;
        }
        if self.values.insert(topic.clone(), fields.clone()).is_none() {
            self.order.push_back(topic.clone());
            if self.order.len() > COMMANDED_TOPICS
                && let Some(old) = self.order.pop_front()
            {
                self.values.remove(&old);
            }
        }
        true
    }

    /// The values last commanded on `topic`.
    pub(super) fn get(&self, topic: &Topic) -> Option<&DataMap> {
        self.values.get(topic)
    }
}

/// A command being kept.
#[derive(Debug, Clone)]
pub(super) struct Kept {
    pub(super) user: String,
    name: String,
    topic: Topic,
    fields: DataMap,
    neutral: DataMap,
    period: Duration,
    /// When it was first sent (seconds since the epoch).
    since: f64,
    /// When it was last sent.
    sent: Instant,
    /// The sequence numbers of its last sends.
    seqs: VecDeque<u64>,
}

impl Kept {
    /// What pages are shown of it.
    fn json(&self) -> Json {
        json!({
            "type": "kept",
            "topic": self.topic.as_str(),
            "command": self.name,
            "user": self.user,
            "since": self.since,
            "fields": &self.fields,
        })
    }

    fn sent_as(&mut self, seq: u64, at: Instant) {
        self.sent = at;
        if self.seqs.len() == SENDS_REMEMBERED {
            self.seqs.pop_front();
        }
        self.seqs.push_back(seq);
    }
}

/// The commands being kept, by topic, and why the last one on each ended.
#[derive(Debug, Default)]
pub(super) struct Keeps {
    kept: HashMap<Topic, Kept>,
    ended: HashMap<Topic, Json>,
}

impl Keeps {
    /// Removes and returns the kept commands `stop` picks.
    pub(super) fn take(&mut self, stop: impl Fn(&Kept) -> bool) -> Vec<Kept> {
        let topics: Vec<Topic> = self
            .kept
            .values()
            .filter(|k| stop(k))
            .map(|k| k.topic.clone())
            .collect();
        topics
            .into_iter()
            .filter_map(|t| self.kept.remove(&t))
            .collect()
    }

    /// The kept command a vehicle's refusal `ack` answers, removed.
    fn refused(&mut self, ack: &Ack) -> Option<Kept> {
        if ack.state != "refused" || ack.seq < 0 {
            return None;
        }
        let topic = self
            .kept
            .values()
            .find(|k| k.seqs.contains(&(ack.seq as u64)))?
            .topic
            .clone();
        self.kept.remove(&topic)
    }

    /// What pages are shown when they open a layout: each kept command, and how the last one
    /// on each other topic ended.
    pub(super) fn json(&self) -> Vec<Json> {
        let mut out: Vec<Json> = self.kept.values().map(Kept::json).collect();
        out.extend(
            self.ended
                .iter()
                .filter(|(t, _)| !self.kept.contains_key(*t))
                .map(|(_, e)| e.clone()),
        );
        out
    }

    /// Records why `k` ended: the message every page is shown.
    fn end(&mut self, k: &Kept, why: &str) -> Json {
        let m = json!({
            "type": "kept",
            "topic": k.topic.as_str(),
            "command": k.name,
            "user": k.user,
            "since": k.since,
            "ended": now_s(),
            "reason": why,
        });
        self.ended.insert(k.topic.clone(), m.clone());
        if self.ended.len() > COMMANDED_TOPICS {
            self.ended.clear();
        }
        m
    }
}

impl Hub {
    /// Records `fields` as the values last commanded on `topic`, and tells every page when they
    /// changed.
    pub(super) fn commanded(&self, topic: &Topic, fields: &DataMap) {
        let changed = self.state().commanded.record(topic, fields);
        if changed {
            self.broadcast(&json!({
                "type": "commanded",
                "topic": topic.as_str(),
                "fields": fields,
            }));
        }
    }

    /// The current value of each field of `decl`: last commanded on its topic; for a field the
    /// layout measures (`from.FIELD`) and nothing commanded, the measured value, brought within
    /// the field's bounds.
    pub(super) fn current(&self, decl: &CommandDecl) -> DataMap {
        let st = self.state();
        let mut out = st.commanded.get(&decl.topic).cloned().unwrap_or_default();
        for (field, (topic, f)) in &decl.from {
            if out.get(field).is_some() {
                continue;
            }
            let measured = st.latest.get(topic).and_then(|l| l.map.get(f)?.as_f64());
            if let Some(x) = measured.filter(|x| x.is_finite()) {
                let lo = decl.min.get(field).copied().unwrap_or(f64::NEG_INFINITY);
                let hi = decl.max.get(field).copied().unwrap_or(f64::INFINITY);
                out.insert(field.clone(), Value::Float(x.clamp(lo, hi)));
            }
        }
        out
    }

    /// After `user` sent `decl` as bus message `seq` with `fields`: a kept command starts (or
    /// takes the new values); any other command on a kept topic ends the keeping.
    pub(super) fn sent(&self, user: &str, decl: &CommandDecl, fields: &DataMap, seq: u64) {
        let now = Instant::now();
        let message = {
            let mut st = self.state();
            match decl.keep {
                Some(period) => {
                    let since = st
                        .keeps
                        .kept
                        .get(&decl.topic)
                        .filter(|k| k.user == user && k.name == decl.name)
                        .map_or_else(now_s, |k| k.since);
                    let mut k = Kept {
                        user: user.to_string(),
                        name: decl.name.clone(),
                        topic: decl.topic.clone(),
                        fields: fields.clone(),
                        neutral: decl.neutral.clone(),
                        period,
                        since,
                        sent: now,
                        seqs: VecDeque::new(),
                    };
                    k.sent_as(seq, now);
                    let m = k.json();
                    st.keeps.kept.insert(decl.topic.clone(), k);
                    Some(m)
                }
                None => {
                    drop(st);
                    return self.unkeep(&decl.topic, &format!("{} sent instead", decl.name));
                }
            }
        };
        if let Some(m) = message {
            self.broadcast(&m);
        }
    }

    /// Stops keeping the command on `topic` (another command took its place): no neutral.
    pub(super) fn unkeep(&self, topic: &Topic, why: &str) {
        let message = {
            let mut st = self.state();
            let replaced = st.keeps.take(|k| &k.topic == topic);
            replaced.first().map(|k| st.keeps.end(k, why))
        };
        if let Some(m) = message {
            self.broadcast(&m);
        }
    }

    /// A vehicle's answer: a refusal of a kept command ends it, with the vehicle's reason.
    pub(super) fn kept_answered(&self, ack: &Ack) {
        let message = {
            let mut st = self.state();
            st.keeps.refused(ack).map(|k| {
                let why = format!("the vehicle refused it: {}", ack.reason);
                tracing::warn!(component = "console", user = %k.user, command = %k.name, "no longer kept: {why}");
                st.keeps.end(&k, &why)
            })
        };
        if let Some(m) = message {
            self.broadcast(&m);
        }
    }

    /// Ends the kept commands `stop` picks: each one's neutral goes once (when it declares one).
    pub(super) async fn end_kept(&self, stop: impl Fn(&Kept) -> bool, why: &str) {
        let (ended, messages) = {
            let mut st = self.state();
            let ended = st.keeps.take(stop);
            let messages: Vec<Json> = ended.iter().map(|k| st.keeps.end(k, why)).collect();
            (ended, messages)
        };
        for m in &messages {
            self.broadcast(m);
        }
        for k in ended {
            tracing::info!(component = "console", user = %k.user, command = %k.name, "no longer kept: {why}");
            if k.neutral.is_empty() {
                continue;
            }
            let mut neutral = k.fields.clone();
            for (f, v) in k.neutral.iter() {
                neutral.insert(f.to_string(), v.clone());
            }
            let _ = self.publish(&k.user, &k.name, &k.topic, neutral).await;
        }
    }

    /// Sends again each kept command whose period has passed; ends those whose sender no longer
    /// holds control.
    pub(super) async fn keep(&self, now: Instant) {
        let holder = self.state().lease.holder().map(str::to_string);
        self.end_kept(
            |k| holder.as_deref() != Some(k.user.as_str()),
            "control ended",
        )
        .await;
        let due: Vec<Kept> = self
            .state()
            .keeps
            .kept
            .values()
            .filter(|k| now.duration_since(k.sent) >= k.period)
            .cloned()
            .collect();
        for k in due {
            let seq = self
                .port
                .publish_numbered(Kind::Command, k.topic.clone(), k.fields.clone())
                .await;
            match seq {
                Ok(seq) => {
                    self.commanded(&k.topic, &k.fields);
                    if let Some(kept) = self.state().keeps.kept.get_mut(&k.topic) {
                        kept.sent_as(seq, now);
                    }
                }
                Err(e) => {
                    self.end_kept(|x| x.topic == k.topic, &format!("not sent: {e}"))
                        .await;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{Fixture, field, waiting};
    use super::*;
    use seabus_medium::{Message, Stamp};

    /// The `cmd.helm` commands among `sent`.
    fn helms(sent: &[Message]) -> Vec<&Message> {
        sent.iter()
            .filter(|m| m.topic.as_str() == "cmd.helm")
            .collect()
    }

    /// Runs the hub's watch every 50 ms for `secs` seconds of paused time.
    async fn run_for(f: &Fixture, secs: u64) {
        for _ in 0..secs * 20 {
            tokio::time::advance(Duration::from_millis(50)).await;
            f.hub.watch().await;
        }
    }

    /// The `kept` messages among the events waiting on `events`.
    fn kept_events(
        events: &mut tokio::sync::broadcast::Receiver<std::sync::Arc<str>>,
    ) -> Vec<Json> {
        std::iter::from_fn(|| events.try_recv().ok())
            .map(|t| serde_json::from_str::<Json>(&t).unwrap())
            .filter(|e| e["type"] == "kept")
            .collect()
    }

    fn course() -> DataMap {
        DataMap::new()
            .with("heading", 90)
            .with("depth", 5.0)
            .with("speed", 1.5)
    }

    #[tokio::test(start_paused = true)]
    async fn a_kept_command_goes_on_until_control_is_released_then_its_neutral_goes_once() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut events = f.hub.events();
        let mut ana = f.pilot("ana").await;
        f.hub
            .send(&mut ana, "pilot", "helm", &course(), None)
            .await
            .unwrap();
        let first = waiting(&mut driver);
        assert_eq!(helms(&first).len(), 1);
        let kept = kept_events(&mut events).remove(0);
        assert_eq!(kept["command"], "helm");
        assert_eq!(kept["user"], "ana");
        run_for(&f, 60).await;
        let again = waiting(&mut driver);
        let again = helms(&again);
        // once a second for a minute, with the pilot's values
        assert!((59..=61).contains(&again.len()), "{} re-sends", again.len());
        assert!(
            again
                .iter()
                .all(|m| field(m, "speed") == Some(Value::Float(1.5))
                    && field(m, "heading") == Some(Value::Int(90)))
        );
        f.hub.lease(&ana.session, false).await.unwrap();
        let released = waiting(&mut driver);
        let released = helms(&released);
        assert_eq!(released.len(), 1);
        assert_eq!(field(released[0], "speed"), Some(Value::Float(0.0)));
        assert_eq!(field(released[0], "heading"), Some(Value::Int(90)));
        run_for(&f, 5).await;
        assert!(helms(&waiting(&mut driver)).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn a_kept_command_the_vehicle_refuses_ends_and_every_page_is_told_why() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        f.hub
            .send(&mut ana, "pilot", "helm", &course(), None)
            .await
            .unwrap();
        run_for(&f, 2).await;
        let sent = waiting(&mut driver);
        let last = helms(&sent).pop().unwrap().clone();
        let mut events = f.hub.events();
        let refusal = DataMap::new()
            .with("origin", last.origin().to_string())
            .with("request_seq", last.seq() as i64)
            .with("state", "refused")
            .with("reason", "the frontseat is stopped (mode S)");
        f.hub
            .observe(&Topic::new("cmd.status").unwrap(), Stamp::now(), &refusal);
        let ended = kept_events(&mut events).remove(0);
        assert_eq!(
            ended["reason"],
            "the vehicle refused it: the frontseat is stopped (mode S)"
        );
        run_for(&f, 3).await;
        assert!(helms(&waiting(&mut driver)).is_empty());
        // a page opening the layout now is told too
        let mut late = f.client("bo");
        let opened = f.hub.open(&mut late, "pilot", &Default::default());
        assert_eq!(opened["kept"][0]["reason"], ended["reason"]);
    }

    #[tokio::test(start_paused = true)]
    async fn a_field_measured_by_the_layout_goes_as_measured() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = f.pilot("ana").await;
        let depth = Topic::new("nav.depth").unwrap();
        let heading_speed = DataMap::new().with("heading", 10).with("speed", 1.0);
        let refused = f
            .hub
            .send(&mut ana, "pilot", "helm", &heading_speed, None)
            .await;
        assert_eq!(
            refused.unwrap_err().to_string(),
            "`depth` has no known value (nothing commanded or measured yet): set it"
        );
        f.hub
            .observe(&depth, Stamp::now(), &DataMap::new().with("depth", 7.5));
        let depth_sent = |sent: Vec<Message>| field(helms(&sent)[0], "depth");
        f.hub
            .send(&mut ana, "pilot", "helm", &heading_speed, None)
            .await
            .unwrap();
        assert_eq!(depth_sent(waiting(&mut driver)), Some(Value::Float(7.5)));
        // once commanded, the commanded value stands; a measurement beyond the bounds is brought
        // within them
        f.hub
            .observe(&depth, Stamp::now(), &DataMap::new().with("depth", 9.0));
        let depth_sent = |sent: Vec<Message>| field(helms(&sent)[0], "depth");
        f.hub
            .send(&mut ana, "pilot", "helm", &heading_speed, None)
            .await
            .unwrap();
        assert_eq!(depth_sent(waiting(&mut driver)), Some(Value::Float(7.5)));
        let mut fresh = f
            .hub
            .current(&ana.layout.as_ref().unwrap().commands["helm"]);
        assert_eq!(fresh.get("depth"), Some(&Value::Float(7.5)));
        f.hub.state().commanded = Commanded::default();
        f.hub
            .observe(&depth, Stamp::now(), &DataMap::new().with("depth", -0.2));
        fresh = f
            .hub
            .current(&ana.layout.as_ref().unwrap().commands["helm"]);
        assert_eq!(fresh.get("depth"), Some(&Value::Float(0.0)));
    }
}
