//! Helpers shared by the end-to-end tests: the program, temporary system files, ports.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

pub mod moos;

/// Every medium family's schemes, as the program has them in its default build.
pub fn schemes() -> seabus_medium::Schemes {
    seabus_medium::Schemes::with(&[
        seabus_medium_udp::register,
        seabus_medium_serial::register,
        seabus_medium_can::register,
        seabus_medium_lcm::register,
        seabus_medium_dsaav::register,
        seabus_medium_moos::register,
        seabus_medium_mavlink::register,
    ])
}

/// The `seabus` program under test.
pub fn seabus() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_seabus"));
    c.env_remove("RUST_LOG");
    c
}

/// Writes `text` to `name` in a fresh temporary directory (kept alive by the returned guard).
pub fn system_file(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join(name);
    std::fs::write(&path, text).expect("the system file is written");
    (dir, path)
}

/// Runs `seabus check FILE`.
pub fn check(path: &Path) -> Output {
    seabus()
        .arg("check")
        .arg(path)
        .output()
        .expect("seabus runs")
}

/// A UDP port nobody uses right now.
pub fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("an ephemeral port")
}

/// A TCP port nobody listens on right now.
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("an ephemeral port")
}

/// A multicast group of our own for one test.
pub fn group() -> String {
    format!("239.255.{}.{}", fastrand::u8(1..250), fastrand::u8(1..250))
}

/// A child process killed when dropped, so that a failing test leaves nothing running.
pub struct Running(pub Child);

