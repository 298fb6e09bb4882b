//! `seabus check FILE` and `seabus run FILE` on systems with a console: what one refuses the other
//! refuses with the same message, both warn alike about layouts, and both accept a valid console.

mod common;
use common::*;
use std::path::Path;
use std::process::Output;

/// The system: a simulated vehicle on an in-process bus, and a console on any free port.
const SYSTEM: &str = r#"<seabus node="check-run">
  <medium name="bus" url="inproc://"/>
  <module name="vehicle" type="vehicle-sim" medium="bus"/>
  <console medium="bus" listen="127.0.0.1:0" users="users.xml" layouts="pilot.xml"/>
</seabus>
"#;

/// A layout that fits the system: every field the vehicle requires, ranges within the limits.
const LAYOUT: &str = r#"<layout name="pilot">
  <command name="course" topic="cmd.course" fields="heading=0.0, depth=0.0, speed=0.0" max.speed="2"/>
  <readout bind="nav.depth.depth"/>
  <slider id="speed" command="course.speed" min="0" max="2"/>
  <number id="heading" command="course.heading" min="0" max="360"/>
</layout>
"#;

/// What both commands must do with a case.
enum Expect {
    /// Refuse it (exit 2) with this message (`{dir}` is the case's directory).
    Error(&'static str),
    /// Accept it with these warnings: `check` exits 1, `run` starts and logs them.
    Warnings(&'static [&'static str]),
}

/// A system and its files written to a directory, as a user would lay them out.
struct Case {
    what: &'static str,
    /// The system file, `SYSTEM` with these replacements.
    system: &'static [(&'static str, &'static str)],
    /// The layout file `pilot.xml`, `LAYOUT` with these replacements.
    layout: &'static [(&'static str, &'static str)],
    /// Files besides the system and layout (a users file `users.xml` is always written first).
    files: &'static [(&'static str, &'static str)],
    expect: Expect,
}

/// `text` with each `(from, to)` replaced; panics when `from` is not in it (a case that tests
/// nothing).
fn replaced(text: &str, edits: &[(&str, &str)]) -> String {
    let mut out = text.to_string();
    for (from, to) in edits {
        assert!(out.contains(from), "`{from}` is not in {out}");
        out = out.replacen(from, to, 1);
    }
    out
}

