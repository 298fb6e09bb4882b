//! The serial media over real pseudo-terminals: a `pty://` medium and a `serial://` medium that opens
//! its other end. NMEA sentences both ways, rejections counted, the link lost and found again.

use seabus_medium::framing::nmea_sentence;
use seabus_medium::{DataMap, Interface, LinkState, Medium, Node, Payload, SendError};
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::time::timeout;

const WAIT: Duration = Duration::from_secs(5);

fn place() -> (tempfile::TempDir, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frontseat").display().to_string();
    (dir, path)
}

async fn wait_link(m: &Medium, up: bool) {
    let mut w = m.watch_link();
    let res = timeout(WAIT, w.wait_for(|s| matches!(s, LinkState::Up) == up)).await;
    assert!(
        res.is_ok(),
        "link of {} never became {}: {:?}",
        m.name(),
        if up { "up" } else { "down" },
        m.link_state()
    );
}

async fn text(port: &mut Interface) -> (String, String) {
    let m = timeout(WAIT, port.recv())
        .await
        .expect("a frame arrives")
        .unwrap();
    let bytes = m.payload.as_bytes().expect("frames are bytes").to_vec();
    (m.topic.to_string(), String::from_utf8(bytes).unwrap())
}

#[tokio::test]
async fn nmea_sentences_cross_a_pseudo_terminal_both_ways() {
    let (_dir, path) = place();
    let node = Node::new("n");
    let front = seabus_medium_serial::schemes()
        .open("front", &format!("pty://{path}"), &node)
        .unwrap();
    let back = seabus_medium_serial::schemes()
        .open("back", &format!("serial://{path}?baud=19200"), &node)
        .unwrap();
    wait_link(&back, true).await;
    let mut front_rx = front.attach("sim").subscribed("nmea.**").unwrap();
    let mut back_rx = back.attach("driver").subscribed("nmea.**").unwrap();
    // a sentence without checksum gets one on the way out
    back.attach("tx")
        .send("out", Payload::from(b"$OSD,G,C,S,P,,,,".as_slice()))
        .await
        .unwrap();
    let (topic, s) = text(&mut front_rx).await;
    assert_eq!(topic, "nmea.OSD");
    assert_eq!(s, nmea_sentence(b'$', "OSD,G,C,S,P,,,,"));
    front
        .attach("tx")
        .send(
            "out",
            Payload::from(b"$C82.8P-3.89R-2.63T20.3D3.2*78".as_slice()),
        )
        .await
        .unwrap();
    assert_eq!(
        text(&mut back_rx).await,
        ("nmea.C".into(), "$C82.8P-3.89R-2.63T20.3D3.2*78".into())
    );
    // a datamap is not a sentence
    let err = back
        .attach("tx")
        .send("out", DataMap::new())
        .await
        .unwrap_err();
    assert!(err.to_string().contains("carries bytes or text"), "{err}");
}

#[tokio::test]
async fn garbage_and_bad_sentences_are_counted_and_the_next_one_arrives() {
    let (_dir, path) = place();
    let node = Node::new("n");
    // the device is not there yet: the medium opens anyway, link down, and keeps trying
    let back = seabus_medium_serial::schemes()
        .open("back", &format!("serial://{path}?reopen=50ms"), &node)
        .unwrap();
    assert!(matches!(back.link_state(), LinkState::Down(_)));
    let mut rx = back.attach("driver").subscribed("nmea.**").unwrap();
    let sent = back
        .attach("tx")
        .send("x", Payload::from(b"$A,1".as_slice()))
        .await;
    assert!(matches!(sent, Err(SendError::LinkDown { .. })), "{sent:?}");
    // a bare pseudo-terminal whose far end is linked at the path: raw bytes go in as they are
    let (mut master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let name = tokio_serial::SerialPort::name(&slave).unwrap();
    let held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&name)
        .unwrap();
    drop(slave);
    std::os::unix::fs::symlink(&name, &path).unwrap();
    wait_link(&back, true).await;
    let good = nmea_sentence(b'$', "GPHDT,12.5,T");
    let mut junk = b"\x01\x02noise\r\n".to_vec();
    junk.extend_from_slice(b"$GPHDT,1.0,T*00\r\n");
    junk.extend(std::iter::repeat_n(b'Z', 10_000));
    junk.extend_from_slice(b"\r\n$GPGGA,cut short");
    // a sentence 10 kB long that never ends: the next `$` starts afresh
    junk.extend_from_slice(b"$GPTXT,");
    junk.extend(std::iter::repeat_n(b'Y', 10_000));
    junk.extend_from_slice(format!("{good}\r\n").as_bytes());
    master.write_all(&junk).await.unwrap();
    let (topic, s) = text(&mut rx).await;
    assert_eq!((topic.as_str(), s.as_str()), ("nmea.GPHDT", good.as_str()));
    assert!(rx.try_recv().is_err(), "only the good sentence got through");
    let st = back.stats().rejected;
    assert_eq!(st.get("garbage"), Some(&2), "{st:?}");
    assert_eq!(st.get("bad-checksum"), Some(&1), "{st:?}");
    assert_eq!(st.get("truncated"), Some(&1), "{st:?}");
    assert_eq!(st.get("too-long"), Some(&1), "{st:?}");
    // every byte of them is counted as dropped: 7 + 10 000 of garbage, the 15 of the bad
    // checksum, the 16 cut short and the 10 007 of the sentence too long (line endings aside)
    let dropped = async {
        while back.stats().dropped_bytes < 20_045 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    };
    let _ = timeout(WAIT, dropped).await;
    assert_eq!(back.stats().dropped_bytes, 20_045);
    drop(held);
}

#[tokio::test]
async fn a_lost_device_is_reported_and_reopened_by_itself() {
    let (_dir, path) = place();
    let node = Node::new("n");
    let front = seabus_medium_serial::schemes()
        .open("front", &format!("pty://{path}"), &node)
        .unwrap();
    let back = seabus_medium_serial::schemes()
        .open("back", &format!("serial://{path}?reopen=100ms"), &node)
        .unwrap();
    wait_link(&back, true).await;
    let mut rx = back.attach("driver").subscribed("nmea.**").unwrap();
    // the far end goes away: the link goes down, sends fail at once
    front.close();
    drop(front);
    wait_link(&back, false).await;
    let err = back
        .attach("tx")
        .send("x", Payload::from(b"$A,1".as_slice()))
        .await
        .unwrap_err();
    assert!(matches!(err, SendError::LinkDown { .. }), "{err}");
    assert!(
        !std::path::Path::new(&path).exists(),
        "the link was removed with the terminal"
    );
    // it comes back: the medium reopens it without being asked
    let front = seabus_medium_serial::schemes()
        .open("front", &format!("pty://{path}"), &node)
        .unwrap();
    wait_link(&back, true).await;
    let tx = front.attach("tx");
    let good = nmea_sentence(b'$', "GPHDT,7.0,T");
    // the reopened side may take a moment to be read: send until it arrives
    let mut got = None;
    for _ in 0..20 {
        tx.send("out", Payload::from(good.as_bytes()))
            .await
            .unwrap();
        if let Ok(Some(m)) = timeout(Duration::from_millis(250), rx.recv()).await {
            got = Some(m);
            break;
        }
    }
    let m = got.expect("data flows again");
    assert_eq!(m.payload.as_bytes().unwrap().as_ref(), good.as_bytes());
}