impl std::ops::Deref for Running {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Running {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// Starts `seabus run FILE` with its output captured; it is killed if the test ends first.
pub fn spawn_run(path: &Path, extra: &[&str]) -> Running {
    Running(
        seabus()
            .arg("run")
            .arg(path)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("seabus run starts"),
    )
}

/// Sends SIGTERM to a child.
pub fn terminate(child: &Child) {
    // SAFETY: kill(2) on our own child's pid
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
}

/// Waits at most `limit` for a child to exit; kills it if it does not.
pub fn wait_for(child: &mut Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}

/// The environment variable that makes a test fail, rather than skip, when the machine does not
/// give it what it needs (network namespaces, veth pairs, raw sockets). `scripts/test` sets it when
/// run as root, and so does CI.
pub const REQUIRE_PRIVILEGES: &str = "SEABUS_REQUIRE_PRIVILEGES";

/// Whether `SEABUS_REQUIRE_PRIVILEGES` is set (to anything but empty or `0`).
pub fn privileges_required() -> bool {
    std::env::var_os(REQUIRE_PRIVILEGES).is_some_and(|v| !v.is_empty() && v != "0")
}

/// The one decision for every test that needs privileges: `need` is what the test needs, or why
/// this machine cannot give it. With `SEABUS_REQUIRE_PRIVILEGES` set, a reason fails `test` with
/// it; without, `test` is skipped: this says so on stderr and returns `None`, and the test returns.
#[track_caller]
pub fn privileged<T>(test: &str, need: Result<T, String>) -> Option<T> {
    match need {
        Ok(v) => Some(v),
        Err(reason) if privileges_required() => {
            panic!("{test}: {reason} ({REQUIRE_PRIVILEGES} is set, so this test must run here)")
        }
        Err(reason) => {
            eprintln!(
                "SKIPPED {test}: {reason} (set {REQUIRE_PRIVILEGES}=1 to make this a failure)"
            );
            None
        }
    }
}

/// Two namespaces joined by a veth pair, removed on drop.
pub struct Hosts {
    /// The first namespace.
    pub a: String,
    /// The second namespace.
    pub b: String,
    /// The veth end in `a`.
    pub dev_a: String,
    /// The veth end in `b`.
    pub dev_b: String,
    /// The hosts are 10.77.SUBNET.1 (in `a`) and .2 (in `b`).
    pub subnet: u8,
}

/// Runs `ip ARGS`.
pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Hosts {
    /// Makes the namespaces and the veth pair; an error says why it cannot (not root, no `ip`).
    pub fn new() -> Result<Hosts, String> {
        let id = std::process::id() % 100_000;
        let subnet = fastrand::u8(1..250);
        let (va, vb) = (format!("sba{id}"), format!("sbb{id}"));
        let hosts = Hosts {
            a: format!("sb-a-{id}"),
            b: format!("sb-b-{id}"),
            dev_a: va.clone(),
            dev_b: vb.clone(),
            subnet,
        };
        ip(&["netns", "add", &hosts.a])?;
        ip(&["netns", "add", &hosts.b])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &hosts.a])?;
        ip(&["link", "set", &vb, "netns", &hosts.b])?;
        for (ns, dev, host) in [(&hosts.a, &va, 1), (&hosts.b, &vb, 2)] {
            let addr = format!("10.77.{subnet}.{host}/24");
            ip(&["-n", ns, "addr", "add", &addr, "brd", "+", "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }
}

impl Hosts {
    /// [`Hosts::new`] for `test`, through [`privileged`]: `None` when the test is skipped.
    #[track_caller]
    pub fn for_test(test: &str) -> Option<Hosts> {
        privileged(
            test,
            Hosts::new()
                .map_err(|e| format!("cannot make network namespaces and a veth pair ({e})")),
        )
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // the veth pair goes with its namespaces; it is still here only when making them stopped
        // before it was moved
        let _ = ip(&["link", "del", &self.dev_a]);
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}

/// Moves the calling thread into network namespace `ns`: sockets it makes afterwards live there.
pub fn enter_namespace(ns: &str) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let f = std::fs::File::open(format!("/var/run/netns/{ns}"))?;
    // SAFETY: setns(2) on a namespace file we hold open
    if unsafe { libc::setns(f.as_raw_fd(), libc::CLONE_NEWNET) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Waits (at most `limit`) until `path` exists, as a pseudo-terminal `seabus run` makes does;
/// whether it does.
pub fn wait_for_path(path: &Path, limit: Duration) -> bool {
    let deadline = Instant::now() + limit;
    while !path.exists() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    path.exists()
}

/// Starts `seabus spy URL --json --for SECS`; its messages arrive on the receiver as JSON values.
pub fn spy_json(url: &str, secs: u32) -> (Running, std::sync::mpsc::Receiver<serde_json::Value>) {
    let mut spy = Running(
        seabus()
            .args(["spy", url, "--json", "--for", &secs.to_string()])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("spy starts"),
    );
    let out = spy.0.stdout.take().expect("spy's output is piped");
    (spy, lines_of(out, |l| serde_json::from_str(&l).ok()))
}

/// The lines a child writes to `out`, each made a `T` by `read` (those it gives `None` left out),
/// on a receiver, read by a thread of their own until the child closes its output.
pub fn lines_of<T: Send + 'static>(
    out: impl std::io::Read + Send + 'static,
    read: impl Fn(String) -> Option<T> + Send + 'static,
) -> std::sync::mpsc::Receiver<T> {
    use std::io::BufRead;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
            if let Some(v) = read(line)
                && tx.send(v).is_err()
            {
                return;
            }
        }
    });
    rx
}

/// Starts `seabus record URL FILE --for SECS`, its standard error captured (the summary).
pub fn spawn_record(url: &str, file: &Path, secs: u32) -> Child {
    seabus()
        .args(["record", url])
        .arg(file)
        .args(["--for", &secs.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("record starts")
}

/// Starts `seabus spy URL ARGS…` (the table, unless ARGS say `--json`), its output captured.
pub fn spawn_spy(url: &str, args: &[&str]) -> Child {
    seabus()
        .arg("spy")
        .arg(url)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spy starts")
}

/// Waits for a spy line that `pred` accepts, at most `limit`; every line read is kept in `seen`.
pub fn wait_for_line(
    rx: &std::sync::mpsc::Receiver<serde_json::Value>,
    seen: &mut Vec<serde_json::Value>,
    limit: Duration,
    what: &str,
    pred: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = Instant::now() + limit;
    while Instant::now() < deadline {
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(100)) {
            seen.push(v.clone());
            if pred(&v) {
                return v;
            }
        }
    }
    panic!("no {what} within {limit:?}");
}

/// Runs `cmd` to its end, `what` naming it; fails the test, with what it wrote to stderr, unless
/// it ran and succeeded.
pub fn succeeds(cmd: &mut Command, what: &str) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what} does not run: {e}"));
    assert!(
        out.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs a Python script with arguments and environment; fails the test when it fails.
pub fn python(script: &str, args: &[&str], env: &[(&str, &str)]) -> String {
    let out = succeeds(
        Command::new("python3")
            .arg("-c")
            .arg(script)
            .args(args)
            .envs(env.iter().copied()),
        "python3",
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Sends SIGINT to a child (as Ctrl-C would).
pub fn interrupt(child: &Child) {
    // SAFETY: kill(2) on our own child's pid
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
}

/// Waits at most 10 s for a child's exit and output.
pub fn finish(mut child: Child) -> Output {
    let status = wait_for(&mut child, Duration::from_secs(10));
    let out = child.wait_with_output().expect("the output of a child");
    assert!(status.is_some(), "the child did not exit within 10 s");
    out
}

/// What a child wrote on its standard error.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A Python peer of the tests (a script in `tests/peers`) that reports on stdout, one JSON object
/// a line with its `event`, and takes orders on stdin, one a line; it is told `quit`, then killed,
/// when dropped.
pub struct PythonPeer {
    child: Running,
    script: String,
    events: std::sync::mpsc::Receiver<serde_json::Value>,
    /// Everything it reported so far.
    pub seen: Vec<serde_json::Value>,
}

impl PythonPeer {
    /// Starts `python3 tests/peers/SCRIPT ARGS` and waits (at most 10 s) for its `ready`.
    pub fn start(script: &str, args: &[&str]) -> PythonPeer {
        use std::io::BufRead;
        let path = format!("{}/tests/peers/{script}", env!("CARGO_MANIFEST_DIR"));
        let mut child = Running(
            Command::new("python3")
                .arg(&path)
                .args(args)
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .spawn()
                .expect("python3 runs"),
        );
        let out = child.0.stdout.take().expect("its output is piped");
        let (tx, events) = std::sync::mpsc::channel();
        let who = script.to_string();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
                let v: serde_json::Value = serde_json::from_str(&line)
                    .unwrap_or_else(|e| panic!("{who} reports JSON, not {line:?}: {e}"));
                if tx.send(v).is_err() {
                    return;
                }
            }
        });
        let mut peer = PythonPeer {
            child,
            script: script.to_string(),
            events,
            seen: Vec::new(),
        };
        peer.wait("ready", Duration::from_secs(10), |_| true);
        peer
    }

    /// Starts a pymavlink vehicle (`mavlink_vehicle.py`, `mavlink_ardusub.py`) on UDP port `port`
    /// of loopback, sending to 127.0.0.1:`to` as well, for at most `secs`.
    pub fn mavlink(script: &str, port: u16, to: u16, secs: u32) -> PythonPeer {
        let (port, secs, to) = (
            port.to_string(),
            secs.to_string(),
            format!("127.0.0.1:{to}"),
        );
        PythonPeer::start(script, &[&port, &secs, "--to", &to])
    }

    /// Waits at most `limit` for an event `event` that `pred` accepts (seen before or coming).
    pub fn wait(
        &mut self,
        event: &str,
        limit: Duration,
        pred: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        if let Some(v) = self.seen.iter().find(|v| v["event"] == event && pred(v)) {
            return v.clone();
        }
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Ok(v) = self.events.recv_timeout(Duration::from_millis(50)) {
                self.seen.push(v.clone());
                if v["event"] == event && pred(&v) {
                    return v;
                }
            }
        }
        panic!(
            "{} reported no such {event} within {limit:?}; it reported {:?}",
            self.script, self.seen
        );
    }

