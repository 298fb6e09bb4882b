//! Sentuators over DSAAV RPC: a depth sensor and an elevator actuator on their nodes answer get,
//! set and health calls, a station discovers a service by broadcast, and the sensor's readings
//! reach the listeners its configuration registers, as unreliable notifications.

use seabus_dsaav::config::Database;
use seabus_dsaav::rpc::{CallOptions, Outcome, RpcError};
use seabus_dsaav::sentuator::{self, Device, Sentuator, SentuatorClient, quantity};
use seabus_medium::{DataMap, Medium, Node};
use seabus_medium_dsaav::wire::Address;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

struct DepthSensor {
    depth: f64,
}

impl Device for DepthSensor {
    fn get(&mut self) -> DataMap {
        DataMap::new()
            .with("quantity", quantity::DEPTH)
            .with("measurement", sentuator::measurement::RAW)
            .with("depth", self.depth)
    }
}

struct Elevator {
    angle: f64,
}

impl Device for Elevator {
    fn get(&mut self) -> DataMap {
        DataMap::new()
            .with("quantity", quantity::ELEVATOR)
            .with("elevator", self.angle)
    }
    fn set(&mut self, values: &DataMap) -> Outcome {
        match values.get_f64("elevator") {
            Some(a) if a.abs() <= 30.0 => {
                self.angle = a;
                Ok(self.get())
            }
            Some(a) => Err((5, format!("elevator {a}° is past its 30° limit"))),
            None => Err((5, "set needs `elevator`".to_string())),
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sensors_and_actuators_answer_and_notify_their_listeners() {
    let bus = format!("dsaav+inproc://sent{}", fastrand::u32(..));
    let cfg = Database::parse(
        "starfish.ini",
        "[DepthSensor]\nServer = 4:0\nListeners = 3:1, 5:0\n[Elevators]\nServer = 2:0\n",
    )
    .unwrap();
    let at = |node, port| Address { node, port };

    let sensor_medium = open(&format!("{bus}?node=4"));
    let listeners = sentuator::listeners(&cfg, "DepthSensor").unwrap();
    assert_eq!(listeners, vec![at(3, 1), at(5, 0)]);
    let sensor = Sentuator::start(
        &sensor_medium,
        0,
        9,
        DepthSensor { depth: 12.5 },
        &["DepthSensor"],
        listeners,
    );
    let elevator_medium = open(&format!("{bus}?node=2"));
    let _elevator = Sentuator::start(
        &elevator_medium,
        0,
        9,
        Elevator { angle: 0.0 },
        &["Elevators"],
        vec![],
    );

    // two listeners collect notifications
    let heard: Arc<Mutex<Vec<(Address, f64)>>> = Arc::default();
    let mut listener_media = Vec::new();
    for (node, port) in [(3u16, 1u16), (5, 0)] {
        let m = open(&format!("{bus}?node={node}"));
        let h = heard.clone();
        let lm = m.clone();
        tokio::spawn(async move {
            sentuator::listen(&lm, port, move |_, reading| {
                h.lock().unwrap().push((
                    Address { node, port },
                    reading.get_f64("depth").unwrap_or(f64::NAN),
                ));
            })
            .await
        });
        listener_media.push(m);
    }

    let station = open(&format!("{bus}?node=7"));
    let client = SentuatorClient::new(&station, 3, CallOptions::default());
    let reading = client.get(at(4, 0)).await.unwrap();
    assert_eq!(reading.get_f64("depth"), Some(12.5));
    assert_eq!(reading.get_i64("quantity"), Some(quantity::DEPTH));
    match client
        .set(at(4, 0), &DataMap::new().with("depth", 1.0f64))
        .await
    {
        Err(RpcError::Failed { status: 3, .. }) => {}
        other => panic!("a sensor cannot be set, got {other:?}"),
    }
    let set = client
        .set(at(2, 0), &DataMap::new().with("elevator", 5.0f64))
        .await
        .unwrap();
    assert_eq!(set.get_f64("elevator"), Some(5.0));
    assert_eq!(
        client.get(at(2, 0)).await.unwrap().get_f64("elevator"),
        Some(5.0)
    );
    match client
        .set(at(2, 0), &DataMap::new().with("elevator", 45.0f64))
        .await
    {
        Err(RpcError::Failed { message, .. }) => assert!(message.contains("30° limit")),
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert_eq!(
        client.health(at(4, 0)).await.unwrap(),
        (
            seabus_dsaav::health::ComponentState::Healthy,
            vec!["DepthSensor".to_string()]
        )
    );
    let (found, _, services) = client.discover().await.unwrap();
    assert!(
        (found == at(4, 0) && services == ["DepthSensor"])
            || (found == at(2, 0) && services == ["Elevators"]),
        "{found} {services:?}"
    );

    // ten readings, each notified to both listeners
    for i in 0..10 {
        sensor.device().lock().unwrap().depth = f64::from(i);
        assert_eq!(sensor.notify().await, 2);
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while heard.lock().unwrap().len() < 20 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let heard = heard.lock().unwrap();
    for who in [at(3, 1), at(5, 0)] {
        let depths: Vec<f64> = heard
            .iter()
            .filter(|(a, _)| *a == who)
            .map(|(_, d)| *d)
            .collect();
        assert_eq!(depths, (0..10).map(f64::from).collect::<Vec<_>>(), "{who}");
    }
}
