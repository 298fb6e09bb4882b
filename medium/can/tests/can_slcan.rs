//! slcan over pseudo-terminals: the real python-can opens seabus's pseudo-terminal adapter as it
//! opens a CANable and frames go both ways (standard, extended, remote, CAN FD); seabus as the host
//! of an adapter sends the opening sequence, reads frames with timestamps, and counts what the
//! adapter refuses and what is not slcan.

use seabus_medium::{DataMap, Interface, Medium, Message, Node, Value};
use seabus_medium_can::frame::CanFrame;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn bytes(v: &[u8]) -> Value {
    Value::Bytes(v.to_vec())
}

fn open(url: &str) -> Medium {
    seabus_medium_can::schemes()
        .open("can", url, &Node::new("t"))
        .expect("the CAN medium opens")
}

fn link_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "seabus-{name}-{}-{}",
        std::process::id(),
        fastrand::u32(..)
    ))
}

/// The next message on `iface`, at most 10 s away.
async fn next(iface: &mut Interface) -> Message {
    tokio::time::timeout(Duration::from_secs(10), iface.recv())
        .await
        .expect("a frame within 10 s")
        .expect("the medium is open")
}

fn frame_of(m: &Message) -> CanFrame {
    CanFrame::from_message(m.topic.as_str(), &m.payload).expect("a CAN frame")
}

/// python-can as the host: opens the adapter, sends four frames, then prints what it receives.
const PYTHON_HOST: &str = r#"
import can, json, sys, time
bus = can.Bus(interface="slcan", channel=sys.argv[1], bitrate=500000, sleep_after_open=0)
for m in [
    can.Message(arbitration_id=0x123, is_extended_id=False, data=[1, 2, 3]),
    can.Message(arbitration_id=0x18FF50E5, is_extended_id=True, data=b"\xaa" * 8),
    can.Message(arbitration_id=0x7FF, is_extended_id=False, is_remote_frame=True, dlc=4),
    can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, is_fd=True, bitrate_switch=True, data=bytes(range(16))),
]:
    bus.send(m)
print("sent", flush=True)
got, deadline = 0, time.time() + 10
while got < 4 and time.time() < deadline:
    m = bus.recv(timeout=0.5)
    if m is None:
        continue
    got += 1
    print(json.dumps({"id": m.arbitration_id, "ext": m.is_extended_id, "rtr": m.is_remote_frame,
                      "fd": m.is_fd, "brs": m.bitrate_switch, "dlc": m.dlc, "data": bytes(m.data).hex()}), flush=True)
