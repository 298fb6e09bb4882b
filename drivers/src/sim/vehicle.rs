//! `vehicle-sim`: a simulated vehicle that follows course commands and publishes its navigation,
//! battery and state as standard datasets.
//!
//! It accepts `cmd.course` (heading, depth, speed; valid for the command's `timeout`, or the
//! `timeout` parameter) and `cmd.mission` (`stop` ends the current course). Without a valid course
//! it stops and surfaces, as a frontseat does when its backseat falls silent. Each command is
//! answered on `cmd.status` (`acknowledged`, or `refused` with the reason), with its origin and
//! sequence number, as a driver answers a console. It publishes
//! `nav.attitude`, `nav.position`, `nav.depth`, `nav.altitude` and `nav.velocity` every tick, and
//! `power.battery` and `vehicle.state` once a second.
//!
//! Parameters: `lat`, `lon`, `heading` (start), `water_depth` (m, 40), `battery` (Wh, 600),
//! `timeout` (s, 5), `turn_rate` (deg/s, 10), `dive_rate` (m/s, 0.3), `accel` (m/s², 0.2),
//! `max_speed` (m/s, 2.5).

use super::kinematics::{Limits, Setpoint, Vehicle};
use crate::command_status::{self, DATASET, command_status};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Kind, Message, Topic, Value};
use seabus_modules::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::time::Duration;
use tokio::time::Instant;

/// The `vehicle-sim` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "vehicle-sim",
    kind: ModuleKind::Driver,
    summary: "a simulated vehicle following course commands",
    build,
};

const SLOW: TimerId = 1;

/// The topics the simulator uses, taken from the dataset catalogue.
struct Topics {
    attitude: Topic,
    position: Topic,
    depth: Topic,
    altitude: Topic,
    velocity: Topic,
    battery: Topic,
    state: Topic,
    course: Topic,
    mission: Topic,
    status: Topic,
}

struct Sim {
    vehicle: Vehicle,
    limits: Limits,
    water_depth: f64,
    default_timeout: Duration,
    course: Option<(Setpoint, Instant)>,
    last_step: Option<Instant>,
    topics: Topics,
    tally: Tally,
}

fn build(cfg: &ModuleConfig, cat: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let lat = p.float_or("lat", 43.5)?;
    let lon = p.float_or("lon", 16.4)?;
    if !(-90.0..=90.0).contains(&lat) {
        return Err(p.required("lat")?.error("must be within ±90"));
    }
    let limits = Limits {
        turn_rate: p.positive_or("turn_rate", 10.0)?,
        dive_rate: p.positive_or("dive_rate", 0.3)?,
        accel: p.positive_or("accel", 0.2)?,
        max_speed: p.positive_or("max_speed", 2.5)?,
        max_depth: p.positive_or("max_depth", 100.0)?,
    };
    let topic = |dataset: &str, fallback: &str| p.dataset_topic(cat, dataset, fallback);
    let topics = Topics {
        attitude: topic("attitude", "nav.attitude")?,
        position: topic("position", "nav.position")?,
        depth: topic("depth", "nav.depth")?,
        altitude: topic("altitude", "nav.altitude")?,
        velocity: topic("velocity", "nav.velocity")?,
        battery: topic("battery", "power.battery")?,
        state: topic("vehicle-state", "vehicle.state")?,
        course: topic("course-command", "cmd.course")?,
        mission: topic("mission-command", "cmd.mission")?,
        status: topic(DATASET, "cmd.status")?,
    };
    let decl = Declaration::new(ModuleKind::Driver)
        .produces(TopicDecl::dataset(&topics.attitude, "attitude"))
        .produces(TopicDecl::dataset(&topics.position, "position"))
        .produces(TopicDecl::dataset(&topics.depth, "depth"))
        .produces(TopicDecl::dataset(&topics.altitude, "altitude"))
        .produces(TopicDecl::dataset(&topics.velocity, "velocity"))
        .produces(TopicDecl::dataset(&topics.battery, "battery"))
        .produces(TopicDecl::dataset(&topics.state, "vehicle-state"))
        .produces(TopicDecl::dataset(&topics.status, DATASET))
        .accepts(TopicDecl::dataset(&topics.course, "course-command"))
        .accepts(TopicDecl::dataset(&topics.mission, "mission-command"))
        .default_tick(Duration::from_millis(100));
    Ok(Built {
        decl,
        module: Box::new(Sim {
            vehicle: Vehicle::at(
                lat,
                lon,
                p.float_or("heading", 0.0)?,
                p.positive_or("battery", 600.0)?,
            ),
            limits,
            water_depth: p.non_negative_or("water_depth", 40.0)?,
            default_timeout: p.duration_or("timeout", Duration::from_secs(5))?,
            course: None,
            last_step: None,
            topics,
            tally: Tally::new(),
        }),
    })
}

impl Sim {
    /// Answers command `msg` on `cmd.status`: acknowledged, or refused with the reason.
    async fn answer(&self, ctx: &Context, msg: &Message, command: &str, done: Result<(), &str>) {
        let (state, error) = match done {
            Ok(()) => ("acknowledged", ""),
            Err(why) => ("refused", why),
        };
        let request = command_status::request(msg);
        let status = command_status(command, state, None, Some(error), Some(&request));
        if let Err(e) = ctx
            .dataset_on(0, Kind::Data, DATASET, &self.topics.status, status)
            .await
        {
            self.tally.record(ctx.name(), "status", &e);
        }
    }

