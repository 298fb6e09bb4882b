//! What the vehicle was last commanded, and commands the console keeps for their sender.
//!
//! The values last commanded on each command topic (by this console, or read from the bus: another
//! console or a module) are what a page's inputs start from, and what a command's unchosen fields
//! are sent as: a layout's declared value never stands in for the vehicle's.
//!
//! A command declared with `keep` is sent again every `keep` period while its sender holds
//! control, so that the vehicle holds it (a frontseat's keep-alive never lapses). It ends when
//! another command goes on its topic (from this console or anyone else on the bus; a dead-man
//! command driven on it takes over), when the layout's safe action (`safe`, a stop) is sent, when
//! the vehicle refuses it (every page is told why), or when control ends: released, or its holder
//! gone for the lease's grace time. Ending with control sends its `neutral` once, when it declares
//! one; without one the re-sends stop and the vehicle's own time-out applies (an Iver2 stops).
//!
//! Every command the console publishes goes out under one lock ([`Hub::sending`]), so a re-send
//! decided before a command ended can never follow what ended it.

use super::history::Ack;
use super::lease::Lease;
use super::{Hub, now_s};
use crate::auth::Session;
use crate::layout::CommandDecl;
use seabus_medium::{DataMap, Kind, SendError, Topic, Value};
use serde_json::{Value as Json, json};
use std::collections::{HashMap, VecDeque};
use std::time::Duration;
use tokio::time::Instant;

/// Command topics whose last values are kept, at most (the first recorded is forgotten first).
pub const COMMANDED_TOPICS: usize = 256;
/// A measurement older than this is not a current value.
pub const MEASURED_FRESH: Duration = Duration::from_secs(5);
/// Sequence numbers of a kept command's sends remembered for matching the vehicle's answers.
const SENDS_REMEMBERED: usize = 8;
/// Sequence numbers of the console's own commands remembered (to tell its own from others').
const OWN_REMEMBERED: usize = 256;
/// Commands heard from the console's own medium waiting to be told from its own, at most.
const HEARD: usize = 64;

/// A command read from the bus: topic, origin, sequence number and fields.
type Heard = (Topic, String, u64, DataMap);

/// The values last commanded on each topic, and the console's own recent commands.
#[derive(Debug, Default)]
pub(super) struct Commanded {
    values: HashMap<Topic, DataMap>,
    /// Who commanded each topic's values (an origin, and whether the console itself sent them:
    /// a module on the console's own medium shares its origin), and since when (seconds since
    /// the epoch).
    by: HashMap<Topic, (String, bool, f64)>,
    order: VecDeque<Topic>,
    own: VecDeque<u64>,
    /// Commands of the console's own origin, told from its own once no send is under way.
    heard: VecDeque<Heard>,
}

impl Commanded {
    /// Records `fields` commanded on `topic` by origin `by` (`console`: the console's own):
    /// whether they differ from the last.
    pub(super) fn record(
        &mut self,
        topic: &Topic,
        fields: &DataMap,
        by: &str,
        console: bool,
    ) -> bool {
        if self.values.get(topic) == Some(fields) {
            return false;
        }
        self.by
            .insert(topic.clone(), (by.to_string(), console, now_s()));
        if self.values.insert(topic.clone(), fields.clone()).is_none() {
            self.order.push_back(topic.clone());
            if self.order.len() > COMMANDED_TOPICS
                && let Some(old) = self.order.pop_front()
            {
                self.values.remove(&old);
                self.by.remove(&old);
            }
        }
        true
    }

    /// Who commanded `topic`'s last values, and since when they stand: `{by, console, since}`.
    pub(super) fn by_json(&self, topic: &Topic) -> Option<Json> {
        let (by, console, since) = self.by.get(topic)?;
        Some(json!({"by": by, "console": console, "since": since}))
    }

    /// The values last commanded on `topic`.
    pub(super) fn get(&self, topic: &Topic) -> Option<&DataMap> {
        self.values.get(topic)
    }