bus.shutdown()
"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_can_opens_the_pty_adapter_and_frames_go_both_ways() {
    if Command::new("python3")
        .args(["-c", "import can, serial"])
        .status()
        .map_or(true, |s| !s.success())
    {
        panic!("python-can is not installed: run scripts/test, which installs it");
    }
    let path = link_path("slcan");
    let medium = open(&format!("slcan+pty://{}", path.display()));
    let mut iface = medium.attach("test");
    iface.subscribe("can.**").unwrap();

    let mut py = Command::new("python3")
        .args(["-c", PYTHON_HOST])
        .arg(&path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 starts");

    // what python-can sent arrives as CAN messages
    let want = [
        CanFrame::data(0x123, false, &[1, 2, 3]).unwrap(),
        CanFrame::data(0x18FF_50E5, true, &[0xAA; 8]).unwrap(),
        CanFrame::remote(0x7FF, false, 4).unwrap(),
        CanFrame::fd(0x1AB_CDEF, true, &(0..16).collect::<Vec<u8>>(), true, false).unwrap(),
    ];
    let topics = ["can.123", "can.18ff50e5", "can.7ff", "can.01abcdef"];
    for (f, t) in want.iter().zip(topics) {
        let m = next(&mut iface).await;
        assert_eq!(m.topic.as_str(), t);
        assert_eq!(&frame_of(&m), f);
    }
    // python-can's opening (C, S6, an empty line, O, O) was taken without complaint
    assert_eq!(medium.stats().rejected_total(), 0, "{:?}", medium.stats());

    // seabus's frames reach python-can
    let ours = [
        ("can.321", DataMap::new().with("data", bytes(&[9, 8]))),
        ("can.1fffffff", DataMap::new().with("data", bytes(&[0; 8]))),
        (
            "can.010",
            DataMap::new().with("rtr", true).with("dlc", 2i64),
        ),
        (
            "can.456",
            DataMap::new()
                .with("data", bytes(&[7; 12]))
                .with("fd", true),
        ),
    ];
    for (topic, map) in ours {
        iface.send(topic, map).await.unwrap();
    }
    let out = py.stdout.take().unwrap();
    let lines: Vec<serde_json::Value> = BufReader::new(out)
        .lines()
        .map_while(Result::ok)
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(&l).unwrap())
        .collect();
    let status = py.wait().unwrap();
    let mut err = String::new();
    let _ = py.stderr.take().unwrap().read_to_string(&mut err);
    assert!(status.success(), "{err}");
    let seen: Vec<(u64, bool, bool, bool, bool, u64, String)> = lines
        .iter()
        .map(|v| {
            (
                v["id"].as_u64().unwrap(),
                v["ext"].as_bool().unwrap(),
                v["rtr"].as_bool().unwrap(),
                v["fd"].as_bool().unwrap(),
                v["brs"].as_bool().unwrap(),
                v["dlc"].as_u64().unwrap(),
                v["data"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    assert_eq!(
        seen,
        [
            (0x321, false, false, false, false, 2, "0908".to_string()),
            (0x1FFF_FFFF, true, false, false, false, 8, "00".repeat(8)),
            (0x10, false, true, false, false, 2, String::new()),
            (0x456, false, false, true, false, 12, "07".repeat(12)),
        ]
    );
    medium.close();
    assert!(!path.exists(), "the link goes when the medium closes");
}

/// A raw pseudo-terminal standing for an adapter: its master side, and its path.
fn raw_pty() -> (std::fs::File, PathBuf) {
    // SAFETY: plain libc calls on descriptors this function owns
    unsafe {
        let master = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY);
        assert!(master >= 0, "posix_openpt");
        assert_eq!(libc::grantpt(master), 0);
        assert_eq!(libc::unlockpt(master), 0);
        let mut name = [0 as libc::c_char; 128];
        assert_eq!(libc::ptsname_r(master, name.as_mut_ptr(), name.len()), 0);
        let path = std::ffi::CStr::from_ptr(name.as_ptr())
            .to_string_lossy()
            .into_owned();
        // raw mode on the adapter's side, so that CRs pass unchanged
        let slave = libc::open(name.as_ptr(), libc::O_RDWR | libc::O_NOCTTY);
        let mut t: libc::termios = std::mem::zeroed();
        libc::tcgetattr(slave, &mut t);
        libc::cfmakeraw(&mut t);
        libc::tcsetattr(slave, libc::TCSANOW, &t);
        libc::close(slave);
        use std::os::fd::FromRawFd;
        (std::fs::File::from_raw_fd(master), PathBuf::from(path))
    }
}

/// Reads from the adapter's side until `want` has arrived (at most 5 s).
fn read_until(adapter: &mut std::fs::File, want: &[u8]) -> Vec<u8> {
    use std::os::fd::AsRawFd;
    // SAFETY: fcntl on our own descriptor
    unsafe {
        let fd = adapter.as_raw_fd();
        libc::fcntl(
            fd,
            libc::F_SETFL,
            libc::fcntl(fd, libc::F_GETFL) | libc::O_NONBLOCK,
        );
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    while Instant::now() < deadline && !got.windows(want.len()).any(|w| w == want) {
        match adapter.read(&mut buf) {
            Ok(n) if n > 0 => got.extend_from_slice(&buf[..n]),
            _ => std::thread::sleep(Duration::from_millis(10)),
        }
    }
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_host_opens_its_adapter_reads_frames_and_counts_what_is_wrong() {
    let (mut adapter, path) = raw_pty();
    let medium = open(&format!(
        "slcan://{}?bitrate=250000&timestamps=true",
        path.display()
    ));
    let mut iface = medium.attach("test");
    iface.subscribe("can.**").unwrap();

    // the opening sequence, as a CANable expects it
    let opening = tokio::task::block_in_place(|| read_until(&mut adapter, b"O\r"));
    assert_eq!(opening, b"C\rS5\rZ1\rO\r");

    // frames from the adapter, with its timestamps; a refusal and a garbage line are counted
    adapter
        .write_all(b"\r\x07t1232DEAD1234\rxyz\rT18FF50E50EA5F\rr0013ABCD\r")
        .unwrap();
    let a = next(&mut iface).await;
    assert_eq!(a.topic.as_str(), "can.123");
    let map = a.payload.as_map().unwrap();
    assert_eq!(map.get_i64("time_ms"), Some(0x1234));
    assert_eq!(
        frame_of(&a),
        CanFrame::data(0x123, false, &[0xDE, 0xAD]).unwrap()
    );
    let b = next(&mut iface).await;
    assert_eq!(
        frame_of(&b),
        CanFrame::data(0x18FF_50E5, true, &[]).unwrap()
    );
    assert_eq!(b.payload.as_map().unwrap().get_i64("time_ms"), Some(0xEA5F));
    let c = next(&mut iface).await;
    assert_eq!(frame_of(&c), CanFrame::remote(0x001, false, 3).unwrap());
    let rejected = medium.stats().rejected;
    assert_eq!(rejected.get("slcan-refused"), Some(&1), "{rejected:?}");
    assert_eq!(rejected.get("slcan-unknown-line"), Some(&1), "{rejected:?}");
    assert_eq!(rejected.values().sum::<u64>(), 2, "{rejected:?}");

    // what is sent goes to the adapter as slcan lines
    iface
        .send("can.7ff", DataMap::new().with("data", bytes(&[1, 2, 3])))
        .await
        .unwrap();
    let sent = tokio::task::block_in_place(|| read_until(&mut adapter, b"t7FF3010203\r"));
    assert!(
        sent.ends_with(b"t7FF3010203\r"),
        "{:?}",
        String::from_utf8_lossy(&sent)
    );

    // a message that is no CAN frame is refused with the reason
    let e = iface
        .send("can.800", DataMap::new())
        .await
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("identifier 0x800 is past the 11-bit limit"),
        "{e}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_host_and_the_pty_adapter_talk_to_each_other() {
    let path = link_path("slcan-pair");
    let adapter = open(&format!("slcan+pty://{}", path.display()));
    let host = open(&format!("slcan://{}?timestamps=true", path.display()));
    let mut on_adapter = adapter.attach("a");
    on_adapter.subscribe("can.**").unwrap();
    let mut on_host = host.attach("h");
    on_host.subscribe("can.**").unwrap();
    // the host opens the channel; its frames then pass (bounded retries while it opens)
    let mut got = None;
    for _ in 0..50 {
        let _ = on_host
            .send("can.100", DataMap::new().with("data", bytes(&[1])))
            .await;
        if let Ok(Some(m)) =
            tokio::time::timeout(Duration::from_millis(100), on_adapter.recv()).await
        {
            got = Some(m);
            break;
        }
    }
    let m = got.expect("the host's frame reaches the adapter");
    assert_eq!(frame_of(&m), CanFrame::data(0x100, false, &[1]).unwrap());
    // and the adapter's frames reach the host, with timestamps since the host asked for them
    adapter
        .attach("x")
        .send("can.00abcdef", DataMap::new().with("data", bytes(&[5; 8])))
        .await
        .unwrap();
    let back = next(&mut on_host).await;
    assert_eq!(
        frame_of(&back),
        CanFrame::data(0xAB_CDEF, true, &[5; 8]).unwrap()
    );
    assert!(back.payload.as_map().unwrap().get_i64("time_ms").is_some());
}
