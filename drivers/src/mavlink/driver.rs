//! `mavlink`: the driver of one MAVLink vehicle (an ArduSub ROV, an ArduRover boat), placed on a
//! MAVLink medium and a bus: `media="mav bus"`.
//!
//! It follows the vehicle the medium lists on `mavlink.vehicles` (`sysid`, or the first vehicle
//! heard) and publishes on the bus what its messages say, as standard datasets:
//! ATTITUDE → `nav.attitude`; GLOBAL_POSITION_INT → `nav.position`, `nav.velocity` and
//! `nav.heading` (VFR_HUD stands in for the last two while no GLOBAL_POSITION_INT brings them);
//! the depth sensor's SCALED_PRESSURE (`pressure`) or GLOBAL_POSITION_INT's relative altitude
//! (`depth="position"`) → `nav.depth`; BATTERY_STATUS, or SYS_STATUS while no BATTERY_STATUS comes
//! → `power.battery`; its HEARTBEAT → `vehicle.state` (mode by name, armed, system status).
//! Values MAVLink marks unknown are left out, never published as numbers ([`super::ardupilot`]).
//!
//! Commands it takes on the bus, each sent to the vehicle as MAVLink:
//! - `cmd.arm` (`armed`, `force`) → COMMAND_LONG MAV_CMD_COMPONENT_ARM_DISARM;
//! - `cmd.mode` (`mode`, a name such as MANUAL or DEPTH_HOLD) → COMMAND_LONG MAV_CMD_DO_SET_MODE;
//! - `cmd.course` (`heading`, `depth`, `speed`) → SET_POSITION_TARGET_GLOBAL_INT (a GUIDED target);
//! - `cmd.manual` (`x`, `y`, `z`, `r`, `buttons`, MANUAL_CONTROL's own scale) → MANUAL_CONTROL.
//!
//! Every command's fate goes on `cmd.status`: a COMMAND_LONG is `pending`, then `acknowledged`,
//! `refused` (the COMMAND_ACK's result: DENIED, UNSUPPORTED, FAILED, TEMPORARILY_REJECTED, …) or
//! `timed-out` once it has gone `retries` more times (confirmation counting up) without an answer
//! within `ack_timeout` each; messages MAVLink does not acknowledge are `sent`. A command for a
//! vehicle that is not heard, or that is not valid, is `refused` at once with the reason.
//!
//! Safety: values out of range are refused, never clamped. When `cmd.manual` stops for
//! `manual_timeout` while the last one was not neutral, the driver sends one neutral
//! MANUAL_CONTROL itself (x = y = r = 0, z = `neutral_z`, no buttons) and nothing else.
//!
//! Health: it reports the vehicle on `seabus.health.<health>` (`Vehicle` unless said) every
//! second and at once on a change: HEALTHY while its heartbeat is heard, OFFLINE when it is lost.

use super::ardupilot::{self, Firmware, short};
use crate::command_status::{self, command_status};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Format, Kind, LinkState, Message, Payload, Topic};
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TICK, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use seabus_modules::{Catalogue, Params};
use std::time::Duration;
use tokio::time::Instant;

/// The `mavlink` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "mavlink",
    kind: ModuleKind::Driver,
    summary: "MAVLink vehicle (ArduSub, ArduRover) on a mavlink:// medium",
    build,
};

/// MANUAL_CONTROL's range for x, y and r (and z's top).
pub const MANUAL_MAX: f64 = 1000.0;
/// ArduPilot's magic number that forces arming or disarming (MAV_CMD_COMPONENT_ARM_DISARM param2).
const FORCE: f64 = 21196.0;
/// SET_POSITION_TARGET_GLOBAL_INT type mask: use altitude, velocity north and east and yaw; ignore
/// latitude, longitude, vertical speed, accelerations and yaw rate.
const COURSE_MASK: i64 = 1 | 2 | 32 | 64 | 128 | 256 | 2048;
/// How long a GLOBAL_POSITION_INT's velocity or heading, or a BATTERY_STATUS, keeps the other
/// message from standing in for it.
const STAND_IN: Duration = Duration::from_secs(2);

/// Where depth comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DepthFrom {
    /// The depth sensor's pressure message.
    Pressure,
    /// GLOBAL_POSITION_INT's relative altitude.
    Position,
}

struct Settings {
    sysid: Option<u32>,
    pressure: String,
    depth_from: DepthFrom,
    surface: f64,
    density: f64,
    ack_timeout: Duration,
    retries: u8,
    manual_timeout: Duration,
    neutral_z: i64,
    z_min: i64,
    health_every: Duration,
}

struct Topics {
    attitude: Topic,
    position: Topic,
    velocity: Topic,
    heading: Topic,
    depth: Topic,
    battery: Topic,
    state: Topic,
    status: Topic,
    health: Topic,
    arm: Topic,
    mode: Topic,
    course: Topic,
    manual: Topic,
}

