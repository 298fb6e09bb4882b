//! `dsaav-ecomms`: the DSAAV external communications service (`media="bus dsaav"`).
//!
//! Components send a message out through an external link with a `send` call (op 400: `interface`,
//! `destination`, `class`, `priority`, `lifetime` in seconds, `text`); the service queues it and
//! hands the link the waiting messages, highest priority first (oldest first within a priority),
//! at each of its ticks, as `ecomms.<INTERFACE>.out` on the bus (`destination`, `class`,
//! `priority`, `text`) for the link's driver. A message still waiting when its lifetime ends is
//! dropped and counted. Incoming messages the drivers publish as `ecomms.<INTERFACE>.in`
//! (`source`, `class`, `text`) go, as unreliable `receive` calls (op 402), to every component
//! that registered with a `listen` call (op 401, optionally for one `class`).

use super::rpc::{self, RpcClient};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Topic};
use seabus_medium_dsaav::wire::Address;
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::time::Instant;

/// The EComms operations.
pub mod ops {
    /// Queues a message for an external link.
    pub const SEND: i32 = 400;
    /// Registers the caller for incoming messages.
    pub const LISTEN: i32 = 401;
    /// An incoming message, to a listener.
    pub const RECEIVE: i32 = 402;
}

/// The `dsaav-ecomms` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "dsaav-ecomms",
    kind: ModuleKind::Service,
    summary: "DSAAV external communications: prioritised, expiring outgoing queue; listeners",
    build,
};

/// A message waiting for its link.
#[derive(Debug, Clone)]
struct Outgoing {
    interface: String,
    destination: String,
    class: i64,
    priority: i64,
    expires: Instant,
    text: String,
    order: u64,
}

/// The messages to hand the links now, highest priority first and oldest first within one, and
/// how many ran out of lifetime.
fn due(mut queue: Vec<Outgoing>, now: Instant) -> (Vec<Outgoing>, u64) {
    let before = queue.len();
    queue.retain(|m| m.expires > now);
    let expired = (before - queue.len()) as u64;
    queue.sort_by(|a, b| b.priority.cmp(&a.priority).then(a.order.cmp(&b.order)));
    (queue, expired)
}

#[derive(Default)]
struct State {
    queue: Vec<Outgoing>,
    listeners: Vec<(Address, Option<i64>)>,
    next: u64,
    expired: u64,
}

struct Ecomms {
    port: u16,
    state: Arc<Mutex<State>>,
    client: Option<RpcClient>,
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let port = cfg.params.parse("port", "a port 0–65535")?.unwrap_or(3);
    let decl = Declaration::new(ModuleKind::Service)
        .consumes(TopicDecl::topic("ecomms.*.in"))
        .produces(TopicDecl::topic("ecomms.*.out"))
        .default_tick(Duration::from_millis(100));
    Ok(Built {
        decl,
        module: Box::new(Ecomms {
            port,
            state: Arc::default(),
            client: None,
        }),
    })
}

fn text(p: &DataMap, key: &str) -> Result<String, (i64, String)> {
    p.get_str(key)
        .map(str::to_string)
        .ok_or_else(|| (5, format!("the call needs `{key}` (text)")))
}

/// Answers one call on the service's state.
fn handle(state: &Mutex<State>, call: rpc::Call) -> rpc::Outcome {
    let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
    let p = &call.params;
    match call.op {
        ops::SEND => {
            let interface = text(p, "interface")?;
            if Topic::new(&format!("ecomms.{interface}.out")).is_err() || interface.contains('.') {
                return Err((5, format!("`{interface}` is not an interface name")));
            }
            let lifetime = p.get_f64("lifetime").unwrap_or(60.0);
            let lifetime = Duration::try_from_secs_f64(lifetime)
                .map_err(|_| (5, format!("lifetime {lifetime} is not a number of seconds")))?;
            s.next += 1;
            let order = s.next;
            s.queue.push(Outgoing {
                interface,
                destination: text(p, "destination")?,
                class: p.get_i64("class").unwrap_or(0),
                priority: p.get_i64("priority").unwrap_or(0),
                expires: Instant::now() + lifetime,
                text: p.get_str("text").unwrap_or("").to_string(),
                order,
            });
            Ok(DataMap::new().with("count", s.queue.len() as i64))
        }
        ops::LISTEN => {
            let entry = (call.from, p.get_i64("class"));
            if !s.listeners.contains(&entry) {
                s.listeners.push(entry);
            }
            Ok(DataMap::new())
        }
        op => Err((3, format!("operation {op} is not an EComms operation"))),
    }
}

#[async_trait]
impl Module for Ecomms {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let Some(medium) = ctx.port(1).map(|p| p.medium().clone()) else {
            return Err(ModuleError::msg(
                "dsaav-ecomms needs two media: the bus, then the DSAAV medium",
            ));
        };
        let state = self.state.clone();
        let port = self.port;
        let m = medium.clone();
        tokio::spawn(async move {
            rpc::serve(&m, port, &[ops::SEND], move |call| handle(&state, call)).await
        });
        self.client = Some(RpcClient::new(&medium, port.wrapping_add(1)));
        Ok(())
    }

    async fn on_timer(
        &mut self,
        ctx: &mut Context,
        _: seabus_modules::module::TimerId,
    ) -> Result<(), ModuleError> {
        let now = Instant::now();
        let due = {
            let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
            let (due, expired) = due(std::mem::take(&mut s.queue), now);
            s.expired += expired;
            if expired > 0 {
                tracing::warn!(
                    expired = s.expired,
                    "EComms messages dropped at the end of their lifetime"
                );
            }
            due
        };
        for m in due {
            let Ok(topic) = Topic::new(&format!("ecomms.{}.out", m.interface)) else {
                continue;
            };
            let out = DataMap::new()
                .with("destination", m.destination.as_str())
                .with("class", m.class)
                .with("priority", m.priority)
                .with("text", m.text.as_str());
            ctx.publish(&topic, out).await?;
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        _: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let (Some(map), Some(client)) = (msg.payload.as_map(), &self.client) else {
            return Ok(());
        };
        let interface = msg
            .topic
            .as_str()
            .strip_prefix("ecomms.")
            .and_then(|t| t.strip_suffix(".in"))
            .unwrap_or("");
        let class = map.get_i64("class").unwrap_or(0);
        let incoming = DataMap::new()
            .with("interface", interface)
            .with("source", map.get_str("source").unwrap_or(""))
            .with("class", class)
            .with("text", map.get_str("text").unwrap_or(""));
        let listeners = self
            .state
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .listeners
            .clone();
        for (to, wanted) in listeners {
            if wanted.is_none_or(|c| c == class) {
                let _ = client.call_unreliable(to, ops::RECEIVE, &incoming).await;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_get_the_highest_priority_first_and_nothing_past_its_lifetime() {
        let now = Instant::now();
        let m = |text: &str, priority, order, life_ms| Outgoing {
            interface: "modem".into(),
            destination: "ship".into(),
            class: 0,
            priority,
            expires: now + Duration::from_millis(life_ms),
            text: text.into(),
            order,
        };
        let queue = vec![
            m("low", 1, 1, 1000),
            m("high", 9, 2, 1000),
            m("stale", 9, 3, 0),
            m("low-later", 1, 4, 1000),
        ];
        let (out, expired) = due(queue, now);
        let texts: Vec<&str> = out.iter().map(|m| m.text.as_str()).collect();
        assert_eq!(texts, ["high", "low", "low-later"]);
        assert_eq!(expired, 1);
    }
}
