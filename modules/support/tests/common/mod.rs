//! What the modules' tests share: feeding stamped sensor data to a bus and reading what comes back.

#![allow(dead_code)]

use seabus_medium::{
    DataMap, Interface, Kind, Medium, Message, Origin, Payload, Provenance, Stamp, Topic,
};
use std::sync::Arc;
use std::time::Duration;

/// Sends datamaps stamped as a sensor would stamp them, seconds after a fixed start.
pub struct Feed {
    pub tx: Interface,
    pub origin: Arc<Origin>,
    pub seq: u64,
    pub t0: f64,
}

impl Feed {
    /// A feed attached to `bus` as `sensors`.
    pub fn new(bus: &Medium) -> Feed {
        Feed {
            tx: bus.attach("sensors"),
            origin: Origin::new("sensors", "bus", 1),
            seq: 0,
            t0: 1_795_000_000.0,
        }
    }

    /// Sends `map` on `topic` stamped `t` seconds after the start.
    pub async fn send(&mut self, t: f64, topic: &str, map: DataMap) {
        self.seq += 1;
        let msg = Message {
            topic: Topic::new(topic).unwrap(),
            kind: Kind::Data,
            provenance: Provenance {
                origin: self.origin.clone(),
                seq: self.seq,
                hops: 0,
            },
            stamp: Stamp(((self.t0 + t) * 1e9) as i64),
            payload: Payload::from(map),
        };
        self.tx.forward(msg).await.unwrap();
    }
}

/// Up to `n` datamaps received on `topic` (other topics skipped), waiting at most 5 s for each.
pub async fn drain(rx: &mut Interface, topic: &str, n: usize) -> Vec<DataMap> {
    let mut out = Vec::new();
    while out.len() < n {
        match tokio::time::timeout(Duration::from_secs(5), rx.recv()).await {
            Ok(Some(m)) if m.topic.as_str() == topic => {
                out.push(m.payload.as_map().unwrap().clone())
            }
            Ok(Some(_)) => {}
            _ => break,
        }
    }
    out
}