    /// Whether bus message `seq` is one of the console's own commands.
    pub(super) fn own(&self, seq: u64) -> bool {
        self.own.contains(&seq)
    }

    fn sent(&mut self, seq: u64) {
        if self.own.len() == OWN_REMEMBERED {
            self.own.pop_front();
        }
        self.own.push_back(seq);
    }
}

/// A command being kept.
#[derive(Debug, Clone)]
pub(super) struct Kept {
    pub(super) user: String,
    /// The log-in it is kept for.
    pub(super) session: u64,
    /// The vehicle whose control it is kept under (`""`: the console's one control).
    vehicle: String,
    name: String,
    pub(super) topic: Topic,
    fields: DataMap,
    neutral: DataMap,
    period: Duration,
    /// Which keeping this is: a re-send decided for an earlier one is not sent.
    generation: u64,
    /// When it was first sent (seconds since the epoch).
    since: f64,
    /// When it was last sent.
    sent: Instant,
    /// The sequence numbers of its last sends.
    seqs: VecDeque<u64>,
}

impl Kept {
    /// The vehicle whose control it is kept under (`""`: the console's one control).
    pub(super) fn vehicle(&self) -> &str {
        &self.vehicle
    }

    /// Whether its sender holds control of its vehicle.
    pub(super) fn in_control(&self, lease: &Lease) -> bool {
        lease.holds(&self.vehicle, self.session)
    }

    /// Whether `fields` command what it keeps: each of its fields with the same value (numbers
    /// compared as numbers: another sender's `90` is the kept `90.0`).
    fn same_as(&self, fields: &DataMap) -> bool {
        self.fields
            .iter()
            .all(|(k, v)| match (v.as_f64(), fields.get(k)) {
                (Some(x), Some(w)) => w.as_f64() == Some(x),
                (None, w) => w == Some(v),
                (Some(_), None) => false,
            })
    }

    /// What pages are shown of it: while kept its values, once ended when and why.
    fn json(&self, ended: Option<&str>) -> Json {
        let mut m = json!({
            "type": "kept",
            "topic": self.topic.as_str(),
            "command": self.name,
            "user": self.user,
            "since": self.since,
        });
        match ended {
            None => m["fields"] = json!(&self.fields),
            Some(why) => {
                m["ended"] = json!(now_s());
                m["reason"] = json!(why);
            }
        }
        m
    }

    fn sent_as(&mut self, seq: u64, at: Instant) {
        self.sent = at;
        if self.seqs.len() == SENDS_REMEMBERED {
            self.seqs.pop_front();
        }
        self.seqs.push_back(seq);
    }

    /// Its neutral over its values, when it declares one.
    fn neutral(&self) -> Option<DataMap> {
        (!self.neutral.is_empty()).then(|| overlay(&self.fields, &self.neutral))
    }
}

/// `fields` with `over`'s values in place of theirs.
pub(super) fn overlay(fields: &DataMap, over: &DataMap) -> DataMap {
    let mut out = fields.clone();
    for (k, v) in over.iter() {
        out.insert(k.to_string(), v.clone());
    }
    out
}

/// The commands being kept, by topic, and why the last one on each ended.
#[derive(Debug, Default)]
pub(super) struct Keeps {
    kept: HashMap<Topic, Kept>,
    ended: HashMap<Topic, Json>,
    generations: u64,
}

impl Keeps {
    /// Removes the kept commands `stop` picks; returns each with the message pages are shown.
    fn end(&mut self, stop: impl Fn(&Kept) -> bool, why: &str) -> Vec<(Kept, Json)> {
        let ended = super::take_where(&mut self.kept, |_, k| stop(k));
        let mut out = Vec::new();
        for k in ended {
            let m = k.json(Some(why));
            if self.ended.len() >= COMMANDED_TOPICS {
                self.ended.clear();
            }
            self.ended.insert(k.topic.clone(), m.clone());
            tracing::info!(component = "console", user = %k.user, command = %k.name, "no longer kept: {why}");
            out.push((k, m));
        }
        out
    }

