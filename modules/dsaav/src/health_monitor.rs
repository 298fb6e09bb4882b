//! `health-monitor`: the health monitor as a module, watching every module and medium of the
//! system by the rules of a health rules file ([`crate::health`]), and serving DSAAV
//! components as the health service ([`crate::health_service`]).
//!
//! Parameters: `rules` (the rules file, relative to the system file); `dsaav` (one of its media, a
//! DSAAV medium: the health service is served there) with `port` (its port there, default 1 — the
//! paper's `[Health] Server = 1:1`). Its first medium is the bus: it reads there
//! - `seabus.module.<NAME>` — the runtime's module states: running → HEALTHY, failed → MALFUNCTION,
//!   stopped → OFFLINE, for a rules component called like the module;
//! - `seabus.health.<COMPONENT>` — reports a component sends itself (`state` = HEALTHY,
//!   UNAVAILABLE, MALFUNCTION or OFFLINE, or its number): active components send them regularly,
//!   passive ones answer the command `seabus.health.poll` (`component` = its name);
//! - the topics of its `data` components: each message is heard, and a topic silent too long
//!   makes its component UNAVAILABLE, then OFFLINE (a frontseat whose serial line is open but
//!   sends no navigation);
//! - `seabus.media` — the runtime's counters of every medium: the media that lost or refused
//!   anything (rejected input, bytes dropped, overruns, messages dropped from full queues,
//!   commands refused) are listed in the snapshot's `media`, each with its counters;
//! - `seabus.fleet` — which nodes a fleet medium (Zenoh) sees, bridged to the bus: a node online
//!   reports HEALTHY and one gone OFFLINE, for a rules component called like the node (an
//!   `active` component whose `timeout` is longer than the fleet's 5 s announcements);
//!
//! and publishes the health snapshot (`severity`, `components`, `reasons`, and `media` when a
//! medium lost anything) on the rules' topic at
//! their period and at once on every change of a component's state, and the emergency action as a
//! command on entry into EMERGENCY. Its other media are watched for `link` components: a link that
//! goes down makes the component OFFLINE (a serial driver whose device is unplugged).
//!
//! With `dsaav`, DSAAV components report by RPC too, and a passive component whose section in the
//! DSAAV configuration has a `Server` key is polled there with the health call (the others by the
//! bus command); control stations ask the service for the severity.

use crate::config_service::ConfigClient;
use crate::health::{ComponentState, Event, Mode, Monitor, Rules};
use crate::health_service::{self, Status};
use crate::rpc::{CallOptions, RpcClient};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Medium, MediumStats, Message, Topic, Value};
use seabus_medium_dsaav::wire::Address;
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use seabus_modules::runtime::{AbortOnDrop, MEDIA_TOPIC};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc;
use tokio::time::Instant;

/// The `health-monitor` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "health-monitor",
    kind: ModuleKind::Service,
    summary: "component health and vehicle severity from a rules file (DSAAV health monitor)",
    build,
};

const CHECK: TimerId = 1;
const PUBLISH: TimerId = 2;
/// How often timeouts, polls and links are looked at.
const CHECK_EVERY: Duration = Duration::from_millis(100);

struct HealthMonitor {
    rules: Option<Rules>,
    monitor: Option<Monitor>,
    poll_topic: Topic,
    /// The port index of the DSAAV medium and the service's port there.
    dsaav: Option<(usize, u16)>,
    /// The health service, while it runs.
    service: Option<Service>,
    /// The media that lost anything, by name, with their counters (from `seabus.media`).
    media: DataMap,
}

/// The DSAAV side: reports and poll answers arrive on `updates`; status calls are answered from
/// `status`; passive components are polled at `addresses`, once the configuration gave them.
struct Service {
    updates: mpsc::Receiver<(String, ComponentState)>,
    sender: mpsc::Sender<(String, ComponentState)>,
    status: Status,
    addresses: Arc<Mutex<HashMap<String, Address>>>,
    rpc: Arc<RpcClient>,
    /// The server and the configuration lookup, stopped with the module.
    _tasks: [AbortOnDrop; 2],
}

