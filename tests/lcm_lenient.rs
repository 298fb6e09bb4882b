//! What liblcm reads, a seabus bridge reads too: a C program (lcm-gen's C types, liblcm) sends a
//! boolean of 4, a Latin-1 string and a message with bytes after it; seabus bridges them to a
//! second LCM group, where a C subscriber receives exactly what a C subscriber on the first group
//! got (the boolean's byte 4 too), and each case is counted.

mod common;
use common::*;
use std::io::BufRead;
use std::time::{Duration, Instant};

#[test]
fn a_bridge_carries_what_liblcm_reads_and_counts_each_case() {
    let dir = tempfile::tempdir().unwrap();
    let peer = lcm_c_peer(dir.path());
    let first = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let second = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="gw">
  <medium name="first" url="{}"/>
  <medium name="second" url="{}"/>
  <bridge name="relay" media="first second" lcm_types="lcm_peer.lcm">
    <route from="first" to="second" topics="READINGS" lcm="peer.reading_t"/>
  </bridge>
</seabus>"#,
        first.replace('&', "&amp;"),
        second.replace('&', "&amp;")
    );
    let path = dir.path().join("relay.xml");
    std::fs::write(&path, system).unwrap();

    // liblcm's own delivery on the first group, and what arrives on the second
    let (direct, direct_lines) = lcm_c_receiver(&peer, "readings", &first, "READINGS", 3, 15);
    let (bridged, bridged_lines) = lcm_c_receiver(&peer, "readings", &second, "READINGS", 3, 15);
    let mut run = spawn_run(&path, &["--for", "6"]);
    let stderr = run.stderr.take().unwrap();
    let (tx, log) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            let _ = tx.send(line.clone());
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let deadline = Instant::now() + Duration::from_secs(10);
    while !log
        .recv_timeout(Duration::from_millis(100))
        .is_ok_and(|l| l.contains("running"))
    {
        assert!(Instant::now() < deadline, "seabus run starts within 10 s");
    }
    // the media join their groups as they start
    std::thread::sleep(Duration::from_millis(500));
    let sent = c_send(&peer, &first);
    assert!(sent, "the C program sent its messages");

    let direct = lcm_c_lines(direct, direct_lines, Duration::from_secs(15));
    let bridged = lcm_c_lines(bridged, bridged_lines, Duration::from_secs(15));
    assert_eq!(
        direct,
        [
            "utime=1 valid=4 label=6f6b depth=3ff8000000000000(1.5)",
            "utime=2 valid=1 label=636166e9 depth=4004000000000000(2.5)",
            "utime=3 valid=0 label=78 depth=400c000000000000(3.5)",
        ],
        "what liblcm delivers on the first group"
    );
    assert_eq!(
        bridged,
        [
            "utime=1 valid=4 label=6f6b depth=3ff8000000000000(1.5)",
            "utime=2 valid=1 label=636166e9 depth=4004000000000000(2.5)",
            "utime=3 valid=0 label=78 depth=400c000000000000(3.5)",
        ],
        "what arrives across the bridge: the same, the boolean's byte 4 too"
    );

    let status = wait_for(&mut run, Duration::from_secs(15)).expect("seabus run --for 6 ends");
    let all = reader.join().unwrap();
    assert!(status.success(), "{status}\n{all}");
    for (reason, what) in [
        (
            "lcm-bool-not-0-1",
            "boolean(s) neither 0 nor 1 read as true",
        ),
        (
            "lcm-string-not-utf8",
            "string(s) not UTF-8 decoded with U+FFFD",
        ),
        (
            "lcm-trailing-bytes",
            "2 byte(s) after the end of the message",
        ),
    ] {
        let lines: Vec<&str> = all
            .lines()
            .filter(|l| l.contains(&format!("reason=\"{reason}\"")))
            .collect();
        assert_eq!(lines.len(), 1, "{reason} said once:\n{all}");
        assert!(
            lines[0].contains("channel `READINGS`")
                && lines[0].contains(what)
                && lines[0].contains("count=1"),
            "{}",
            lines[0]
        );
    }
    assert!(!all.contains("lcm-codec"), "nothing refused:\n{all}");
}

/// Runs the C program sending the lenient cases on `url`.
fn c_send(peer: &std::path::Path, url: &str) -> bool {
    std::process::Command::new(peer)
        .args(["send-lenient", url, "READINGS"])
        .status()
        .expect("the C LCM peer runs")
        .success()
}
