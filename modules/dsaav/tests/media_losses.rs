//! The health snapshot lists the media that lost anything, with their counters as the runtime
//! publishes them on `seabus.media`, and leaves out the media that lost nothing.

use seabus_medium::{DataMap, MediumStats, Topic};
use seabus_modules::system::SystemSpec;
use seabus_modules::{Catalogue, Registry, Runtime};
use std::time::Duration;
use tokio::time::{Instant, timeout_at};

const RULES: &str = r#"<health publish="vehicle.health" period="200ms">
  <component name="gen" mode="active" timeout="30s"/>
</health>"#;

const SYSTEM: &str = r#"<seabus node="n">
  <medium name="bus" url="inproc://"/>
  <medium name="line" url="inproc://"/>
  <module name="health" type="health-monitor" media="bus" rules="rules.xml"/>
</seabus>"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_health_snapshot_lists_the_media_that_lost_anything() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("rules.xml"), RULES).unwrap();
    let path = dir.path().join("system.xml");
    std::fs::write(&path, SYSTEM).unwrap();
    let spec = SystemSpec::load(&path).unwrap();
    let mut registry = Registry::new();
    seabus_dsaav::register(&mut registry);
    let rt = Runtime::start(&spec, &registry, Catalogue::built_in())
        .await
        .unwrap();
    let (bus, line) = (rt.medium("bus").unwrap(), rt.medium("line").unwrap());
    let mut health = bus.attach("watch").subscribed("vehicle.health").unwrap();
    // the monitor is running (and listening to the media's counters) before anything is lost
    timeout_at(Instant::now() + Duration::from_secs(10), health.recv())
        .await
        .expect("a first snapshot")
        .unwrap();
    // the line reads 20 messages, of which a receiver with room for 5 misses 15, rejects a run of
    // garbage and drops its 6 bytes
    let mut slow = line.attach_with("slow", 5, 5);
    slow.subscribe("x").unwrap();
    let ingress = line.ingress();
    for _ in 0..20 {
        ingress.originate(Topic::new("x").unwrap(), DataMap::new().into());
    }
    ingress.reject("garbage", "noise");
    ingress.dropped(6);
    // the media's counters are sampled now and then: one sample may fall while the line still
    // reads (20 received but not yet all handed out, the garbage not yet counted), a later one
    // has everything
    let done = line.stats();
    let deadline = Instant::now() + Duration::from_secs(5);
    let listed = loop {
        let m = timeout_at(deadline, health.recv())
            .await
            .expect("a snapshot listing the line with everything it read, within 5 s")
            .unwrap();
        let map = m.payload.as_map().unwrap().clone();
        if let Some(media) = map.get("media").and_then(|v| v.as_map())
            && let Some(line) = media.get("line").and_then(|v| v.as_map())
            && MediumStats::from_map(line) == done
        {
            break media.clone();
        }
    };
    let names: Vec<&str> = listed.iter().map(|(k, _)| k).collect();
    assert_eq!(names, ["line"], "only the medium that lost anything");
    let counters = MediumStats::from_map(listed.get("line").unwrap().as_map().unwrap());
    assert_eq!(counters, line.stats());
    assert_eq!(counters.queue_dropped["slow"], 15);
    assert_eq!(
        (counters.received, counters.dropped_bytes),
        (20, 6),
        "{counters:?}"
    );
    assert_eq!(counters.rejected["garbage"], 1);
    rt.shutdown().await;
}
