//! The health monitor as a DSAAV service: components report their health to it by RPC, it polls
//! passive components with the health call every DSAAV server answers, and anyone may ask it for
//! the vehicle's severity.
//!
//! - [`ops::REPORT`] (`component`, `state`): an active component's update; sent unreliably by
//!   [`report`], as updates come again and a lost one only counts towards the timeout.
//! - [`ops::STATUS`]: answers `severity` (0 NONE … 3 EMERGENCY) and `components`, each rules
//!   component's state as `NAME=STATE` separated by commas. It also answers a broadcast call, so a
//!   control station finds the monitor without knowing its address.
//! - A passive component is polled with the sentuator health call ([`ops::HEALTH`], which every
//!   DSAAV server answers with its `state`) at the address the configuration gives it: the
//!   `Server` key of its section.
//!
//! The `health-monitor` module ([`crate::health_monitor`]) runs it beside the bus.

use super::health::ComponentState;
use super::rpc::{self, CallOptions, RpcClient};
use seabus_medium::{DataMap, Medium, SendError};
use seabus_medium_dsaav::wire::Address;
use std::sync::{Arc, Mutex};
use tokio::sync::mpsc;

/// The health service's operations.
pub mod ops {
    /// A component's health update.
    pub const REPORT: i32 = 500;
    /// The vehicle's severity and the components' states.
    pub const STATUS: i32 = 501;
    /// The health call every DSAAV server answers (the sentuator health operation).
    pub const HEALTH: i32 = super::super::sentuator::ops::HEALTH;
}

/// Sends `component`'s `state` to the health monitor at `monitor`, unreliably.
pub async fn report(
    rpc: &RpcClient,
    monitor: Address,
    component: &str,
    state: ComponentState,
) -> Result<(), SendError> {
    let update = DataMap::new()
        .with("component", component)
        .with("state", i64::from(state.code()));
    rpc.call_unreliable(monitor, ops::REPORT, &update).await
}

/// Asks the server at `at` for its health; `None` when it does not answer within `opts` or
/// answers no state it could be in.
pub async fn poll(rpc: &RpcClient, at: Address, opts: CallOptions) -> Option<ComponentState> {
    let reply = rpc
        .call(at, ops::HEALTH, &DataMap::new(), opts)
        .await
        .ok()?;
    reply
        .get_i64("state")
        .and_then(ComponentState::from_code)
        .filter(|s| *s != ComponentState::Offline)
}

/// The health call's answer: the server's `state` and the `services` it offers (comma-separated).
pub fn health_reply(state: ComponentState, services: &str) -> DataMap {
    DataMap::new()
        .with("state", i64::from(state.code()))
        .with("services", services)
}

/// What the service answers a status call with; the monitor keeps it current.
pub type Status = Arc<Mutex<DataMap>>;

/// The status answer for a severity and the components' states.
pub fn status(
    severity: super::health::Severity,
    components: impl Iterator<Item = (impl AsRef<str>, ComponentState)>,
) -> DataMap {
    let list: Vec<String> = components
        .map(|(n, s)| format!("{}={}", n.as_ref(), s.name()))
        .collect();
    DataMap::new()
        .with("severity", i64::from(severity.code()))
        .with("components", list.join(","))
}

/// Serves the health service on `port` until the medium closes: reports go to `updates` (the
/// newest dropped while it is full), status calls get what `status` holds. A report naming no
/// component or no state is refused with status 5.
pub async fn serve(
    medium: &Medium,
    port: u16,
    updates: mpsc::Sender<(String, ComponentState)>,
    status: Status,
) {
    rpc::serve(
        medium,
        port,
        &[ops::STATUS, ops::HEALTH],
        move |call| match call.op {
            ops::REPORT => {
                let p = &call.params;
                let component = p.get_str("component").filter(|c| !c.is_empty());
                let state = p.get_i64("state").and_then(ComponentState::from_code);
                let (Some(component), Some(state)) = (component, state) else {
                    return Err((
                        5,
                        "a health report needs `component` and `state` 0–3".to_string(),
                    ));
                };
                let _ = updates.try_send((component.to_string(), state));
                Ok(DataMap::new())
            }
            ops::STATUS => Ok(status.lock().unwrap_or_else(|p| p.into_inner()).clone()),
            ops::HEALTH => Ok(health_reply(ComponentState::Healthy, "Health")),
            op => Err((3, format!("operation {op} is not a health operation"))),
        },
    )
    .await
}

/// An active component's way to the health monitor: its updates, at most one each `every`.
pub struct Reporter {
    rpc: RpcClient,
    monitor: Address,
    component: String,
    every: std::time::Duration,
    last: Option<tokio::time::Instant>,
}

impl Reporter {
    /// How often a component reports, when nothing says otherwise: four times within the
    /// shortest timeout the starfish rules give (1 s), so that a lost update or two go unnoticed.
    pub const EVERY: std::time::Duration = std::time::Duration::from_millis(250);

    /// A reporter for `component` sending from `port` of the medium's node to the health server
    /// the configuration gives it (`[Health] Server`, or `Health.Server` in its section).
    pub async fn from_service(
        medium: &Medium,
        port: u16,
        component: &str,
        cfg: &super::config_service::ConfigClient,
    ) -> Result<Reporter, super::rpc::RpcError> {
        let monitor = cfg.server_of(component, "Health").await?;
        Ok(Reporter {
            rpc: RpcClient::new(medium, port),
            monitor,
            component: component.to_string(),
            every: Reporter::EVERY,
            last: None,
        })
    }

    /// Sends `state` if the last update is `every` old (call it each tick).
    pub async fn update(&mut self, state: ComponentState) {
        let now = tokio::time::Instant::now();
        if self.last.is_some_and(|t| now - t < self.every) {
            return;
        }
        self.last = Some(now);
        if let Err(e) = report(&self.rpc, self.monitor, &self.component, state).await {
            tracing::debug!(component = %self.component, "health update not sent: {e}");
        }
    }
}

/// A component's health from whether its data keeps coming: HEALTHY while it had data within
/// `grace`, UNAVAILABLE after — so that a component just started, or one missing a single
/// reading, does not alarm the vehicle.
#[derive(Debug, Clone)]
pub struct DataHealth {
    last: tokio::time::Instant,
    grace: std::time::Duration,
}

impl DataHealth {
    /// Watching from now, with `grace` for the first data.
    pub fn new(grace: std::time::Duration) -> DataHealth {
        DataHealth {
            last: tokio::time::Instant::now(),
            grace,
        }
    }

    /// Notes whether data came this time; the state that follows.
    pub fn update(&mut self, got_data: bool) -> ComponentState {
        let now = tokio::time::Instant::now();
        if got_data {
            self.last = now;
        }
        if now - self.last <= self.grace {
            ComponentState::Healthy
        } else {
            ComponentState::Unavailable
        }
    }
}
