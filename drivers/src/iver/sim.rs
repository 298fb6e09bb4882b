//! `iver2-sim`: a simulated Iver2 frontseat. It answers a backseat over Remote Helm on its first
//! medium (a `pty://` or a serial line) and, when placed on a second medium, sends NMEA GPS and
//! compass sentences there too.
//!
//! Behaviour: it starts stopped (mode `S`). `$OMSTART` starts a mission (mode `N`: the vehicle holds
//! its heading at `mission_speed`). A valid `$OMS` while a mission runs hands control to the
//! backseat (mode `backseat_mode`, default `P`): heading, depth and speed follow the command; when
//! `$OMS` stops arriving for its timeout, the vehicle stops (mode `S`). `$OMP` drives the fins and
//! motor directly for its timeout (mode `A`). `$OMSTOP` stops. `$OJW` sets the next waypoint, `$OMW`
//! steers to a point, `$OPOS` moves the vehicle, `$ODVL` is acknowledged. Each command gets an `$ACK`
//! (error 20, 21, 27, 30 for bad values; 45 when no mission runs); an `$OSD` is answered with the
//! asked sentences in the order G, C, S, P, D, then its `$ACK`.
//!
//! Parameters: `lat`, `lon`, `heading`, `autostart` (start with the mission running, false),
//! `version` (Remote Helm major version, 5), `osi` (the `$OSI` form: `iver3`, 21 fields with the
//! battery, SRP flag, vehicle name `iver2-sim` and version; or `iver2`, the short 15-field form;
//! `iver3` from version 5 on, else `iver2`), `mission`
//! (`demo.mis`), `mission_speed` (m/s, 1), `backseat_mode` (`P`), `battery` (Wh, 600),
//! `water_depth` (m, 40), `declination` (deg, 0), faults: `noise` (standard deviation of sensor
//! noise, degrees and metres, 0), `garbage` (chance, per reply, of a line of junk first, 0; needs
//! `framing=lines` on the simulator's medium), `silence_every` / `silence_for` (the link goes quiet:
//! no replies, nothing read), and `gps_rate` (NMEA GPS sentences per second on the second medium, 1).

use super::protocol::{
    self, Ack, Command, Compass, DataRequest, DepthUnits, Dvl, Iver3Osi, MAX_TIMEOUT, Opi, Osi,
    Waypoint,
};
use crate::nmea::sentence::build;
use crate::sim::kinematics::{Limits, Setpoint, Vehicle};
use crate::units::{FOOT, KNOT};
use async_trait::async_trait;
use seabus_medium::framing::{ChecksumPolicy, check_nmea};
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{Format, Kind, Message, Payload, Stamp};
use seabus_modules::Catalogue;
use seabus_modules::geo::{offset, wrap180, wrap360};
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TICK, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::time::Duration;
use tokio::time::Instant;

/// The `iver2-sim` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "iver2-sim",
    kind: ModuleKind::Driver,
    summary: "a simulated Iver2 frontseat (Remote Helm), with NMEA GPS and compass",
    build,
};

const GPS: TimerId = 1;

/// What drives the vehicle now.
#[derive(Debug, Clone, PartialEq)]
enum Drive {
    /// Stopped.
    Stopped,
    /// A mission: hold the heading at mission speed.
    Mission { heading: f64 },
    /// The backseat's `$OMS`, until it lapses.
    Backseat { sp: Setpoint, until: Instant },
    /// Direct fins and motor, until they lapse.
    Servo {
        speed: f64,
        turn: f64,
        until: Instant,
    },
    /// Steering to a point (`$OMW`).
    ToPoint {
        lat: f64,
        lon: f64,
        depth: f64,
        speed: f64,
    },
}

struct Sim {
    v: Vehicle,
    limits: Limits,
    units: DepthUnits,
    version: u32,
    /// `$OSI` in the 21-field Iver3 form, else the short one.
    iver3_osi: bool,
    drive: Drive,
    mission: String,
    mission_speed: f64,
    backseat_mode: String,
    waypoint: i64,
    water_depth: f64,
    declination: f64,
    noise: f64,
    garbage: f64,
    silence: Option<(Duration, Duration)>,
    gps_rate: Option<Duration>,
    last_step: Instant,
    started: Instant,
    rng: fastrand::Rng,
    tally: Tally,
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let decl = Declaration::new(ModuleKind::Driver)
        .format(0, Some(Format::Bytes))
        .consumes(TopicDecl::topic("**"))
        .produces(TopicDecl::topic("iver.frontseat"))
        .default_tick(Duration::from_millis(100));
    Ok(Built {
        decl,
        module: Box::new(Sim::new(&cfg.params)?),
    })
}

