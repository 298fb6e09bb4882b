//! What the browser tests of the console share: a system with a console, chromedriver and a
//! headless Chromium logged in, and waiting for what the page or the bus shows.
#![allow(dead_code)]

use crate::common::{self, Running, add_user, group, seabus, spy_json, wait_for_line};
use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{Value as Json, json};
use std::io::BufRead;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::mpsc;
use std::time::{Duration, Instant};

pub const CHROMIUM: &str = "/usr/bin/chromium";
pub const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

/// A running system with a console, and the directory of its files.
pub struct System {
    pub _dir: tempfile::TempDir,
    pub dir: PathBuf,
    pub _run: Running,
    pub url: String,
    /// The loopback network the system's commands go out on (and `test.**` comes in on, when a
    /// test's modules bridge it in).
    pub net: String,
    /// The bus as `seabus spy` shows it (commands and statuses).
    pub spy: mpsc::Receiver<Json>,
    pub _spy: Running,
}

/// The repository's file `rel`, as an absolute path.
pub fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The simulated Iver2 frontseat and its driver, the GPS and compass drivers and the health
/// monitor; `{d}` is the system's directory, `{rules}` the health rules.
pub const IVER: &str = r#"
  <medium name="frontseat" url="pty://{d}/frontseat?framing=lines"/>
  <medium name="serial" url="serial://{d}/frontseat?baud=19200&amp;framing=nmea"/>
  <medium name="sensors-out" url="pty://{d}/sensors"/>
  <medium name="sensors" url="serial://{d}/sensors?baud=4800&amp;framing=nmea"/>
  <module name="frontseat-sim" type="iver2-sim" media="frontseat sensors-out"
          lat="43.5081" lon="16.4402" heading="0" autostart="true" noise="0.2"/>
  <module name="iver" type="iver2" media="serial bus" version="5" request_every="250ms"/>
  <module name="gps" type="nmea-gps" media="sensors bus"/>
  <module name="compass" type="nmea-heading" media="sensors bus"/>
  <module name="health" type="health-monitor" media="bus serial sensors" rules="{rules}"/>
"#;

/// Starts the Iver2 system with `layouts` (paths) and waits for its console's address.
pub fn start(layouts: &[PathBuf]) -> System {
    start_with(IVER, layouts)
}

/// Starts a system of `modules` (media and modules besides the bus) with a console showing
/// `layouts`, and waits for its console's address.
pub fn start_with(modules: &str, layouts: &[PathBuf]) -> System {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let d = dir.path().to_path_buf();
    let users = d.join("users.xml");
    add_user(&users, "pilot", "pilot designer", "pilot-password");
    add_user(&users, "copilot", "pilot", "copilot-password");
    add_user(&users, "ivo", "observer", "observer-password");
    let group = group();
    let port = common::free_port();
    let net = format!("udp://{group}:{port}?ttl=0");
    let layouts: Vec<String> = layouts.iter().map(|p| p.display().to_string()).collect();
    let modules = modules.replace("{d}", &d.display().to_string()).replace(
        "{rules}",
        &repo("configs/demo-health.xml").display().to_string(),
    );
    let text = format!(
        r#"<seabus node="console-test">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="{net}"/>
{modules}
  <bridge name="watch" media="bus net">
    <route from="bus" to="net" topics="cmd.**"/>
  </bridge>
  <console medium="bus" listen="127.0.0.1:0" users="users.xml" layouts="{layouts}"
           log="commands.csv"/>
</seabus>"#,
        layouts = layouts.join(" "),
    );
    let path = d.join("system.xml");
    std::fs::write(&path, text).expect("system written");
    let (spy_run, spy) = spy_json(&net, 120);
    let (run, url) = run_console(&path);
    System {
        _dir: dir,
        dir: d,
        _run: run,
        url,
        net,
        spy,
        _spy: spy_run,
    }
}

/// Starts `seabus run` of the system file `path`, whose console says where it listens: the
/// running system and the console's address.
pub fn run_console(path: &Path) -> (Running, String) {
    let mut run = Running(
        seabus()
            .arg("run")
            .arg(path)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("seabus run starts"),
    );
    let (tx, rx) = mpsc::channel();
    let err = run.0.stderr.take().expect("stderr piped");
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
            if let Some(url) = line.trim().strip_prefix("Console: ") {
                let _ = tx.send(url.to_string());
            }
        }
    });
    let url = rx
        .recv_timeout(Duration::from_secs(30))
        .expect("the console starts and says where");
    (run, url)
}

