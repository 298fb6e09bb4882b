//! What the page looks like at the window sizes pilots use: every widget's text fits its box
//! (nothing cut short, nothing over another widget or outside the window), Stop is in view, the
//! kept-course bar moves nothing, and the widgets that read numbers read them true (a heading of
//! 359.9° is 0, a plot's series with no producer says so, the health table speaks in words).
//! Checked from the page's own layout (its boxes and SVG text), not from screenshots, which are
//! kept under `target/console-screenshots/` to look at.

use super::common;
use super::harness::*;
use fantoccini::{Client, Locator};
use seabus_medium::{DataMap, Value};
use serde_json::json;
use std::time::Duration;

/// Checks the page as it is drawn; returns what does not fit, one line each (empty: all fits).
///
/// - a widget that shows reaches past the window's right edge, or overlaps another widget;
/// - an element with text of its own is cut short (its text wider than its box where the box
///   hides what overflows), or lies outside its widget (a scrolled box's rows may be below);
/// - a table is wider than the box it scrolls in (a column hidden sideways);
/// - two texts of one drawing (gauge, track) overlap, or a text lies outside its drawing;
/// - a gauge's needle reaches into its numbers;
/// - a layout with a safe action has its header's Stop out of view.
const FITS: &str = r#"
const problems = [];
const vw = document.documentElement.clientWidth, vh = window.innerHeight;
const shown = (e) => { const r = e.getBoundingClientRect(); return r.width > 0 && r.height > 0; };
const name = (w) => w.dataset.widgetId || w.dataset.kind || 'widget';
const ownText = (e) => [...e.childNodes].some((n) => n.nodeType === 3 && n.textContent.trim());
const overlap = (a, b) => Math.min(a.right, b.right) - Math.max(a.left, b.left) > 1
  && Math.min(a.bottom, b.bottom) - Math.max(a.top, b.top) > 1;
const leaves = [...document.querySelectorAll('[data-testid=widget]')]
  .filter((w) => shown(w) && !w.querySelector('[data-testid=widget]'));