impl Sim {
    /// A simulator from its parameters.
    fn new(p: &seabus_modules::Params) -> Result<Sim, FileError> {
        let version: u32 = p.parse_or("version", 5, "a Remote Helm major version such as 5")?;
        let garbage = p.non_negative_or("garbage", 0.0)?;
        if garbage > 1.0 {
            return Err(p.required("garbage")?.error("is a chance, from 0 to 1"));
        }
        let silence = match (p.get("silence_every"), p.get("silence_for")) {
            (None, None) => None,
            (Some(_), Some(_)) => Some((
                p.duration_or("silence_every", Duration::ZERO)?,
                p.duration_or("silence_for", Duration::ZERO)?,
            ))
            .filter(|(e, f)| !e.is_zero() && !f.is_zero()),
            (Some(x), None) | (None, Some(x)) => {
                return Err(x.error("give both silence_every and silence_for"));
            }
        };
        let gps_rate = p.positive_or("gps_rate", 1.0)?;
        let iver3_osi = match p.get("osi") {
            None => version >= 5,
            Some(param) => match param.value.as_str() {
                "iver3" => true,
                "iver2" => false,
                other => return Err(param.error(format!("`{other}` is not iver2 or iver3"))),
            },
        };
        let now = Instant::now();
        Ok(Sim {
            v: Vehicle::at(
                p.float_or("lat", 43.5081)?,
                p.float_or("lon", 16.4402)?,
                p.float_or("heading", 0.0)?,
                p.positive_or("battery", 600.0)?,
            ),
            limits: Limits::default(),
            units: DepthUnits::of_version(version),
            version,
            iver3_osi,
            drive: if p.flag_or("autostart", false)? {
                Drive::Mission {
                    heading: p.float_or("heading", 0.0)?,
                }
            } else {
                Drive::Stopped
            },
            mission: p.str("mission").unwrap_or("demo.mis").to_string(),
            mission_speed: p.non_negative_or("mission_speed", 1.0)?,
            backseat_mode: p.str("backseat_mode").unwrap_or("P").to_string(),
            waypoint: 1,
            water_depth: p.positive_or("water_depth", 40.0)?,
            declination: p.float_or("declination", 0.0)?,
            noise: p.non_negative_or("noise", 0.0)?,
            garbage,
            silence,
            gps_rate: seabus_medium::parse::rate_period(gps_rate),
            last_step: now,
            started: now,
            rng: fastrand::Rng::new(),
            tally: Tally::new(),
        })
    }
}

/// The `$ACK` of a command: accepted, or refused with an error number.
fn ack(c: &Command, taken: Result<(), u32>) -> String {
    let (status, error) = match taken {
        Ok(()) => (0, 0),
        Err(n) => (1, n),
    };
    Ack {
        msg_type: c.ack_code(),
        status,
        error,
    }
    .sentence()
}

/// The answer to a sentence that does not read as a command: a known command with bad fields gets
/// its error; anything else is ignored.
fn unreadable_command(line: &str) -> Vec<String> {
    let addr = protocol::address(line);
    let error = match addr {
        "OMS" => Some(20),
        "OMP" => Some(21),
        "OSD" | "OJW" => Some(27),
        "OMSTART" => Some(30),
        _ => None,
    };
    match (protocol::ack_code(addr), error) {
        (Some(msg_type), Some(error)) => vec![
            Ack {
                msg_type,
                status: 1,
                error,
            }
            .sentence(),
        ],
        _ => Vec::new(),
    }
}

impl Sim {
    fn mode(&self) -> &str {
        match &self.drive {
            Drive::Stopped => "S",
            Drive::Mission { .. } => "N",
            Drive::Backseat { .. } | Drive::ToPoint { .. } => &self.backseat_mode,
            Drive::Servo { .. } => "A",
        }
    }

    fn running(&self) -> bool {
        !matches!(self.drive, Drive::Stopped)
    }

    fn silent(&self, now: Instant) -> bool {
        match self.silence {
            None => false,
            Some((every, len)) => {
                let t = now.duration_since(self.started).as_secs_f64();
                t % every.as_secs_f64() >= every.as_secs_f64() - len.as_secs_f64()
            }
        }
    }