/// chromedriver, stopped when dropped.
pub struct Driver {
    pub _child: Running,
    pub url: String,
    /// chromedriver's process group: the browsers it starts are in it, and go with it.
    pub group: u32,
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = std::process::Command::new("kill")
            .args(["-KILL", "--", &format!("-{}", self.group)])
            .stderr(Stdio::null())
            .status();
    }
}

pub fn chromedriver() -> Driver {
    assert!(
        Path::new(CHROMEDRIVER).exists() && Path::new(CHROMIUM).exists(),
        "the console tests need Debian's chromium and chromium-driver (scripts/test installs them)"
    );
    // (a port taken meanwhile by another test makes chromedriver exit: it is started again on
    // another; on a loaded machine it may take long to listen)
    for _ in 0..3 {
        // a TCP port: one free for UDP may be another program's TCP listener, which would be
        // taken for chromedriver
        let port = common::free_tcp_port();
        let mut child = Running(
            std::process::Command::new(CHROMEDRIVER)
                .arg(format!("--port={port}"))
                .process_group(0)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("chromedriver starts"),
        );
        let group = child.0.id();
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
                return Driver {
                    _child: child,
                    url: format!("http://127.0.0.1:{port}"),
                    group,
                };
            }
            let exited = child.0.try_wait().ok().flatten().is_some();
            assert!(Instant::now() < deadline, "chromedriver does not listen");
            if exited {
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    panic!("chromedriver exited three times without listening")
}

/// A headless Chromium with a 1400×1000 window.
pub async fn browser(driver: &Driver) -> Client {
    browser_sized(driver, 1400, 1000).await
}

/// A headless Chromium whose window is `width`×`height`.
pub async fn browser_sized(driver: &Driver, width: u32, height: u32) -> Client {
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": CHROMIUM,
            "args": ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     format!("--window-size={width},{height}")],
        }),
    );
    ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&driver.url)
        .await
        .expect("a browser session")
}

pub async fn log_in(c: &Client, base: &str, name: &str, password: &str) {
    c.goto(&format!("{base}/login")).await.expect("login page");
    c.find(Locator::Css("input[name=name]"))
        .await
        .expect("name field")
        .send_keys(name)
        .await
        .expect("typed");
    c.find(Locator::Css("input[name=password]"))
        .await
        .expect("password field")
        .send_keys(password)
        .await
        .expect("typed");
    c.find(Locator::Css("[data-testid=login-submit]"))
        .await
        .expect("submit")
        .click()
        .await
        .expect("clicked");
}

/// Runs `script` in the page and returns its value.
pub async fn js(c: &Client, script: &str) -> Json {
    c.execute(script, vec![]).await.expect("script runs")
}

