//! Navigation supporting modules built on [`crate::estimate`]; each keeps the raw topics and
//! publishes its estimate on a topic of its own.
//!
//! - `depth-kalman`: reads the depth dataset (`input`, default `nav.depth`) and publishes depth
//!   and vertical speed (`output`, default `nav.depth.filtered`). Parameters: `sigma` (the
//!   readings' noise, m, default 0.2) and `accel` (the vehicle's vertical acceleration, m/s²,
//!   default 0.3).
//! - `position-ekf`: fuses GPS positions (`gps`, default `nav.gps`), DVL velocity in the vehicle
//!   frame (`velocity`, default `nav.velocity`: `surge` and `sway`) and heading (`heading`, default
//!   `nav.attitude`: `yaw`) into a position (`output`, default `nav.position.estimated`) with its
//!   `sigma` and the compass bias it has learnt; between fixes (submerged) it dead-reckons, and the
//!   output says `source = "dead-reckoning"`. The first fix is the origin of its local frame.
//!   Parameters: `gps_sigma` (m, default 3), `vel_sigma` (m/s, default 0.03).
//! - `heading-correction`: reads the compass (`attitude`, default `nav.attitude`: `yaw`, or the
//!   magnetometer `mag_x`, `mag_y`, `mag_z` with `roll` and `pitch`, whose tilt it takes out) and
//!   publishes the heading (`output`, default `nav.heading.corrected`) corrected by the deviation
//!   table (`deviation="0:2, 90:-1.5, 180:0, 270:1"`, compass heading : degrees east) and the
//!   magnetic `variation`, smoothed through turns with the rate of turn (`gain`, default 0.1). With
//!   `learn="true"` it learns the deviation from GPS course over ground (`course`, default
//!   `nav.velocity`) while the vehicle goes straight faster than `min_speed` (m/s, default 0.5).

use crate::estimate::{DepthKalman, PositionEkf};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Stamp, Topic};
use seabus_modules::datasets::Catalogue;
use seabus_modules::geo;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};

/// The `depth-kalman` module type.
pub const DEPTH: ModuleType = ModuleType {
    name: "depth-kalman",
    kind: ModuleKind::Supporting,
    summary: "Kalman-filtered depth and vertical speed from depth readings",
    build: build_depth,
};

/// The `position-ekf` module type.
pub const POSITION: ModuleType = ModuleType {
    name: "position-ekf",
    kind: ModuleKind::Supporting,
    summary: "position from GPS, DVL velocity and heading (EKF), dead-reckoning while submerged",
    build: build_position,
};

struct DepthModule {
    input: Topic,
    output: Topic,
    filter: DepthKalman,
    last: Option<Stamp>,
}

fn build_depth(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let input = p.topic_or("input", "nav.depth")?;
    let output = p.topic_or("output", "nav.depth.filtered")?;
    let decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::dataset(input.as_str(), "depth"))
        .produces(TopicDecl::dataset(output.as_str(), "depth").field("vertical_speed", "m/s"));
    Ok(Built {
        decl,
        module: Box::new(DepthModule {
            input,
            output,
            filter: DepthKalman::new(p.positive_or("sigma", 0.2)?, p.positive_or("accel", 0.3)?),
            last: None,
        }),
    })
}

#[async_trait]
impl Module for DepthModule {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        if msg.topic != self.input {
            return Ok(());
        }
        let Some(depth) = msg.payload.as_map().and_then(|m| m.get_f64("depth")) else {
            return Ok(());
        };
        let dt = self.last.map_or(0.0, |t| msg.stamp.since(t).as_secs_f64());
        self.last = Some(msg.stamp);
        let (d, w) = self.filter.update(dt, depth);
        let out = DataMap::new().with("depth", d).with("vertical_speed", w);
        ctx.publish(&self.output, out).await?;
        Ok(())
    }
}

