//! The demo as a vehicle's computer runs it: how long `seabus demo` takes from being started to
//! its first navigation message on the network, then its resident memory and CPU idle (no
//! console client), after ten console log-ins, after a thousand console connections, and at the
//! end of a long run (it must not grow once the first minute is over). The network is watched
//! with a plain socket joined to the demo's group, the console driven over plain HTTP and
//! WebSocket handshakes written here: nothing of seabus measures seabus.
//!
//! Run: `cargo bench -p seabus --bench footprint` (10 minutes; the smoke run takes about a minute)

use seabus_bench::{Goals, scale};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpStream, UdpSocket};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The demo's network medium (`net` in configs/demo.xml).
const GROUP: Ipv4Addr = Ipv4Addr::new(239, 255, 42, 1);
const PORT: u16 = 47800;
/// Longer than the running system's interval between giving free memory back (10 s).
const SETTLE: Duration = Duration::from_secs(11);

/// A field of a process's `/proc/PID/status` given in kB, as bytes.
fn status_bytes(pid: u32, field: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix(field)?.strip_prefix(':'))?
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// A process's resident memory (bytes) and CPU time (seconds, user + system).
fn sample(pid: u32) -> Option<(u64, f64)> {
    let rss = status_bytes(pid, "VmRSS")?;
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // fields after the command's closing parenthesis: utime and stime are the 12th and 13th
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // SAFETY: sysconf only reads a system constant
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Some((rss, ticks / hz))
}

/// One HTTP exchange on a fresh connection: the response's head (status line and headers).
fn http(addr: SocketAddr, request: &str) -> String {
    let mut s = TcpStream::connect(addr).expect("the console accepts");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("a timeout");
    s.write_all(request.as_bytes()).expect("request sent");
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        match s.read(&mut byte) {
            Ok(1) => head.push(byte[0]),
            _ => break,
        }
    }
    String::from_utf8_lossy(&head).into_owned()
}

/// Logs in as `name`; the session cookie (`seabus_session=…`).
fn log_in(addr: SocketAddr, name: &str, password: &str) -> String {
    let body = format!("name={name}&password={password}");
    let head = http(
        addr,
        &format!(
            "POST /login HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\n\
             Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        ),
    );
    head.lines()
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.eq_ignore_ascii_case("set-cookie").then(|| v.trim())
        })
        .and_then(|c| c.split(';').next())
        .filter(|c| c.starts_with("seabus_session="))
        .unwrap_or_else(|| panic!("{name} logs in: {head}"))
        .to_string()
}

/// Opens the console's WebSocket with `cookie` and closes it again (a client's close frame).
fn connect_once(addr: SocketAddr, cookie: &str) {
    let mut s = TcpStream::connect(addr).expect("the console accepts");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("a timeout");
    write!(
        s,
        "GET /ws HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
         Cookie: {cookie}\r\n\r\n"
    )
    .expect("handshake sent");
    let mut status = String::new();
    BufReader::new(&s)
        .read_line(&mut status)
        .expect("handshake answered");
    assert!(status.starts_with("HTTP/1.1 101"), "{status}");
    // a masked close frame with no body; then whatever the server still sends, until it closes
    s.write_all(&[0x88, 0x80, 1, 2, 3, 4]).expect("close sent");
    let mut rest = [0u8; 4096];
    while matches!(s.read(&mut rest), Ok(n) if n > 0) {}
}

fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

