//! The fault stage: seeded loss, duplication, reordering and delay, for testing what runs on a medium.
//!
//! Any medium gets it from its URL (`udp://…?fault.loss=0.3&fault.dup=0.1&fault.reorder=0.1&fault.seed=7`)
//! or in code. Every message a local interface sends passes through it: it may be lost, sent twice,
//! held back so that later ones overtake it, or delayed. The same seed gives the same decisions for the
//! same sequence of messages.

use crate::medium::{Frame, Inner, SendError};
use crate::message::Message;
use crate::parse::parse_duration;
use crate::url::{MediumUrl, UrlError};
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::time::Instant;

/// What the fault stage does.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultConfig {
    /// Probability that a message is lost.
    pub loss: f64,
    /// Probability that a message is sent twice.
    pub duplicate: f64,
    /// Probability that a message (or copy) is held back by `hold`, letting later ones overtake it.
    pub reorder: f64,
    /// How long a reordered message is held back.
    pub hold: Duration,
    /// Fixed delay added to every message.
    pub delay: Duration,
    /// Random extra delay, uniform in `[0, jitter]`.
    pub jitter: Duration,
    /// Seed of the random decisions.
    pub seed: u64,
}

impl Default for FaultConfig {
    fn default() -> Self {
        FaultConfig {
            loss: 0.0,
            duplicate: 0.0,
            reorder: 0.0,
            hold: Duration::from_millis(2),
            delay: Duration::ZERO,
            jitter: Duration::ZERO,
            seed: 0,
        }
    }
}

impl FaultConfig {
    /// The URL options the fault stage takes.
    pub const OPTIONS: [&'static str; 7] = [
        "fault.loss",
        "fault.dup",
        "fault.reorder",
        "fault.hold",
        "fault.delay",
        "fault.jitter",
        "fault.seed",
    ];

    /// Takes the `fault.*` options from a URL; `None` when there are none.
    pub fn from_url(url: &mut MediumUrl) -> Result<Option<FaultConfig>, UrlError> {
        let opts = url.take_prefixed("fault.");
        if opts.is_empty() {
            return Ok(None);
        }
        let mut cfg = FaultConfig::default();
        for (k, v) in opts {
            let bad = |what: &str| url.error(format!("option `fault.{k}={v}`: expected {what}"));
            let prob = || -> Result<f64, UrlError> {
                v.parse::<f64>()
                    .ok()
                    .filter(|p| (0.0..=1.0).contains(p))
                    .ok_or_else(|| bad("a probability between 0 and 1"))
            };
            let dur = || parse_duration(&v).ok_or_else(|| bad("a duration such as 5ms or 0.2s"));
            match k.as_str() {
                "loss" => cfg.loss = prob()?,
                "dup" => cfg.duplicate = prob()?,
                "reorder" => cfg.reorder = prob()?,
                "hold" => cfg.hold = dur()?,
                "delay" => cfg.delay = dur()?,
                "jitter" => cfg.jitter = dur()?,
                "seed" => cfg.seed = v.parse().map_err(|_| bad("an unsigned integer"))?,
                _ => {
                    return Err(url.error(format!(
                        "unknown option `fault.{k}`; known options: {}",
                        Self::OPTIONS.join(", ")
                    )));
                }
            }
        }
        Ok(Some(cfg))
    }
}

struct Scheduled {
    due: Instant,
    order: u64,
    msg: Option<Message>,
    frame: Option<Frame>,
    from: u64,
    wait: bool,
}

impl PartialEq for Scheduled {
    fn eq(&self, other: &Self) -> bool {
        (self.due, self.order) == (other.due, other.order)
    }
}
impl Eq for Scheduled {}
impl PartialOrd for Scheduled {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Scheduled {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (self.due, self.order).cmp(&(other.due, other.order))
    }
}

pub(crate) struct Faults {
    cfg: FaultConfig,
    rng: Mutex<fastrand::Rng>,
    later: Mutex<Option<mpsc::UnboundedSender<Scheduled>>>,
    order: AtomicU64,
    lost: AtomicU64,
    duplicated: AtomicU64,
    delayed: AtomicU64,
}

impl Faults {
    pub fn new(cfg: FaultConfig) -> Faults {
        Faults {
            rng: Mutex::new(fastrand::Rng::with_seed(cfg.seed)),
            cfg,
            later: Mutex::new(None),
            order: AtomicU64::new(0),
            lost: AtomicU64::new(0),
            duplicated: AtomicU64::new(0),
            delayed: AtomicU64::new(0),
        }
    }

    pub fn stats(&self) -> (u64, u64, u64) {
        (
            self.lost.load(Ordering::Relaxed),
            self.duplicated.load(Ordering::Relaxed),
            self.delayed.load(Ordering::Relaxed),
        )
    }

