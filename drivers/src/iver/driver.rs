//! `iver2`: the Iver2/Iver3 frontseat driver (Remote Helm), placed on the serial line to the
//! frontseat and on a bus: `media="frontseat bus"`.
//!
//! It asks for data with `$OSD` (`request`, default `G C S P`, every `request_every`, default
//! 500ms) and publishes what comes back as standard datasets on the bus: attitude and depth from
//! `$C`, position, velocity, altitude and vehicle state from `$OSI`, battery from `$OPI`, the
//! frontseat's GPS from its RMC (`$GPRMC`, `$GNRMC`, …) on `gps_topic`, and DVL velocities on
//! `dvl_topic`. `$OSI` stands in for the others: its depth is published when no `$C` brought a
//! depth within the last three `request_every`, its battery field (Iver3 form) when no `$OPI`
//! brought a battery in that time — so one source feeds each topic, never both at once. The Iver3
//! `$OSI` also gives `vehicle.info` (vehicle name, version, SRP flag and two more flags, battery),
//! published when name, version or flags change and every `info_every` (5s) otherwise.
//!
//! Commands it accepts on the bus:
//! - `cmd.course` (heading, depth, speed) → `$OMS`, repeated every `repeat` (1s) while the course
//!   stays valid — for the command's `timeout` or `hold` (3s) — so that the frontseat's keep-alive
//!   (`oms_timeout`, 5s, sent in each `$OMS`) never lapses while commands flow, and does lapse when
//!   they stop;
//! - `cmd.actuator` (thrust %, rudder and elevator degrees) → `$OMP` (`fin_scale` counts per
//!   degree, default 4, and `motor_scale` counts per percent, default 1.27, around 0x80);
//! - `cmd.mission`: `start` (with `name`) → `$OMSTART`, `stop` → `$OMSTOP`, `goto` (with
//!   `waypoint`) → `$OJW`;
//! - `cmd.iver.waypoint` (lat, lon, depth, speed, clear; or action `stop`) → `$OMW`;
//! - `cmd.iver.position` (lat, lon, speed) → `$OPOS`; `cmd.iver.dvl` (x, y, timeout) → `$ODVL`.
//!
//! Every command it sends is published on `cmd.status` as `pending`, then `acknowledged`, `refused`
//! (with the text of the `$ACK` error number) or `timed-out` (`ack_timeout`, 3s); a command the
//! frontseat cannot take now is `refused` at once with the reason.
//!
//! The frontseat's state: `offline` while the serial link is down or no data came for
//! `data_timeout` (10s); otherwise from the `$OSI` mode through the mode map — `accepting` (default
//! `N M m A W`), `in-control` (`P`), `idle` (`S` and anything unknown). Course, actuator and waypoint
//! commands are only sent while it is accepting or in control; a mission can be started while idle.
//! `version` is the Remote Helm major version (default 5): below 5, `$OMS` and `$OMW` depths are in
//! feet.

use super::protocol::{self, Command, DataRequest, DepthUnits, FromFront, MAX_TIMEOUT, Waypoint};
use crate::command_status::{self, command_status};
use crate::units::{FOOT, KNOT};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Format, Kind, LinkState, Message, Payload, Topic, Value};
use seabus_modules::geo::wrap360;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TICK, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use seabus_modules::{Catalogue, Params};
use std::collections::VecDeque;
use std::time::Duration;
use tokio::time::Instant;

/// The `iver2` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "iver2",
    kind: ModuleKind::Driver,
    summary: "Iver2/Iver3 frontseat over Remote Helm (serial NMEA)",
    build,
};

const REQUEST: TimerId = 1;

/// Who controls the vehicle, as the frontseat's mode says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// No link, or no data.
    Offline,
    /// The frontseat takes no backseat commands.
    Idle,
    /// The frontseat takes backseat commands.
    Accepting,
    /// The backseat is driving.
    InControl,
}

impl Control {
    /// The name in the vehicle-state dataset.
    pub fn name(self) -> &'static str {
        match self {
            Control::Offline => "offline",
            Control::Idle => "idle",
            Control::Accepting => "accepting",
            Control::InControl => "in-control",
        }
    }

    fn commandable(self) -> bool {
        matches!(self, Control::Accepting | Control::InControl)
    }
}

struct Topics {
    attitude: Topic,
    position: Topic,
    velocity: Topic,
    depth: Topic,
    altitude: Topic,
    battery: Topic,
    state: Topic,
    info: Topic,
    status: Topic,
    course: Topic,
    actuator: Topic,
    mission: Topic,
    gps: Topic,
    dvl: Topic,
}

struct Settings {
    units: DepthUnits,
    request: DataRequest,
    request_every: Duration,
    oms_timeout: f64,
    repeat: Duration,
    hold: Duration,
    max_pitch: f64,
    ack_timeout: Duration,
    data_timeout: Duration,
    info_every: Duration,
    accepting: Vec<String>,
    in_control: Vec<String>,
    fin_scale: f64,
    motor_scale: f64,
}

