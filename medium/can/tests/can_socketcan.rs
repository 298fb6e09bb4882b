//! SocketCAN end to end: two media on a virtual CAN interface exchange frames. It needs a kernel
//! with CAN support and the vcan module; without them it says it was skipped and checks instead
//! that the medium reports why its link is down.

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
    fn new() -> Option<Vcan> {
        let name = format!("sbvcan{}", fastrand::u16(..1000));
        let ok = |args: &[&str]| {
            Command::new("ip")
                .args(args)
                .output()
                .is_ok_and(|o| o.status.success())
        };
        (ok(&["link", "add", "dev", &name, "type", "vcan"])
            && ok(&["link", "set", "up", "dev", &name]))
        .then_some(Vcan(name))
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
async fn frames_cross_a_virtual_can_interface() {
    if !kernel_has_can() {
        eprintln!(
            "SKIPPED frames_cross_a_virtual_can_interface: this kernel has no SocketCAN support \
             (socket(AF_CAN) fails); checking the medium's report instead"
        );
        let m = open("socketcan://can0");
        let s = wait_link(
            &m,
            |s| matches!(s, LinkState::Down(r) if r.contains("SocketCAN")),
        )
        .await;
        match s {
            LinkState::Down(reason) => assert!(
                reason.contains("this kernel has no SocketCAN support"),
                "{reason}"
            ),
            LinkState::Up => panic!("a CAN link came up on a kernel without CAN"),
        }
        return;
    }
    let Some(vcan) = Vcan::new() else {
        eprintln!(
            "SKIPPED frames_cross_a_virtual_can_interface: the kernel has CAN but no vcan \
             interface could be made (vcan module, or root, missing)"
        );
        return;
    };
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
