//! liblcm (the C library, through the `lcm` crate) and seabus's LCM medium side by side, on
//! loopback multicast with ttl 0, in the same run: one sender and one receiver each.
//!
//! - 64-byte messages unpaced: delivered rate and loss; senders' rates, with a plain socket sending
//!   prepared datagrams (to a seabus receiver) taken in turn with the two;
//! - seabus paced at 300k msg/s: loss;
//! - 100 kB messages unpaced: delivered MB/s, and how many arrived;
//! - 64-byte messages paced at 2 kHz: one-way latency p50 / p99;
//! - large messages (100 kB, 500 kB, 1.28 MB: 70 to 900 fragments) from one liblcm sender,
//!   unpaced, to a liblcm receiver and a seabus receiver (its defaults) listening side by side:
//!   how many each delivered.
//!
//! Goals: seabus's 64 B sender at least 0.9× the plain socket's (both unpaced, to a seabus
//! receiver), 64 B delivered at least 3.5× liblcm's, 100 kB MB/s at least liblcm's, latency
//! p50 at most liblcm's, large messages delivered at least as many as liblcm's receiver, at every
//! size. seabus's receiver loses nothing from one sender: the smoke run fails on
//! such a loss (losses with two or three plain senders are reported: with more sender threads
//! than a 2-core machine has cores, they take the receiver's CPU).
//!
//! Run: `cargo bench -p seabus-medium-lcm --bench lcm` (`SEABUS_BENCH_SMOKE=1`: the short run)

#[path = "../../core/benches/common.rs"]
mod common;
#[path = "../tests/support/liblcm.rs"]
mod liblcm;

use seabus_bench::{Goals, scale};
use seabus_medium::{Node, Payload, Stamp, Topic};
use seabus_medium_lcm::wire;
use std::cell::RefCell;
use std::rc::Rc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

const QUIET: Duration = Duration::from_millis(300);
const ROUNDS: usize = 3;

fn url() -> String {
    format!(
        "udpm://239.255.{}.{}:{}?ttl=0",
        fastrand::u8(1..250),
        fastrand::u8(1..250),
        fastrand::u16(20_000..60_000)
    )
}

/// What a receiver saw: count, bytes, time from first to last, one-way latencies.
#[derive(Default)]
struct Seen {
    count: usize,
    bytes: usize,
    first: Option<Instant>,
    last: Option<Instant>,
    latencies: Vec<Duration>,
    /// Messages per second the sender put out.
    offered: f64,
}

impl Seen {
    fn take(&mut self, data: &[u8]) {
        let now = Instant::now();
        self.first.get_or_insert(now);
        self.last = Some(now);
        self.count += 1;
        self.bytes += data.len();
        if let Some(sent) = data.get(..8) {
            let sent = i64::from_le_bytes(sent.try_into().unwrap_or_default());
            self.latencies
                .push(Duration::from_nanos((Stamp::now().0 - sent).max(0) as u64));
        }
    }

    /// Seconds from the first message to the last; infinite (no rate) with fewer than two.
    fn span(&self) -> f64 {
        match (self.first, self.last) {
            (Some(f), Some(l)) if self.count >= 2 => (l - f).as_secs_f64().max(1e-9),
            _ => f64::INFINITY,
        }
    }

    fn rate(&self) -> f64 {
        self.count as f64 / self.span()
    }

    fn mb_per_s(&self) -> f64 {
        self.bytes as f64 / self.span() / 1e6
    }
}

fn stamped(size: usize) -> Vec<u8> {
    let mut p = vec![0u8; size];
    p[..8].copy_from_slice(&Stamp::now().0.to_le_bytes());
    p
}

/// liblcm sender and receiver (each its own instance and thread), with liblcm's defaults.
/// A liblcm receiver on its own thread, taking up to `n` messages until the bus goes quiet;
/// returns once it has subscribed.
fn liblcm_receiver(n: usize) -> std::thread::JoinHandle<Seen> {
    let (ready_tx, ready_rx) = mpsc::channel();
    let receiver = std::thread::spawn(move || {
        let mut lc = liblcm::create();
        let seen = Rc::new(RefCell::new(Seen::default()));
        let s = seen.clone();
        lc.subscribe("BENCH", move |m: liblcm::Raw| s.borrow_mut().take(&m.0));
        let _ = ready_tx.send(());
        let mut quiet_since = Instant::now();
        while seen.borrow().count < n && quiet_since.elapsed() < QUIET {
            if lc.handle_timeout(QUIET / 3).is_ok() {
                quiet_since = Instant::now();
            }
        }
        seen.take()
    });
    let _ = ready_rx.recv();
    receiver
}

