//! Sentuators — sensors and actuators — as DSAAV services over RPC: a server answers `get`, `set`
//! and `health` calls for one device and sends unreliable `notify` calls with each new reading to
//! the listeners the configuration registers for it; a [`SentuatorClient`] makes those calls and
//! [`listen`] receives notifications.
//!
//! A `health` call answers the device's state (`state`, as the health monitor counts them) and
//! `services`, the comma-separated names of the services the component offers: asking every
//! server for its health is how a station discovers what a vehicle offers.

use super::config::Database;
use super::health::ComponentState;
use super::health_service::health_reply;
use super::rpc::{self, CallOptions, Outcome, RpcClient, RpcError};
use seabus_medium::{DataMap, Medium};
use seabus_medium_dsaav::wire::{Address, AddressError};
use std::sync::{Arc, Mutex};

/// The sentuator operations.
pub mod ops {
    /// The latest reading (or the actuator's current setting).
    pub const GET: i32 = 200;
    /// Sets an actuator; answers what it was set to.
    pub const SET: i32 = 201;
    /// A new reading, sent unreliably to each listener.
    pub const NOTIFY: i32 = 202;
    /// The device's state and the services offered.
    pub const HEALTH: i32 = 203;
}

/// Quantities a sentuator measures or actuates (the dictionary key `quantity`).
pub mod quantity {
    /// Depth below the surface, m.
    pub const DEPTH: i64 = 1;
    /// Heading, degrees.
    pub const HEADING: i64 = 2;
    /// Pitch, degrees.
    pub const PITCH: i64 = 3;
    /// Roll, degrees.
    pub const ROLL: i64 = 4;
    /// Speed, m/s.
    pub const SPEED: i64 = 5;
    /// Altitude above the floor, m.
    pub const ALTITUDE: i64 = 6;
    /// Geographic position, degrees.
    pub const POSITION: i64 = 7;
    /// Elevator angle, degrees.
    pub const ELEVATOR: i64 = 8;
    /// Rudder angle, degrees.
    pub const RUDDER: i64 = 9;
    /// Thrust, percent.
    pub const THRUST: i64 = 10;
}

/// How a value was obtained (the dictionary key `measurement`).
pub mod measurement {
    /// Straight from the device.
    pub const RAW: i64 = 0;
    /// Filtered.
    pub const FILTERED: i64 = 1;
    /// Estimated from other quantities.
    pub const ESTIMATED: i64 = 2;
    /// A commanded (set) value.
    pub const COMMANDED: i64 = 3;
}

/// One sensor or actuator behind a sentuator server.
pub trait Device: Send + 'static {
    /// The latest reading, as dictionary keys (`depth`, `quantity`, `measurement`, …).
    fn get(&mut self) -> DataMap;
    /// Sets an actuator; a sensor refuses.
    fn set(&mut self, values: &DataMap) -> Outcome {
        let _ = values;
        Err((3, "a sensor cannot be set".to_string()))
    }
    /// The device's state.
    fn health(&mut self) -> ComponentState {
        ComponentState::Healthy
    }
}

/// A sentuator server: answers calls for its device on `port`, and [`Sentuator::notify`] sends a
/// reading to the listeners.
pub struct Sentuator<D: Device> {
    device: Arc<Mutex<D>>,
    listeners: Vec<Address>,
    notifier: RpcClient,
}

impl<D: Device> Sentuator<D> {
    /// Starts serving `device` on `port` of the medium's node, offering `services` (listed by
    /// health calls), notifying `listeners` (from the configuration) from `notify_port`.
    pub fn start(
        medium: &Medium,
        port: u16,
        notify_port: u16,
        device: D,
        services: &[&str],
        listeners: Vec<Address>,
    ) -> Sentuator<D> {
        let device = Arc::new(Mutex::new(device));
        let served = device.clone();
        let services = services.join(",");
        let m = medium.clone();
        tokio::spawn(async move {
            rpc::serve(&m, port, &[ops::HEALTH], move |call| {
                let mut d = served.lock().unwrap_or_else(|p| p.into_inner());
                match call.op {
                    ops::GET => Ok(d.get()),
                    ops::SET => d.set(&call.params),
                    ops::HEALTH => Ok(health_reply(d.health(), &services)),
                    op => Err((3, format!("operation {op} is not a sentuator operation"))),
                }
            })
            .await
        });
        Sentuator {
            device,
            listeners,
            notifier: RpcClient::new(medium, notify_port),
        }
    }

