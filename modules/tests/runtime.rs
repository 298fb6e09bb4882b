//! The runtime: ticks at their rates, messages to handlers, failing and panicking modules restarted
//! with back-off and reported, and shutdown within its grace even when a module hangs.

use async_trait::async_trait;
use seabus_medium::{DataMap, Medium, MediumStats, Message, Node};
use seabus_modules::runtime::{FIRST_BACKOFF, MEDIA_EVERY, MEDIA_TOPIC, State, Unit};
use seabus_modules::{
    Built, Catalogue, Context, Declaration, Module, ModuleError, ModuleKind, Runtime, TimerId,
    TopicDecl,
};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::time::Instant;

#[derive(Default)]
struct Log {
    starts: Mutex<Vec<Instant>>,
    ticks: AtomicU64,
    messages: AtomicU64,
    stops: AtomicU64,
}

/// A module whose behaviour each test picks.
struct Probe {
    log: Arc<Log>,
    fail_first: u64,
    instance: u64,
    panic: bool,
    hang: bool,
}

#[async_trait]
impl Module for Probe {
    async fn start(&mut self, _ctx: &mut Context) -> Result<(), ModuleError> {
        self.log.starts.lock().unwrap().push(Instant::now());
        Ok(())
    }

    async fn on_timer(&mut self, _ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        self.log.ticks.fetch_add(1, Ordering::SeqCst);
        if self.instance < self.fail_first {
            return Err(ModuleError::msg(format!(
                "instance {} gives up",
                self.instance
            )));
        }
        if self.panic && self.instance == 0 {
            panic!("boom");
        }
        Ok(())
    }

    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        self.log.messages.fetch_add(1, Ordering::SeqCst);
        if self.hang {
            std::future::pending::<()>().await;
        }
        let n = msg
            .payload
            .as_map()
            .and_then(|m| m.get_i64("n"))
            .unwrap_or(0);
        ctx.publish("probe.out", DataMap::new().with("n", n + 1))
            .await
    }

    async fn stop(&mut self, _ctx: &mut Context) {
        self.log.stops.fetch_add(1, Ordering::SeqCst);
    }
}

fn unit(log: &Arc<Log>, tick: Option<Duration>, fail_first: u64, panic: bool, hang: bool) -> Unit {
    let log = log.clone();
    let instances = Arc::new(AtomicU64::new(0));
    Unit {
        name: "probe".into(),
        type_name: "probe".into(),
        media: vec!["bus".into()],
        tick,
        build: Arc::new(move || {
            Ok(Built {
                decl: Declaration::new(ModuleKind::Supporting)
                    .consumes(TopicDecl::topic("probe.in"))
                    .produces(TopicDecl::topic("probe.out")),
                module: Box::new(Probe {
                    log: log.clone(),
                    fail_first,
                    instance: instances.fetch_add(1, Ordering::SeqCst),
                    panic,
                    hang,
                }),
            })
        }),
    }
}

fn start(units: Vec<Unit>) -> (Runtime, Medium) {
    let node = Node::new("test");
    let bus = Medium::in_process("bus", &node);
    let media = BTreeMap::from([("bus".to_string(), bus.clone())]);
    (
        Runtime::with_units(node, media, "bus", units, Catalogue::built_in()),
        bus,
    )
}

#[tokio::test(start_paused = true)]
async fn ticks_arrive_at_the_configured_rate() {
    let log = Arc::new(Log::default());
    let (rt, _bus) = start(vec![unit(
        &log,
        Some(Duration::from_millis(100)),
        0,
        false,
        false,
    )]);
    tokio::time::sleep(Duration::from_millis(1050)).await;
    assert_eq!(log.ticks.load(Ordering::SeqCst), 10);
    rt.shutdown().await;
    assert_eq!(log.stops.load(Ordering::SeqCst), 1, "stop was called once");
}