for (const w of leaves) {
  const wr = w.getBoundingClientRect();
  if (wr.right > vw + 1) problems.push(`${name(w)}: reaches ${Math.round(wr.right)} px, past the window's ${vw}`);
  for (const e of w.querySelectorAll('*')) {
    if (!ownText(e) || !shown(e) || e.closest('svg')) continue;
    const cs = getComputedStyle(e);
    if (cs.visibility === 'hidden') continue;
    const text = e.textContent.trim().slice(0, 40);
    const hides = cs.overflowX !== 'visible' || cs.textOverflow === 'ellipsis';
    if (hides && e.clientWidth > 0 && e.scrollWidth > e.clientWidth + 1) {
      problems.push(`${name(w)}: "${text}" is cut short (${e.scrollWidth} px in ${e.clientWidth})`);
    }
    const r = e.getBoundingClientRect();
    const scrolled = e.closest('.scroll, .log-lines');
    const box = scrolled ? scrolled.getBoundingClientRect() : wr;
    if (r.left < box.left - 1 || r.right > box.right + 1 || (!scrolled && (r.top < wr.top - 1 || r.bottom > wr.bottom + 1))) {
      problems.push(`${name(w)}: "${text}" lies outside its ${scrolled ? 'box' : 'widget'}`);
    }
  }
  for (const t of w.querySelectorAll('table')) {
    const box = t.closest('.scroll') || t.parentElement;
    if (t.scrollWidth > box.clientWidth + 1) {
      const cols = [...t.querySelectorAll('th')].filter((h) => h.getBoundingClientRect().right > box.getBoundingClientRect().right + 1).map((h) => h.textContent);
      const widths = [...t.querySelectorAll('th')].map((h) => `${h.textContent} ${Math.round(h.getBoundingClientRect().width)}`);
      problems.push(`${name(w)}: its table is ${t.scrollWidth} px in ${box.clientWidth}: ${cols.join(', ') || 'a column'} out of sight (columns: ${widths.join(', ')})`);
    }
  }
  for (const s of w.querySelectorAll('svg')) {
    if (!shown(s)) continue;
    const sr = s.getBoundingClientRect();
    const texts = [...s.querySelectorAll('text')].filter((t) => t.textContent.trim() && shown(t))
      .map((t) => [t.textContent.trim(), t.getBoundingClientRect()]);
    texts.forEach(([a, ra], i) => {
      if (ra.left < sr.left - 1 || ra.right > sr.right + 1 || ra.top < sr.top - 1 || ra.bottom > sr.bottom + 1) {
        problems.push(`${name(w)}: "${a}" lies outside its drawing`);
      }
      for (const [b, rb] of texts.slice(i + 1)) {
        if (overlap(ra, rb)) problems.push(`${name(w)}: "${a}" and "${b}" overlap`);
      }
    });
    const needle = s.querySelector('[data-testid=needle]');
    if (needle) {
      const cx = +needle.getAttribute('x1'), cy = +needle.getAttribute('y1');
      const tip = cy - +needle.getAttribute('y2');
      for (const t of s.querySelectorAll('.gauge-tick')) {
        const b = t.getBBox();
        const dx = Math.max(b.x - cx, 0, cx - (b.x + b.width)), dy = Math.max(b.y - cy, 0, cy - (b.y + b.height));
        if (Math.hypot(dx, dy) < tip + 2) problems.push(`${name(w)}: the needle (${tip}) reaches the number ${t.textContent} (${Math.hypot(dx, dy).toFixed(1)} from the centre)`);
      }
    }
  }
}
leaves.forEach((a, i) => {
  for (const b of leaves.slice(i + 1)) {
    if (overlap(a.getBoundingClientRect(), b.getBoundingClientRect())) problems.push(`${name(a)} and ${name(b)} overlap`);
  }
});
const stop = document.querySelector('[data-testid=header-stop]');
if (stop && !stop.hidden) {
  const r = stop.getBoundingClientRect();
  if (!shown(stop) || r.bottom > vh || r.right > vw || r.top < 0) problems.push('the header stop is out of view');
}
return problems;
"#;

/// Where the widgets are: `[id, left, top, width]` of each (their heights follow what they hold:
/// a history grows with its rows).
const BOXES: &str = "return [...document.querySelectorAll('[data-testid=widget]')]
  .map((w) => [w.dataset.widgetId, ...['left', 'top', 'width'].map((k) => Math.round(w.getBoundingClientRect()[k]))]);";

/// Opens layout `name` (with `query`, `&k=v…`) and waits until its widgets are drawn.
async fn open(c: &Client, url: &str, name: &str, query: &str) {
    c.goto(&format!("{url}/?layout={name}{query}"))
        .await
        .expect("the page");
    until(
        c,
        Duration::from_secs(15),
        &format!("layout {name}"),
        &format!(
            "const s = window.seabusConsole && window.seabusConsole.state();
             return s && s.layout === '{name}' && document.querySelectorAll('[data-testid=widget]').length > 1;"
        ),
    )
    .await;
}

