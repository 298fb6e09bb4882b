//! The generic bridge (`<bridge type="route">`, the default): forwards messages between two media
//! by routes, renaming topics and fields, limiting rates and converting payload formats. A message
//! goes by every route that matches it, in the order of the routes; the first copy into a medium
//! keeps its provenance, a further one into the same medium is numbered anew there
//! ([`Interface::forward_anew`](seabus_medium::Interface::forward_anew)), since receivers take one
//! origin's number once. The checks below are made once per message, before its routes.
//! seabus's own topics (`seabus.…`: module states, media counters, bridge reports) cross to a
//! medium whose peers are not seabus programs (no provenance on its wire: LCM, MOOS, CAN, a
//! serial line, DSAAV) only by a route whose `topics` begins with `seabus.` itself; a wildcard
//! route (`**`) does not carry them there.
//!
//! Loop safety, in order of the checks:
//! 1. each side's interface drops duplicates it receives (origin + sequence window);
//! 2. the bridge keeps one more window over both sides, so a message it has seen on either side is
//!    forwarded at most once, whichever way it comes back;
//! 3. a message that has crossed `hops` bridges is not forwarded again;
//! 4. the bridges of one program that forward into the same medium share one more window
//!    ([`Forwarded`], held by the medium): a message that reaches a program two ways (a vehicle
//!    on seabus UDP and on Zenoh, each bridged into the shore's bus) is put on that medium once,
//!    by whichever bridge has it first;
//! 5. a message is never sent to the medium it was first published on, nor back to the side it came
//!    from (a route leads from one medium to the other);
//! 6. media whose wire carries no provenance (CAN, serial lines, MOOS, LCM: their
//!    [`Capabilities`] say so) cannot say a message came from the bridge: the bridge remembers what
//!    it sent to such a medium ([`EchoMemory`], by the medium's own fingerprint of a message) and
//!    drops the same message coming back from it within [`ECHO_WINDOW`] — once per message sent,
//!    so a device sending the same frame loses at most that one.
//!
//! A route's `priority`, `congestion` and `express` are declared, when the bridge starts, on the
//! medium the route delivers to, for its topics as they leave it (after `rename`) and its kind
//! ([`Medium::set_qos`]); a route that says them to a medium that carries no priorities
//! ([`Capabilities::qos`]) is refused when the bridge is built, by `seabus check` as at start.
//!
//! Every second (the `report` parameter) it publishes its counters and latency on
//! `seabus.bridge.<name>` on each of its media whose peers are seabus programs, or on those its
//! `report_on` parameter names (a medium whose peers are not seabus, such as MOOS, only when
//! asked; never a serial line, a CAN bus, LCM or DSAAV, which carry only their own kind of
//! messages). The per-route
//! lists (`route_forwarded`, …) go to a medium whose datamaps carry no lists (MOOS, see
//! [`Capabilities::lists`]) flattened, one field per route (`route_forwarded.0`, …). A report
//! that cannot be published is logged once (until one is published there again) and counted
//! apart (`reports_unpublished`): `errors` counts only messages the bridge failed to forward.

use crate::lcm::ResolvedTypes;
use async_trait::async_trait;
use seabus_medium::dedup::{Dedup, Seen};
use seabus_medium::subindex::{Scratch, SubIndex};
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{
    Capabilities, DataMap, Format, Kind, Medium, Message, Pattern, Payload, Qos, Stamp, Topic,
    Value,
};
use seabus_modules::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{BridgeType, Built};
use seabus_modules::system::{BridgeSpec, RouteSpec};
use std::sync::Arc;
use std::time::Duration;
use tokio::time::Instant;

/// The `route` bridge type.
pub const TYPE: BridgeType = BridgeType {
    name: "route",
    summary: "forwards messages between two media by routes (rename, rate limit, format)",
    build,
};

const REPORT: TimerId = 1;

/// Rate-limit entries (route, topic) kept before the expired ones are forgotten early.
const MAX_RATE_ENTRIES: usize = 10_000;

/// How long the bridge remembers a frame it sent to a medium without provenance.
pub const ECHO_WINDOW: Duration = Duration::from_secs(1);
/// Frames remembered per medium, at most.
const ECHO_ENTRIES: usize = 4096;

/// What a bridge sent to a medium without provenance, for [`ECHO_WINDOW`], by the medium's
/// fingerprint of each message ([`Medium::fingerprint`]).
pub struct EchoMemory {
    sent: std::collections::VecDeque<(u64, Instant)>,
    fingerprint: Fingerprint,
}

/// How a medium fingerprints a message (see [`Medium::fingerprint`]).
type Fingerprint = Box<dyn Fn(&Topic, &Payload) -> u64 + Send + Sync>;

impl Default for EchoMemory {
    /// A memory that fingerprints messages by topic and payload bytes, until it learns its medium.
    fn default() -> Self {
        EchoMemory::with(seabus_medium::medium::fingerprint)
    }
}

impl std::fmt::Debug for EchoMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EchoMemory")
            .field("sent", &self.sent.len())
            .finish()
    }
}

impl EchoMemory {
    /// A memory fingerprinting messages with `fingerprint`.
    pub fn with(fingerprint: impl Fn(&Topic, &Payload) -> u64 + Send + Sync + 'static) -> Self {
        EchoMemory {
            sent: std::collections::VecDeque::new(),
            fingerprint: Box::new(fingerprint),
        }
    }

    /// A memory of what is sent to `medium`, recognised as its wire sees it.
    pub fn of(medium: &Medium) -> Self {
        let medium = medium.clone();
        EchoMemory::with(move |t, p| medium.fingerprint(t, p))
    }

    fn forget_old(&mut self, now: Instant) {
        while self.sent.front().is_some_and(|(_, t)| {
            now.duration_since(*t) > ECHO_WINDOW || self.sent.len() > ECHO_ENTRIES
        }) {
            self.sent.pop_front();
        }
    }

    /// Notes a message sent.
    pub fn sent(&mut self, topic: &Topic, payload: &Payload) {
        let now = Instant::now();
        self.forget_old(now);
        self.sent
            .push_back(((self.fingerprint)(topic, payload), now));
    }

