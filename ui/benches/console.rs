//! The console's cost as its clients grow: 50 bound variables (10 topics × 5 fields) updated at
//! 20 Hz, sent to 1, 10 and 50 logged-in WebSocket clients. Printed for each count: the server
//! process's CPU share (of one core) and the bytes per second each client receives; the same for
//! the floor — every bus message written raw (JSON lines) to as many plain TCP sockets, no
//! coalescing, no WebSocket; and the Foxglove live view (`seabus_ui::foxglove`): 50 topics of 5
//! fields at 20 Hz to as many Foxglove WebSocket clients subscribed to every channel.
//!
//! The clients run in a child process (this binary again), so the CPU figure is the server's
//! alone (with the publisher, which every run has). Goal: the console's CPU at most 1.5× the
//! floor's at 10 clients. The smoke run (`SEABUS_BENCH_SMOKE=1`) measures 1 and 10 clients, 8 s
//! each instead of 10.
//!
//! ```text
//! cargo bench -p seabus-ui --bench console
//! ```

use futures_util::StreamExt;
use seabus_bench::{Goals, scale};
use seabus_medium::{DataMap, Medium, Node};
use seabus_modules::system::SystemSpec;
use seabus_ui::console::{self, Console};
use seabus_ui::foxglove;
use seabus_ui::users::Users;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

const TOPICS: usize = 10;
const FIELDS: usize = 5;
const RATE_HZ: f64 = 20.0;
/// The client counts measured (the goal is held at 10); the smoke run leaves out 50.
fn client_counts() -> Vec<usize> {
    scale(vec![1, 10, 50], vec![1, 10])
}
/// The client count the goal is held at.
const GOAL_CLIENTS: usize = 10;
/// The Foxglove run's topics.
const FOXGLOVE_TOPICS: usize = 50;

/// Seconds each run is measured (the child process, started with the same environment, agrees).
fn seconds() -> u64 {
    scale(10, 8)
}

fn cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct we own
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 * 1e-6;
    t(u.ru_utime) + t(u.ru_stime)
}

/// Each variable in a readout, and each topic's in a plot (whose past the console keeps).
fn layout() -> String {
    let mut widgets = String::new();
    for t in 0..TOPICS {
        let mut series = String::new();
        for f in 0..FIELDS {
            widgets += &format!("    <readout bind=\"bench.t{t}.f{f}\" precision=\"3\"/>\n");
            series += &format!("      <series bind=\"bench.t{t}.f{f}\"/>\n");
        }
        widgets += &format!("    <plot window=\"10min\">\n{series}    </plot>\n");
    }
    format!(
        "<layout name=\"bench\" roles=\"observer\">\n  <grid columns=\"5\">\n{widgets}  </grid>\n</layout>\n"
    )
}

/// Publishes [`TOPICS`] topics at [`RATE_HZ`] until dropped.
fn publish(bus: &Medium) -> tokio::task::JoinHandle<()> {
    publish_topics(bus, TOPICS)
}

/// Publishes `topics` topics of [`FIELDS`] fields at [`RATE_HZ`] until dropped.
fn publish_topics(bus: &Medium, topics: usize) -> tokio::task::JoinHandle<()> {
    let tx = bus.attach("sensors");
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / RATE_HZ));
        let mut n = 0u64;
        loop {
            tick.tick().await;
            n += 1;
            for t in 0..topics {
                let mut m = DataMap::new();
                for f in 0..FIELDS {
                    m.insert(format!("f{f}"), (n as f64) * 0.001 + f as f64);
                }
                let _ = tx.send(format!("bench.t{t}").as_str(), m).await;
            }
        }
    })
}

/// Runs the clients (in the child process); prints the bytes each received.
async fn clients(mode: &str, addr: &str, cookie: &str, count: usize) {
    let mut tasks = Vec::new();
    for _ in 0..count {
        let (mode, addr, cookie) = (mode.to_string(), addr.to_string(), cookie.to_string());
        tasks.push(tokio::spawn(async move {
            let deadline = Instant::now() + Duration::from_secs(seconds());
            let mut bytes = 0usize;
            if mode == "foxglove" {
                bytes = foxglove_client(&addr, deadline).await;
            } else if mode == "raw" {
                let mut s = TcpStream::connect(&addr).await.expect("raw server");
                let mut buf = vec![0u8; 65536];
                while let Ok(Ok(n)) =
                    tokio::time::timeout_at(deadline.into(), s.read(&mut buf)).await
                {
                    if n == 0 {
                        break;
                    }
                    bytes += n;
                }
            } else {
                use tokio_tungstenite::tungstenite::client::IntoClientRequest;
                let mut req = format!("ws://{addr}/ws")
                    .into_client_request()
                    .expect("request");
                req.headers_mut()
                    .insert("cookie", cookie.parse().expect("cookie header"));
                let tcp = TcpStream::connect(&addr).await.expect("console");
                let (mut ws, _) = tokio_tungstenite::client_async(req, tcp)
                    .await
                    .expect("websocket");
                use futures_util::SinkExt;
                ws.send(tokio_tungstenite::tungstenite::Message::Text(
                    r#"{"type":"open","layout":"bench"}"#.into(),
                ))
                .await
                .expect("open");
                while let Ok(Some(Ok(m))) =
                    tokio::time::timeout_at(deadline.into(), ws.next()).await
                {
                    bytes += m.len();
                }
            }
            bytes
        }));
    }
    for t in tasks {
        println!("{}", t.await.expect("client"));
    }
}

