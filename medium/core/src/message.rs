//! The message: topic, kind, provenance, timestamp and payload.

use crate::payload::Payload;
use crate::topic::Topic;
use std::fmt;
use std::hash::{Hash, Hasher};
use std::sync::Arc;
use std::time::Duration;

/// What a message is for; it decides the queueing policy at every receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// Data: a full queue drops its oldest data message (counted).
    Data,
    /// A command: never dropped silently; a full queue holds the sender back.
    Command,
}

impl Kind {
    /// `data` or `command`.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Data => "data",
            Kind::Command => "command",
        }
    }
}

/// Where a message was first published: a node, one of its media, and the node's boot number.
///
/// The boot number is drawn at random when a node starts, so a restarted node's sequence numbers
/// never collide with those of its earlier run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Origin {
    /// The publishing node's name.
    pub node: Arc<str>,
    /// The medium the message was first published on, by its name on that node.
    pub medium: Arc<str>,
    /// A number drawn when the node started.
    pub boot: u32,
    /// A hash of the three fields above, for fast look-ups.
    pub id: u64,
}

impl Origin {
    /// Builds an origin and computes its id.
    pub fn new(node: &str, medium: &str, boot: u32) -> Arc<Origin> {
        Arc::new(Origin {
            node: Arc::from(node),
            medium: Arc::from(medium),
            boot,
            id: Origin::id_of(node, medium, boot),
        })
    }

    /// The id an origin with these fields has.
    pub fn id_of(node: &str, medium: &str, boot: u32) -> u64 {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        node.hash(&mut h);
        medium.hash(&mut h);
        boot.hash(&mut h);
        h.finish()
    }
}

impl fmt::Display for Origin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.node, self.medium)
    }
}

/// A message's provenance: its origin, the origin's sequence number, and how many bridges it crossed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Provenance {
    /// Where the message was first published.
    pub origin: Arc<Origin>,
    /// Per-origin sequence number, counting up from 1.
    pub seq: u64,
    /// Bridges crossed so far.
    pub hops: u8,
}

/// A timestamp: nanoseconds since the Unix epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Stamp(pub i64);

impl Stamp {
    /// The current wall-clock time.
    pub fn now() -> Stamp {
        Stamp(crate::clock::now_ns())
    }

    /// Seconds since the epoch as a float.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// Time from `earlier` to `self`, zero when `earlier` is later.
    pub fn since(self, earlier: Stamp) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0).max(0) as u64)
    }

    /// The monotonic instant this stamp of this host's clock was: now, less the wall-clock time
    /// since (now for a stamp not yet reached). For timing what arrived by when it arrived, not by
    /// when it was looked at.
    pub fn instant(self) -> tokio::time::Instant {
        let now = tokio::time::Instant::now();
        now.checked_sub(Stamp::now().since(self)).unwrap_or(now)
    }
}

/// A message on a medium.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    /// The topic.
    pub topic: Topic,
    /// Data or command.
    pub kind: Kind,
    /// Origin, sequence number and hop count.
    pub provenance: Provenance,
    /// When the message was first published.
    pub stamp: Stamp,
    /// The payload.
    pub payload: Payload,
}

impl Message {
    /// The origin.
    pub fn origin(&self) -> &Origin {
        &self.provenance.origin
    }

    /// The per-origin sequence number.
    pub fn seq(&self) -> u64 {
        self.provenance.seq
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{SystemTime, UNIX_EPOCH};

    fn system_now() -> i64 {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .expect("after the epoch")
            .as_nanos() as i64
    }

    #[test]
    fn a_stamp_is_the_wall_clock_in_nanoseconds_since_the_epoch() {
        let before = system_now();
        let stamp = Stamp::now();
        let after = system_now();
        assert!(
            (before..=after).contains(&stamp.0),
            "{} not within {before}..={after}",
            stamp.0
        );
    }
}