    /// Gaussian-like noise of the configured size.
    fn noisy(&mut self, x: f64) -> f64 {
        if self.noise == 0.0 {
            return x;
        }
        let n: f64 = (0..6).map(|_| self.rng.f64() - 0.5).sum::<f64>() * std::f64::consts::SQRT_2;
        x + n * self.noise
    }

    /// Answers one backseat sentence with the lines to send back.
    fn answer(&mut self, line: &str, now: Instant) -> Vec<String> {
        let cmd = match protocol::parse_command(line, self.units) {
            Ok(c) => c,
            Err(e) => {
                self.tally.record("iver2-sim", "bad-command", &e);
                return unreadable_command(line);
            }
        };
        let taken = match &cmd {
            Command::Osd(r) => {
                let mut out = self.data_lines(r);
                out.push(ack(&cmd, Ok(())));
                return out;
            }
            Command::Oms {
                heading,
                depth,
                speed_knots,
                timeout,
                ..
            } => self.take_oms(*heading, *depth, *speed_knots, *timeout, now),
            Command::Omp { bytes, timeout } => self.take_omp(bytes, *timeout, now),
            Command::OmStart { mission, .. } => {
                if !mission.is_empty() {
                    self.mission = mission.clone();
                }
                self.waypoint = 1;
                self.drive = Drive::Mission {
                    heading: self.v.heading,
                };
                Ok(())
            }
            Command::OmStop => {
                self.drive = Drive::Stopped;
                Ok(())
            }
            Command::Ojw(wp) => self.take_ojw(*wp),
            Command::Omw(w) => self.take_omw(w.as_ref()),
            Command::Opos { lat, lon, .. } => self.take_position(*lat, *lon),
            Command::Odvl { .. } => Ok(()),
        };
        vec![ack(&cmd, taken)]
    }

    /// Error 45 unless a mission runs.
    fn mission_running(&self) -> Result<(), u32> {
        if self.running() { Ok(()) } else { Err(45) }
    }

    /// The sentences an `$OSD` asks for, in the order G, C, S, P, D.
    fn data_lines(&mut self, r: &DataRequest) -> Vec<String> {
        let mut out = Vec::new();
        if r.gps {
            out.push(self.rmc_line());
        }
        if r.compass {
            out.push(self.compass_line());
        }
        if r.state {
            out.push(self.osi_line());
        }
        if r.power {
            out.push(self.opi_line());
        }
        if r.dvl {
            out.push(self.dvl_line());
        }
        out
    }

    /// `$OMS`: the backseat drives until the timeout (a negative depth is a height above the
    /// bottom); error 20 for values out of range, 45 when no mission runs.
    fn take_oms(
        &mut self,
        heading: f64,
        depth: f64,
        speed_knots: f64,
        timeout: f64,
        now: Instant,
    ) -> Result<(), u32> {
        let valid = (0.0..=360.0).contains(&heading)
            && (-100.0..=100.0).contains(&depth)
            && (0.0..=10.0).contains(&speed_knots)
            && (0.0..=MAX_TIMEOUT).contains(&timeout);
        if !valid {
            return Err(20);
        }
        self.mission_running()?;
        let depth = if depth < 0.0 {
            (self.water_depth + depth).max(0.0)
        } else {
            depth
        };
        self.drive = Drive::Backseat {
            sp: Setpoint {
                heading,
                depth,
                speed: speed_knots * KNOT,
            },
            until: now + Duration::from_secs_f64(timeout),
        };
        Ok(())
    }

    /// `$OMP`: fins and motor drive directly until the timeout; error 45 when no mission runs, 21
    /// for a timeout out of range.
    fn take_omp(&mut self, bytes: &[u8; 5], timeout: f64, now: Instant) -> Result<(), u32> {
        self.mission_running()?;
        if !(0.0..=MAX_TIMEOUT).contains(&timeout) {
            return Err(21);
        }
        let motor = f64::from(bytes[4]) - 128.0;
        let yaw = (f64::from(bytes[0]) + f64::from(bytes[1])) / 2.0 - 128.0;
        self.drive = Drive::Servo {
            speed: (motor / 127.0).max(0.0) * self.limits.max_speed,
            turn: yaw / 4.0,
            until: now + Duration::from_secs_f64(timeout),
        };
        Ok(())
    }