fn c_lcm(size: usize, n: usize, rate: Option<f64>) -> Seen {
    let receiver = liblcm_receiver(n);
    let mut lc = liblcm::create();
    let start = Instant::now();
    for i in 0..n {
        if let Some(r) = rate {
            common::pace(start + Duration::from_secs_f64(i as f64 / r));
        }
        let _ = lc.publish("BENCH", &liblcm::Raw(stamped(size)));
    }
    let offered = n as f64 / start.elapsed().as_secs_f64();
    let mut seen = receiver.join().expect("receiver");
    seen.offered = offered;
    seen
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
}

/// A seabus LCM medium on its own thread, taking up to `n` messages until the bus goes quiet;
/// returns once it listens.
fn seabus_receiver(url: &str, n: usize) -> std::thread::JoinHandle<Seen> {
    let (ready_tx, ready_rx) = mpsc::channel();
    let url = url.to_string();
    let receiver = std::thread::spawn(move || {
        runtime().block_on(async move {
            let m = seabus_medium_lcm::schemes()
                .open("lcm", &url, &Node::new("rx"))
                .expect("opens");
            let mut port = m
                .attach_with("rx", n, 16)
                .subscribed("**")
                .expect("pattern");
            let _ = ready_tx.send(());
            let mut seen = Seen::default();
            while let Ok(Some(msg)) = tokio::time::timeout(QUIET, port.recv()).await {
                seen.take(msg.payload.as_bytes().map_or(&[][..], |b| &b[..]));
                if seen.count == n {
                    break;
                }
            }
            seen
        })
    });
    let _ = ready_rx.recv();
    receiver
}

/// Two seabus LCM media, sender and receiver, each on its own thread.
fn seabus(url: &str, size: usize, n: usize, rate: Option<f64>) -> Seen {
    let receiver = seabus_receiver(url, n);
    let offered = runtime().block_on(async move {
        let m = seabus_medium_lcm::schemes()
            .open("lcm", url, &Node::new("tx"))
            .expect("opens");
        let port = m.attach("tx");
        let topic = Topic::new("BENCH").expect("topic");
        let start = Instant::now();
        for i in 0..n {
            if let Some(r) = rate {
                common::pace(start + Duration::from_secs_f64(i as f64 / r));
            }
            let _ = port.send(&topic, Payload::from(stamped(size))).await;
        }
        n as f64 / start.elapsed().as_secs_f64()
    });
    let mut seen = receiver.join().expect("receiver");
    seen.offered = offered;
    seen
}

/// One liblcm sender, unpaced, to a liblcm receiver and a seabus receiver (its defaults) on `url`
/// at once: the messages each delivered.
fn side_by_side(url: &str, size: usize, n: usize) -> (usize, usize) {
    let c = liblcm_receiver(n);
    let s = seabus_receiver(url, n);
    let mut lc = liblcm::create();
    for _ in 0..n {
        let _ = lc.publish("BENCH", &liblcm::Raw(stamped(size)));
    }
    let c = c.join().expect("liblcm receiver").count;
    let s = s.join().expect("seabus receiver").count;
    (c, s)
}

/// Datagrams a plain sender hands the kernel in one call.
const BATCH: usize = 32;

/// Sends `batch` on the connected `sock` with as few sendmmsg(2) calls as the kernel allows.
fn send_batch(sock: &std::net::UdpSocket, batch: &[Vec<u8>]) {
    use std::os::fd::AsRawFd;
    let mut iovs: Vec<libc::iovec> = batch
        .iter()
        .map(|d| libc::iovec {
            iov_base: d.as_ptr() as *mut libc::c_void,
            iov_len: d.len(),
        })
        .collect();
    // SAFETY: mmsghdr is plain data; the zeroed fields mean no address, control data or flags
    let mut msgs: Vec<libc::mmsghdr> = iovs
        .iter_mut()
        .map(|iov| {
            let mut m: libc::mmsghdr = unsafe { std::mem::zeroed() };
            m.msg_hdr.msg_iov = iov;
            m.msg_hdr.msg_iovlen = 1;
            m
        })
        .collect();
    let mut sent = 0;
    while sent < msgs.len() {
        // SAFETY: the headers point at iovecs and datagrams that outlive the call
        let n = unsafe {
            libc::sendmmsg(
                sock.as_raw_fd(),
                msgs[sent..].as_mut_ptr(),
                (msgs.len() - sent) as libc::c_uint,
                0,
            )
        };
        if n <= 0 {
            return;
        }
        sent += n as usize;
    }
}

