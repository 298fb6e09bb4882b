//! State estimators the supporting modules use, free of I/O so that they are tested against
//! synthetic data with a known truth:
//!
//! - [`DepthKalman`] — a Kalman filter of depth and vertical speed (constant vertical speed
//!   driven by white acceleration noise) from noisy depth readings;
//! - [`PositionEkf`] — an extended Kalman filter of position (north, east in metres from an
//!   origin) and compass bias, dead-reckoning with DVL velocity and heading while submerged and
//!   corrected by GPS fixes at the surface, which also teach it the compass bias;
//! - [`tilt_compensated`], [`HeadingSmoother`] and [`Deviation`] — a compass heading with the
//!   tilt taken out, smoothed without lag through turns, and corrected by a deviation table that
//!   can be learnt from GPS course over ground.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};

/// Depth and vertical speed from depth readings.
#[derive(Debug, Clone)]
pub struct DepthKalman {
    /// Depth (m, down positive) and vertical speed (m/s, down positive).
    x: Vector2<f64>,
    p: Matrix2<f64>,
    /// Acceleration noise spectral density, (m/s²)² per Hz.
    q: f64,
    /// Reading noise variance, m².
    r: f64,
    started: bool,
}

impl DepthKalman {
    /// A filter for readings with standard deviation `sigma` (m), the vehicle's vertical
    /// acceleration having standard deviation `accel` (m/s²).
    pub fn new(sigma: f64, accel: f64) -> DepthKalman {
        DepthKalman {
            x: Vector2::zeros(),
            p: Matrix2::identity(),
            q: accel * accel,
            r: sigma * sigma,
            started: false,
        }
    }

    /// Takes a reading `dt` seconds after the previous one; returns depth and vertical speed.
    pub fn update(&mut self, dt: f64, depth: f64) -> (f64, f64) {
        if !self.started {
            self.started = true;
            self.x = Vector2::new(depth, 0.0);
            self.p = Matrix2::new(self.r, 0.0, 0.0, 1.0);
            return (depth, 0.0);
        }
        let dt = dt.clamp(0.0, 10.0);
        let f = Matrix2::new(1.0, dt, 0.0, 1.0);
        let (dt2, dt3) = (dt * dt, dt * dt * dt);
        let q = self.q * Matrix2::new(dt3 * dt / 4.0, dt3 / 2.0, dt3 / 2.0, dt2);
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + q;
        // the reading sees depth only
        let innovation = depth - self.x[0];
        let s = self.p[(0, 0)] + self.r;
        let k = Vector2::new(self.p[(0, 0)] / s, self.p[(1, 0)] / s);
        self.x += k * innovation;
        let kh = Matrix2::new(k[0], 0.0, k[1], 0.0);
        self.p = (Matrix2::identity() - kh) * self.p;
        (self.x[0], self.x[1])
    }
}

/// Position and compass bias from dead reckoning and GPS.
#[derive(Debug, Clone)]
pub struct PositionEkf {
    /// North (m), east (m), compass bias (rad: true heading = compass + bias).
    x: Vector3<f64>,
    p: Matrix3<f64>,
    /// Velocity noise variance, (m/s)².
    vel_var: f64,
    /// How fast the compass bias may wander, rad² per second.
    bias_walk: f64,
}

impl PositionEkf {
    /// Starts at `north`, `east` known to `sigma` metres, the compass bias unknown to
    /// `bias_sigma_deg`; DVL velocities with standard deviation `vel_sigma` (m/s).
    pub fn new(north: f64, east: f64, sigma: f64, bias_sigma_deg: f64, vel_sigma: f64) -> Self {
        let b = bias_sigma_deg.to_radians();
        PositionEkf {
            x: Vector3::new(north, east, 0.0),
            p: Matrix3::from_diagonal(&Vector3::new(sigma * sigma, sigma * sigma, b * b)),
            vel_var: vel_sigma * vel_sigma,
            bias_walk: (0.01f64).to_radians().powi(2),
        }
    }

    /// Moves `dt` seconds on at `surge` (forward) and `sway` (starboard) m/s, the compass reading
    /// `heading_deg`.
    pub fn predict(&mut self, dt: f64, heading_deg: f64, surge: f64, sway: f64) {
        let dt = dt.clamp(0.0, 10.0);
        let h = heading_deg.to_radians() + self.x[2];
        let (s, c) = h.sin_cos();
        let vn = surge * c - sway * s;
        let ve = surge * s + sway * c;
        self.x[0] += vn * dt;
        self.x[1] += ve * dt;
        // how the move depends on the bias
        let f = Matrix3::new(1.0, 0.0, -ve * dt, 0.0, 1.0, vn * dt, 0.0, 0.0, 1.0);
        let g = dt * dt * self.vel_var;
        let q = Matrix3::from_diagonal(&Vector3::new(g, g, self.bias_walk * dt));
        self.p = f * self.p * f.transpose() + q;
    }

