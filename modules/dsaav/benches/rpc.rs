//! Reliable DSAAV RPC round trips against a plain socket ping-pong of the same size on the same
//! kind of link, in one run: over UDP (a ttl-0 multicast group, as the medium's backbone; the plain
//! sockets set up as the medium sets its socket up), and over raw Ethernet between two network
//! namespaces joined by a veth
//! pair (made here; needs root and `ip`, else that part says it was skipped, or fails the smoke
//! run when `SEABUS_REQUIRE_PRIVILEGES` is set); then sentuator notifications from one server to
//! four listeners, in-process and over UDP. Goal: a reliable call's p50 at most 1.3× the plain
//! ping-pong's, on each link. Each end of a call, and of a ping-pong, runs on a core of its own, as
//! two computers would (left to the scheduler, the ends share a core in some runs and not in
//! others, and the floor moved between 15 and 75 µs from run to run). Over UDP the bench also
//! prints the ping-pong between two tokio sockets, each on its runtime, the floor of any end a
//! runtime wakes. The smoke run (`SEABUS_BENCH_SMOKE=1`) makes fewer calls.
//!
//! Run: `cargo bench -p seabus-dsaav --bench rpc`

use seabus_bench::{Goals, scale};
use seabus_dsaav::rpc::{self, CallOptions, RpcClient};
use seabus_dsaav::sentuator;
use seabus_medium::{DataMap, Node};
use seabus_medium_dsaav::wire::Address;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

const SERVER: Address = Address { node: 2, port: 1 };

/// A multicast group and port of its own for a run (ttl 0 keeps it on this host).
fn group() -> String {
    format!(
        "239.255.{}.{}:{}",
        fastrand::u8(1..250),
        fastrand::u8(1..250),
        fastrand::u16(20_000..60_000)
    )
}

/// Round trips timed on each side.
fn calls() -> usize {
    scale(5_000, 2_000)
}

fn quantile_us(sorted: &[Duration], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize].as_secs_f64() * 1e6
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
}

/// Moves the calling thread into network namespace `ns` (sockets it makes afterwards live there).
fn enter(ns: &str) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let f = std::fs::File::open(format!("/var/run/netns/{ns}"))?;
    // SAFETY: setns(2) on a namespace file we hold open
    if unsafe { libc::setns(f.as_raw_fd(), libc::CLONE_NEWNET) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// The end of a round trip a thread plays: each end runs on a core of its own, as two computers
/// would, and so do the two ends of the plain ping-pong it is compared with.
#[derive(Clone, Copy)]
enum End {
    Caller,
    Answerer,
}

/// Pins the calling thread (and the threads it starts) to `end`'s core: the first or the second
/// core this process may run on. Left to the scheduler, the two ends sometimes share a core, where
/// a wake-up is cheaper than across cores, and sometimes not: the floor and the call then
/// differ by where the scheduler put them, not by what they do. With one core, nothing is pinned.
fn pin(end: End) {
    // SAFETY: cpu_set_t is plain data; all zeroes is the empty set
    let mut allowed: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: the set is ours and its true size is given
    if unsafe { libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut allowed) }
        != 0
    {
        return;
    }
    let cores: Vec<usize> = (0..libc::CPU_SETSIZE as usize)
        // SAFETY: `i` is below CPU_SETSIZE
        .filter(|&i| unsafe { libc::CPU_ISSET(i, &allowed) })
        .take(2)
        .collect();
    if cores.len() < 2 {
        return;
    }
    let core = cores[match end {
        End::Caller => 0,
        End::Answerer => 1,
    }];
    // SAFETY: as above
    let mut one: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: `core` is below CPU_SETSIZE; the set is ours and its true size is given
    unsafe {
        libc::CPU_SET(core, &mut one);
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &one);
    }
}

/// Round trips of reliable calls from node 1 to a server on node 2, each on its own thread (in
/// its own namespace when given).
fn rpc_round_trips(
    server_url: String,
    client_url: String,
    ns: Option<(String, String)>,
) -> Vec<Duration> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let server_ns = ns.as_ref().map(|n| n.1.clone());
    std::thread::spawn(move || {
        pin(End::Answerer);
        if let Some(ns) = server_ns {
            enter(&ns).expect("enter the server's namespace");
        }
        runtime().block_on(async move {
            let m = seabus_medium_dsaav::schemes()
                .open("dsaav", &server_url, &Node::new("server"))
                .expect("opens");
            let _ = ready_tx.send(());
            rpc::serve(&m, SERVER.port, &[1], |call| Ok(call.params)).await;
        });
    });
    let _ = ready_rx.recv();
    let client_ns = ns.map(|n| n.0);
    std::thread::spawn(move || {
        pin(End::Caller);
        if let Some(ns) = client_ns {
            enter(&ns).expect("enter the client's namespace");
        }
        runtime().block_on(async move {
            let m = seabus_medium_dsaav::schemes()
                .open("dsaav", &client_url, &Node::new("client"))
                .expect("opens");
            let client = RpcClient::new(&m, 9);
            let opts = CallOptions::default();
            let params = DataMap::new().with("depth", 12.5f64).with("count", 1i64);
            // the first calls also teach the raw Ethernet medium the server's hardware address
            for _ in 0..100 {
                let _ = client.call(SERVER, 1, &params, opts).await;
            }
            let mut out = Vec::with_capacity(calls());
            for _ in 0..calls() {
                let t = Instant::now();
                if client.call(SERVER, 1, &params, opts).await.is_ok() {
                    out.push(t.elapsed());
                }
            }
            out.sort();
            out
        })
    })
    .join()
    .expect("client")
}