/// Waits (at most `limit`) until `script` returns something truthy; returns it.
pub async fn until(c: &Client, limit: Duration, what: &str, script: &str) -> Json {
    let deadline = Instant::now() + limit;
    loop {
        let v = js(c, script).await;
        let truthy =
            !matches!(v, Json::Null | Json::Bool(false)) && v != json!(0) && v != json!("");
        if truthy {
            return v;
        }
        if Instant::now() >= deadline {
            let blocked = js(
                c,
                "return window.seabusConsole ? window.seabusConsole.policyViolations() : [location.href, document.body.className, document.title];",
            )
            .await;
            panic!(
                "{what}: not within {limit:?} (last: {v}; blocked by the content policy: {blocked})"
            );
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Waits (at most `limit`) until `script` returns `expected`; fails with the last value otherwise.
pub async fn until_eq(c: &Client, limit: Duration, what: &str, script: &str, expected: Json) {
    let deadline = Instant::now() + limit;
    loop {
        let v = js(c, script).await;
        if v == expected {
            return;
        }
        if Instant::now() >= deadline {
            assert_eq!(v, expected, "{what}: not within {limit:?}");
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Waits like [`until`] for `script` to return text; returns the text.
pub async fn until_text(c: &Client, limit: Duration, what: &str, script: &str) -> String {
    until(c, limit, what, script)
        .await
        .as_str()
        .unwrap_or_default()
        .to_string()
}

pub async fn screenshot(c: &Client, name: &str) {
    let png = c.screenshot().await.expect("a screenshot");
    let dir = repo("target/console-screenshots");
    std::fs::create_dir_all(&dir).expect("screenshot directory");
    std::fs::write(dir.join(name), png).expect("screenshot written");
}

pub const STATE: &str = "return window.seabusConsole && window.seabusConsole.state();";

/// The text of the widget with `id`.
pub fn widget_text(id: &str) -> String {
    format!(
        "const w = document.querySelector('[data-widget-id=\"{id}\"]'); return w ? w.innerText : null;"
    )
}

/// The commands `seabus spy` saw within `limit` on `topic`.
pub fn commands_on(spy: &mpsc::Receiver<Json>, topic: &str, limit: Duration) -> Vec<Json> {
    let deadline = Instant::now() + limit;
    let mut out = Vec::new();
    while Instant::now() < deadline {
        if let Ok(v) = spy.recv_timeout(Duration::from_millis(50))
            && v["topic"] == topic
        {
            out.push(v);
        }
    }
    out
}

/// Takes control from the header.
pub async fn take_control(c: &Client, user: &str) {
    until(
        c,
        Duration::from_secs(10),
        "the take-control button",
        "const b = document.querySelector('[data-testid=take-control]'); return b && !b.hidden && !b.disabled;",
    )
    .await;
    c.find(Locator::Css("[data-testid=take-control]"))
        .await
        .expect("take button")
        .click()
        .await
        .expect("clicked");
    // the page says what taking control keeps, and takes it once confirmed
    confirm_take(c).await;
    until(
        c,
        Duration::from_secs(5),
        "control",
        &format!(
            "const s = window.seabusConsole.state(); return s.lease === '{user}' && s.inControl;"
        ),
    )
    .await;
}

/// Confirms the open take-control dialog; what it said (title, text, kept values).
pub async fn confirm_take(c: &Client) -> Json {
    until(
        c,
        Duration::from_secs(5),
        "the take-control dialog",
        "const d = document.querySelector('[data-testid=confirm-dialog]');
         return d.open && /^Take control/.test(d.querySelector('h2').textContent);",
    )
    .await;
    let said = js(
        c,
        "const d = document.querySelector('[data-testid=confirm-dialog]');
         return {title: d.querySelector('h2').textContent,
                 text: document.getElementById('confirm-text').textContent,
                 fields: document.getElementById('confirm-fields').textContent};",
    )
    .await;
    c.find(Locator::Css("[data-testid=confirm-ok]"))
        .await
        .expect("the dialog's take button")
        .click()
        .await
        .expect("clicked");
    said
}

/// Sets a slider to `value` and lets go of it, as a user dragging it does.
pub async fn slide(c: &Client, id: &str, value: f64) {
    js(
        c,
        &format!(
            "const r = document.querySelector('[data-widget-id=\"{id}\"] input[type=range]');
             r.value = '{value}';
             r.dispatchEvent(new Event('input', {{bubbles: true}}));
             r.dispatchEvent(new Event('change', {{bubbles: true}}));
             return true;"
        ),
    )
    .await;
}

/// Waits for the frontseat to take backseat commands (the log shows its control).
pub async fn frontseat_accepting(c: &Client) {
    until(
        c,
        Duration::from_secs(20),
        "a frontseat that takes commands",
        "const l = document.querySelector('[data-kind=log]'); return l && /control=(accepting|in-control)/.test(l.innerText);",
    )
    .await;
}

/// A browser logged in as the pilot, with control, once the frontseat takes commands.
pub async fn pilot_in_control(sys: &System) -> (Driver, Client) {
    let driver = chromedriver();
    let c = browser(&driver).await;
    log_in(&c, &sys.url, "pilot", "pilot-password").await;
    take_control(&c, "pilot").await;
    frontseat_accepting(&c).await;
    (driver, c)
}

/// The next course the spy sees with `pred`, and the frontseat's settled answer to it.
pub fn course_and_answer(
    spy: &mpsc::Receiver<Json>,
    what: &str,
    pred: impl Fn(&Json) -> bool,
) -> (Json, Json) {
    let mut seen = Vec::new();
    let course = wait_for_line(spy, &mut seen, Duration::from_secs(10), what, |v| {
        v["topic"] == "cmd.course" && pred(&v["payload"])
    });
    let answer = wait_for_line(
        spy,
        &mut seen,
        Duration::from_secs(10),
        "the frontseat's answer",
        |v| {
            v["topic"] == "cmd.status"
                && v["payload"]["request_seq"] == course["seq"]
                && v["payload"]["state"] != "pending"
        },
    );
    (course, answer)
}

/// The vehicle's control (`vehicle.state.control`) as the page has it.
pub const CONTROL: &str =
    "const s = window.seabusConsole.topic('vehicle.state'); return s && s.fields.control;";

pub async fn no_policy_violations(c: &Client) {
    assert_eq!(
        js(c, "return window.seabusConsole.policyViolations();").await,
        json!([]),
        "the content policy blocked part of the page"
    );
}
