//! A simple vehicle model: first-order heading, depth and speed responses with rate limits, dead
//! reckoning on a flat earth, and a battery drained by hotel load and propulsion.

use seabus_modules::geo::{moved, wrap180, wrap360};

/// What the vehicle is asked to hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    /// Heading, degrees true.
    pub heading: f64,
    /// Depth, metres (0 at the surface).
    pub depth: f64,
    /// Speed through the water, m/s.
    pub speed: f64,
}

/// Limits of the vehicle's response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Fastest turn, degrees per second.
    pub turn_rate: f64,
    /// Fastest depth change, m/s.
    pub dive_rate: f64,
    /// Fastest speed change, m/s².
    pub accel: f64,
    /// Top speed, m/s.
    pub max_speed: f64,
    /// Deepest depth, m.
    pub max_depth: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            turn_rate: 10.0,
            dive_rate: 0.3,
            accel: 0.2,
            max_speed: 2.5,
            max_depth: 100.0,
        }
    }
}

/// The vehicle's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vehicle {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Heading, degrees true, in [0, 360).
    pub heading: f64,
    /// Pitch, degrees, bow up positive.
    pub pitch: f64,
    /// Roll, degrees, starboard down positive.
    pub roll: f64,
    /// Turn rate, degrees per second.
    pub yaw_rate: f64,
    /// Depth, metres.
    pub depth: f64,
    /// Depth rate, m/s, down positive.
    pub vertical_speed: f64,
    /// Speed through the water, m/s.
    pub speed: f64,
    /// Energy left, Wh.
    pub energy: f64,
    /// Full charge, Wh.
    pub capacity: f64,
}

impl Vehicle {
    /// A vehicle at rest on the surface at a position, with a full battery of `capacity` Wh.
    pub fn at(lat: f64, lon: f64, heading: f64, capacity: f64) -> Vehicle {
        Vehicle {
            lat,
            lon,
            heading: wrap360(heading),
            pitch: 0.0,
            roll: 0.0,
            yaw_rate: 0.0,
            depth: 0.0,
            vertical_speed: 0.0,
            speed: 0.0,
            energy: capacity,
            capacity,
        }
    }

    /// Battery charge, percent.
    pub fn percent(&self) -> f64 {
        if self.capacity <= 0.0 {
            0.0
        } else {
            (self.energy / self.capacity * 100.0).clamp(0.0, 100.0)
        }
    }

    /// Power drawn now, W: a hotel load and propulsion growing with the cube of speed.
    pub fn power(&self) -> f64 {
        10.0 + 8.0 * self.speed.powi(3)
    }

    /// Advances the model by `dt` seconds towards `target` (`None`: stop and surface).
    pub fn step(&mut self, dt: f64, target: Option<Setpoint>, limits: &Limits) {
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let sp = target.unwrap_or(Setpoint {
            heading: self.heading,
            depth: 0.0,
            speed: 0.0,
        });
        let speed_goal = if self.energy > 0.0 {
            sp.speed.clamp(0.0, limits.max_speed)
        } else {
            0.0
        };
        self.speed += approach(self.speed, speed_goal, limits.accel * dt);

        let err = wrap180(sp.heading - self.heading);
        // turning needs way on: the rudder bites with speed
        let authority = (self.speed / 0.5).min(1.0);
        let turn = err.clamp(-limits.turn_rate * dt, limits.turn_rate * dt) * authority;
        self.heading = wrap360(self.heading + turn);
        self.yaw_rate = turn / dt;
        self.roll = (-0.5 * self.yaw_rate).clamp(-20.0, 20.0);

        let depth_goal = sp.depth.clamp(0.0, limits.max_depth);
        let dz = approach(self.depth, depth_goal, limits.dive_rate * dt);
        self.depth = (self.depth + dz).max(0.0);
        self.vertical_speed = dz / dt;
        self.pitch = if self.speed > 0.05 {
            (-self.vertical_speed.atan2(self.speed).to_degrees()).clamp(-30.0, 30.0)
        } else {
            0.0
        };

        let h = self.heading.to_radians();
        let north = self.speed * h.cos() * dt;
        let east = self.speed * h.sin() * dt;
        (self.lat, self.lon) = moved(self.lat, self.lon, north, east);
        self.energy = (self.energy - self.power() * dt / 3600.0).max(0.0);
    }
}

/// The step from `from` towards `to`, at most `max` in size.
fn approach(from: f64, to: f64, max: f64) -> f64 {
    (to - from).clamp(-max, max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use seabus_modules::geo::METRES_PER_DEG;

    fn run(v: &mut Vehicle, secs: f64, sp: Option<Setpoint>) {
        let limits = Limits::default();
        for _ in 0..(secs * 10.0) as usize {
            v.step(0.1, sp, &limits);
        }
    }

    #[test]
    fn reaches_the_commanded_heading_depth_and_speed() {
        let mut v = Vehicle::at(43.5, 16.4, 0.0, 600.0);
        let sp = Setpoint {
            heading: 270.0,
            depth: 5.0,
            speed: 1.5,
        };
        run(&mut v, 60.0, Some(sp));
        assert!(
            (v.heading - 270.0).abs() < 0.01,
            "turned the short way to {}",
            v.heading
        );
        assert!((v.depth - 5.0).abs() < 1e-9);
        assert!((v.speed - 1.5).abs() < 1e-9);
        assert!(v.lon < 16.4, "went west");
        assert!(v.percent() < 100.0);
    }

    #[test]
    fn dead_reckons_distance_at_speed() {
        let mut v = Vehicle::at(0.0, 0.0, 0.0, 600.0);
        v.speed = 2.0;
        run(
            &mut v,
            100.0,
            Some(Setpoint {
                heading: 0.0,
                depth: 0.0,
                speed: 2.0,
            }),
        );
        let metres = v.lat * METRES_PER_DEG;
        assert!((metres - 200.0).abs() < 1e-6, "{metres}");
    }

    #[test]
    fn without_a_command_it_stops_and_surfaces() {
        let mut v = Vehicle::at(0.0, 0.0, 90.0, 600.0);
        v.speed = 2.0;
        v.depth = 3.0;
        run(&mut v, 30.0, None);
        assert_eq!(v.speed, 0.0);
        assert_eq!(v.depth, 0.0);
        assert_eq!(v.heading, 90.0);
    }
}