    fn active(&self, now: Instant) -> Option<Setpoint> {
        self.course
            .filter(|(_, until)| now < *until)
            .map(|(sp, _)| sp)
    }

    async fn publish_nav(&self, ctx: &Context) -> Result<(), ModuleError> {
        let v = &self.vehicle;
        let h = v.heading.to_radians();
        ctx.publish_dataset(
            "attitude",
            &self.topics.attitude,
            DataMap::new()
                .with("yaw", v.heading)
                .with("pitch", v.pitch)
                .with("roll", v.roll)
                .with("yaw_rate", v.yaw_rate),
        )
        .await?;
        ctx.publish_dataset(
            "position",
            &self.topics.position,
            DataMap::new()
                .with("lat", v.lat)
                .with("lon", v.lon)
                .with("fix", if v.depth < 0.5 { 1i64 } else { 6 })
                .with(
                    "source",
                    if v.depth < 0.5 {
                        "gps"
                    } else {
                        "dead-reckoning"
                    },
                ),
        )
        .await?;
        ctx.publish_dataset(
            "depth",
            &self.topics.depth,
            DataMap::new()
                .with("depth", v.depth)
                .with("vertical_speed", v.vertical_speed),
        )
        .await?;
        ctx.publish_dataset(
            "altitude",
            &self.topics.altitude,
            DataMap::new()
                .with("altitude", (self.water_depth - v.depth).max(0.0))
                .with("water_depth", self.water_depth),
        )
        .await?;
        ctx.publish_dataset(
            "velocity",
            &self.topics.velocity,
            DataMap::new()
                .with("speed", v.speed)
                .with("course", v.heading)
                .with("north", v.speed * h.cos())
                .with("east", v.speed * h.sin())
                .with("down", v.vertical_speed)
                .with("reference", Value::label("water")),
        )
        .await
    }

    async fn publish_slow(&self, ctx: &Context) -> Result<(), ModuleError> {
        let v = &self.vehicle;
        ctx.publish_dataset(
            "battery",
            &self.topics.battery,
            DataMap::new()
                .with("percent", v.percent())
                .with("remaining", v.energy)
                .with("power", v.power())
                .with("state", Value::label("discharging")),
        )
        .await?;
        let mut state = DataMap::new();
        match self.active(Instant::now()) {
            Some(sp) => {
                state.insert("mode", Value::label("following"));
                state.insert("control", Value::label("in-control"));
                state.insert("commanded_heading", sp.heading);
                state.insert("commanded_depth", sp.depth);
                state.insert("commanded_speed", sp.speed);
            }
            None => {
                state.insert("mode", Value::label("idle"));
                state.insert("control", Value::label("accepting"));
            }
        }
        state.insert("error", Value::label(""));
        ctx.publish_dataset("vehicle-state", &self.topics.state, state)
            .await
    }
}

#[async_trait]
impl Module for Sim {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        ctx.every(SLOW, Duration::from_secs(1));
        self.last_step = Some(Instant::now());
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(map) = msg.payload.as_map() else {
            return Ok(());
        };
        if *msg.topic == *self.topics.course {
            if let Err(e) = ctx.catalogue().validate("course-command", map) {
                self.tally.record(
                    ctx.name(),
                    "refused",
                    format_args!("course command from {} refused: {e}", msg.provenance.origin),
                );
                self.answer(ctx, &msg, "course", Err(&e.to_string())).await;
                return Ok(());
            }
            let sp = Setpoint {
                heading: map.get_f64("heading").unwrap_or(0.0),
                depth: map.get_f64("depth").unwrap_or(0.0),
                speed: map.get_f64("speed").unwrap_or(0.0),
            };
            let timeout = map
                .get_f64("timeout")
                .filter(|t| t.is_finite() && *t > 0.0)
                .map_or(self.default_timeout, |t| {
                    seabus_medium::parse::secs(t.min(3600.0)).unwrap_or(self.default_timeout)
                });
            self.course = Some((sp, Instant::now() + timeout));
            self.answer(ctx, &msg, "course", Ok(())).await;
        } else if *msg.topic == *self.topics.mission {
            match map.get_str("action") {
                Some("stop") => {
                    self.course = None;
                    self.answer(ctx, &msg, "mission", Ok(())).await;
                }
                other => {
                    let why = format!("mission action {other:?}: only stop is simulated");
                    self.answer(ctx, &msg, "mission", Err(&why)).await;
                }
            }
        }
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        if timer == SLOW {
            return self.publish_slow(ctx).await;
        }
        let now = Instant::now();
        let dt = self
            .last_step
            .map_or(0.1, |t| now.duration_since(t).as_secs_f64())
            .min(1.0);
        self.last_step = Some(now);
        let target = self.active(now);
        self.vehicle.step(dt, target, &self.limits);
        self.publish_nav(ctx).await
    }
}
