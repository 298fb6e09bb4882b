//! `can-device`: a CAN device described by a CAN database, integrated without code.
//!
//! ```xml
//! <medium name="can" url="slcan:///dev/ttyACM0?bitrate=500000"/>
//! <module name="thruster" type="can-device" media="can bus" dbc="can/vehicle.dbc" node="SEABUS"/>
//! ```
//!
//! Its first medium is the CAN medium, its second the bus. Each frame of a message the database
//! names is decoded ([`super::dbc`]) and published on the bus as `PREFIX.MessageName`
//! (`thruster.ThrusterStatus`), a datamap of its signals' physical values (units in the module's
//! declaration). A command on `PREFIX.MessageName` for a message it may send is encoded and sent
//! as a frame; each command's fate is published on `cmd.status` (`sent`, or `refused` with the
//! reason: a signal out of its range, an unknown signal, a link that is down).
//!
//! Parameters: `dbc` (the database, relative to the system file), `prefix` (the topics' first
//! part; default the module's name), `node` (the database node seabus plays: commands are taken
//! for the messages it sends, the others are published; without it, every message is both),
//! `messages` (names of the messages it handles, comma-separated; default all). Frames shorter than
//! their message are counted and dropped.

use super::dbc::{Database, MessageDef};
use crate::command_status::{self, command_status};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{Format, Kind, Message, Topic};
use seabus_medium_can::frame::{CanFrame, FrameKind};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::collections::HashMap;
use std::sync::Arc;

/// The `can-device` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "can-device",
    kind: ModuleKind::Driver,
    summary: "a CAN device described by a DBC file: its messages as topics, commands as frames",
    build,
};

/// The topic of command status reports.
const STATUS: &str = "cmd.status";

struct CanDevice {
    db: Arc<Database>,
    /// Published messages, by (identifier, extended): their index and topic.
    published: HashMap<(u32, bool), (usize, Topic)>,
    /// Messages taken as commands, by topic: their index.
    commands: HashMap<String, usize>,
    tally: Tally,
    next_id: i64,
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let Some(file) = p.get("dbc") else {
        return Err(cfg
            .pos
            .error("a can-device needs `dbc`, its CAN database file"));
    };
    let path = seabus_modules::system::beside(&cfg.pos, &file.value);
    if !path.exists() {
        return Err(file.error(format!("`{}` does not exist", path.display())));
    }
    let db = Database::load(&path)?;
    if cfg.media.len() != 2 {
        return Err(cfg.pos.error(
            "a can-device is on two media: the CAN medium, then the bus (media=\"can bus\")",
        ));
    }
    let prefix = p.str("prefix").unwrap_or(&cfg.name).to_string();
    let node = p.str("node");
    if let Some(n) = node
        && !db.messages.iter().any(|m| m.senders.iter().any(|s| s == n))
    {
        return Err(p.get("node").map_or_else(
            || cfg.pos.error("no message"),
            |a| {
                a.error(format!(
                    "no message of {} is sent by node `{n}`",
                    path.display()
                ))
            },
        ));
    }
    let wanted: Option<Vec<String>> = p.str("messages").map(|m| {
        m.split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect()
    });
    if let (Some(w), Some(attr)) = (&wanted, p.get("messages"))
        && let Some(bad) = w.iter().find(|n| db.by_name(n).is_none())
    {
        return Err(attr.error(format!("`{bad}` is not a message of {}", path.display())));
    }
    let topic_of = |m: &MessageDef| -> Result<Topic, FileError> {
        Topic::new(&format!("{prefix}.{}", m.name)).map_err(|e| {
            cfg.pos
                .error(format!("message `{}` gives no topic: {e}", m.name))
        })
    };
    let mut decl = Declaration::new(ModuleKind::Driver)
        .format(0, Some(Format::Map))
        .consumes(TopicDecl::topic("can.**"))
        .format(1, Some(Format::Map))
        .produces(TopicDecl::dataset(STATUS, command_status::DATASET).on_port(1));
    let mut published = HashMap::new();
    let mut commands = HashMap::new();
    for (i, m) in db.messages.iter().enumerate() {
        let topic = topic_of(m)?;
        let fields = |mut t: TopicDecl| {
            for s in &m.signals {
                t = t.field(&s.name, &s.unit);
            }
            t.on_port(1)
        };
        if wanted.as_ref().is_some_and(|w| !w.contains(&m.name)) {
            continue;
        }
        let ours = node.map(|n| m.senders.iter().any(|s| s == n));
        if ours != Some(false) {
            decl = decl.accepts(fields(TopicDecl::topic(topic.as_str())));
            commands.insert(topic.as_str().to_string(), i);
        }
        if ours != Some(true) {
            decl = decl.produces(fields(TopicDecl::topic(topic.as_str())));
            published.insert((m.id, m.extended), (i, topic));
        }
    }
    Ok(Built {
        decl,
        module: Box::new(CanDevice {
            db: Arc::new(db),
            published,
            commands,
            tally: Tally::new(),
            next_id: 1,
        }),
    })
}

impl CanDevice {
    async fn on_frame(&mut self, ctx: &mut Context, msg: &Message) -> Result<(), ModuleError> {
        let Ok(frame) = CanFrame::from_message(msg.topic.as_str(), &msg.payload) else {
            return Ok(());
        };
        if frame.kind() != FrameKind::Data {
            return Ok(());
        }
        let Some((i, topic)) = self.published.get(&(frame.id(), frame.is_extended())) else {
            return Ok(());
        };
        let def = &self.db.messages[*i];
        if frame.payload().len() < def.size {
            self.tally.record(
                ctx.name(),
                "short-frame",
                format_args!(
                    "{def}: {} bytes, the database says {}",
                    frame.payload().len(),
                    def.size
                ),
            );
            return Ok(());
        }
        let map = def.decode(frame.payload());
        ctx.publish_on(1, Kind::Data, topic.clone(), map).await?;
        Ok(())
    }

    async fn command(&mut self, ctx: &mut Context, msg: &Message) -> Result<(), ModuleError> {
        let Some(&i) = self.commands.get(msg.topic.as_str()) else {
            return Ok(());
        };
        let def = &self.db.messages[i];
        let id = self.next_id;
        self.next_id += 1;
        let values = msg.payload.to_map().unwrap_or_default();
        let sent = match def.encode(&values) {
            Ok(data) => {
                let frame = if data.len() > 8 {
                    CanFrame::fd(def.id, def.extended, &data, true, false)
                } else {
                    CanFrame::data(def.id, def.extended, &data)
                }
                .map_err(|e| e.to_string());
                match frame {
                    Ok(f) => ctx
                        .publish_on(0, Kind::Data, f.topic(), f.to_map(None))
                        .await
                        .map_err(|e| e.to_string()),
                    Err(e) => Err(e),
                }
            }
            Err(e) => Err(e.to_string()),
        };
        let (state, error) = match &sent {
            Ok(()) => ("sent", None),
            Err(why) => {
                self.tally.record(
                    ctx.name(),
                    "refused",
                    format_args!("{} refused: {why}", def.name),
                );
                ("refused", Some(why.as_str()))
            }
        };
        let request = command_status::request(msg);
        let status = command_status(&def.name, state, Some(id), error, Some(&request));
        ctx.publish_on(1, Kind::Data, STATUS, status).await?;
        Ok(())
    }
}

#[async_trait]
impl Module for CanDevice {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        if port == 0 {
            self.on_frame(ctx, &msg).await
        } else if msg.kind == Kind::Command {
            self.command(ctx, &msg).await
        } else {
            Ok(())
        }
    }
}