    /// Whether a message read is the echo of one sent (which is then forgotten).
    pub fn is_echo(&mut self, topic: &Topic, payload: &Payload) -> bool {
        self.forget_old(Instant::now());
        let f = (self.fingerprint)(topic, payload);
        match self.sent.iter().position(|(g, _)| *g == f) {
            Some(i) => {
                self.sent.remove(i);
                true
            }
            None => false,
        }
    }
}

/// Why a message could not be carried across: a reason to count it under, and what happened.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// The key it is counted under.
    pub reason: &'static str,
    /// What happened, naming the channel.
    pub detail: String,
}

impl Problem {
    /// A problem of `reason`.
    pub fn new(reason: &'static str, detail: String) -> Problem {
        Problem { reason, detail }
    }
}

/// A route compiled for one direction.
struct Leg {
    from: usize,
    to: usize,
    topics: Pattern,
    rename: Option<Pattern>,
    min_interval: Option<Duration>,
    format: Option<Format>,
    kind: Option<Kind>,
    fields: Vec<(String, String)>,
    keep: bool,
    lcm: Option<crate::lcm::Mapping>,
    /// The quality of service of what it delivers, declared on the far medium when the bridge
    /// starts.
    qos: Option<Qos>,
    /// Its pattern names seabus's own topics (`seabus.…`): it carries them to any medium.
    own: bool,
}

#[derive(Default, Clone, Copy)]
struct LegStats {
    forwarded: u64,
    rate_limited: u64,
    latency_sum_ms: f64,
    latency_max_ms: f64,
    latency_n: u64,
}

#[derive(Default)]
struct Counters {
    duplicates: u64,
    late: u64,
    hop_limited: u64,
    returned: u64,
    echoes: u64,
    unrouted: u64,
    errors: u64,
    reports_unpublished: u64,
}

/// What the bridges of this program forwarded into one medium (held by the medium, see
/// [`Medium::shared`]): a message forwarded into it once is not forwarded into it again by
/// another bridge.
#[derive(Default)]
pub struct Forwarded(std::sync::Mutex<Dedup>);

impl Forwarded {
    /// Whether `msg` was forwarded into this medium before (it is noted now if not).
    pub fn already(&self, msg: &Message) -> bool {
        let mut seen = self.0.lock().unwrap_or_else(|p| p.into_inner());
        seen.check(msg) == Seen::Duplicate
    }
}

/// The generic bridge.
pub struct RouteBridge {
    media: [String; 2],
    hops: u8,
    legs: Vec<Leg>,
    stats: Vec<LegStats>,
    counters: Counters,
    seen: Dedup,
    /// Whether each side takes channel names that are not seabus topics (LCM).
    names_channels: [bool; 2],
    /// When each rate-limited topic's next message is due.
    schedule: crate::rate::Schedule,
    report: Option<Duration>,
    report_topic: Topic,
    /// The ports reports go out on: those whose medium carries datamaps as they are.
    report_ports: Vec<usize>,
    /// Each side's medium carries lists in its datamaps (else reports go flattened).
    lists: [bool; 2],
    /// A report could not be published on this side, and was logged as such.
    report_failing: [bool; 2],
    /// LCM types, when a route has one.
    types: Option<Arc<ResolvedTypes>>,
    /// Messages not carried across, by reason (logged without flooding).
    problems: Tally,
    /// What was sent to each side whose medium carries no provenance.
    echo: [Option<EchoMemory>; 2],
    /// What the routes of the message at hand make of it (kept between messages).
    outs: Vec<Out>,
    /// Whether each side's peers are not seabus programs (its wire carries no provenance):
    /// seabus's own topics go there only by a route that names them.
    foreign: [bool; 2],
    /// The legs leading from each side, filed by their topics (under their place in `legs`).
    index: [SubIndex; 2],
    /// What the index found for the message at hand (kept between messages).
    scratch: Scratch,
}

fn build(spec: &BridgeSpec, caps: &[Capabilities; 2], _: &Catalogue) -> Result<Built, FileError> {
    let (bridge, decl) = RouteBridge::new(spec, caps)?;
    Ok(Built {
        decl,
        module: Box::new(bridge),
    })
}

impl RouteBridge {
    /// Compiles a bridge from its system-file form and what its media can do, with its
    /// declaration.
    pub fn new(
        spec: &BridgeSpec,
        caps: &[Capabilities; 2],
    ) -> Result<(RouteBridge, Declaration), FileError> {
        let port_of = |name: &str| if name == spec.media[0] { 0 } else { 1 };
        let mut legs = Vec::new();
        let mut decl = Declaration::new(ModuleKind::Bridge)
            .format(0, None)
            .format(1, None);
        let types = if spec.routes.iter().any(|r| r.lcm.is_some())
            || spec.params.get("lcm_types").is_some()
        {
            Some(crate::lcm::load(spec)?)
        } else {
            None
        };
        for r in &spec.routes {
            for (from, to) in r.legs(&spec.media[0], &spec.media[1]) {
                let (from, to) = (port_of(from), port_of(to));
                // data travels on what the bridge consumes, commands on what it accepts
                if r.kind != Some(Kind::Command) {
                    decl = decl.consumes(TopicDecl::topic(r.topics.as_str()).on_port(from));
                }
                if r.kind != Some(Kind::Data) {
                    decl = decl.accepts(TopicDecl::topic(r.topics.as_str()).on_port(from));
                }
                decl = decl.produces(TopicDecl::topic(r.out_pattern().as_str()).on_port(to));
                legs.push(Leg {
                    from,
                    to,
                    topics: r.topics.clone(),
                    rename: r.rename.clone(),
                    min_interval: r.min_interval,
                    format: r.format,
                    kind: r.kind,
                    fields: r.fields.clone(),
                    keep: r.keep,
                    lcm: match &types {
                        Some(t) => crate::lcm::Mapping::new(spec, caps, r, t, from, to)?,
                        None => None,
                    },
                    qos: route_qos(spec, caps, r, to)?,
                    own: r.topics.as_str().split('.').next() == Some("seabus"),
                });
            }
        }
        let mut index = [SubIndex::default(), SubIndex::default()];
        for (i, l) in legs.iter().enumerate() {
            index[l.from].insert(i as u32, &l.topics, l.kind);
        }
        let report = spec.params.duration_or("report", Duration::from_secs(1))?;
        let report_ports = report_ports(spec, caps)?;
        let report_topic = Topic::new(&format!("seabus.bridge.{}", spec.name))
            .map_err(|e| spec.pos.error(e.to_string()))?;
        let bridge = RouteBridge {
            media: spec.media.clone(),
            hops: spec.hops,
            stats: vec![LegStats::default(); legs.len()],
            legs,
            counters: Counters::default(),
            seen: Dedup::new(),
            schedule: crate::rate::Schedule::default(),
            report: (!report.is_zero()).then_some(report),
            report_topic,
            report_ports,
            lists: caps.each_ref().map(|c| c.lists),
            report_failing: [false; 2],
            types,
            problems: Tally::new(),
            echo: [0, 1].map(|i| (!caps[i].provenance).then(EchoMemory::default)),
            names_channels: [0, 1].map(|i| caps[i].names_channels()),
            outs: Vec::new(),
            foreign: caps.each_ref().map(|c| !c.provenance),
            index,
            scratch: Scratch::default(),
        };
        Ok((bridge, decl))
    }
}

