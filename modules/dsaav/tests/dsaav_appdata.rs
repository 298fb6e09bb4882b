//! The application data of the DSAAV configuration database survives a writer killed at any
//! moment: the file on disk is always the old version or the new one, complete, and loads.
//!
//! The test runs its own binary again as a child (test `writer_child`, which does nothing unless
//! [`CHILD`] names a directory). The child opens the database there and puts version after version
//! of a large record, reporting each version once it is written; the parent kills it with SIGKILL
//! at random moments and checks what is on disk.

use seabus_dsaav::config::{Database, Sections};
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The environment variable naming the child's directory.
const CHILD: &str = "SEABUS_TEST_APPDATA_WRITER";

/// Characters in a record after its version number: large enough that a kill often lands in the
/// middle of writing one.
const RECORD_LEN: usize = 64 * 1024;

/// Rounds of spawn and kill.
const ROUNDS: usize = 30;

/// Most rounds, when none of the first [`ROUNDS`] killed the child in the middle of a write.
const MAX_ROUNDS: usize = 200;

/// How long a child writes when nobody kills it.
const CHILD_LIMIT: Duration = Duration::from_secs(20);

/// The configuration data both processes use; the record masks nothing in it.
const CONFIG: &str = "[Data]\nrecord = 0 from the configuration\n";

/// The record of version `n`: the number, a space, and a letter that depends on `n`, repeated.
fn record(n: u64) -> String {
    let letter = char::from(b'a' + (n % 26) as u8);
    format!("{n} {}", letter.to_string().repeat(RECORD_LEN))
}

/// The version of the application data in `dir`: 0 when there is no file yet. Panics unless the
/// file loads and holds one complete record.
fn version_on_disk(dir: &Path) -> u64 {
    let path = dir.join("appdata.ini");
    if !path.exists() {
        return 0;
    }
    let app =
        Sections::read(&path).unwrap_or_else(|e| panic!("the application data is damaged: {e}"));
    let names: Vec<&str> = app.iter().map(|s| s.name()).collect();
    assert_eq!(names, ["Data"], "sections on disk");
    let text = &app.get("Data", "record").expect("a record on disk").value;
    let n: u64 = text
        .split(' ')
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| {
            panic!(
                "a record without a version: {:?}",
                &text[..text.len().min(40)]
            )
        });
    assert!(*text == record(n), "record {n} is not complete");
    n
}

/// The version in a line the child printed with `word`; the test harness may have printed the
/// test's name before it on the same line.
fn reported(line: &str, word: &str) -> Option<u64> {
    line.split_once(word)?.1.trim().parse().ok()
}

/// The child: puts versions of the record into the application data in `CHILD`'s directory until
/// killed, printing `open N` when it has loaded version N and `written N` after each version.
#[test]
#[ignore = "run by killed_writer_leaves_the_old_or_the_new_application_data as a child process"]
fn writer_child() {
    let Some(dir) = std::env::var_os(CHILD) else {
        return;
    };
    let dir = Path::new(&dir);
    let mut db = Database::open(&dir.join("config.ini"), &dir.join("appdata.ini"))
        .unwrap_or_else(|e| panic!("cannot open: {e}"));
    let start = match db.get("Data", "record") {
        Ok(v) => v
            .text
            .split(' ')
            .next()
            .and_then(|n| n.parse::<u64>().ok())
            .expect("a version"),
        Err(e) => panic!("no record: {e}"),
    };
    let mut out = std::io::stdout();
    writeln!(out, "open {start}").expect("stdout");
    out.flush().expect("stdout");
    let began = Instant::now();
    let mut n = start;
    while began.elapsed() < CHILD_LIMIT {
        n += 1;
        db.put_str("Data", "record", &record(n)).expect("written");
        writeln!(out, "written {n}").expect("stdout");
        out.flush().expect("stdout");
    }
}

#[test]
fn killed_writer_leaves_the_old_or_the_new_application_data() {
    // On the build's disk rather than in /tmp, which may be a RAM disk where writes take no time.
    let dir = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).expect("a temporary directory");
    std::fs::write(dir.path().join("config.ini"), CONFIG).expect("written");
    let exe = std::env::current_exe().expect("the test binary");
    let seed = fastrand::u64(..);
    let mut rng = fastrand::Rng::with_seed(seed);
    let began = Instant::now();
    let mut writes = 0;
    let mut interrupted = 0;
    let mut round = 0;
    while round < ROUNDS || (interrupted == 0 && round < MAX_ROUNDS) {
        let before = version_on_disk(dir.path());
        let temps_before = temp_files(dir.path());
        let mut child = Command::new(&exe)
            .args(["writer_child", "--exact", "--ignored", "--nocapture"])
            .args(["--test-threads", "1"])
            .env(CHILD, dir.path())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("the child starts");
        let mut lines = BufReader::new(child.stdout.take().expect("piped")).lines();
        let opened = lines
            .by_ref()
            .map_while(Result::ok)
            .find_map(|l| reported(&l, "open "));
        let Some(opened) = opened else {
            let status = child.wait();
            panic!("round {round} (seed {seed}): the child did not open the database: {status:?}");
        };
        assert_eq!(
            opened, before,
            "round {round}: the child loaded another version"
        );
        std::thread::sleep(Duration::from_micros(rng.u64(0..=25_000)));
        let running = child.try_wait().expect("the child's status").is_none();
        child.kill().expect("killed");
        child.wait().expect("reaped");
        assert!(
            running,
            "round {round}: the child stopped before it was killed"
        );
        let last = lines
            .map_while(Result::ok)
            .filter_map(|l| reported(&l, "written "))
            .last()
            .unwrap_or(before);
        let after = version_on_disk(dir.path());
        assert!(
            after == last || after == last + 1,
            "round {round} (seed {seed}): version {after} on disk after the child reported {last}"
        );
        writes += last.saturating_sub(before);
        // A kill between creating the temporary file and renaming it leaves the temporary file
        // behind: the kill landed in the middle of a write, and the file loaded all the same.
        interrupted += usize::from(temp_files(dir.path()) > temps_before);
        assert!(
            began.elapsed() < Duration::from_secs(120),
            "round {round}: too slow"
        );
        round += 1;
    }
    assert!(writes > 0, "no child wrote anything (seed {seed})");
    assert!(
        interrupted > 0,
        "no kill landed in the middle of a write in {round} rounds (seed {seed})"
    );
}

/// How many temporary files writers left in `dir`.
fn temp_files(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .expect("listed")
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .count()
}
