//! The LCM medium against real LCM peers on this machine (ttl 0): the C library liblcm, through
//! the `lcm` crate that binds it, and the Python `lcm` package; short and fragmented messages in
//! both directions, packets compared byte for byte with liblcm's, and fragments out of order,
//! repeated, missing and interleaved from two senders over real sockets; a sender starting again
//! on the same port, two local publishers of large messages, and closing.
//!
//! The peers are installed by `./scripts/test` (Debian `liblcm-dev`, PyPI `lcm`).

#[path = "support/liblcm.rs"]
mod support;

use seabus_medium::{Medium, Message, Node};
use seabus_medium_lcm::wire::{self, Packet};
use socket2::{Domain, Protocol, Socket, Type};
use std::io::{BufRead, BufReader, Write};
use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};
use support::Raw;
use tokio::time::timeout;

const WAIT: Duration = Duration::from_secs(10);
/// Big enough for several fragments.
const BIG: usize = 300_000;

/// This run's LCM group and port (ttl 0), also given to liblcm through `LCM_DEFAULT_URL`.
fn url() -> &'static str {
    static URL: OnceLock<String> = OnceLock::new();
    URL.get_or_init(|| {
        let url = format!(
            "udpm://239.255.{}.{}:{}?ttl=0&recv_buf_size=4194304",
            fastrand::u8(1..250),
            fastrand::u8(1..250),
            fastrand::u16(20_000..60_000)
        );
        support::use_url(&url);
        url
    })
}

fn group_port() -> (Ipv4Addr, u16) {
    let rest = url().trim_start_matches("udpm://");
    let (hp, _) = rest.split_once('?').unwrap_or((rest, ""));
    let (h, p) = hp.split_once(':').expect("host:port");
    (h.parse().expect("group"), p.parse().expect("port"))
}

fn pattern(n: usize, salt: u8) -> Vec<u8> {
    (0..n)
        .map(|i| (i as u8).wrapping_mul(7).wrapping_add(salt) ^ (i >> 8) as u8)
        .collect()
}

fn liblcm() -> lcm::Lcm {
    url();
    support::create()
}

fn open(name: &str, options: &str) -> Medium {
    seabus_medium_lcm::schemes()
        .open(name, &format!("{}{options}", url()), &Node::new("t"))
        .expect("lcm medium opens")
}

async fn next(iface: &mut seabus_medium::Interface) -> Message {
    timeout(WAIT, iface.recv())
        .await
        .expect("a message in time")
        .expect("medium open")
}

/// The topics and payloads of the first `n` messages whose topic starts with `prefix`, sorted;
/// fewer if [`WAIT`] passes first.
async fn receive(
    iface: &mut seabus_medium::Interface,
    n: usize,
    prefix: &str,
) -> Vec<(String, Vec<u8>)> {
    let mut got = Vec::new();
    let deadline = Instant::now() + WAIT;
    while got.len() < n && Instant::now() < deadline {
        let msg = next(iface).await;
        if msg.topic.as_str().starts_with(prefix) {
            got.push((
                msg.topic.to_string(),
                msg.payload.as_bytes().unwrap().to_vec(),
            ));
        }
    }
    got.sort();
    got
}

fn python(script: &str) -> std::process::Child {
    Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(url())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs")
}

const PY_CHECK: &str = "import lcm, sys
try:
    lcm.LCM
except AttributeError:
    sys.exit('the Python lcm package is missing: run ./scripts/test or pip install lcm')
