//! `dsaav-sentuators`: joins a seabus bus to DSAAV sentuators (`media="bus dsaav"`).
//!
//! - Sentuator notifications sent to its `port` on the DSAAV medium become standard datasets on the
//!   bus, by quantity: depth → `nav.depth`, heading → `nav.heading`, altitude → `nav.altitude`,
//!   position → `nav.position` (others are counted and dropped).
//! - Actuator commands on the bus (`cmd.actuator`: `elevator`, `rudder`, `thrust`) become `set`
//!   calls to the sentuators its parameters `elevators`, `rudder` and `thruster` name (`NODE:PORT`).
//!
//! Register it as a listener of the sensors in the DSAAV configuration (`Listeners = 6:1`).

use super::rpc::CallOptions;
use super::sentuator::{SentuatorClient, ops, quantity};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Kind, Message};
use seabus_medium_dsaav::wire::Address;
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};

/// The `dsaav-sentuators` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "dsaav-sentuators",
    kind: ModuleKind::Bridge,
    summary: "sentuator notifications to datasets, actuator commands to sentuator set calls",
    build,
};

/// The dataset a notification of `quantity` becomes: name, topic and the fields it carries.
fn dataset_of(q: i64) -> Option<(&'static str, &'static str, &'static [&'static str])> {
    match q {
        quantity::DEPTH => Some(("depth", "nav.depth", &["depth"])),
        quantity::HEADING => Some(("heading", "nav.heading", &["heading"])),
        quantity::ALTITUDE => Some(("altitude", "nav.altitude", &["altitude"])),
        quantity::POSITION => Some(("position", "nav.position", &["lat", "lon"])),
        _ => None,
    }
}

struct Bridge {
    port: u16,
    actuators: Vec<(&'static str, Address)>,
    client: Option<SentuatorClient>,
    dropped: u64,
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let port: u16 = p.parse("port", "a port 0–65535")?.unwrap_or(1);
    let mut actuators = Vec::new();
    for (param, field) in [
        ("elevators", "elevator"),
        ("rudder", "rudder"),
        ("thruster", "thrust"),
    ] {
        if let Some(a) = p.get(param) {
            let at: Address = a
                .value
                .trim()
                .parse()
                .map_err(|e: seabus_medium_dsaav::wire::AddressError| a.error(e.to_string()))?;
            actuators.push((field, at));
        }
    }
    let mut decl = Declaration::new(ModuleKind::Bridge)
        .consumes(TopicDecl::topic("dsaav.rpc-oneway").on_port(1))
        .accepts(TopicDecl::dataset("cmd.actuator", "actuator-command"));
    for q in [
        quantity::DEPTH,
        quantity::HEADING,
        quantity::ALTITUDE,
        quantity::POSITION,
    ] {
        if let Some((dataset, topic, _)) = dataset_of(q) {
            decl = decl.produces(TopicDecl::dataset(topic, dataset));
        }
    }
    Ok(Built {
        decl,
        module: Box::new(Bridge {
            port,
            actuators,
            client: None,
            dropped: 0,
        }),
    })
}

impl Bridge {
    async fn notification(&mut self, ctx: &mut Context, map: &DataMap) -> Result<(), ModuleError> {
        let to_me = map
            .get_str("@dst")
            .and_then(|d| d.parse::<Address>().ok())
            .is_some_and(|a| a.port == self.port);
        if !to_me || map.get_i64("op") != Some(i64::from(ops::NOTIFY)) {
            return Ok(());
        }
        let Some((dataset, topic, fields)) = map.get_i64("quantity").and_then(dataset_of) else {
            self.dropped += 1;
            return Ok(());
        };
        let mut out = DataMap::with_capacity(fields.len());
        for f in fields {
            match map.get(f) {
                Some(v) => out.push(*f, v.clone()),
                None => {
                    self.dropped += 1;
                    return Ok(());
                }
            }
        }
        ctx.publish_dataset(dataset, topic, out).await
    }

    async fn command(&mut self, map: &DataMap) {
        let Some(client) = &self.client else {
            return;
        };
        for (field, at) in &self.actuators {
            if let Some(v) = map.get_f64(field) {
                let set = DataMap::new().with(*field, v);
                if let Err(e) = client.set(*at, &set).await {
                    tracing::warn!("{field} → {at}: {e}");
                }
            }
        }
    }
}

#[async_trait]
impl Module for Bridge {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let Some(medium) = ctx.port(1).map(|p| p.medium().clone()) else {
            return Err(ModuleError::msg(
                "dsaav-sentuators needs two media: the bus, then the DSAAV medium",
            ));
        };
        // its own port for calls, next to the one notifications come to
        self.client = Some(SentuatorClient::new(
            &medium,
            self.port.wrapping_add(1),
            CallOptions::default(),
        ));
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(map) = msg.payload.as_map() else {
            return Ok(());
        };
        match (port, msg.kind) {
            (1, Kind::Data) => self.notification(ctx, map).await,
            (0, Kind::Command) => {
                self.command(map).await;
                Ok(())
            }
            _ => Ok(()),
        }
    }
}