/// The sides the bridge reports on: those `report_on` names (each must carry datamaps as they
/// are), else those whose peers are seabus programs (their wire carries seabus's provenance).
fn report_ports(spec: &BridgeSpec, caps: &[Capabilities; 2]) -> Result<Vec<usize>, FileError> {
    let Some(p) = spec.params.get("report_on") else {
        return Ok((0..2).filter(|&i| caps[i].provenance).collect());
    };
    let mut ports = Vec::new();
    for name in p.value.split_whitespace() {
        let Some(i) = spec.media.iter().position(|m| m == name) else {
            return Err(p.error(format!(
                "`{name}` is not a medium of this bridge ({} and {})",
                spec.media[0], spec.media[1]
            )));
        };
        if !caps[i].carries_datamaps() {
            return Err(p.error(format!(
                "medium `{name}` carries only its own kind of messages: no report can go there"
            )));
        }
        if !ports.contains(&i) {
            ports.push(i);
        }
    }
    Ok(ports)
}

/// The quality of service of what route `r` delivers to medium `to` (0 or 1), refused when that
/// medium carries no priorities.
fn route_qos(
    spec: &BridgeSpec,
    caps: &[Capabilities; 2],
    r: &RouteSpec,
    to: usize,
) -> Result<Option<Qos>, FileError> {
    let Some(rq) = &r.qos else {
        return Ok(None);
    };
    if caps[to].qos {
        return Ok(Some(rq.qos));
    }
    // a route both ways delivers to both media: it may say which one it means
    let hint = match (&r.from, &r.to) {
        (None, None) if caps[1 - to].qos => format!(
            "; give the route to=\"{}\" for what goes there only",
            spec.media[1 - to]
        ),
        _ => String::new(),
    };
    Err(rq.attr.error(format!(
        "the route delivers to medium `{}`, which carries no priority, congestion control or \
         express (a Zenoh medium does){hint}",
        spec.media[to]
    )))
}

/// Where a message goes: the side, and the message as it leaves.
type Out = (usize, Message);

