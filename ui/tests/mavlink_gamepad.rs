//! The console's gamepad driving an ArduSub ROV: a system with a `mavlink://` medium on UDP
//! loopback, the `mavlink` driver between it and the bus, and a console on the bus with the stick
//! layout of docs/mavlink.md (`stick`, a dead-man `cmd.manual` at 10 Hz). pymavlink stands in for
//! the ROV (`tests/peers/mavlink_ardusub.py`) and reports every MANUAL_CONTROL it receives. The
//! operator logs in over HTTP and drives over the WebSocket as the page does: `drive` messages
//! with the values the gamepad's axes give, faster than the layout's rate.
//!
//! What the ROV receives: nothing from a pilot who does not hold control; from the holder,
//! MANUAL_CONTROL with exactly the driven values, held to the layout's 10 Hz; when control is
//! released, or the holder logs out, while the page goes on driving, one neutral (x = y = r = 0,
//! z = 500, no buttons) and nothing after it.

mod common;

use common::{Ws, http, login, open_ws};
use futures_util::{SinkExt, StreamExt};
use seabus_medium::{Interface, Kind, Message};
use seabus_modules::system::SystemSpec;
use seabus_modules::{Catalogue, Registry, Runtime};
use seabus_ui::console::{self, Console};
use seabus_ui::users::{Users, add_user};
use serde_json::{Value as Json, json};
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use tokio_tungstenite::tungstenite;

/// The layout's rate for `stick`, as docs/mavlink.md gives it.
const RATE_HZ: f64 = 10.0;
/// How often the test's page sends `drive`: five times the layout's rate.
const PAGE_EVERY: Duration = Duration::from_millis(20);

/// The ROV layout of docs/mavlink.md, as it is written there.
fn documented_layout() -> String {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/mavlink.md"))
        .expect("docs/mavlink.md is read");
    let start = doc
        .find("<layout name=\"rov\"")
        .expect("docs/mavlink.md has the ROV layout");
    let end =
        start + doc[start..].find("</layout>").expect("the ROV layout ends") + "</layout>".len();
    let layout = doc[start..end].to_string();
    assert!(
        layout.contains("topic=\"cmd.manual\"") && layout.contains("rate=\"10Hz\""),
        "the documented stick is a 10 Hz cmd.manual: {layout}"
    );
    layout
}

/// A UDP port free on loopback now.
fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

/// The Python ROV: its process, what it reports, and where to give it orders.
struct Rov {
    child: Child,
    stdin: ChildStdin,
    events: mpsc::UnboundedReceiver<Json>,
    seen: Vec<Json>,
}

impl Rov {
    /// Starts it on `port`, sending to the medium at `to`, for at most `secs`.
    async fn start(port: u16, to: u16, secs: u32) -> Rov {
        let script = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/peers/mavlink_ardusub.py"
        );
        let mut child = Command::new("python3")
            .args([
                script,
                &port.to_string(),
                &secs.to_string(),
                "--to",
                &format!("127.0.0.1:{to}"),
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("python3 runs");
        let stdin = child.stdin.take().expect("piped");
        let out = child.stdout.take().expect("piped");
        let (tx, events) = mpsc::unbounded_channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let v: Json = serde_json::from_str(&line).expect("the ROV reports JSON");
                if tx.send(v).is_err() {
                    return;
                }
            }
        });
        let mut rov = Rov {
            child,
            stdin,
            events,
            seen: Vec::new(),
        };
        rov.wait("ready", Duration::from_secs(10), |_| true).await;
        rov
    }

    /// Waits at most `limit` for an event `event` that `pred` accepts (seen before or coming).
    async fn wait(&mut self, event: &str, limit: Duration, pred: impl Fn(&Json) -> bool) -> Json {
        if let Some(v) = self.seen.iter().find(|v| v["event"] == event && pred(v)) {
            return v.clone();
        }
        let deadline = Instant::now() + limit;
        while let Ok(Some(v)) = tokio::time::timeout_at(deadline.into(), self.events.recv()).await {
            self.seen.push(v.clone());
            if v["event"] == event && pred(&v) {
                return v;
            }
        }
        panic!(
            "the ROV reported no such {event} within {limit:?}; it reported {:?}",
            self.seen
        );
    }

    /// Everything it reports for `limit`.
    async fn drain(&mut self, limit: Duration) {
        let deadline = Instant::now() + limit;
        while let Ok(Some(v)) = tokio::time::timeout_at(deadline.into(), self.events.recv()).await {
            self.seen.push(v);
        }
    }

    /// The MANUAL_CONTROLs it received, and forgets them.
    fn take_manuals(&mut self) -> Vec<Json> {
        let (manuals, rest) = std::mem::take(&mut self.seen)
            .into_iter()
            .partition(|v| v["event"] == "manual");
        self.seen = rest;
        manuals
    }
}

