//! What the default build says it holds: `seabus schemes` lists every scheme of every medium
//! family with what it opens and leaves no family out; `seabus --version` names the version and
//! the media; a URL of a scheme no family has is refused by `seabus check`.

mod common;
use common::*;

/// Every scheme of the default build with its family, in the order `seabus schemes` lists them.
const SCHEMES: [(&str, &str); 15] = [
    ("inproc", "inproc"),
    ("udp", "udp"),
    ("serial", "serial"),
    ("pty", "serial"),
    ("slcan", "can"),
    ("slcan+pty", "can"),
    ("cannelloni", "can"),
    ("socketcan", "can"),
    ("udpm", "lcm"),
    ("dsaav+eth", "dsaav"),
    ("dsaav+udp", "dsaav"),
    ("dsaav+inproc", "dsaav"),
    ("moos", "moos"),
    ("zenoh", "zenoh"),
    ("mavlink", "mavlink"),
];

fn stdout_of(args: &[&str]) -> String {
    let out = seabus().args(args).output().expect("seabus runs");
    assert!(
        out.status.success(),
        "seabus {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("UTF-8")
}

#[test]
fn schemes_lists_every_scheme_of_the_default_build_with_what_it_opens() {
    let text = stdout_of(&["schemes"]);
    let registry = schemes();
    let mut listed = Vec::new();
    for line in text.lines() {
        assert!(
            !line.starts_with("not compiled in"),
            "the default build leaves nothing out: {line}\n{text}"
        );
        let mut words = line.split_whitespace();
        let (name, family) = (
            words.next().expect("a scheme"),
            words.next().expect("its family"),
        );
        let summary = words.collect::<Vec<_>>().join(" ");
        assert!(!summary.is_empty(), "a summary for {name}: {line}");
        // the summary is the one the medium family registers
        if let Some(s) = registry.iter().find(|s| s.name == name) {
            assert_eq!(summary, s.summary, "{line}");
        }
        listed.push((name, family));
    }
    assert_eq!(listed, SCHEMES, "{text}");
}

#[test]
fn version_names_the_version_and_the_media_compiled_in() {
    let text = stdout_of(&["--version"]);
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(concat!("seabus ", env!("CARGO_PKG_VERSION"))),
        "{text}"
    );
    let media = lines.next().expect("a media line");
    assert_eq!(
        media,
        "media: inproc (inproc) udp (udp) serial (serial, pty) \
         can (slcan, slcan+pty, cannelloni, socketcan) lcm (udpm) \
         dsaav (dsaav+eth, dsaav+udp, dsaav+inproc) moos (moos) zenoh (zenoh) mavlink (mavlink)",
        "{text}"
    );
    // the families, without their schemes
    let families: Vec<&str> = media
        .trim_start_matches("media:")
        .split(')')
        .filter_map(|f| f.split('(').next())
        .map(str::trim)
        .filter(|f| !f.is_empty())
        .collect();
    assert_eq!(
        families,
        [
            "inproc", "udp", "serial", "can", "lcm", "dsaav", "moos", "zenoh", "mavlink"
        ]
    );
    assert_eq!(lines.next(), None, "no family is left out: {text}");
}

#[test]
fn check_refuses_a_scheme_no_family_has() {
    let (_dir, path) = system_file(
        "nosuch.xml",
        "<seabus node=\"n\">\n  <medium name=\"far\" url=\"nosuch://x\"/>\n</seabus>\n",
    );
    let out = check(&path);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "{}:2:22: unknown medium scheme `nosuch://` in `nosuch://x`",
            path.display()
        )),
        "{err}"
    );
}