/// The vehicle followed, as the medium's vehicles list last said.
#[derive(Debug, Clone, PartialEq)]
struct Vehicle {
    sysid: u32,
    compid: i64,
    alive: bool,
    firmware: Firmware,
    mav_type: String,
    armed: bool,
    custom_mode: i64,
    status: String,
}

/// A COMMAND_LONG sent and not yet answered.
struct Pending {
    id: i64,
    command: &'static str,
    long: DataMap,
    confirmation: u8,
    sent: Instant,
    request: Option<(String, u64)>,
}

/// A MANUAL_CONTROL's axes, on MAVLink's scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Manual {
    /// Forward (−1000 to 1000).
    pub x: i64,
    /// Right (−1000 to 1000).
    pub y: i64,
    /// Thrust up; ArduSub: 0 to 1000, 500 neutral.
    pub z: i64,
    /// Yaw, clockwise (−1000 to 1000).
    pub r: i64,
    /// Buttons pressed, one bit each.
    pub buttons: i64,
}

impl Manual {
    /// The neutral command: no motion, thrust `neutral_z`, no buttons.
    pub fn neutral(neutral_z: i64) -> Manual {
        Manual {
            x: 0,
            y: 0,
            z: neutral_z,
            r: 0,
            buttons: 0,
        }
    }

    /// A `cmd.manual` (already checked against its dataset) on MAVLink's scale: values rounded to
    /// whole numbers; anything out of range is refused, naming the field.
    pub fn from_map(map: &DataMap, z_min: i64) -> Result<Manual, String> {
        let axis = |k: &str, min: f64| -> Result<i64, String> {
            let v = map.get_f64(k).ok_or_else(|| format!("`{k}` is missing"))?;
            if !(min..=MANUAL_MAX).contains(&v) {
                return Err(format!("`{k}` = {v} is outside {min} to {MANUAL_MAX}"));
            }
            Ok(v.round() as i64)
        };
        let buttons = match map.get("buttons") {
            None => 0,
            Some(v) => v
                .as_i64()
                .filter(|b| (0..=i64::from(u16::MAX)).contains(b))
                .ok_or_else(|| format!("`buttons` = {v} is no 16-bit button mask"))?,
        };
        Ok(Manual {
            x: axis("x", -MANUAL_MAX)?,
            y: axis("y", -MANUAL_MAX)?,
            z: axis("z", z_min as f64)?,
            r: axis("r", -MANUAL_MAX)?,
            buttons,
        })
    }

    fn map(&self, target: u32) -> DataMap {
        DataMap::new()
            .with("target", i64::from(target))
            .with("x", self.x)
            .with("y", self.y)
            .with("z", self.z)
            .with("r", self.r)
            .with("buttons", self.buttons)
    }
}

/// The stream of manual commands.
struct ManualStream {
    last: Manual,
    at: Instant,
    neutral: bool,
}

struct Mav {
    s: Settings,
    t: Topics,
    vehicle: Option<Vehicle>,
    /// why the vehicle is not commandable, when it is not
    lost: String,
    pending: Vec<Pending>,
    next_id: i64,
    manual: Option<ManualStream>,
    last_state: Option<(String, Instant)>,
    last_health: Option<(bool, Instant)>,
    gpi_velocity_at: Option<Instant>,
    gpi_heading_at: Option<Instant>,
    battery_status_at: Option<Instant>,
    tally: Tally,
}

