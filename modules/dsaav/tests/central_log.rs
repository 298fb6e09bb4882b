//! The tracing layer that sends every seabus event to the DSAAV central log: records named after
//! the module's span or the event's `component`, levels mapped, DATA by target, each component at
//! its configured level, its own events never forwarded; and with no logging service to reach,
//! events are dropped and counted without holding anyone up.

use seabus_dsaav::central::{self, DATA_TARGET, Forwarder, MODULE_SPAN, QUEUE};
use seabus_dsaav::config::Database;
use seabus_dsaav::config_service;
use seabus_dsaav::logging::{self, LogFile};
use seabus_medium::{Medium, Node};
use std::time::{Duration, Instant};
use tracing_subscriber::prelude::*;

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

/// The central log's lines as (level, component, text), once `n` are there (at most 10 s).
async fn lines(path: &std::path::Path, n: usize) -> Vec<(String, String, String)> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let parsed: Vec<(String, String, String)> = text
            .lines()
            .map(|l| {
                // TIME LEVEL COMPONENT TEXT, the middle two padded
                let rest = l.split_once(' ').map_or("", |(_, r)| r).trim_start();
                let level = rest.split(' ').next().unwrap_or("").to_string();
                let rest = rest[level.len()..].trim_start();
                let component = rest.split(' ').next().unwrap_or("").to_string();
                let text = rest[component.len()..].trim().to_string();
                (level, component, text)
            })
            .collect();
        if parsed.len() >= n || Instant::now() > deadline {
            return parsed;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

// one test per process (nextest): the layer's forwarder is the program's
#[tokio::test(flavor = "current_thread")]
async fn events_reach_the_central_log_named_and_filtered() {
    let _guard = tracing_subscriber::registry()
        .with(seabus_modules::logs::layer())
        .set_default();
    let dir = tempfile::tempdir().unwrap();
    let bus = format!("dsaav+inproc://central{}", fastrand::u32(..));
    let n1 = open(&format!("{bus}?node=1"));
    let db = Database::parse(
        "v.ini",
        "[Logging]\nServer = 1:0\nLogLevel = LOG_INFO\n[gps]\nLogging.LogLevel = LOG_DEBUG\n",
    )
    .unwrap();
    let path = dir.path().join("v.log");
    let (_drain, draining) = tokio::sync::watch::channel(true);
    {
        let (m, log) = (n1.clone(), LogFile::open(path.clone(), 1 << 20, 1).unwrap());
        tokio::spawn(async move { logging::serve(&m, 0, log, draining).await });
        let m = n1.clone();
        tokio::spawn(async move { config_service::serve(&m, 2, db).await });
    }
    let n9 = open(&format!("{bus}?node=9"));
    let forwarder = Forwarder::attach(&n9, 100, "vehicle");

    async {
        tracing::warn!(target: "seabus_drivers::gps", "no fix");
        tracing::debug!(target: "seabus_drivers::gps", satellites = 3, "searching");
        tracing::trace!(target: "seabus_drivers::gps", "never forwarded");
        tracing::info!(target: DATA_TARGET, "lat=43.1 lon=16.4");
    }
    .instrument_in(tracing::info_span!(MODULE_SPAN, name = "gps"))
    .await;
    async {
        tracing::debug!(target: "seabus_modules::x", "below INFO: not sent");
        tracing::error!(target: "seabus_modules::x", component = "DepthFilter", "depth lost");
    }
    .instrument_in(tracing::info_span!(MODULE_SPAN, name = "helm"))
    .await;
    tracing::info!(target: "seabus", "running");
    tracing::warn!(target: "other_crate", "not ours: not sent");

    let got = lines(&path, 5).await;
    let want = [
        ("WARNING", "gps", "no fix"),
        ("DEBUG", "gps", "searching satellites=3"),
        ("DATA", "gps", "lat=43.1 lon=16.4"),
        ("ERROR", "DepthFilter", "depth lost"),
        ("INFO", "vehicle", "running"),
    ];
    let got_ref: Vec<(&str, &str, &str)> = got
        .iter()
        .map(|(a, b, c)| (a.as_str(), b.as_str(), c.as_str()))
        .collect();
    assert_eq!(got_ref, want);
    // nothing more comes (the skipped ones stay out)
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(lines(&path, 0).await.len(), 5);
    assert_eq!((forwarder.dropped(), central::failed()), (0, 0));
    forwarder.finish(Duration::from_secs(1)).await;
}

/// `instrument` for the tests: runs a future inside a span.
trait InSpan: std::future::Future + Sized {
    fn instrument_in(self, span: tracing::Span) -> tracing::instrument::Instrumented<Self> {
        tracing::Instrument::instrument(self, span)
    }
}
impl<F: std::future::Future> InSpan for F {}

#[tokio::test(flavor = "current_thread")]
async fn without_a_logging_service_records_are_dropped_and_counted() {
    let _guard = tracing_subscriber::registry()
        .with(seabus_modules::logs::layer())
        .set_default();
    // no configuration server on this backbone: the forwarder keeps looking
    let n9 = open(&format!(
        "dsaav+inproc://nobody{}?node=9",
        fastrand::u32(..)
    ));
    let forwarder = Forwarder::attach(&n9, 100, "vehicle");
    let events = 3 * QUEUE as u64;
    for i in 0..events {
        tracing::warn!(target: "seabus_modules::flood", "event {i}");
    }
    // the queue holds QUEUE; the rest were dropped at once, not waited for
    assert!(
        forwarder.dropped() >= events - QUEUE as u64,
        "dropped {} of {events}",
        forwarder.dropped()
    );
}