struct PositionModule {
    gps: Topic,
    velocity: Topic,
    heading: Topic,
    output: Topic,
    gps_sigma: f64,
    vel_sigma: f64,
    /// The local frame's origin, the first fix.
    origin: Option<(f64, f64)>,
    ekf: Option<PositionEkf>,
    heading_deg: Option<f64>,
    last_velocity: Option<Stamp>,
    /// Whether the latest update was a fix.
    fixed: bool,
}

fn build_position(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let gps = p.topic_or("gps", "nav.gps")?;
    let velocity = p.topic_or("velocity", "nav.velocity")?;
    let heading = p.topic_or("heading", "nav.attitude")?;
    let output = p.topic_or("output", "nav.position.estimated")?;
    let decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::dataset(gps.as_str(), "position"))
        .consumes(
            TopicDecl::topic(velocity.as_str())
                .field("surge", "m/s")
                .field("sway", "m/s"),
        )
        .consumes(TopicDecl::topic(heading.as_str()).field("yaw", "deg"))
        .produces(
            TopicDecl::dataset(output.as_str(), "position")
                .field("sigma", "m")
                .field("compass_bias", "deg"),
        );
    Ok(Built {
        decl,
        module: Box::new(PositionModule {
            gps,
            velocity,
            heading,
            output,
            gps_sigma: p.positive_or("gps_sigma", 3.0)?,
            vel_sigma: p.positive_or("vel_sigma", 0.03)?,
            origin: None,
            ekf: None,
            heading_deg: None,
            last_velocity: None,
            fixed: false,
        }),
    })
}

impl PositionModule {
    async fn publish(&self, ctx: &mut Context) -> Result<(), ModuleError> {
        let (Some(ekf), Some((lat0, lon0))) = (&self.ekf, self.origin) else {
            return Ok(());
        };
        let (n, e) = ekf.position();
        let (lat, lon) = geo::moved(lat0, lon0, n, e);
        let out = DataMap::new()
            .with("lat", lat)
            .with("lon", lon)
            .with("fix", 6i64)
            .with("source", if self.fixed { "ekf" } else { "dead-reckoning" })
            .with("sigma", ekf.sigma())
            .with("compass_bias", ekf.bias_deg());
        ctx.publish(&self.output, out).await?;
        Ok(())
    }
}

#[async_trait]
impl Module for PositionModule {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(m) = msg.payload.as_map() else {
            return Ok(());
        };
        if msg.topic == self.heading {
            self.heading_deg = m.get_f64("yaw").or_else(|| m.get_f64("heading"));
            return Ok(());
        }
        if msg.topic == self.gps {
            let (Some(lat), Some(lon)) = (m.get_f64("lat"), m.get_f64("lon")) else {
                return Ok(());
            };
            if m.get_i64("fix").is_some_and(|f| f == 0) {
                return Ok(());
            }
            let (lat0, lon0) = *self.origin.get_or_insert((lat, lon));
            let (n, e) = geo::offset(lat0, lon0, lat, lon);
            match &mut self.ekf {
                Some(ekf) => ekf.gps(n, e, self.gps_sigma),
                None => {
                    self.ekf = Some(PositionEkf::new(n, e, self.gps_sigma, 10.0, self.vel_sigma));
                }
            }
            self.fixed = true;
            return self.publish(ctx).await;
        }
        if msg.topic == self.velocity {
            let (Some(surge), Some(heading), Some(ekf)) =
                (m.get_f64("surge"), self.heading_deg, &mut self.ekf)
            else {
                return Ok(());
            };
            let sway = m.get_f64("sway").unwrap_or(0.0);
            let dt = self
                .last_velocity
                .map_or(0.0, |t| msg.stamp.since(t).as_secs_f64());
            self.last_velocity = Some(msg.stamp);
            ekf.predict(dt, heading, surge, sway);
            self.fixed = false;
            return self.publish(ctx).await;
        }
        Ok(())
    }
}