    /// Takes a GPS fix at `north`, `east` with standard deviation `sigma` metres.
    pub fn gps(&mut self, north: f64, east: f64, sigma: f64) {
        let h = Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        let r = Matrix2::identity() * (sigma * sigma);
        let y = Vector2::new(north, east) - h * self.x;
        let s = h * self.p * h.transpose() + r;
        let Some(s_inv) = s.try_inverse() else {
            return;
        };
        let k = self.p * h.transpose() * s_inv;
        self.x += k * y;
        self.p = (Matrix3::identity() - k * h) * self.p;
    }

    /// North and east (m).
    pub fn position(&self) -> (f64, f64) {
        (self.x[0], self.x[1])
    }

    /// The compass bias learnt (degrees; true heading = compass + bias).
    pub fn bias_deg(&self) -> f64 {
        self.x[2].to_degrees()
    }

    /// The position's standard deviation (m, the larger axis).
    pub fn sigma(&self) -> f64 {
        self.p[(0, 0)].max(self.p[(1, 1)]).sqrt()
    }
}

/// The heading a magnetometer gives once its tilt is taken out: `mag` the field in the vehicle
/// frame (x forward, y starboard, z down; any unit), roll and pitch in degrees (starboard down and
/// bow up positive). Degrees clockwise from magnetic north, in [0, 360).
pub fn tilt_compensated(mag: [f64; 3], roll_deg: f64, pitch_deg: f64) -> f64 {
    let (sr, cr) = roll_deg.to_radians().sin_cos();
    let (sp, cp) = pitch_deg.to_radians().sin_cos();
    let [mx, my, mz] = mag;
    let xh = mx * cp + my * sr * sp + mz * cr * sp;
    let yh = my * cr - mz * sr;
    seabus_modules::geo::wrap360((-yh).atan2(xh).to_degrees())
}

/// Smooths a heading without the lag of plain averaging: the rate of turn carries the estimate
/// through turns, and each reading pulls it by `gain` (0–1) of the difference.
#[derive(Debug, Clone)]
pub struct HeadingSmoother {
    gain: f64,
    estimate: Option<f64>,
}

impl HeadingSmoother {
    /// A smoother taking `gain` of each reading's difference.
    pub fn new(gain: f64) -> HeadingSmoother {
        HeadingSmoother {
            gain: gain.clamp(0.0, 1.0),
            estimate: None,
        }
    }

    /// Takes a reading `dt` seconds after the last, turning at `rate` deg/s (when known).
    pub fn update(&mut self, dt: f64, heading: f64, rate: Option<f64>) -> f64 {
        use seabus_modules::geo::{wrap180, wrap360};
        let e = match self.estimate {
            None => heading,
            Some(prev) => {
                let predicted = prev + rate.unwrap_or(0.0) * dt.clamp(0.0, 10.0);
                // without a rate, a turn is followed by the readings alone
                let gain = if rate.is_some() {
                    self.gain
                } else {
                    self.gain.max(0.3)
                };
                predicted + gain * wrap180(heading - predicted)
            }
        };
        let e = wrap360(e);
        self.estimate = Some(e);
        e
    }
}

/// A compass deviation table: deviation (degrees, east positive: true = compass + deviation) by
/// compass heading, interpolated around the circle; learnt from GPS course over ground while the
/// vehicle goes straight and fast enough that course is heading.
#[derive(Debug, Clone)]
pub struct Deviation {
    /// Sums of learnt samples' headings and deviations, and their count, per 10° of heading.
    bins: [(f64, f64, u32); 36],
    /// Points given in the configuration, (heading, deviation), sorted.
    table: Vec<(f64, f64)>,
}

impl Deviation {
    /// A table of `(heading, deviation)` points (none: no deviation until some is learnt).
    pub fn new(mut table: Vec<(f64, f64)>) -> Deviation {
        table.sort_by(|a, b| a.0.total_cmp(&b.0));
        Deviation {
            bins: [(0.0, 0.0, 0); 36],
            table,
        }
    }

    /// Learns from one sample: the compass said `heading` while the course over ground was `course`.
    pub fn learn(&mut self, heading: f64, course: f64) {
        let h = seabus_modules::geo::wrap360(heading);
        let bin = (h / 10.0) as usize % 36;
        let d = seabus_modules::geo::wrap180(course - heading);
        self.bins[bin].0 += h;
        self.bins[bin].1 += d;
        self.bins[bin].2 += 1;
    }

