//! `square`: an example helm that drives a vehicle around a square with course commands.
//!
//! It commands a heading, depth and speed on `cmd.course` at its tick rate (the stream is the
//! vehicle's keep-alive), and turns 90° once the vehicle has covered `side` metres on the current
//! leg, measured from `nav.position`. Parameters: `side` (m, default 100), `speed` (m/s, 1.5),
//! `depth` (m, 0), `heading` (first leg, deg, 0), `turn` (`right` or `left`), `timeout` (s, the
//! course command's validity, 5), `yield_to` (a topic whose `holder` field, when not empty, names
//! someone else in control — the console's `console.control` by default; empty: never yields).
//!
//! While someone holds control it sends nothing; when they release it, it starts a new leg where
//! the vehicle is.

use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Topic};
use seabus_modules::datasets::Catalogue;
use seabus_modules::geo::{distance, wrap360};
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::time::Duration;

/// The `square` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "square",
    kind: ModuleKind::Supporting,
    summary: "drives a vehicle around a square with course commands",
    build,
};

struct Square {
    side: f64,
    speed: f64,
    depth: f64,
    heading: f64,
    turn: f64,
    timeout: f64,
    leg_start: Option<(f64, f64)>,
    legs: i64,
    course_topic: Topic,
    /// The topic naming who else is in control, if it yields.
    yield_to: Option<Topic>,
    /// Who holds control now, when someone does.
    held_by: Option<String>,
}

fn build(cfg: &ModuleConfig, cat: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let side = p.positive_or("side", 100.0)?;
    let speed = p.non_negative_or("speed", 1.5)?;
    let depth = p.float_or("depth", 0.0)?;
    let timeout = p.positive_or("timeout", 5.0)?;
    let turn = match p.str("turn").map(str::trim) {
        None | Some("right") => 90.0,
        Some("left") => -90.0,
        Some(_) => return Err(p.required("turn")?.error("expected right or left")),
    };
    let course_topic = p.dataset_topic(cat, "course-command", "cmd.course")?;
    let yield_to = match p.str("yield_to").map(str::trim) {
        Some("") => None,
        _ => Some(p.topic_or("yield_to", "console.control")?),
    };
    let mut decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::dataset(
            cat.topic_of("position", "nav.position"),
            "position",
        ))
        .produces(TopicDecl::dataset(&course_topic, "course-command"))
        .default_tick(Duration::from_secs(1));
    if let Some(t) = &yield_to {
        decl = decl.consumes(TopicDecl::topic(t.as_str()).field("holder", ""));
    }
    Ok(Built {
        decl,
        module: Box::new(Square {
            side,
            speed,
            depth,
            heading: wrap360(p.float_or("heading", 0.0)?),
            turn,
            timeout,
            leg_start: None,
            legs: 0,
            course_topic,
            yield_to,
            held_by: None,
        }),
    })
}

impl Square {
    fn command(&self) -> DataMap {
        DataMap::new()
            .with("heading", self.heading)
            .with("depth", self.depth)
            .with("speed", self.speed)
            .with("timeout", self.timeout)
    }
}

#[async_trait]
impl Module for Square {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(pos) = msg.payload.as_map() else {
            return Ok(());
        };
        if self.yield_to.as_ref() == Some(&msg.topic) {
            let holder = pos
                .get("holder")
                .and_then(seabus_medium::Value::as_str)
                .filter(|h| !h.is_empty())
                .map(str::to_string);
            if holder != self.held_by {
                match &holder {
                    Some(h) => tracing::info!(module = ctx.name(), "{h} has control: pausing"),
                    None => {
                        tracing::info!(module = ctx.name(), "control released: a new leg");
                        self.leg_start = None;
                    }
                }
                self.held_by = holder;
            }
            return Ok(());
        }
        if self.held_by.is_some() {
            return Ok(());
        }
        let (Some(lat), Some(lon)) = (pos.get_f64("lat"), pos.get_f64("lon")) else {
            return Ok(());
        };
        match self.leg_start {
            None => self.leg_start = Some((lat, lon)),
            Some((lat0, lon0)) if distance(lat0, lon0, lat, lon) >= self.side => {
                self.heading = wrap360(self.heading + self.turn);
                self.legs += 1;
                self.leg_start = Some((lat, lon));
                tracing::info!(
                    module = ctx.name(),
                    leg = self.legs,
                    heading = self.heading,
                    "next leg"
                );
                ctx.command_dataset("course-command", &self.course_topic, self.command())
                    .await?;
            }
            Some(_) => {}
        }
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        if self.held_by.is_some() {
            return Ok(());
        }
        ctx.command_dataset("course-command", &self.course_topic, self.command())
            .await
    }
}
