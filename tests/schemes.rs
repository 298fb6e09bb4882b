//! What a build says it holds, for the default build and for a vehicle's build with only some
//! media (`--no-default-features --features serial,udp`): `seabus schemes` lists every scheme
//! compiled in with what it opens and names the families left out with their features; `seabus
//! --version` names the version and the media; `seabus check` refuses a medium left out, naming
//! the feature, and a URL of a scheme no family has.

mod common;
use common::*;

/// Every medium family in the order `seabus schemes` lists them: its name (which is its cargo
/// feature), whether this build has it, its schemes and a URL of its first scheme.
const FAMILIES: [(&str, bool, &[&str], &str); 8] = [
    (
        "udp",
        cfg!(feature = "udp"),
        &["udp"],
        "udp://127.0.0.1:47999",
    ),
    (
        "serial",
        cfg!(feature = "serial"),
        &["serial", "pty"],
        "serial:///dev/ttyS9",
    ),
    (
        "can",
        cfg!(feature = "can"),
        &["slcan", "slcan+pty", "cannelloni", "socketcan"],
        "slcan:///dev/ttyACM0",
    ),
    (
        "lcm",
        cfg!(feature = "lcm"),
        &["udpm"],
        "udpm://239.255.76.67:7667?ttl=0",
    ),
    (
        "dsaav",
        cfg!(feature = "dsaav"),
        &["dsaav+eth", "dsaav+udp", "dsaav+inproc"],
        "dsaav+inproc://",
    ),
    (
        "moos",
        cfg!(feature = "moos"),
        &["moos"],
        "moos://127.0.0.1:9000",
    ),
    (
        "zenoh",
        cfg!(feature = "zenoh"),
        &["zenoh"],
        "zenoh://?mode=peer",
    ),
    (
        "mavlink",
        cfg!(feature = "mavlink"),
        &["mavlink"],
        "mavlink://udpin:127.0.0.1:14550",
    ),
];

fn compiled()
-> impl Iterator<Item = &'static (&'static str, bool, &'static [&'static str], &'static str)> {
    FAMILIES.iter().filter(|f| f.1)
}

fn left_out()
-> impl Iterator<Item = &'static (&'static str, bool, &'static [&'static str], &'static str)> {
    FAMILIES.iter().filter(|f| !f.1)
}

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
fn schemes_lists_every_scheme_of_this_build_with_what_it_opens_and_names_the_rest() {
    let text = stdout_of(&["schemes"]);
    let registry = schemes();
    let mut listed = Vec::new();
    let mut not_compiled = Vec::new();
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("not compiled in: ") {
            not_compiled.push(rest.to_string());
            continue;
        }
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
        listed.push((name.to_string(), family.to_string()));
    }
    let mut expected = vec![("inproc".to_string(), "inproc".to_string())];
    for (family, _, schemes, _) in compiled() {
        expected.extend(schemes.iter().map(|s| (s.to_string(), family.to_string())));
    }
    assert_eq!(listed, expected, "{text}");
    let expected: Vec<String> = left_out()
        .map(|(f, ..)| format!("{f} (cargo feature `{f}`)"))
        .collect();
    assert_eq!(not_compiled, expected, "{text}");
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
    let mut media = String::from("media: inproc (inproc)");
    for (family, _, schemes, _) in compiled() {
        media += &format!(" {family} ({})", schemes.join(", "));
    }
    assert_eq!(lines.next(), Some(media.as_str()), "{text}");
    let out: Vec<&str> = left_out().map(|f| f.0).collect();
    if out.is_empty() {
        assert_eq!(lines.next(), None, "no family is left out: {text}");
    } else {
        assert_eq!(
            lines.next(),
            Some(format!("left out: {}", out.join(", ")).as_str()),
            "{text}"
        );
    }
}

/// A medium of every family: one this build left out is refused by `check` with the feature to
/// build with; one it has is read as that family's (whatever else `check` says of it).
#[test]
fn check_names_the_feature_of_a_medium_left_out_of_this_build() {
    for (family, has, _, url) in FAMILIES {
        let (_dir, path) = system_file(
            "one.xml",
            &format!(
                "<seabus node=\"n\">\n  <medium name=\"m\" url=\"{}\"/>\n</seabus>\n",
                url.replace('&', "&amp;")
            ),
        );
        let out = check(&path);
        let err = String::from_utf8_lossy(&out.stderr);
        let refusal = format!(
            "{}:2:20: medium `{family}` is not compiled into this seabus (feature `{family}`)",
            path.display()
        );
        if has {
            assert!(!err.contains("not compiled"), "{family}: {err}");
            assert!(!err.contains("unknown medium scheme"), "{family}: {err}");
        } else {
            assert_eq!(out.status.code(), Some(2), "{family}: {err}");
            assert!(err.contains(&refusal), "{family}: {err}");
        }
    }
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
