//! SocketCAN end to end: two media on a virtual CAN interface exchange frames. That needs a kernel
//! with CAN support, the vcan module and root, so the test is ignored unless asked for
//! (`cargo nextest run -p seabus-medium-can --run-ignored all`); asked for, it fails with the reason
//! when the machine lacks any of them. CAN end to end is otherwise covered by slcan over
//! pseudo-terminals and cannelloni over UDP. What every machine checks here is that a `socketcan://`
//! medium whose interface cannot be opened keeps its link down and says why.

use seabus_medium::{DataMap, LinkState, Medium, Node, Value};
use seabus_medium_can::frame::CanFrame;
use seabus_medium_can::socketcan::kernel_has_can;
use std::process::Command;
use std::time::{Duration, Instant};

fn open(url: &str) -> Medium {
    seabus_medium_can::schemes()
        .open("can", url, &Node::new("t"))
        .expect("the CAN medium opens")
}

/// Waits (at most 5 s) for the link to be what `pred` wants.
async fn wait_link(m: &Medium, pred: impl Fn(&LinkState) -> bool) -> LinkState {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let s = m.link_state();
        if pred(&s) || Instant::now() > deadline {
            return s;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// A vcan interface, removed on drop.
struct Vcan(String);

impl Vcan {
    /// Makes and raises a vcan interface; an error says which step failed and why.
    fn new() -> Result<Vcan, String> {
        let name = format!("sbvcan{}", fastrand::u16(..1000));
        let run = |args: &[&str]| {
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
        };
        run(&["link", "add", "dev", &name, "type", "vcan"])?;
        let vcan = Vcan(name);
        run(&["link", "set", "up", "dev", &vcan.0])?;
        Ok(vcan)
    }
}

impl Drop for Vcan {
    fn drop(&mut self) {
        let _ = Command::new("ip")
            .args(["link", "del", "dev", &self.0])
            .output();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_missing_interface_keeps_the_link_down_and_says_why() {
    let m = open("socketcan://sbnosuch0");
    let s = wait_link(
        &m,
        |s| matches!(s, LinkState::Down(r) if !r.ends_with("not opened yet")),
    )
    .await;
    let LinkState::Down(reason) = s else {
        panic!("a CAN link came up on an interface that does not exist");
    };
    if kernel_has_can() {
        assert!(reason.starts_with("cannot open sbnosuch0: "), "{reason}");
    } else {
        assert_eq!(
            reason,
            "sbnosuch0: this kernel has no SocketCAN support (no AF_CAN sockets); use slcan or \
             cannelloni"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs a kernel with SocketCAN and the vcan module, and root; run with --run-ignored on such a machine"]
async fn frames_cross_a_virtual_can_interface() {
    // asked for explicitly: a machine that cannot run it fails it, it is never skipped
    assert!(
        kernel_has_can(),
        "this kernel has no SocketCAN support (socket(AF_CAN) fails): run this test on a kernel \
         with CAN and the vcan module"
    );
    let vcan = Vcan::new().unwrap_or_else(|e| {
        panic!("no vcan interface could be made (the vcan module, or root, is missing): {e}")
    });
    let a = open(&format!("socketcan://{}", vcan.0));
    let b = open(&format!("socketcan://{}?filter=100:700", vcan.0));
    assert_eq!(wait_link(&a, |s| *s == LinkState::Up).await, LinkState::Up);
    assert_eq!(wait_link(&b, |s| *s == LinkState::Up).await, LinkState::Up);
    let mut on_b = b.attach("b");
    on_b.subscribe("can.**").unwrap();
    let on_a = a.attach("a");
    let bytes = |v: &[u8]| Value::Bytes(v.to_vec());
    // filtered out by the kernel, then one that passes
    on_a.send("can.200", DataMap::new().with("data", bytes(&[9])))
        .await
        .unwrap();
    on_a.send("can.1ab", DataMap::new().with("data", bytes(&[1, 2])))
        .await
        .unwrap();
    let m = tokio::time::timeout(Duration::from_secs(5), on_b.recv())
        .await
        .expect("a frame within 5 s")
        .expect("open");
    assert_eq!(
        CanFrame::from_message(m.topic.as_str(), &m.payload).unwrap(),
        CanFrame::data(0x1AB, false, &[1, 2]).unwrap()
    );
}