    /// Decides the fate of one message: the delays of the copies to send (none when lost).
    fn decide(&self) -> Vec<Duration> {
        let mut rng = self.rng.lock().unwrap_or_else(|p| p.into_inner());
        let c = &self.cfg;
        if rng.f64() < c.loss {
            return Vec::new();
        }
        let copies = if rng.f64() < c.duplicate { 2 } else { 1 };
        (0..copies)
            .map(|_| {
                let mut d = c.delay;
                if !c.jitter.is_zero() {
                    d += c.jitter.mul_f64(rng.f64());
                }
                if rng.f64() < c.reorder {
                    d += c.hold;
                }
                d
            })
            .collect()
    }

    pub async fn apply(
        &self,
        inner: &Arc<Inner>,
        msg: Option<Message>,
        frame: Option<Frame>,
        from: u64,
        wait: bool,
    ) -> Result<(), SendError> {
        let delays = self.decide();
        if delays.is_empty() {
            self.lost.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        }
        if delays.len() > 1 {
            self.duplicated
                .fetch_add(delays.len() as u64 - 1, Ordering::Relaxed);
        }
        let now = Instant::now();
        let mut result = Ok(());
        for d in delays {
            if d.is_zero() {
                let r = inner
                    .dispatch(msg.clone(), frame.clone(), Some(from), wait, false)
                    .await;
                if result.is_ok() {
                    result = r;
                }
            } else {
                self.delayed.fetch_add(1, Ordering::Relaxed);
                self.schedule(
                    inner,
                    Scheduled {
                        due: now + d,
                        order: self.order.fetch_add(1, Ordering::Relaxed),
                        msg: msg.clone(),
                        frame: frame.clone(),
                        from,
                        wait,
                    },
                );
            }
        }
        result
    }

    fn schedule(&self, inner: &Arc<Inner>, item: Scheduled) {
        let mut later = self.later.lock().unwrap_or_else(|p| p.into_inner());
        let tx = later.get_or_insert_with(|| {
            let (tx, rx) = mpsc::unbounded_channel();
            let task = tokio::spawn(run_later(Arc::downgrade(inner), rx));
            // closing the medium stops what is still held back
            inner.own_task(task.abort_handle());
            tx
        });
        let _ = tx.send(item);
    }
}

/// Sends held-back and delayed messages when they are due, earliest first.
async fn run_later(inner: Weak<Inner>, mut rx: mpsc::UnboundedReceiver<Scheduled>) {
    let mut heap: BinaryHeap<Reverse<Scheduled>> = BinaryHeap::new();
    loop {
        let next_due = heap.peek().map(|Reverse(s)| s.due);
        tokio::select! {
            item = rx.recv() => match item {
                Some(s) => heap.push(Reverse(s)),
                None => return,
            },
            _ = async {
                match next_due {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            } => {
                let now = Instant::now();
                while heap.peek().is_some_and(|Reverse(s)| s.due <= now) {
                    let Some(Reverse(s)) = heap.pop() else { break };
                    let Some(inner) = inner.upgrade() else { return };
                    if let Err(e) = inner.dispatch(s.msg, s.frame, Some(s.from), s.wait, false).await {
                        tracing::debug!("delayed message not sent: {e}");
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_come_from_the_url() {
        let mut u = MediumUrl::parse(
            "udp://h:1?fault.loss=0.3&fault.dup=0.1&fault.hold=5ms&ttl=0&fault.seed=9",
        )
        .unwrap();
        let cfg = FaultConfig::from_url(&mut u).unwrap().unwrap();
        assert_eq!(cfg.loss, 0.3);
        assert_eq!(cfg.duplicate, 0.1);
        assert_eq!(cfg.hold, Duration::from_millis(5));
        assert_eq!(cfg.seed, 9);
        assert_eq!(u.take("ttl").as_deref(), Some("0"));
        let mut u = MediumUrl::parse("udp://h:1?fault.loss=2").unwrap();
        let e = FaultConfig::from_url(&mut u).unwrap_err();
        assert_eq!(
            e.reason,
            "option `fault.loss=2`: expected a probability between 0 and 1"
        );
        let mut u = MediumUrl::parse("udp://h:1?fault.los=0.1").unwrap();
        assert!(
            FaultConfig::from_url(&mut u)
                .unwrap_err()
                .reason
                .contains("unknown option `fault.los`")
        );
    }

    #[test]
    fn decisions_follow_the_seed() {
        let cfg = FaultConfig {
            loss: 0.3,
            duplicate: 0.2,
            reorder: 0.2,
            seed: 42,
            ..FaultConfig::default()
        };
        let a = Faults::new(cfg.clone());
        let b = Faults::new(cfg);
        let da: Vec<_> = (0..1000).map(|_| a.decide()).collect();
        let db: Vec<_> = (0..1000).map(|_| b.decide()).collect();
        assert_eq!(da, db);
        let lost = da.iter().filter(|d| d.is_empty()).count();
        assert!((220..380).contains(&lost), "lost {lost} of 1000 at p=0.3");
        let dup = da.iter().filter(|d| d.len() == 2).count();
        assert!((90..200).contains(&dup), "duplicated {dup}");
    }
}