/// A command sent and not yet answered.
struct Pending {
    id: i64,
    command: &'static str,
    code: u32,
    sent: Instant,
    /// published on `cmd.status` (repeats of a course command are not)
    report: bool,
    request: Option<(String, u64)>,
}

/// The course being held.
struct Course {
    oms: Command,
    until: Instant,
    heading: f64,
    depth: f64,
    speed: f64,
}

struct Iver {
    s: Settings,
    t: Topics,
    last_data: Option<Instant>,
    mode: String,
    error: String,
    mission: String,
    waypoint: Option<i64>,
    control: Control,
    reason: String,
    course: Option<Course>,
    last_oms: Option<Instant>,
    pending: VecDeque<Pending>,
    next_id: i64,
    last_state: Option<(Control, String, String, Instant)>,
    heading: Option<f64>,
    /// When a `$C` last brought a depth.
    compass_depth_at: Option<Instant>,
    /// When an `$OPI` last brought a battery.
    opi_battery_at: Option<Instant>,
    /// The `vehicle.info` last published, and when.
    last_info: Option<(InfoKey, Instant)>,
    tally: Tally,
}

/// What makes `vehicle.info` change: name, version and flags (not the battery, which drifts).
#[derive(Debug, Clone, PartialEq)]
struct InfoKey {
    vehicle: String,
    version: String,
    srp: bool,
    flags: [bool; 2],
}

impl InfoKey {
    fn of(i: &protocol::Iver3Osi) -> InfoKey {
        InfoKey {
            vehicle: i.vehicle.clone(),
            version: i.version.clone(),
            srp: i.srp,
            flags: i.flags,
        }
    }
}

/// `vehicle.info` is due when it changed, or `every` has passed since it was last published.
fn info_due(
    last: Option<&(InfoKey, Instant)>,
    key: &InfoKey,
    now: Instant,
    every: Duration,
) -> bool {
    last.is_none_or(|(k, at)| k != key || now.duration_since(*at) >= every)
}

/// A value from `$OSI` stands in for a dedicated sentence's (`$C` depth, `$OPI` battery) when that
/// sentence has not brought one within `window`.
fn osi_stands_in(dedicated_at: Option<Instant>, now: Instant, window: Duration) -> bool {
    dedicated_at.is_none_or(|t| now.duration_since(t) > window)
}

