//! What the console's tests share: a console on an in-process bus, with its users, layouts and
//! system file in a directory of its own (and restarted on them), and the requests a browser makes
//! — log-in over HTTP, the WebSocket with the session cookie.

#![allow(dead_code)]

use seabus_medium::{Medium, Node};
use seabus_modules::system::SystemSpec;
use seabus_ui::console::{self, Console};
use seabus_ui::users::{Users, add_user};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;
use tokio_tungstenite::{WebSocketStream, client_async, tungstenite};

pub const PILOT: &str = r#"<layout name="pilot" title="Pilot" roles="pilot">
  <command name="course" topic="cmd.course" fields="heading=0, depth=0, speed=0" rate="5Hz"
           neutral="speed=0" max.speed="3"/>
  <command name="start" topic="cmd.mission" fields="action=start, name=survey" confirm="hold"
           hold="300ms"/>
  <command name="stop" topic="cmd.mission" fields="action=stop" confirm="dialog"/>
  <command name="camera" topic="cmd.camera" fields="on=false" lease="false"/>
  <column>
    <readout bind="nav.depth.depth" unit="m"/>
    <slider command="course.heading" min="0" max="359"/>
    <slider command="course.speed" min="0" max="3"/>
    <button command="start"/>
    <button command="stop"/>
    <toggle command="camera.on"/>
  </column>
</layout>
"#;

pub const WATCH: &str = r#"<layout name="watch" title="Watch" roles="observer pilot">
  <grid columns="1">
    <readout bind="nav.depth.depth" unit="m"/>
  </grid>
</layout>
"#;

/// A console and the directory of its files.
pub struct Setup {
    pub dir: PathBuf,
    pub addr: SocketAddr,
    pub bus: Medium,
    console: Option<Console>,
    // last: the directory goes after the console has stopped
    _dir: tempfile::TempDir,
}

impl Setup {
    /// The running console.
    pub fn console(&self) -> &Console {
        self.console.as_ref().expect("a running console")
    }

    /// Stops the console (it writes its sessions as it stops).
    pub fn stop(&mut self) {
        self.console = None;
    }

    /// Starts the console again on its files as they are now (at another port).
    pub async fn start(&mut self) {
        let console = start(&self.dir, &self.bus).await;
        self.addr = console.addr();
        self.console = Some(console);
    }

    /// Stops the console, then starts it again.
    pub async fn restart(&mut self) {
        self.stop();
        self.start().await;
    }
}

/// A console with users ana (pilot, designer), bo (pilot), ivo (observer) and dee (designer,
/// observer), their passwords `NAME-password` (bo's `bo-password1`), the pilot and watch
/// layouts, and a command log.
pub async fn setup() -> Setup {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_path_buf();
    std::fs::write(d.join("pilot.xml"), PILOT).unwrap();
    std::fs::write(d.join("watch.xml"), WATCH).unwrap();
    let users = d.join("users.xml");
    add_user(
        &users,
        "ana",
        &["pilot".into(), "designer".into()],
        "ana-password",
    )
    .unwrap();
    add_user(&users, "bo", &["pilot".into()], "bo-password1").unwrap();
    add_user(&users, "ivo", &["observer".into()], "ivo-password").unwrap();
    add_user(
        &users,
        "dee",
        &["designer".into(), "observer".into()],
        "dee-password",
    )
    .unwrap();
    std::fs::write(
        d.join("system.xml"),
        r#"<seabus node="t">
  <medium name="bus" url="inproc://"/>
  <console medium="bus" listen="127.0.0.1:0" users="users.xml" layouts="pilot.xml watch.xml"
           ack_timeout="600ms" log="commands.csv"/>
</seabus>"#,
    )
    .unwrap();
    let bus = Medium::in_process("bus", &Node::new("t"));
    let console = start(&d, &bus).await;
    Setup {
        dir: d,
        addr: console.addr(),
        bus,
        console: Some(console),
        _dir: dir,
    }
}

/// Starts the console of `dir`'s system file with its users file as it is now.
async fn start(dir: &Path, bus: &Medium) -> Console {
    let spec = SystemSpec::load(&dir.join("system.xml")).unwrap();
    let cs = console::specs(&spec).unwrap().remove(0);
    let users = Users::load(&dir.join("users.xml")).unwrap();
    Console::start(&cs, users, bus, Vec::new()).await.unwrap()
}

/// A raw HTTP request; returns the status code and the response's head.
pub async fn http(addr: SocketAddr, request: String) -> (u16, String) {
    let mut s = TcpStream::connect(addr).await.unwrap();
    s.write_all(request.as_bytes()).await.unwrap();
    let mut out = Vec::new();
    tokio::time::timeout(Duration::from_secs(10), s.read_to_end(&mut out))
        .await
        .expect("an answer")
        .unwrap();
    let text = String::from_utf8_lossy(&out).into_owned();
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, text)
}

/// Logs in; returns the status and the session cookie, if one was set.
pub async fn login(addr: SocketAddr, name: &str, password: &str) -> (u16, Option<String>, String) {
    let body = format!("name={name}&password={password}");
    let (status, head) = http(
        addr,
        format!(
            "POST /login HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\n\
             Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        ),
    )
    .await;
    let cookie = head
        .lines()
        .find_map(|l| {
            l.strip_prefix("set-cookie: ")
                .or(l.strip_prefix("Set-Cookie: "))
        })
        .and_then(|c| c.split(';').next())
        .filter(|c| c.starts_with("seabus_session=") && c.len() > "seabus_session=".len())
        .map(str::to_string);
    (status, cookie, head)
}

/// `GET path` with `cookie`; returns the status and the response's head.
pub async fn get(addr: SocketAddr, path: &str, cookie: &str) -> (u16, String) {
    http(
        addr,
        format!(
            "GET {path} HTTP/1.1\r\nHost: {addr}\r\nCookie: {cookie}\r\nConnection: close\r\n\r\n"
        ),
    )
    .await
}

pub type Ws = WebSocketStream<TcpStream>;

pub async fn open_ws(addr: SocketAddr, cookie: Option<&str>) -> Result<Ws, tungstenite::Error> {
    let mut req = format!("ws://{addr}/ws").into_client_request().unwrap();
    if let Some(c) = cookie {
        req.headers_mut()
            .insert("cookie", HeaderValue::from_str(c).unwrap());
    }
    let tcp = TcpStream::connect(addr).await.unwrap();
    client_async(req, tcp).await.map(|(ws, _)| ws)
}