fn build(cfg: &ModuleConfig, cat: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let sysid = match p.get("sysid") {
        None => None,
        Some(param) => Some(
            param
                .value
                .trim()
                .parse::<u32>()
                .ok()
                .filter(|n| (1..=255).contains(n))
                .ok_or_else(|| {
                    param.error(format!(
                        "`{}` is not a vehicle's system id (1 to 255)",
                        param.value.trim()
                    ))
                })?,
        ),
    };
    let pressure = p.str("pressure").unwrap_or("SCALED_PRESSURE").to_string();
    if !["SCALED_PRESSURE", "SCALED_PRESSURE2", "SCALED_PRESSURE3"].contains(&pressure.as_str()) {
        return Err(p.required("pressure")?.error(format!(
            "`{pressure}` is not SCALED_PRESSURE, SCALED_PRESSURE2 or SCALED_PRESSURE3"
        )));
    }
    let depth_from = match p.str("depth").unwrap_or("pressure") {
        "pressure" => DepthFrom::Pressure,
        "position" => DepthFrom::Position,
        other => {
            return Err(p
                .required("depth")?
                .error(format!("`{other}` is not `pressure` or `position`")));
        }
    };
    let density = match p.str("water").unwrap_or("salt") {
        "salt" => ardupilot::SALT,
        "fresh" => ardupilot::FRESH,
        other => other
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|d| (900.0..=1100.0).contains(d))
            .ok_or_else(|| {
                let why = format!(
                    "`{}` is not `salt`, `fresh` or a density in kg/m³ from 900 to 1100",
                    other.trim()
                );
                p.get("water")
                    .map_or_else(|| cfg.pos.error(&why), |w| w.error(&why))
            })?,
    };
    let retries: u8 = p.parse_or("retries", 2, "a number of re-sends from 0 to 5")?;
    if retries > 5 {
        return Err(p
            .required("retries")?
            .error("a number of re-sends from 0 to 5"));
    }
    let neutral_z: i64 = p.parse_or(
        "neutral_z",
        500,
        "MANUAL_CONTROL's neutral z, -1000 to 1000",
    )?;
    let z_min: i64 = p.parse_or("z_min", 0, "MANUAL_CONTROL's lowest z, -1000 to 1000")?;
    if !(-1000..=1000).contains(&z_min) || !(z_min..=1000).contains(&neutral_z) {
        let why = format!(
            "neutral_z ({neutral_z}) must lie from z_min ({z_min}) to 1000, and z_min from -1000"
        );
        return Err(p
            .get("neutral_z")
            .or_else(|| p.get("z_min"))
            .map_or_else(|| cfg.pos.error(&why), |q| q.error(&why)));
    }
    let s = Settings {
        sysid,
        pressure,
        depth_from,
        surface: p.positive_or("surface_pressure", ardupilot::SURFACE_HPA)?,
        density,
        ack_timeout: p.duration_or("ack_timeout", Duration::from_millis(1500))?,
        retries,
        manual_timeout: p.duration_or("manual_timeout", Duration::from_secs(1))?,
        neutral_z,
        z_min,
        health_every: p.duration_or("health_every", Duration::from_secs(1))?,
    };
    let t = topics(p, cat)?;
    Ok(Built {
        decl: declaration(&t),
        module: Box::new(Mav::new(s, t)),
    })
}

fn topics(p: &Params, cat: &Catalogue) -> Result<Topics, FileError> {
    let topic = |name: &str, dataset: &str, fallback: &str| {
        p.dataset_topic_or(name, cat, dataset, fallback)
    };
    let command = |dataset: &str, fallback: &str| p.dataset_topic(cat, dataset, fallback);
    let component = p.str("health").unwrap_or("Vehicle");
    let health = Topic::new(&format!("seabus.health.{component}")).map_err(|e| {
        p.get("health")
            .map_or_else(|| p.error(e.to_string()), |h| h.error(e.to_string()))
    })?;
    Ok(Topics {
        attitude: topic("attitude_topic", "attitude", "nav.attitude")?,
        position: topic("position_topic", "position", "nav.position")?,
        velocity: topic("velocity_topic", "velocity", "nav.velocity")?,
        heading: topic("heading_topic", "heading", "nav.heading")?,
        depth: topic("depth_topic", "depth", "nav.depth")?,
        battery: topic("battery_topic", "battery", "power.battery")?,
        state: topic("state_topic", "vehicle-state", "vehicle.state")?,
        status: topic("status_topic", command_status::DATASET, "cmd.status")?,
        health,
        arm: command("arm-command", "cmd.arm")?,
        mode: command("mode-command", "cmd.mode")?,
        course: command("course-command", "cmd.course")?,
        manual: command("manual-command", "cmd.manual")?,
    })
}

/// Port 0 is the MAVLink medium's topics; port 1 carries the datasets and the commands.
fn declaration(t: &Topics) -> Declaration {
    let mut decl = Declaration::new(ModuleKind::Driver)
        .format(0, Some(Format::Map))
        .consumes(TopicDecl::topic("mavlink.**"))
        .format(1, Some(Format::Map))
        .default_tick(Duration::from_millis(100));
    for (topic, dataset) in [
        (&t.attitude, "attitude"),
        (&t.position, "position"),
        (&t.velocity, "velocity"),
        (&t.heading, "heading"),
        (&t.depth, "depth"),
        (&t.battery, "battery"),
        (&t.state, "vehicle-state"),
        (&t.status, command_status::DATASET),
    ] {
        decl = decl.produces(TopicDecl::dataset(topic, dataset).on_port(1));
    }
    decl.produces(TopicDecl::topic(&t.health).on_port(1))
        .accepts(TopicDecl::dataset(&t.arm, "arm-command").on_port(1))
        .accepts(TopicDecl::dataset(&t.mode, "mode-command").on_port(1))
        .accepts(TopicDecl::dataset(&t.course, "course-command").on_port(1))
        .accepts(TopicDecl::dataset(&t.manual, "manual-command").on_port(1))
}

/// The system id and message name of a topic `mavlink.SYSID.NAME`.
fn sender(topic: &str) -> Option<(u32, &str)> {
    let rest = topic.strip_prefix("mavlink.")?;
    let (sys, name) = rest.split_once('.')?;
    Some((sys.parse().ok()?, name))
}

