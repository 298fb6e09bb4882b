//! `health-monitor`: the health monitor as a module, watching every module and medium of the
//! system by the rules of a health rules file ([`crate::dsaav::health`]).
//!
//! Parameters: `rules` (the rules file, relative to the system file). Its first medium is the bus:
//! it reads there
//! - `seabus.module.<NAME>` — the runtime's module states: running → HEALTHY, failed → MALFUNCTION,
//!   stopped → OFFLINE, for a rules component called like the module;
//! - `seabus.health.<COMPONENT>` — reports a component sends itself (`state` = HEALTHY,
//!   UNAVAILABLE, MALFUNCTION or OFFLINE, or its number): active components send them regularly,
//!   passive ones answer the command `seabus.health.poll` (`component` = its name);
//!
//! and publishes the health snapshot (`severity`, `components`) on the rules' topic at their
//! period and at once on every change of severity, and the emergency action as a command on entry
//! into EMERGENCY. Its other media are watched for `link` components: a link that goes down makes
//! the component OFFLINE (a serial driver whose device is unplugged).

use crate::datasets::Catalogue;
use crate::dsaav::health::{ComponentState, Event, Monitor, Rules};
use crate::module::{Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl};
use crate::registry::{Built, ModuleConfig, ModuleType};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Topic};
use std::time::Duration;
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
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let Some(file) = p.get("rules") else {
        return Err(cfg
            .pos
            .error("a health-monitor needs `rules`, its health rules file"));
    };
    let path = crate::system::beside(&cfg.pos, &file.value);
    if !path.exists() {
        return Err(file.error(format!("`{}` does not exist", path.display())));
    }
    let rules = Rules::load(&path)?;
    let decl = Declaration::new(ModuleKind::Service)
        .consumes(TopicDecl::topic("seabus.module.*"))
        .consumes(TopicDecl::topic("seabus.health.*"))
        .produces(TopicDecl::topic(rules.publish.as_str()));
    Ok(Built {
        decl,
        module: Box::new(HealthMonitor {
            rules: Some(rules),
            monitor: None,
            poll_topic: Topic::new("seabus.health.poll")
                .map_err(|e| cfg.pos.error(e.to_string()))?,
        }),
    })
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
    /// Acts on what the monitor said: snapshots on severity changes, the emergency action, polls.
    async fn act(&mut self, ctx: &mut Context, events: Vec<Event>) -> Result<(), ModuleError> {
        let mut publish = false;
        for e in events {
            match e {
                Event::State {
                    component,
                    from,
                    to,
                    ..
                } => tracing::info!(component = %component, "health {from} -> {to}"),
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
                    let ask = DataMap::new().with("component", component.as_ref());
                    ctx.command(&self.poll_topic, ask).await?;
                }
            }
        }
        if publish {
            self.publish(ctx).await?;
        }
        Ok(())
    }

    async fn publish(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        if let Some(m) = &self.monitor {
            let topic = m.rules().publish.clone();
            ctx.publish(&topic, m.snapshot()).await?;
        }
        Ok(())
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
        self.monitor = Some(Monitor::new(rules, Instant::now()));
        self.publish(ctx).await
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(monitor) = self.monitor.as_mut() else {
            return Ok(());
        };
        let Some(map) = msg.payload.as_map() else {
            return Ok(());
        };
        let topic = msg.topic.as_str();
        let report = if let Some(module) = topic.strip_prefix("seabus.module.") {
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
        if timer == PUBLISH {
            return self.publish(ctx).await;
        }
        let Some(monitor) = self.monitor.as_mut() else {
            return Ok(());
        };
        let now = Instant::now();
        let mut events = Vec::new();
        for i in 1..ctx.ports() {
            if let Some(port) = ctx.port(i) {
                let medium = port.medium();
                events.extend(monitor.link(medium.name(), &medium.link_state(), now));
            }
        }
        events.extend(monitor.tick(now));
        self.act(ctx, events).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn module_states_map_to_component_states() {
        assert_eq!(module_state("running"), Some(ComponentState::Healthy));
        assert_eq!(module_state("failed"), Some(ComponentState::Malfunction));
        assert_eq!(module_state("stopped"), Some(ComponentState::Offline));
        assert_eq!(module_state("starting"), None);
    }
}