fn words(s: &str) -> Vec<String> {
    s.split([' ', ','])
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

fn build(cfg: &ModuleConfig, cat: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let version: u32 = p.parse_or("version", 5, "a Remote Helm major version such as 5")?;
    let request = data_request(p)?;
    let (oms_timeout, repeat) = keep_alive(cfg)?;
    let t = topics(p, cat)?;
    let s = Settings {
        units: DepthUnits::of_version(version),
        request,
        request_every: p.duration_or("request_every", Duration::from_millis(500))?,
        oms_timeout,
        repeat,
        hold: p.duration_or("hold", Duration::from_secs(3))?,
        max_pitch: p.positive_or("max_pitch", 20.0)?,
        ack_timeout: p.duration_or("ack_timeout", Duration::from_secs(3))?,
        data_timeout: p.duration_or("data_timeout", Duration::from_secs(10))?,
        info_every: p.duration_or("info_every", Duration::from_secs(5))?,
        accepting: words(p.str("accepting").unwrap_or("N M m A W")),
        in_control: words(p.str("in_control").unwrap_or("P")),
        fin_scale: p.positive_or("fin_scale", 4.0)?,
        motor_scale: p.positive_or("motor_scale", 1.27)?,
    };
    Ok(Built {
        decl: declaration(p, &t),
        module: Box::new(Iver::new(s, t)),
    })
}

/// The `$OSD` data request from `request`: letters among G, C, S, P, D.
fn data_request(p: &Params) -> Result<DataRequest, FileError> {
    let letters = words(p.str("request").unwrap_or("G C S P"));
    let mut request = DataRequest::default();
    for l in &letters {
        match l.as_str() {
            "G" => request.gps = true,
            "C" => request.compass = true,
            "S" => request.state = true,
            "P" => request.power = true,
            "D" => request.dvl = true,
            other => {
                return Err(p
                    .required("request")?
                    .error(format!("`{other}` is not one of G, C, S, P, D")));
            }
        }
    }
    Ok(request)
}

/// `oms_timeout` (seconds) and `repeat`: the keep-alive each `$OMS` carries and how often a held
/// course is sent again, which must be sooner than the keep-alive lapses.
fn keep_alive(cfg: &ModuleConfig) -> Result<(f64, Duration), FileError> {
    let p = &cfg.params;
    let oms_timeout = p.positive_or("oms_timeout", 5.0)?;
    if oms_timeout > MAX_TIMEOUT {
        return Err(p
            .required("oms_timeout")?
            .error(format!("the frontseat takes 0 to {MAX_TIMEOUT} seconds")));
    }
    let repeat = p.duration_or("repeat", Duration::from_secs(1))?;
    if repeat.as_secs_f64() >= oms_timeout {
        let why = format!(
            "`repeat` ({:.1}s) must be shorter than `oms_timeout` ({oms_timeout}s), or the frontseat's keep-alive lapses",
            repeat.as_secs_f64()
        );
        return Err(match p.get("repeat").or_else(|| p.get("oms_timeout")) {
            Some(param) => param.error(why),
            None => cfg.pos.error(why),
        });
    }
    Ok((oms_timeout, repeat))
}

/// The topics it publishes on and the catalogue topics of the commands it takes.
fn topics(p: &Params, cat: &Catalogue) -> Result<Topics, FileError> {
    let topic = |name: &str, dataset: &str, fallback: &str| {
        p.dataset_topic_or(name, cat, dataset, fallback)
    };
    // the commands it takes arrive on the catalogue's topics
    let command = |dataset: &str, fallback: &str| p.dataset_topic(cat, dataset, fallback);
    Ok(Topics {
        attitude: topic("attitude_topic", "attitude", "nav.attitude")?,
        position: topic("position_topic", "position", "nav.position")?,
        velocity: topic("velocity_topic", "velocity", "nav.velocity")?,
        depth: topic("depth_topic", "depth", "nav.depth")?,
        altitude: topic("altitude_topic", "altitude", "nav.altitude")?,
        battery: topic("battery_topic", "battery", "power.battery")?,
        state: topic("state_topic", "vehicle-state", "vehicle.state")?,
        info: topic("info_topic", "vehicle-info", "vehicle.info")?,
        status: topic("status_topic", command_status::DATASET, "cmd.status")?,
        course: command("course-command", "cmd.course")?,
        actuator: command("actuator-command", "cmd.actuator")?,
        mission: command("mission-command", "cmd.mission")?,
        gps: p.topic_or("gps_topic", "nav.gps")?,
        dvl: p.topic_or("dvl_topic", "nav.dvl")?,
    })
}

/// Port 0 takes the frontseat's sentences; port 1 carries the datasets and the commands.
fn declaration(p: &Params, t: &Topics) -> Declaration {
    let mut decl = Declaration::new(ModuleKind::Driver)
        .format(0, Some(Format::Bytes))
        .consumes(TopicDecl::topic(p.str("input").unwrap_or("**")))
        .format(1, Some(Format::Map))
        .default_tick(Duration::from_millis(100));
    for (topic, dataset) in [
        (&t.attitude, "attitude"),
        (&t.position, "position"),
        (&t.velocity, "velocity"),
        (&t.depth, "depth"),
        (&t.altitude, "altitude"),
        (&t.battery, "battery"),
        (&t.state, "vehicle-state"),
        (&t.info, "vehicle-info"),
        (&t.status, command_status::DATASET),
        (&t.gps, "position"),
        (&t.dvl, "velocity"),
    ] {
        decl = decl.produces(TopicDecl::dataset(topic, dataset).on_port(1));
    }
    decl.accepts(TopicDecl::dataset(&t.course, "course-command").on_port(1))
        .accepts(TopicDecl::dataset(&t.actuator, "actuator-command").on_port(1))
        .accepts(TopicDecl::dataset(&t.mission, "mission-command").on_port(1))
        .accepts(
            TopicDecl::topic("cmd.iver.waypoint")
                .field("lat", "deg")
                .field("lon", "deg")
                .field("depth", "m")
                .field("speed", "m/s")
                .on_port(1),
        )
        .accepts(
            TopicDecl::topic("cmd.iver.position")
                .field("lat", "deg")
                .field("lon", "deg")
                .on_port(1),
        )
        .accepts(
            TopicDecl::topic("cmd.iver.dvl")
                .field("x", "m/s")
                .field("y", "m/s")
                .on_port(1),
        )
}

/// A fin angle as an `$OMP` byte around the neutral 0x80.
fn fin_byte(degrees: f64, scale: f64) -> u8 {
    (128.0 + degrees * scale).round().clamp(0.0, 255.0) as u8
}

impl Iver {
    /// A driver that has heard nothing from the frontseat yet.
    fn new(s: Settings, t: Topics) -> Iver {
        Iver {
            s,
            t,
            last_data: None,
            mode: String::new(),
            error: String::new(),
            mission: String::new(),
            waypoint: None,
            control: Control::Offline,
            reason: "no data from the frontseat yet".into(),
            course: None,
            last_oms: None,
            pending: VecDeque::new(),
            next_id: 1,
            last_state: None,
            heading: None,
            compass_depth_at: None,
            opi_battery_at: None,
            last_info: None,
            tally: Tally::new(),
        }
    }

    fn control_of(&self, mode: &str) -> Control {
        if self.s.in_control.iter().any(|m| m == mode) {
            Control::InControl
        } else if self.s.accepting.iter().any(|m| m == mode) {
            Control::Accepting
        } else {
            Control::Idle
        }
    }

    /// Works out the control state from the link, the data's age and the mode.
    fn update_control(&mut self, link: &LinkState, now: Instant) {
        let stale = self
            .last_data
            .is_none_or(|t| now.duration_since(t) > self.s.data_timeout);
        let (control, reason) = match link {
            LinkState::Down(why) => (Control::Offline, format!("serial link down: {why}")),
            LinkState::Up if stale => (
                Control::Offline,
                format!(
                    "no data from the frontseat for {:.0}s",
                    self.s.data_timeout.as_secs_f64()
                ),
            ),
            LinkState::Up => {
                let c = self.control_of(&self.mode);
                let reason = if c == Control::Idle {
                    format!(
                        "the frontseat is {} (mode {})",
                        protocol::mode_text(&self.mode),
                        self.mode
                    )
                } else {
                    String::new()
                };
                (c, reason)
            }
        };
        if control != self.control {
            tracing::info!(
                "frontseat {} -> {}{}",
                self.control.name(),
                control.name(),
                if reason.is_empty() {
                    String::new()
                } else {
                    format!(" ({reason})")
                }
            );
        }
        self.control = control;
        self.reason = reason;
    }

    async fn publish(&self, ctx: &Context, dataset: &str, topic: &Topic, map: DataMap) {
        if let Err(e) = ctx.dataset_on(1, Kind::Data, dataset, topic, map).await {
            self.tally.record(ctx.name(), "invalid-data", &e);
        }
    }

    /// Depth from the surface, given in feet (`$C`, or `$OSI` standing in for it).
    async fn publish_depth(&self, ctx: &Context, feet: f64) {
        let m = DataMap::new().with("depth", feet * FOOT);
        self.publish(ctx, "depth", &self.t.depth, m).await;
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

    /// Sends a command; with `report`, it is tracked on `cmd.status`.
    async fn send(
        &mut self,
        ctx: &Context,
        cmd: &Command,
        report: bool,
        request: Option<(String, u64)>,
    ) {
        let id = self.next_id;
        self.next_id += 1;
        let line = cmd.sentence(self.s.units);
        if let Err(e) = ctx
            .publish_on(
                0,
                Kind::Data,
                "iver.command",
                Payload::from(line.into_bytes()),
            )
            .await
        {
            if report {
                self.status(ctx, id, cmd.name(), "refused", &e.to_string(), &request)
                    .await;
            }
            return;
        }
        if report {
            self.status(ctx, id, cmd.name(), "pending", "", &request)
                .await;
        }
        self.pending.push_back(Pending {
            id,
            command: cmd.name(),
            code: cmd.ack_code(),
            sent: Instant::now(),
            report,
            request,
        });
    }

    async fn refuse(
        &mut self,
        ctx: &Context,
        command: &str,
        why: &str,
        request: Option<(String, u64)>,
    ) {
        let id = self.next_id;
        self.next_id += 1;
        self.tally.record(
            ctx.name(),
            "refused",
            format_args!("{command} refused: {why}"),
        );
        self.status(ctx, id, command, "refused", why, &request)
            .await;
    }

    async fn on_front(&mut self, ctx: &Context, line: &str) {
        let now = Instant::now();
        let parsed = match protocol::parse_front(line) {
            Ok(p) => p,
            Err(e) => {
                self.tally.record(ctx.name(), "unreadable", &e);
                return;
            }
        };
        self.last_data = Some(now);
        match parsed {
            FromFront::Osi(o) => self.on_osi(ctx, &o, now).await,
            FromFront::Compass(c) => self.on_compass(ctx, c).await,
            FromFront::Opi(p) => self.on_opi(ctx, p).await,
            FromFront::Ack(a) => self.on_ack(ctx, a).await,
            FromFront::Dvl(d) => self.on_dvl(ctx, d).await,
            FromFront::Rmc(r) => {
                if let (Some(lat), Some(lon)) = (r.lat, r.lon) {
                    let m = DataMap::new()
                        .with("lat", lat)
                        .with("lon", lon)
                        .with("source", Value::label("gps"));
                    self.publish(ctx, "position", &self.t.gps, m).await;
                }
            }
            FromFront::Other(addr) => {
                self.tally
                    .record(ctx.name(), "unknown-sentence", format_args!("${addr}"));
            }
        }
    }

    /// How long a `$C` depth or an `$OPI` battery keeps `$OSI` from standing in for it.
    fn stand_in_window(&self) -> Duration {
        self.s.request_every * 3
    }

    /// `$OSI`: the frontseat's mode, mission and error state, its position, velocity and altitude,
    /// depth and battery when no `$C` or `$OPI` brings them, `vehicle.info`, and the control state.
    async fn on_osi(&mut self, ctx: &Context, o: &protocol::Osi, now: Instant) {
        self.mode = o.mode.clone();
        self.error = o.error.clone();
        self.mission = o.mission.clone();
        self.waypoint = o.next_waypoint;
        if let (Some(lat), Some(lon)) = (o.lat, o.lon) {
            let m = DataMap::new()
                .with("lat", lat)
                .with("lon", lon)
                .with("source", Value::label("frontseat"));
            self.publish(ctx, "position", &self.t.position, m).await;
        }
        if let (Some(kn), Some(h)) = (o.speed_knots, o.heading) {
            self.heading = Some(h);
            let m = DataMap::new()
                .with("speed", kn * KNOT)
                .with("course", wrap360(h))
                .with("reference", Value::label("water"));
            self.publish(ctx, "velocity", &self.t.velocity, m).await;
        }
        if let Some(ft) = o.altimeter_feet {
            let m = DataMap::new()
                .with("altitude", (ft * FOOT).max(0.0))
                .with("valid", ft > 0.0);
            self.publish(ctx, "altitude", &self.t.altitude, m).await;
        }
        let window = self.stand_in_window();
        if osi_stands_in(self.compass_depth_at, now, window)
            && let Some(ft) = o.depth_feet
        {
            self.publish_depth(ctx, ft).await;
        }
        if osi_stands_in(self.opi_battery_at, now, window)
            && let Some(pc) = o.battery_percent()
        {
            self.publish(
                ctx,
                "battery",
                &self.t.battery,
                DataMap::new().with("percent", pc),
            )
            .await;
        }
        if let Some(i) = &o.iver3 {
            self.publish_info(ctx, i, now).await;
        }
        let link = ctx
            .port(0)
            .map_or(LinkState::Up, |p| p.medium().link_state());
        self.update_control(&link, now);
        self.publish_state(ctx).await;
    }

    /// `vehicle.info` from an Iver3 `$OSI`, when it changed or is due again.
    async fn publish_info(&mut self, ctx: &Context, i: &protocol::Iver3Osi, now: Instant) {
        let key = InfoKey::of(i);
        if !info_due(self.last_info.as_ref(), &key, now, self.s.info_every) {
            return;
        }
        let mut m = DataMap::new()
            .with("vehicle", i.vehicle.as_str())
            .with("version", i.version.as_str())
            .with("srp", i.srp)
            .with("flag_20", i.flags[0])
            .with("flag_21", i.flags[1]);
        if let Some(pc) = i.battery_percent {
            m.insert("battery", pc);
        }
        self.publish(ctx, "vehicle-info", &self.t.info, m).await;
        self.last_info = Some((key, now));
    }

    /// `$C`: attitude, and depth.
    async fn on_compass(&mut self, ctx: &Context, c: protocol::Compass) {
        self.heading = Some(c.heading);
        let mut m = DataMap::new()
            .with("yaw", wrap360(c.heading))
            .with("pitch", c.pitch)
            .with("roll", c.roll);
        if let Some(t) = c.temperature {
            m.insert("temperature", t);
        }
        self.publish(ctx, "attitude", &self.t.attitude, m).await;
        if let Some(ft) = c.depth_feet {
            self.compass_depth_at = Some(Instant::now());
            self.publish_depth(ctx, ft).await;
        }
    }

    /// `$OPI`: the battery.
    async fn on_opi(&mut self, ctx: &Context, p: protocol::Opi) {
        let Some(pc) = p.percent else {
            return;
        };
        self.opi_battery_at = Some(Instant::now());
        let mut m = DataMap::new().with("percent", pc);
        for (k, v) in [
            ("remaining", p.remaining_wh),
            ("power", p.power_w),
            ("voltage", p.volts),
            ("current", p.current),
            ("minutes", p.minutes),
        ] {
            if let Some(v) = v {
                m.insert(k, v);
            }
        }
        let state = match p.state.as_str() {
            "C" => "charging",
            "F" => "full",
            _ => "discharging",
        };
        m.insert("state", state);
        m.insert("leak", p.leak);
        self.publish(ctx, "battery", &self.t.battery, m).await;
    }

    /// `$DVL`: velocity over ground, turned from the vehicle's frame by the last heading.
    async fn on_dvl(&self, ctx: &Context, d: protocol::Dvl) {
        let (Some(vx), Some(vy)) = (d.vx, d.vy) else {
            return;
        };
        let speed = vx.hypot(vy);
        let heading = self.heading.unwrap_or(0.0);
        // +y is port in the vehicle's frame: starboard sway is -vy
        let course = wrap360(heading + (-vy).atan2(vx).to_degrees());
        let mut m = DataMap::new()
            .with("speed", speed)
            .with("course", course)
            .with("surge", vx)
            .with("sway", -vy)
            .with("reference", Value::label("ground"));
        if let Some(vz) = d.vz {
            m.insert("heave", vz);
        }
        self.publish(ctx, "velocity", &self.t.dvl, m).await;
    }

    async fn on_ack(&mut self, ctx: &Context, a: protocol::Ack) {
        let answered = self.pending.iter().position(|p| p.code == a.msg_type);
        let Some(p) = answered.and_then(|i| self.pending.remove(i)) else {
            self.tally.record(
                ctx.name(),
                "unexpected-ack",
                format_args!("$ACK for message type {}", a.msg_type),
            );
            return;
        };
        if a.status == 0 {
            if p.report {
                self.status(ctx, p.id, p.command, "acknowledged", "", &p.request)
                    .await;
            }
        } else {
            let text = format!("error {}: {}", a.error, protocol::error_text(a.error));
            self.tally.record(
                ctx.name(),
                "refused-by-frontseat",
                format_args!("the frontseat refused ${}: {text}", p.command),
            );
            // a refused repeat of a course is reported too: the course is not being held
            self.status(ctx, p.id, p.command, "refused", &text, &p.request)
                .await;
        }
    }

    /// Publishes the vehicle state when it changed, and at least once a second.
    async fn publish_state(&mut self, ctx: &Context) {
        let now = Instant::now();
        let changed = self
            .last_state
            .as_ref()
            .is_none_or(|(c, m, e, _)| *c != self.control || *m != self.mode || *e != self.error);
        let due = self
            .last_state
            .as_ref()
            .is_none_or(|(_, _, _, at)| now.duration_since(*at) >= Duration::from_secs(1));
        if !(changed || due) {
            return;
        }
        let mut m = DataMap::new()
            .with(
                "mode",
                if self.mode.is_empty() {
                    "unknown"
                } else {
                    self.mode.as_str()
                },
            )
            .with("control", self.control.name())
            .with("error", protocol::error_state_text(&self.error))
            .with("mission", self.mission.as_str())
            .with("reason", self.reason.as_str());
        if let Some(w) = self.waypoint.filter(|w| *w >= 0) {
            m.insert("waypoint", w);
        }
        if let Some(c) = &self.course {
            m.insert("commanded_heading", c.heading);
            m.insert("commanded_depth", c.depth);
            m.insert("commanded_speed", c.speed);
        }
        self.publish(ctx, "vehicle-state", &self.t.state, m).await;
        self.last_state = Some((self.control, self.mode.clone(), self.error.clone(), now));
    }

    async fn on_command(&mut self, ctx: &Context, msg: Message) {
        let Some(map) = msg.payload.as_map() else {
            return;
        };
        let request = Some(command_status::request(&msg));
        let topic = msg.topic.as_str();
        if topic == self.t.course.as_str() {
            self.on_course(ctx, map, request).await;
        } else if topic == self.t.actuator.as_str() {
            self.on_actuator(ctx, map, request).await;
        } else if topic == self.t.mission.as_str() {
            self.on_mission(ctx, map, request).await;
        } else if topic == "cmd.iver.waypoint" {
            self.on_waypoint(ctx, map, request).await;
        } else if topic == "cmd.iver.position" {
            self.on_position(ctx, map, request).await;
        } else if topic == "cmd.iver.dvl" {
            self.on_dvl_aid(ctx, map, request).await;
        }
    }

    /// A course command: a new course is sent as `$OMS` and reported; the same course again only
    /// keeps it held, and is sent when a repeat is due.
    async fn on_course(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        if let Err(e) = ctx.catalogue().validate("course-command", map) {
            return self.refuse(ctx, "OMS", &e.to_string(), request).await;
        }
        if !self.control.commandable() {
            let why = self.reason.clone();
            self.course = None;
            return self.refuse(ctx, "OMS", &why, request).await;
        }
        let f = |k: &str| map.get_f64(k);
        let (heading, depth, speed) = (
            f("heading").unwrap_or(0.0),
            f("depth").unwrap_or(0.0),
            f("speed").unwrap_or(0.0),
        );
        let hold = course_hold(f("timeout"), self.s.hold);
        let oms = Command::Oms {
            heading,
            depth,
            max_pitch: f("max_pitch").unwrap_or(self.s.max_pitch),
            speed_knots: speed / KNOT,
            timeout: self.s.oms_timeout,
        };
        // a new course is reported; the same course again only keeps it alive
        let same = self
            .course
            .as_ref()
            .is_some_and(|c| c.heading == heading && c.depth == depth && c.speed == speed);
        let due = self.last_oms.is_none_or(|t| t.elapsed() >= self.s.repeat);
        self.course = Some(Course {
            oms: oms.clone(),
            until: Instant::now() + hold,
            heading,
            depth,
            speed,
        });
        if !same || due {
            self.send(ctx, &oms, !same, request).await;
            self.last_oms = Some(Instant::now());
        }
    }

    /// An actuator command (thrust, rudder, elevator): `$OMP`.
    async fn on_actuator(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        if let Err(e) = ctx.catalogue().validate("actuator-command", map) {
            return self.refuse(ctx, "OMP", &e.to_string(), request).await;
        }
        if !self.control.commandable() {
            let why = self.reason.clone();
            return self.refuse(ctx, "OMP", &why, request).await;
        }
        let f = |k: &str| map.get_f64(k);
        let rudder = f("rudder").unwrap_or(0.0);
        let elevator = f("elevator").unwrap_or(0.0);
        let thrust = f("thrust").unwrap_or(0.0);
        let (fs, ms) = (self.s.fin_scale, self.s.motor_scale);
        let cmd = Command::Omp {
            bytes: [
                fin_byte(rudder, fs),
                fin_byte(rudder, fs),
                fin_byte(elevator, fs),
                fin_byte(elevator, fs),
                fin_byte(thrust, ms),
            ],
            timeout: f("timeout").unwrap_or(3.0).clamp(0.0, MAX_TIMEOUT),
        };
        self.send(ctx, &cmd, true, request).await;
    }

    /// A mission command: `start` → `$OMSTART`, `stop` or `abort` → `$OMSTOP` (which drops the
    /// course held), `goto` → `$OJW`. A mission can be started while the frontseat is idle.
    async fn on_mission(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        if let Err(e) = ctx.catalogue().validate("mission-command", map) {
            return self.refuse(ctx, "mission", &e.to_string(), request).await;
        }
        if self.control == Control::Offline {
            let why = self.reason.clone();
            return self.refuse(ctx, "mission", &why, request).await;
        }
        let cmd = match map.get_str("action").unwrap_or("") {
            "start" => Command::OmStart {
                ignore_gps: map.get_bool("ignore_gps").unwrap_or(false),
                ignore_sounder: map.get_bool("ignore_sounder").unwrap_or(false),
                ignore_pressure: map.get_bool("ignore_pressure").unwrap_or(false),
                mission_type: 0,
                mission: map.get_str("name").unwrap_or("").to_string(),
            },
            "stop" | "abort" => Command::OmStop,
            "goto" => match map.get_i64("waypoint").filter(|w| (0..=999).contains(w)) {
                Some(w) => Command::Ojw(w as u32),
                None => {
                    return self
                        .refuse(ctx, "OJW", "goto needs a waypoint from 0 to 999", request)
                        .await;
                }
            },
            other => {
                let why = format!(
                    "the Iver frontseat cannot `{other}` a mission (start, stop, abort, goto)"
                );
                return self.refuse(ctx, "mission", &why, request).await;
            }
        };
        if matches!(cmd, Command::OmStop) {
            self.course = None;
        }
        self.send(ctx, &cmd, true, request).await;
    }

    /// A waypoint (`cmd.iver.waypoint`): `$OMW`, or `$OMW,STOP` for action `stop`.
    async fn on_waypoint(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        if !self.control.commandable() {
            let why = self.reason.clone();
            return self.refuse(ctx, "OMW", &why, request).await;
        }
        let f = |k: &str| map.get_f64(k);
        let cmd = if map.get_str("action") == Some("stop") {
            Command::Omw(None)
        } else {
            match (f("lat"), f("lon")) {
                (Some(lat), Some(lon)) => Command::Omw(Some(Waypoint {
                    clear: map.get_bool("clear").unwrap_or(false),
                    lat,
                    lon,
                    depth: f("depth").unwrap_or(0.0),
                    speed_knots: f("speed").unwrap_or(1.0) / KNOT,
                })),
                _ => {
                    return self
                        .refuse(ctx, "OMW", "a waypoint needs lat and lon", request)
                        .await;
                }
            }
        };
        self.send(ctx, &cmd, true, request).await;
    }

    /// A position fix to inject (`cmd.iver.position`): `$OPOS`.
    async fn on_position(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        let f = |k: &str| map.get_f64(k);
        match (f("lat"), f("lon")) {
            (Some(lat), Some(lon)) => {
                let cmd = Command::Opos {
                    lat,
                    lon,
                    speed_knots: f("speed").unwrap_or(0.0) / KNOT,
                };
                self.send(ctx, &cmd, true, request).await;
            }
            _ => {
                self.refuse(ctx, "OPOS", "a position needs lat and lon", request)
                    .await
            }
        }
    }

    /// A velocity to inject (`cmd.iver.dvl`): `$ODVL`.
    async fn on_dvl_aid(&mut self, ctx: &Context, map: &DataMap, request: Option<(String, u64)>) {
        let f = |k: &str| map.get_f64(k);
        match (f("x"), f("y")) {
            (Some(x), Some(y)) => {
                let cmd = Command::Odvl {
                    x,
                    y,
                    timeout: f("timeout").unwrap_or(3.0).clamp(0.0, MAX_TIMEOUT),
                };
                self.send(ctx, &cmd, true, request).await;
            }
            _ => {
                self.refuse(ctx, "ODVL", "a velocity needs x and y", request)
                    .await
            }
        }
    }

    async fn on_tick(&mut self, ctx: &Context) {
        let now = Instant::now();
        let link = ctx
            .port(0)
            .map_or(LinkState::Up, |p| p.medium().link_state());
        self.update_control(&link, now);
        // keep the course alive while it is valid; let it lapse when commands stop
        if let Some(c) = &self.course {
            if now >= c.until {
                tracing::info!(
                    module = ctx.name(),
                    "course commands stopped; the frontseat's $OMS will time out"
                );
                self.course = None;
            } else if !self.control.commandable() {
                self.course = None;
            } else if self
                .last_oms
                .is_none_or(|t| now.duration_since(t) >= self.s.repeat)
            {
                let oms = c.oms.clone();
                self.send(ctx, &oms, false, None).await;
                self.last_oms = Some(now);
            }
        }
        // unanswered commands time out
        while let Some(p) = self.pending.front() {
            if now.duration_since(p.sent) < self.s.ack_timeout {
                break;
            }
            let Some(p) = self.pending.pop_front() else {
                break;
            };
            if p.report || p.command == "OMS" {
                let why = format!("no $ACK within {:.1}s", self.s.ack_timeout.as_secs_f64());
                self.status(ctx, p.id, p.command, "timed-out", &why, &p.request)
                    .await;
            }
        }
        self.publish_state(ctx).await;
    }
}

#[async_trait]
impl Module for Iver {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        ctx.every(REQUEST, self.s.request_every);
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        if port == 0 {
            if let Some(b) = msg.payload.as_bytes() {
                let line = String::from_utf8_lossy(b);
                self.on_front(ctx, &line).await;
            }
        } else {
            self.on_command(ctx, msg).await;
        }
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        match timer {
            TICK => self.on_tick(ctx).await,
            REQUEST => {
                let osd = Command::Osd(self.s.request.clone());
                self.send(ctx, &osd, false, None).await;
            }
            _ => {}
        }
        Ok(())
    }
}

/// How long a course is held: its own `timeout` (when it gives one), at most [`MAX_TIMEOUT`] —
/// a sender that dies never holds the vehicle on its course for longer — else `default`.
fn course_hold(timeout: Option<f64>, default: Duration) -> Duration {
    timeout
        .and_then(seabus_medium::parse::secs)
        .filter(|d| !d.is_zero())
        .map_or(default, |d| d.min(Duration::from_secs_f64(MAX_TIMEOUT)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_course_is_held_for_its_own_timeout_at_most_two_minutes() {
        let three = Duration::from_secs(3);
        assert_eq!(course_hold(None, three), three);
        assert_eq!(course_hold(Some(0.0), three), three);
        assert_eq!(course_hold(Some(-1.0), three), three);
        assert_eq!(course_hold(Some(30.0), three), Duration::from_secs(30));
        assert_eq!(course_hold(Some(1e9), three), Duration::from_secs(120));
    }

    #[test]
    fn osi_stands_in_only_when_the_dedicated_sentence_is_quiet() {
        let now = Instant::now();
        let window = Duration::from_millis(1500);
        // never heard ($C not requested, or never answered): $OSI gives the value
        assert!(osi_stands_in(None, now, window));
        // heard recently: $OSI stays quiet
        assert!(!osi_stands_in(Some(now), now, window));
        assert!(!osi_stands_in(
            Some(now - Duration::from_millis(1500)),
            now,
            window
        ));
        // gone quiet for longer than the window: $OSI takes over again
        assert!(osi_stands_in(
            Some(now - Duration::from_millis(1501)),
            now,
            window
        ));
    }

    #[test]
    fn vehicle_info_is_due_on_change_or_after_its_period() {
        let now = Instant::now();
        let every = Duration::from_secs(5);
        let key = InfoKey {
            vehicle: "iver3-3082".into(),
            version: "5.4".into(),
            srp: false,
            flags: [true, false],
        };
        assert!(info_due(None, &key, now, every));
        let last = (key.clone(), now - Duration::from_secs(1));
        assert!(!info_due(Some(&last), &key, now, every));
        let srp = InfoKey {
            srp: true,
            ..key.clone()
        };
        assert!(info_due(Some(&last), &srp, now, every));
        let renamed = InfoKey {
            vehicle: "other".into(),
            ..key.clone()
        };
        assert!(info_due(Some(&last), &renamed, now, every));
        let old = (key.clone(), now - every);
        assert!(info_due(Some(&old), &key, now, every));
    }

    #[test]
    fn fin_bytes_are_centred_and_clamped() {
        assert_eq!(fin_byte(0.0, 4.0), 0x80);
        assert_eq!(fin_byte(10.0, 4.0), 0xA8);
        assert_eq!(fin_byte(-10.0, 4.0), 0x58);
        assert_eq!(fin_byte(100.0, 4.0), 0xFF);
        assert_eq!(fin_byte(100.0, 1.27), 0xFF);
        assert_eq!(fin_byte(-100.0, 1.27), 0x01);
    }
}