/// A vehicle from a `mavlink.vehicles` entry.
fn vehicle_of(m: &DataMap) -> Option<Vehicle> {
    let sysid = u32::try_from(m.get_i64("sysid")?).ok()?;
    let text = |k: &str| m.get_str(k).unwrap_or_default().to_string();
    Some(Vehicle {
        sysid,
        compid: m.get_i64("compid").unwrap_or(1),
        alive: m.get_bool("alive").unwrap_or(false),
        firmware: Firmware::of(&text("type"), &text("autopilot")),
        mav_type: text("type"),
        armed: m.get_bool("armed").unwrap_or(false),
        custom_mode: m.get_i64("custom_mode").unwrap_or(0),
        status: text("system_status"),
    })
}

/// A COMMAND_LONG's fields: `command` with `params` (the rest 0), confirmation 0.
fn command_long(target: &Vehicle, command: &str, params: &[f64]) -> DataMap {
    let mut m = DataMap::new()
        .with("target_system", i64::from(target.sysid))
        .with("target_component", target.compid)
        .with("command", command)
        .with("confirmation", 0i64);
    for i in 0..7 {
        m.insert(
            format!("param{}", i + 1),
            params.get(i).copied().unwrap_or(0.0),
        );
    }
    m
}

/// SET_POSITION_TARGET_GLOBAL_INT for a course: depth as altitude below home, speed along the
/// heading as velocity north and east, the heading as yaw.
fn course_target(target: &Vehicle, heading: f64, depth: f64, speed: f64) -> DataMap {
    let h = heading.to_radians();
    let yaw = if h > std::f64::consts::PI {
        h - 2.0 * std::f64::consts::PI
    } else {
        h
    };
    DataMap::new()
        .with("time_boot_ms", 0i64)
        .with("target_system", i64::from(target.sysid))
        .with("target_component", target.compid)
        .with("coordinate_frame", "MAV_FRAME_GLOBAL_RELATIVE_ALT_INT")
        .with("type_mask", COURSE_MASK)
        .with("lat_int", 0i64)
        .with("lon_int", 0i64)
        .with("alt", -depth)
        .with("vx", speed * h.cos())
        .with("vy", speed * h.sin())
        .with("vz", 0.0)
        .with("afx", 0.0)
        .with("afy", 0.0)
        .with("afz", 0.0)
        .with("yaw", yaw)
        .with("yaw_rate", 0.0)
}

impl Mav {
    fn new(s: Settings, t: Topics) -> Mav {
        Mav {
            s,
            t,
            vehicle: None,
            lost: "no vehicle heard yet".into(),
            pending: Vec::new(),
            next_id: 1,
            manual: None,
            last_state: None,
            last_health: None,
            gpi_velocity_at: None,
            gpi_heading_at: None,
            battery_status_at: None,
            tally: Tally::new(),
        }
    }

    /// The vehicle, when it is heard; otherwise why not.
    fn commandable(&self) -> Result<&Vehicle, String> {
        match &self.vehicle {
            Some(v) if v.alive && self.lost.is_empty() => Ok(v),
            _ => Err(self.lost.clone()),
        }
    }

    async fn publish(&self, ctx: &Context, dataset: &str, topic: &Topic, map: DataMap) {
        if let Err(e) = ctx.dataset_on(1, Kind::Data, dataset, topic, map).await {
            self.tally.record(ctx.name(), "invalid-data", &e);
        }
    }

    async fn status(
        &self,
        ctx: &Context,
        id: i64,
        command: &str,
        state: &str,
        error: &str,
        request: &Option<(String, u64)>,
    ) {
        let m = command_status(command, state, Some(id), Some(error), request.as_ref());
        self.publish(ctx, command_status::DATASET, &self.t.status, m)
            .await;
    }

    fn take_id(&mut self) -> i64 {
        let id = self.next_id;
        self.next_id += 1;
        id
    }

    async fn refuse(
        &mut self,
        ctx: &Context,
        command: &str,
        why: &str,
        request: Option<(String, u64)>,
    ) {
        let id = self.take_id();
        self.tally.record(
            ctx.name(),
            "refused",
            format_args!("{command} refused: {why}"),
        );
        self.status(ctx, id, command, "refused", why, &request)
            .await;
    }

    /// Sends message `name` with `map` to the vehicle `sysid`.
    async fn send_mav(
        &self,
        ctx: &Context,
        sysid: u32,
        name: &str,
        map: DataMap,
    ) -> Result<(), String> {
        ctx.publish_on(
            0,
            Kind::Command,
            format!("mavlink.{sysid}.{name}"),
            Payload::from(map),
        )
        .await
        .map_err(|e| e.to_string())
    }

    // ---- from the vehicle

    async fn on_vehicles(&mut self, ctx: &Context, map: &DataMap) {
        let Some(v) = vehicle_of(map) else {
            return;
        };
        let ours = match (&self.vehicle, self.s.sysid) {
            (Some(cur), _) => cur.sysid == v.sysid && cur.compid == v.compid,
            (None, Some(want)) => want == v.sysid,
            (None, None) => v.alive,
        };
        if !ours {
            return;
        }
        if self.vehicle.is_none() {
            tracing::info!(
                module = ctx.name(),
                "following vehicle {} (component {}, {})",
                v.sysid,
                v.compid,
                v.mav_type
            );
        }
        self.vehicle = Some(v);
        self.update_lost(ctx).await;
        self.publish_state(ctx, false).await;
    }

