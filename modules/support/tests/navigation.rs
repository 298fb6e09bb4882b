//! The navigation supporting modules in a running system, fed synthetic sensor data with a known
//! truth (stamped as sensors would stamp it): `depth-kalman` beats the raw depth; `position-ekf`
//! learns a compass bias at the surface and dead-reckons a submerged leg with it.

mod common;

use common::{Feed, drain};
use seabus_medium::{DataMap, Interface};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::time::Duration;

/// Gaussian noise from a seeded generator (Box–Muller).
fn gauss(rng: &mut fastrand::Rng, sigma: f64) -> f64 {
    let (u1, u2) = (rng.f64().max(1e-12), rng.f64());
    sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

async fn start() -> (Runtime, Feed, Interface) {
    let spec = SystemSpec::parse(
        "nav.xml",
        r#"<seabus node="nav">
  <medium name="bus" url="inproc://"/>
  <module name="depth" type="depth-kalman" medium="bus" sigma="0.2" accel="0.3"/>
  <module name="ekf" type="position-ekf" medium="bus" gps_sigma="2" vel_sigma="0.02"/>
  <module name="compass" type="heading-correction" medium="bus" learn="true" variation="4"/>
</seabus>"#,
    )
    .unwrap();
    let rt = Runtime::start(&spec, &seabus_support::registry(), Catalogue::built_in())
        .await
        .unwrap();
    let bus = rt.medium("bus").unwrap().clone();
    let mut rx = bus.attach_with("rx", 1 << 16, 16);
    rx.subscribe("nav.depth.filtered").unwrap();
    rx.subscribe("nav.position.estimated").unwrap();
    rx.subscribe("nav.heading.corrected").unwrap();
    // the modules subscribe as they start
    tokio::time::sleep(Duration::from_millis(200)).await;
    let feed = Feed::new(&bus);
    (rt, feed, rx)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn depth_kalman_beats_the_raw_depth() {
    let (rt, mut feed, mut rx) = start().await;
    let mut rng = fastrand::Rng::with_seed(3);
    let mut truth = Vec::new();
    let mut raw = Vec::new();
    for i in 0..1200 {
        let t = f64::from(i) * 0.1;
        let d = 10.0 + 2.0 * (0.2 * t).sin();
        let r = d + gauss(&mut rng, 0.2);
        truth.push((d, 0.4 * (0.2 * t).cos()));
        raw.push(r);
        feed.send(t, "nav.depth", DataMap::new().with("depth", r))
            .await;
        if i % 10 == 0 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }
    let out = drain(&mut rx, "nav.depth.filtered", 1200).await;
    assert_eq!(out.len(), 1200, "one estimate per reading");
    let rms = |e: &mut dyn Iterator<Item = f64>| {
        let v: Vec<f64> = e.collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    };
    let raw_rms = rms(&mut (100..1200).map(|i| raw[i] - truth[i].0));
    let depth_rms = rms(&mut (100..1200).map(|i| out[i].get_f64("depth").unwrap() - truth[i].0));
    let speed_rms =
        rms(&mut (100..1200).map(|i| out[i].get_f64("vertical_speed").unwrap() - truth[i].1));
    println!(
        "depth-kalman: raw {raw_rms:.3} m, filtered {depth_rms:.3} m, vertical speed {speed_rms:.3} m/s"
    );
    assert!(depth_rms < 0.5 * raw_rms, "{depth_rms} vs {raw_rms}");
    assert!(speed_rms < 0.1, "{speed_rms}");
    rt.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn position_ekf_learns_the_compass_bias_and_dead_reckons() {
    let (rt, mut feed, mut rx) = start().await;
    let mut rng = fastrand::Rng::with_seed(5);
    let (lat0, lon0) = (43.5, 16.4);
    let (bias, speed, dt) = (3.0f64, 1.5f64, 0.2f64);
    let (mut n, mut e) = (0.0f64, 0.0f64);
    let mut sent = 0usize;
    let steps = 6000;
    for i in 0..steps {
        let t = i as f64 * dt;
        let surface = i < 3000;
        let heading = if !surface {
            80.0
        } else if (i / 300) % 2 == 0 {
            45.0
        } else {
            135.0
        };
        let h = f64::to_radians(heading);
        n += speed * h.cos() * dt;
        e += speed * h.sin() * dt;
        let compass = heading - bias + gauss(&mut rng, 0.5);
        feed.send(
            t,
            "nav.attitude",
            DataMap::new()
                .with("yaw", compass)
                .with("pitch", 0.0)
                .with("roll", 0.0),
        )
        .await;
        feed.send(
            t,
            "nav.velocity",
            DataMap::new()
                .with("surge", speed + gauss(&mut rng, 0.02))
                .with("sway", gauss(&mut rng, 0.02)),
        )
        .await;
        sent += 1;
        if surface && i % 5 == 0 {
            let (lat, lon) = seabus_modules::geo::moved(
                lat0,
                lon0,
                n + gauss(&mut rng, 2.0),
                e + gauss(&mut rng, 2.0),
            );
            feed.send(
                t,
                "nav.gps",
                DataMap::new()
                    .with("lat", lat)
                    .with("lon", lon)
                    .with("fix", 1i64),
            )
            .await;
            sent += 1;
        }
        // sensors at their pace, not a flood the module's queue would drop from
        if i % 10 == 0 {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }
    // the first estimates come once the first fix gave the origin
    let out = drain(&mut rx, "nav.position.estimated", sent - 1).await;
    let last = out.last().expect("estimates");
    assert_eq!(last.get_str("source"), Some("dead-reckoning"));
    let learnt = last.get_f64("compass_bias").unwrap();
    let (lat, lon) = (last.get_f64("lat").unwrap(), last.get_f64("lon").unwrap());
    let (true_lat, true_lon) = seabus_modules::geo::moved(lat0, lon0, n, e);
    let err = seabus_modules::geo::distance(lat, lon, true_lat, true_lon);
    println!(
        "position-ekf: compass bias {learnt:.2}° (truth {bias}°), error after a 900 m dead-reckoned leg {err:.1} m"
    );
    assert!((learnt - bias).abs() < 0.5, "learnt {learnt}°");
    assert!(err < 10.0, "{err} m after 900 m");
    rt.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn heading_correction_learns_the_deviation_on_straight_legs() {
    let (rt, mut feed, mut rx) = start().await;
    let mut rng = fastrand::Rng::with_seed(8);
    // the compass errs by 3 sin(h) + 1 degrees; the variation is 4° east
    let deviation = |h: f64| 3.0 * h.to_radians().sin() + 1.0;
    let mut t = 0.0;
    let mut sent = 0;
    for leg in 0..12 {
        let truth = f64::from(leg) * 30.0 + 5.0;
        for i in 0..60 {
            if i % 10 == 0 {
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
            t += 0.2;
            let compass = truth - 4.0 - deviation(truth) + gauss(&mut rng, 1.0);
            feed.send(
                t,
                "nav.attitude",
                DataMap::new()
                    .with("yaw", compass)
                    .with("yaw_rate", 0.0)
                    .with("pitch", 0.0)
                    .with("roll", 0.0),
            )
            .await;
            feed.send(
                t,
                "nav.velocity",
                DataMap::new()
                    .with("course", truth + gauss(&mut rng, 1.0))
                    .with("speed", 1.5),
            )
            .await;
            sent += 1;
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    // a last pass over every leg's heading (long enough for the smoother to settle after each
    // jump, which the rate of turn does not announce): the corrected heading is the truth
    let mut errors = Vec::new();
    for leg in 0..12 {
        let truth = f64::from(leg) * 30.0 + 5.0;
        for i in 0..100 {
            if i % 10 == 0 {
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
            t += 0.2;
            let compass = truth - 4.0 - deviation(truth);
            feed.send(
                t,
                "nav.attitude",
                DataMap::new()
                    .with("yaw", compass)
                    .with("yaw_rate", 0.0)
                    .with("pitch", 0.0)
                    .with("roll", 0.0),
            )
            .await;
        }
        let out = drain(
            &mut rx,
            "nav.heading.corrected",
            if leg == 0 { sent + 100 } else { 100 },
        )
        .await;
        let last = out.last().expect("corrected headings");
        errors.push(seabus_modules::geo::wrap180(
            last.get_f64("heading").unwrap() - truth,
        ));
    }
    let worst = errors.iter().fold(0.0f64, |a, e| a.max(e.abs()));
    println!("heading-correction: worst error {worst:.2}° after learning ({errors:.2?})");
    assert!(worst < 0.6, "{errors:?}");
    rt.shutdown().await;
}
