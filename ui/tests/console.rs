//! The console server driven as a page drives it — log-in over HTTP, then JSON over the WebSocket
//! — with a bus where a test driver receives the commands and acknowledges them. Every rule is
//! checked on the server side: sessions, log-in limits, roles, control, confirmation, dead-man
//! commands, acknowledgements, bound fields only, the designer's saves.

mod common;

use common::{PILOT, Setup, WATCH, Ws, http, login, open_ws, setup};
use futures_util::{SinkExt, StreamExt};
use seabus_medium::{DataMap, Interface, Kind, Medium, Message, Value};
use serde_json::{Value as Json, json};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite;

async fn connect(s: &Setup, name: &str, password: &str) -> Ws {
    let (_, cookie, head) = login(s.addr, name, password).await;
    let cookie = cookie.unwrap_or_else(|| panic!("{name} logged in: {head}"));
    let mut ws = open_ws(s.addr, Some(&cookie)).await.unwrap();
    let hello = next(&mut ws, "hello").await;
    assert_eq!(hello["user"], name);
    ws
}

async fn send(ws: &mut Ws, v: Json) {
    ws.send(tungstenite::Message::Text(v.to_string().into()))
        .await
        .unwrap();
}

/// The next message of `kind`, skipping others; panics after 5 s.
async fn next(ws: &mut Ws, kind: &str) -> Json {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let msg = tokio::time::timeout(left, ws.next())
            .await
            .unwrap_or_else(|_| panic!("no `{kind}` message within 5 s"))
            .expect("open")
            .expect("readable");
        if let tungstenite::Message::Text(t) = msg {
            let v: Json = serde_json::from_str(&t).unwrap();
            if v["type"] == kind {
                return v;
            }
        }
    }
}

/// The next message of `kind` that satisfies `pick`.
async fn next_where(ws: &mut Ws, kind: &str, pick: impl Fn(&Json) -> bool) -> Json {
    for _ in 0..200 {
        let v = next(ws, kind).await;
        if pick(&v) {
            return v;
        }
    }
    panic!("no matching `{kind}`");
}

/// Sends `v` and expects the error that says `why`.
async fn refused_with(ws: &mut Ws, v: Json, why: &str) {
    send(ws, v).await;
    let e = next(ws, "error").await;
    assert!(e["message"].as_str().unwrap_or("").contains(why), "{e}");
}

async fn open(ws: &mut Ws, layout: &str) -> Json {
    send(ws, json!({"type": "open", "layout": layout})).await;
    next(ws, "layout").await
}

/// An interface on the bus that sees the commands.
fn driver(bus: &Medium) -> Interface {
    let mut d = bus.attach("driver");
    d.subscribe_kind("cmd.**", Some(Kind::Command)).unwrap();
    d
}

/// The commands the driver receives within `wait`.
async fn received(d: &mut Interface, wait: Duration) -> Vec<Message> {
    let mut out = Vec::new();
    let deadline = Instant::now() + wait;
    while let Ok(Some(m)) =
        tokio::time::timeout(deadline.saturating_duration_since(Instant::now()), d.recv()).await
    {
        out.push(m);
    }
    out
}