/// A users file with one pilot, made by `seabus user add` (once: the hash takes a while).
fn users_file() -> String {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("users.xml");
    let mut child = seabus()
        .args(["user", "add"])
        .arg(&path)
        .args(["ana", "--roles", "pilot"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("seabus user add starts");
    std::io::Write::write_all(child.stdin.as_mut().expect("stdin piped"), b"a-password\n")
        .expect("the password is written");
    let out = child.wait_with_output().expect("seabus user add ends");
    assert!(out.status.success(), "{out:?}");
    std::fs::read_to_string(&path).expect("the users file is written")
}

/// Writes `case` to a fresh directory; returns it and the system file.
fn write(case: &Case, users: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let (dir, system) = system_file("system.xml", &replaced(SYSTEM, case.system));
    let d = dir.path();
    std::fs::write(d.join("users.xml"), users).expect("users written");
    std::fs::write(d.join("pilot.xml"), replaced(LAYOUT, case.layout)).expect("layout written");
    for (name, text) in case.files {
        std::fs::write(d.join(name), text).expect("file written");
    }
    (dir, system)
}

/// `seabus run FILE --for 2`.
fn run(path: &Path) -> Output {
    seabus()
        .arg("run")
        .arg(path)
        .args(["--for", "2"])
        .output()
        .expect("seabus runs")
}

/// What is wrong with how `check` and `run` treated `case`, if anything.
fn judge(case: &Case, dir: &Path, check: &Output, run: &Output) -> Option<String> {
    let text = |o: &Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let (check_err, run_err) = (text(check), text(run));
    let d = dir.display().to_string();
    let problem = match &case.expect {
        Expect::Error(msg) => {
            let want = msg.replace("{dir}", &d);
            let codes = (check.status.code(), run.status.code());
            if codes != (Some(2), Some(2)) {
                format!("exit codes (check, run) {codes:?}, not (2, 2)")
            } else if check_err.trim_end() != want || run_err.trim_end() != want {
                format!("want {want}")
            } else {
                return None;
            }
        }
        Expect::Warnings(warnings) => {
            let want: Vec<String> = warnings.iter().map(|w| w.replace("{dir}", &d)).collect();
            let codes = (check.status.code(), run.status.code());
            let got: Vec<&str> = check_err.lines().collect();
            let logged: Vec<&str> = run_err.lines().filter(|l| l.contains("warning:")).collect();
            let same = logged.len() == want.len()
                && want
                    .iter()
                    .zip(&logged)
                    .all(|(w, l)| l.ends_with(w.as_str()));
            if codes != (Some(1), Some(0)) {
                format!("exit codes (check, run) {codes:?}, not (1, 0)")
            } else if got != want || !same {
                format!("want\n{}", want.join("\n"))
            } else if !run_err.contains("Console: http://127.0.0.1:") {
                "run did not start the console".to_string()
            } else {
                return None;
            }
        }
    };
    Some(format!(
        "{}: {problem}\n  check: {check_err}\n  run: {run_err}",
        case.what
    ))
}

const NEEDS_USERS: &str = "{dir}/system.xml:4:3: a console listening on 0.0.0.0:0 needs `users`, a \
     users file with password hashes (`seabus user add FILE NAME --roles pilot` writes one): only a \
     console on a loopback address (such as 127.0.0.1) makes one-time users of its own";

/// Broken consoles and layouts, each with what both commands must say.
fn cases() -> Vec<Case> {
    let error = |what, system, layout, files, msg| Case {
        what,
        system,
        layout,
        files,
        expect: Expect::Error(msg),
    };
    vec![
        error(
            "no users file on an address beyond this machine",
            &[
                (r#" users="users.xml""#, ""),
                (r#"listen="127.0.0.1:0""#, r#"listen="0.0.0.0:0""#),
            ],
            &[],
            &[],
            NEEDS_USERS,
        ),
        error(
            "the users file is missing",
            &[(r#"users="users.xml""#, r#"users="crew.xml""#)],
            &[],
            &[],
            "{dir}/system.xml:4:46: attribute `users`: cannot read the users file \
             {dir}/crew.xml: No such file or directory (os error 2)",
        ),
        error(
            "a user without a password",
            &[(r#"users="users.xml""#, r#"users="crew.xml""#)],
            &[],
            &[(
                "crew.xml",
                "<users>\n  <user name=\"ana\" roles=\"pilot\"/>\n</users>\n",
            )],
            "{dir}/crew.xml:2:3: <user> is missing attribute `password`",
        ),
        error(
            "the console's medium is unknown",
            &[(r#"<console medium="bus""#, r#"<console medium="net""#)],
            &[],
            &[],
            "{dir}/system.xml:4:12: attribute `medium`: no medium called `net`",
        ),
        error(
            "a console attribute that does not read",
            &[(
                r#"layouts="pilot.xml""#,
                r#"layouts="pilot.xml" ack_timeout="soon""#,
            )],
            &[],
            &[],
            "{dir}/system.xml:4:84: attribute `ack_timeout`: `soon` is not a duration (such as 5s)",
        ),
        error(
            "two consoles on one port",
            &[(
                r#"  <console medium="bus" listen="127.0.0.1:0""#,
                "  <console medium=\"bus\" listen=\"0.0.0.0:47001\" users=\"users.xml\" \
                 layouts=\"pilot.xml\"/>\n  <console medium=\"bus\" listen=\"127.0.0.1:47001\"",
            )],
            &[],
            &[],
            "{dir}/system.xml:5:25: attribute `listen`: `127.0.0.1:47001`: the console at line \
             4 listens on 0.0.0.0:47001 already; give each console a port of its own",
        ),
        error(
            "two consoles keeping their sessions in one file",
            &[(
                r#"  <console medium="bus" listen="127.0.0.1:0""#,
                "  <console medium=\"bus\" listen=\"127.0.0.1:0\" users=\"users.xml\" \
                 layouts=\"pilot.xml\"/>\n  <console medium=\"bus\" listen=\"127.0.0.1:0\"",
            )],
            &[],
            &[],
            "{dir}/system.xml:5:3: the console at line 4 keeps its sessions in \
             {dir}/users.sessions already; give each console a `sessions` file of its own",
        ),
        error(
            "the layout file is missing",
            &[(r#"layouts="pilot.xml""#, r#"layouts="pilot.xml helm.xml""#)],
            &[],
            &[],
            "{dir}/system.xml:4:64: attribute `layouts`: cannot read the layout {dir}/helm.xml: \
             No such file or directory (os error 2)",
        ),
        error(
            "an XML syntax error in the layout",
            &[],
            &[(
                r#"<readout bind="nav.depth.depth"/>"#,
                r#"<readout bind="nav.depth.depth">"#,
            )],
            &[],
            "{dir}/pilot.xml:6:1: XML syntax error: ill-formed document: expected `</readout>`, \
             but `</layout>` was found",
        ),
        error(
            "a widget sends an unknown command",
            &[],
            &[(r#"command="course.speed""#, r#"command="cruise.speed""#)],
            &[],
            "{dir}/pilot.xml:4:22: attribute `command`: no command called `cruise`; commands: \
             course",
        ),
        error(
            "an unknown layout attribute",
            &[],
            &[(
                r#"<layout name="pilot">"#,
                r#"<layout name="pilot" colour="red">"#,
            )],
            &[],
            "{dir}/pilot.xml:1:22: unknown attribute `colour` on <layout>; expected one of: name, \
             title, roles, vehicle",
        ),
        error(
            "a template that uses itself",
            &[],
            &[(
                r#"<readout bind="nav.depth.depth"/>"#,
                r#"<template name="t"><use template="t"/></template><use template="t"/>"#,
            )],
            &[],
            "{dir}/pilot.xml:3:27: attribute `template`: template `t` uses itself: t → t",
        ),
        Case {
            what: "a slider beyond the command's maximum",
            system: &[],
            layout: &[(r#"min="0" max="2"/>"#, r#"min="0" max="3"/>"#)],
            files: &[],
            expect: Expect::Warnings(&[
                "{dir}/pilot.xml:4:3: warning: slider `speed` goes from 0 to 3, beyond the \
                 limits of `course.speed` (at most 2): the server refuses values beyond them",
            ]),
        },
        Case {
            what: "a number below the vehicle's minimum",
            system: &[],
            layout: &[(r#"min="0" max="360""#, r#"min="-10" max="360""#)],
            files: &[],
            expect: Expect::Warnings(&[
                "{dir}/pilot.xml:5:3: warning: number `heading` goes from -10 to 360, beyond the \
                 limits of field `heading` of dataset `course-command` (0 to 360): values beyond \
                 them are not valid for module `vehicle`",
            ]),
        },
        Case {
            what: "course widgets without a field the vehicle requires",
            system: &[],
            layout: &[(
                "heading=0.0, depth=0.0, speed=0.0",
                "heading=0.0, speed=0.0",
            )],
            files: &[],
            expect: Expect::Warnings(&[
                "{dir}/pilot.xml:4:3: warning: slider `speed` sends command `course` without \
                 `depth`, which module `vehicle` requires (dataset `course-command`); declare it \
                 in the command's `fields`",
                "{dir}/pilot.xml:5:3: warning: number `heading` sends command `course` without \
                 `depth`, which module `vehicle` requires (dataset `course-command`); declare it \
                 in the command's `fields`",
            ]),
        },
    ]
}

#[test]
fn check_and_run_refuse_and_warn_alike() {
    let users = users_file();
    let cases = cases();
    assert!(cases.len() >= 10);
    let mut wrong = Vec::new();
    for case in &cases {
        let (dir, system) = write(case, &users);
        let (c, r) = (check(&system), run(&system));
        wrong.extend(judge(case, dir.path(), &c, &r));
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n\n"));
}

#[test]
fn a_valid_console_is_accepted_by_both() {
    let case = Case {
        what: "valid",
        system: &[],
        layout: &[],
        files: &[],
        expect: Expect::Warnings(&[]),
    };
    let (dir, system) = write(&case, &users_file());
    let out = check(&system);
    assert_eq!(
        (out.status.code(), String::from_utf8_lossy(&out.stderr)),
        (Some(0), "".into())
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        format!(
            "{}: valid (1 medium, 1 module, 0 bridges)\n",
            dir.path().join("system.xml").display()
        )
    );
    let out = run(&system);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("Console: http://127.0.0.1:"), "{err}");
    assert!(!err.contains("warning:"), "{err}");
}

/// The system files among `dir`'s XML files (root element `<seabus>`), sorted.
fn system_files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out: Vec<_> = std::fs::read_dir(dir)
        .expect("the directory reads")
        .map(|e| e.expect("an entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "xml"))
        .filter(|p| {
            std::fs::read_to_string(p)
                .expect("the file reads")
                .contains("\n<seabus ")
        })
        .collect();
    out.sort();
    out
}

/// How `check` and `run` disagree on `file`, if they do: what `check` refuses (exit 2), `run`
/// refuses with the same message; what `check` accepts (0 or 1), `run` runs (exit 0).
fn disagreement(file: &Path) -> Option<String> {
    let (c, r) = (check(file), run(file));
    let text = |o: &Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let agree = match c.status.code() {
        Some(2) => r.status.code() == Some(2) && text(&c) == text(&r),
        Some(0 | 1) => r.status.code() == Some(0),
        _ => false,
    };
    (!agree).then(|| {
        format!(
            "{}: check exits {:?}, run {:?}\n  check: {}\n  run: {}",
            file.display(),
            c.status.code(),
            r.status.code(),
            text(&c),
            text(&r)
        )
    })
}

#[test]
fn check_and_run_agree_on_every_example_system() {
    let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let files: Vec<_> = system_files(&configs)
        .into_iter()
        .chain(system_files(&configs.join("fleet")))
        .collect();
    assert!(files.len() >= 10, "{files:?}");
    let wrong: Vec<String> = files.iter().filter_map(|f| disagreement(f)).collect();
    assert!(wrong.is_empty(), "{}", wrong.join("\n\n"));
    // the demo's system, as docs/console.md runs it: its console on 127.0.0.1 makes its own users
    let demo = check(&configs.join("demo.xml"));
    assert_eq!(demo.status.code(), Some(0), "{demo:?}");
}

/// A copy of `configs/demo.xml` in `dir` without its helm (the README's step 3), with the files
/// that travel with it when `companions`; its console and Foxglove server on any free port.
fn demo_copy(dir: &Path, companions: bool) -> std::path::PathBuf {
    let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let text = std::fs::read_to_string(configs.join("demo.xml")).expect("the demo reads");
    let helm = text
        .lines()
        .find(|l| l.contains(r#"<module name="helm""#))
        .expect("the demo has a helm");
    // (on any free ports, so that it runs beside other programs that use the demo's)
    let text = text
        .replacen(helm, "", 1)
        .replacen(
            r#"<console medium="bus""#,
            r#"<console listen="127.0.0.1:0" medium="bus""#,
            1,
        )
        .replacen(
            r#"<foxglove medium="bus""#,
            r#"<foxglove listen="127.0.0.1:0" medium="bus""#,
            1,
        );
    let path = dir.join("demo.xml");
    std::fs::write(&path, text).expect("the copy is written");
    if companions {
        std::fs::create_dir(dir.join("console")).expect("a console folder");
        for rel in [
            "demo-health.xml",
            "console/pilot.xml",
            "console/scientist.xml",
        ] {
            std::fs::copy(configs.join(rel), dir.join(rel)).expect("copied");
        }
    }
    path
}

#[test]
fn a_copy_of_the_demo_runs_with_its_files_and_is_refused_alike_without_them() {
    // with the files the README says travel with it: both accept it, and the console's one-time
    // users log in
    let dir = tempfile::tempdir().expect("a temporary directory");
    let copy = demo_copy(dir.path(), true);
    assert_eq!(disagreement(&copy), None);
    let out = check(&copy);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let mut running = spawn_run(&copy, &["--for", "20"]);
    let (password, url) = one_time_password(&mut running, "pilot");
    assert_logs_in(&url, "pilot", &password);
    drop(running);
    // alone: both refuse it, naming the health rules file that did not travel
    let alone = tempfile::tempdir().expect("a temporary directory");
    let copy = demo_copy(alone.path(), false);
    assert_eq!(disagreement(&copy), None);
    let out = check(&copy);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "parameter `rules`: `{}` does not exist",
            alone.path().join("demo-health.xml").display()
        )),
        "{err}"
    );
}