/// The first byte of a ping-pong's datagram from the caller.
const PING: u8 = 1;
/// The first byte of the answer.
const PONG: u8 = 2;

/// A socket on `group` set up as a medium sets its socket up (ttl 0, non-blocking), and the
/// group's address to send to.
fn group_socket(group: &str) -> (std::net::UdpSocket, std::net::SocketAddr) {
    let mut url = seabus_medium::url::MediumUrl::parse(&format!("udp://{group}?ttl=0"))
        .expect("a group's URL");
    let endpoint = seabus_medium::net::UdpEndpoint::from_url(&mut url).expect("an endpoint");
    let (s, dests) = seabus_medium::net::bind(&endpoint).expect("bind");
    (s, dests[0])
}

/// A plain UDP ping-pong of `size` bytes over a multicast group as the DSAAV medium uses one (ttl
/// 0, two sockets set up as two media's, `seabus_medium::net::bind`), each taking its own copy of
/// what it sends and leaving it: the first byte says who sent.
fn udp_ping_pong(group: &str, size: usize) -> Vec<Duration> {
    let open = || {
        let (s, to) = group_socket(group);
        s.set_nonblocking(false).expect("blocking");
        s.set_read_timeout(Some(Duration::from_secs(1)))
            .expect("timeout");
        (s, to)
    };
    let ((a, to), (b, _)) = (open(), open());
    std::thread::spawn(move || {
        pin(End::Answerer);
        let mut buf = [0u8; 2048];
        while let Ok(n) = b.recv(&mut buf) {
            if n > 0 && buf[0] == PING {
                buf[0] = PONG;
                let _ = b.send_to(&buf[..n], to);
            }
        }
    });
    std::thread::spawn(move || {
        pin(End::Caller);
        let mut msg = vec![0u8; size];
        msg[0] = PING;
        let mut buf = [0u8; 2048];
        let mut out = Vec::with_capacity(calls());
        for _ in 0..calls() {
            let t = Instant::now();
            let _ = a.send_to(&msg, to);
            // the answer, not the copy of what was just sent
            while let Ok(n) = a.recv(&mut buf) {
                if n > 0 && buf[0] == PONG {
                    out.push(t.elapsed());
                    break;
                }
            }
        }
        out.sort();
        out
    })
    .join()
    .expect("pinger")
}

/// [`udp_ping_pong`] with each end a tokio socket on a runtime of its own thread, as each end of
/// a call is: the floor of any end a runtime wakes.
fn udp_ping_pong_async(group: &str, size: usize) -> Vec<Duration> {
    let ((a, to), (b, _)) = (group_socket(group), group_socket(group));
    std::thread::spawn(move || {
        pin(End::Answerer);
        runtime().block_on(async move {
            let b = tokio::net::UdpSocket::from_std(b).expect("registered");
            let mut buf = [0u8; 2048];
            while let Ok(Ok(n)) =
                tokio::time::timeout(Duration::from_secs(1), b.recv(&mut buf)).await
            {
                if n > 0 && buf[0] == PING {
                    buf[0] = PONG;
                    let _ = b.send_to(&buf[..n], to).await;
                }
            }
        });
    });
    std::thread::spawn(move || {
        pin(End::Caller);
        runtime().block_on(async move {
            let a = tokio::net::UdpSocket::from_std(a).expect("registered");
            let mut msg = vec![0u8; size];
            msg[0] = PING;
            let mut buf = [0u8; 2048];
            let mut out = Vec::with_capacity(calls());
            for _ in 0..calls() {
                let t = Instant::now();
                let _ = a.send_to(&msg, to).await;
                // the answer, not the copy of what was just sent
                let deadline = tokio::time::Instant::now() + Duration::from_secs(1);
                while let Ok(Ok(n)) = tokio::time::timeout_at(deadline, a.recv(&mut buf)).await {
                    if n > 0 && buf[0] == PONG {
                        out.push(t.elapsed());
                        break;
                    }
                }
            }
            out.sort();
            out
        })
    })
    .join()
    .expect("pinger")
}