/// Reports and poll answers waiting for the monitor, at most.
const UPDATES: usize = 1024;

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let Some(file) = p.get("rules") else {
        return Err(cfg
            .pos
            .error("a health-monitor needs `rules`, its health rules file"));
    };
    let path = seabus_modules::system::beside(&cfg.pos, &file.value);
    if !path.exists() {
        return Err(file.error(format!("`{}` does not exist", path.display())));
    }
    let rules = Rules::load(&path)?;
    let dsaav = match p.get("dsaav") {
        None => None,
        Some(d) => {
            let Some(i) = cfg.media.iter().position(|m| m == d.value.trim()) else {
                return Err(d.error(format!(
                    "`{}` is not one of the module's media: {}",
                    d.value.trim(),
                    cfg.media.join(", ")
                )));
            };
            Some((i, p.parse("port", "a port 0–65535")?.unwrap_or(1)))
        }
    };
    let mut decl = Declaration::new(ModuleKind::Service)
        .consumes(TopicDecl::topic("seabus.module.*"))
        .consumes(TopicDecl::topic("seabus.health.*"))
        .consumes(TopicDecl::topic(MEDIA_TOPIC))
        .consumes(TopicDecl::topic(seabus_medium::topic::FLEET))
        .produces(TopicDecl::topic(rules.publish.as_str()));
    for c in &rules.components {
        if let Mode::Data { topics } = &c.mode {
            for t in topics {
                if !decl.consumes.iter().any(|d| d.topic == t.topic.as_str()) {
                    decl = decl.consumes(TopicDecl::topic(t.topic.as_str()));
                }
            }
        }
    }
    Ok(Built {
        decl,
        module: Box::new(HealthMonitor {
            rules: Some(rules),
            monitor: None,
            poll_topic: Topic::new("seabus.health.poll")
                .map_err(|e| cfg.pos.error(e.to_string()))?,
            dsaav,
            service: None,
            media: DataMap::new(),
        }),
    })
}

/// The media of a `seabus.media` message that lost or refused anything, with their counters.
fn media_with_losses(map: &DataMap) -> DataMap {
    let Some(media) = map.get("media").and_then(Value::as_map) else {
        return DataMap::new();
    };
    media
        .iter()
        .filter_map(|(name, counters)| {
            let counters = counters.as_map()?;
            MediumStats::from_map(counters)
                .has_losses()
                .then(|| (name.to_string(), Value::Map(counters.clone())))
        })
        .collect()
}

/// A node the fleet medium announced, as a component: online HEALTHY, gone OFFLINE.
fn fleet_member(map: &DataMap) -> Option<(String, ComponentState)> {
    let node = map.get_str("node")?;
    let state = match map.get_bool("online")? {
        true => ComponentState::Healthy,
        false => ComponentState::Offline,
    };
    Some((node.to_string(), state))
}

fn module_state(state: &str) -> Option<ComponentState> {
    match state {
        "running" => Some(ComponentState::Healthy),
        "failed" => Some(ComponentState::Malfunction),
        "stopped" => Some(ComponentState::Offline),
        _ => None,
    }
}

impl HealthMonitor {
    /// Acts on what the monitor said: a snapshot on state changes, the emergency action, polls.
    /// True when it published the snapshot.
    async fn act(&mut self, ctx: &mut Context, events: Vec<Event>) -> Result<bool, ModuleError> {
        let mut publish = false;
        for e in events {
            match e {
                Event::State {
                    component,
                    from,
                    to,
                    ..
                } => {
                    let why = self.monitor.as_ref().and_then(|m| m.reason(&component));
                    let why = why.map(|w| format!(": {w}")).unwrap_or_default();
                    tracing::info!(component = %component, "health {from} -> {to}{why}");
                    publish = true;
                }
                Event::Severity { from, to } => {
                    tracing::warn!("vehicle severity {} -> {}", from.name(), to.name());
                    publish = true;
                }
                Event::Emergency { action: Some(a) } => {
                    tracing::error!(topic = %a.topic, "emergency: sending the emergency action");
                    ctx.command(&a.topic, a.fields.clone()).await?;
                }
                Event::Emergency { action: None } => tracing::error!("vehicle in EMERGENCY"),
                Event::Poll { component } => {
                    let at = self.service.as_ref().and_then(|s| {
                        let known = s.addresses.lock().unwrap_or_else(|p| p.into_inner());
                        known.get(component.as_ref()).copied()
                    });
                    match (at, &self.service) {
                        (Some(at), Some(s)) => {
                            let (rpc, to) = (s.rpc.clone(), s.sender.clone());
                            let opts = poll_options(&self.monitor, &component);
                            tokio::spawn(async move {
                                if let Some(state) = health_service::poll(&rpc, at, opts).await {
                                    let _ = to.try_send((component.to_string(), state));
                                }
                            });
                        }
                        _ => {
                            let ask = DataMap::new().with("component", component.as_ref());
                            ctx.command(&self.poll_topic, ask).await?;
                        }
                    }
                }
            }
        }
        if publish {
            self.publish(ctx).await?;
        }
        Ok(publish)
    }