    /// Works out whether the vehicle is heard, from the vehicles list and the medium's link;
    /// reports a change to the health monitor at once.
    async fn update_lost(&mut self, ctx: &Context) {
        let link = ctx
            .port(0)
            .map_or(LinkState::Up, |p| p.medium().link_state());
        let lost = match (&self.vehicle, link) {
            (None, _) => match self.s.sysid {
                Some(n) => format!("vehicle {n} not heard yet"),
                None => "no vehicle heard yet".into(),
            },
            (Some(v), LinkState::Down(why)) => {
                format!("vehicle {} lost: {why}", v.sysid)
            }
            (Some(v), LinkState::Up) if !v.alive => {
                format!("vehicle {} lost: its heartbeat stopped", v.sysid)
            }
            _ => String::new(),
        };
        if lost != self.lost {
            if lost.is_empty() {
                tracing::info!(module = ctx.name(), "vehicle heard");
            } else {
                tracing::warn!(module = ctx.name(), "{lost}");
            }
            self.lost = lost;
            self.report_health(ctx).await;
            self.publish_state(ctx, true).await;
        }
    }

    async fn report_health(&mut self, ctx: &Context) {
        let healthy = self.lost.is_empty();
        let mut m = DataMap::new().with("state", if healthy { "HEALTHY" } else { "OFFLINE" });
        if !healthy {
            m.insert("reason", self.lost.as_str());
        }
        if let Err(e) = ctx.publish_on(1, Kind::Data, &self.t.health, m).await {
            self.tally.record(ctx.name(), "health-report", &e);
        }
        self.last_health = Some((healthy, Instant::now()));
    }

    /// `vehicle.state`: when it changed (or `force`), and at least once a second.
    async fn publish_state(&mut self, ctx: &Context, force: bool) {
        let now = Instant::now();
        let (mode, control, mut m) = match (&self.vehicle, self.lost.is_empty()) {
            (Some(v), alive) => {
                let mode = v.firmware.mode_name(v.custom_mode);
                let control = match (alive, v.armed, mode.as_str()) {
                    (false, _, _) => "offline",
                    (true, false, _) => "idle",
                    (true, true, "GUIDED") => "in-control",
                    (true, true, _) => "accepting",
                };
                let m = DataMap::new()
                    .with("armed", v.armed)
                    .with("status", short(&v.status, "MAV_STATE_"))
                    .with("type", short(&v.mav_type, "MAV_TYPE_"))
                    .with("sysid", i64::from(v.sysid));
                (mode, control, m)
            }
            (None, _) => ("unknown".to_string(), "offline", DataMap::new()),
        };
        m.insert("mode", mode.as_str());
        m.insert("control", control);
        m.insert("reason", self.lost.as_str());
        let key = format!("{m:?}");
        let due = self
            .last_state
            .as_ref()
            .is_none_or(|(k, at)| *k != key || now.duration_since(*at) >= Duration::from_secs(1));
        if force || due {
            self.publish(ctx, "vehicle-state", &self.t.state, m).await;
            self.last_state = Some((key, now));
        }
    }

    async fn on_mav(&mut self, ctx: &Context, name: &str, m: &DataMap) {
        let now = Instant::now();
        match name {
            "ATTITUDE" => {
                if let Some(a) = ardupilot::attitude(m) {
                    self.publish(ctx, "attitude", &self.t.attitude, a).await;
                }
            }
            "GLOBAL_POSITION_INT" => {
                let g = ardupilot::global_position(m);
                if let Some(p) = g.position {
                    self.publish(ctx, "position", &self.t.position, p).await;
                }
                if let Some(v) = g.velocity {
                    self.gpi_velocity_at = Some(now);
                    self.publish(ctx, "velocity", &self.t.velocity, v).await;
                }
                if let Some(h) = g.heading {
                    self.gpi_heading_at = Some(now);
                    self.publish(ctx, "heading", &self.t.heading, h).await;
                }
                if let (DepthFrom::Position, Some(d)) = (self.s.depth_from, g.depth) {
                    let d = DataMap::new().with("depth", d);
                    self.publish(ctx, "depth", &self.t.depth, d).await;
                }
            }
            "VFR_HUD" => {
                let quiet =
                    |at: Option<Instant>| at.is_none_or(|t| now.duration_since(t) > STAND_IN);
                let (v, h) = ardupilot::vfr_hud(m);
                if let Some(v) = v.filter(|_| quiet(self.gpi_velocity_at)) {
                    self.publish(ctx, "velocity", &self.t.velocity, v).await;
                }
                if let Some(h) = h.filter(|_| quiet(self.gpi_heading_at)) {
                    self.publish(ctx, "heading", &self.t.heading, h).await;
                }
            }
            "SYS_STATUS" => {
                let quiet = self
                    .battery_status_at
                    .is_none_or(|t| now.duration_since(t) > STAND_IN);
                if quiet && let Some(b) = ardupilot::sys_status_battery(m) {
                    self.publish(ctx, "battery", &self.t.battery, b).await;
                }
            }
            "BATTERY_STATUS" => {
                // the first battery (id 0) is the vehicle's
                if m.get_i64("id").unwrap_or(0) == 0
                    && let Some(b) = ardupilot::battery_status(m)
                {
                    self.battery_status_at = Some(now);
                    self.publish(ctx, "battery", &self.t.battery, b).await;
                }
            }
            "COMMAND_ACK" => self.on_ack(ctx, m).await,
            other if other == self.s.pressure && self.s.depth_from == DepthFrom::Pressure => {
                if let Some(d) = ardupilot::pressure_depth(m, self.s.surface, self.s.density) {
                    self.publish(ctx, "depth", &self.t.depth, d).await;
                }
            }
            _ => {}
        }
    }