fn main() {
    let (early, late) = scale((60u64, 600u64), (10, 45));
    let connections = scale(1000, 200);
    // shared with the demo, which binds the same port
    let socket = socket2::Socket::new(
        socket2::Domain::IPV4,
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )
    .expect("a UDP socket");
    socket.set_reuse_address(true).expect("reuse");
    socket
        .bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, PORT)).into())
        .expect("the demo's port");
    let socket: UdpSocket = socket.into();
    socket
        .join_multicast_v4(&GROUP, &Ipv4Addr::UNSPECIFIED)
        .expect("the demo's group");
    socket
        .set_read_timeout(Some(Duration::from_millis(100)))
        .expect("a timeout");
    let started = Instant::now();
    let mut demo = Command::new(env!("CARGO_BIN_EXE_seabus"))
        .args(["demo", "--for", &(late + 5).to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("seabus demo starts");
    let pid = demo.id();
    // the users it prints (name, password) and the console's address
    let (said, heard) = mpsc::channel();
    for out in [
        Box::new(demo.stdout.take().unwrap()) as Box<dyn Read + Send>,
        Box::new(demo.stderr.take().unwrap()),
    ] {
        let said = said.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                let _ = said.send(line);
            }
        });
    }
    let mut buf = [0u8; 65536];
    let first = loop {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "no navigation message from the demo within 30 s"
        );
        if let Ok(n) = socket.recv(&mut buf)
            && buf[..n].windows(4).any(|w| w == b"nav.")
        {
            break started.elapsed();
        }
    };
    drop(socket);
    println!(
        "seabus demo: first navigation message on the network {:.0} ms after start",
        first.as_secs_f64() * 1e3
    );
    let mut pilot = None;
    let mut console = None;
    while pilot.is_none() || console.is_none() {
        let line = heard
            .recv_timeout(Duration::from_secs(20))
            .expect("the demo prints its console and users");
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["pilot", password, ..] => pilot = Some(password.to_string()),
            ["Console:", url] => {
                console = Some(
                    url.trim_start_matches("http://")
                        .parse::<SocketAddr>()
                        .expect("the console's address"),
                )
            }
            _ => {}
        }
    }
    let (pilot, console) = (pilot.unwrap(), console.unwrap());
    let at = |secs: u64| {
        std::thread::sleep(Duration::from_secs(secs).saturating_sub(started.elapsed()));
        sample(pid).expect("the demo runs")
    };
    let (_, cpu_idle_from) = at(early / 2);
    let (idle_end, cpu_idle_to) = at(early);
    // what the program holds itself, and the pages of its code and libraries it has run
    let own = status_bytes(pid, "RssAnon").expect("the demo runs");
    let code = status_bytes(pid, "RssFile").expect("the demo runs");
    let idle_cpu = (cpu_idle_to - cpu_idle_from) / (early - early / 2) as f64;
    let mut cookie = String::new();
    for _ in 0..10 {
        cookie = log_in(console, "pilot", &pilot);
    }
    std::thread::sleep(SETTLE);
    let (logged_in, _) = sample(pid).expect("the demo runs");
    for _ in 0..connections {
        connect_once(console, &cookie);
    }
    std::thread::sleep(SETTLE);
    let (connected, cpu_connected) = sample(pid).expect("the demo runs");
    let after = started.elapsed().as_secs();
    let (end, cpu_end) = at(late.max(after + 10));
    let _ = demo.kill();
    let _ = demo.wait();
    let long_cpu = (cpu_end - cpu_connected) / (late.max(after + 10) - after) as f64;
    println!(
        "  resident memory: {:.1} MB idle at {early} s, {:.1} MB after 10 log-ins, {:.1} MB after \
         {connections} console connections, {:.1} MB at {} s",
        mb(idle_end),
        mb(logged_in),
        mb(connected),
        mb(end),
        late.max(after + 10)
    );
    println!(
        "  idle at {early} s: {:.1} MB the program's own memory, {:.1} MB pages of its code and \
         libraries",
        mb(own),
        mb(code)
    );
    println!(
        "  CPU: {:.1} % of one core idle, {:.1} % over the rest of the run (the simulated vehicle, \
         its drivers, bridges to UDP and LCM, the console and Foxglove servers)",
        idle_cpu * 100.0,
        long_cpu * 100.0
    );
    let mut goals = Goals::new();
    goals.at_most("demo resident memory idle, MB", mb(idle_end), 16.0);
    goals.at_most(
        "demo resident memory after 10 log-ins, MB",
        mb(logged_in),
        24.0,
    );
    goals.at_most(
        &format!("demo resident memory at the end / after {connections} connections"),
        end as f64 / connected as f64,
        1.1,
    );
    goals.finish();
}