    /// Looks at the links, the DSAAV updates, the timeouts and the polls due now, and acts on
    /// what changed. True when it published the snapshot.
    async fn check(&mut self, ctx: &mut Context) -> Result<bool, ModuleError> {
        let Some(monitor) = self.monitor.as_mut() else {
            return Ok(false);
        };
        let now = Instant::now();
        let mut events = Vec::new();
        for i in 1..ctx.ports() {
            if let Some(port) = ctx.port(i) {
                let medium = port.medium();
                events.extend(monitor.link(medium.name(), &medium.link_state(), now));
            }
        }
        if let Some(service) = self.service.as_mut() {
            while let Ok((component, state)) = service.updates.try_recv() {
                events.extend(monitor.report(&component, state, now));
            }
        }
        events.extend(monitor.tick(now));
        if let Some(service) = &self.service {
            *service.status.lock().unwrap_or_else(|p| p.into_inner()) =
                health_service::status(monitor.severity(), monitor.components());
        }
        self.act(ctx, events).await
    }

    async fn publish(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        if let Some(m) = &self.monitor {
            let topic = m.rules().publish.clone();
            let mut snapshot = m.snapshot();
            if !self.media.is_empty() {
                snapshot.insert("media", self.media.clone());
            }
            ctx.publish(&topic, snapshot).await?;
        }
        Ok(())
    }
}

impl Service {
    /// Serves the health service on `port` of `medium` and looks up, through the configuration
    /// service, where the rules' passive components answer health calls.
    fn start(medium: &Medium, port: u16, rules: &Rules) -> Service {
        let (sender, updates) = mpsc::channel(UPDATES);
        let status: Status = Arc::default();
        let addresses: Arc<Mutex<HashMap<String, Address>>> = Arc::default();
        let server = {
            let (m, tx, st) = (medium.clone(), sender.clone(), status.clone());
            tokio::spawn(async move { health_service::serve(&m, port, tx, st).await })
        };
        let passive: Vec<String> = rules
            .components
            .iter()
            .filter(|c| matches!(c.mode, Mode::Passive { .. }))
            .map(|c| c.name.to_string())
            .collect();
        let lookup = {
            let (m, known) = (medium.clone(), addresses.clone());
            tokio::spawn(async move { find_passive(&m, port, passive, known).await })
        };
        Service {
            updates,
            sender,
            status,
            addresses,
            rpc: Arc::new(RpcClient::new(medium, port)),
            _tasks: [
                AbortOnDrop(server.abort_handle()),
                AbortOnDrop(lookup.abort_handle()),
            ],
        }
    }
}

/// Finds the configuration server (trying again until it answers) and asks it where each of
/// `passive` is served: its section's `Server` key. Components without one are polled on the bus.
async fn find_passive(
    medium: &Medium,
    port: u16,
    passive: Vec<String>,
    known: Arc<Mutex<HashMap<String, Address>>>,
) {
    if passive.is_empty() {
        return;
    }
    let opts = CallOptions::default();
    let cfg = loop {
        match ConfigClient::discover(medium, port, opts).await {
            Ok(c) => break c,
            Err(e) => tracing::debug!("health monitor: no configuration server yet: {e}"),
        }
    };
    for name in passive {
        match cfg.server_of(&name, &name).await {
            Ok(at) => {
                tracing::debug!(component = %name, "polled by DSAAV at {at}");
                known
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .insert(name, at);
            }
            Err(e) => tracing::debug!(component = %name, "polled on the bus: {e}"),
        }
    }
}