    /// Keeps everything it reports for `limit`.
    pub fn drain(&mut self, limit: Duration) {
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Ok(v) = self.events.recv_timeout(Duration::from_millis(50)) {
                self.seen.push(v);
            }
        }
    }

    /// Every event `event` it reported so far.
    pub fn all(&self, event: &str) -> Vec<serde_json::Value> {
        self.seen
            .iter()
            .filter(|v| v["event"] == event)
            .cloned()
            .collect()
    }

    /// Gives it the order `what`.
    pub fn order(&mut self, what: &str) {
        use std::io::Write;
        let stdin = self.child.0.stdin.as_mut().expect("its input is piped");
        writeln!(stdin, "{what}").expect("it takes orders");
        stdin.flush().expect("it takes orders");
    }
}

impl Drop for PythonPeer {
    fn drop(&mut self) {
        if let Some(stdin) = self.child.0.stdin.as_mut() {
            use std::io::Write;
            let _ = writeln!(stdin, "quit");
        }
    }
}

/// Adds a user with `seabus user add`, the password on stdin.
pub fn add_user(users: &Path, name: &str, roles: &str, password: &str) {
    let mut child = seabus()
        .args(["user", "add"])
        .arg(users)
        .args([name, "--roles", roles])
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("seabus user add runs");
    std::io::Write::write_all(
        &mut child.stdin.take().expect("stdin"),
        format!("{password}\n").as_bytes(),
    )
    .expect("password written");
    let out = child.wait_with_output().expect("it ends");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The C LCM peer (`tests/peers/lcm_peer.c`), built in `dir` with the C types lcm-gen makes of
/// `tests/peers/lcm_peer.lcm` and liblcm (Debian's `liblcm-dev` and `liblcm-bin`, which
/// `./scripts/test` installs); `dir` also gets a copy of the `.lcm` file, for seabus to read.
pub fn lcm_c_peer(dir: &Path) -> PathBuf {
    let peers = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers");
    for file in ["lcm_peer.c", "lcm_peer.lcm"] {
        std::fs::copy(peers.join(file), dir.join(file)).expect("the peer's files are copied");
    }
    let run = |program: &str, args: &[&str]| {
        succeeds(
            Command::new(program).args(args).current_dir(dir),
            &format!("{program} {args:?} (./scripts/test installs liblcm-bin and liblcm-dev)"),
        );
    };
    // lcm-gen of the same release as the C library
    run("/usr/bin/lcm-gen", &["-c", "lcm_peer.lcm"]);
    run(
        "cc",
        &[
            "-Wall",
            "-Werror",
            "-o",
            "lcm_peer",
            "lcm_peer.c",
            "peer_reading_t.c",
            "peer_survey_t.c",
            "-I.",
            "-llcm",
        ],
    );
    dir.join("lcm_peer")
}

/// Starts the C LCM peer receiving `n` messages of `what` (`readings`, `surveys`) on `channel`
/// of `url` for at most `secs` s; returns once it has subscribed, with its lines to come.
pub fn lcm_c_receiver(
    peer: &Path,
    what: &str,
    url: &str,
    channel: &str,
    n: usize,
    secs: u32,
) -> (Running, std::sync::mpsc::Receiver<String>) {
    use std::io::BufRead;
    let mut child = Command::new(peer)
        .args([
            &format!("recv-{what}"),
            url,
            channel,
            &n.to_string(),
            &secs.to_string(),
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("the C LCM peer starts");
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let ready = rx.recv_timeout(Duration::from_secs(10));
    assert_eq!(ready.as_deref(), Ok("ready"), "the C LCM peer subscribes");
    (Running(child), rx)
}

/// The lines a C LCM peer printed until it ended (at most `limit` away).
pub fn lcm_c_lines(
    mut peer: Running,
    lines: std::sync::mpsc::Receiver<String>,
    limit: Duration,
) -> Vec<String> {
    let status = wait_for(&mut peer, limit);
    // the peer has ended: its output ends too
    let got: Vec<String> = lines.iter().collect();
    assert!(
        status.is_some_and(|s| s.success()),
        "the C LCM peer received what it waited for ({status:?}): {got:?}"
    );
    got
}

/// Waits at most `limit` for a `seabus run` to end (killed if it does not); its exit status
/// (`None` when it was killed) and all it wrote to stderr.
pub fn ended(mut run: Running, limit: Duration) -> (Option<std::process::ExitStatus>, String) {
    use std::io::Read;
    let status = wait_for(&mut run, limit);
    let mut stderr = String::new();
    if let Some(mut err) = run.stderr.take() {
        let _ = err.read_to_string(&mut stderr);
    }
    (status, stderr)
}

/// Reads a running system's stderr up to its console's address: the one-time password it printed
/// for user `name` and the console's URL (`http://ADDR`). The rest of stderr is drained.
pub fn one_time_password(run: &mut Running, name: &str) -> (String, String) {
    use std::io::BufRead;
    let err = run.0.stderr.take().expect("stderr piped");
    let mut lines = std::io::BufReader::new(err).lines();
    let mut password = None;
    let mut url = None;
    for line in lines.by_ref().take(200).map_while(Result::ok) {
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.first() == Some(&name) && words.len() >= 3 {
            password = Some(words[1].to_string());
        }
        if let Some(u) = line.trim().strip_prefix("Console: ") {
            url = Some(u.to_string());
            break;
        }
    }
    std::thread::spawn(move || for _ in lines {});
    (
        password.unwrap_or_else(|| panic!("no password printed for {name}")),
        url.expect("the console's address is printed"),
    )
}

/// Logs in to the console at `url` (`http://ADDR`) as a browser's form does; fails unless the
/// console answers with a session.
pub fn assert_logs_in(url: &str, name: &str, password: &str) {
    let answer = http_login(url, name, password);
    assert!(
        answer
            .to_lowercase()
            .contains("set-cookie: seabus_session="),
        "{name} does not log in: {answer}"
    );
}

/// Logs in to the console at `url` (`http://ADDR`) as a browser's form does; the whole answer.
pub fn http_login(url: &str, name: &str, password: &str) -> String {
    use std::io::Write;
    let addr = url.trim_start_matches("http://");
    let body = format!("name={name}&password={password}");
    let mut s = std::net::TcpStream::connect(addr).expect("the console listens");
    s.set_read_timeout(Some(Duration::from_secs(30)))
        .expect("a timeout");
    write!(
        s,
        "POST /login HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .expect("sent");
    let mut answer = String::new();
    std::io::Read::read_to_string(&mut s, &mut answer).expect("answer");
    answer
}

/// The paths `scripts/peers NAME` prints for `vars` (the environment's, when it names them all, as
/// `./scripts/test` sets them), building the peer once when it has not been built.
pub fn peer_paths(name: &str, vars: &[&str]) -> Vec<PathBuf> {
    let set: Vec<Option<std::ffi::OsString>> = vars.iter().map(std::env::var_os).collect();
    if set.iter().all(Option::is_some) {
        return set.into_iter().flatten().map(PathBuf::from).collect();
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = succeeds(
        Command::new(root.join("scripts/peers")).arg(name),
        &format!("scripts/peers {name} (builds it from the shared peers' archive)"),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    vars.iter()
        .map(|var| {
            text.lines()
                .find_map(|l| l.strip_prefix(&format!("{var}=")))
                .map(PathBuf::from)
                .unwrap_or_else(|| panic!("scripts/peers {name} printed no {var}: {text}"))
        })
        .collect()
}
