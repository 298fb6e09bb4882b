//! The vehicles a MAVLink medium hears, from their heartbeats, and the medium's link state that
//! follows from them.
//!
//! A vehicle is a component whose HEARTBEAT names an autopilot (anything but
//! `MAV_AUTOPILOT_INVALID`, which ground stations, companion computers, cameras and gimbals
//! send). For each one, by system and component id, the medium keeps its type, autopilot, whether
//! it is armed, its base and custom mode, its system status and when it was last heard, and
//! publishes them on [`TOPIC`] (one datamap per vehicle) when something but the time changes —
//! it appears, arms or disarms, changes mode, type or status, goes silent or comes back — and
//! every [`REPEAT`] besides.
//!
//! The link is up while some vehicle's heartbeat has been heard within the medium's `timeout`,
//! down otherwise. This is a plain state machine without a clock: it is told every heartbeat
//! and asked at the instants it names ([`Vehicles::next_deadline`]).

use seabus_medium::datamap::{DataMap, Value};
use seabus_medium::medium::LinkState;
use std::collections::BTreeMap;
use std::time::{Duration, Instant, SystemTime};

/// The topic of the vehicles list.
pub const TOPIC: &str = "mavlink.vehicles";

/// How often the whole list is published even when nothing changed.
pub const REPEAT: Duration = Duration::from_secs(5);

/// How many vehicles are kept; the one heard least recently is forgotten for a new one.
pub const MAX_VEHICLES: usize = 256;

/// What a heartbeat says of its sender.
#[derive(Debug, Clone, PartialEq, Eq)]
struct State {
    mav_type: String,
    autopilot: String,
    armed: bool,
    base_mode: String,
    custom_mode: i64,
    system_status: String,
}

#[derive(Debug, Clone)]
struct Vehicle {
    state: State,
    heard: Instant,
    heard_wall: SystemTime,
    alive: bool,
}

/// The vehicles heard, and the link state.
#[derive(Debug)]
pub struct Vehicles {
    timeout: Duration,
    known: BTreeMap<(u32, u8), Vehicle>,
    up: bool,
    /// why the link is down when no vehicle was lost (nothing heard yet, the wire lost)
    down: String,
    next_repeat: Instant,
}

/// What changed at an instant: the vehicles to publish, and the link's new state.
#[derive(Debug, Default, PartialEq)]
pub struct Changes {
    /// The datamaps of the vehicles to publish on [`TOPIC`].
    pub publish: Vec<DataMap>,
    /// The link's state, when it changed.
    pub link: Option<LinkState>,
}

const ARMED: &str = "MAV_MODE_FLAG_SAFETY_ARMED";
const NO_AUTOPILOT: &str = "MAV_AUTOPILOT_INVALID";

impl Vehicles {
    /// No vehicle heard yet, at `now`; a vehicle is alive while heard within `timeout`. The link
    /// starts down for `why`.
    pub fn new(timeout: Duration, now: Instant, why: impl Into<String>) -> Vehicles {
        Vehicles {
            timeout,
            known: BTreeMap::new(),
            up: false,
            down: why.into(),
            next_repeat: now + REPEAT,
        }
    }

    /// A HEARTBEAT from system `sysid`, component `compid` with fields `hb` (as
    /// [`crate::convert`] reads them), heard at `now` (`wall`: the same instant on the clock).
    pub fn heartbeat(
        &mut self,
        sysid: u32,
        compid: u8,
        hb: &DataMap,
        now: Instant,
        wall: SystemTime,
    ) -> Changes {
        let text = |k: &str| hb.get_str(k).unwrap_or_default().to_string();
        let autopilot = text("autopilot");
        if autopilot.is_empty() || autopilot == NO_AUTOPILOT {
            return Changes::default();
        }
        let base_mode = text("base_mode");
        let state = State {
            mav_type: text("type"),
            autopilot,
            armed: base_mode.split(" | ").any(|f| f == ARMED),
            base_mode,
            custom_mode: hb.get_i64("custom_mode").unwrap_or(0),
            system_status: text("system_status"),
        };
        let key = (sysid, compid);
        let changed = match self.known.get_mut(&key) {
            Some(v) => {
                let changed = v.state != state || !v.alive;
                *v = Vehicle {
                    state,
                    heard: now,
                    heard_wall: wall,
                    alive: true,
                };
                changed
            }
            None => {
                if self.known.len() >= MAX_VEHICLES
                    && let Some(oldest) = self
                        .known
                        .iter()
                        .min_by_key(|(_, v)| v.heard)
                        .map(|(k, _)| *k)
                {
                    self.known.remove(&oldest);
                }
                self.known.insert(
                    key,
                    Vehicle {
                        state,
                        heard: now,
                        heard_wall: wall,
                        alive: true,
                    },
                );
                true
            }
        };
        let mut out = Changes::default();
        if changed {
            out.publish.push(self.map_of(key));
        }
        if !self.up {
            self.up = true;
            out.link = Some(LinkState::Up);
        }
        out
    }

