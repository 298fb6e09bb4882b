//! The program a vehicle runs is stripped, its line tables moved beside it by `scripts/split-debug`
//! (the last step of `scripts/dist`): a panic's backtrace names the functions and their files and
//! lines while the `.debug` file sits beside the program, and none without it.

mod common;
use common::succeeds;
use std::path::Path;
use std::process::Command;

/// A program that panics two calls deep, as a vehicle's would.
const CRASH: &str = "fn main() {
    let log: Vec<u8> = Vec::new();
    steer(&log);
}

#[inline(never)]
fn steer(log: &[u8]) {
    panic!(\"the log ends at {} bytes\", log.len());
}
";

/// What the program at `path` writes to stderr when it panics with a backtrace asked for.
fn crash(path: &Path) -> String {
    let out = Command::new(path)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("the program runs");
    assert!(!out.status.success(), "it panics");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn a_stripped_programs_backtrace_reads_names_and_lines_from_the_file_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("crash.rs");
    std::fs::write(&source, CRASH).unwrap();
    let built = dir.path().join("crash");
    succeeds(
        Command::new("rustc")
            .args(["-C", "debuginfo=line-tables-only", "-C", "strip=none", "-o"])
            .arg(&built)
            .arg(&source),
        "rustc",
    );
    let vehicle = dir.path().join("vehicle");
    succeeds(
        Command::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/split-debug"))
            .arg(&built)
            .arg(&vehicle),
        "scripts/split-debug",
    );
    let program = vehicle.join("crash");
    let debug = vehicle.join("crash.debug");
    assert!(
        std::fs::metadata(&program).unwrap().len() < std::fs::metadata(&built).unwrap().len(),
        "the installed program is the smaller"
    );

    // the panic's own message says where it was raised whatever is installed: the backtrace's
    // frames are what need the line tables
    let frame_line = |text: &str| {
        text.lines()
            .any(|l| l.trim_start().starts_with("at ") && l.contains("crash.rs:8"))
    };
    let beside = crash(&program);
    assert!(beside.contains("crash::steer"), "{beside}");
    assert!(frame_line(&beside), "{beside}");

    std::fs::rename(&debug, dir.path().join("elsewhere.debug")).unwrap();
    let alone = crash(&program);
    assert!(alone.contains("the log ends at 0 bytes"), "{alone}");
    assert!(!alone.contains("crash::steer"), "{alone}");
    assert!(!frame_line(&alone), "{alone}");
}
