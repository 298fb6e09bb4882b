//! The recent past the console keeps for plots: a page opening a layout that plots a field of a
//! topic no layout plotted before (a layout opened with variables of its own) adds that field, and
//! the past the other layouts' plots show of that topic stays.

use super::common;
use super::harness::*;
use seabus_medium::DataMap;
use std::time::Duration;

/// The depth of `test.motion` over a minute.
const DEPTH: &str = r#"<layout name="depth" roles="observer">
  <plot label="Depth" window="60s"><series bind="test.motion.depth" label="Depth" unit="m"/></plot>
</layout>
"#;

/// Any field of `test.motion`, named when the layout is opened (`&field=temp`).
const ANY: &str = r#"<layout name="any" roles="observer">
  <var name="field" default="depth"/>
  <plot label="Field" window="60s"><series bind="test.motion.${field}" label="${field}"/></plot>
</layout>
"#;

/// How much of its window the plot labelled `label` spans, once it spans more than `least`.
fn spans(label: &str, least: f64) -> String {
    format!(
        "const p = window.seabusConsole && window.seabusConsole.plot('{label}');
         if (!p || !p.lines.length) return false;
         const xs = p.lines.flatMap((l) => l.points.map((q) => q[0]));
         const span = (Math.max(...xs) - Math.min(...xs)) / p.area.width;
         return span > {least} && span;"
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_layout_plotting_a_new_field_leaves_the_other_plots_their_past() {
    let dir = tempfile::tempdir().expect("dir");
    let (depth, any) = (dir.path().join("depth.xml"), dir.path().join("any.xml"));
    std::fs::write(&depth, DEPTH).expect("layout");
    std::fs::write(&any, ANY).expect("layout");
    let feed = r#"
  <bridge name="feed" media="net bus">
    <route from="net" to="bus" topics="test.**"/>
  </bridge>"#;
    let sys = start_with(feed, &[depth, any]);
    let net = common::schemes()
        .open("net", &sys.net, &seabus_medium::Node::new("feeder"))
        .expect("the network opens");
    let port = net.attach("feeder");
    // the depth and temperature at 5 Hz, for as long as the test (2 minutes at most)
    let feeder = tokio::spawn(async move {
        for i in 0..600 {
            let m = DataMap::new()
                .with("depth", 10.0 + (i as f64 / 20.0).sin())
                .with("temp", 4.0 + i as f64 / 1000.0);
            let _ = port.send("test.motion", m).await;
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    });
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "ivo", "observer-password").await;
    c.goto(&format!("{}/?layout=depth", sys.url))
        .await
        .expect("the depth layout");
    until(
        &c,
        Duration::from_secs(15),
        "the depth plot",
        &spans("Depth", 0.0),
    )
    .await;
    tokio::time::sleep(Duration::from_secs(20)).await;
    c.refresh().await.expect("reloaded");
    let before = until(
        &c,
        Duration::from_secs(5),
        "20 s of depth",
        &spans("Depth", 0.3),
    )
    .await;
    // a layout that plots the temperature, which no layout plotted before
    c.goto(&format!("{}/?layout=any&field=temp", sys.url))
        .await
        .expect("the layout of any field");
    until(
        &c,
        Duration::from_secs(10),
        "the temperature plotted",
        "const p = window.seabusConsole && window.seabusConsole.plot('Field');
         return p && p.lines.length > 0 && p.lines[0].points.length > 1;",
    )
    .await;
    // the depth plot, reloaded, has its past at once
    c.goto(&format!("{}/?layout=depth", sys.url))
        .await
        .expect("the depth layout again");
    let after = until(
        &c,
        Duration::from_secs(5),
        "the depth's past after the temperature was plotted",
        &spans("Depth", 0.3),
    )
    .await;
    assert!(
        after.as_f64() >= before.as_f64(),
        "the depth plot spanned {before} of its window, then {after}"
    );
    feeder.abort();
    c.close().await.expect("closed");
}
