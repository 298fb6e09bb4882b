//! `convert` in a running system with conversions declared in the system file: geodetic positions
//! to a local grid checked against pymap3d (an independent geodesy library), and a DVL mounted at
//! 45° reporting mm/s in its own frame turned into north-east-down velocity with the vehicle's
//! attitude read from another topic, against the velocity the synthetic vehicle truly had.

mod common;

use common::{Feed, drain};
use seabus_medium::{DataMap, Interface};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

const SYSTEM: &str = r#"<seabus node="nav">
  <medium name="bus" url="inproc://"/>
  <module name="grid" type="convert" medium="bus" input="nav.position" output="nav.local"
          fields="alt_ft ft->m as alt"
          frames="geodetic->enu(43.5081, 16.4402, 0): lat, lon, alt -> x, y, z;
                  geodetic->ned(43.5081, 16.4402): lat, lon, alt -> north, east, down;
                  enu->geodetic(43.5081, 16.4402, 0): x, y, z -> lat2, lon2, alt2"/>
  <module name="dvl" type="convert" medium="bus" input="dvl.raw" output="nav.velocity.ned"
          fields="vx mm/s->m/s; vy mm/s->m/s; vz mm/s->m/s"
          frames="rotate(0, 0, 45): vx, vy, vz -> surge, sway, heave;
                  rotate(roll, pitch, heading): surge, sway, heave -> vn, ve, vd"
          attitude="nav.attitude" attitude_age="500ms" keep="false"/>
</seabus>"#;

async fn start() -> (Runtime, Feed, Interface) {
    let spec = SystemSpec::parse("convert.xml", SYSTEM).unwrap();
    let rt = Runtime::start(&spec, &seabus_support::registry(), Catalogue::built_in())
        .await
        .unwrap();
    let bus = rt.medium("bus").unwrap().clone();
    let mut rx = bus.attach_with("rx", 1 << 14, 16);
    rx.subscribe("nav.local").unwrap();
    rx.subscribe("nav.velocity.ned").unwrap();
    // the modules subscribe as they start
    tokio::time::sleep(Duration::from_millis(200)).await;
    (rt, Feed::new(&bus), rx)
}