";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn liblcm_messages_reach_seabus() {
    let m = open("lcm", "");
    let mut iface = m.attach("t").subscribed("**").unwrap();
    let short = pattern(64, 1);
    let big = pattern(BIG, 2);
    let (s, b) = (short.clone(), big.clone());
    std::thread::spawn(move || {
        let mut lc = liblcm();
        lc.publish("C_SHORT", &Raw(s)).expect("liblcm publishes");
        lc.publish("C_BIG", &Raw(b)).expect("liblcm publishes");
    });
    let got = receive(&mut iface, 2, "C_").await;
    assert_eq!(
        got,
        vec![("C_BIG".to_string(), big), ("C_SHORT".to_string(), short)]
    );
    assert_eq!(m.stats().rejected_total(), 0, "{:?}", m.stats().rejected);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn seabus_messages_reach_liblcm() {
    let m = open("lcm", "");
    let iface = m.attach("t");
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let peer = std::thread::spawn(move || {
        let mut lc = liblcm();
        let got = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
        for ch in ["S_SHORT", "S_BIG"] {
            let g = got.clone();
            lc.subscribe(ch, move |m: Raw| g.borrow_mut().push((ch, m.0)));
        }
        ready_tx.send(()).expect("test waiting");
        let deadline = Instant::now() + WAIT;
        while got.borrow().len() < 2 && Instant::now() < deadline {
            let _ = lc.handle_timeout(Duration::from_millis(100));
        }
        got.take()
    });
    ready_rx.recv_timeout(WAIT).expect("liblcm subscribed");
    let short = pattern(64, 3);
    let big = pattern(BIG, 4);
    iface.send("S_SHORT", short.clone()).await.unwrap();
    iface.send("S_BIG", big.clone()).await.unwrap();
    let mut got = peer.join().expect("peer thread");
    got.sort();
    assert_eq!(got, vec![("S_BIG", big), ("S_SHORT", short)]);
}

/// A socket that hears the group as liblcm's receivers do.
fn listener() -> UdpSocket {
    let (group, port) = group_port();
    listener_on(group, port)
}

/// A socket that hears `group` on `port` as liblcm's receivers do.
fn listener_on(group: Ipv4Addr, port: u16) -> UdpSocket {
    let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).unwrap();
    s.set_reuse_address(true).unwrap();
    let _ = s.set_recv_buffer_size(4 << 20);
    s.bind(&SocketAddr::from((group, port)).into()).unwrap();
    let a = s.join_multicast_v4(&group, &Ipv4Addr::UNSPECIFIED);
    let b = s.join_multicast_v4(&group, &Ipv4Addr::LOCALHOST);
    assert!(a.is_ok() || b.is_ok(), "joined {group}");
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    s.into()
}

/// The datagrams carrying the message on `channel`, in arrival order.
fn capture(sock: &UdpSocket, channel: &str) -> Vec<Vec<u8>> {
    let mut out: Vec<Vec<u8>> = Vec::new();
    let mut seq = None;
    let mut buf = vec![0u8; 65_536];
    let deadline = Instant::now() + WAIT;
    while Instant::now() < deadline {
        let Ok(n) = sock.recv(&mut buf) else { continue };
        let d = buf[..n].to_vec();
        match wire::parse(&d) {
            Ok(Packet::Fragment(f)) if f.channel == Some(channel) => {
                seq = Some(f.seq);
                out.push(d);
            }
            Ok(Packet::Fragment(f)) if Some(f.seq) == seq => out.push(d),
            Ok(Packet::Short { channel: c, .. }) if c == channel => out.push(d),
            _ => {}
        }
        let done = match out.first().map(|d| wire::parse(d)) {
            Some(Ok(Packet::Short { .. })) => true,
            Some(Ok(Packet::Fragment(f))) => out.len() == usize::from(f.count),
            _ => false,
        };
        if done {
            break;
        }
    }
    out
}