    /// What pages are shown when they open a layout: each kept command, and how the last one
    /// on each other topic ended.
    pub(super) fn json(&self) -> Vec<Json> {
        let mut out: Vec<Json> = self.kept.values().map(|k| k.json(None)).collect();
        out.extend(
            self.ended
                .iter()
                .filter(|(t, _)| !self.kept.contains_key(*t))
                .map(|(_, e)| e.clone()),
        );
        out
    }
}

impl Hub {
    /// Publishes a command as the console's own (recorded as last commanded on its topic, and
    /// known as the console's when the bus brings it back); its bus sequence number. Callers
    /// hold [`Hub::sending`].
    pub(super) async fn emit(&self, topic: &Topic, fields: &DataMap) -> Result<u64, SendError> {
        let seq = self
            .port
            .publish_numbered(Kind::Command, topic.clone(), fields.clone())
            .await?;
        self.state().commanded.sent(seq);
        self.commanded(topic, fields, &self.origin, true);
        Ok(seq)
    }

    /// Records `fields` as the values last commanded on `topic` by origin `by` (`console`: the
    /// console's own), and tells every page when they changed (with who commanded them, and
    /// since when).
    pub(super) fn commanded(&self, topic: &Topic, fields: &DataMap, by: &str, console: bool) {
        let changed = {
            let mut st = self.state();
            st.commanded
                .record(topic, fields, by, console)
                .then(|| st.commanded.by_json(topic))
                .flatten()
        };
        if let Some(by) = changed {
            self.broadcast(&json!({
                "type": "commanded",
                "topic": topic.as_str(),
                "fields": fields,
                "by": by["by"],
                "console": by["console"],
                "since": by["since"],
            }));
        }
    }

    /// A command read from the bus: unless it is the console's own, it is the topic's last
    /// commanded value and ends the keeping of the console's command on that topic. One from the
    /// console's own medium (the console, or a module beside it) may arrive before the send that
    /// made it has noted its number: it waits for [`Hub::keep`], which tells them apart with no
    /// send under way.
    pub(super) fn heard_command(&self, topic: &Topic, origin: &str, seq: u64, fields: &DataMap) {
        if origin == self.origin {
            let mut st = self.state();
            if !st.commanded.own(seq) {
                if st.commanded.heard.len() == HEARD {
                    st.commanded.heard.pop_front();
                }
                let heard = (topic.clone(), origin.to_string(), seq, fields.clone());
                st.commanded.heard.push_back(heard);
            }
            return;
        }
        self.others_command(topic, origin, fields);
    }

    /// Another sender's command on `topic`: the last commanded, and the end of keeping there —
    /// unless it commands what is kept (a helm's last course, sent as the console took it over).
    fn others_command(&self, topic: &Topic, origin: &str, fields: &DataMap) {
        self.commanded(topic, fields, origin, false);
        self.stop_keeping(
            |k| &k.topic == topic && !k.same_as(fields),
            &format!("{topic} commanded by {origin}"),
        );
    }

    /// The commands heard from the console's own medium that were not its own (with no send
    /// under way, every one of its own has its number noted).
    async fn sort_heard(&self) {
        let _sending = self.sending.lock().await;
        let heard: Vec<Heard> = {
            let mut st = self.state();
            let heard = std::mem::take(&mut st.commanded.heard);
            heard
                .into_iter()
                .filter(|(_, _, seq, _)| !st.commanded.own(*seq))
                .collect()
        };
        for (topic, origin, _, fields) in heard {
            self.others_command(&topic, &origin, &fields);
        }
    }

    /// The current value of each field of `decl`: last commanded on its topic; for a field the
    /// layout measures (`from.FIELD`) and nothing commanded, the measured value if it is fresh
    /// ([`MEASURED_FRESH`]), brought within the field's bounds.
    pub(super) fn current(&self, decl: &CommandDecl) -> DataMap {
        let st = self.state();
        let mut out = st.commanded.get(&decl.topic).cloned().unwrap_or_default();
        let oldest = now_s() - MEASURED_FRESH.as_secs_f64();
        for (field, (topic, f)) in &decl.from {
            if out.get(field).is_some() {
                continue;
            }
            let measured = st
                .latest
                .get(topic)
                .filter(|l| l.stamp >= oldest)
                .and_then(|l| l.map.get(f)?.as_f64());
            if let Some(x) = measured.filter(|x| x.is_finite()) {
                let lo = decl.min.get(field).copied().unwrap_or(f64::NEG_INFINITY);
                let hi = decl.max.get(field).copied().unwrap_or(f64::INFINITY);
                out.insert(field.clone(), Value::Float(x.clamp(lo, hi)));
            }
        }
        out
    }

