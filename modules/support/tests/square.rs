//! The `square` helm steps back while someone else holds control (the console's
//! `console.control`), and starts a new leg when they release it.

mod common;

use common::Feed;
use seabus_medium::{DataMap, Interface, Kind};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::time::Duration;

/// The course commands received within `wait`.
async fn commands(rx: &mut Interface, wait: Duration) -> usize {
    let deadline = tokio::time::Instant::now() + wait;
    let mut n = 0;
    while let Ok(Some(_)) = tokio::time::timeout_at(deadline, rx.recv()).await {
        n += 1;
    }
    n
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_helm_pauses_while_someone_holds_control() {
    let spec = SystemSpec::parse(
        "square.xml",
        r#"<seabus node="n">
  <medium name="bus" url="inproc://"/>
  <module name="helm" type="square" medium="bus" tick="20Hz" side="50"/>
</seabus>"#,
    )
    .unwrap();
    let rt = Runtime::start(&spec, &seabus_support::registry(), Catalogue::built_in())
        .await
        .unwrap();
    let bus = rt.medium("bus").unwrap().clone();
    let mut rx = bus.attach("rx");
    rx.subscribe_kind("cmd.course", Some(Kind::Command))
        .unwrap();
    let mut feed = Feed::new(&bus);
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert!(
        commands(&mut rx, Duration::from_millis(500)).await >= 5,
        "commanding"
    );
    feed.send(
        1.0,
        "console.control",
        DataMap::new().with("holder", "ana").with("since", 1.0),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    while rx.try_recv().is_ok() {}
    assert_eq!(
        commands(&mut rx, Duration::from_millis(600)).await,
        0,
        "silent while ana has control"
    );
    feed.send(
        2.0,
        "console.control",
        DataMap::new().with("holder", "").with("since", 0.0),
    )
    .await;
    assert!(
        commands(&mut rx, Duration::from_millis(500)).await >= 5,
        "commanding again once released"
    );
    rt.shutdown().await;
}