/// How a DSAAV poll of `component` waits: no longer than its poll period.
fn poll_options(monitor: &Option<Monitor>, component: &str) -> CallOptions {
    let poll = monitor
        .as_ref()
        .and_then(|m| m.rules().component(component))
        .and_then(|c| match c.mode {
            Mode::Passive { poll, .. } => Some(poll),
            _ => None,
        })
        .unwrap_or(Duration::from_secs(1));
    CallOptions {
        timeout: poll,
        first_retry: (poll / 8).max(Duration::from_millis(10)),
        max_retry: poll / 2,
    }
}

#[async_trait]
impl Module for HealthMonitor {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let rules = match self.rules.take() {
            Some(r) => r,
            None => match &self.monitor {
                // restarted: start again from the same rules
                Some(m) => m.rules().clone(),
                None => return Err(ModuleError::msg("no health rules")),
            },
        };
        ctx.every(PUBLISH, rules.period);
        ctx.every(CHECK, CHECK_EVERY);
        if let Some((i, port)) = self.dsaav {
            let Some(medium) = ctx.port(i).map(|p| p.medium().clone()) else {
                return Err(ModuleError::msg("the DSAAV medium has no port"));
            };
            self.service = Some(Service::start(&medium, port, &rules));
        }
        self.monitor = Some(Monitor::new(rules, Instant::now()));
        self.publish(ctx).await
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let topic = msg.topic.as_str();
        if port == 0
            && let Some(monitor) = self.monitor.as_mut()
        {
            let events = monitor.data(topic, Instant::now());
            if !events.is_empty() {
                self.act(ctx, events).await?;
                return Ok(());
            }
        }
        let Some(monitor) = self.monitor.as_mut() else {
            return Ok(());
        };
        let Some(map) = msg.payload.as_map() else {
            return Ok(());
        };
        if topic == MEDIA_TOPIC {
            // said in the next snapshot
            self.media = media_with_losses(map);
            return Ok(());
        }
        let report = if topic == seabus_medium::topic::FLEET {
            fleet_member(map)
        } else if let Some(module) = topic.strip_prefix("seabus.module.") {
            map.get_str("state")
                .and_then(module_state)
                .map(|s| (module.to_string(), s))
        } else if let Some(component) = topic.strip_prefix("seabus.health.") {
            let state = match map.get("state") {
                Some(v) => v
                    .as_str()
                    .and_then(|s| s.parse::<ComponentState>().ok())
                    .or_else(|| v.as_i64().and_then(ComponentState::from_code)),
                None => None,
            };
            state.map(|s| (component.to_string(), s))
        } else {
            None
        };
        if let Some((component, state)) = report {
            let events = monitor.report(&component, state, Instant::now());
            self.act(ctx, events).await?;
        }
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        // the snapshot published at the period measures the silences up to now
        let published = self.check(ctx).await?;
        if timer == PUBLISH && !published {
            self.publish(ctx).await?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_media_with_losses_are_listed_with_their_counters() {
        let lossy = MediumStats {
            received: 40,
            queue_dropped: [("gps".to_string(), 12)].into(),
            ..MediumStats::default()
        };
        let rejecting = MediumStats {
            rejected: [("garbage".to_string(), 2)].into(),
            dropped_bytes: 9,
            ..MediumStats::default()
        };
        let quiet = MediumStats {
            received: 1000,
            published: 10,
            ..MediumStats::default()
        };
        let published = seabus_modules::runtime::media_map([
            ("bus", &quiet),
            ("gps-line", &lossy),
            ("serial", &rejecting),
        ]);
        let listed = media_with_losses(&published);
        let names: Vec<&str> = listed.iter().map(|(k, _)| k).collect();
        assert_eq!(names, ["gps-line", "serial"]);
        let back = MediumStats::from_map(listed.get("gps-line").unwrap().as_map().unwrap());
        assert_eq!(back, lossy);
        assert!(media_with_losses(&DataMap::new()).is_empty());
    }

    #[test]
    fn module_states_map_to_component_states() {
        assert_eq!(module_state("running"), Some(ComponentState::Healthy));
        assert_eq!(module_state("failed"), Some(ComponentState::Malfunction));
        assert_eq!(module_state("stopped"), Some(ComponentState::Offline));
        assert_eq!(module_state("starting"), None);
    }
}