/// The `heading-correction` module type.
pub const HEADING: ModuleType = ModuleType {
    name: "heading-correction",
    kind: ModuleKind::Supporting,
    summary: "compass heading with tilt compensation, deviation (configured or learnt from GPS) and smoothing",
    build: build_heading,
};

struct HeadingModule {
    attitude: Topic,
    course: Topic,
    output: Topic,
    variation: f64,
    learn: bool,
    min_speed: f64,
    deviation: crate::estimate::Deviation,
    smoother: crate::estimate::HeadingSmoother,
    last: Option<(Stamp, f64, Option<f64>)>,
}

fn build_heading(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let attitude = p.topic_or("attitude", "nav.attitude")?;
    let course = p.topic_or("course", "nav.velocity")?;
    let output = p.topic_or("output", "nav.heading.corrected")?;
    let mut table = Vec::new();
    if let Some(t) = p.get("deviation") {
        for item in t.value.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let point = item
                .split_once(':')
                .and_then(|(h, d)| Some((h.trim().parse().ok()?, d.trim().parse().ok()?)));
            let Some(point) = point else {
                return Err(t.error(format!("`{item}` is not HEADING:DEVIATION in degrees")));
            };
            table.push(point);
        }
    }
    let decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::topic(attitude.as_str()).field("yaw", "deg"))
        .consumes(TopicDecl::topic(course.as_str()).field("course", "deg"))
        .produces(TopicDecl::dataset(output.as_str(), "heading"));
    Ok(Built {
        decl,
        module: Box::new(HeadingModule {
            attitude,
            course,
            output,
            variation: p.float_or("variation", 0.0)?,
            learn: p.flag_or("learn", false)?,
            min_speed: p.non_negative_or("min_speed", 0.5)?,
            deviation: crate::estimate::Deviation::new(table),
            smoother: crate::estimate::HeadingSmoother::new(p.positive_or("gain", 0.1)?),
            last: None,
        }),
    })
}

#[async_trait]
impl Module for HeadingModule {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(m) = msg.payload.as_map() else {
            return Ok(());
        };
        if msg.topic == self.course {
            // course over ground is heading only when going straight and fast enough
            let straight = self
                .last
                .is_some_and(|(_, _, rate)| rate.is_none_or(|r| r.abs() < 1.0));
            if let (true, true, Some(course), Some((_, compass, _))) =
                (self.learn, straight, m.get_f64("course"), self.last)
                && m.get_f64("speed").is_some_and(|s| s >= self.min_speed)
            {
                self.deviation.learn(compass, course - self.variation);
            }
            return Ok(());
        }
        if msg.topic != self.attitude {
            return Ok(());
        }
        let mag = (m.get_f64("mag_x"), m.get_f64("mag_y"), m.get_f64("mag_z"));
        let compass = match (mag, m.get_f64("roll"), m.get_f64("pitch")) {
            ((Some(x), Some(y), Some(z)), Some(roll), Some(pitch)) => {
                crate::estimate::tilt_compensated([x, y, z], roll, pitch)
            }
            _ => match m.get_f64("yaw").or_else(|| m.get_f64("heading")) {
                Some(h) => h,
                None => return Ok(()),
            },
        };
        let rate = m.get_f64("yaw_rate").or_else(|| m.get_f64("rate"));
        let dt = self
            .last
            .map_or(0.0, |(t, _, _)| msg.stamp.since(t).as_secs_f64());
        self.last = Some((msg.stamp, compass, rate));
        let deviation = self.deviation.at(compass);
        let heading = self
            .smoother
            .update(dt, compass + deviation + self.variation, rate);
        let mut out = DataMap::new()
            .with("heading", heading)
            .with("deviation", deviation)
            .with("variation", self.variation);
        if let Some(r) = rate {
            out.insert("rate", r);
        }
        ctx.publish(&self.output, out).await?;
        Ok(())
    }
}