/// A plain raw Ethernet ping-pong between the namespaces (EtherType 0x88B6, broadcast).
fn ethernet_ping_pong(
    ns: &(String, String),
    devs: &(String, String),
    size: usize,
) -> Vec<Duration> {
    use seabus_medium_dsaav::eth::RawSocket;
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let (b_ns, b_dev) = (ns.1.clone(), devs.1.clone());
    std::thread::spawn(move || {
        pin(End::Answerer);
        enter(&b_ns).expect("enter");
        runtime().block_on(async move {
            let s = RawSocket::open(&b_dev, 0x88B6).expect("raw socket");
            let _ = ready_tx.send(());
            let mut buf = vec![0u8; 2048];
            while let Ok(Ok(got)) =
                tokio::time::timeout(Duration::from_secs(1), s.recv(&mut buf)).await
            {
                // the socket also sees the frames it sends itself
                if let Some((_, n)) = got.filter(|(from, _)| *from != s.mac()) {
                    let _ = s.send(None, &buf[..n]).await;
                }
            }
        });
    });
    let _ = ready_rx.recv();
    let (a_ns, a_dev) = (ns.0.clone(), devs.0.clone());
    std::thread::spawn(move || {
        pin(End::Caller);
        enter(&a_ns).expect("enter");
        runtime().block_on(async move {
            let s = RawSocket::open(&a_dev, 0x88B6).expect("raw socket");
            let msg = vec![1u8; size];
            let mut buf = vec![0u8; 2048];
            let mut out = Vec::with_capacity(calls());
            for _ in 0..calls() {
                let t = Instant::now();
                let _ = s.send(None, &msg).await;
                // the answer, not the copy of what was just sent
                let deadline = tokio::time::Instant::now() + Duration::from_secs(1);
                while let Ok(Ok(got)) = tokio::time::timeout_at(deadline, s.recv(&mut buf)).await {
                    if got.is_some_and(|(from, _)| from != s.mac()) {
                        out.push(t.elapsed());
                        break;
                    }
                }
            }
            out.sort();
            out
        })
    })
    .join()
    .expect("pinger")
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).trim().to_string())
    }
}

/// Prints a path's figures and holds its ratio to the goal; `aim` (the reason) when the goal is
/// not yet reached and the ratio is only reported.
fn report(goals: &mut Goals, what: &str, rpc: &[Duration], plain: &[Duration], aim: Option<&str>) {
    println!(
        "  {what}: reliable RPC p50 {:.1} us p99 {:.1} us ({} calls)   plain ping-pong p50 {:.1} us p99 {:.1} us",
        quantile_us(rpc, 0.5),
        quantile_us(rpc, 0.99),
        rpc.len(),
        quantile_us(plain, 0.5),
        quantile_us(plain, 0.99),
    );
    let name = format!("{what}: reliable RPC p50 / ping-pong p50");
    let ratio = quantile_us(rpc, 0.5) / quantile_us(plain, 0.5);
    match aim {
        Some(why) => goals.aim_at_most(&name, ratio, 1.3, why),
        None => goals.at_most(&name, ratio, 1.3),
    };
}

/// Whether `SEABUS_REQUIRE_PRIVILEGES` is set (to anything but empty or `0`), as the tests read
/// it: what needs privileges must then run.
fn privileges_required() -> bool {
    std::env::var_os("SEABUS_REQUIRE_PRIVILEGES").is_some_and(|v| !v.is_empty() && v != "0")
}

struct Gauge(f64);

impl sentuator::Device for Gauge {
    fn get(&mut self) -> DataMap {
        DataMap::new()
            .with("quantity", sentuator::quantity::DEPTH)
            .with("depth", self.0)
    }
}

/// One sentuator server notifying four listeners on `base` (each medium its own node): how many
/// notifications each listener took per second.
fn notifications(base: &str, n: usize) -> (f64, Vec<usize>) {
    let sep = if base.contains('?') { '&' } else { '?' };
    runtime().block_on(async move {
        let counts: Vec<Arc<AtomicUsize>> = (0..4).map(|_| Arc::default()).collect();
        let mut media = Vec::new();
        let mut listeners = Vec::new();
        for (i, count) in counts.iter().enumerate() {
            let node = 10 + i as u16;
            let m = seabus_medium_dsaav::schemes()
                .open("dsaav", &format!("{base}{sep}node={node}"), &Node::new("l"))
                .expect("opens");
            let c = count.clone();
            let lm = m.clone();
            tokio::spawn(async move {
                sentuator::listen(&lm, 0, move |_, _| {
                    c.fetch_add(1, Ordering::Relaxed);
                })
                .await
            });
            media.push(m);
            listeners.push(Address { node, port: 0 });
        }
        let m = seabus_medium_dsaav::schemes()
            .open("dsaav", &format!("{base}{sep}node=1"), &Node::new("s"))
            .expect("opens");
        let server = sentuator::Sentuator::start(&m, 0, 9, Gauge(0.0), &["Depth"], listeners);
        tokio::time::sleep(Duration::from_millis(50)).await;
        let start = Instant::now();
        for i in 0..n {
            server.device().lock().expect("device").0 = i as f64;
            server.notify().await;
            if i % 64 == 0 {
                tokio::task::yield_now().await;
            }
        }
        // let the listeners drain
        let mut last = 0;
        for _ in 0..100 {
            tokio::time::sleep(Duration::from_millis(20)).await;
            let now: usize = counts.iter().map(|c| c.load(Ordering::Relaxed)).sum();
            if now == last {
                break;
            }
            last = now;
        }
        let secs = start.elapsed().as_secs_f64();
        let got: Vec<usize> = counts.iter().map(|c| c.load(Ordering::Relaxed)).collect();
        (n as f64 / secs, got)
    })
}