    /// Before `decl` is published (with [`Hub::sending`] held): the safe action ends every kept
    /// command; any command ends the one kept on its topic. No neutral goes: `decl` is what
    /// follows.
    pub(super) fn sending_instead(&self, decl: &CommandDecl) {
        let why = format!("{} sent instead", decl.name);
        if decl.safe {
            self.stop_keeping(|_| true, &why);
        } else {
            self.stop_keeping(|k| k.topic == decl.topic, &why);
        }
    }

    /// After `session`'s user sent `decl` as bus message `seq` with `fields`: a kept command starts,
    /// unless a dead-man command is driving its topic (which then owns it).
    pub(super) fn sent(&self, session: &Session, decl: &CommandDecl, fields: &DataMap, seq: u64) {
        let Some(period) = decl.keep else {
            return;
        };
        let now = Instant::now();
        let message = {
            let mut st = self.state();
            if st.drives.driving(&decl.topic) {
                return;
            }
            st.keeps.generations += 1;
            let mut k = Kept {
                user: session.user.clone(),
                session: session.id,
                vehicle: decl.vehicle().to_string(),
                name: decl.name.clone(),
                topic: decl.topic.clone(),
                fields: fields.clone(),
                neutral: decl.neutral.clone(),
                period,
                generation: st.keeps.generations,
                since: now_s(),
                sent: now,
                seqs: VecDeque::new(),
            };
            k.sent_as(seq, now);
            let m = k.json(None);
            st.keeps.kept.insert(decl.topic.clone(), k);
            m
        };
        self.broadcast(&message);
    }

    /// Ends the kept commands `stop` picks, without their neutral (something else follows).
    pub(super) fn stop_keeping(&self, stop: impl Fn(&Kept) -> bool, why: &str) {
        let ended = self.state().keeps.end(stop, why);
        for (_, m) in &ended {
            self.broadcast(m);
        }
    }

    /// A vehicle's answer: a refusal of a kept command ends it, with the vehicle's reason.
    pub(super) fn kept_answered(&self, ack: &Ack) {
        if ack.state != "refused" || ack.seq < 0 {
            return;
        }
        let seq = ack.seq as u64;
        let why = format!("the vehicle refused it: {}", ack.reason);
        self.stop_keeping(|k| k.seqs.contains(&seq), &why);
    }

    /// Ends the kept commands `stop` picks, each one's neutral going once (when it declares
    /// one): the end of control.
    /// `stop` is asked with the lease as it is then (under [`Hub::sending`]): a command kept
    /// while the caller waited for that lock is judged by who holds control, not by what the
    /// caller saw before.
    pub(super) async fn end_kept(&self, stop: impl Fn(&Kept, &Lease) -> bool, why: &str) {
        let _sending = self.sending.lock().await;
        let ended = {
            let st = &mut *self.state();
            let lease = &st.lease;
            st.keeps.end(|k| stop(k, lease), why)
        };
        for (k, m) in ended {
            self.broadcast(&m);
            if let Some(neutral) = k.neutral() {
                let _ = self.publish(&k.user, &k.name, &k.topic, neutral).await;
            }
        }
    }