fn field(m: &Message, k: &str) -> Option<Value> {
    m.payload.as_map().and_then(|p| p.get(k)).cloned()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn log_in_needs_the_password_and_is_rate_limited() {
    let s = setup().await;
    // the page and the socket need a session
    let (status, head) = http(
        s.addr,
        format!(
            "GET / HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            s.addr
        ),
    )
    .await;
    assert_eq!(status, 303, "{head}");
    assert!(head.to_lowercase().contains("location: /login"), "{head}");
    assert!(open_ws(s.addr, None).await.is_err());
    assert!(
        open_ws(s.addr, Some("seabus_session=0123456789abcdef"))
            .await
            .is_err()
    );
    // wrong passwords: refused, then limited for the name from any address
    for i in 0..5 {
        let (status, cookie, head) = login(s.addr, "bo", "guess").await;
        assert_eq!(
            (status, cookie.is_none()),
            (303, true),
            "attempt {i}: {head}"
        );
        assert!(head.contains("error=Wrong"), "{head}");
    }
    let (status, cookie, _) = login(s.addr, "bo", "bo-password1").await;
    assert_eq!(
        (status, cookie),
        (429, None),
        "the right password is refused while limited"
    );
    // and this address is held back for every name
    let (status, _, _) = login(s.addr, "ana", "ana-password").await;
    assert_eq!(status, 429);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_answer_carries_the_security_headers() {
    let s = setup().await;
    let (_, cookie, _) = login(s.addr, "ana", "ana-password").await;
    let cookie = cookie.expect("a session");
    for (path, with) in [
        ("/login", None),
        ("/", Some(&cookie)),
        ("/", None),
        ("/assets/console.js", None),
        ("/assets/nothing.js", None),
    ] {
        let cookie = with.map_or(String::new(), |c| format!("Cookie: {c}\r\n"));
        let (status, text) = http(
            s.addr,
            format!("GET {path} HTTP/1.1\r\nHost: x\r\n{cookie}Connection: close\r\n\r\n"),
        )
        .await;
        let head = text.split("\r\n\r\n").next().unwrap().to_ascii_lowercase();
        for (name, value) in seabus_ui::server::SECURITY_HEADERS {
            assert!(
                head.contains(&format!("{name}: {}", value.to_ascii_lowercase())),
                "{path} ({status}) lacks {name}:\n{head}"
            );
        }
        assert!(
            head.contains("connect-src 'self' ws://x wss://x\r\n"),
            "the page's own WebSocket: {head}"
        );
        assert!(!head.contains("unsafe-inline"), "{head}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_observer_cannot_command_even_with_a_forged_message() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    let mut ivo = connect(&s, "ivo", "ivo-password").await;
    // the pilot layout is not ivo's
    refused_with(
        &mut ivo,
        json!({"type": "open", "layout": "pilot"}),
        "no layout",
    )
    .await;
    let l = open(&mut ivo, "watch").await;
    assert_eq!(l["layout"]["name"], "watch");
    // forged: a command of a layout ivo never opened, and control
    refused_with(
        &mut ivo,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"speed": 2}}),
        "not open",
    )
    .await;
    refused_with(
        &mut ivo,
        json!({"type": "lease", "action": "take"}),
        "role pilot",
    )
    .await;
    send(
        &mut ivo,
        json!({"type": "drive", "layout": "watch", "command": "course", "fields": {"speed": 2}}),
    )
    .await;
    next(&mut ivo, "error").await;
    assert!(
        received(&mut d, Duration::from_millis(300))
            .await
            .is_empty(),
        "nothing reached the bus"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_the_holder_of_control_commands_and_acknowledgements_show() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    let mut control = s.bus.attach("control");
    control.subscribe("console.control").unwrap();
    let mut ana = connect(&s, "ana", "ana-password").await;
    let mut bo = connect(&s, "bo", "bo-password1").await;
    open(&mut ana, "pilot").await;
    open(&mut bo, "pilot").await;
    // without control: refused, and the refusal is in everyone's history
    send(
        &mut ana,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"heading": 90}}),
    )
    .await;
    let refused = next(&mut bo, "command").await;
    assert_eq!(refused["state"], "refused");
    assert!(refused["reason"].as_str().unwrap().contains("no control"));
    send(&mut ana, json!({"type": "lease", "action": "take"})).await;
    let lease = next_where(&mut bo, "lease", |v| v["holder"] == "ana").await;
    assert!(lease["since"].as_f64().is_some());
    // modules on the bus see who has control too
    let m = tokio::time::timeout(Duration::from_secs(2), control.recv())
        .await
        .expect("console.control")
        .expect("open");
    assert_eq!(
        field(&m, "holder")
            .and_then(|v| v.as_str().map(str::to_string))
            .as_deref(),
        Some("ana")
    );
    // bo can neither take control nor command while ana has it
    refused_with(
        &mut bo,
        json!({"type": "lease", "action": "take"}),
        "ana has control",
    )
    .await;
    refused_with(
        &mut bo,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"heading": 10}}),
        "ana has it",
    )
    .await;
    // ana commands: the driver gets the whole command, and acknowledges it
    send(
        &mut ana,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"heading": 90, "speed": 1.5}}),
    )
    .await;
    let got = received(&mut d, Duration::from_millis(300)).await;
    assert_eq!(got.len(), 1, "{got:?}");
    let m = &got[0];
    assert_eq!(m.topic.as_str(), "cmd.course");
    assert_eq!(field(m, "heading").and_then(|v| v.as_f64()), Some(90.0));
    assert_eq!(field(m, "speed").and_then(|v| v.as_f64()), Some(1.5));
    assert_eq!(field(m, "depth").and_then(|v| v.as_f64()), Some(0.0));
    let pending = next_where(&mut bo, "command", |v| v["state"] == "pending").await;
    assert_eq!(pending["user"], "ana");
    let status = DataMap::new()
        .with("command", "OMS")
        .with("state", "acknowledged")
        .with("origin", m.provenance.origin.to_string())
        .with("request_seq", m.provenance.seq as i64);
    d.send("cmd.status", status).await.unwrap();
    let acked = next_where(&mut bo, "command", |v| v["id"] == pending["id"]).await;
    assert_eq!(acked["state"], "acknowledged");
    // out of range: refused by the server with the reason
    send(
        &mut ana,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"speed": 9}}),
    )
    .await;
    next(&mut ana, "error").await;
    // unanswered: timed out after ack_timeout
    send(
        &mut ana,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"heading": 180}}),
    )
    .await;
    let late = next_where(&mut ana, "command", |v| v["state"] == "timed-out").await;
    assert_eq!(late["fields"]["heading"].as_f64(), Some(180.0));
    // a command that needs no control goes from bo too
    send(
        &mut bo,
        json!({"type": "send", "layout": "pilot", "command": "camera", "fields": {"on": true}}),
    )
    .await;
    // ana releases; now bo takes control and commands
    send(&mut ana, json!({"type": "lease", "action": "release"})).await;
    next_where(&mut bo, "lease", |v| v["holder"].is_null()).await;
    send(&mut bo, json!({"type": "lease", "action": "take"})).await;
    next_where(&mut ana, "lease", |v| v["holder"] == "bo").await;
    send(
        &mut bo,
        json!({"type": "send", "layout": "pilot", "command": "course", "fields": {"heading": 45}}),
    )
    .await;
    let got = received(&mut d, Duration::from_millis(300)).await;
    let topics: Vec<&str> = got.iter().map(|m| m.topic.as_str()).collect();
    assert!(
        topics.contains(&"cmd.camera") && topics.contains(&"cmd.course"),
        "{topics:?}"
    );
    // every command is in the log with its user and state
    let log = std::fs::read_to_string(s.dir.join("commands.csv")).unwrap();
    assert!(
        log.lines()
            .any(|l| l.contains(",ana,course,") && l.contains("acknowledged"))
    );
    assert!(log.lines().any(|l| l.contains(",bo,camera,")));
    assert!(log.lines().any(|l| l.contains("timed-out")));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn confirmed_commands_must_be_armed_and_held() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    let mut ana = connect(&s, "ana", "ana-password").await;
    open(&mut ana, "pilot").await;
    send(&mut ana, json!({"type": "lease", "action": "take"})).await;
    next_where(&mut ana, "lease", |v| v["holder"] == "ana").await;
    let start = json!({"type": "send", "layout": "pilot", "command": "start"});
    refused_with(&mut ana, start.clone(), "not confirmed").await;
    // armed, but let go before the hold time
    send(
        &mut ana,
        json!({"type": "arm", "layout": "pilot", "command": "start"}),
    )
    .await;
    let arm = next(&mut ana, "armed").await["arm"].clone();
    let mut early = start.clone();
    early["confirmed"] = arm;
    refused_with(&mut ana, early, "held").await;
    // held long enough
    send(
        &mut ana,
        json!({"type": "arm", "layout": "pilot", "command": "start"}),
    )
    .await;
    let arm = next(&mut ana, "armed").await["arm"].clone();
    tokio::time::sleep(Duration::from_millis(350)).await;
    let mut held = start.clone();
    held["confirmed"] = arm.clone();
    send(&mut ana, held.clone()).await;
    let got = received(&mut d, Duration::from_millis(300)).await;
    assert_eq!(got.len(), 1);
    assert_eq!(
        field(&got[0], "action")
            .and_then(|v| v.as_str().map(str::to_string))
            .as_deref(),
        Some("start")
    );
    // an arm is used once
    send(&mut ana, held).await;
    next(&mut ana, "error").await;
    assert!(
        received(&mut d, Duration::from_millis(200))
            .await
            .is_empty()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crafted_message_overriding_a_buttons_fixed_field_is_refused() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    let mut ana = connect(&s, "ana", "ana-password").await;
    open(&mut ana, "pilot").await;
    send(&mut ana, json!({"type": "lease", "action": "take"})).await;
    next_where(&mut ana, "lease", |v| v["holder"] == "ana").await;
    // armed and held as the start button is, but with the mission's action made up by the page
    send(
        &mut ana,
        json!({"type": "arm", "layout": "pilot", "command": "start"}),
    )
    .await;
    let arm = next(&mut ana, "armed").await["arm"].clone();
    tokio::time::sleep(Duration::from_millis(350)).await;
    refused_with(
        &mut ana,
        json!({"type": "send", "layout": "pilot", "command": "start", "confirmed": arm,
               "fields": {"action": "abort"}}),
        "field `action` is set by the layout's controls, and none of them sends \"abort\"",
    )
    .await;
    let refusal = next_where(&mut ana, "command", |c| c["state"] == "refused").await;
    assert_eq!(refusal["command"], "start");
    assert!(
        received(&mut d, Duration::from_millis(300))
            .await
            .is_empty(),
        "the vehicle receives nothing"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dead_man_command_goes_neutral_once_when_its_re_sends_stop() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    let (_, cookie, _) = login(s.addr, "ana", "ana-password").await;
    let cookie = cookie.unwrap();
    let mut ana = open_ws(s.addr, Some(&cookie)).await.unwrap();
    next(&mut ana, "hello").await;
    open(&mut ana, "pilot").await;
    send(&mut ana, json!({"type": "lease", "action": "take"})).await;
    next_where(&mut ana, "lease", |v| v["holder"] == "ana").await;
    let drive = json!({"type": "drive", "layout": "pilot", "command": "course", "fields": {"speed": 2, "heading": 30}});
    // every 300 ms: a re-send within the command's three periods (5 Hz: 600 ms) keeps it alive,
    // and one at least 0.8 of a period (160 ms) after the last published is published, with
    // room for the hub taking one late and the next on time
    for _ in 0..5 {
        send(&mut ana, drive.clone()).await;
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    // the page stops (frozen): within three periods the neutral command goes, once
    let got = received(&mut d, Duration::from_millis(1500)).await;
    let speeds: Vec<f64> = got
        .iter()
        .filter_map(|m| field(m, "speed").and_then(|v| v.as_f64()))
        .collect();
    assert_eq!(speeds.len(), 6, "five drives and one neutral: {speeds:?}");
    assert!(speeds[..5].iter().all(|v| *v == 2.0));
    assert_eq!(speeds[5], 0.0);
    // the neutral keeps the other fields as last driven
    assert_eq!(
        field(&got[5], "heading").and_then(|v| v.as_f64()),
        Some(30.0)
    );
    assert!(
        received(&mut d, Duration::from_millis(800))
            .await
            .is_empty(),
        "then nothing"
    );

    // driving, then the connection drops: neutral once
    send(&mut ana, drive.clone()).await;
    assert_eq!(received(&mut d, Duration::from_millis(100)).await.len(), 1);
    drop(ana);
    let got = received(&mut d, Duration::from_millis(400)).await;
    let speeds: Vec<f64> = got
        .iter()
        .filter_map(|m| field(m, "speed").and_then(|v| v.as_f64()))
        .collect();
    assert_eq!(speeds, [0.0], "neutral once when the connection closed");

    // the page connects again (its log-in keeps control for the grace): an explicit release
    // goes neutral once, at once
    let mut ana = open_ws(s.addr, Some(&cookie)).await.unwrap();
    next(&mut ana, "hello").await;
    open(&mut ana, "pilot").await;
    send(&mut ana, drive.clone()).await;
    send(
        &mut ana,
        json!({"type": "release", "layout": "pilot", "command": "course"}),
    )
    .await;
    let got = received(&mut d, Duration::from_millis(300)).await;
    let speeds: Vec<f64> = got
        .iter()
        .filter_map(|m| field(m, "speed").and_then(|v| v.as_f64()))
        .collect();
    assert_eq!(speeds, [2.0, 0.0]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_gets_only_the_fields_it_binds_at_most_twenty_times_a_second() {
    let s = setup().await;
    let mut ivo = connect(&s, "ivo", "ivo-password").await;
    let layout = open(&mut ivo, "watch").await;
    assert_eq!(layout["producers"]["nav.depth"], false, "{layout}");
    let tx = s.bus.attach("sensor");
    let t0 = Instant::now();
    for i in 0..100 {
        tx.send(
            "nav.depth",
            DataMap::new().with("depth", f64::from(i)).with("raw", 7i64),
        )
        .await
        .unwrap();
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let mut frames = Vec::new();
    loop {
        let v = next(&mut ivo, "data").await;
        let depth = v["topics"]["nav.depth"]["fields"]["depth"].as_f64();
        assert!(
            v["topics"]["nav.depth"]["fields"].get("raw").is_none(),
            "{v}"
        );
        frames.push(v);
        if depth == Some(99.0) {
            break;
        }
    }
    // 100 messages arrive as frames at least 50 ms apart, the last value last
    let took = t0.elapsed().as_secs_f64();
    assert!(
        frames.len() as f64 <= took / 0.05 + 2.0 && frames.len() < 100,
        "{} frames in {took:.2} s",
        frames.len()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_designer_saves_layouts_that_read_and_refuses_others_with_their_place() {
    let s = setup().await;
    let mut bo = connect(&s, "bo", "bo-password1").await;
    refused_with(
        &mut bo,
        json!({"type": "save", "layout": "watch", "xml": WATCH}),
        "role designer",
    )
    .await;
    let mut ana = connect(&s, "ana", "ana-password").await;
    let bad = WATCH.replace(
        "<readout bind=\"nav.depth.depth\"",
        "<readout bind=\"nav.depth.depth\" colour=",
    );
    send(
        &mut ana,
        json!({"type": "save", "layout": "watch", "xml": bad}),
    )
    .await;
    let e = next(&mut ana, "error").await;
    assert_eq!(e["error"]["line"], 3, "{e}");
    assert!(e["error"]["col"].as_u64().unwrap() > 1, "{e}");
    let good = WATCH.replace("title=\"Watch\"", "title=\"Watch floor\"");
    send(
        &mut ana,
        json!({"type": "save", "layout": "watch", "xml": good}),
    )
    .await;
    next(&mut ana, "saved").await;
    let l = next(&mut ana, "layout").await;
    assert_eq!(l["layout"]["title"], "Watch floor");
    assert_eq!(
        std::fs::read_to_string(s.dir.join("watch.xml.bak")).unwrap(),
        WATCH
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn what_a_page_makes_up_stays_out_of_everyone_s_history() {
    let s = setup().await;
    let mut ana = connect(&s, "ana", "ana-password").await;
    let mut ivo = connect(&s, "ivo", "ivo-password").await;
    open(&mut ivo, "watch").await;
    let junk = "j".repeat(100_000);
    send(
        &mut ivo,
        json!({"type": "send", "layout": junk, "command": junk, "fields": {"x": junk}}),
    )
    .await;
    next(&mut ivo, "error").await;
    // nothing reaches the others' history
    let quiet = tokio::time::timeout(Duration::from_millis(500), next(&mut ana, "command")).await;
    assert!(quiet.is_err(), "a made-up command was recorded: {quiet:?}");
    let mut late = connect(&s, "bo", "bo-password1").await;
    let h = next(&mut late, "history").await;
    assert_eq!(h["commands"].as_array().map(Vec::len), Some(0), "{h}");
    assert!(!s.dir.join("commands.csv").exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_designer_alone_cannot_change_who_may_command() {
    let s = setup().await;
    let mut dee = connect(&s, "dee", "dee-password").await;
    // the pilot's layout is not dee's to save
    refused_with(
        &mut dee,
        json!({"type": "save", "layout": "pilot", "xml": PILOT}),
        "no layout",
    )
    .await;
    // dee's own layout: a new title is fine, a command or a role is not
    let armed = WATCH.replace(
        "  <grid columns=\"1\">",
        "  <command name=\"go\" topic=\"cmd.mission\" fields=\"action=start\" role=\"designer\" lease=\"false\"/>\n  <grid columns=\"1\">",
    );
    refused_with(
        &mut dee,
        json!({"type": "save", "layout": "watch", "xml": armed}),
        "role pilot",
    )
    .await;
    let wider = WATCH.replace(
        "roles=\"observer pilot\"",
        "roles=\"observer pilot designer\"",
    );
    send(
        &mut dee,
        json!({"type": "save", "layout": "watch", "xml": wider}),
    )
    .await;
    next(&mut dee, "error").await;
    let renamed = WATCH.replace("title=\"Watch\"", "title=\"Bridge\"");
    send(
        &mut dee,
        json!({"type": "save", "layout": "watch", "xml": renamed}),
    )
    .await;
    next(&mut dee, "saved").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn logging_out_releases_control_and_re_sends_are_held_to_the_rate() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    let (_, cookie, _) = login(s.addr, "ana", "ana-password").await;
    let cookie = cookie.unwrap();
    let mut ana = open_ws(s.addr, Some(&cookie)).await.unwrap();
    next(&mut ana, "hello").await;
    let mut bo = connect(&s, "bo", "bo-password1").await;
    open(&mut ana, "pilot").await;
    send(&mut ana, json!({"type": "lease", "action": "take"})).await;
    next_where(&mut bo, "lease", |v| v["holder"] == "ana").await;
    // 40 re-sends as fast as a page can: the 5 Hz command goes out about 5 times a second
    let drive = json!({"type": "drive", "layout": "pilot", "command": "course", "fields": {"speed": 1, "heading": 10}});
    let t0 = Instant::now();
    for _ in 0..40 {
        send(&mut ana, drive.clone()).await;
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let took = t0.elapsed().as_secs_f64();
    let sent = received(&mut d, Duration::from_millis(50)).await.len();
    assert!(
        (sent as f64) <= took * 5.0 / 0.8 + 2.0,
        "{sent} published in {took:.2} s"
    );
    // log-out: control goes at once (and the drive's neutral with it)
    let (status, _) = http(
        s.addr,
        format!(
            "GET /logout HTTP/1.1\r\nHost: {}\r\nCookie: {cookie}\r\nConnection: close\r\n\r\n",
            s.addr
        ),
    )
    .await;
    assert_eq!(status, 303);
    let t = Instant::now();
    next_where(&mut bo, "lease", |v| v["holder"].is_null()).await;
    assert!(t.elapsed() < Duration::from_secs(3), "{:?}", t.elapsed());
    let got = received(&mut d, Duration::from_millis(300)).await;
    assert!(
        got.iter()
            .any(|m| field(m, "speed").and_then(|v| v.as_f64()) == Some(0.0)),
        "{got:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn control_belongs_to_the_log_in_that_took_it_not_to_its_user() {
    let s = setup().await;
    let mut d = driver(&s.bus);
    // the same pilot logged in twice (two machines): each log-in has its own session
    let (_, first_cookie, _) = login(s.addr, "ana", "ana-password").await;
    let mut first = open_ws(s.addr, Some(&first_cookie.unwrap())).await.unwrap();
    let first_hello = next(&mut first, "hello").await;
    let (_, second_cookie, _) = login(s.addr, "ana", "ana-password").await;
    let second_cookie = second_cookie.unwrap();
    let mut second = open_ws(s.addr, Some(&second_cookie)).await.unwrap();
    let second_hello = next(&mut second, "hello").await;
    assert_ne!(first_hello["session"], second_hello["session"]);
    open(&mut first, "pilot").await;
    open(&mut second, "pilot").await;
    send(&mut first, json!({"type": "lease", "action": "take"})).await;
    let taken = next_where(&mut second, "lease", |v| v["holder"] == "ana").await;
    assert_eq!(taken["session"], first_hello["session"]);
    // the second log-in neither takes control nor commands
    refused_with(
        &mut second,
        json!({"type": "lease", "action": "take"}),
        "you have control in another log-in",
    )
    .await;
    refused_with(
        &mut second,
        json!({"type": "send", "layout": "pilot", "command": "course",
               "fields": {"heading": 10, "speed": 1}}),
        "another log-in",
    )
    .await;
    assert!(
        received(&mut d, Duration::from_millis(200))
            .await
            .is_empty()
    );
    // its log-out leaves the first log-in's control
    let (status, _) = http(
        s.addr,
        format!(
            "GET /logout HTTP/1.1\r\nHost: {}\r\nCookie: {second_cookie}\r\nConnection: close\r\n\r\n",
            s.addr
        ),
    )
    .await;
    assert_eq!(status, 303);
    send(
        &mut first,
        json!({"type": "drive", "layout": "pilot", "command": "course",
               "fields": {"heading": 20, "speed": 1}}),
    )
    .await;
    let got = received(&mut d, Duration::from_millis(300)).await;
    assert!(!got.is_empty(), "the first log-in still commands");
    assert_eq!(field(&got[0], "heading"), Some(Value::from(20)));
    send(&mut first, json!({"type": "lease", "action": "release"})).await;
    next_where(&mut first, "lease", |v| v["holder"].is_null()).await;
}
