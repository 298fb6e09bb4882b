//! A vehicle that leaves the fleet is OFFLINE in the shore's health snapshot, as a component that
//! stopped would be; one that comes back is HEALTHY again.

use seabus_medium::{DataMap, Payload, Topic};
use seabus_modules::system::SystemSpec;
use seabus_modules::{Catalogue, Registry, Runtime};
use std::time::Duration;
use tokio::time::{Instant, timeout_at};

const RULES: &str = r#"<health publish="fleet.health" period="200ms">
  <component name="auv1" mode="active" timeout="15s"/>
  <component name="auv2" mode="active" timeout="15s"/>
</health>"#;

const SYSTEM: &str = r#"<seabus node="shore">
  <medium name="bus" url="inproc://"/>
  <module name="health" type="health-monitor" media="bus" rules="rules.xml"/>
</seabus>"#;

fn member(node: &str, online: bool) -> DataMap {
    DataMap::new()
        .and("node", node)
        .and("online", online)
        .and("since", 1.0e9)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vehicle_that_leaves_the_fleet_is_offline() {
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
    let bus = rt.medium("bus").unwrap();
    let mut health = bus.attach("watch").subscribed("fleet.health").unwrap();
    // the monitor is running (and listening to the fleet) before anything is announced
    timeout_at(Instant::now() + Duration::from_secs(10), health.recv())
        .await
        .expect("a first snapshot")
        .unwrap();
    let fleet = bus.attach("fleet");
    let topic = Topic::new(seabus_medium::topic::FLEET).unwrap();
    let state_of = |map: &DataMap, node: &str| {
        map.get("components")
            .and_then(|c| c.as_map())
            .and_then(|c| c.get_str(node))
            .map(str::to_string)
    };
    // both online
    for node in ["auv1", "auv2"] {
        fleet
            .send(topic.as_str(), Payload::from(member(node, true)))
            .await
            .unwrap();
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let m = timeout_at(deadline, health.recv())
            .await
            .expect("a snapshot")
            .unwrap();
        let map = m.payload.as_map().unwrap().clone();
        if state_of(&map, "auv1").as_deref() == Some("HEALTHY")
            && state_of(&map, "auv2").as_deref() == Some("HEALTHY")
        {
            break;
        }
    }
    // auv2 leaves
    fleet
        .send(topic.as_str(), Payload::from(member("auv2", false)))
        .await
        .unwrap();
    loop {
        let m = timeout_at(deadline + Duration::from_secs(5), health.recv())
            .await
            .expect("a snapshot with auv2 offline")
            .unwrap();
        let map = m.payload.as_map().unwrap().clone();
        if state_of(&map, "auv2").as_deref() == Some("OFFLINE") {
            assert_eq!(
                state_of(&map, "auv1").as_deref(),
                Some("HEALTHY"),
                "{map:?}"
            );
            break;
        }
    }
    rt.shutdown().await;
}