    /// `$OJW`: the next waypoint; error 45 when no mission runs.
    fn take_ojw(&mut self, wp: u32) -> Result<(), u32> {
        self.mission_running()?;
        self.waypoint = i64::from(wp);
        Ok(())
    }

    /// `$OMW`: steer to a point, or back to the mission for `$OMW,STOP`; error 45 when no mission
    /// runs.
    fn take_omw(&mut self, w: Option<&Waypoint>) -> Result<(), u32> {
        self.mission_running()?;
        self.drive = match w {
            None => Drive::Mission {
                heading: self.v.heading,
            },
            Some(w) => Drive::ToPoint {
                lat: w.lat,
                lon: w.lon,
                depth: w.depth.max(0.0),
                speed: w.speed_knots * KNOT,
            },
        };
        Ok(())
    }

    /// `$OPOS`: the vehicle moves to the position; error 6 for one off the globe.
    fn take_position(&mut self, lat: f64, lon: f64) -> Result<(), u32> {
        if (-90.0..=90.0).contains(&lat) && (-180.0..=180.0).contains(&lon) {
            self.v.lat = lat;
            self.v.lon = lon;
            Ok(())
        } else {
            Err(6)
        }
    }

    /// Advances the vehicle; a timed command that lapsed stops it.
    fn step(&mut self, now: Instant) {
        let dt = now.duration_since(self.last_step).as_secs_f64().min(1.0);
        self.last_step = now;
        let target = match &self.drive {
            Drive::Stopped => None,
            Drive::Mission { heading } => Some(Setpoint {
                heading: *heading,
                depth: 0.0,
                speed: self.mission_speed,
            }),
            Drive::Backseat { sp, until } => {
                if now >= *until {
                    tracing::info!("simulated frontseat: $OMS timed out, stopping");
                    self.drive = Drive::Stopped;
                    None
                } else {
                    Some(*sp)
                }
            }
            Drive::Servo { speed, turn, until } => {
                if now >= *until {
                    self.drive = Drive::Stopped;
                    None
                } else {
                    Some(Setpoint {
                        heading: self.v.heading + turn,
                        depth: self.v.depth,
                        speed: *speed,
                    })
                }
            }
            Drive::ToPoint {
                lat,
                lon,
                depth,
                speed,
            } => {
                let (n, e) = offset(self.v.lat, self.v.lon, *lat, *lon);
                if n.hypot(e) < 5.0 {
                    self.drive = Drive::Mission {
                        heading: self.v.heading,
                    };
                    None
                } else {
                    Some(Setpoint {
                        heading: wrap360(e.atan2(n).to_degrees()),
                        depth: *depth,
                        speed: *speed,
                    })
                }
            }
        };
        self.v.step(dt, target, &self.limits);
    }

    fn secs_of_day() -> f64 {
        Stamp::now().as_secs_f64().rem_euclid(86_400.0)
    }

    fn rmc_line(&mut self) -> String {
        let (lat, lon) = (
            self.noisy(self.v.lat * 1e5) / 1e5,
            self.noisy(self.v.lon * 1e5) / 1e5,
        );
        let course = self.v.heading;
        build::rmc(
            "GP",
            Self::secs_of_day(),
            "211126",
            lat,
            lon,
            self.v.speed,
            course,
        )
    }

    fn compass_line(&mut self) -> String {
        Compass {
            heading: wrap360(self.noisy(self.v.heading)),
            pitch: self.noisy(self.v.pitch).clamp(-90.0, 90.0),
            roll: wrap180(self.noisy(self.v.roll)),
            temperature: Some(18.5),
            depth_feet: Some(self.noisy(self.v.depth).max(0.0) / FOOT),
        }
        .sentence()
    }

    fn osi_line(&mut self) -> String {
        let altitude_ft = (self.water_depth - self.v.depth).max(0.0) / FOOT;
        let iver3 = self.iver3_osi.then(|| Iver3Osi {
            battery_percent: Some(self.v.percent().round().clamp(0.0, 100.0)),
            srp: false,
            vehicle: "iver2-sim".into(),
            version: format!("{}.0", self.version),
            flags: [false, false],
        });
        Osi {
            fins: "8080808080".into(),
            mode: self.mode().to_string(),
            next_waypoint: Some(self.waypoint),
            lat: Some(self.v.lat),
            lon: Some(self.v.lon),
            speed_knots: Some(self.v.speed / KNOT),
            distance_to_waypoint: Some(0.0),
            error: "N".into(),
            altimeter_feet: Some(self.noisy(altitude_ft).max(0.0)),
            park_time: Some(0.0),
            declination: Some(self.declination),
            mission: self.mission.clone(),
            remaining: Some(0.0),
            heading: Some(self.v.heading),
            depth_feet: Some(self.v.depth / FOOT),
            iver3,
            extra: Vec::new(),
        }
        .sentence()
    }