#[tokio::test]
async fn messages_reach_handlers_and_what_they_publish_goes_out() {
    let log = Arc::new(Log::default());
    let (rt, bus) = start(vec![unit(&log, None, 0, false, false)]);
    let mut out = bus.attach("test").subscribed("probe.out").unwrap();
    let tx = bus.attach("tx");
    tokio::time::sleep(Duration::from_millis(50)).await;
    for n in 0..5i64 {
        tx.send("probe.in", DataMap::new().with("n", n))
            .await
            .unwrap();
    }
    let mut got = Vec::new();
    while got.len() < 5 {
        let m = tokio::time::timeout(Duration::from_secs(5), out.recv())
            .await
            .unwrap()
            .unwrap();
        got.push(m.payload.as_map().unwrap().get_i64("n").unwrap());
    }
    assert_eq!(got, [1, 2, 3, 4, 5]);
    rt.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn a_failing_module_is_restarted_with_growing_back_off_and_reported() {
    let log = Arc::new(Log::default());
    let (rt, bus) = start(vec![unit(
        &log,
        Some(Duration::from_millis(10)),
        3,
        false,
        false,
    )]);
    let mut status = bus.attach("status").subscribed("seabus.module.*").unwrap();
    tokio::time::sleep(Duration::from_secs(2)).await;
    let starts = log.starts.lock().unwrap().clone();
    assert_eq!(starts.len(), 4, "three failures, then a good instance");
    let gaps: Vec<Duration> = starts.windows(2).map(|w| w[1] - w[0]).collect();
    // each instance fails at its first tick (10 ms), then waits 100, 200, 400 ms
    for (i, gap) in gaps.iter().enumerate() {
        let backoff = FIRST_BACKOFF * 2u32.pow(i as u32);
        assert!(
            *gap >= backoff && *gap < backoff + Duration::from_millis(50),
            "gap {i}: {gap:?}"
        );
    }
    let st = &rt.status()[0];
    assert_eq!((st.state, st.restarts), (State::Running, 3));
    let mut states = Vec::new();
    while let Ok(m) = status.try_recv() {
        let map = m.payload.as_map().unwrap().clone();
        states.push(map.get_str("state").unwrap().to_string());
        if map.get_str("state") == Some("failed") {
            assert!(map.get_str("error").unwrap().contains("gives up"), "{map}");
        }
    }
    assert_eq!(
        states.iter().filter(|s| *s == "failed").count(),
        3,
        "{states:?}"
    );
    assert_eq!(states.last().map(String::as_str), Some("running"));
    rt.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn a_panicking_module_is_restarted_and_the_panic_reported() {
    let log = Arc::new(Log::default());
    let (rt, bus) = start(vec![unit(
        &log,
        Some(Duration::from_millis(10)),
        0,
        true,
        false,
    )]);
    let mut status = bus
        .attach("status")
        .subscribed("seabus.module.probe")
        .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(log.starts.lock().unwrap().len(), 2);
    let mut saw_panic = false;
    while let Ok(m) = status.try_recv() {
        if let Some(e) = m.payload.as_map().unwrap().get_str("error") {
            saw_panic |= e == "panicked: boom";
        }
    }
    assert!(saw_panic);
    assert_eq!(rt.status()[0].state, State::Running);
    rt.shutdown().await;
}

#[tokio::test]
async fn shutdown_cuts_off_a_hanging_module_within_its_grace() {
    let log = Arc::new(Log::default());
    let (rt, bus) = start(vec![unit(&log, None, 0, false, true)]);
    tokio::time::sleep(Duration::from_millis(50)).await;
    bus.attach("tx")
        .send("probe.in", DataMap::new())
        .await
        .unwrap();
    let waited = Instant::now();
    while log.messages.load(Ordering::SeqCst) == 0 && waited.elapsed() < Duration::from_secs(5) {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let begun = Instant::now();
    rt.shutdown().await;
    let took = begun.elapsed();
    assert!(took < Duration::from_secs(2), "shutdown took {took:?}");
}

/// A module type whose builder panics on its first call.
fn panicking_build_unit(log: &Arc<Log>) -> Unit {
    let calls = Arc::new(AtomicU64::new(0));
    let log = log.clone();
    Unit {
        name: "fragile".into(),
        type_name: "fragile".into(),
        media: vec!["bus".into()],
        tick: None,
        build: Arc::new(move || {
            if calls.fetch_add(1, Ordering::SeqCst) == 0 {
                panic!("cannot build");
            }
            Ok(Built {
                decl: Declaration::new(ModuleKind::Supporting),
                module: Box::new(Probe {
                    log: log.clone(),
                    fail_first: 0,
                    instance: 1,
                    panic: false,
                    hang: false,
                }),
            })
        }),
    }
}

#[tokio::test(start_paused = true)]
async fn regression_a_panic_while_building_is_a_failure_like_any_other() {
    let log = Arc::new(Log::default());
    let (rt, _bus) = start(vec![panicking_build_unit(&log)]);
    tokio::time::sleep(Duration::from_millis(500)).await;
    let st = &rt.status()[0];
    assert_eq!((st.state, st.restarts), (State::Running, 1), "{st:?}");
    assert_eq!(log.starts.lock().unwrap().len(), 1);
    rt.shutdown().await;
}

/// A module whose `stop` takes far longer than the shutdown grace.
struct SlowStop(Arc<AtomicU64>);

#[async_trait]
impl Module for SlowStop {
    async fn stop(&mut self, _ctx: &mut Context) {
        tokio::time::sleep(Duration::from_secs(3)).await;
        self.0.store(1, Ordering::SeqCst);
    }
}

#[tokio::test(start_paused = true)]
async fn regression_a_module_cut_off_at_shutdown_does_not_run_on() {
    let finished = Arc::new(AtomicU64::new(0));
    let flag = finished.clone();
    let unit = Unit {
        name: "slow".into(),
        type_name: "slow".into(),
        media: vec!["bus".into()],
        tick: None,
        build: Arc::new(move || {
            Ok(Built {
                decl: Declaration::new(ModuleKind::Supporting),
                module: Box::new(SlowStop(flag.clone())),
            })
        }),
    };
    let (rt, _bus) = start(vec![unit]);
    tokio::time::sleep(Duration::from_millis(10)).await;
    let begun = Instant::now();
    rt.shutdown().await;
    assert!(begun.elapsed() < Duration::from_secs(2));
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(
        finished.load(Ordering::SeqCst),
        0,
        "its stop was cut off with it"
    );
}

#[tokio::test]
async fn consumed_topics_take_data_only() {
    // a module consuming `probe.in` is not handed commands on it (nor would a module accepting
    // commands be handed data)
    let log = Arc::new(Log::default());
    let (rt, bus) = start(vec![unit(&log, None, 0, false, false)]);
    tokio::time::sleep(Duration::from_millis(50)).await;
    let tx = bus.attach("tx");
    tx.command("probe.in", DataMap::new()).await.unwrap();
    tx.send("probe.in", DataMap::new()).await.unwrap();
    let waited = Instant::now();
    while log.messages.load(Ordering::SeqCst) == 0 && waited.elapsed() < Duration::from_secs(5) {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(log.messages.load(Ordering::SeqCst), 1);
    rt.shutdown().await;
}

#[tokio::test(start_paused = true)]
async fn the_media_counters_are_published_when_they_change_and_only_then() {
    let node = Node::new("test");
    let bus = Medium::in_process("bus", &node);
    let line = Medium::in_process("line", &node);
    let media = BTreeMap::from([
        ("bus".to_string(), bus.clone()),
        ("line".to_string(), line.clone()),
    ]);
    let mut watch = bus.attach("watch").subscribed(MEDIA_TOPIC).unwrap();
    let rt = Runtime::with_units(node, media, "bus", Vec::new(), Catalogue::built_in());
    let next = |watch: &mut seabus_medium::Interface| {
        let m = watch.try_recv().expect("the media's counters");
        let map = m.payload.as_map().unwrap().clone();
        assert_eq!(Catalogue::built_in().validate("media-stats", &map), Ok(()));
        let of = |name: &str| {
            MediumStats::from_map(
                map.get_path(&format!("media.{name}"))
                    .and_then(|v| v.as_map())
                    .unwrap(),
            )
        };
        (of("bus"), of("line"))
    };
    // once at the start, all quiet
    tokio::time::sleep(Duration::from_millis(10)).await;
    let (_, first) = next(&mut watch);
    assert_eq!(first, MediumStats::default());
    // the line reads 10 messages, a receiver with room for 4 misses 6, and it drops garbage
    let mut slow = line.attach_with("slow", 4, 4);
    slow.subscribe("x").unwrap();
    let ingress = line.ingress();
    for _ in 0..10 {
        ingress.originate(
            seabus_medium::Topic::new("x").unwrap(),
            DataMap::new().into(),
        );
    }
    ingress.reject("garbage", "noise");
    ingress.dropped(17);
    ingress.overrun(3);
    tokio::time::sleep(MEDIA_EVERY).await;
    let (_, now) = next(&mut watch);
    assert_eq!(now, line.stats());
    assert_eq!(
        (
            now.received,
            now.rejected_total(),
            now.dropped_bytes,
            now.overruns
        ),
        (10, 1, 17, 3)
    );
    assert_eq!(now.queue_dropped, BTreeMap::from([("slow".to_string(), 6)]));
    // nothing read or lost since: nothing published, however long
    tokio::time::sleep(MEDIA_EVERY * 5).await;
    assert!(watch.try_recv().is_err(), "published without a change");
    rt.shutdown().await;
}