impl RouteBridge {
    /// Puts in `out` what `msg`, read on side `port`, becomes under every route that matches it
    /// (in the order of the routes); or says why nothing goes (the last route's reason when every
    /// matching route dropped it).
    fn routes(
        &mut self,
        node: &str,
        port: usize,
        msg: Message,
        out: &mut Vec<Out>,
    ) -> Result<(), &'static str> {
        match self.seen.check(&msg) {
            Seen::New => {}
            Seen::Duplicate => {
                self.counters.duplicates += 1;
                return Err("duplicate");
            }
            // Taken later than a thousand newer ones from its origin (the two sides are read
            // turn about, commands first): forwarded all the same. Each side already dropped the
            // copies it received twice; a copy that crossed over both ways is dropped by the
            // receivers' windows, and the hop limit bounds any path.
            Seen::Late => self.counters.late += 1,
        }
        if let Some(memory) = &mut self.echo[port]
            && memory.is_echo(&msg.topic, &msg.payload)
        {
            self.counters.echoes += 1;
            return Err("echo of what it sent");
        }
        // the legs from this side whose topics and kind match, in the order of the routes
        let own = msg.topic.as_str().split('.').next() == Some("seabus");
        self.index[port].matching(msg.topic.as_str(), msg.kind, &mut self.scratch);
        let mut found = std::mem::take(&mut self.scratch.found);
        if own {
            found.retain(|&i| {
                let l = &self.legs[i as usize];
                !self.foreign[l.to] || l.own
            });
        }
        let result = self.each_leg(node, msg, &found, out);
        self.scratch.found = found;
        result
    }

    /// Puts in `out` what `msg` becomes under each of the legs `found` (or says why none takes
    /// it, the last leg's reason when each dropped it).
    fn each_leg(
        &mut self,
        node: &str,
        msg: Message,
        found: &[u32],
        out: &mut Vec<Out>,
    ) -> Result<(), &'static str> {
        if found.is_empty() {
            self.counters.unrouted += 1;
            return Err("no route");
        }
        if msg.provenance.hops >= self.hops {
            self.counters.hop_limited += 1;
            return Err("hop limit");
        }
        let mut why = "no route";
        let mut msg = Some(msg);
        for (n, &i) in found.iter().enumerate() {
            // the last route takes the message itself, the others a copy
            let m = if n + 1 == found.len() {
                msg.take()
            } else {
                msg.clone()
            };
            let Some(m) = m else { break };
            match self.leg(i as usize, node, m) {
                Ok(o) => out.push(o),
                Err(reason) => why = reason,
            }
        }
        if out.is_empty() { Err(why) } else { Ok(()) }
    }

    /// What `msg` becomes under route leg `i`, or why it does not go.
    fn leg(&mut self, i: usize, node: &str, mut msg: Message) -> Result<Out, &'static str> {
        let leg = &self.legs[i];
        // a channel name that is not a seabus topic (from LCM) goes only where such names go
        if !self.names_channels[leg.to] && !msg.topic.is_topic() {
            self.counters.unrouted += 1;
            return Err("not a seabus topic");
        }
        let origin = &msg.provenance.origin;
        if &*origin.node == node && *origin.medium == *self.media[leg.to] {
            self.counters.returned += 1;
            return Err("would return to its origin medium");
        }
        let topic = match &leg.rename {
            None => msg.topic.clone(),
            Some(to) => {
                let renamed = leg
                    .topics
                    .captures(&msg.topic)
                    .and_then(|caps| to.fill(&caps))
                    .and_then(|t| Topic::new(&t).ok());
                match renamed {
                    Some(t) => t,
                    None => {
                        self.counters.errors += 1;
                        return Err("rename produced no valid topic");
                    }
                }
            }
        };
        if let (Some(period), Kind::Data) = (leg.min_interval, msg.kind) {
            let now = Instant::now();
            if !self.schedule.admit(i, &topic, period, now) {
                self.stats[i].rate_limited += 1;
                return Err("rate limit");
            }
            if self.schedule.len() > MAX_RATE_ENTRIES {
                let legs = &self.legs;
                self.schedule.prune(now, |i| legs[i].min_interval);
                if self.schedule.len() > MAX_RATE_ENTRIES {
                    // a flood of distinct topics: start over rather than grow without bound
                    self.schedule.clear();
                }
            }
        }
        // the payload is taken out of the message, so a datamap no one else holds is renamed in place
        let taken = std::mem::replace(&mut msg.payload, Payload::from(Vec::new()));
        let converted = match (&leg.lcm, &self.types) {
            (Some(lcm), Some(types)) => convert_lcm(
                taken,
                leg,
                lcm,
                types,
                (&msg.topic, &topic),
                msg.stamp,
                (&self.problems, self.report_topic.as_str()),
            ),
            _ => convert(taken, &leg.fields, leg.keep, leg.format)
                .map_err(|e| Problem::new("conversion", format!("topic `{}`: {e}", msg.topic))),
        };
        let payload = match converted {
            Ok(p) => p,
            Err(p) => {
                self.counters.errors += 1;
                self.problems
                    .record(self.report_topic.as_str(), p.reason, p.detail);
                return Err("conversion");
            }
        };
        let st = &mut self.stats[i];
        st.forwarded += 1;
        let latency = Stamp::now().since(msg.stamp).as_secs_f64() * 1e3;
        st.latency_sum_ms += latency;
        st.latency_max_ms = st.latency_max_ms.max(latency);
        st.latency_n += 1;
        let to = leg.to;
        let mut out = msg;
        out.topic = topic;
        out.payload = payload;
        out.provenance.hops = out.provenance.hops.saturating_add(1);
        if let Some(memory) = &mut self.echo[to] {
            memory.sent(&out.topic, &out.payload);
        }
        Ok((to, out))
    }

    fn report_map(&mut self) -> DataMap {
        let c = &self.counters;
        let list = |f: &dyn Fn(&LegStats) -> Value| Value::List(self.stats.iter().map(f).collect());
        let forwarded: u64 = self.stats.iter().map(|s| s.forwarded).sum();
        let rate_limited: u64 = self.stats.iter().map(|s| s.rate_limited).sum();
        let map = DataMap::new()
            .with("forwarded", forwarded as i64)
            .with("duplicates", c.duplicates as i64)
            .with("late", c.late as i64)
            .with("hop_limited", c.hop_limited as i64)
            .with("returned", c.returned as i64)
            .with("echoes", c.echoes as i64)
            .with("rate_limited", rate_limited as i64)
            .with("unrouted", c.unrouted as i64)
            .with("errors", c.errors as i64)
            .with("reports_unpublished", c.reports_unpublished as i64)
            .with("route_forwarded", list(&|s| Value::Int(s.forwarded as i64)))
            .with(
                "route_rate_limited",
                list(&|s| Value::Int(s.rate_limited as i64)),
            )
            .with(
                "route_latency_ms",
                list(&|s| {
                    Value::Float(if s.latency_n > 0 {
                        s.latency_sum_ms / s.latency_n as f64
                    } else {
                        0.0
                    })
                }),
            )
            .with(
                "route_latency_max_ms",
                list(&|s| Value::Float(s.latency_max_ms)),
            );
        // what was not carried across, or carried as liblcm reads it, by reason
        let mut map = map;
        for (reason, n) in self.problems.counts() {
            map.push(reason, i64::try_from(n).unwrap_or(i64::MAX));
        }
        // latency is reported per period
        for s in &mut self.stats {
            s.latency_sum_ms = 0.0;
            s.latency_max_ms = 0.0;
            s.latency_n = 0;
        }
        map
    }
}

/// Carries a payload across a route with an LCM type: decoded from LCM bytes read on `from`, field
/// renames applied, then encoded for the LCM channel `to` (or put in the far side's format). What
/// is read leniently is counted in `tally`, logged as `source`.
fn convert_lcm(
    p: Payload,
    leg: &Leg,
    lcm: &crate::lcm::Mapping,
    types: &ResolvedTypes,
    (from, to): (&Topic, &Topic),
    stamp: Stamp,
    (tally, source): (&Tally, &str),
) -> Result<Payload, Problem> {
    let p = if lcm.decodes() {
        Payload::from(lcm.decode(types, from.as_str(), &p, tally, source)?)
    } else {
        p
    };
    let conversion =
        |e: seabus_medium::ConvertError| Problem::new("conversion", format!("topic `{from}`: {e}"));
    if !lcm.encodes() {
        return convert(p, &leg.fields, leg.keep, leg.format).map_err(conversion);
    }
    let map = convert(p, &leg.fields, leg.keep, None)
        .and_then(|p| p.to_map())
        .map_err(conversion)?;
    lcm.encode(types, to.as_str(), &map, stamp)
}

/// Applies field renames (which need a datamap), keeping only the listed fields unless `keep`,
/// and the far side's format.
fn convert(
    p: Payload,
    fields: &[(String, String)],
    keep: bool,
    format: Option<Format>,
) -> Result<Payload, seabus_medium::ConvertError> {
    let p = if fields.is_empty() && keep {
        p
    } else if keep {
        let map = p.to_map()?;
        drop(p);
        let mut map = Arc::unwrap_or_clone(map);
        for (from, to) in fields {
            map.rename(from, to);
        }
        Payload::from(map)
    } else {
        // only the listed fields, in the order listed
        let map = p.to_map()?;
        let mut out = DataMap::with_capacity(fields.len());
        for (from, to) in fields {
            if let Some(v) = map.get(from) {
                out.push(to.clone(), v.clone());
            }
        }
        Payload::from(out)
    };
    match format {
        Some(f) => p.convert(f),
        None => Ok(p),
    }
}