/// A Foxglove WebSocket client subscribing to every channel advertised; the bytes it received
/// until `deadline`.
async fn foxglove_client(addr: &str, deadline: Instant) -> usize {
    use futures_util::SinkExt;
    use tokio_tungstenite::tungstenite::Message as Ws;
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let mut req = format!("ws://{addr}")
        .into_client_request()
        .expect("request");
    req.headers_mut().insert(
        "sec-websocket-protocol",
        "foxglove.sdk.v1".parse().expect("header"),
    );
    let tcp = TcpStream::connect(addr).await.expect("foxglove server");
    let (mut ws, _) = tokio_tungstenite::client_async(req, tcp)
        .await
        .expect("websocket");
    let (mut bytes, mut next_id) = (0usize, 0u32);
    while let Ok(Some(Ok(m))) = tokio::time::timeout_at(deadline.into(), ws.next()).await {
        bytes += m.len();
        let Ws::Text(text) = m else { continue };
        let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) else {
            continue;
        };
        if v["op"] != "advertise" {
            continue;
        }
        let subscriptions: Vec<serde_json::Value> = v["channels"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|c| {
                next_id += 1;
                serde_json::json!({"id": next_id, "channelId": c["id"]})
            })
            .collect();
        let subscribe = serde_json::json!({"op": "subscribe", "subscriptions": subscriptions});
        ws.send(Ws::Text(subscribe.to_string().into()))
            .await
            .expect("subscribe");
    }
    bytes
}

async fn foxglove_run(clients: usize) -> (f64, f64) {
    let dir = tempfile::tempdir().expect("dir");
    let system = dir.path().join("system.xml");
    std::fs::write(
        &system,
        r#"<seabus node="b"><medium name="bus" url="inproc://"/>
  <foxglove medium="bus" listen="127.0.0.1:0"/></seabus>"#,
    )
    .expect("system");
    let spec = SystemSpec::load(&system).expect("system reads");
    let fs = foxglove::specs(&spec).expect("the element reads").remove(0);
    let bus = Medium::in_process("bus", &Node::new("b"));
    let server = foxglove::Foxglove::start(&fs, &bus, seabus_modules::Catalogue::built_in())
        .await
        .expect("the server starts");
    let publisher = publish_topics(&bus, FOXGLOVE_TOPICS);
    let r = measure(
        "foxglove",
        server.addr().to_string(),
        String::new(),
        clients,
    )
    .await;
    publisher.abort();
    r
}

async fn login(addr: std::net::SocketAddr) -> String {
    let body = "name=bench&password=bench-password";
    let mut s = TcpStream::connect(addr).await.expect("console");
    s.write_all(
        format!(
            "POST /login HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
        .as_bytes(),
    )
    .await
    .expect("sent");
    let mut out = String::new();
    s.read_to_string(&mut out).await.expect("answer");
    out.lines()
        .find_map(|l| {
            l.to_lowercase()
                .starts_with("set-cookie: ")
                .then(|| l[12..].to_string())
        })
        .and_then(|c| c.split(';').next().map(str::to_string))
        .expect("a session cookie")
}

/// Runs the clients in a child process while measuring this one; returns (CPU share, bytes/s
/// per client).
async fn measure(mode: &str, addr: String, cookie: String, clients: usize) -> (f64, f64) {
    let exe = std::env::current_exe().expect("this binary");
    let child = tokio::process::Command::new(exe)
        .args(["--clients", mode, &addr, &cookie, &clients.to_string()])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("clients start");
    // the clients connect; measuring starts once they are in
    tokio::time::sleep(Duration::from_millis(500)).await;
    let (cpu0, t0) = (cpu_seconds(), Instant::now());
    let out = child.wait_with_output().await.expect("clients end");
    let (cpu, wall) = (cpu_seconds() - cpu0, t0.elapsed().as_secs_f64());
    let per: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.trim().parse().ok())
        .collect();
    let mean = per.iter().sum::<f64>() / per.len().max(1) as f64 / seconds() as f64;
    (100.0 * cpu / wall, mean)
}