    async fn on_ack(&mut self, ctx: &Context, m: &DataMap) {
        let command = m.get_str("command").unwrap_or_default();
        let result = m.get_str("result").unwrap_or_default();
        let Some(i) = self.pending.iter().position(|p| p.command == command) else {
            self.tally.record(
                ctx.name(),
                "unexpected-ack",
                format_args!("COMMAND_ACK for {command} ({result}), which was not sent"),
            );
            return;
        };
        match result {
            "MAV_RESULT_IN_PROGRESS" => {
                // answered: it goes on; the wait starts again
                self.pending[i].sent = Instant::now();
            }
            "MAV_RESULT_ACCEPTED" => {
                let p = self.pending.remove(i);
                self.status(ctx, p.id, p.command, "acknowledged", "", &p.request)
                    .await;
            }
            other => {
                let p = self.pending.remove(i);
                let why = short(other, "MAV_RESULT_");
                self.tally.record(
                    ctx.name(),
                    "refused-by-vehicle",
                    format_args!("the vehicle refused {}: {why}", p.command),
                );
                self.status(ctx, p.id, p.command, "refused", why, &p.request)
                    .await;
            }
        }
    }

    // ---- from the bus

    async fn on_command(&mut self, ctx: &Context, msg: Message) {
        let Some(map) = msg.payload.as_map() else {
            return;
        };
        let request = Some(command_status::request(&msg));
        let topic = msg.topic.as_str();
        if topic == self.t.arm.as_str() {
            self.on_arm(ctx, map, request).await;
        } else if topic == self.t.mode.as_str() {
            self.on_mode(ctx, map, request).await;
        } else if topic == self.t.course.as_str() {
            self.on_course(ctx, map, request).await;
        } else if topic == self.t.manual.as_str() {
            self.on_manual(ctx, map, request).await;
        }
    }

    /// Sends a COMMAND_LONG and tracks it on `cmd.status`.
    async fn send_long(
        &mut self,
        ctx: &Context,
        command: &'static str,
        params: &[f64],
        request: Option<(String, u64)>,
    ) {
        let v = match self.commandable() {
            Ok(v) => v.clone(),
            Err(why) => return self.refuse(ctx, command, &why, request).await,
        };
        if self.pending.iter().any(|p| p.command == command) {
            let why = "the same command is still waiting for its acknowledgement";
            return self.refuse(ctx, command, why, request).await;
        }
        let long = command_long(&v, command, params);
        let id = self.take_id();
        if let Err(e) = self
            .send_mav(ctx, v.sysid, "COMMAND_LONG", long.clone())
            .await
        {
            return self.status(ctx, id, command, "refused", &e, &request).await;
        }
        self.status(ctx, id, command, "pending", "", &request).await;
        self.pending.push(Pending {
            id,
            command,
            long,
            confirmation: 0,
            sent: Instant::now(),
            request,
        });
    }

    async fn on_arm(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        const ARM: &str = "MAV_CMD_COMPONENT_ARM_DISARM";
        if let Err(e) = ctx.catalogue().validate("arm-command", map) {
            return self.refuse(ctx, ARM, &e.to_string(), request).await;
        }
        let arm = map.get_bool("armed").unwrap_or(false);
        let force = map.get_bool("force").unwrap_or(false);
        let params = [if arm { 1.0 } else { 0.0 }, if force { FORCE } else { 0.0 }];
        self.send_long(ctx, ARM, &params, request).await;
    }

    async fn on_mode(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        const MODE: &str = "MAV_CMD_DO_SET_MODE";
        if let Err(e) = ctx.catalogue().validate("mode-command", map) {
            return self.refuse(ctx, MODE, &e.to_string(), request).await;
        }
        let firmware = match self.commandable() {
            Ok(v) => v.firmware,
            Err(why) => return self.refuse(ctx, MODE, &why, request).await,
        };
        let name = map.get_str("mode").unwrap_or_default();
        match firmware.mode_number(name) {
            // param1: MAV_MODE_FLAG_CUSTOM_MODE_ENABLED; param2: the custom mode
            Ok(n) => {
                self.send_long(ctx, MODE, &[1.0, f64::from(n)], request)
                    .await
            }
            Err(why) => self.refuse(ctx, MODE, &why, request).await,
        }
    }

