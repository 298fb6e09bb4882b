//! Helpers shared by the end-to-end tests: the program, temporary system files, ports.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The `seabus` program under test.
pub fn seabus() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_seabus"));
    c.env_remove("RUST_LOG");
    c
}

/// Writes `text` to `name` in a fresh temporary directory (kept alive by the returned guard).
pub fn system_file(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join(name);
    std::fs::write(&path, text).expect("the system file is written");
    (dir, path)
}

/// Runs `seabus check FILE`.
pub fn check(path: &Path) -> Output {
    seabus()
        .arg("check")
        .arg(path)
        .output()
        .expect("seabus runs")
}

/// A UDP port nobody uses right now.
pub fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("an ephemeral port")
}

/// A multicast group of our own for one test.
pub fn group() -> String {
    format!("239.255.{}.{}", fastrand::u8(1..250), fastrand::u8(1..250))
}

/// Starts `seabus run FILE` with its output captured.
pub fn spawn_run(path: &Path, extra: &[&str]) -> Child {
    seabus()
        .arg("run")
        .arg(path)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("seabus run starts")
}

/// Sends SIGTERM to a child.
pub fn terminate(child: &Child) {
    // SAFETY: kill(2) on our own child's pid
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGTERM);
    }
}

/// Waits at most `limit` for a child to exit; kills it if it does not.
pub fn wait_for(child: &mut Child, limit: Duration) -> Option<std::process::ExitStatus> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    let _ = child.wait();
    None
}