/// A seabus LCM medium receiving what plain sockets send (`senders` threads sharing `rate`,
/// unpaced when infinite): LC02 datagrams made beforehand, so that the offered rate is the
/// kernel's, not a sender library's.
fn seabus_from_raw(url: &str, size: usize, n: usize, rate: f64, senders: usize) -> Seen {
    let receiver = seabus_receiver(url, n);
    let rest = url.trim_start_matches("udpm://");
    let group_port = rest.split('?').next().unwrap_or(rest);
    let start = Instant::now();
    let per = n / senders;
    let threads: Vec<_> = (0..senders)
        .map(|_| {
            let group_port = group_port.to_string();
            std::thread::spawn(move || {
                let sock = std::net::UdpSocket::bind("0.0.0.0:0").expect("bind");
                // the send buffer seabus's medium asks for
                seabus_medium::net::set_send_buffer(&sock);
                sock.set_multicast_ttl_v4(0).expect("ttl");
                sock.connect(group_port).expect("connect");
                let datagrams: Vec<Vec<u8>> = (0..per)
                    .map(|i| {
                        let mut d =
                            wire::encode(i as u32, "BENCH", &vec![0u8; size]).expect("encodes");
                        d.swap_remove(0)
                    })
                    .collect();
                let start = Instant::now();
                let each = rate / senders as f64;
                // in batches of BATCH datagrams, one sendmmsg(2) each, each batch on time
                for (b, batch) in datagrams.chunks(BATCH).enumerate() {
                    common::pace(start + Duration::from_secs_f64((b * BATCH) as f64 / each));
                    send_batch(&sock, batch);
                }
            })
        })
        .collect();
    for t in threads {
        let _ = t.join();
    }
    let offered = (per * senders) as f64 / start.elapsed().as_secs_f64();
    let mut seen = receiver.join().expect("receiver");
    seen.offered = offered;
    seen
}