    async fn on_course(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        const COURSE: &str = "SET_POSITION_TARGET_GLOBAL_INT";
        if let Err(e) = ctx.catalogue().validate("course-command", map) {
            return self.refuse(ctx, COURSE, &e.to_string(), request).await;
        }
        let v = match self.commandable() {
            Ok(v) => v.clone(),
            Err(why) => return self.refuse(ctx, COURSE, &why, request).await,
        };
        let f = |k: &str| map.get_f64(k).unwrap_or(0.0);
        let (heading, depth, speed) = (f("heading"), f("depth"), f("speed"));
        if depth < 0.0 {
            let why =
                "a MAVLink vehicle takes a depth, not an altitude above the floor (negative depth)";
            return self.refuse(ctx, COURSE, why, request).await;
        }
        let target = course_target(&v, heading, depth, speed);
        let id = self.take_id();
        match self.send_mav(ctx, v.sysid, COURSE, target).await {
            Ok(()) => self.status(ctx, id, COURSE, "sent", "", &request).await,
            Err(e) => self.status(ctx, id, COURSE, "refused", &e, &request).await,
        }
    }

    async fn on_manual(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        const MANUAL: &str = "MANUAL_CONTROL";
        if let Err(e) = ctx.catalogue().validate("manual-command", map) {
            return self.refuse(ctx, MANUAL, &e.to_string(), request).await;
        }
        let manual = match Manual::from_map(map, self.s.z_min) {
            Ok(m) => m,
            Err(why) => return self.refuse(ctx, MANUAL, &why, request).await,
        };
        let v = match self.commandable() {
            Ok(v) => v.clone(),
            Err(why) => return self.refuse(ctx, MANUAL, &why, request).await,
        };
        let neutral = manual == Manual::neutral(self.s.neutral_z);
        // a stream's start and its neutral are reported; the re-sends between are not
        let starts = self.manual.as_ref().is_none_or(|m| m.neutral);
        let sent = self
            .send_mav(ctx, v.sysid, MANUAL, manual.map(v.sysid))
            .await;
        self.manual = Some(ManualStream {
            last: manual,
            at: Instant::now(),
            neutral,
        });
        match sent {
            Ok(()) if starts || neutral => {
                let id = self.take_id();
                self.status(ctx, id, MANUAL, "sent", "", &request).await;
            }
            Ok(()) => {}
            Err(e) => {
                let id = self.take_id();
                self.status(ctx, id, MANUAL, "refused", &e, &request).await;
            }
        }
    }

    async fn on_tick(&mut self, ctx: &Context) {
        let now = Instant::now();
        self.update_lost(ctx).await;
        // the manual stream stopped while not neutral: neutral, once
        if let Some(m) = &self.manual
            && !m.neutral
            && now.duration_since(m.at) >= self.s.manual_timeout
        {
            let neutral = Manual::neutral(self.s.neutral_z);
            let last = m.last;
            self.manual = Some(ManualStream {
                last: neutral,
                at: now,
                neutral: true,
            });
            let why = format!(
                "cmd.manual stopped for {:.1}s after x={} y={} z={} r={}: neutral sent",
                self.s.manual_timeout.as_secs_f64(),
                last.x,
                last.y,
                last.z,
                last.r
            );
            tracing::warn!(module = ctx.name(), "{why}");
            if let Some(sysid) = self.vehicle.as_ref().map(|v| v.sysid) {
                let id = self.take_id();
                match self
                    .send_mav(ctx, sysid, "MANUAL_CONTROL", neutral.map(sysid))
                    .await
                {
                    Ok(()) => {
                        self.status(ctx, id, "MANUAL_CONTROL", "sent", &why, &None)
                            .await
                    }
                    Err(e) => {
                        self.status(ctx, id, "MANUAL_CONTROL", "refused", &e, &None)
                            .await
                    }
                }
            }
        }
        // unanswered commands go again, confirmation counting up, then time out
        let mut i = 0;
        while i < self.pending.len() {
            if now.duration_since(self.pending[i].sent) < self.s.ack_timeout {
                i += 1;
                continue;
            }
            if self.pending[i].confirmation < self.s.retries && self.lost.is_empty() {
                let p = &mut self.pending[i];
                p.confirmation += 1;
                p.sent = now;
                p.long.insert("confirmation", i64::from(p.confirmation));
                let (sysid, long) = (
                    p.long.get_i64("target_system").unwrap_or(0) as u32,
                    p.long.clone(),
                );
                if let Err(e) = self.send_mav(ctx, sysid, "COMMAND_LONG", long).await {
                    self.tally.record(ctx.name(), "resend", &e);
                }
                i += 1;
                continue;
            }
            let p = self.pending.remove(i);
            let why = format!(
                "no COMMAND_ACK within {:.1}s, sent {} time{}{}",
                self.s.ack_timeout.as_secs_f64(),
                p.confirmation + 1,
                if p.confirmation == 0 { "" } else { "s" },
                if self.lost.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", self.lost)
                }
            );
            self.status(ctx, p.id, p.command, "timed-out", &why, &p.request)
                .await;
        }
        if self
            .last_health
            .is_none_or(|(_, at)| now.duration_since(at) >= self.s.health_every)
        {
            self.report_health(ctx).await;
        }
        self.publish_state(ctx, false).await;
    }
}

