//! What a console costs a small computer: password checks give their working memory back, so ten
//! log-ins one after the other leave a running system's resident memory where it was (each check
//! uses argon2id's 19 MiB, which a process that kept it would hold for good).

mod common;
use common::*;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::time::Duration;

/// The resident memory of process `pid`, in bytes (Linux).
fn resident(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("the process runs");
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("VmRSS in /proc/PID/status");
    kb * 1024
}

/// Logs in over plain HTTP as a browser's form does; the answer's status line and headers.
fn log_in(addr: SocketAddr, name: &str, password: &str) -> String {
    let body = format!("name={name}&password={password}");
    let mut s = TcpStream::connect(addr).expect("the console accepts");
    s.set_read_timeout(Some(Duration::from_secs(20)))
        .expect("a timeout");
    write!(
        s,
        "POST /login HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .expect("request sent");
    let mut answer = String::new();
    let _ = s.read_to_string(&mut answer);
    answer
        .split("\r\n\r\n")
        .next()
        .unwrap_or_default()
        .to_string()
}

#[test]
fn ten_log_ins_leave_the_console_s_memory_where_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let users = dir.path().join("users.xml");
    add_user(&users, "ana", "pilot", "ana-password-1");
    let layout = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/console/pilot.xml");
    let (_d, path) = system_file(
        "console.xml",
        &format!(
            r#"<seabus node="small">
  <medium name="bus" url="inproc://"/>
  <module name="sim" type="vehicle-sim" medium="bus"/>
  <console medium="bus" listen="127.0.0.1:{}" users="{}" layouts="{}"/>
</seabus>"#,
            free_port(),
            users.display(),
            layout.display()
        ),
    );
    let mut run = spawn_run(&path, &["--for", "60"]);
    let err = run.stderr.take().unwrap();
    let mut lines = BufReader::new(err).lines().map_while(Result::ok);
    let addr: SocketAddr = lines
        .by_ref()
        .take(50)
        .find_map(|l| {
            l.trim()
                .strip_prefix("Console: http://")
                .map(|a| a.parse().expect("an address"))
        })
        .expect("the console says where it listens");
    std::thread::spawn(move || lines.for_each(drop));
    // one log-in first, so that what the first one sets up once (sessions, the pages) is in both
    let head = log_in(addr, "ana", "ana-password-1");
    assert!(head.starts_with("HTTP/1.1 303"), "{head}");
    std::thread::sleep(Duration::from_millis(500));
    let before = resident(run.id());
    for i in 0..10 {
        let head = log_in(addr, "ana", "ana-password-1");
        assert!(head.starts_with("HTTP/1.1 303"), "log-in {i}: {head}");
        assert!(
            head.to_lowercase().contains("set-cookie: seabus_session="),
            "log-in {i}: {head}"
        );
    }
    std::thread::sleep(Duration::from_millis(500));
    let after = resident(run.id());
    let grown = after as f64 / 1e6 - before as f64 / 1e6;
    assert!(
        grown < 8.0,
        "resident memory {:.1} MB before ten log-ins, {:.1} MB after",
        before as f64 / 1e6,
        after as f64 / 1e6
    );
}