    /// What is due at `now`: vehicles gone silent, the link going down, the periodic list.
    pub fn tick(&mut self, now: Instant) -> Changes {
        let mut out = Changes::default();
        let timeout = self.timeout;
        let mut lost = Vec::new();
        for (key, v) in self.known.iter_mut() {
            if v.alive && now.saturating_duration_since(v.heard) >= timeout {
                v.alive = false;
                lost.push(*key);
            }
        }
        if now >= self.next_repeat {
            self.next_repeat = now + REPEAT;
            out.publish = self.known.keys().map(|k| self.map_of(*k)).collect();
        } else {
            out.publish = lost.iter().map(|k| self.map_of(*k)).collect();
        }
        if self.up && !self.known.values().any(|v| v.alive) {
            self.up = false;
            let why = match lost.as_slice() {
                [(s, c)] => format!(
                    "no heartbeat from the vehicle (system {s}, component {c}) for {:?}",
                    self.timeout
                ),
                _ => format!("no heartbeat from any vehicle for {:?}", self.timeout),
            };
            self.down = why.clone();
            out.link = Some(LinkState::Down(why));
        }
        out
    }

    /// The wire was lost, or cannot be reached (`why`): every vehicle is silent and the link down
    /// at once, with `why` (the link's change is said again when the reason changes).
    pub fn lost(&mut self, why: impl Into<String>) -> Changes {
        let why = why.into();
        let new_reason = self.down != why;
        self.down = why;
        let mut out = Changes::default();
        let silenced: Vec<(u32, u8)> = self
            .known
            .iter_mut()
            .filter(|(_, v)| v.alive)
            .map(|(k, v)| {
                v.alive = false;
                *k
            })
            .collect();
        out.publish = silenced.iter().map(|k| self.map_of(*k)).collect();
        if self.up || new_reason {
            self.up = false;
            out.link = Some(LinkState::Down(self.down.clone()));
        }
        out
    }

    /// The link's state now.
    pub fn link(&self) -> LinkState {
        if self.up {
            LinkState::Up
        } else {
            LinkState::Down(self.down.clone())
        }
    }

    /// The next instant [`Vehicles::tick`] has something to do.
    pub fn next_deadline(&self) -> Instant {
        self.known
            .values()
            .filter(|v| v.alive)
            .map(|v| v.heard + self.timeout)
            .fold(self.next_repeat, Instant::min)
    }

    /// Every vehicle's datamap.
    pub fn all(&self) -> Vec<DataMap> {
        self.known.keys().map(|k| self.map_of(*k)).collect()
    }