#[async_trait]
impl Module for Mav {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        if port != 0 {
            self.on_command(ctx, msg).await;
            return Ok(());
        }
        let Some(map) = msg.payload.as_map() else {
            return Ok(());
        };
        let topic = msg.topic.as_str();
        if topic == "mavlink.vehicles" {
            self.on_vehicles(ctx, map).await;
        } else if let Some((sysid, name)) = sender(topic)
            && self.vehicle.as_ref().is_some_and(|v| v.sysid == sysid)
        {
            self.on_mav(ctx, name, map).await;
        }
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        if timer == TICK {
            self.on_tick(ctx).await;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vehicle() -> Vehicle {
        Vehicle {
            sysid: 1,
            compid: 1,
            alive: true,
            firmware: Firmware::Sub,
            mav_type: "MAV_TYPE_SUBMARINE".into(),
            armed: false,
            custom_mode: 19,
            status: "MAV_STATE_STANDBY".into(),
        }
    }

    #[test]
    fn manual_values_are_rounded_never_clamped() {
        let m = |x: f64, y: f64, z: f64, r: f64| {
            DataMap::new()
                .with("x", x)
                .with("y", y)
                .with("z", z)
                .with("r", r)
        };
        assert_eq!(
            Manual::from_map(&m(250.4, -1000.0, 500.0, 999.6), 0),
            Ok(Manual {
                x: 250,
                y: -1000,
                z: 500,
                r: 1000,
                buttons: 0
            })
        );
        assert_eq!(
            Manual::from_map(&m(1000.5, 0.0, 500.0, 0.0), 0),
            Err("`x` = 1000.5 is outside -1000 to 1000".into())
        );
        assert_eq!(
            Manual::from_map(&m(0.0, 0.0, -10.0, 0.0), 0),
            Err("`z` = -10 is outside 0 to 1000".into())
        );
        // a boat whose z goes both ways
        assert_eq!(
            Manual::from_map(&m(0.0, 0.0, -10.0, 0.0), -1000).unwrap().z,
            -10
        );
        let e = Manual::from_map(&m(0.0, 0.0, 500.0, 0.0).with("buttons", 70000i64), 0);
        assert_eq!(e, Err("`buttons` = 70000 is no 16-bit button mask".into()));
        assert_eq!(Manual::neutral(500).map(1).get_i64("z"), Some(500));
    }

    #[test]
    fn commands_carry_what_ardupilot_expects() {
        let v = vehicle();
        let arm = command_long(&v, "MAV_CMD_COMPONENT_ARM_DISARM", &[1.0, FORCE]);
        assert_eq!(arm.get_str("command"), Some("MAV_CMD_COMPONENT_ARM_DISARM"));
        assert_eq!(arm.get_f64("param1"), Some(1.0));
        assert_eq!(arm.get_f64("param2"), Some(21196.0));
        assert_eq!(arm.get_f64("param7"), Some(0.0));
        assert_eq!(arm.get_i64("confirmation"), Some(0));
        let c = course_target(&v, 270.0, 12.0, 0.5);
        assert_eq!(c.get_f64("alt"), Some(-12.0));
        assert!((c.get_f64("vx").unwrap()).abs() < 1e-12);
        assert!((c.get_f64("vy").unwrap() + 0.5).abs() < 1e-12);
        assert!((c.get_f64("yaw").unwrap() + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(c.get_i64("type_mask"), Some(2531));
    }

    #[test]
    fn topics_name_their_sender_and_message() {
        assert_eq!(sender("mavlink.1.ATTITUDE"), Some((1, "ATTITUDE")));
        assert_eq!(sender("mavlink.vehicles"), None);
        assert_eq!(sender("nav.attitude"), None);
        let v = vehicle_of(
            &DataMap::new()
                .with("sysid", 1i64)
                .with("compid", 1i64)
                .with("type", "MAV_TYPE_SURFACE_BOAT")
                .with("autopilot", "MAV_AUTOPILOT_ARDUPILOTMEGA")
                .with("armed", true)
                .with("custom_mode", 4i64)
                .with("system_status", "MAV_STATE_ACTIVE")
                .with("alive", true),
        )
        .unwrap();
        assert_eq!(v.firmware, Firmware::Rover);
        assert_eq!(v.firmware.mode_name(v.custom_mode), "HOLD");
    }
}