    /// The points in force: the learnt bins (each at its samples' mean heading) where there are
    /// any, else the table's.
    pub fn points(&self) -> Vec<(f64, f64)> {
        let learnt: Vec<(f64, f64)> = self
            .bins
            .iter()
            .filter(|(_, _, n)| *n >= 5)
            .map(|(h, d, n)| (h / f64::from(*n), d / f64::from(*n)))
            .collect();
        if learnt.is_empty() {
            self.table.clone()
        } else {
            learnt
        }
    }

    /// The deviation at compass heading `heading`.
    pub fn at(&self, heading: f64) -> f64 {
        let pts = self.points();
        match pts.len() {
            0 => 0.0,
            1 => pts[0].1,
            _ => {
                let h = seabus_modules::geo::wrap360(heading);
                // the points around h, wrapping at 360
                let after = pts.iter().position(|p| p.0 >= h).unwrap_or(0);
                let before = (after + pts.len() - 1) % pts.len();
                let (h0, d0) = pts[before];
                let (h1, d1) = pts[after];
                let span = seabus_modules::geo::wrap360(h1 - h0);
                if span == 0.0 {
                    return d0;
                }
                let f = seabus_modules::geo::wrap360(h - h0) / span;
                d0 + f * (d1 - d0)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gaussian noise from a seeded generator (Box–Muller).
    struct Noise(fastrand::Rng);

    impl Noise {
        fn next(&mut self, sigma: f64) -> f64 {
            let (u1, u2) = (self.0.f64().max(1e-12), self.0.f64());
            sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
        }
    }

    fn rms(v: &[f64]) -> f64 {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }

    #[test]
    fn the_depth_filter_beats_the_raw_readings() {
        let mut noise = Noise(fastrand::Rng::with_seed(7));
        let mut f = DepthKalman::new(0.2, 0.3);
        let dt = 0.1;
        let (mut raw_err, mut depth_err, mut speed_err) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..3000 {
            let t = f64::from(i) * dt;
            let truth = 10.0 + 2.0 * (0.2 * t).sin();
            let truth_speed = 0.4 * (0.2 * t).cos();
            let reading = truth + noise.next(0.2);
            let (d, w) = f.update(dt, reading);
            // after the filter settles
            if i > 100 {
                raw_err.push(reading - truth);
                depth_err.push(d - truth);
                speed_err.push(w - truth_speed);
            }
        }
        let (raw, depth, speed) = (rms(&raw_err), rms(&depth_err), rms(&speed_err));
        println!(
            "depth filter: raw RMS {raw:.3} m, filtered {depth:.3} m, vertical speed {speed:.3} m/s"
        );
        assert!(depth < 0.5 * raw, "filtered {depth} vs raw {raw}");
        assert!(speed < 0.1, "vertical speed RMS {speed}");
    }

    /// The truth and a naive dead reckoning with the raw compass, for comparison.
    struct Sim {
        truth: (f64, f64),
        naive: (f64, f64),
        noise: Noise,
    }

    const BIAS: f64 = 3.0; // the compass reads 3° less than the truth
    const DT: f64 = 0.2;
    const SPEED: f64 = 1.5;

    impl Sim {
        fn step(&mut self, heading: f64, gps: bool, ekf: &mut PositionEkf) {
            let h = heading.to_radians();
            self.truth.0 += SPEED * h.cos() * DT;
            self.truth.1 += SPEED * h.sin() * DT;
            let compass = heading - BIAS + self.noise.next(0.5);
            let surge = SPEED + self.noise.next(0.02);
            let sway = self.noise.next(0.02);
            ekf.predict(DT, compass, surge, sway);
            let (s, c) = compass.to_radians().sin_cos();
            self.naive.0 += (surge * c - sway * s) * DT;
            self.naive.1 += (surge * s + sway * c) * DT;
            if gps {
                let (n, e) = (
                    self.truth.0 + self.noise.next(2.0),
                    self.truth.1 + self.noise.next(2.0),
                );
                ekf.gps(n, e, 2.0);
            }
        }
    }

    fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
        ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt()
    }

    #[test]
    fn the_ekf_learns_the_compass_bias_and_dead_reckons_with_it() {
        let mut ekf = PositionEkf::new(0.0, 0.0, 5.0, 10.0, 0.02);
        let mut sim = Sim {
            truth: (0.0, 0.0),
            naive: (0.0, 0.0),
            noise: Noise(fastrand::Rng::with_seed(11)),
        };
        // ten minutes at the surface on a zig-zag with GPS at 5 Hz: the bias is learnt
        for i in 0..3000 {
            let heading = if (i / 300) % 2 == 0 { 45.0 } else { 135.0 };
            sim.step(heading, true, &mut ekf);
        }
        let learnt = ekf.bias_deg();
        println!("compass bias learnt: {learnt:.2}° (truth {BIAS}°)");
        assert!((learnt - BIAS).abs() < 0.5, "learnt {learnt}°");
        // ten minutes submerged, dead reckoning on 80°
        let dive = sim.truth;
        let naive_dive = sim.naive;
        let start_err = dist(ekf.position(), dive);
        for _ in 0..3000 {
            sim.step(80.0, false, &mut ekf);
        }
        let travelled = dist(sim.truth, dive);
        let ekf_err = dist(ekf.position(), sim.truth);
        // the raw compass's error over the leg alone
        let naive_err = dist(
            (sim.naive.0 - naive_dive.0, sim.naive.1 - naive_dive.1),
            (sim.truth.0 - dive.0, sim.truth.1 - dive.1),
        );
        println!(
            "dead-reckoned {travelled:.0} m: EKF error {ekf_err:.1} m ({start_err:.1} m at the dive), \
             raw compass {naive_err:.1} m over the leg, EKF sigma {:.1} m",
            ekf.sigma()
        );
        assert!(
            ekf_err < start_err + 0.01 * travelled,
            "EKF error {ekf_err} m"
        );
        assert!(ekf_err < naive_err, "EKF {ekf_err} m vs raw {naive_err} m");
    }

    #[test]
    fn tilt_is_taken_out_of_the_magnetometer() {
        // a field 60° below the horizon towards magnetic north, seen by a vehicle on heading h,
        // rolled and pitched
        for (h, roll, pitch) in [
            (0.0, 0.0, 0.0),
            (30.0, 10.0, -5.0),
            (200.0, -20.0, 15.0),
            (300.0, 5.0, 25.0),
        ] {
            let (dip, f) = (60f64.to_radians(), 50.0);
            let ned = nalgebra::Vector3::new(f * dip.cos(), 0.0, f * dip.sin());
            let rot = nalgebra::Rotation3::from_euler_angles(
                f64::to_radians(roll),
                f64::to_radians(pitch),
                f64::to_radians(h),
            );
            // body = R^T * ned
            let body = rot.inverse() * ned;
            let got = tilt_compensated([body[0], body[1], body[2]], roll, pitch);
            assert!(
                seabus_modules::geo::wrap180(got - h).abs() < 0.01,
                "{h} {roll} {pitch}: {got}"
            );
        }
    }

    #[test]
    fn the_smoother_follows_turns_and_calms_noise() {
        let mut noise = Noise(fastrand::Rng::with_seed(5));
        let mut s = HeadingSmoother::new(0.05);
        let (mut err_raw, mut err_s) = (Vec::new(), Vec::new());
        let dt = 0.1;
        for i in 0..2000 {
            let t = f64::from(i) * dt;
            // straight, then a 10°/s turn, then straight
            let (truth, rate) = if t < 60.0 {
                (90.0, 0.0)
            } else if t < 78.0 {
                (90.0 + 10.0 * (t - 60.0), 10.0)
            } else {
                (270.0, 0.0)
            };
            let reading = truth + noise.next(2.0);
            let e = s.update(dt, reading, Some(rate));
            if i > 50 {
                err_raw.push(seabus_modules::geo::wrap180(reading - truth));
                err_s.push(seabus_modules::geo::wrap180(e - truth));
            }
        }
        let (raw, smooth) = (rms(&err_raw), rms(&err_s));
        println!("heading smoother: raw {raw:.2}°, smoothed {smooth:.2}° through a 180° turn");
        assert!(smooth < 0.4 * raw, "{smooth} vs {raw}");
    }

    #[test]
    fn deviation_is_learnt_from_course_over_ground() {
        let mut noise = Noise(fastrand::Rng::with_seed(9));
        // the compass errs by 3 sin(h) + 1 degrees
        let deviation = |h: f64| 3.0 * h.to_radians().sin() + 1.0;
        let mut d = Deviation::new(vec![]);
        for leg in 0..12 {
            let truth = f64::from(leg) * 30.0 + 5.0;
            for _ in 0..40 {
                // compass = truth - deviation, so true = compass + deviation
                let compass = truth - deviation(truth) + noise.next(1.0);
                let course = truth + noise.next(1.0);
                d.learn(compass, course);
            }
        }
        let mut worst = 0.0f64;
        for leg in 0..12 {
            let truth = f64::from(leg) * 30.0 + 5.0;
            let compass = truth - deviation(truth);
            worst = worst.max((d.at(compass) - deviation(truth)).abs());
        }
        println!("deviation learnt: worst error {worst:.2}° on the legs sailed");
        assert!(worst < 0.6, "{worst}");
        // a configured table is interpolated around the circle
        let t = Deviation::new(vec![(0.0, 2.0), (90.0, -2.0), (180.0, 0.0), (270.0, 4.0)]);
        assert!((t.at(45.0) - 0.0).abs() < 1e-9);
        assert!((t.at(315.0) - 3.0).abs() < 1e-9);
        assert!((t.at(270.0) - 4.0).abs() < 1e-9);
    }
}