    /// Sends again each kept command whose period has passed; ends those whose sender no longer
    /// holds control. Runs in a task of its own (a full queue on the bus never holds up the
    /// watchdog).
    pub async fn keep(&self, now: Instant) {
        self.sort_heard().await;
        self.end_kept(|k, lease| !k.in_control(lease), "control ended")
            .await;
        let due: Vec<(Topic, u64)> = self
            .state()
            .keeps
            .kept
            .values()
            .filter(|k| now.duration_since(k.sent) >= k.period)
            .map(|k| (k.topic.clone(), k.generation))
            .collect();
        for (topic, generation) in due {
            let _sending = self.sending.lock().await;
            // still the same keeping, its sender still in control: it may have ended meanwhile
            let fields = {
                let st = self.state();
                st.keeps
                    .kept
                    .get(&topic)
                    .filter(|k| k.generation == generation && k.in_control(&st.lease))
                    .map(|k| k.fields.clone())
            };
            let Some(fields) = fields else {
                continue;
            };
            match self.emit(&topic, &fields).await {
                Ok(seq) => {
                    let mut st = self.state();
                    if let Some(k) = st.keeps.kept.get_mut(&topic)
                        && k.generation == generation
                    {
                        k.sent_as(seq, now);
                    }
                }
                Err(e) => self.stop_keeping(
                    |k| k.topic == topic && k.generation == generation,
                    &format!("not sent: {e}"),
                ),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{Fixture, field, waiting};
    use super::super::{Client, CommandError, LeaseError};
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
            f.hub.keep(Instant::now()).await;
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

    /// The pilot `ana`, in control, having sent [`course`] on the kept `helm`.
    async fn kept_helm(f: &Fixture) -> Client {
        let mut ana = f.pilot("ana").await;
        f.hub
            .send(&mut ana, "pilot", "helm", &course(), None)
            .await
            .unwrap();
        ana
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
        let ana = kept_helm(&f).await;
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
        f.hub.lease(&ana.session, "", false).await.unwrap();
        let released = waiting(&mut driver);
        let released = helms(&released);
        assert_eq!(released.len(), 1);
        assert_eq!(field(released[0], "speed"), Some(Value::Float(0.0)));
        assert_eq!(field(released[0], "heading"), Some(Value::Int(90)));
        run_for(&f, 5).await;
        assert!(helms(&waiting(&mut driver)).is_empty());
    }

    /// Polls `f` until it waits (for the sending lock the test holds).
    async fn waits<F: std::future::Future>(f: std::pin::Pin<&mut F>) {
        let polled = tokio::time::timeout(Duration::from_millis(10), f).await;
        assert!(polled.is_err(), "it waits for the sending lock");
    }

    /// The one `kept` event on `events` says a course is kept (not ended), and it is.
    fn only_kept_anew(
        f: &Fixture,
        events: &mut tokio::sync::broadcast::Receiver<std::sync::Arc<str>>,
    ) {
        let told = kept_events(events);
        assert_eq!(told.len(), 1, "{told:?}");
        assert_eq!(told[0]["reason"], Json::Null, "{told:?}");
        assert_eq!(f.hub.state().keeps.kept.len(), 1);
    }

    #[tokio::test(start_paused = true)]
    async fn a_command_kept_while_the_keeper_waits_to_send_is_judged_by_the_lease_then() {
        let f = Fixture::new();
        let mut ana = kept_helm(&f).await;
        f.hub.stop_keeping(|_| true, "a fresh start");
        let mut events = f.hub.events();
        // the keeper waits for the sending lock (to sort what it heard), and a page's course
        // waits behind it: the course is kept while the keeper waits for the lock again, to end
        // what is no longer in control
        let sending = f.hub.sending.lock().await;
        let mut keeping = std::pin::pin!(f.hub.keep(Instant::now()));
        waits(keeping.as_mut()).await;
        let fields = course();
        let mut course = std::pin::pin!(f.hub.send(&mut ana, "pilot", "helm", &fields, None));
        waits(course.as_mut()).await;
        drop(sending);
        let ((), sent) = tokio::join!(keeping, course);
        sent.unwrap();
        // ana holds control: the new course stays kept
        only_kept_anew(&f, &mut events);
    }

    #[tokio::test(start_paused = true)]
    async fn a_command_kept_under_control_taken_again_outlives_the_release_before_it() {
        let f = Fixture::new();
        let mut ana = f.pilot("ana").await;
        // a dead-man course runs: the release's neutral waits for the sending lock
        let ahead = DataMap::new().with("heading", 1).with("speed", 2);
        f.hub
            .drive(&mut ana, "pilot", "course", &ahead)
            .await
            .unwrap();
        let mut events = f.hub.events();
        let sending = f.hub.sending.lock().await;
        let session = ana.session.clone();
        let mut release = std::pin::pin!(f.hub.lease(&session, "", false));
        waits(release.as_mut()).await;
        // control taken again and a kept course sent, which waits behind that neutral and ahead
        // of the release's end of what it kept
        f.hub.lease(&ana.session, "", true).await.unwrap();
        let fields = course();
        let mut helm = std::pin::pin!(f.hub.send(&mut ana, "pilot", "helm", &fields, None));
        waits(helm.as_mut()).await;
        drop(sending);
        let (released, sent) = tokio::join!(release, helm);
        released.unwrap();
        sent.unwrap();
        only_kept_anew(&f, &mut events);
    }

    #[tokio::test(start_paused = true)]
    async fn a_kept_command_the_vehicle_refuses_ends_and_every_page_is_told_why() {
        let f = Fixture::new();
        let mut driver = f.driver();
        kept_helm(&f).await;
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

    #[tokio::test(start_paused = true)]
    async fn a_stick_takes_the_topic_over_and_nothing_kept_follows_its_neutral() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = kept_helm(&f).await;
        let fast = DataMap::new().with("speed", 1.9);
        f.hub.drive(&mut ana, "pilot", "helm", &fast).await.unwrap();
        // a step sent while the stick drives is not kept: the stick owns the topic
        let step = DataMap::new().with("heading", 95);
        f.hub
            .send(&mut ana, "pilot", "helm", &step, None)
            .await
            .unwrap();
        f.hub.release(&ana, "pilot", "helm").await;
        let sent = waiting(&mut driver);
        let speeds: Vec<_> = helms(&sent).iter().map(|m| field(m, "speed")).collect();
        let want = [1.5, 1.9, 1.9, 0.0].map(|x| Some(Value::Float(x)));
        assert_eq!(speeds, want);
        run_for(&f, 5).await;
        assert!(helms(&waiting(&mut driver)).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn the_safe_action_ends_every_kept_command_before_it_goes() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut events = f.hub.events();
        let mut ana = kept_helm(&f).await;
        run_for(&f, 2).await;
        f.hub
            .send(&mut ana, "pilot", "stop", &DataMap::new(), None)
            .await
            .unwrap();
        let ended = kept_events(&mut events).pop().unwrap();
        assert_eq!(ended["reason"], "stop sent instead");
        let sent = waiting(&mut driver);
        assert_eq!(sent.last().map(|m| m.topic.as_str()), Some("cmd.mission"));
        run_for(&f, 5).await;
        assert!(helms(&waiting(&mut driver)).is_empty());
    }

    #[tokio::test(start_paused = true)]
    async fn another_senders_command_on_the_topic_ends_the_keeping_and_its_own_do_not() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut events = f.hub.events();
        let mut reader = f.bus.attach("console");
        reader
            .subscribe_kind("cmd.helm", Some(seabus_medium::Kind::Command))
            .unwrap();
        let other = f.bus.attach("autopilot");
        let test = async {
            let mut ana = f.pilot("ana").await;
            f.hub
                .send(&mut ana, "pilot", "helm", &course(), None)
                .await
                .unwrap();
            // its own commands, read back from the bus, change nothing
            run_for(&f, 3).await;
            assert_eq!(kept_events(&mut events).len(), 1);
            let theirs = DataMap::new()
                .with("heading", 10)
                .with("depth", 2.0)
                .with("speed", 0.5);
            other.command("cmd.helm", theirs.clone()).await.unwrap();
            run_for(&f, 1).await;
            let ended = kept_events(&mut events).pop().unwrap();
            assert_eq!(ended["reason"], "cmd.helm commanded by t/bus");
            waiting(&mut driver);
            run_for(&f, 5).await;
            assert!(helms(&waiting(&mut driver)).is_empty());
            // and what they commanded is what the next command starts from
            let helm = &ana.layout.as_ref().unwrap().commands["helm"];
            assert_eq!(f.hub.current(helm), theirs);
        };
        tokio::select! {
            _ = f.hub.read(reader) => panic!("the bus closed"),
            _ = test => {}
        }
    }

    #[tokio::test(start_paused = true)]
    async fn taking_control_keeps_the_course_a_helm_commanded_as_the_page_showed_it() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut events = f.hub.events();
        // a helm module commands the course; nobody has control
        let topic = Topic::new("cmd.helm").unwrap();
        f.hub.heard_command(&topic, "auv/helm", 7, &course());
        let ana = f.client("ana");
        // the page showed another course than the vehicle's last: control is not taken
        let shown = course().with("speed", 1.0);
        let refused = f
            .hub
            .take_keeping(&ana, "", &[("helm".into(), shown)])
            .await;
        let refused = refused.unwrap_err().to_string();
        assert!(
            refused.starts_with("control not taken: helm changed while you confirmed (now "),
            "{refused}"
        );
        assert_eq!(f.hub.lease_json()["holder"], Json::Null);
        // nor for a command that is not kept
        let not_kept = f
            .hub
            .take_keeping(&ana, "", &[("course".into(), DataMap::new())])
            .await;
        assert_eq!(
            not_kept.unwrap_err().to_string(),
            "control not taken: `course` is not a kept command of this layout under this control"
        );
        assert!(waiting(&mut driver).is_empty(), "nothing was sent");
        // as shown: control is taken and the course goes at once, then every second
        f.hub
            .take_keeping(&ana, "", &[("helm".into(), course())])
            .await
            .unwrap();
        assert_eq!(f.hub.lease_json()["holder"], "ana");
        let first = waiting(&mut driver);
        assert_eq!(helms(&first).len(), 1, "{first:?}");
        assert_eq!(helms(&first)[0].payload.as_map(), Some(&course()));
        only_kept_anew(&f, &mut events);
        // the helm sending its last course again as it steps back does not end the keeping
        f.hub.heard_command(&topic, "auv/helm", 8, &course());
        run_for(&f, 3).await;
        let again = waiting(&mut driver);
        assert!(helms(&again).len() >= 2, "{again:?}");
        assert!(
            helms(&again)
                .iter()
                .all(|m| m.payload.as_map() == Some(&course()))
        );
        assert!(kept_events(&mut events).is_empty(), "still kept");
    }

    #[tokio::test(start_paused = true)]
    async fn another_log_in_of_the_holder_neither_commands_nor_ends_its_control() {
        let f = Fixture::new();
        let mut driver = f.driver();
        let mut ana = kept_helm(&f).await;
        // the same pilot logs in again elsewhere
        let mut again = f.client("ana");
        assert_ne!(again.session.id, ana.session.id);
        let taken = f.hub.lease(&again.session, "", true).await;
        assert_eq!(taken, Err(LeaseError::HeldElsewhere));
        let sent = f
            .hub
            .send(
                &mut again,
                "pilot",
                "helm",
                &course().with("speed", 0.5),
                None,
            )
            .await;
        assert_eq!(sent, Err(CommandError::ControlElsewhere));
        // its log-out leaves the first log-in's control and its kept course
        waiting(&mut driver);
        f.hub.release_everything(&again.session).await;
        f.hub.disconnect(&again).await;
        run_for(&f, 3).await;
        assert_eq!(f.hub.lease_json()["session"], ana.session.id);
        let kept = waiting(&mut driver);
        assert!(helms(&kept).len() >= 2, "{kept:?}");
        assert!(
            helms(&kept)
                .iter()
                .all(|m| m.payload.as_map() == Some(&course()))
        );
        // the holder still commands
        let slower = course().with("speed", 0.5);
        f.hub
            .send(&mut ana, "pilot", "helm", &slower, None)
            .await
            .unwrap();
    }
}
