//! The demo as a vehicle's computer runs it: how long `seabus demo` takes from being started to
//! its first navigation message on the network, and its resident memory and CPU over a long run
//! (it must not grow after the first minute). The network is watched with a plain socket joined to
//! the demo's group, not with seabus.
//!
//! Run: `cargo bench -p seabus --bench startup` (10 minutes; the smoke run takes 40 s)

use seabus_bench::{Goals, scale};
use std::net::{Ipv4Addr, UdpSocket};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The demo's network medium (`net` in configs/demo.xml).
const GROUP: Ipv4Addr = Ipv4Addr::new(239, 255, 42, 1);
const PORT: u16 = 47800;

/// A process's resident memory (bytes) and CPU time (seconds, user + system).
fn sample(pid: u32) -> Option<(u64, f64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .split_whitespace()
        .next()?
        .parse()
        .ok()?;
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // fields after the command's closing parenthesis: utime and stime are the 12th and 13th
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // SAFETY: sysconf only reads a system constant
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Some((kb * 1024, ticks / hz))
}

fn main() {
    let (early, late) = scale((60u64, 600u64), (10, 40));
    // shared with the demo, which binds the same port
    let socket = socket2::Socket::new(
        socket2::Domain::IPV4,
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )
    .expect("a UDP socket");
    socket.set_reuse_address(true).expect("reuse");
    socket
        .bind(&std::net::SocketAddr::from((Ipv4Addr::UNSPECIFIED, PORT)).into())
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
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("seabus demo starts");
    let pid = demo.id();
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
    let at = |secs: u64| {
        let wait = Duration::from_secs(secs).saturating_sub(started.elapsed());
        std::thread::sleep(wait);
        sample(pid).expect("the demo runs")
    };
    let (rss_early, cpu_early) = at(early);
    let (rss_late, cpu_late) = at(late);
    let _ = demo.kill();
    let _ = demo.wait();
    let cpu_share = (cpu_late - cpu_early) / (late - early) as f64;
    println!(
        "  resident memory: {:.1} MB at {early} s, {:.1} MB at {late} s",
        rss_early as f64 / 1e6,
        rss_late as f64 / 1e6
    );
    println!(
        "  CPU from {early} s to {late} s: {:.1} % of one core (the simulated vehicle, its drivers, \
         bridges to UDP and LCM, the console and Foxglove servers with no client)",
        cpu_share * 100.0
    );
    let mut goals = Goals::new();
    goals.at_most(
        &format!("demo resident memory at {late} s / at {early} s"),
        rss_late as f64 / rss_early as f64,
        1.1,
    );
    goals.finish();
}
