//! The console in a real browser: headless Chromium driven over WebDriver (Debian's chromium and
//! chromedriver, which scripts/test installs) against `seabus run` of a system with the simulated
//! Iver2 frontseat, its driver and the shipped pilot and scientist layouts; users made with
//! `seabus user add`. What reaches the bus is watched with `seabus spy` on a loopback group.
//! Screenshots go to `target/console-screenshots/`.

#[path = "../common/mod.rs"]
mod common;
mod fit;
mod harness;
mod history;
mod safety;

use common::{
    Running, add_user, assert_logs_in, group, one_time_password, seabus, spy_json, wait_for_line,
};
use fantoccini::{Client, Locator};
use harness::*;
use serde_json::{Value as Json, json};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pilot_sees_the_vehicle_live_and_a_slider_command_is_acknowledged() {
    let sys = start(&[repo("configs/console/pilot.xml")]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    // the layout renders, and values arrive
    until(
        &c,
        Duration::from_secs(15),
        "the pilot layout",
        "return document.querySelector('[data-kind=track]') && document.querySelector('[data-widget-id=heading]');",
    )
    .await;
    let depth_id = js(
        &c,
        "return document.querySelectorAll('[data-kind=readout]')[1].dataset.widgetId;",
    )
    .await;
    let depth_id = depth_id.as_str().expect("a readout id").to_string();
    until(
        &c,
        Duration::from_secs(15),
        "a live heading",
        "const r = document.querySelectorAll('[data-kind=readout]')[0]; return r && /[0-9]/.test(r.innerText) && !/no data/.test(r.innerText) && r.innerText;",
    )
    .await;
    assert!(js(&c, &widget_text(&depth_id)).await.is_string());
    // values keep changing (the simulated vehicle moves)
    let readouts = "return [...document.querySelectorAll('[data-kind=readout]')].map(r => r.innerText).join(' | ');";
    let first = js(&c, readouts).await;
    let mut changed = false;
    for _ in 0..50 {
        tokio::time::sleep(Duration::from_millis(200)).await;
        let now = js(&c, readouts).await;
        if now != first {
            changed = true;
            break;
        }
    }
    assert!(changed, "the readouts never changed: {first}");

    take_control(&c, "pilot").await;
    // the driver sends commands once the frontseat takes them (it refuses them while offline)
    until(
        &c,
        Duration::from_secs(20),
        "a frontseat that takes commands",
        "const l = document.querySelector('[data-kind=log]'); return l && /control=(accepting|in-control)/.test(l.innerText);",
    )
    .await;
    slide(&c, "heading", 123.0).await;
    // the command reaches the vehicle through the driver …
    let mut seen = Vec::new();
    let course = wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(10),
        "cmd.course",
        |v| v["topic"] == "cmd.course",
    );
    assert_eq!(
        course["payload"]["heading"].as_f64(),
        Some(123.0),
        "{course}"
    );
    // … and its acknowledgement from the simulated frontseat shows in the history
    let history = until_text(
        &c,
        Duration::from_secs(20),
        "a settled command in the history",
        "const h = document.querySelector('[data-kind=history]'); return h && /acknowledged|refused|timed-out/.test(h.innerText) && h.innerText;",
    )
    .await;
    assert!(history.contains("acknowledged"), "{history}");
    screenshot(&c, "pilot.png").await;
    assert_eq!(
        js(&c, "return window.seabusConsole.policyViolations();").await,
        json!([]),
        "the content policy blocked part of the page"
    );
    let log = std::fs::read_to_string(sys.dir.join("commands.csv")).expect("the command log");
    assert!(
        log.lines()
            .any(|l| l.contains(",pilot,course,") && l.contains("acknowledged")),
        "{log}"
    );
    c.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn escape_stops_the_mission_at_once_without_a_dialog() {
    let sys = start(&[repo("configs/console/pilot.xml")]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    take_control(&c, "pilot").await;
    until(
        &c,
        Duration::from_secs(20),
        "a frontseat that takes commands",
        "const l = document.querySelector('[data-kind=log]'); return l && /control=(accepting|in-control)/.test(l.innerText);",
    )
    .await;
    while sys.spy.try_recv().is_ok() {}
    let pressed = Instant::now();
    c.find(Locator::Css("body"))
        .await
        .expect("the page")
        .send_keys("\u{E00C}")
        .await
        .expect("Escape pressed");
    let mut seen = Vec::new();
    let stop = wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(5),
        "cmd.mission",
        |v| v["topic"] == "cmd.mission",
    );
    let took = pressed.elapsed();
    assert_eq!(stop["payload"]["action"], "stop", "{stop}");
    assert!(took < Duration::from_millis(500), "stop took {took:?}");
    assert_eq!(
        js(
            &c,
            "return document.querySelector('dialog[open]') === null;"
        )
        .await,
        json!(true),
        "no dialog was asked"
    );
    // the simulated frontseat takes it: the driver acknowledges the stop
    let ack = wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(10),
        "the stop's acknowledgement",
        |v| {
            v["topic"] == "cmd.status"
                && v["payload"]["request_seq"] == stop["seq"]
                && v["payload"]["state"] != "pending"
        },
    );
    assert_eq!(ack["payload"]["state"], "acknowledged", "{ack}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_observer_is_offered_no_commands_and_a_forged_one_is_refused() {
    let sys = start(&[
        repo("configs/console/pilot.xml"),
        repo("configs/console/scientist.xml"),
    ]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "ivo", "observer-password").await;
    until(
        &c,
        Duration::from_secs(15),
        "the scientist layout",
        "return document.querySelector('[data-kind=health]') && document.querySelector('[data-kind=plot]');",
    )
    .await;
    let controls = js(
        &c,
        "return document.querySelectorAll('[data-kind=slider],[data-kind=button],[data-kind=number],[data-kind=toggle],[data-kind=text]').length
              + document.querySelectorAll('[data-testid=take-control]:not([hidden])').length;",
    )
    .await;
    assert_eq!(controls, json!(0), "an observer sees no command controls");
    // everything is drawn under the page's content policy: nothing blocked, and the plot's
    // legend keeps its colours (set through the style object, not a style attribute)
    until(
        &c,
        Duration::from_secs(10),
        "a plot legend",
        "return document.querySelector('[data-kind=plot] .sw');",
    )
    .await;
    assert_eq!(
        js(&c, "return window.seabusConsole.policyViolations();").await,
        json!([]),
        "the content policy blocked part of the page"
    );
    let swatch = js(
        &c,
        "return getComputedStyle(document.querySelector('[data-kind=plot] .sw')).backgroundColor;",
    )
    .await;
    assert_ne!(
        swatch,
        json!("rgba(0, 0, 0, 0)"),
        "the legend lost its colour"
    );
    // the health table: each component and the vehicle's severity, live. Both lines are up once
    // the serial media have opened their pseudo-terminals (until then the frontseat may show
    // OFFLINE): then both components are HEALTHY and the severity is NONE.
    until_eq(
        &c,
        Duration::from_secs(20),
        "the health table with both lines up",
        "const h = document.querySelector('[data-kind=health]');
         if (!h) return null;
         const sev = h.querySelector('[data-testid=severity]');
         const state = (n) => { const r = h.querySelector(`tr[data-component=\"${n}\"]`); return r ? [r.children[4].textContent, r.children[5].textContent] : null; };
         return {severity: sev && sev.textContent, Frontseat: state('Frontseat'), Sensors: state('Sensors'), Navigation: state('Navigation'), VehicleState: state('VehicleState')};",
        json!({"severity": "severity NONE", "Frontseat": ["HEALTHY", ""], "Sensors": ["HEALTHY", ""], "Navigation": ["HEALTHY", ""], "VehicleState": ["HEALTHY", ""]}),
    )
    .await;
    screenshot(&c, "observer.png").await;
    // the media that lost anything, as the health monitor lists them, under the components
    let media = js(
        &c,
        "const now = Date.now() / 1000;
         window.seabusConsole.receive({type: 'data', now, topics: {'vehicle.health': {stamp: now,
           fields: {severity: 'NONE', components: {Sensors: 'HEALTHY'}, reasons: {},
             media: {sensors: {received: 24450, rejected: {garbage: 2}, dropped_bytes: 57,
                               overruns: 0, queue_dropped: {gps: 412}}}}}}});
         const t = document.querySelector('[data-kind=health] [data-testid=health-media]');
         const r = t && t.querySelector('tr[data-medium=sensors]');
         return {shown: !!t && !t.hidden, row: r && [...r.children].map((td) => td.textContent)};",
    )
    .await;
    assert_eq!(
        media,
        json!({"shown": true, "row": ["sensors", "412 (gps 412)", "2 (garbage 2)", "57", "0"]})
    );
    // a forged command over the page's own session: refused by the server
    js(
        &c,
        "window.forged = [];
         const ws = new WebSocket(`ws://${location.host}/ws`);
         ws.onmessage = (e) => window.forged.push(JSON.parse(e.data));
         ws.onopen = () => {
           ws.send(JSON.stringify({type: 'open', layout: 'pilot'}));
           ws.send(JSON.stringify({type: 'lease', action: 'take'}));
           ws.send(JSON.stringify({type: 'send', layout: 'pilot', command: 'course', fields: {speed: 2.5}}));
           ws.send(JSON.stringify({type: 'drive', layout: 'scientist', command: 'course', fields: {speed: 2.5}}));
         };
         return true;",
    )
    .await;
    let errors = until(
        &c,
        Duration::from_secs(10),
        "the refusals",
        "const e = (window.forged || []).filter(m => m.type === 'error'); return e.length >= 4 && e.map(m => m.message);",
    )
    .await;
    let text = errors.to_string();
    assert!(
        text.contains("no layout") && text.contains("role pilot"),
        "{text}"
    );
    assert!(
        commands_on(&sys.spy, "cmd.course", Duration::from_secs(2)).is_empty(),
        "nothing reached the bus"
    );
    c.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_pilot_cannot_command_until_the_first_releases_control() {
    let sys = start(&[repo("configs/console/pilot.xml")]);
    let driver = chromedriver();
    let a = browser(&driver).await;
    let b = browser(&driver).await;
    log_in(&a, &sys.url, "pilot", "pilot-password").await;
    log_in(&b, &sys.url, "copilot", "copilot-password").await;
    take_control(&a, "pilot").await;
    // everyone sees who has control; the second pilot's controls say why they are off
    until(
        &b,
        Duration::from_secs(5),
        "the holder shown",
        "return /pilot/.test(document.querySelector('[data-testid=lease-holder]').innerText);",
    )
    .await;
    // a pilot may take control, so the button is shown, but disabled while someone holds it
    let blocked = js(
        &b,
        "const b = document.querySelector('[data-testid=take-control]');
         const r = document.querySelector('[data-widget-id=heading] input[type=range]');
         return {hidden: b.hidden, disabled: b.disabled, why: b.title, slider: r.disabled};",
    )
    .await;
    assert_eq!(
        blocked,
        json!({"hidden": false, "disabled": true, "why": "pilot holds control", "slider": true})
    );
    // even sent anyway (as a modified page would), the server refuses
    js(
        &b,
        "const ws = new WebSocket(`ws://${location.host}/ws`);
         window.forged = [];
         ws.onmessage = (e) => window.forged.push(JSON.parse(e.data));
         ws.onopen = () => {
           ws.send(JSON.stringify({type: 'open', layout: 'pilot'}));
           ws.send(JSON.stringify({type: 'send', layout: 'pilot', command: 'course', fields: {heading: 10}}));
         };
         return true;",
    )
    .await;
    let refused = until(
        &b,
        Duration::from_secs(5),
        "the refusal",
        "const e = (window.forged || []).find(m => m.type === 'error'); return e && e.message;",
    )
    .await;
    assert!(
        refused.as_str().unwrap_or("").contains("pilot has it"),
        "{refused}"
    );
    assert!(commands_on(&sys.spy, "cmd.course", Duration::from_secs(1)).is_empty());
    // released: the second pilot takes control and commands
    a.find(Locator::Css("[data-testid=release-control]"))
        .await
        .expect("release button")
        .click()
        .await
        .expect("clicked");
    take_control(&b, "copilot").await;
    slide(&b, "depth", 4.5).await;
    // the course, then the console keeping it (once a second) with the same values
    let got = commands_on(&sys.spy, "cmd.course", Duration::from_secs(3));
    assert!((2..=5).contains(&got.len()), "{got:?}");
    assert!(
        got.iter().all(|c| c["payload"] == got[0]["payload"]),
        "{got:?}"
    );
    assert_eq!(got[0]["payload"]["depth"].as_f64(), Some(4.5));
    a.close().await.expect("closed");
    b.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gamepad_that_freezes_mid_command_sends_neutral_once_then_nothing() {
    let sys = start(&[repo("configs/console/pilot.xml")]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    take_control(&c, "pilot").await;
    // a gamepad: centred first, then the speed stick (axis 1) pushed forward, its readings
    // changing as a live pad's do
    js(
        &c,
        "window.pad = {id: 'test pad', index: 0, connected: true, mapping: 'standard',
                       timestamp: 1, axes: [0, 0, 0, 0], buttons: []};
         window.padLive = true;
         navigator.getGamepads = () => [window.pad];
         window.dispatchEvent(Object.assign(new Event('gamepadconnected'), {gamepad: window.pad}));
         setTimeout(() => {
           window.padTimer = setInterval(() => {
             if (!window.padLive) return;
             window.pad = Object.assign({}, window.pad, {timestamp: window.pad.timestamp + 16,
               axes: [0, -0.8 - Math.random() * 0.01, 0, 0]});
           }, 16);
         }, 300);
         return true;",
    )
    .await;
    until(
        &c,
        Duration::from_secs(10),
        "drive messages",
        "return window.seabusConsole.state().drives >= 5;",
    )
    .await;
    // the pad freezes: same timestamp, same readings, stick still deflected
    js(&c, "window.padLive = false; return true;").await;
    let released = until(
        &c,
        Duration::from_secs(5),
        "the release",
        "const s = window.seabusConsole.state(); return s.releases >= 1 && s;",
    )
    .await;
    assert_eq!(released["releases"], json!(1), "{released}");
    // on the bus: drives at speed > 0, then one neutral (speed 0), then nothing
    let mut seen = Vec::new();
    wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(5),
        "the neutral command",
        |v| v["topic"] == "cmd.course" && v["payload"]["speed"].as_f64() == Some(0.0),
    );
    let driven: Vec<f64> = seen
        .iter()
        .filter(|v| v["topic"] == "cmd.course")
        .filter_map(|v| v["payload"]["speed"].as_f64())
        .collect();
    // the stick at 0.80–0.81 through deadband 0.1, expo 0.5 and gain −2.5: 1.56–1.60 m/s
    assert!(
        driven.len() >= 3
            && driven[..driven.len() - 1]
                .iter()
                .all(|s| (1.54..=1.62).contains(s)),
        "{driven:?}"
    );
    let after = commands_on(&sys.spy, "cmd.course", Duration::from_secs(2));
    assert!(
        after.is_empty(),
        "commands after the neutral one: {after:?}"
    );
    let state = js(&c, STATE).await;
    assert_eq!(state["releases"], json!(1), "{state}");
    c.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_layout_shows_its_line_and_column_and_log_ins_are_limited() {
    let bad_dir = tempfile::tempdir().expect("dir");
    let bad = bad_dir.path().join("bad.xml");
    let bad_text = "<layout name=\"bad\" roles=\"pilot\">\n  <column>\n    <readout bind=\"nav.depth.depth\" precision=\"two\"/>\n  </column>\n</layout>\n";
    std::fs::write(&bad, bad_text).expect("written");
    // the check command names the place …
    let out = seabus()
        .args(["layout", "check"])
        .arg(&bad)
        .arg(repo("configs/demo.xml"))
        .output()
        .expect("seabus layout check runs");
    let err =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{err}");
    // FILE:3:COLUMN: MESSAGE
    let (col, message) = err
        .lines()
        .find_map(|l| l.strip_prefix(&format!("{}:3:", bad.display())))
        .and_then(|rest| rest.split_once(": "))
        .unwrap_or_else(|| panic!("an error at line 3 of {}: {err}", bad.display()));
    let (col, message) = (col.to_string(), message.to_string());
    // … and so does the page, for a layout that breaks while the console runs (`seabus run`
    // refuses to start with it broken)
    std::fs::write(&bad, bad_text.replace("\"two\"", "\"2\"")).expect("written");
    let sys = start(std::slice::from_ref(&bad));
    std::fs::write(&bad, bad_text).expect("written");
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    let shown = until(
        &c,
        Duration::from_secs(15),
        "the layout error",
        "const e = document.querySelector('[data-testid=layout-error]');
         const text = (id) => { const x = e.querySelector(`[data-testid=${id}]`); return x && x.textContent; };
         return e && !e.hidden && {where: text('error-where'), message: text('error-message'), line: e.lastElementChild.textContent};",
    )
    .await;
    // the same place and words as the check command
    assert_eq!(
        shown,
        json!({
            "where": format!("{}:3:{col}", bad.display()),
            "message": message,
            "line": format!("line 3, column {col}"),
        })
    );
    screenshot(&c, "layout-error.png").await;
    // wrong passwords: after five, even the right one is refused for a while
    c.goto(&format!("{}/logout", sys.url))
        .await
        .expect("log out");
    for _ in 0..5 {
        log_in(&c, &sys.url, "copilot", "wrong-password").await;
        until(
            &c,
            Duration::from_secs(5),
            "the refusal",
            "const e = document.querySelector('[data-testid=login-error]'); return e && !e.hidden && e.innerText;",
        )
        .await;
    }
    log_in(&c, &sys.url, "copilot", "copilot-password").await;
    let limited = until(
        &c,
        Duration::from_secs(5),
        "the limit",
        "const e = document.querySelector('[data-testid=login-error]'); return e && !e.hidden && e.innerText;",
    )
    .await;
    assert!(
        limited.as_str().unwrap_or("").contains("Too many"),
        "{limited}"
    );
    c.close().await.expect("closed");
}

#[test]
fn only_a_loopback_console_makes_passwords_of_its_own_and_it_prints_them() {
    // a console beyond this machine without a users file does not start
    let dir = tempfile::tempdir().expect("dir");
    let path = dir.path().join("s.xml");
    std::fs::write(
        &path,
        r#"<seabus node="n"><medium name="bus" url="inproc://"/>
  <console medium="bus" listen="0.0.0.0:0" layouts="x.xml"/></seabus>"#,
    )
    .expect("written");
    let out = seabus()
        .args(["run"])
        .arg(&path)
        .args(["--for", "5"])
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("needs `users`"), "{err}");
    // the demo prints its users and passwords, and they log in
    let mut demo = Running(
        seabus()
            .args(["demo", "--for", "30"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the demo starts"),
    );
    let (password, url) = one_time_password(&mut demo, "observer");
    assert_logs_in(&url, "observer", &password);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_designer_adds_a_bound_widget_and_saves_the_layout_as_xml() {
    let copy_dir = tempfile::tempdir().expect("dir");
    let layout = copy_dir.path().join("pilot.xml");
    // (a layout for one vehicle: what it says of its vehicle is saved with it)
    let text = std::fs::read_to_string(repo("configs/console/pilot.xml")).expect("the layout");
    let one = r#"roles="pilot">"#;
    assert!(text.contains(one));
    std::fs::write(
        &layout,
        text.replacen(one, r#"roles="pilot" vehicle="${vehicle}">"#, 1),
    )
    .expect("copied");
    let sys = start(std::slice::from_ref(&layout));
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    until(
        &c,
        Duration::from_secs(15),
        "the layout",
        "return document.querySelector('[data-kind=track]');",
    )
    .await;
    let click = |sel: &'static str| {
        let c = c.clone();
        async move {
            c.find(Locator::Css(sel))
                .await
                .unwrap_or_else(|_| panic!("{sel}"))
                .click()
                .await
                .unwrap_or_else(|_| panic!("click {sel}"));
        }
    };
    click("[data-testid=edit-toggle]").await;
    click("[data-testid=add-readout]").await;
    // the new readout is selected: bind it and label it in the side panel
    js(
        &c,
        "const set = (k, v) => { const i = document.querySelector(`[data-testid=attributes] [data-attr=${k}]`);
                                 i.value = v; i.dispatchEvent(new Event('change', {bubbles: true})); };
         set('bind', 'nav.altitude.altitude'); set('label', 'Clearance'); set('unit', 'm');
         return true;",
    )
    .await;
    click("[data-testid=save-layout]").await;
    let deadline = Instant::now() + Duration::from_secs(10);
    let text = loop {
        let text = std::fs::read_to_string(&layout).expect("the layout file");
        if text.contains("Clearance") {
            break text;
        }
        assert!(
            Instant::now() < deadline,
            "the layout was not saved:\n{text}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert!(text.contains("nav.altitude.altitude"), "{text}");
    assert!(text.contains("roles=\"pilot\""), "roles kept: {text}");
    assert!(
        text.contains("vehicle=\"iver\""),
        "the vehicle kept: {text}"
    );
    assert!(copy_dir.path().join("pilot.xml.bak").exists());
    // what was saved reads, and checks against the system
    let out = seabus()
        .args(["layout", "check"])
        .arg(&layout)
        .arg(repo("configs/demo.xml"))
        .output()
        .expect("layout check runs");
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // and the page shows the new widget, reloaded from the server
    until(
        &c,
        Duration::from_secs(10),
        "the new readout",
        "return [...document.querySelectorAll('[data-kind=readout]')].some(r => /Clearance/i.test(r.innerText));",
    )
    .await;
    c.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_layout_loads_before_data_and_shows_missing_producers_and_stale_values() {
    let dir = tempfile::tempdir().expect("dir");
    let layout = dir.path().join("fresh.xml");
    std::fs::write(
        &layout,
        r#"<layout name="fresh" roles="observer">
  <column>
    <readout id="counter" bind="test.counter.counter" fresh="1500ms"/>
    <readout id="ghost" bind="nowhere.value"/>
    <readout id="quiet" bind="test.quiet.counter"/>
  </column>
</layout>
"#,
    )
    .expect("layout");
    // three values two seconds apart, then silence; and a producer that has sent nothing yet
    let sys = start_with(
        r#"<module name="gen" type="generator" medium="bus" tick="0.5Hz" count="3"/>
  <module name="quiet" type="generator" medium="bus" topic="test.quiet" count="0"/>"#,
        &[layout],
    );
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "ivo", "observer-password").await;
    let status = |id: &str| {
        format!(
            "const w = document.querySelector('[data-widget-id=\"{id}\"]'); return w ? w.innerText : '';"
        )
    };
    // rendered before any value: waiting for data, and a binding nothing produces
    let before = until_text(&c, Duration::from_secs(10), "the layout", &status("quiet")).await;
    assert!(before.contains("no data"), "{before}");
    let ghost = until_text(&c, Duration::from_secs(5), "the ghost", &status("ghost")).await;
    assert!(ghost.contains("no producer"), "{ghost}");
    // values, fresh
    let fresh = until_text(
        &c,
        Duration::from_secs(10),
        "a value",
        "const w = document.querySelector('[data-widget-id=counter]'); return w && /[0-9]/.test(w.innerText) && !/no data|stale/.test(w.innerText) && w.innerText;",
    )
    .await;
    assert!(!fresh.contains("stale"), "{fresh}");
    // the generator stops: the last value turns stale
    let stale = until_text(
        &c,
        Duration::from_secs(15),
        "a stale value",
        "const w = document.querySelector('[data-widget-id=counter]'); return w && /stale/.test(w.innerText) && w.innerText;",
    )
    .await;
    assert!(
        stale.chars().any(|c| c.is_ascii_digit()),
        "the last value stays shown: {stale}"
    );
    c.close().await.expect("closed");
}

// ------------------------------------------------------------------ plots and readouts
//
// Values the test publishes on the system's network (`test.**`, bridged onto the console's bus),
// read back from what each plot drew (`window.seabusConsole.plot(LABEL)`: lines in canvas
// pixels, axes) and from the readouts' text.

/// Modules that bring `test.**` from the network onto the console's bus.
const FEED: &str = r#"
  <bridge name="feed" media="net bus">
    <route from="net" to="bus" topics="test.**"/>
  </bridge>
"#;

/// A layout of plots, readouts and a track over `test.**`, for the observer.
const LINES: &str = r#"<layout name="lines" roles="observer">
  <row>
    <column>
      <plot label="Heading" window="60s">
        <series bind="test.heading.heading" label="Heading" unit="°" angle="true"/>
      </plot>
      <plot label="Depth and speed" window="60s">
        <series bind="test.motion.depth" label="Depth" unit="m"/>
        <series bind="test.motion.speed" label="Speed" unit="m/s"/>
      </plot>
      <grid columns="2">
        <readout id="heading" bind="test.heading.heading" unit="°" precision="0" angle="true"/>
        <readout id="armed" bind="test.state.armed" label="Thrusters" true="armed" false="safe"/>
      </grid>
    </column>
    <track position="test.position" trail="600"/>
  </row>
</layout>
"#;

/// The system with [`LINES`], an observer's page on it, and a port that publishes on its network.
async fn lines_page() -> (
    System,
    Driver,
    Client,
    seabus_medium::Interface,
    tempfile::TempDir,
) {
    let dir = tempfile::tempdir().expect("dir");
    let layout = dir.path().join("lines.xml");
    std::fs::write(&layout, LINES).expect("layout");
    let sys = start_with(FEED, &[layout]);
    let net = common::schemes()
        .open("net", &sys.net, &seabus_medium::Node::new("feeder"))
        .expect("the network opens");
    let port = net.attach("feeder");
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "ivo", "observer-password").await;
    until(
        &c,
        Duration::from_secs(15),
        "the layout",
        "return document.querySelectorAll('[data-kind=plot]').length === 2
                && window.seabusConsole.plot('Heading');",
    )
    .await;
    (sys, driver, c, port, dir)
}

/// Publishes `fields` on `topic` of the network.
async fn publish(port: &seabus_medium::Interface, topic: &str, fields: seabus_medium::DataMap) {
    port.send(topic, fields).await.expect("published");
}

/// What the plot labelled `label` drew.
async fn drawn(c: &Client, label: &str) -> Json {
    js(c, &format!("return window.seabusConsole.plot('{label}');")).await
}

/// The points of each line of a plot's drawing (`[[x, y], …]` each).
fn lines_of(plot: &Json, series: &str) -> Vec<Vec<(f64, f64)>> {
    plot["lines"]
        .as_array()
        .expect("lines")
        .iter()
        .filter(|l| l["series"] == series)
        .map(|l| {
            l["points"]
                .as_array()
                .expect("points")
                .iter()
                .map(|p| (p[0].as_f64().expect("x"), p[1].as_f64().expect("y")))
                .collect()
        })
        .collect()
}

/// Waits (at most 10 s) until the readout `id` shows `text`; fails with what it shows.
async fn readout_shows(c: &Client, id: &str, text: &str) {
    until_eq(
        c,
        Duration::from_secs(10),
        &format!("readout {id}"),
        &format!(
            "const v = document.querySelector('[data-widget-id=\"{id}\"] [data-testid=value]');
             return v && v.textContent;"
        ),
        json!(text),
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_heading_crossing_north_draws_no_wall_and_readouts_read_true() {
    let (_sys, _driver, c, port, _dir) = lines_page().await;
    // a heading turning steadily from 350° through north to 10°, as a compass reports it
    for i in 0..=20 {
        let heading = (350.0 + f64::from(i)) % 360.0;
        publish(
            &port,
            "test.heading",
            seabus_medium::DataMap::new().with("heading", heading),
        )
        .await;
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
    let plot = until(
        &c,
        Duration::from_secs(10),
        "all 21 headings drawn",
        "const p = window.seabusConsole.plot('Heading');
         return p && p.lines.reduce((n, l) => n + l.points.length, 0) >= 21 && p;",
    )
    .await;
    let lines = lines_of(&plot, "Heading");
    assert_eq!(lines.len(), 1, "one line, no gap: {plot}");
    let points = &lines[0];
    assert_eq!(points.len(), 21, "{plot}");
    // the heading only rises, so the line only climbs, by about a twentieth of the axis each
    // step: no segment drops across the plot at north
    let height = plot["area"]["height"].as_f64().expect("height");
    for w in points.windows(2) {
        let dy = w[1].1 - w[0].1;
        assert!(
            dy < 0.0 && -dy < 0.15 * height,
            "a step of {dy} px on a plot {height} px high: {points:?}"
        );
    }
    // one axis, in degrees, numbered within [0, 360) on both sides of north
    let axes = plot["axes"].as_array().expect("axes");
    assert_eq!(axes.len(), 1, "{plot}");
    assert_eq!(axes[0]["unit"], "°");
    let ticks: Vec<f64> = axes[0]["ticks"]
        .as_array()
        .expect("ticks")
        .iter()
        .map(|t| t.as_str().and_then(|t| t.parse().ok()).expect("a number"))
        .collect();
    assert!(
        ticks.iter().all(|t| (0.0..360.0).contains(t))
            && ticks.iter().any(|t| *t >= 340.0)
            && ticks.iter().any(|t| *t < 20.0),
        "{ticks:?}"
    );
    // the readout of the same heading, at precision 0: within 0–359, never 360
    readout_shows(&c, "heading", "10").await;
    for (heading, shown) in [(359.96, "0"), (359.4, "359"), (-0.3, "0"), (725.0, "5")] {
        publish(
            &port,
            "test.heading",
            seabus_medium::DataMap::new().with("heading", heading),
        )
        .await;
        readout_shows(&c, "heading", shown).await;
    }
    // a true/false value shows the readout's words
    for (armed, shown) in [(false, "safe"), (true, "armed"), (false, "safe")] {
        publish(
            &port,
            "test.state",
            seabus_medium::DataMap::new().with("armed", armed),
        )
        .await;
        readout_shows(&c, "armed", shown).await;
    }
    screenshot(&c, "angles.png").await;
    no_policy_violations(&c).await;
    c.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gap_in_the_data_breaks_the_line_and_each_unit_gets_its_own_axis() {
    let (_sys, _driver, c, port, _dir) = lines_page().await;
    // depth (m) and speed (m/s) every 200 ms, then nothing for 3 s, then again
    for burst in 0..2 {
        if burst == 1 {
            tokio::time::sleep(Duration::from_secs(3)).await;
        }
        for i in 0..8 {
            let k = f64::from(burst * 8 + i);
            let fields = seabus_medium::DataMap::new()
                .with("depth", 10.0 + 0.1 * k)
                .with("speed", 1.2 - 0.01 * k);
            publish(&port, "test.motion", fields).await;
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
    let plot = until(
        &c,
        Duration::from_secs(10),
        "all 16 samples of each series drawn",
        "const p = window.seabusConsole.plot('Depth and speed');
         return p && p.lines.reduce((n, l) => n + l.points.length, 0) >= 32 && p;",
    )
    .await;
    for series in ["Depth", "Speed"] {
        let lines = lines_of(&plot, series);
        let sizes: Vec<usize> = lines.iter().map(Vec::len).collect();
        assert_eq!(
            sizes,
            [8, 8],
            "{series}: two lines of 8, split at the gap: {plot}"
        );
        // the second starts well right of where the first ends (3 s of a 60 s window)
        let width = plot["area"]["width"].as_f64().expect("width");
        let (end, start) = (lines[0][7].0, lines[1][0].0);
        assert!(start - end > 0.04 * width, "{series}: {end} → {start}");
    }
    // two axes: metres on the left, metres per second on the right, each fitting its series
    let axes: Vec<Json> = plot["axes"]
        .as_array()
        .expect("axes")
        .iter()
        .map(|a| json!([a["unit"], a["side"]]))
        .collect();
    assert_eq!(axes, [json!(["m", "left"]), json!(["m/s", "right"])]);
    let range = |k: usize| {
        let a = &plot["axes"][k];
        (
            a["min"].as_f64().expect("min"),
            a["max"].as_f64().expect("max"),
        )
    };
    let ((d0, d1), (s0, s1)) = (range(0), range(1));
    assert!(d0 > 9.0 && d1 < 12.0, "depth axis {d0}–{d1}");
    assert!(s0 > 0.9 && s1 < 1.3, "speed axis {s0}–{s1}");
    screenshot(&c, "gap-and-axes.png").await;
    no_policy_violations(&c).await;
    c.close().await.expect("closed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_backlog_fills_the_plot_and_the_track_at_once() {
    let (_sys, _driver, c, port, _dir) = lines_page().await;
    // the last 30 s of heading and position, one sample a second, as the server sends them when
    // a page opens its layout: handed to the page's own message handler
    let script = "const now = Date.now() / 1000;
         const heading = [], position = [];
         for (let i = 0; i < 30; i++) {
           const stamp = now - 29.5 + i;
           heading.push({stamp, fields: {heading: (345 + i) % 360}});
           position.push({stamp, fields: {lat: 43.5 + i * 1e-4, lon: 16.4}});
         }
         window.backlog = {type: 'backlog', topics: {'test.heading': heading, 'test.position': position}};
         window.seabusConsole.receive(window.backlog);
         return true;";
    js(&c, script).await;
    let trail = "const t = document.querySelector('[data-kind=track] [data-testid=trail]');
         return t ? t.getAttribute('points').trim().split(/\\s+/).length : 0;";
    let plot = drawn(&c, "Heading").await;
    let lines = lines_of(&plot, "Heading");
    assert_eq!(
        lines.iter().map(Vec::len).collect::<Vec<_>>(),
        [30],
        "{plot}"
    );
    // where their times are in the 60 s window: the oldest half way, the newest near now
    let (left, width) = (
        plot["area"]["left"].as_f64().expect("left"),
        plot["area"]["width"].as_f64().expect("width"),
    );
    let at = |ago: f64| left + width * (1.0 - ago / 60.0);
    let (first, last) = (lines[0][0].0, lines[0][29].0);
    assert!(
        (first - at(29.5)).abs() < 0.03 * width,
        "{first}, not {}",
        at(29.5)
    );
    assert!(
        (last - at(0.5)).abs() < 0.03 * width,
        "{last}, not {}",
        at(0.5)
    );
    assert_eq!(js(&c, trail).await, json!(30), "the track's trail");
    // the same again changes nothing: one sample per stamp
    js(
        &c,
        "window.seabusConsole.receive(window.backlog); return true;",
    )
    .await;
    let again = drawn(&c, "Heading").await;
    assert_eq!(lines_of(&again, "Heading")[0].len(), 30, "{again}");
    assert_eq!(js(&c, trail).await, json!(30));
    // live values go on after it
    for i in 0..3 {
        publish(
            &port,
            "test.heading",
            seabus_medium::DataMap::new().with("heading", 15.0 + f64::from(i)),
        )
        .await;
        publish(
            &port,
            "test.position",
            seabus_medium::DataMap::new()
                .with("lat", 43.504 + f64::from(i) * 1e-4)
                .with("lon", 16.4),
        )
        .await;
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    until(
        &c,
        Duration::from_secs(10),
        "the live samples after the backlog",
        "const p = window.seabusConsole.plot('Heading');
         return p && p.lines.length === 1 && p.lines[0].points.length === 33;",
    )
    .await;
    assert_eq!(js(&c, trail).await, json!(33));
    no_policy_violations(&c).await;
    c.close().await.expect("closed");
}

// ---------------------------------------------------------------- what the pilot commands

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_course_changed_in_one_field_keeps_the_others_and_is_held_until_control_is_released() {
    let sys = start(&[repo("configs/console/pilot.xml")]);
    let (_driver, c) = pilot_in_control(&sys).await;
    // depth, then speed: each goes with the other fields as they were
    slide(&c, "depth", 3.0).await;
    let (_, answer) = course_and_answer(&sys.spy, "a course at 3 m", |p| p["depth"] == 3.0);
    assert_eq!(answer["payload"]["state"], "acknowledged", "{answer}");
    slide(&c, "speed", 1.2).await;
    let (course, _) = course_and_answer(&sys.spy, "a course at 1.2 m/s", |p| p["speed"] == 1.2);
    assert_eq!(course["payload"]["depth"], 3.0, "{course}");
    // a new page starts from what the vehicle was commanded, not from the layout's zeros
    c.refresh().await.expect("reloaded");
    until_eq(
        &c,
        Duration::from_secs(15),
        "the depth slider at the commanded depth",
        "const w = document.querySelector('[data-widget-id=depth]'); return w && [w.dataset.source, w.querySelector('output').textContent];",
        json!(["commanded", "3"]),
    )
    .await;
    while sys.spy.try_recv().is_ok() {}
    slide(&c, "heading", 200.0).await;
    let (course, answer) =
        course_and_answer(&sys.spy, "a course to 200°", |p| p["heading"] == 200.0);
    assert_eq!(course["payload"]["depth"], 3.0, "{course}");
    assert_eq!(course["payload"]["speed"], 1.2, "{course}");
    assert_eq!(answer["payload"]["state"], "acknowledged", "{answer}");
    until(
        &c,
        Duration::from_secs(5),
        "holding course",
        "const k = document.querySelector('[data-testid=kept]'); return k && /holding course since \\d\\d:\\d\\d:\\d\\d/.test(k.innerText) && k.innerText;",
    )
    .await;
    // a minute later the console still keeps it: the frontseat never times out
    let mut resent = 0;
    let mut controls = Vec::new();
    let minute = Instant::now() + Duration::from_secs(60);
    while Instant::now() < minute {
        let courses = commands_on(&sys.spy, "cmd.course", Duration::from_secs(5));
        resent += courses
            .iter()
            .filter(|v| v["payload"]["heading"] == 200.0 && v["payload"]["speed"] == 1.2)
            .count();
        controls.push(js(&c, CONTROL).await);
    }
    let kept = js(
        &c,
        "const k = document.querySelector('[data-testid=kept-commands]'); return k && k.innerText;",
    )
    .await;
    assert!(
        resent >= 50,
        "{resent} courses in a minute; the page: {kept}"
    );
    assert!(
        controls.iter().all(|s| s == "in-control"),
        "the vehicle left backseat control: {controls:?}"
    );
    // releasing control is the safe action: speed 0 once, then nothing
    c.find(Locator::Css("[data-testid=release-control]"))
        .await
        .expect("release button")
        .click()
        .await
        .expect("released");
    let mut seen = Vec::new();
    let neutral = wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(2),
        "the course's neutral",
        |v| v["topic"] == "cmd.course" && v["payload"]["speed"] == 0.0,
    );
    assert_eq!(neutral["payload"]["heading"], 200.0, "{neutral}");
    let after = commands_on(&sys.spy, "cmd.course", Duration::from_secs(3));
    assert!(after.is_empty(), "courses after release: {after:?}");
    assert_eq!(
        js(&c, "return window.seabusConsole.policyViolations();").await,
        json!([])
    );
}

/// The Iver2 system, with a route for mission commands from its network (another operator).
fn iver_with_remote_missions() -> String {
    format!(
        r#"{IVER}
  <bridge name="remote" media="bus net">
    <route from="net" to="bus" topics="cmd.mission" kind="command"/>
  </bridge>"#
    )
}

/// The kept-command reason the page shows, once it shows one.
async fn kept_reason(c: &Client) -> String {
    until_text(
        c,
        Duration::from_secs(10),
        "why the course is no longer held",
        "const r = document.querySelector('[data-testid=kept-reason]'); return r && r.innerText;",
    )
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_course_the_stopped_vehicle_refuses_says_why_and_offers_start() {
    let sys = start_with(
        &iver_with_remote_missions(),
        &[repo("configs/console/pilot.xml")],
    );
    let (_driver, c) = pilot_in_control(&sys).await;
    slide(&c, "heading", 90.0).await;
    let (_, answer) = course_and_answer(&sys.spy, "a course to 90°", |p| p["heading"] == 90.0);
    assert_eq!(answer["payload"]["state"], "acknowledged", "{answer}");
    // someone else stops the mission: the next time the course goes, the vehicle refuses it
    let net = common::schemes()
        .open("net", &sys.net, &seabus_medium::Node::new("shore"))
        .expect("the network opens");
    let shore = net.attach("shore");
    shore
        .command(
            "cmd.mission",
            seabus_medium::DataMap::new().with("action", "stop"),
        )
        .await
        .expect("sent");
    assert_eq!(
        kept_reason(&c).await,
        "the vehicle refused it: the frontseat is stopped (mode S)"
    );
    // what was on its way before is passed over; after it, nothing
    tokio::time::sleep(Duration::from_millis(300)).await;
    while sys.spy.try_recv().is_ok() {}
    let stopped = commands_on(&sys.spy, "cmd.course", Duration::from_secs(3));
    assert!(stopped.is_empty(), "courses after the refusal: {stopped:?}");
    // the page offers the start, held as the layout asks
    js(
        &c,
        "const b = document.querySelector('[data-testid=kept-resume] button');
         b.dispatchEvent(new KeyboardEvent('keydown', {bubbles: true, key: ' '}));
         setTimeout(() => b.dispatchEvent(new KeyboardEvent('keyup', {bubbles: true, key: ' '})), 1600);
         return b.innerText;",
    )
    .await;
    let mut seen = Vec::new();
    let start = wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(5),
        "the mission's start",
        |v| v["topic"] == "cmd.mission" && v["payload"]["action"] == "start",
    );
    assert_eq!(start["payload"]["name"], "survey", "{start}");
    until_eq(
        &c,
        Duration::from_secs(10),
        "the vehicle taking commands again",
        CONTROL,
        json!("accepting"),
    )
    .await;
    // the pilot's own stop ends the kept course before it goes: no course follows it
    slide(&c, "heading", 120.0).await;
    course_and_answer(&sys.spy, "a course to 120°", |p| p["heading"] == 120.0);
    c.find(Locator::Css("body"))
        .await
        .expect("the page")
        .send_keys("\u{E00C}")
        .await
        .expect("Escape pressed");
    let mut seen = Vec::new();
    wait_for_line(
        &sys.spy,
        &mut seen,
        Duration::from_secs(5),
        "the stop",
        |v| v["topic"] == "cmd.mission" && v["payload"]["action"] == "stop",
    );
    let after = commands_on(&sys.spy, "cmd.course", Duration::from_secs(3));
    assert!(after.is_empty(), "courses after the stop: {after:?}");
    assert_eq!(kept_reason(&c).await, "stop sent instead");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_reloaded_after_half_a_minute_shows_the_last_half_minute_at_once() {
    let sys = start(&[
        repo("configs/console/pilot.xml"),
        repo("configs/console/scientist.xml"),
    ]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    let trail = "const t = document.querySelector('[data-kind=track] [data-testid=trail]');
         return t ? t.getAttribute('points').trim().split(/\\s+/).filter(Boolean).length : 0;";
    until(&c, Duration::from_secs(15), "the track", trail).await;
    tokio::time::sleep(Duration::from_secs(30)).await;
    c.refresh().await.expect("reloaded");
    // the track is full as soon as the layout is there (the vehicle reports 4 times a second)
    let loaded = Instant::now();
    until(
        &c,
        Duration::from_secs(15),
        "the reloaded track",
        "return !!document.querySelector('[data-kind=track] [data-testid=trail]');",
    )
    .await;
    let shown = until(
        &c,
        Duration::from_secs(3),
        "a full track",
        &format!("const n = (() => {{ {trail} }})(); return n >= 80 && n;"),
    )
    .await;
    assert!(
        loaded.elapsed() < Duration::from_secs(10),
        "{shown} points after {:?}",
        loaded.elapsed()
    );
    // a layout never opened before has the past too: the observer's heading plot spans the
    // half minute
    c.goto(&format!("{}/logout", sys.url))
        .await
        .expect("logged out");
    log_in(&c, &sys.url, "ivo", "observer-password").await;
    let span = until(
        &c,
        Duration::from_secs(5),
        "the heading plot spanning the last half minute",
        "const p = window.seabusConsole && window.seabusConsole.plot('Heading');
         if (!p || !p.lines.length) return false;
         const xs = p.lines.flatMap((l) => l.points.map((q) => q[0]));
         const span = (Math.max(...xs) - Math.min(...xs)) / p.area.width;
         return span > 0.45 && span;",
    )
    .await;
    assert!(span.as_f64().is_some_and(|s| s <= 1.0), "{span}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_frontseat_on_a_live_line_leaves_healthy_within_3_s_with_the_reason() {
    // the simulated frontseat falls silent for 5 s of every 9 while its serial line stays open
    let silent = IVER.replace(
        r#"noise="0.2"/>"#,
        r#"noise="0.2" silence_every="9s" silence_for="5s"/>"#,
    );
    assert_ne!(silent, IVER);
    let sys = start_with(&silent, &[repo("configs/console/scientist.xml")]);
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "ivo", "observer-password").await;
    until(
        &c,
        Duration::from_secs(15),
        "the health table",
        "return !!window.seabusConsole && !!document.querySelector('[data-kind=health]');",
    )
    .await;
    // the page notes when the navigation last moved and when the health row first left HEALTHY
    js(
        &c,
        "window.watch = {last: null, stamp: null, left: null, reason: null};
         setInterval(() => {
           const w = window.watch;
           if (!window.seabusConsole) return;
           const p = window.seabusConsole.topic('nav.attitude');
           if (p && p.stamp !== w.stamp) { w.stamp = p.stamp; w.last = performance.now(); w.left = null; }
           const r = document.querySelector('[data-kind=health] tr[data-component=Navigation]');
           if (!r || w.last === null || w.left !== null) return;
           if (r.children[4].textContent !== 'HEALTHY') {
             w.left = performance.now() - w.last;
             w.reason = r.children[5].textContent;
             w.state = r.children[4].textContent;
           }
         }, 50);
         return true;",
    )
    .await;
    let seen = until(
        &c,
        Duration::from_secs(25),
        "the navigation row leaving HEALTHY",
        "const w = window.watch; return !!w && w.left !== null && w;",
    )
    .await;
    let after = seen["left"].as_f64().expect("milliseconds");
    assert!(
        after < 3000.0,
        "left HEALTHY {after} ms after the last attitude"
    );
    let reason = seen["reason"].as_str().unwrap_or("");
    assert!(
        reason.starts_with("nav.position silent for ") && reason.ends_with(" s"),
        "{seen}"
    );
    assert_eq!(seen["state"], "UNAVAILABLE", "{seen}");
    // when the frontseat talks again, the row is HEALTHY with no reason
    until_eq(
        &c,
        Duration::from_secs(15),
        "the navigation row healthy again",
        "const r = document.querySelector('[data-kind=health] tr[data-component=Navigation]');
         return r && [r.children[4].textContent, r.children[5].textContent];",
        json!(["HEALTHY", ""]),
    )
    .await;
}

#[test]
fn the_demo_runs_twenty_seconds_without_a_warning() {
    // (with the console tests: one demo at a time, on its own fixed paths and groups)
    let out = seabus()
        .args(["demo", "--for", "20"])
        .stdout(Stdio::null())
        .output()
        .expect("the demo runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let loud: Vec<&str> = err
        .lines()
        .filter(|l| l.contains(" WARN ") || l.contains(" ERROR "))
        .collect();
    assert!(loud.is_empty(), "{}", loud.join("\n"));
    // the junk the simulated frontseat puts on its line is said once, at the start
    assert_eq!(
        err.matches("the simulated frontseat puts a line of junk before 1.0 % of its replies")
            .count(),
        1,
        "{err}"
    );
    // and the vehicle did run: the frontseat took the helm's commands
    assert!(err.contains("frontseat accepting -> in-control"), "{err}");
}

/// The vehicles of the fleet test, with where each simulated frontseat starts.
const FLEET: [(&str, f64, f64); 3] = [
    ("auv1", 43.5081, 16.4402),
    ("auv2", 43.5101, 16.4432),
    ("auv3", 43.5121, 16.4462),
];

/// A vehicle of the fleet: a simulated Iver2 frontseat and its driver, its bus reaching the shore's
/// Zenoh router at `port` under `fleet/NAME`.
fn fleet_vehicle(d: &Path, (name, lat, lon): (&str, f64, f64), port: u16) -> String {
    let line = d.join(format!("{name}-frontseat")).display().to_string();
    format!(
        r#"<seabus node="{name}">
  <medium name="bus" url="inproc://"/>
  <medium name="frontseat" url="pty://{line}?framing=lines"/>
  <medium name="serial" url="serial://{line}?baud=19200&amp;framing=nmea"/>
  <medium name="fleet" url="zenoh://?mode=client&amp;connect=tcp/127.0.0.1:{port}&amp;prefix=fleet/{name}&amp;scout=false"/>
  <module name="frontseat-sim" type="iver2-sim" media="frontseat" lat="{lat}" lon="{lon}" heading="0" autostart="true"/>
  <module name="iver" type="iver2" media="serial bus" version="5" request_every="250ms"/>
  <bridge name="shore" media="bus fleet" report="0">
    <route from="bus" to="fleet" topics="**"/>
    <route from="fleet" to="bus" topics="cmd.**" kind="command"/>
  </bridge>
</seabus>"#
    )
}

/// The shore station: a Zenoh router at `port`, the fleet bridged to its bus `bus` (a loopback
/// group the test watches) and the shipped fleet console on it.
fn fleet_shore(port: u16, bus: &str) -> String {
    let layouts = repo("configs/fleet/console").display().to_string();
    format!(
        r#"<seabus node="shore">
  <medium name="bus" url="{bus}"/>
  <medium name="fleet" url="zenoh://?mode=router&amp;listen=tcp/127.0.0.1:{port}&amp;prefix=fleet&amp;scout=false"/>
  <bridge name="fleet" media="fleet bus" report="0">
    <route from="fleet" to="bus" topics="*.nav.**"/>
    <route from="fleet" to="bus" topics="*.vehicle.state"/>
    <route from="fleet" to="bus" topics="*.power.battery"/>
    <route from="fleet" to="bus" topics="*.cmd.status"/>
    <route from="fleet" to="bus" topics="seabus.fleet"/>
    <route from="bus" to="fleet" topics="*.cmd.**" kind="command"/>
  </bridge>
  <console medium="bus" listen="127.0.0.1:0" users="users.xml" layouts="{layouts}"
           log="commands.csv"/>
</seabus>"#
    )
}

/// The rows of the fleet table: vehicle → its cells by column.
const FLEET_ROWS: &str =
    "return Object.fromEntries([...document.querySelectorAll('[data-testid=fleet-table] tbody tr')]
     .map(r => [r.dataset.vehicle, Object.fromEntries([...r.querySelectorAll('td[data-col]')]
       .map(td => [td.dataset.col, td.innerText]))]));";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fleet_console_shows_three_vehicles_and_a_pilot_commands_the_one_chosen() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let d = dir.path();
    add_user(&d.join("users.xml"), "pilot", "pilot", "pilot-password");
    // the shore's Zenoh router listens on TCP
    let port = common::free_tcp_port();
    let bus = format!("udp://{}:{}?ttl=0", group(), common::free_port());
    let shore_file = d.join("shore.xml");
    std::fs::write(&shore_file, fleet_shore(port, &bus)).expect("shore written");
    let (_spy_run, spy) = spy_json(&bus, 150);
    let (_shore, url) = run_console(&shore_file);
    let _vehicles: Vec<Running> = FLEET
        .iter()
        .map(|v| {
            let file = d.join(format!("{}.xml", v.0));
            std::fs::write(&file, fleet_vehicle(d, *v, port)).expect("vehicle written");
            Running(
                seabus()
                    .arg("run")
                    .arg(&file)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .expect("seabus run starts"),
            )
        })
        .collect();
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &url, "pilot", "pilot-password").await;

    // the fleet table: the three vehicles (not the shore itself), online, in their modes
    let rows = until(
        &c,
        Duration::from_secs(40),
        "three vehicles online in the fleet table",
        &format!(
            "const rows = (() => {{ {FLEET_ROWS} }})();
             const names = Object.keys(rows);
             return names.length === 3 && names.every(n => rows[n].online === 'online'
               && rows[n].mode !== '—' && rows[n].position !== '—') && rows;"
        ),
    )
    .await;
    let names: Vec<&String> = rows.as_object().unwrap().keys().collect();
    assert_eq!(names, ["auv1", "auv2", "auv3"], "{rows}");
    for (name, row) in rows.as_object().unwrap() {
        assert_eq!(row["control"], "free", "{name}: {row}");
    }
    // every vehicle's track on the one map
    let trails = until(
        &c,
        Duration::from_secs(20),
        "three trails",
        "const t = window.seabusConsole.plot('All tracks');
         return t && ['auv1', 'auv2', 'auv3'].every(v => t[v] >= 2) && t;",
    )
    .await;
    assert_eq!(
        trails.as_object().unwrap().keys().collect::<Vec<_>>(),
        ["auv1", "auv2", "auv3"],
        "{trails}"
    );
    screenshot(&c, "fleet.png").await;
    // the table commands nothing: control is taken on a vehicle's own page
    assert_eq!(
        js(
            &c,
            "return document.querySelector('[data-testid=take-control]').hidden;"
        )
        .await,
        json!(true)
    );

    // auv2's own layout, from its row
    c.find(Locator::Css(
        "tr[data-vehicle=auv2] [data-testid=fleet-open]",
    ))
    .await
    .expect("auv2's open button")
    .click()
    .await
    .expect("clicked");
    until_eq(
        &c,
        Duration::from_secs(10),
        "auv2's layout",
        "const s = window.seabusConsole.state(); return [s.layout, s.vehicle, document.querySelector('[data-testid=control-label]').textContent];",
        json!(["vehicle", "auv2", "Control of auv2"]),
    )
    .await;
    take_control(&c, "pilot").await;
    assert_eq!(
        js(&c, "return window.seabusConsole.state().leases;").await,
        json!({"auv2": "pilot"})
    );
    until(
        &c,
        Duration::from_secs(30),
        "auv2's frontseat taking commands",
        "const l = document.querySelector('[data-kind=log]'); return l && /control=(accepting|in-control)/.test(l.innerText);",
    )
    .await;
    slide(&c, "heading", 200.0).await;

    // the course goes to auv2, whose driver acknowledges it; auv1 and auv3 get nothing
    let mut seen = Vec::new();
    let course = wait_for_line(
        &spy,
        &mut seen,
        Duration::from_secs(10),
        "auv2.cmd.course",
        |v| v["topic"] == "auv2.cmd.course",
    );
    assert_eq!(
        course["payload"]["heading"].as_f64(),
        Some(200.0),
        "{course}"
    );
    let origin = course["origin"].as_str().expect("an origin").to_string();
    let acknowledged = wait_for_line(
        &spy,
        &mut seen,
        Duration::from_secs(15),
        "auv2's acknowledgement",
        |v| {
            v["topic"] == "auv2.cmd.status"
                && v["payload"]["origin"] == origin.as_str()
                && v["payload"]["state"] == "acknowledged"
        },
    );
    assert_eq!(acknowledged["payload"]["command"], "OMS", "{acknowledged}");
    let history = until_text(
        &c,
        Duration::from_secs(15),
        "the acknowledgement in the history",
        "const h = document.querySelector('[data-kind=history]'); return h && /acknowledged/.test(h.innerText) && h.innerText;",
    )
    .await;
    assert!(
        history.contains("heading=200") && history.contains("acknowledged"),
        "{history}"
    );
    // 3 s more of the shore's bus: the console said who controls auv2 and kept auv2's course,
    // and nothing of the console's reached auv1 or auv3
    let deadline = Instant::now() + Duration::from_secs(3);
    while Instant::now() < deadline {
        if let Ok(v) = spy.recv_timeout(Duration::from_millis(50)) {
            seen.push(v);
        }
    }
    let mine =
        |v: &&Json| v["origin"] == origin.as_str() || v["payload"]["origin"] == origin.as_str();
    let topics: std::collections::BTreeSet<&str> = seen
        .iter()
        .filter(mine)
        .filter_map(|v| v["topic"].as_str())
        // (the shore's own modules publish on its bus as the same origin)
        .filter(|t| t.starts_with("auv"))
        .collect();
    assert_eq!(
        topics,
        ["auv2.cmd.course", "auv2.cmd.status", "auv2.console.control"].into(),
        "what the console's control and commands caused on the shore's bus"
    );
    // back in the fleet table, auv2 is the pilot's and the others are free
    c.find(Locator::Css("[data-testid=layout-select]"))
        .await
        .expect("the layout list")
        .select_by_value("fleet")
        .await
        .expect("fleet chosen");
    let rows = until(
        &c,
        Duration::from_secs(10),
        "the fleet table again",
        &format!("const rows = (() => {{ {FLEET_ROWS} }})(); return Object.keys(rows).length === 3 && rows;"),
    )
    .await;
    let control: Vec<&str> = ["auv1", "auv2", "auv3"]
        .iter()
        .map(|v| rows[v]["control"].as_str().unwrap_or("?"))
        .collect();
    assert_eq!(control, ["free", "you (pilot)", "free"], "{rows}");
    c.close().await.expect("closed");
}