    fn opi_line(&self) -> String {
        let power = self.v.power();
        Opi {
            percent: Some(self.v.percent()),
            remaining_wh: Some(self.v.energy),
            power_w: Some(power),
            volts: Some(14.0 + 2.8 * self.v.percent() / 100.0),
            current: Some(-power / 15.0),
            minutes: Some(self.v.energy / power.max(0.1) * 60.0),
            state: "D".into(),
            leak: false,
        }
        .sentence()
    }

    fn dvl_line(&self) -> String {
        let bottom_lock = self.water_depth - self.v.depth < 80.0;
        Dvl {
            vx: Some(self.v.speed),
            vy: Some(0.0),
            vz: Some(self.v.vertical_speed),
            xdist: None,
            ydist: None,
            depth: Some(self.v.depth),
            altitude: bottom_lock.then_some(self.water_depth - self.v.depth),
        }
        .sentence()
    }

    async fn send_lines(&mut self, ctx: &Context, port: usize, lines: Vec<String>) {
        for line in lines {
            // junk goes on the Remote Helm line only (the NMEA line takes sentences alone)
            if port == 0 && self.garbage > 0.0 && self.rng.f64() < self.garbage {
                let junk = "\u{1}#~garbage~".to_string();
                if let Err(e) = ctx
                    .publish_on(
                        port,
                        Kind::Data,
                        "iver.frontseat",
                        Payload::from(junk.into_bytes()),
                    )
                    .await
                {
                    self.tally.record(ctx.name(), "garbage-not-sent", &e);
                }
            }
            if let Err(e) = ctx
                .publish_on(
                    port,
                    Kind::Data,
                    "iver.frontseat",
                    Payload::from(line.into_bytes()),
                )
                .await
            {
                self.tally.record(ctx.name(), "send-failed", &e);
            }
        }
    }
}

#[async_trait]
impl Module for Sim {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        if self.garbage > 0.0 {
            tracing::info!(
                module = ctx.name(),
                "the simulated frontseat puts a line of junk before {:.1} % of its replies \
                 (`garbage`): the backseat rejects and counts them",
                self.garbage * 100.0
            );
        }
        if ctx.ports() > 1
            && let Some(p) = self.gps_rate
        {
            ctx.every(GPS, p);
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let now = Instant::now();
        if port != 0 || self.silent(now) {
            return Ok(());
        }
        let Some(bytes) = msg.payload.as_bytes() else {
            return Ok(());
        };
        // a lines-framed medium hands over raw lines: check them like an NMEA framer would
        let line = match check_nmea(bytes, ChecksumPolicy::Require) {
            Ok(l) => String::from_utf8_lossy(&l).into_owned(),
            Err(r) => {
                self.tally
                    .record(ctx.name(), r.reason(), "a line from the backseat");
                return Ok(());
            }
        };
        let replies = self.answer(&line, now);
        self.send_lines(ctx, 0, replies).await;
        Ok(())
    }