async fn console_run(clients: usize) -> (f64, f64) {
    let dir = tempfile::tempdir().expect("dir");
    std::fs::write(dir.path().join("bench.xml"), layout()).expect("layout");
    std::fs::write(
        dir.path().join("users.xml"),
        Users::with_passwords(&[("bench", &["observer"], "bench-password")])
            .expect("users")
            .to_xml(),
    )
    .expect("users");
    let system = dir.path().join("system.xml");
    std::fs::write(
        &system,
        r#"<seabus node="b"><medium name="bus" url="inproc://"/>
  <console medium="bus" listen="127.0.0.1:0" users="users.xml" layouts="bench.xml"/></seabus>"#,
    )
    .expect("system");
    let spec = SystemSpec::load(&system).expect("system reads");
    let cs = console::specs(&spec).expect("console reads").remove(0);
    let bus = Medium::in_process("bus", &Node::new("b"));
    let users = Users::load(&dir.path().join("users.xml")).expect("users read");
    let console = Console::start(&cs, users, &bus, Vec::new())
        .await
        .expect("console starts");
    let publisher = publish(&bus);
    let cookie = login(console.addr()).await;
    let r = measure("console", console.addr().to_string(), cookie, clients).await;
    publisher.abort();
    r
}

async fn raw_run(clients: usize) -> (f64, f64) {
    let bus = Medium::in_process("bus", &Node::new("b"));
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr");
    let server = tokio::spawn({
        let bus = bus.clone();
        async move {
            loop {
                let Ok((mut sock, _)) = listener.accept().await else {
                    return;
                };
                let mut rx = bus.attach("raw");
                let _ = rx.subscribe("bench.**");
                tokio::spawn(async move {
                    while let Some(m) = rx.recv().await {
                        let Some(map) = m.payload.as_map() else {
                            continue;
                        };
                        let mut line = format!(
                            "{{\"topic\":\"{}\",\"stamp\":{},\"fields\":{}}}\n",
                            m.topic,
                            m.stamp.as_secs_f64(),
                            seabus_medium::json::to_json(map).unwrap_or_default()
                        );
                        if sock.write_all(line.as_bytes()).await.is_err() {
                            return;
                        }
                        line.clear();
                    }
                });
            }
        }
    });
    let publisher = publish(&bus);
    let r = measure("raw", addr.to_string(), String::new(), clients).await;
    publisher.abort();
    server.abort();
    r
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    if let Some(i) = args.iter().position(|a| a == "--clients") {
        let get = |k: usize| args.get(i + k).cloned().unwrap_or_default();
        let count = get(4).parse().expect("a client count");
        rt.block_on(clients(&get(1), &get(2), &get(3), count));
        return;
    }
    if args.iter().any(|a| a == "--bench") || args.len() == 1 {
        let seconds = seconds();
        println!(
            "server CPU (% of a core) and bytes per client, {seconds} s each:\n\
             - console: {} variables ({TOPICS} topics x {FIELDS} fields) at {RATE_HZ} Hz, WebSocket, bound \
             fields, <= 20 frames/s\n\
             - raw floor: every message as a JSON line on TCP\n\
             - Foxglove live view: {FOXGLOVE_TOPICS} topics x {FIELDS} fields at {RATE_HZ} Hz, every \
             message, clients subscribed to every channel",
            TOPICS * FIELDS
        );
        println!(
            "  clients   console CPU  kB/s/client   raw CPU  kB/s/client   console/raw   Foxglove CPU  kB/s/client"
        );
        let mut goals = Goals::new();
        for n in client_counts() {
            let (c_cpu, c_bytes) = rt.block_on(console_run(n));
            let (r_cpu, r_bytes) = rt.block_on(raw_run(n));
            let (f_cpu, f_bytes) = rt.block_on(foxglove_run(n));
            println!(
                "  {n:>7}   {c_cpu:>9.1} %  {:>11.1}   {r_cpu:>5.1} %  {:>11.1}   {:>11.2}   {f_cpu:>10.1} %  {:>11.1}",
                c_bytes / 1e3,
                r_bytes / 1e3,
                c_cpu / r_cpu,
                f_bytes / 1e3
            );
            if n == GOAL_CLIENTS {
                goals.at_most(
                    &format!("console server CPU / raw floor's, {n} clients"),
                    c_cpu / r_cpu,
                    1.5,
                );
            }
        }
        goals.finish();
    }
}