/// What does not fit on the page as it is now, each tab of it shown in turn (`at`: the size and
/// layout, to name in the problems).
async fn misfits(c: &Client, at: &str) -> Vec<String> {
    let tabs = js(c, "return document.querySelectorAll('[role=tab]').length;").await;
    let mut out = Vec::new();
    for i in 0..tabs.as_u64().unwrap_or(0).max(1) {
        js(
            c,
            &format!(
                "const t = document.querySelectorAll('[role=tab]')[{i}]; if (t) t.click(); return true;"
            ),
        )
        .await;
        tokio::time::sleep(Duration::from_millis(300)).await;
        screenshot(c, &format!("fit-{at}-{i}.png").replace(' ', "-")).await;
        let found = js(c, FITS).await;
        for p in found.as_array().expect("a list") {
            out.push(format!(
                "{at} (tab {i}): {}",
                p.as_str().unwrap_or_default()
            ));
        }
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_shipped_layouts_fit_at_1280x800_and_1600x900() {
    let layouts = [
        repo("configs/console/pilot.xml"),
        repo("configs/console/scientist.xml"),
        repo("configs/fleet/console/fleet.xml"),
        repo("configs/fleet/console/vehicle.xml"),
    ];
    let helm = format!(
        "{IVER}\n  <module name=\"helm\" type=\"square\" medium=\"bus\" tick=\"1Hz\" side=\"60\" \
         speed=\"1.5\" depth=\"0\" heading=\"0\"/>"
    );
    let sys = start_with(&helm, &layouts);
    let driver = chromedriver();
    let mut problems = Vec::new();
    for (w, h) in [(1280, 800), (1600, 900)] {
        let c = browser_sized(&driver, w, h).await;
        log_in(&c, &sys.url, "pilot", "pilot-password").await;
        open(&c, &sys.url, "pilot", "").await;
        // the numbers are in, the history has rows (a course and a stop, answered)
        until(
            &c,
            Duration::from_secs(20),
            "the vehicle's numbers",
            "return [...document.querySelectorAll('[data-kind=readout] [data-testid=value]')]
                .filter((v) => /[0-9]/.test(v.textContent)).length >= 4;",
        )
        .await;
        if w == 1280 {
            take_control(&c, "pilot").await;
            let before = js(&c, BOXES).await;
            c.find(Locator::Css("body"))
                .await
                .expect("the page")
                .send_keys("\u{E014}")
                .await
                .expect("ArrowRight");
            until(
                &c,
                Duration::from_secs(10),
                "the kept course's bar",
                "return document.querySelector('[data-testid=kept][data-command=course]');",
            )
            .await;
            // the bar covers room kept for it: no widget moved or changed size
            assert_eq!(
                js(&c, BOXES).await,
                before,
                "the kept course's bar moved the page"
            );
            c.find(Locator::Css("[data-testid=header-stop]"))
                .await
                .expect("the header's stop")
                .click()
                .await
                .expect("clicked");
            until(
                &c,
                Duration::from_secs(10),
                "the stop in the history",
                "return [...document.querySelectorAll('[data-kind=history] tr[data-state]')]
                    .some((r) => r.dataset.state !== 'pending' && /stop/.test(r.textContent));",
            )
            .await;
        }
        problems.extend(misfits(&c, &format!("{w}x{h} pilot")).await);
        for (name, query) in [("fleet", ""), ("vehicle", "&vehicle=auv2")] {
            open(&c, &sys.url, name, query).await;
            tokio::time::sleep(Duration::from_secs(2)).await;
            problems.extend(misfits(&c, &format!("{w}x{h} {name}")).await);
        }
        // the scientist's layout is an observer's
        c.goto(&format!("{}/logout", sys.url))
            .await
            .expect("logged out");
        log_in(&c, &sys.url, "ivo", "observer-password").await;
        open(&c, &sys.url, "scientist", "").await;
        tokio::time::sleep(Duration::from_secs(2)).await;
        problems.extend(misfits(&c, &format!("{w}x{h} scientist")).await);
        c.close().await.expect("closed");
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// A narrow column of widgets over `test.**`: a compass gauge, a long number, a plot with a
/// series nothing produces, a health table and the commands' history.
const NARROW: &str = r#"<layout name="narrow" roles="pilot">
  <command name="note" topic="cmd.note" fields="text=, mode=standby" lease="false"/>
  <row sizes="1 3">
    <column>
      <gauge id="compass" bind="test.heading.heading" angle="true" unit="°" precision="0"/>
      <grid columns="3">
        <readout id="big" bind="test.motion.depth" unit="m" precision="3"/>
        <readout id="speed" bind="test.motion.speed" unit="m/s" precision="2"/>
        <readout id="heading" bind="test.heading.heading" unit="°" precision="0" angle="true"/>
      </grid>
      <history id="commands" lines="20"/>
    </column>
    <column>
      <plot label="Depth" window="60s">
        <series bind="test.motion.depth" label="Depth" unit="m"/>
        <series bind="nowhere.depth.depth" label="Ghost" unit="m"/>
      </plot>
      <health id="health" bind="test.health"/>
      <text command="note.text" label="Note"/>
    </column>
  </row>
</layout>
"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn narrow_widgets_read_true_and_fit() {
    let dir = tempfile::tempdir().expect("dir");
    let layout = dir.path().join("narrow.xml");
    std::fs::write(&layout, NARROW).expect("layout");
    let feed = r#"
  <bridge name="feed" media="net bus">
    <route from="net" to="bus" topics="test.**"/>
  </bridge>"#;
    let sys = start_with(feed, &[layout]);
    let net = common::schemes()
        .open("net", &sys.net, &seabus_medium::Node::new("feeder"))
        .expect("the network opens");
    let port = net.attach("feeder");
    let driver = chromedriver();
    let c = browser_sized(&driver, 1280, 800).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    open(&c, &sys.url, "narrow", "").await;
    let mut components = DataMap::new();
    components.push("frontseat".to_string(), Value::label("HEALTHY"));
    components.push("gps".to_string(), Value::label("OFFLINE"));
    let mut reasons = DataMap::new();
    reasons.push(
        "gps".to_string(),
        Value::from("no update for 12.0 s on the sensors line"),
    );
    let health = DataMap::new()
        .and("severity", Value::label("WARN"))
        .and("components", Value::Map(components))
        .and("reasons", Value::Map(reasons))
        .and("unknown", Value::Int(3));
    // values until the page has them all (bounded: 10 s)
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    let shown = "const v = (id) => document.querySelector(`[data-widget-id=\"${id}\"] [data-testid=value]`).textContent;
        return [v('compass'), v('big'), v('heading')];";
    loop {
        for (topic, fields) in [
            ("test.heading", DataMap::new().with("heading", 359.9)),
            (
                "test.motion",
                DataMap::new().with("depth", -12345.678).with("speed", 1.25),
            ),
            ("test.health", health.clone()),
        ] {
            port.send(topic, fields).await.expect("published");
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
        if js(&c, shown).await == json!(["0", "-12345.678", "0"])
            || std::time::Instant::now() > deadline
        {
            break;
        }
    }
    // 359.9° is 0, in the compass and the readout, and the needle points (nearly) north
    assert_eq!(js(&c, shown).await, json!(["0", "-12345.678", "0"]));
    let needle = js(
        &c,
        "return document.querySelector('[data-widget-id=compass] [data-testid=needle]').parentNode.getAttribute('transform');",
    )
    .await;
    assert_eq!(needle, json!("rotate(359.90 100 88)"));
    // the series nothing produces says so in the plot's legend; the other shows its value
    let legend = until_text(
        &c,
        Duration::from_secs(5),
        "the plot's legend",
        "const l = document.querySelector('[data-kind=plot] .plot-legend');
         return l && /no producer/.test(l.textContent) && l.textContent;",
    )
    .await;
    assert_eq!(legend, "Depth-12345.7Ghostno producer");
    // the health table: its components, and the updates it does not judge, in words
    let unknown = until_text(
        &c,
        Duration::from_secs(5),
        "the health table",
        "const u = document.querySelector('[data-widget-id=health] [data-testid=health-unknown]'); return u && u.textContent;",
    )
    .await;
    assert_eq!(
        unknown,
        "3 updates from components the health rules do not name (not judged)"
    );
    let health_text = js(&c, &widget_text("health")).await;
    assert!(
        !health_text
            .as_str()
            .unwrap_or_default()
            .contains("unknown:"),
        "{health_text}"
    );
    // a command with a long text, refused by nobody and answered by nobody: its row in the
    // narrow history keeps its state in sight
    let note = c
        .find(Locator::Css("[data-kind=text] input"))
        .await
        .expect("the note box");
    note.send_keys(&format!("{}\u{E007}", "a long note for the log ".repeat(4)))
        .await
        .expect("typed");
    until(
        &c,
        Duration::from_secs(10),
        "the note in the history",
        "return document.querySelector('[data-widget-id=commands] tr[data-state]');",
    )
    .await;
    let problems = misfits(&c, "narrow 1280x800").await;
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    c.close().await.expect("closed");
}
