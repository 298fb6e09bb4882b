//! Who is in the fleet: each node's Zenoh medium declares a liveliness token `<fleet>/<node>`
//! (`fleet/auv1`), and every Zenoh medium follows the tokens of its fleet. A node is online while
//! its token lives; it goes offline when its session ends or its connection is lost for a lease
//! (the `lease` option, 3 s by default).
//!
//! The medium says so on its own `seabus.fleet` topic, as it happens and every [`EVERY`] for all
//! it knows: one message per node with `node`, `online`, `since` (seconds since 1970, when it came
//! or went) and, when a message of that node arrived in the last period, `latency` (seconds from
//! the message's stamp to its arrival: the one-way delay when the clocks agree). A bridge route
//! carries it to the bus like any other topic of the medium.

use seabus_medium::{DataMap, Ingress, Message, Payload, Stamp, Topic};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Session;
use zenoh::liveliness::LivelinessToken;
use zenoh::sample::{Sample, SampleKind};

/// How often every known node is announced again.
pub const EVERY: Duration = Duration::from_secs(5);
/// [`EVERY`] in the link watch's one-second ticks.
pub(crate) const EVERY_TICKS: u32 = 5;

/// The topic the fleet is announced on.
pub use seabus_medium::topic::FLEET as TOPIC;

#[derive(Debug, Clone)]
struct Member {
    online: bool,
    since: f64,
    /// the latest one-way delay measured, taken when announced
    latency: Option<f64>,
}

/// The members of one fleet, as this medium sees them.
#[derive(Clone)]
pub struct Fleet {
    root: Arc<str>,
    ingress: Ingress,
    members: Arc<Mutex<BTreeMap<String, Member>>>,
}

impl Fleet {
    /// The fleet under key `root`, announced through `ingress`.
    pub fn new(root: &str, ingress: Ingress) -> Fleet {
        Fleet {
            root: Arc::from(root),
            ingress,
            members: Arc::default(),
        }
    }

    fn members(&self) -> std::sync::MutexGuard<'_, BTreeMap<String, Member>> {
        self.members.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Declares this node's token `token` and follows the fleet's; what is returned keeps the
    /// token alive.
    pub async fn join(
        &self,
        session: &Session,
        token: &str,
    ) -> Option<(LivelinessToken, zenoh::pubsub::Subscriber<()>)> {
        let declared = session.liveliness().declare_token(token.to_string()).await;
        let token = match declared {
            Ok(t) => t,
            Err(e) => {
                self.ingress
                    .reject("fleet", format_args!("cannot declare {token}: {e}"));
                return None;
            }
        };
        let me = self.clone();
        let watched = session
            .liveliness()
            .declare_subscriber(format!("{}/*", self.root))
            .history(true)
            .callback(move |sample| me.changed(&sample))
            .await;
        match watched {
            Ok(sub) => Some((token, sub)),
            Err(e) => {
                self.ingress
                    .reject("fleet", format_args!("cannot follow {}/*: {e}", self.root));
                None
            }
        }
    }

    /// A token came or went.
    fn changed(&self, sample: &Sample) {
        let key = sample.key_expr().as_str();
        let Some(node) = key.rsplit('/').next().filter(|n| !n.is_empty()) else {
            return;
        };
        let online = sample.kind() == SampleKind::Put;
        let member = {
            let mut members = self.members();
            let m = members.entry(node.to_string()).or_insert(Member {
                online: !online,
                since: 0.0,
                latency: None,
            });
            if m.online == online {
                return;
            }
            m.online = online;
            m.since = Stamp::now().as_secs_f64();
            m.clone()
        };
        if online {
            tracing::info!(medium = self.root.as_ref(), "{node} joined the fleet");
        } else {
            tracing::warn!(medium = self.root.as_ref(), "{node} left the fleet");
        }
        self.announce(node, &member);
    }

    /// A message from a member arrived: its one-way delay is noted.
    pub fn heard(&self, msg: &Message) {
        let delay = Stamp::now().as_secs_f64() - msg.stamp.as_secs_f64();
        if let Some(m) = self.members().get_mut(&*msg.provenance.origin.node) {
            m.latency = Some(delay);
        }
    }

    fn announce(&self, node: &str, m: &Member) {
        let mut map = DataMap::with_capacity(4)
            .and("node", node)
            .and("online", m.online)
            .and("since", m.since);
        if let Some(l) = m.latency {
            map.push("latency", l);
        }
        if let Ok(topic) = Topic::new(TOPIC) {
            self.ingress.originate(topic, Payload::from(map));
        }
    }

    /// Announces every known node again (their latencies measured since the last time).
    pub fn announce_all(&self) {
        let all: Vec<(String, Member)> = self
            .members()
            .iter_mut()
            .map(|(n, m)| {
                let copy = m.clone();
                m.latency = None;
                (n.clone(), copy)
            })
            .collect();
        for (node, m) in all {
            self.announce(&node, &m);
        }
    }
}