    fn map_of(&self, key: (u32, u8)) -> DataMap {
        let Some(v) = self.known.get(&key) else {
            return DataMap::new();
        };
        let heard = v
            .heard_wall
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        DataMap::from_entries(vec![
            ("sysid".into(), Value::Int(key.0.into())),
            ("compid".into(), Value::Int(key.1.into())),
            ("type".into(), Value::from(v.state.mav_type.as_str())),
            ("autopilot".into(), Value::from(v.state.autopilot.as_str())),
            ("armed".into(), Value::Bool(v.state.armed)),
            ("base_mode".into(), Value::from(v.state.base_mode.as_str())),
            ("custom_mode".into(), Value::Int(v.state.custom_mode)),
            (
                "system_status".into(),
                Value::from(v.state.system_status.as_str()),
            ),
            ("last_heard".into(), Value::Float(heard)),
            ("alive".into(), Value::Bool(v.alive)),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hb(autopilot: &str, base_mode: &str, custom_mode: i64) -> DataMap {
        DataMap::new()
            .with("custom_mode", custom_mode)
            .with("type", "MAV_TYPE_SUBMARINE")
            .with("autopilot", autopilot)
            .with("base_mode", base_mode)
            .with("system_status", "MAV_STATE_ACTIVE")
            .with("mavlink_version", 3i64)
    }

    const ARDU: &str = "MAV_AUTOPILOT_ARDUPILOTMEGA";
    const ARMED_MODE: &str = "MAV_MODE_FLAG_SAFETY_ARMED | MAV_MODE_FLAG_CUSTOM_MODE_ENABLED";

    #[test]
    fn a_vehicle_appears_arms_goes_silent_and_comes_back() {
        let t0 = Instant::now();
        let wall = SystemTime::UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut v = Vehicles::new(Duration::from_secs(3), t0, "no vehicle heard yet");
        assert_eq!(
            v.link(),
            LinkState::Down("no vehicle heard yet".to_string())
        );
        let c = v.heartbeat(
            1,
            1,
            &hb(ARDU, "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED", 19),
            ms(0),
            wall,
        );
        assert_eq!(c.link, Some(LinkState::Up));
        assert_eq!(c.publish.len(), 1);
        let m = &c.publish[0];
        assert_eq!(
            (
                m.get_i64("sysid"),
                m.get_i64("compid"),
                m.get_str("type"),
                m.get_bool("armed"),
                m.get_i64("custom_mode"),
                m.get_f64("last_heard"),
                m.get_bool("alive"),
            ),
            (
                Some(1),
                Some(1),
                Some("MAV_TYPE_SUBMARINE"),
                Some(false),
                Some(19),
                Some(1_700_000_000.0),
                Some(true)
            )
        );
        // the same again: nothing to publish
        let same = v.heartbeat(
            1,
            1,
            &hb(ARDU, "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED", 19),
            ms(1000),
            wall,
        );
        assert_eq!(same, Changes::default());
        // armed: published
        let armed = v.heartbeat(1, 1, &hb(ARDU, ARMED_MODE, 19), ms(2000), wall);
        assert_eq!(armed.publish[0].get_bool("armed"), Some(true));
        assert_eq!(armed.link, None);
        assert_eq!(v.next_deadline(), ms(5000));
        // not yet silent at 4.999 s
        assert_eq!(v.tick(ms(4999)), Changes::default());
        let gone = v.tick(ms(5000));
        assert_eq!(
            gone.link,
            Some(LinkState::Down(
                "no heartbeat from the vehicle (system 1, component 1) for 3s".to_string()
            ))
        );
        assert_eq!(gone.publish.len(), 1);
        assert_eq!(gone.publish[0].get_bool("alive"), Some(false));
        // the list every 5 s, also when nothing changed
        assert_eq!(v.next_deadline(), ms(10_000));
        assert_eq!(v.tick(ms(9999)), Changes::default());
        let again = v.tick(ms(10_000));
        assert_eq!((again.publish.len(), again.link), (1, None));
        assert_eq!(v.next_deadline(), ms(15_000));
        // back
        let back = v.heartbeat(1, 1, &hb(ARDU, ARMED_MODE, 19), ms(11_000), wall);
        assert_eq!(back.link, Some(LinkState::Up));
        assert_eq!(back.publish[0].get_bool("alive"), Some(true));
    }

    #[test]
    fn ground_stations_and_other_components_are_no_vehicles() {
        let t0 = Instant::now();
        let mut v = Vehicles::new(Duration::from_secs(3), t0, "none");
        let gcs = hb(NO_AUTOPILOT, "", 0);
        assert_eq!(
            v.heartbeat(255, 190, &gcs, t0, SystemTime::now()),
            Changes::default()
        );
        assert!(v.all().is_empty());
        assert!(matches!(v.link(), LinkState::Down(_)));
    }

    #[test]
    fn the_link_stays_up_while_one_vehicle_of_two_is_heard() {
        let t0 = Instant::now();
        let s = |n: u64| t0 + Duration::from_secs(n);
        let wall = SystemTime::now();
        let mut v = Vehicles::new(Duration::from_secs(3), t0, "none");
        v.heartbeat(1, 1, &hb(ARDU, "", 0), s(0), wall);
        v.heartbeat(2, 1, &hb(ARDU, "", 0), s(2), wall);
        let one = v.tick(s(3));
        assert_eq!((one.publish.len(), one.link), (1, None));
        let both = v.tick(s(5));
        assert_eq!(
            both.link,
            Some(LinkState::Down(
                "no heartbeat from the vehicle (system 2, component 1) for 3s".to_string()
            ))
        );
        // the wire lost: down at once, with its reason
        v.heartbeat(1, 1, &hb(ARDU, "", 0), s(6), wall);
        let lost = v.lost("connection reset");
        assert_eq!(
            lost.link,
            Some(LinkState::Down("connection reset".to_string()))
        );
        assert_eq!(lost.publish.len(), 1);
        assert_eq!(v.link(), LinkState::Down("connection reset".to_string()));
        // the same reason again changes nothing; another one is said
        assert_eq!(v.lost("connection reset"), Changes::default());
        assert_eq!(
            v.lost("connection refused").link,
            Some(LinkState::Down("connection refused".to_string()))
        );
    }

    #[test]
    fn the_list_is_bounded() {
        let t0 = Instant::now();
        let wall = SystemTime::now();
        let mut v = Vehicles::new(Duration::from_secs(3), t0, "none");
        for i in 0..=MAX_VEHICLES {
            let (s, c) = ((i % 256) as u32, (i / 256) as u8 + 1);
            v.heartbeat(
                s,
                c,
                &hb(ARDU, "", 0),
                t0 + Duration::from_millis(i as u64),
                wall,
            );
        }
        assert_eq!(v.all().len(), MAX_VEHICLES);
        // the first one, heard least recently, was forgotten
        assert!(
            v.all()
                .iter()
                .all(|m| m.get_i64("compid") != Some(1) || m.get_i64("sysid") != Some(0))
        );
    }
}