fn seq_of(d: &[u8]) -> u32 {
    u32::from_be_bytes([d[4], d[5], d[6], d[7]])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn packets_are_byte_for_byte_those_of_liblcm() {
    let sock = listener();
    let payload = pattern(BIG, 5);
    // liblcm's packets for a fragmented message and a short one
    let p = payload.clone();
    std::thread::spawn(move || {
        let mut lc = liblcm();
        lc.publish("BYTES_C", &Raw(p)).unwrap();
        lc.publish("BYTES_C_SHORT", &Raw(b"hello".to_vec()))
            .unwrap();
    });
    for (channel, data) in [("BYTES_C", &payload[..]), ("BYTES_C_SHORT", b"hello")] {
        let theirs = capture(&sock, channel);
        assert!(!theirs.is_empty(), "liblcm's {channel} captured");
        let ours = wire::encode(seq_of(&theirs[0]), channel, data).unwrap();
        assert_eq!(theirs.len(), ours.len(), "{channel}: fragment count");
        assert!(
            theirs == ours,
            "{channel}: liblcm's packets differ from seabus's"
        );
    }
    // and seabus's own medium sends exactly the same
    let m = open("lcm", "");
    let iface = m.attach("t");
    iface.send("BYTES_S", payload.clone()).await.unwrap();
    let sent = capture(&sock, "BYTES_S");
    assert_eq!(
        sent,
        wire::encode(seq_of(&sent[0]), "BYTES_S", &payload).unwrap()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_lcm_both_ways() {
    let m = open("lcm", "");
    let mut iface = m.attach("t").subscribed("**").unwrap();
    // Python → seabus
    let mut publisher = python(&format!(
        "{PY_CHECK}
lc = lcm.LCM(sys.argv[1])
lc.publish('PY_TO_SB_SHORT', bytes(range(64)))
lc.publish('PY_TO_SB_BIG', bytes(i % 251 for i in range({BIG})))
"
    ));
    let got = receive(&mut iface, 2, "PY_TO_SB_").await;
    assert!(publisher.wait().unwrap().success());
    assert_eq!(
        got,
        vec![
            (
                "PY_TO_SB_BIG".to_string(),
                (0..BIG).map(|i| (i % 251) as u8).collect()
            ),
            ("PY_TO_SB_SHORT".to_string(), (0..64).collect()),
        ]
    );

    // seabus → Python: it prints the channel, length and a digest of what it receives
    let mut subscriber = python(&format!(
        "{PY_CHECK}
import hashlib, time
lc = lcm.LCM(sys.argv[1])
got = []
lc.subscribe('SB_TO_PY_.*', lambda ch, data: got.append((ch, len(data), hashlib.sha256(data).hexdigest())))
print('ready', flush=True)
end = time.time() + {}
while len(got) < 2 and time.time() < end:
    lc.handle_timeout(100)
for g in sorted(got):
    print(*g, flush=True)
",
        WAIT.as_secs()
    ));
    let mut lines = BufReader::new(subscriber.stdout.take().unwrap()).lines();
    assert_eq!(lines.next().unwrap().unwrap(), "ready");
    let big = pattern(BIG, 6);
    iface
        .send("SB_TO_PY_SHORT", b"short".to_vec())
        .await
        .unwrap();
    iface.send("SB_TO_PY_BIG", big.clone()).await.unwrap();
    let printed: Vec<String> = lines.map_while(Result::ok).collect();
    assert!(subscriber.wait().unwrap().success());
    let digest = |d: &[u8]| {
        let out = Command::new("sha256sum")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .and_then(|mut c| {
                c.stdin.take().unwrap().write_all(d)?;
                c.wait_with_output()
            })
            .unwrap();
        String::from_utf8(out.stdout).unwrap()[..64].to_string()
    };
    assert_eq!(
        printed,
        vec![
            format!("SB_TO_PY_BIG {BIG} {}", digest(&big)),
            format!("SB_TO_PY_SHORT 5 {}", digest(b"short")),
        ]
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fragments_in_any_order_repeated_missing_and_interleaved() {
    // a group of its own: its repeated and missing fragments are counted by every medium hearing them
    let (group, port) = (
        Ipv4Addr::new(239, 255, 77, fastrand::u8(1..250)),
        fastrand::u16(20_000..60_000),
    );
    let m = seabus_medium_lcm::schemes()
        .open(
            "lcm",
            &format!("udpm://{group}:{port}?ttl=0&recv_buf_size=4194304&frag_timeout=300ms"),
            &Node::new("t"),
        )
        .expect("lcm medium opens");
    let mut iface = m.attach("t").subscribed("**").unwrap();
    let to = SocketAddr::from((group, port));
    let sender = || {
        let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).unwrap();
        s.set_multicast_ttl_v4(0).unwrap();
        let _ = s.set_multicast_if_v4(&Ipv4Addr::LOCALHOST);
        s.bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)).into())
            .unwrap();
        UdpSocket::from(s)
    };
    let (a, b) = (sender(), sender());
    let pa = pattern(200_000, 7);
    let pb = pattern(260_000, 8);
    let pc = pattern(140_000, 9);
    // the same sequence number from two senders: keyed apart by sender
    let mut fa = wire::encode(11, "FRAG_A", &pa).unwrap();
    let fb = wire::encode(11, "FRAG_B", &pb).unwrap();
    let fc = wire::encode(12, "FRAG_C", &pc).unwrap();
    fa.reverse();
    // liblcm's start-up self test is not a message for anyone here
    for d in wire::encode(0, wire::SELF_TEST_CHANNEL, b"self test").unwrap() {
        a.send_to(&d, to).unwrap();
    }
    let mut sent_twice = 0;
    for i in 0..fa.len().max(fb.len()) {
        if let Some(d) = fa.get(i) {
            a.send_to(d, to).unwrap();
            a.send_to(d, to).unwrap();
            sent_twice += 1;
        }
        if let Some(d) = fb.get(i) {
            b.send_to(d, to).unwrap();
        }
        // C never sends its last fragment
        if let Some(d) = fc.get(i).filter(|_| i + 1 < fc.len()) {
            a.send_to(d, to).unwrap();
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let got = receive(&mut iface, 2, "").await;
    assert_eq!(
        got,
        vec![("FRAG_A".to_string(), pa), ("FRAG_B".to_string(), pb)]
    );
    // C is given up once its timeout passes, and counted; nothing else arrives
    let deadline = Instant::now() + WAIT;
    let timed_out = loop {
        let n = m
            .stats()
            .rejected
            .get("lcm-fragment-timeout")
            .copied()
            .unwrap_or(0);
        if n > 0 || Instant::now() > deadline {
            break n;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert_eq!(timed_out, 1);
    let stats = m.stats();
    assert_eq!(
        stats.rejected.get("lcm-duplicate-fragment").copied(),
        Some(sent_twice as u64)
    );
    assert!(
        iface.try_recv().is_err(),
        "the incomplete message is not delivered"
    );
}

/// A group and port of a test's own, so that what it sends and counts is its own.
fn own_group() -> (Ipv4Addr, u16) {
    (
        Ipv4Addr::new(239, 255, 78, fastrand::u8(1..250)),
        fastrand::u16(20_000..60_000),
    )
}

fn open_on(group: Ipv4Addr, port: u16) -> Medium {
    seabus_medium_lcm::schemes()
        .open(
            "lcm",
            &format!("udpm://{group}:{port}?ttl=0&recv_buf_size=4194304"),
            &Node::new("t"),
        )
        .expect("lcm medium opens")
}

/// A plain socket sending to the group on loopback.
fn plain_sender() -> UdpSocket {
    let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).unwrap();
    s.set_multicast_ttl_v4(0).unwrap();
    let _ = s.set_multicast_if_v4(&Ipv4Addr::LOCALHOST);
    s.bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)).into())
        .unwrap();
    UdpSocket::from(s)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sender_starting_again_on_its_port_loses_nothing() {
    // sequence numbers 0..=2000, then 0..=2000 again from the same address: a sender on a fixed
    // port that started again. LCM never sends a message twice, so all of them are new.
    const RUN: u32 = 2001;
    let (group, port) = own_group();
    let m = open_on(group, port);
    let mut iface = m.attach_with("t", 8192, 64).subscribed("**").unwrap();
    let to = SocketAddr::from((group, port));
    let sender = std::thread::spawn(move || {
        let s = plain_sender();
        for run in 0..2u32 {
            for seq in 0..RUN {
                let body = (run * RUN + seq).to_be_bytes();
                for d in wire::encode(seq, "RESTART", &body).unwrap() {
                    s.send_to(&d, to).unwrap();
                }
                if seq % 50 == 0 {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        }
    });
    let mut got = Vec::new();
    let deadline = Instant::now() + WAIT;
    while got.len() < 2 * RUN as usize && Instant::now() < deadline {
        let Ok(Some(msg)) = timeout(Duration::from_millis(500), iface.recv()).await else {
            continue;
        };
        let b = msg.payload.as_bytes().expect("bytes");
        got.push(u32::from_be_bytes(b[..4].try_into().expect("4 bytes")));
    }
    sender.join().expect("sender thread");
    got.sort_unstable();
    assert_eq!(
        got,
        (0..2 * RUN).collect::<Vec<_>>(),
        "{} of {} delivered; rejected: {:?}",
        got.len(),
        2 * RUN,
        m.stats().rejected
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fragments_of_two_local_publishers_do_not_interleave() {
    // liblcm up to 1.4 keeps one partial message per sender and drops it when a fragment of
    // another message comes: one message's fragments must go out together
    const EACH: u8 = 4;
    let (group, port) = own_group();
    let sock = listener_on(group, port);
    let m = open_on(group, port);
    let expected =
        2 * usize::from(EACH) * wire::encode(0, "ILV_0", &pattern(BIG, 0)).unwrap().len();
    let capture = std::thread::spawn(move || {
        let mut seen: Vec<(u32, u16)> = Vec::new();
        let mut buf = vec![0u8; 65_536];
        let deadline = Instant::now() + WAIT;
        while seen.len() < expected && Instant::now() < deadline {
            let Ok(n) = sock.recv(&mut buf) else { continue };
            if let Ok(Packet::Fragment(f)) = wire::parse(&buf[..n]) {
                seen.push((f.seq, f.no));
            }
        }
        seen
    });
    let publishers: Vec<_> = (0..2u8)
        .map(|k| {
            let iface = m.attach(&format!("p{k}"));
            tokio::spawn(async move {
                for i in 0..EACH {
                    iface
                        .send(format!("ILV_{k}").as_str(), pattern(BIG, k * 16 + i))
                        .await
                        .expect("sent");
                }
            })
        })
        .collect();
    for p in publishers {
        p.await.expect("publisher");
    }
    let seen = tokio::task::spawn_blocking(move || capture.join().expect("capture thread"))
        .await
        .expect("capture");
    assert_eq!(seen.len(), expected, "every fragment captured");
    // the fragments of each message come in one run, in order
    let mut runs: Vec<(u32, Vec<u16>)> = Vec::new();
    for (seq, no) in seen {
        match runs.last_mut() {
            Some((s, nos)) if *s == seq => nos.push(no),
            _ => runs.push((seq, vec![no])),
        }
    }
    let mut seqs: Vec<u32> = runs.iter().map(|(s, _)| *s).collect();
    seqs.sort_unstable();
    seqs.dedup();
    assert_eq!(
        seqs.len(),
        runs.len(),
        "a message's fragments were interleaved with another's: {runs:?}"
    );
    assert!(
        runs.iter()
            .all(|(_, nos)| nos.iter().copied().eq(0..nos.len() as u16))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn closing_releases_the_receive_socket() {
    for subscribe_before in [true, false] {
        let (group, port) = own_group();
        let m = open_on(group, port);
        let mut iface = m.attach("t");
        if subscribe_before {
            iface.subscribe("**").unwrap();
        }
        m.close();
        if !subscribe_before {
            // nothing joins for a closed medium
            iface.subscribe("**").unwrap();
        }
        // the medium still exists, but its port is free: a socket that does not share it binds
        let deadline = Instant::now() + WAIT;
        let bound = loop {
            match UdpSocket::bind((group, port)) {
                Ok(s) => break Ok(s),
                Err(e) if Instant::now() > deadline => break Err(e),
                Err(_) => tokio::time::sleep(Duration::from_millis(20)).await,
            }
        };
        assert!(
            bound.is_ok(),
            "{group}:{port} still held after close (subscribed before: {subscribe_before}): {bound:?}"
        );
        drop(m);
    }
}
