//! `square`: an example helm that drives a vehicle around a square with course commands.
//!
//! It commands a heading, depth and speed on `cmd.course` at its tick rate (the stream is the
//! vehicle's keep-alive), and turns 90° once the vehicle has covered `side` metres on the current
//! leg, measured from `nav.position`. Parameters: `side` (m, default 100), `speed` (m/s, 1.5),
//! `depth` (m, 0), `heading` (first leg, deg, 0), `turn` (`right` or `left`), `timeout` (s, the
//! course command's validity, 5).

use crate::datasets::Catalogue;
use crate::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TICK, TimerId, TopicDecl,
};
use crate::registry::{Built, ModuleConfig, ModuleType};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message};
use std::time::Duration;

/// The `square` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "square",
    kind: ModuleKind::Supporting,
    summary: "drives a vehicle around a square with course commands",
    build,
};

/// Metres per degree of latitude.
pub const METRES_PER_DEG: f64 = 111_320.0;

/// Distance in metres between two positions (equirectangular: fine over a few kilometres).
pub fn distance(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> f64 {
    let north = (lat2 - lat1) * METRES_PER_DEG;
    let east = (lon2 - lon1) * METRES_PER_DEG * ((lat1 + lat2) / 2.0).to_radians().cos();
    north.hypot(east)
}

struct Square {
    side: f64,
    speed: f64,
    depth: f64,
    heading: f64,
    turn: f64,
    timeout: f64,
    leg_start: Option<(f64, f64)>,
    legs: i64,
    tick: Option<Duration>,
}

fn build(cfg: &ModuleConfig, cat: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let side = p.float_or("side", 100.0)?;
    if side <= 0.0 {
        return Err(p.required("side")?.error("must be above zero"));
    }
    let turn = match p.str("turn").map(str::trim) {
        None | Some("right") => 90.0,
        Some("left") => -90.0,
        Some(_) => return Err(p.required("turn")?.error("expected right or left")),
    };
    let course = cat
        .get("course-command")
        .map_or("cmd.course", |d| d.topic.as_str());
    let position = cat
        .get("position")
        .map_or("nav.position", |d| d.topic.as_str());
    let decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::dataset(position, "position"))
        .produces(TopicDecl::dataset(course, "course-command"));
    Ok(Built {
        decl,
        module: Box::new(Square {
            side,
            speed: p.float_or("speed", 1.5)?,
            depth: p.float_or("depth", 0.0)?,
            heading: p.float_or("heading", 0.0)?.rem_euclid(360.0),
            turn,
            timeout: p.float_or("timeout", 5.0)?,
            leg_start: None,
            legs: 0,
            tick: cfg.tick,
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
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        if self.tick.is_none() {
            ctx.every(TICK, Duration::from_secs(1));
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(pos) = msg.payload.as_map() else {
            return Ok(());
        };
        let (Some(lat), Some(lon)) = (pos.get_f64("lat"), pos.get_f64("lon")) else {
            return Ok(());
        };
        match self.leg_start {
            None => self.leg_start = Some((lat, lon)),
            Some((lat0, lon0)) if distance(lat0, lon0, lat, lon) >= self.side => {
                self.heading = (self.heading + self.turn).rem_euclid(360.0);
                self.legs += 1;
                self.leg_start = Some((lat, lon));
                tracing::info!(
                    module = ctx.name(),
                    leg = self.legs,
                    heading = self.heading,
                    "next leg"
                );
                ctx.command_dataset("course-command", "cmd.course", self.command())
                    .await?;
            }
            Some(_) => {}
        }
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        ctx.command_dataset("course-command", "cmd.course", self.command())
            .await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_is_metres() {
        assert!((distance(0.0, 0.0, 0.001, 0.0) - 111.32).abs() < 1e-6);
        let d = distance(60.0, 10.0, 60.0, 10.002);
        assert!((d - 111.32).abs() < 0.5, "{d}");
    }
}