impl Drop for Rov {
    fn drop(&mut self) {
        let _ = writeln!(self.stdin, "quit");
        let _ = self.stdin.flush();
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A MANUAL_CONTROL's values as the ROV reports them: target, x, y, z, r, buttons.
fn values(v: &Json) -> [i64; 6] {
    ["target", "x", "y", "z", "r", "buttons"].map(|k| {
        v[k].as_i64()
            .unwrap_or_else(|| panic!("MANUAL_CONTROL without {k}: {v}"))
    })
}

/// Seconds between the ROV's receipts of consecutive MANUAL_CONTROLs.
fn gaps(manuals: &[Json]) -> Vec<f64> {
    manuals
        .windows(2)
        .map(|w| w[1]["t"].as_f64().unwrap() - w[0]["t"].as_f64().unwrap())
        .collect()
}

fn median(mut xs: Vec<f64>) -> f64 {
    assert!(!xs.is_empty());
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

async fn send(ws: &mut Ws, v: &Json) -> Result<(), tungstenite::Error> {
    ws.send(tungstenite::Message::Text(v.to_string().into()))
        .await
}

/// The next message of `kind` that `pick` accepts, skipping others; panics after 5 s.
async fn next_where(ws: &mut Ws, kind: &str, pick: impl Fn(&Json) -> bool) -> Json {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let msg = tokio::time::timeout_at(deadline.into(), ws.next())
            .await
            .unwrap_or_else(|_| panic!("no matching `{kind}` message within 5 s"))
            .expect("open")
            .expect("readable");
        if let tungstenite::Message::Text(t) = msg {
            let v: Json = serde_json::from_str(&t).unwrap();
            if v["type"] == kind && pick(&v) {
                return v;
            }
        }
    }
}

/// Logs `name` in, opens the WebSocket and the ROV layout; returns the socket and the cookie.
async fn pilot(addr: std::net::SocketAddr, name: &str, password: &str) -> (Ws, String) {
    let (_, cookie, head) = login(addr, name, password).await;
    let cookie = cookie.unwrap_or_else(|| panic!("{name} logged in: {head}"));
    let mut ws = open_ws(addr, Some(&cookie)).await.unwrap();
    let hello = next_where(&mut ws, "hello", |_| true).await;
    assert_eq!(hello["user"], name);
    send(&mut ws, &json!({"type": "open", "layout": "rov"}))
        .await
        .unwrap();
    let layout = next_where(&mut ws, "layout", |_| true).await;
    assert_eq!(layout["layout"]["name"], "rov", "{layout}");
    (ws, cookie)
}

/// A `drive` of the stick, as the page sends it from the gamepad's axes.
fn drive(x: i64, y: i64, z: i64, r: i64) -> Json {
    json!({"type": "drive", "layout": "rov", "command": "stick",
           "fields": {"x": x, "y": y, "z": z, "r": r}})
}

/// Sends `msg` every [`PAGE_EVERY`], `count` times; returns the seconds from the first to the
/// last. Stops early (returning `None`) when the socket no longer takes messages.
async fn keep_driving(ws: &mut Ws, msg: &Json, count: usize) -> Option<f64> {
    let t0 = Instant::now();
    let mut last = t0;
    for _ in 0..count {
        send(ws, msg).await.ok()?;
        last = Instant::now();
        tokio::time::sleep(PAGE_EVERY).await;
    }
    Some(last.duration_since(t0).as_secs_f64())
}

/// Checks a stream of MANUAL_CONTROLs driven for `window` seconds with `driven` values: the
/// values exactly, and held to the layout's rate although the page sent five times as often.
fn assert_driven_at_rate(driven: &[Json], expected: [i64; 6], window: f64) {
    for v in driven {
        assert_eq!(values(v), expected, "{driven:?}");
    }
    // the hub lets a re-send out once 0.8 of a period has passed since the last: at most
    // 12.5 a second, against the page's 50
    let n = driven.len() as f64;
    assert!(
        n >= window * RATE_HZ * 0.5 && n <= window * RATE_HZ / 0.8 + 2.0,
        "{n} MANUAL_CONTROLs over {window:.2} s of driving at {RATE_HZ} Hz"
    );
    let typical = median(gaps(driven));
    assert!(
        (0.07..=0.2).contains(&typical),
        "MANUAL_CONTROLs {typical:.3} s apart, the page's drives {:.3} s: {:?}",
        PAGE_EVERY.as_secs_f64(),
        gaps(driven)
    );
}

const NEUTRAL: [i64; 6] = [1, 0, 0, 500, 0, 0];

/// What `watch` heard on the bus so far: the `cmd.manual` commands' (x, y, z, r), and the
/// driver's `cmd.status` errors.
async fn on_the_bus(watch: &mut Interface) -> (Vec<[i64; 4]>, Vec<String>) {
    let (mut manuals, mut errors) = (Vec::new(), Vec::new());
    let deadline = Instant::now() + Duration::from_secs(2);
    for _ in 0..1000 {
        let Ok(Some(m)) = tokio::time::timeout_at(
            deadline
                .min(Instant::now() + Duration::from_millis(100))
                .into(),
            watch.recv(),
        )
        .await
        else {
            break;
        };
        let Message { topic, payload, .. } = m;
        let p = payload.as_map().expect("a datamap");
        match topic.as_str() {
            "cmd.manual" => manuals.push(["x", "y", "z", "r"].map(|k| {
                p.get_f64(k)
                    .unwrap_or_else(|| panic!("cmd.manual without {k}")) as i64
            })),
            _ => errors.extend(p.get_str("error").map(str::to_string)),
        }
    }
    (manuals, errors)
}

/// The neutral the ROV received was the console's, sent once, not the driver's own after its
/// `manual_timeout`.
fn assert_neutral_from_the_console(manuals: &[[i64; 4]], errors: &[String]) {
    let neutrals = manuals.iter().filter(|m| **m == [0, 0, 500, 0]).count();
    assert_eq!(
        (neutrals, manuals.last()),
        (1, Some(&[0, 0, 500, 0])),
        "the console's cmd.manual: {manuals:?}"
    );
    assert!(
        !errors.iter().any(|e| e.contains("neutral sent")),
        "the driver had to send neutral itself: {errors:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_consoles_gamepad_drives_manual_control_at_the_leases_rate_and_stops_neutral_when_the_lease_ends()
 {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (mav_port, rov_port) = (free_port(), free_port());
    std::fs::write(d.join("rov.xml"), documented_layout()).unwrap();
    let users = d.join("users.xml");
    add_user(&users, "ana", &["pilot".into()], "ana-password").unwrap();
    add_user(&users, "bo", &["pilot".into()], "bo-password1").unwrap();
    std::fs::write(
        d.join("system.xml"),
        format!(
            r#"<seabus node="rov">
  <medium name="bus" url="inproc://"/>
  <medium name="mav" url="mavlink://udpin:127.0.0.1:{mav_port}?timeout=2s"/>
  <module name="rov" type="mavlink" media="mav bus" manual_timeout="1s"/>
  <console medium="bus" listen="127.0.0.1:0" users="users.xml" layouts="rov.xml"/>
</seabus>"#
        ),
    )
    .unwrap();

    // the system as `seabus run` starts it: the runtime, then the console on its bus
    let spec = SystemSpec::load(&d.join("system.xml")).unwrap();
    let mut registry = Registry::new();
    registry.set_schemes(seabus_medium_mavlink::schemes());
    seabus_drivers::register(&mut registry);
    seabus_ui::register(&mut registry);
    let runtime = Runtime::start(&spec, &registry, Catalogue::built_in())
        .await
        .unwrap();
    let bus = runtime.medium("bus").expect("the bus").clone();
    let produced = seabus_ui::layout::producers(&spec, &registry, &Catalogue::built_in(), "bus")
        .into_iter()
        .map(|p| p.pattern)
        .collect();
    let cs = console::specs(&spec).unwrap().remove(0);
    let console = Console::start(&cs, Users::load(&users).unwrap(), &bus, produced)
        .await
        .unwrap();
    let addr = console.addr();

    // the ROV is heard: the driver follows it
    let mut state = bus.attach("watch");
    state.subscribe("vehicle.state").unwrap();
    let mut watch = bus.attach("commands");
    watch
        .subscribe_kind("cmd.manual", Some(Kind::Command))
        .unwrap();
    watch.subscribe("cmd.status").unwrap();
    let mut rov = Rov::start(rov_port, mav_port, 90).await;
    let heard = async {
        for _ in 0..100 {
            let m = state.recv().await.expect("the bus is open");
            let p = m.payload.as_map().expect("a datamap");
            if p.get_str("control") == Some("idle") {
                return;
            }
        }
        panic!("vehicle.state never said the ROV was idle");
    };
    tokio::time::timeout(Duration::from_secs(10), heard)
        .await
        .expect("the driver hears the ROV within 10 s");

    let (mut ana, ana_cookie) = pilot(addr, "ana", "ana-password").await;
    let (mut bo, _) = pilot(addr, "bo", "bo-password1").await;
    send(&mut ana, &json!({"type": "lease", "action": "take"}))
        .await
        .unwrap();
    next_where(&mut bo, "lease", |v| v["holder"] == "ana").await;

    // bo, a pilot without control, drives: refused, and the ROV receives nothing
    let bos = drive(900, 0, 1000, 0);
    send(&mut bo, &bos).await.unwrap();
    let e = next_where(&mut bo, "error", |_| true).await;
    assert!(
        e["message"].as_str().unwrap_or("").contains("ana has it"),
        "{e}"
    );
    assert!(keep_driving(&mut bo, &bos, 25).await.is_some());
    rov.drain(Duration::from_millis(500)).await;
    let got = rov.take_manuals();
    assert!(got.is_empty(), "bo's stick reached the ROV: {got:?}");
    let (commands, _) = on_the_bus(&mut watch).await;
    assert!(
        commands.is_empty(),
        "bo's stick reached the bus: {commands:?}"
    );

    // ana drives: stick forward and right, thrust up, turning (x = 250, y = -400, z = 700,
    // r = 150), for 1.5 s at the page's 50 Hz
    let ahead = drive(250, -400, 700, 150);
    let window = keep_driving(&mut ana, &ahead, 75)
        .await
        .expect("the page drives");
    // control released while the page goes on driving: its drives are refused now
    send(&mut ana, &json!({"type": "lease", "action": "release"}))
        .await
        .unwrap();
    next_where(&mut bo, "lease", |v| v["holder"].is_null()).await;
    assert!(keep_driving(&mut ana, &ahead, 25).await.is_some());
    next_where(&mut ana, "error", |e| {
        e["message"]
            .as_str()
            .is_some_and(|m| m.contains("no control"))
    })
    .await;
    rov.wait("manual", Duration::from_secs(3), |v| values(v) == NEUTRAL)
        .await;
    // longer than the driver's manual_timeout and the hub's three periods: nothing more comes
    rov.drain(Duration::from_millis(2000)).await;
    let manuals = rov.take_manuals();
    let (driven, tail) = manuals.split_at(manuals.len() - 1);
    assert_eq!(
        values(&tail[0]),
        NEUTRAL,
        "the last MANUAL_CONTROL is the neutral: {manuals:?}"
    );
    assert!(
        driven.iter().all(|v| values(v) != NEUTRAL),
        "one neutral, after the driven ones: {manuals:?}"
    );
    assert_driven_at_rate(driven, [1, 250, -400, 700, 150, 0], window);
    let (commands, errors) = on_the_bus(&mut watch).await;
    assert_neutral_from_the_console(&commands, &errors);

    // ana takes control again and drives (back, left, thrust down, turning the other way);
    // she logs out while the page is still driving
    send(&mut ana, &json!({"type": "lease", "action": "take"}))
        .await
        .unwrap();
    next_where(&mut bo, "lease", |v| v["holder"] == "ana").await;
    let back = drive(-600, 300, 200, -900);
    let window = keep_driving(&mut ana, &back, 50)
        .await
        .expect("the page drives");
    let (status, head) = http(
        addr,
        format!(
            "GET /logout HTTP/1.1\r\nHost: {addr}\r\nCookie: {ana_cookie}\r\nConnection: close\r\n\r\n"
        ),
    )
    .await;
    assert_eq!(status, 303, "{head}");
    next_where(&mut bo, "lease", |v| v["holder"].is_null()).await;
    // the page goes on as long as its socket takes messages: none of it reaches the ROV
    keep_driving(&mut ana, &back, 25).await;
    rov.wait("manual", Duration::from_secs(3), |v| values(v) == NEUTRAL)
        .await;
    rov.drain(Duration::from_millis(2000)).await;
    let manuals = rov.take_manuals();
    let (driven, tail) = manuals.split_at(manuals.len() - 1);
    assert_eq!(
        values(&tail[0]),
        NEUTRAL,
        "the last MANUAL_CONTROL is the neutral: {manuals:?}"
    );
    assert!(
        driven.iter().all(|v| values(v) != NEUTRAL),
        "one neutral, after the driven ones: {manuals:?}"
    );
    assert_driven_at_rate(driven, [1, -600, 300, 200, -900, 0], window);
    let (commands, errors) = on_the_bus(&mut watch).await;
    assert_neutral_from_the_console(&commands, &errors);

    drop((ana, bo, rov));
    drop(console);
    runtime.shutdown().await;
}