#[async_trait]
impl Module for RouteBridge {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        for (i, memory) in self.echo.iter_mut().enumerate() {
            if let (Some(memory), Some(port)) = (memory, ctx.port(i)) {
                *memory = EchoMemory::of(port.medium());
            }
        }
        // what the routes deliver goes with their quality of service, in the order of the routes
        for leg in &self.legs {
            let (Some(qos), Some(port)) = (leg.qos, ctx.port(leg.to)) else {
                continue;
            };
            let topics = leg.rename.as_ref().unwrap_or(&leg.topics);
            if !port.medium().set_qos(topics, leg.kind, qos) {
                tracing::warn!(
                    bridge = ctx.name(),
                    to = %self.media[leg.to],
                    "`{qos}` for {topics} not honoured: the medium carries no priorities"
                );
            }
        }
        match self.report {
            Some(r) if !self.report_ports.is_empty() => ctx.every(REPORT, r),
            Some(_) => tracing::info!(
                bridge = ctx.name(),
                "no report published: neither {} nor {} carries datamaps as they are",
                self.media[0],
                self.media[1]
            ),
            None => {}
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let mut outs = std::mem::take(&mut self.outs);
        // what no route takes is counted where it was dropped
        let _ = self.routes(&ctx.node().name, port, msg, &mut outs);
        // per side: whether a message went there already, and whether another bridge had
        // forwarded it there before
        let (mut sent, mut skip) = ([false; 2], [false; 2]);
        for (to, out) in outs.drain(..) {
            if skip[to] {
                self.counters.duplicates += 1;
                continue;
            }
            let Some(iface) = ctx.port(to) else {
                return Err(ModuleError::msg(format!("bridge has no port {to}")));
            };
            let result = if std::mem::replace(&mut sent[to], true) {
                // a second route into the same medium: the copy is a message of its own there,
                // numbered by that medium (receivers would take one origin's number once)
                match iface.forward_anew(out).await {
                    Ok(seq) => {
                        self.seen.check_raw(iface.medium().origin().id, seq);
                        Ok(())
                    }
                    Err(e) => Err(e),
                }
            } else if iface.medium().shared::<Forwarded>().already(&out) {
                skip[to] = true;
                self.counters.duplicates += 1;
                continue;
            } else {
                iface.forward(out).await
            };
            if let Err(e) = result {
                self.counters.errors += 1;
                // a medium whose link is down refuses every message: counted, logged now and then
                self.problems.record(
                    self.report_topic.as_str(),
                    "not-forwarded",
                    format_args!("not forwarded to {}: {e}", self.media[to]),
                );
            }
        }
        self.outs = outs;
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        // the media that carry datamaps hear about the bridge between them
        let map = self.report_map();
        for port in self.report_ports.clone() {
            let report = if self.lists[port] {
                map.clone()
            } else {
                map.clone().flatten_lists()
            };
            // a report that cannot go out is counted apart, never a reason to stop forwarding
            match ctx
                .publish_on(port, Kind::Data, &self.report_topic, report)
                .await
            {
                Ok(_) => self.report_failing[port] = false,
                Err(e) => {
                    self.counters.reports_unpublished += 1;
                    // a medium whose link is down fails every period: said once, until a
                    // report goes out there again
                    if !std::mem::replace(&mut self.report_failing[port], true) {
                        tracing::warn!(
                            bridge = ctx.name(),
                            "report not published on {} (said once until one is): {e}",
                            self.media[port]
                        );
                    }
                }
            }
        }
        let legs = &self.legs;
        self.schedule
            .prune(Instant::now(), |i| legs[i].min_interval);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use seabus_medium::{Origin, Provenance};
    use seabus_modules::system::SystemSpec;

    /// What became of one message under a bridge whose routes send it one way at most.
    #[derive(Debug, PartialEq)]
    enum Verdict {
        Forward(usize, Message),
        Drop(&'static str),
    }

    impl RouteBridge {
        fn route(&mut self, node: &str, port: usize, msg: Message) -> Verdict {
            let mut out = Vec::new();
            match self.routes(node, port, msg, &mut out) {
                Ok(()) => {
                    assert_eq!(out.len(), 1, "one route: {out:?}");
                    let (to, m) = out.remove(0);
                    Verdict::Forward(to, m)
                }
                Err(why) => Verdict::Drop(why),
            }
        }
    }

    fn bridge(routes: &str, hops: u8) -> RouteBridge {
        let text = format!(
            "<seabus><medium name=\"a\" url=\"inproc://\"/><medium name=\"b\" url=\"inproc://\"/>\
             <bridge name=\"x\" media=\"a b\" hops=\"{hops}\">{routes}</bridge></seabus>"
        );
        let spec = SystemSpec::parse("t.xml", &text).unwrap();
        RouteBridge::new(&spec.bridges[0], &caps(&spec.bridges[0]))
            .unwrap()
            .0
    }

    /// What the media of a bridge can do, as their schemes say.
    fn caps(spec: &BridgeSpec) -> [Capabilities; 2] {
        let schemes = seabus_medium::Schemes::with(&[
            seabus_medium_lcm::register,
            seabus_medium_can::register,
            seabus_medium_udp::register,
            seabus_medium_serial::register,
        ]);
        spec.urls.clone().map(|u| schemes.check(&u).unwrap())
    }

    fn msg(topic: &str, node: &str, medium: &str, seq: u64, hops: u8) -> Message {
        Message {
            topic: Topic::new(topic).unwrap(),
            kind: Kind::Data,
            provenance: Provenance {
                origin: Origin::new(node, medium, 1),
                seq,
                hops,
            },
            stamp: Stamp::now(),
            payload: Payload::from(DataMap::new().with("hdg", 1.5f64)),
        }
    }

    #[tokio::test(start_paused = true)]
    async fn an_echo_is_dropped_once_per_frame_sent_and_only_for_a_while() {
        let mut m = EchoMemory::with(|t, p| seabus_medium_can::frame_fingerprint(t, p).unwrap());
        let topic = Topic::new("can.123").unwrap();
        let frame = |d: &[u8]| Payload::from(DataMap::new().with("data", Value::Bytes(d.to_vec())));
        // bytes and a datamap of the same frame are the same on the wire
        m.sent(&topic, &Payload::from(vec![1u8, 2]));
        assert!(!m.is_echo(&topic, &frame(&[1, 3])), "other data");
        assert!(
            !m.is_echo(&Topic::new("can.124").unwrap(), &frame(&[1, 2])),
            "other id"
        );
        assert!(m.is_echo(&topic, &frame(&[1, 2])));
        assert!(
            !m.is_echo(&topic, &frame(&[1, 2])),
            "one echo per frame sent"
        );
        m.sent(&topic, &frame(&[1, 2]));
        tokio::time::advance(ECHO_WINDOW + Duration::from_millis(1)).await;
        assert!(
            !m.is_echo(&topic, &frame(&[1, 2])),
            "forgotten after the window"
        );
    }

    #[test]
    fn an_lcm_channel_that_is_not_a_topic_crosses_only_to_lcm() {
        let text = "<seabus><medium name=\"lcm\" url=\"udpm://239.255.76.67:7667\"/>\
             <medium name=\"lcm2\" url=\"udpm://239.255.76.68:7667\"/>\
             <medium name=\"net\" url=\"udp://239.1.1.1:5\"/>\
             <bridge name=\"a\" media=\"lcm net\"><route topics=\"**\"/></bridge>\
             <bridge name=\"b\" media=\"lcm lcm2\"><route topics=\"**\"/></bridge></seabus>";
        let spec = SystemSpec::parse("t.xml", text).unwrap();
        let mut built: Vec<RouteBridge> = spec
            .bridges
            .iter()
            .map(|b| RouteBridge::new(b, &caps(b)).unwrap().0)
            .collect();
        let odd = |seq| Message {
            topic: Topic::channel("with space").unwrap(),
            payload: Payload::from(vec![1u8, 2]),
            ..msg("x", "peer", "lcm", seq, 0)
        };
        assert!(matches!(
            built[0].route("n", 0, odd(1)),
            Verdict::Drop("not a seabus topic")
        ));
        assert_eq!(built[0].counters.unrouted, 1);
        match built[1].route("n", 0, odd(1)) {
            Verdict::Forward(1, m) => assert_eq!(m.topic.as_str(), "with space"),
            _ => panic!("not forwarded from LCM to LCM"),
        }
    }

    #[test]
    fn media_without_provenance_get_an_echo_memory_and_reports_go_where_datamaps_fit() {
        let text = "<seabus><medium name=\"line\" url=\"pty:///tmp/x\"/>\
             <medium name=\"bus\" url=\"cannelloni://127.0.0.1:5\"/>\
             <medium name=\"net\" url=\"udp://239.1.1.1:5\"/>\
             <bridge name=\"a\" media=\"line net\"><route topics=\"**\"/></bridge>\
             <bridge name=\"b\" media=\"net bus\"><route topics=\"**\"/></bridge></seabus>";
        let spec = SystemSpec::parse("t.xml", text).unwrap();
        let built: Vec<RouteBridge> = spec
            .bridges
            .iter()
            .map(|b| RouteBridge::new(b, &caps(b)).unwrap().0)
            .collect();
        let echo = |b: &RouteBridge| b.echo.each_ref().map(Option::is_some);
        assert_eq!(
            echo(&built[0]),
            [true, false],
            "a serial line has no provenance"
        );
        assert_eq!(echo(&built[1]), [false, true], "nor has CAN");
        assert_eq!(
            built[0].report_ports,
            vec![1],
            "a serial line carries no datamap report"
        );
        assert_eq!(
            built[1].report_ports,
            vec![0],
            "CAN carries only its frames"
        );
    }

    #[test]
    fn seabus_s_own_topics_reach_a_foreign_bus_only_by_a_route_that_names_them() {
        let text = |routes: &str| {
            format!(
                "<seabus><medium name=\"net\" url=\"udp://239.1.1.1:5\"/>\
                 <medium name=\"lcm\" url=\"udpm://239.255.76.67:7667?ttl=0\"/>\
                 <bridge name=\"x\" media=\"net lcm\">{routes}</bridge></seabus>"
            )
        };
        let build = |routes: &str| {
            let spec = SystemSpec::parse("t.xml", &text(routes)).unwrap();
            RouteBridge::new(&spec.bridges[0], &caps(&spec.bridges[0]))
                .unwrap()
                .0
        };
        let mut wild = build(r#"<route from="net" to="lcm" topics="**"/>"#);
        for (i, topic) in ["seabus.media", "seabus.module.gps", "seabus.bridge.up"]
            .iter()
            .enumerate()
        {
            assert_eq!(
                wild.route("me", 0, msg(topic, "n", "net", i as u64 + 1, 0)),
                Verdict::Drop("no route"),
                "{topic}"
            );
        }
        assert!(matches!(
            wild.route("me", 0, msg("nav.depth", "n", "net", 9, 0)),
            Verdict::Forward(1, _)
        ));
        // a segment named like it is no reason to stop anything else
        assert!(matches!(
            wild.route("me", 0, msg("auv1.seabus.media", "n", "net", 10, 0)),
            Verdict::Forward(1, _)
        ));
        // asked for by name, it goes
        let mut named = build(r#"<route from="net" to="lcm" topics="seabus.media"/>"#);
        assert!(matches!(
            named.route("me", 0, msg("seabus.media", "n", "net", 1, 0)),
            Verdict::Forward(1, _)
        ));
        // towards a seabus medium a wildcard carries them as ever
        let mut back = build(r#"<route from="lcm" to="net" topics="**"/>"#);
        assert!(matches!(
            back.route("me", 1, msg("seabus.media", "n", "lcm", 1, 0)),
            Verdict::Forward(0, _)
        ));
    }

    #[test]
    fn forwards_once_renames_and_counts_hops() {
        let mut b = bridge(r#"<route topics="nav.*" rename="auv1.nav.*"/>"#, 8);
        let Verdict::Forward(to, out) = b.route("me", 0, msg("nav.depth", "me", "a", 1, 0)) else {
            panic!()
        };
        assert_eq!(
            (to, out.topic.as_str(), out.provenance.hops),
            (1, "auv1.nav.depth", 1)
        );
        assert_eq!(out.provenance.seq, 1, "provenance is kept");
        // the same message coming back from the other side is not forwarded again
        assert_eq!(
            b.route("me", 1, msg("nav.depth", "me", "a", 1, 1)),
            Verdict::Drop("duplicate")
        );
        assert_eq!(
            b.route("me", 0, msg("cmd.x", "me", "a", 2, 0)),
            Verdict::Drop("no route")
        );
    }

    #[test]
    fn never_returns_a_message_to_its_origin_medium_and_honours_the_hop_limit() {
        let mut b = bridge(r#"<route topics="**"/>"#, 3);
        assert_eq!(
            b.route("me", 0, msg("t", "me", "b", 1, 1)),
            Verdict::Drop("would return to its origin medium")
        );
        // the same medium name on another node is another medium
        assert!(matches!(
            b.route("me", 0, msg("t", "other", "b", 1, 1)),
            Verdict::Forward(1, _)
        ));
        assert_eq!(
            b.route("me", 0, msg("t", "me", "a", 7, 3)),
            Verdict::Drop("hop limit")
        );
        assert!(matches!(
            b.route("me", 0, msg("t", "me", "a", 8, 2)),
            Verdict::Forward(1, _)
        ));
    }

    #[test]
    fn every_route_that_matches_forwards_with_its_own_name_fields_and_rate() {
        let mut b = bridge(
            r#"<route from="a" topics="nav.local" rename="NAV_X" keep="false"><field name="x" rename="value"/></route>
               <route from="a" topics="nav.local" rename="NAV_Y" keep="false" rate="1"><field name="y" rename="value"/></route>
               <route from="a" topics="nav.*" format="xml"/>
               <route from="b" topics="nav.local"/>"#,
            8,
        );
        let fields = |o: &Out| {
            let map = o.1.payload.to_map().unwrap();
            (
                o.1.topic.to_string(),
                map.get_f64("value"),
                map.get_f64("x"),
            )
        };
        let local = |seq| {
            let mut m = msg("nav.local", "n", "a", seq, 0);
            m.payload = Payload::from(DataMap::new().with("x", 1.5).with("y", -2.0));
            m
        };
        let mut out = Vec::new();
        b.routes("me", 0, local(1), &mut out).unwrap();
        assert_eq!(
            out.iter().map(fields).collect::<Vec<_>>(),
            [
                ("NAV_X".to_string(), Some(1.5), None),
                ("NAV_Y".to_string(), Some(-2.0), None),
                ("nav.local".to_string(), None, Some(1.5)),
            ]
        );
        assert_eq!(out[2].1.payload.format(), Format::Xml);
        assert!(out.iter().all(|(to, m)| *to == 1 && m.provenance.hops == 1));
        // the next one within the second: the rate-limited route drops it, the others take it
        out.clear();
        b.routes("me", 0, local(2), &mut out).unwrap();
        assert_eq!(out.len(), 2);
        // once seen, it goes by no route at all (the window is the bridge's, not a route's)
        out.clear();
        assert_eq!(b.routes("me", 1, local(2), &mut out), Err("duplicate"));
        assert!(out.is_empty());
        let report = b.report_map();
        assert_eq!(
            report.get("route_forwarded"),
            Some(&Value::List(vec![
                Value::Int(2),
                Value::Int(1),
                Value::Int(2),
                Value::Int(0)
            ]))
        );
        assert_eq!(report.get_i64("rate_limited"), Some(1));
    }

    #[test]
    fn rate_limits_data_per_topic_and_converts_formats_and_fields() {
        let mut b = bridge(
            r#"<route from="a" topics="nav.*" rate="1" format="xml"><field name="hdg" rename="heading"/></route>"#,
            8,
        );
        let Verdict::Forward(_, out) = b.route("me", 0, msg("nav.x", "n", "a", 1, 0)) else {
            panic!()
        };
        assert_eq!(out.payload.format(), Format::Xml);
        assert_eq!(out.payload.to_map().unwrap().get_f64("heading"), Some(1.5));
        assert_eq!(
            b.route("me", 0, msg("nav.x", "n", "a", 2, 0)),
            Verdict::Drop("rate limit")
        );
        assert!(
            matches!(
                b.route("me", 0, msg("nav.y", "n", "a", 3, 0)),
                Verdict::Forward(..)
            ),
            "per topic"
        );
        // a command is never rate-limited
        let mut c = msg("nav.x", "n", "a", 4, 0);
        c.kind = Kind::Command;
        assert!(matches!(b.route("me", 0, c), Verdict::Forward(..)));
        // nothing routes from b
        assert_eq!(
            b.route("me", 1, msg("nav.z", "n", "b", 5, 0)),
            Verdict::Drop("no route")
        );
        let report = b.report_map();
        assert_eq!(report.get_i64("forwarded"), Some(3));
        assert_eq!(report.get_i64("rate_limited"), Some(1));
        assert_eq!(report.get_i64("unrouted"), Some(1));
    }

    #[test]
    fn nested_maps_cross_in_every_format_and_renames_touch_top_level_fields() {
        let pose = DataMap::new().with("hdg", 2.5f64).with(
            "wps",
            Value::List(vec![DataMap::new().with("hdg", 3i64).into()]),
        );
        for format in ["map", "xml", "bytes"] {
            let mut b = bridge(
                &format!(
                    r#"<route from="a" topics="nav.*" format="{format}"><field name="hdg" rename="heading"/></route>"#
                ),
                8,
            );
            let mut m = msg("nav.pose", "n", "a", 1, 0);
            m.payload = Payload::from(
                DataMap::new()
                    .with("hdg", 1.5f64)
                    .with("pose", pose.clone()),
            );
            let Verdict::Forward(_, out) = b.route("me", 0, m) else {
                panic!("{format}")
            };
            let map = out.payload.to_map().unwrap();
            assert_eq!(
                *map,
                DataMap::new()
                    .with("heading", 1.5f64)
                    .with("pose", pose.clone()),
                "{format}"
            );
            assert_eq!(map.get_path("pose.hdg"), Some(&Value::Float(2.5)));
        }
    }

    /// A bridge between `a` (in-process) and `z`, a medium that carries priorities, with `routes`.
    fn qos_bridge(routes: &str) -> Result<RouteBridge, String> {
        let text = format!(
            "<seabus><medium name=\"a\" url=\"inproc://\"/><medium name=\"z\" url=\"inproc://\"/>\n\
             <bridge name=\"x\" media=\"a z\">\n{routes}\n</bridge></seabus>"
        );
        let spec = SystemSpec::parse("t.xml", &text).unwrap();
        let z = Capabilities {
            qos: true,
            ..Capabilities::IN_PROCESS
        };
        RouteBridge::new(&spec.bridges[0], &[Capabilities::IN_PROCESS, z])
            .map(|(b, _)| b)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn quality_of_service_goes_only_to_a_medium_that_carries_priorities() {
        use seabus_medium::qos::{Congestion, Priority};
        let b = qos_bridge(
            r#"<route from="a" topics="nav.*" rename="auv1.nav.*" priority="data-high" congestion="block"/>
               <route from="z" to="a" topics="cmd.**"/>"#,
        )
        .unwrap();
        let qos: Vec<_> = b.legs.iter().map(|l| (l.to, l.qos)).collect();
        assert_eq!(
            qos,
            [
                (
                    1,
                    Some(Qos {
                        priority: Some(Priority::DataHigh),
                        congestion: Some(Congestion::Block),
                        express: None,
                    })
                ),
                (0, None)
            ]
        );
        assert_eq!(
            qos_bridge(r#"<route from="z" topics="cmd.**" express="true"/>"#)
                .err()
                .unwrap(),
            "t.xml:3:33: attribute `express`: the route delivers to medium `a`, which carries no \
             priority, congestion control or express (a Zenoh medium does)"
        );
        assert_eq!(
            qos_bridge(r#"<route topics="**" priority="realtime"/>"#)
                .err()
                .unwrap(),
            "t.xml:3:20: attribute `priority`: the route delivers to medium `a`, which carries no \
             priority, congestion control or express (a Zenoh medium does); give the route \
             to=\"z\" for what goes there only"
        );
    }

    #[cfg(feature = "lcm")]
    fn lcm_bridge(routes: &str) -> Result<RouteBridge, String> {
        let text = format!(
            "<seabus><medium name=\"a\" url=\"inproc://\"/>\
             <medium name=\"l\" url=\"udpm://239.255.76.67:7667\"/>\
             <bridge name=\"x\" media=\"a l\">{routes}</bridge></seabus>"
        );
        let spec = SystemSpec::parse("t.xml", &text).unwrap();
        RouteBridge::new(&spec.bridges[0], &caps(&spec.bridges[0]))
            .map(|(b, _)| b)
            .map_err(|e| e.to_string())
    }

    #[cfg(feature = "lcm")]
    #[test]
    fn lcm_routes_encode_for_lcm_and_decode_from_it_checking_the_type() {
        let mut b = lcm_bridge(
            r#"<route from="a" topics="nav.position" rename="NAV_POSITION" lcm="seabus.position_t">
                 <field name="latitude" rename="lat"/></route>
               <route from="l" topics="NAV_POSITION" lcm="seabus.position_t"/>"#,
        )
        .unwrap();
        let mut m = msg("nav.position", "n", "a", 1, 0);
        m.payload = Payload::from(
            DataMap::new()
                .with("latitude", 43.5f64)
                .with("lon", 16.4f64)
                .with("utime", 7i64),
        );
        let Verdict::Forward(1, out) = b.route("me", 0, m) else {
            panic!("forwarded to the LCM side")
        };
        let bytes = out.payload.as_bytes().expect("LCM bytes").clone();
        let types = b.types.clone().unwrap();
        let ty = types.get("seabus.position_t").unwrap();
        assert_eq!(bytes[..8], ty.fingerprint().to_be_bytes());
        // and back, a message an LCM program sent (not the bridge's own, which it would take for
        // an echo): decoded, with the fields of the type
        let from_lcm = DataMap::new().with("lat", 43.5f64).with("utime", 8i64);
        let mut back = msg("NAV_POSITION", "lcm@x", "l", 1, 0);
        back.payload =
            Payload::from(seabus_medium_lcm::codec::encode(&types, ty, &from_lcm).unwrap());
        let Verdict::Forward(0, out) = b.route("me", 1, back) else {
            panic!("forwarded from the LCM side")
        };
        let map = out.payload.as_map().expect("a datamap");
        assert_eq!(map.get_f64("lat"), Some(43.5));
        assert_eq!(map.get_i64("utime"), Some(8));
        assert!(
            map.get_f64("hdop").is_some_and(f64::is_nan),
            "missing is NaN"
        );
        // another type on the channel is refused and counted
        let heading = types.get("seabus.heading_t").unwrap();
        let other = seabus_medium_lcm::codec::encode(&types, heading, &DataMap::new()).unwrap();
        let mut wrong = msg("NAV_POSITION", "lcm@x", "l", 2, 0);
        wrong.payload = Payload::from(other);
        assert_eq!(b.route("me", 1, wrong), Verdict::Drop("conversion"));
        assert_eq!(
            b.problems.counts().get("lcm-type-mismatch").copied(),
            Some(1)
        );
    }

    #[cfg(feature = "lcm")]
    #[test]
    fn lcm_routes_name_unknown_types_and_need_an_lcm_medium() {
        let e = lcm_bridge(r#"<route topics="x" lcm="seabus.nope_t"/>"#)
            .err()
            .unwrap();
        assert!(
            e.contains("unknown LCM type `seabus.nope_t`") && e.contains("seabus.position_t"),
            "{e}"
        );
        let text = "<seabus><medium name=\"a\" url=\"inproc://\"/><medium name=\"b\" url=\"inproc://\"/>\
             <bridge name=\"x\" media=\"a b\"><route topics=\"x\" lcm=\"seabus.position_t\"/></bridge></seabus>";
        let spec = SystemSpec::parse("t.xml", text).unwrap();
        let e = RouteBridge::new(&spec.bridges[0], &caps(&spec.bridges[0]))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("needs an LCM medium"), "{e}");
    }
}