    /// The device, to update it between notifications.
    pub fn device(&self) -> &Arc<Mutex<D>> {
        &self.device
    }

    /// Sends the device's current reading to every listener, unreliably; returns how many
    /// notifications went out.
    pub async fn notify(&self) -> usize {
        let reading = self.device.lock().unwrap_or_else(|p| p.into_inner()).get();
        let mut sent = 0;
        for &to in &self.listeners {
            if self
                .notifier
                .call_unreliable(to, ops::NOTIFY, &reading)
                .await
                .is_ok()
            {
                sent += 1;
            }
        }
        sent
    }
}

/// Receives notifications on `port` of the medium's node, handing each reading and its sender to
/// `on_reading`, until the medium closes.
pub async fn listen(medium: &Medium, port: u16, mut on_reading: impl FnMut(Address, DataMap)) {
    rpc::serve(medium, port, &[], move |call| {
        if call.op == ops::NOTIFY {
            on_reading(call.from, call.params);
        }
        Ok(DataMap::new())
    })
    .await
}

/// Calls a sentuator server.
pub struct SentuatorClient {
    rpc: RpcClient,
    opts: CallOptions,
}

impl SentuatorClient {
    /// A client on `port` of the medium's node.
    pub fn new(medium: &Medium, port: u16, opts: CallOptions) -> SentuatorClient {
        SentuatorClient {
            rpc: RpcClient::new(medium, port),
            opts,
        }
    }

    /// The latest reading of the sentuator at `at`.
    pub async fn get(&self, at: Address) -> Result<DataMap, RpcError> {
        self.rpc
            .call(at, ops::GET, &DataMap::new(), self.opts)
            .await
    }

    /// Sets the actuator at `at`.
    pub async fn set(&self, at: Address, values: &DataMap) -> Result<DataMap, RpcError> {
        self.rpc.call(at, ops::SET, values, self.opts).await
    }

    /// The state of the sentuator at `at`, and the services its component offers.
    pub async fn health(&self, at: Address) -> Result<(ComponentState, Vec<String>), RpcError> {
        let reply = self
            .rpc
            .call(at, ops::HEALTH, &DataMap::new(), self.opts)
            .await?;
        Ok(health_of(&reply))
    }

    /// Asks every server on the RPC channel for its health: the first to answer, with its
    /// address, state and services.
    pub async fn discover(&self) -> Result<(Address, ComponentState, Vec<String>), RpcError> {
        let (at, reply) = self
            .rpc
            .discover(ops::HEALTH, &DataMap::new(), self.opts)
            .await?;
        let (state, services) = health_of(&reply);
        Ok((at, state, services))
    }
}

/// The listeners the configuration registers for `component`: its `Listeners` key, addresses
/// separated by commas (`Listeners = 3:1, 5:0`); none when the key is absent.
pub fn listeners(db: &Database, component: &str) -> Result<Vec<Address>, String> {
    match db.get_str(component, "Listeners") {
        Ok(text) => parse_listeners(component, text),
        Err(_) => Ok(Vec::new()),
    }
}

/// Reads a `Listeners` value of `component`: addresses separated by commas.
pub fn parse_listeners(component: &str, text: &str) -> Result<Vec<Address>, String> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|a| {
            a.parse()
                .map_err(|e: AddressError| format!("[{component}] Listeners: {e}"))
        })
        .collect()
}

fn health_of(reply: &DataMap) -> (ComponentState, Vec<String>) {
    let services = reply
        .get_str("services")
        .unwrap_or("")
        .split(',')
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect();
    (
        reply
            .get_i64("state")
            .and_then(ComponentState::from_code)
            .unwrap_or(ComponentState::Unavailable),
        services,
    )
}