fn main() {
    println!(
        "DSAAV reliable RPC round trips (two parameters, about 60-byte frames), {} calls each:",
        calls()
    );
    let mut goals = Goals::new();
    let backbone = group();
    let rpc = rpc_round_trips(
        format!("dsaav+udp://{backbone}?ttl=0&node=2"),
        format!("dsaav+udp://{backbone}?ttl=0&node=1"),
        None,
    );
    let runtime_floor = udp_ping_pong_async(&group(), 60);
    report(
        &mut goals,
        "UDP (multicast, ttl 0)",
        &rpc,
        &udp_ping_pong(&group(), 60),
        Some(
            "each end of the call is woken by its runtime, where the plain ping-pong's ends \
             block in the kernel: against the ping-pong of two tokio sockets (the line below) the \
             call is 1.24-1.55",
        ),
    );
    println!(
        "    the same ping-pong between two tokio sockets, each on its runtime: p50 {:.1} us (the RPC {:.2} of it)",
        quantile_us(&runtime_floor, 0.5),
        quantile_us(&rpc, 0.5) / quantile_us(&runtime_floor, 0.5),
    );

    let id = std::process::id() % 100_000;
    let ns = (format!("sbr-a-{id}"), format!("sbr-b-{id}"));
    let devs = (format!("sra{id}"), format!("srb{id}"));
    let made = ip(&["netns", "add", &ns.0])
        .and_then(|()| ip(&["netns", "add", &ns.1]))
        .and_then(|()| {
            ip(&[
                "link", "add", &devs.0, "type", "veth", "peer", "name", &devs.1,
            ])
        })
        .and_then(|()| ip(&["link", "set", &devs.0, "netns", &ns.0]))
        .and_then(|()| ip(&["link", "set", &devs.1, "netns", &ns.1]))
        .and_then(|()| ip(&["-n", &ns.0, "link", "set", &devs.0, "up"]))
        .and_then(|()| ip(&["-n", &ns.1, "link", "set", &devs.1, "up"]));
    match &made {
        Ok(()) => {
            let rpc = rpc_round_trips(
                format!("dsaav+eth://{}?node=2", devs.1),
                format!("dsaav+eth://{}?node=1", devs.0),
                Some(ns.clone()),
            );
            report(
                &mut goals,
                "raw Ethernet between two namespaces (veth)",
                &rpc,
                &ethernet_ping_pong(&ns, &devs, 60),
                None,
            );
        }
        Err(e) => println!("  raw Ethernet: skipped, cannot make network namespaces here ({e})"),
    }
    let _ = ip(&["netns", "del", &ns.0]);
    let _ = ip(&["netns", "del", &ns.1]);
    if let Err(e) = made
        && seabus_bench::smoke()
        && privileges_required()
    {
        eprintln!(
            "smoke run: raw Ethernet needs network namespaces and a veth pair, which could not be \
             made ({e}), and SEABUS_REQUIRE_PRIVILEGES is set"
        );
        std::process::exit(1);
    }

    let n = scale(20_000, 5_000);
    println!("Sentuator notifications, one server to four listeners, {n} readings:");
    for (what, base) in [
        (
            "in-process",
            format!("dsaav+inproc://bench{}", fastrand::u32(..)),
        ),
        (
            "UDP (multicast, ttl 0)",
            format!(
                "dsaav+udp://239.255.{}.{}:{}?ttl=0",
                fastrand::u8(1..250),
                fastrand::u8(1..250),
                fastrand::u16(20_000..60_000)
            ),
        ),
    ] {
        let (rate, got) = notifications(&base, n);
        println!(
            "  {what}: {rate:.0} readings/s sent ({:.0} notifications/s), each listener received {:?} of {n}",
            rate * 4.0,
            got
        );
    }
    goals.finish();
}