/// pymap3d's geodetic2enu of each (lat, lon, alt) from the same origin.
fn pymap3d_enu(points: &[(f64, f64, f64)]) -> Vec<(f64, f64, f64)> {
    let script = "import sys, pymap3d\n\
                  for line in sys.stdin:\n    \
                  lat, lon, alt = map(float, line.split())\n    \
                  print(*pymap3d.geodetic2enu(lat, lon, alt, 43.5081, 16.4402, 0.0))\n";
    let mut child = Command::new("python3")
        .args(["-c", script])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    let mut input = String::new();
    for (lat, lon, alt) in points {
        input += &format!("{lat:.12} {lon:.12} {alt:.6}\n");
    }
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "pymap3d failed (scripts/test installs it): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], v[1], v[2])
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn geodetic_positions_land_on_the_local_grid_as_pymap3d_puts_them() {
    let (rt, mut feed, mut rx) = start().await;
    let mut rng = fastrand::Rng::with_seed(11);
    // a survey area 40 km across, from the surface to 100 m depth (altitude in feet)
    let points: Vec<(f64, f64, f64)> = (0..200)
        .map(|_| {
            (
                43.5081 + (rng.f64() - 0.5) * 0.36,
                16.4402 + (rng.f64() - 0.5) * 0.5,
                -rng.f64() * 328.0,
            )
        })
        .collect();
    for (i, (lat, lon, alt_ft)) in points.iter().enumerate() {
        let map = DataMap::new()
            .with("lat", *lat)
            .with("lon", *lon)
            .with("alt_ft", *alt_ft);
        feed.send(i as f64 * 0.1, "nav.position", map).await;
    }
    let out = drain(&mut rx, "nav.local", points.len()).await;
    assert_eq!(out.len(), points.len(), "one grid position per fix");
    let truth = pymap3d_enu(
        &points
            .iter()
            .map(|(lat, lon, ft)| (*lat, *lon, ft * 0.3048))
            .collect::<Vec<_>>(),
    );
    let mut worst = 0.0f64;
    let mut farthest = 0.0f64;
    for ((o, t), p) in out.iter().zip(&truth).zip(&points) {
        let g = |k: &str| o.get_f64(k).unwrap();
        let err = (g("x") - t.0)
            .abs()
            .max((g("y") - t.1).abs())
            .max((g("z") - t.2).abs());
        worst = worst.max(err);
        farthest = farthest.max(t.0.hypot(t.1));
        // north-east-down is the same point, axes swapped
        assert!(
            (g("north") - t.1).abs() < 1e-3
                && (g("east") - t.0).abs() < 1e-3
                && (g("down") + t.2).abs() < 1e-3
        );
        // back to geodetic: the fix it came from
        assert!(
            (g("lat2") - p.0).abs() < 1e-9 && (g("lon2") - p.1).abs() < 1e-9,
            "{o:?} from {p:?}"
        );
        assert!((g("alt2") - p.2 * 0.3048).abs() < 1e-4, "{o:?}");
        // keep="true": the fix itself passes through, the renamed source does not
        assert_eq!(o.get_f64("lat"), Some(p.0));
        assert!(o.get("alt_ft").is_none());
    }
    println!(
        "geodetic->enu: worst difference from pymap3d {:.2e} m over {:.1} km",
        worst,
        farthest / 1000.0
    );
    assert!(worst < 1e-3, "{worst} m from pymap3d");
    rt.shutdown().await;
}

/// The rotation body → north-east-down for roll, pitch, yaw in degrees, written out element by
/// element (aerospace z-y-x), independent of the code under test.
fn body_to_ned(roll: f64, pitch: f64, yaw: f64) -> [[f64; 3]; 3] {
    let (sr, cr) = roll.to_radians().sin_cos();
    let (sp, cp) = pitch.to_radians().sin_cos();
    let (sy, cy) = yaw.to_radians().sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

fn transpose_times(m: [[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|j| (0..3).map(|i| m[i][j] * v[i]).sum())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rotated_dvl_gives_the_vehicles_north_east_down_velocity() {
    let (rt, mut feed, mut rx) = start().await;
    let mut truths = Vec::new();
    // a vehicle turning through a full circle, pitching and rolling, at 1.5 m/s
    for i in 0..120 {
        let t = f64::from(i) * 0.2;
        let (roll, pitch, heading) = (
            8.0 * (0.5 * t).sin(),
            -5.0 + 4.0 * (0.3 * t).cos(),
            f64::from(i) * 3.0,
        );
        feed.send(
            t,
            "nav.attitude",
            DataMap::new()
                .with("roll", roll)
                .with("pitch", pitch)
                .with("heading", heading),
        )
        .await;
        // the velocity in the vehicle frame (forward, a little crabbing, slowly sinking)
        let body = [1.5, 0.1 * (0.2 * t).sin(), 0.05];
        let ned = {
            let m = body_to_ned(roll, pitch, heading);
            [0, 1, 2].map(|i| (0..3).map(|j| m[i][j] * body[j]).sum::<f64>())
        };
        // the DVL is turned 45° to starboard on its mount: it sees the body velocity rotated back
        let sensor = transpose_times(body_to_ned(0.0, 0.0, 45.0), body);
        feed.send(
            t + 0.05,
            "dvl.raw",
            DataMap::new()
                .with("vx", sensor[0] * 1000.0)
                .with("vy", sensor[1] * 1000.0)
                .with("vz", sensor[2] * 1000.0),
        )
        .await;
        truths.push(ned);
        // let the attitude land before its DVL reading
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    let out = drain(&mut rx, "nav.velocity.ned", truths.len()).await;
    assert_eq!(out.len(), truths.len(), "one velocity per DVL reading");
    let mut worst = 0.0f64;
    for (o, t) in out.iter().zip(&truths) {
        for (k, v) in ["vn", "ve", "vd"].iter().zip(t) {
            worst = worst.max((o.get_f64(k).unwrap() - v).abs());
        }
        // keep="false": only what was converted
        assert!(o.get("roll").is_none() && o.get("surge").is_some());
    }
    println!("rotate: worst velocity error {worst:.2e} m/s");
    assert!(worst < 1e-9, "{worst}");

    // a reading 2 s after the latest attitude is not turned with that stale attitude …
    feed.send(
        100.0,
        "dvl.raw",
        DataMap::new()
            .with("vx", 1000.0)
            .with("vy", 0.0)
            .with("vz", 0.0),
    )
    .await;
    // … and one without the fields it needs is not published either; then a fresh pair is
    feed.send(101.9, "dvl.raw", DataMap::new().with("vx", 1.0))
        .await;
    feed.send(
        102.0,
        "nav.attitude",
        DataMap::new()
            .with("roll", 0.0)
            .with("pitch", 0.0)
            .with("heading", 90.0),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(20)).await;
    feed.send(
        102.1,
        "dvl.raw",
        DataMap::new()
            .with("vx", 1000.0)
            .with("vy", -1000.0)
            .with("vz", 0.0),
    )
    .await;
    let next = drain(&mut rx, "nav.velocity.ned", 1).await;
    assert_eq!(next.len(), 1);
    // the mount turns (1, -1) to (√2, 0), straight ahead; heading east makes it east
    let (vn, ve) = (
        next[0].get_f64("vn").unwrap(),
        next[0].get_f64("ve").unwrap(),
    );
    assert!(
        vn.abs() < 1e-9 && (ve - 2f64.sqrt()).abs() < 1e-9,
        "{:?}",
        next[0]
    );
    rt.shutdown().await;
}

#[test]
fn bad_conversions_are_refused_at_their_place() {
    let check = |module: &str| {
        let text = format!(
            "<seabus node=\"n\">\n  <medium name=\"bus\" url=\"inproc://\"/>\n  {module}\n</seabus>"
        );
        let spec = SystemSpec::parse("bad.xml", &text).unwrap();
        match seabus_modules::system::check(
            &spec,
            &seabus_support::registry(),
            &Catalogue::built_in(),
        ) {
            Ok(_) => panic!("{module} accepted"),
            Err(e) => e.to_string(),
        }
    };
    let e = check(
        r#"<module name="c" type="convert" medium="bus" input="a" output="b" fields="d ft->kn"/>"#,
    );
    assert!(
        e.contains("bad.xml:3:") && e.contains("do not convert"),
        "{e}"
    );
    let e = check(
        r#"<module name="c" type="convert" medium="bus" input="a" output="b" frames="geodetic->enu(43): lat, lon -> x, y"/>"#,
    );
    assert!(
        e.contains("bad.xml:3:") && e.contains("2 or 3 arguments"),
        "{e}"
    );
    let e = check(r#"<module name="c" type="convert" medium="bus" input="a" output="b"/>"#);
    assert!(e.contains("bad.xml:3:") && e.contains("`fields`"), "{e}");
}
