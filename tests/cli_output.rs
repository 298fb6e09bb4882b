//! What the command line prints, as a user reads it: `spy` ended by SIGTERM prints its table as on
//! Ctrl-C, `types` lines up its columns, `check` counts in words ("1 bridge"), and `export` into a
//! pipe its reader closed early ends quietly.

mod common;
use common::*;
use std::io::BufRead;
use std::process::Stdio;
use std::time::Duration;

#[test]
fn spy_ended_by_sigterm_prints_its_table_as_on_ctrl_c() {
    for (signal, stop) in [
        ("SIGTERM", terminate as fn(&std::process::Child)),
        ("SIGINT", interrupt),
    ] {
        let url = format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port());
        let spy = spawn_spy(&url, &["--for", "20"]);
        std::thread::sleep(Duration::from_millis(500));
        let out = seabus()
            .args([
                "pub",
                &url,
                "nav.depth",
                "depth=4",
                "--count",
                "3",
                "--rate",
                "20",
            ])
            .output()
            .expect("pub runs");
        assert!(out.status.success(), "{}", stderr(&out));
        std::thread::sleep(Duration::from_millis(300));
        stop(&spy);
        let out = finish(spy);
        let table = String::from_utf8_lossy(&out.stdout);
        assert_eq!(out.status.code(), Some(0), "{signal}: {}", stderr(&out));
        let lines: Vec<&str> = table.lines().collect();
        assert!(
            lines.first().is_some_and(|l| l.starts_with("topic ")),
            "{signal}: {table}"
        );
        let row: Vec<&str> = lines
            .iter()
            .find(|l| l.starts_with("nav.depth "))
            .unwrap_or_else(|| panic!("{signal}: no nav.depth row in {table}"))
            .split_whitespace()
            .collect();
        assert_eq!(row[1], "3", "{signal}: three messages counted: {table}");
    }
}

#[test]
fn types_lines_up_its_columns() {
    let out = seabus().arg("types").output().expect("types runs");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    // in each list, the column after the name starts at the same place on every line, two
    // spaces after the longest name
    let mut lists = 0;
    for section in ["module types:", "bridge types:", "standard datasets:"] {
        let rows: Vec<&str> = text
            .lines()
            .skip_while(|l| *l != section)
            .skip(1)
            .take_while(|l| l.starts_with("  "))
            .collect();
        assert!(!rows.is_empty(), "{section} in {text}");
        let longest = rows
            .iter()
            .map(|r| r[2..].split(' ').next().map_or(0, str::len))
            .max()
            .expect("rows");
        for r in &rows {
            let second = &r[2 + longest..];
            assert!(
                second.starts_with("  ") && !second[2..].starts_with(' '),
                "{section}: `{r}` does not line up at column {}",
                2 + longest + 2
            );
        }
        lists += 1;
    }
    assert_eq!(lists, 3);
}

#[test]
fn check_counts_in_words() {
    let (_dir, path) = system_file(
        "one.xml",
        r#"<seabus node="one">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="udp://239.255.42.9:47809?ttl=0"/>
  <module name="vehicle" type="vehicle-sim" medium="bus"/>
  <bridge name="up" media="bus net"><route topics="nav.**"/></bridge>
</seabus>
"#,
    );
    let out = check(&path);
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        format!("{}: valid (2 media, 1 module, 1 bridge)\n", path.display())
    );
}

#[test]
fn export_into_a_pipe_closed_early_ends_quietly() {
    // a log far larger than a pipe holds
    let dir = tempfile::tempdir().expect("a temporary directory");
    let log = dir.path().join("big.lcm");
    let mut w = seabus_medium::eventlog::Writer::create(&log).expect("the log is made");
    let data = seabus_medium::binary::encode(
        &seabus_medium::DataMap::new()
            .with("depth", 4.5f64)
            .with("note", "x".repeat(200)),
    )
    .expect("a datamap");
    for i in 0..5000i64 {
        w.write(1_700_000_000_000_000 + i * 1000, "nav.depth", &data)
            .expect("written");
    }
    w.flush().expect("flushed");
    // `seabus export … | head -n 1`
    let mut export = seabus()
        .arg("export")
        .arg(&log)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("export starts");
    let first = {
        let mut out = std::io::BufReader::new(export.stdout.take().expect("piped"));
        let mut line = String::new();
        out.read_line(&mut line).expect("a line");
        line
    };
    assert!(first.contains("\"topic\":\"nav.depth\""), "{first}");
    let out = finish(export);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert_eq!(stderr(&out), "", "nothing said about the closed pipe");
}