    async fn on_timer(&mut self, ctx: &mut Context, timer: TimerId) -> Result<(), ModuleError> {
        let now = Instant::now();
        match timer {
            TICK => self.step(now),
            GPS if !self.silent(now) => {
                let (lat, lon) = (
                    self.noisy(self.v.lat * 1e5) / 1e5,
                    self.noisy(self.v.lon * 1e5) / 1e5,
                );
                let surfaced = self.v.depth < 0.5;
                let t = Self::secs_of_day();
                let heading = self.noisy(self.v.heading);
                let (pitch, roll) = (self.noisy(self.v.pitch), self.noisy(self.v.roll));
                let mut lines = vec![build::gga(
                    "GP",
                    t,
                    lat,
                    lon,
                    surfaced,
                    if surfaced { 9 } else { 0 },
                )];
                if surfaced {
                    lines.push(build::rmc(
                        "GP",
                        t,
                        "211126",
                        lat,
                        lon,
                        self.v.speed,
                        self.v.heading,
                    ));
                }
                lines.push(build::hdg(
                    "HC",
                    wrap360(heading - self.declination),
                    0.0,
                    self.declination,
                ));
                lines.push(build::xdr_pitch_roll("HC", pitch, roll));
                self.send_lines(ctx, 1, lines).await;
            }
            _ => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use seabus_medium::framing::nmea_sentence;
    use seabus_modules::Params;

    fn sim() -> Sim {
        Sim::new(&Params::from_pairs(&[])).unwrap()
    }

    fn acks(lines: &[String]) -> Vec<Ack> {
        lines
            .iter()
            .filter_map(|l| match protocol::parse_front(l) {
                Ok(protocol::FromFront::Ack(a)) => Some(a),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn osd_is_answered_in_order_with_its_ack_last() {
        let mut s = sim();
        let out = s.answer(&nmea_sentence(b'$', "OSD,G,C,S,P,,,,"), Instant::now());
        let addrs: Vec<&str> = out.iter().map(|l| protocol::address(l)).collect();
        assert_eq!(addrs, ["GPRMC", "C", "OSI", "OPI", "ACK"]);
        assert_eq!(
            acks(&out),
            [Ack {
                msg_type: 8,
                status: 0,
                error: 0
            }]
        );
        let out = s.answer(&nmea_sentence(b'$', "OSD,Q,,,,,,,"), Instant::now());
        assert_eq!(
            acks(&out),
            [Ack {
                msg_type: 8,
                status: 1,
                error: 27
            }]
        );
    }

    #[test]
    fn osi_comes_in_the_iver3_or_the_short_form() {
        let osi = |pairs: &[(&str, &str)]| {
            let mut s = Sim::new(&Params::from_pairs(pairs)).unwrap();
            let line = s.osi_line();
            match protocol::parse_front(&line) {
                Ok(protocol::FromFront::Osi(o)) => (protocol::fields(&line).len(), *o),
                other => panic!("{line}: {other:?}"),
            }
        };
        let (n, o) = osi(&[]);
        assert_eq!(n, 21);
        let i = o.iver3.unwrap();
        assert_eq!(
            (i.vehicle.as_str(), i.version.as_str(), i.battery_percent),
            ("iver2-sim", "5.0", Some(100.0))
        );
        let (n, o) = osi(&[("osi", "iver2")]);
        assert_eq!((n, o.iver3), (15, None));
        let (n, o) = osi(&[("version", "4")]);
        assert_eq!((n, o.iver3), (15, None));
        let e = Sim::new(&Params::from_pairs(&[("osi", "iver4")]))
            .err()
            .unwrap();
        assert!(
            e.to_string().contains("`iver4` is not iver2 or iver3"),
            "{e}"
        );
    }

    #[test]
    fn oms_needs_a_running_mission_and_valid_values_and_lapses() {
        let mut s = sim();
        let now = Instant::now();
        let oms = |body: &str| nmea_sentence(b'$', body);
        assert_eq!(
            acks(&s.answer(&oms("OMS,90.0,2.0,20.0,2.0,5"), now)),
            [Ack {
                msg_type: 9,
                status: 1,
                error: 45
            }]
        );
        assert_eq!(
            acks(&s.answer(&oms("OMSTART,0,0,0,0,m.mis"), now)),
            [Ack {
                msg_type: 3,
                status: 0,
                error: 0
            }]
        );
        assert_eq!(s.mode(), "N");
        assert_eq!(
            acks(&s.answer(&oms("OMS,400.0,2.0,20.0,2.0,5"), now)),
            [Ack {
                msg_type: 9,
                status: 1,
                error: 20
            }]
        );
        assert_eq!(
            acks(&s.answer(&oms("OMS,90.0,2.0,20.0,2.0,200"), now)),
            [Ack {
                msg_type: 9,
                status: 1,
                error: 20
            }]
        );
        assert_eq!(
            acks(&s.answer(&oms("OMS,90.0,2.0,20.0,2.0,5"), now)),
            [Ack {
                msg_type: 9,
                status: 0,
                error: 0
            }]
        );
        assert_eq!(s.mode(), "P");
        // the vehicle follows
        let mut t = now;
        for _ in 0..40 {
            t += Duration::from_millis(100);
            s.step(t);
        }
        assert!(s.v.heading > 20.0 && s.v.speed > 0.5, "{:?}", s.v);
        // five seconds without another $OMS: stopped
        for _ in 0..20 {
            t += Duration::from_millis(100);
            s.step(t);
        }
        assert_eq!(s.mode(), "S");
    }
}