fn main() {
    let c_url = url();
    liblcm::use_url(&c_url);
    let sb_url = format!("{}&recv_buf_size=8388608", url());
    println!("LCM on loopback multicast, ttl 0: liblcm (C, its defaults) vs seabus's LCM medium");
    let mut goals = Goals::new();

    let n = scale(300_000, 100_000);
    let (mut c_rates, mut s_rates, mut c_got, mut s_got) = (Vec::new(), Vec::new(), 0, 0);
    let (mut c_sent, mut s_sent, mut p_sent) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..ROUNDS {
        let c = c_lcm(64, n, None);
        c_got += c.count;
        c_rates.push(c.rate());
        c_sent.push(c.offered);
        let s = seabus(&sb_url, 64, n, None);
        s_got += s.count;
        s_rates.push(s.rate());
        s_sent.push(s.offered);
        let p = seabus_from_raw(&sb_url, 64, n, f64::INFINITY, 1);
        goals.none_lost(
            "seabus's LCM receiver, 64 B unpaced, 1 plain socket",
            n,
            p.count,
        );
        p_sent.push(p.offered);
    }
    goals.none_lost(
        "seabus's LCM receiver, 64 B unpaced, seabus sender",
        n * ROUNDS,
        s_got,
    );
    let (s_sent, p_sent) = (common::median(s_sent), common::median(p_sent));
    println!(
        "  64 B unpaced, senders' rates: liblcm {}   seabus {}   a plain socket (prepared datagrams, sendmmsg) {}",
        common::rate(common::median(c_sent)),
        common::rate(s_sent),
        common::rate(p_sent)
    );
    goals.at_least("64 B sender, seabus / plain socket", s_sent / p_sent, 0.9);
    let (c, s) = (common::median(c_rates), common::median(s_rates));
    let total = (n * ROUNDS) as f64;
    println!(
        "  64 B unpaced, {n} sent per run, median of {ROUNDS}: liblcm delivers {} ({:.0}% received)   seabus {} ({:.0}% received)",
        common::rate(c),
        100.0 * c_got as f64 / total,
        common::rate(s),
        100.0 * s_got as f64 / total,
    );
    goals.aim_at_least(
        "64 B delivered, seabus / liblcm",
        s / c,
        3.5,
        "1.87-5.87 between runs on this machine: the reader hands messages to the interface in \
         bursts, without yielding",
    );
    let paced = seabus(&sb_url, 64, n, Some(300_000.0));
    goals.none_lost(
        "seabus's LCM receiver, 64 B at 300k msg/s, seabus sender",
        n,
        paced.count,
    );
    println!(
        "  64 B paced at 300k msg/s from a seabus sender (it reached {}): seabus delivered {} of {n}, lost {}",
        common::rate(paced.offered),
        paced.count,
        n - paced.count
    );
    for senders in [1, 2, 3] {
        let raw = seabus_from_raw(&sb_url, 64, n, 300_000.0, senders);
        println!(
            "  64 B paced at 300k msg/s from {senders} plain socket(s) (they reached {}): seabus delivered {} of {n}, lost {}",
            common::rate(raw.offered),
            raw.count,
            n - raw.count
        );
        if senders == 1 {
            goals.none_lost(
                "seabus's LCM receiver, 64 B at 300k msg/s, 1 plain socket",
                n,
                raw.count,
            );
        }
    }

    let n = scale(20_000, 10_000);
    let (mut c_mb, mut s_mb, mut c_got, mut s_got) = (Vec::new(), Vec::new(), 0, 0);
    for _ in 0..ROUNDS {
        let c = c_lcm(100_000, n, None);
        c_mb.push(c.mb_per_s());
        c_got += c.count;
        let s = seabus(&sb_url, 100_000, n, None);
        s_mb.push(s.mb_per_s());
        s_got += s.count;
    }
    let (c, s) = (common::median(c_mb), common::median(s_mb));
    let total = (n * ROUNDS) as f64;
    println!(
        "  100 kB unpaced, {n} sent per run, median of {ROUNDS}: liblcm {c:.0} MB/s ({:.0}% received)   seabus {s:.0} MB/s ({:.0}% received)",
        100.0 * c_got as f64 / total,
        100.0 * s_got as f64 / total,
    );
    goals.at_least("100 kB MB/s, seabus / liblcm", s / c, 1.0);

    let n = scale(10_000, 2_000);
    let mut c_lat = c_lcm(64, n, Some(2_000.0)).latencies;
    let s_run = seabus(&sb_url, 64, n, Some(2_000.0));
    goals.none_lost(
        "seabus's LCM receiver, 64 B at 2 kHz, seabus sender",
        n,
        s_run.count,
    );
    let mut s_lat = s_run.latencies;
    c_lat.sort();
    s_lat.sort();
    let c50 = common::quantile_us(&c_lat, 0.5);
    let s50 = common::quantile_us(&s_lat, 0.5);
    println!(
        "  64 B paced at 2 kHz, {n} messages, one-way latency: liblcm p50 {c50:.1} us p99 {:.1} us   seabus p50 {s50:.1} us p99 {:.1} us",
        common::quantile_us(&c_lat, 0.99),
        common::quantile_us(&s_lat, 0.99)
    );
    goals.at_most("64 B latency p50 at 2 kHz, seabus / liblcm", s50 / c50, 1.0);

    for (size, n) in [
        (100_000, scale(2_000, 500)),
        (500_000, scale(400, 100)),
        (1_280_000, scale(160, 40)),
    ] {
        let (mut c_got, mut s_got) = (0, 0);
        for _ in 0..ROUNDS {
            let (c, s) = side_by_side(&c_url, size, n);
            c_got += c;
            s_got += s;
        }
        let total = n * ROUNDS;
        println!(
            "  {} kB unpaced from one liblcm sender, {n} per run, {ROUNDS} runs, both listening: liblcm delivered {c_got} ({:.0}%)   seabus {s_got} ({:.0}%)",
            size / 1000,
            100.0 * c_got as f64 / total as f64,
            100.0 * s_got as f64 / total as f64,
        );
        goals.at_least(
            &format!("{} kB delivered side by side, seabus / liblcm", size / 1000),
            s_got as f64 / c_got.max(1) as f64,
            1.0,
        );
    }
    goals.finish();
}
