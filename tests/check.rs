//! `seabus check` and `seabus run` on good and bad system files: the exact error and exit code.

mod common;
use common::*;

fn expect_error(text: &str, line_col_msg: &str) {
    let (_dir, path) = system_file("system.xml", text);
    for cmd in ["check", "run"] {
        let out = seabus().arg(cmd).arg(&path).output().expect("seabus runs");
        assert_eq!(out.status.code(), Some(2), "{cmd}: exit code for {text}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        let expected = format!("{}:{line_col_msg}", path.display());
        assert_eq!(
            stderr.lines().last(),
            Some(expected.as_str()),
            "{cmd}: stderr was {stderr}"
        );
    }
}

#[test]
fn xml_syntax_errors_name_line_and_column() {
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\">\n</seabus>\n",
        "3:1: XML syntax error: ill-formed document: expected `</medium>`, but `</seabus>` was found",
    );
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"a\" type=\"generator\" medium=\"bus\"\n",
        "3:3: XML syntax error: syntax error: tag not closed: `>` not found before end of input",
    );
}

/// The names `seabus types` lists under `heading` (indented lines) or after it on its line.
fn listed(heading: &str) -> String {
    let out = seabus().arg("types").output().expect("seabus runs");
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    if let Some(line) = text.lines().find(|l| l.starts_with(heading)) {
        let rest = line[heading.len()..].trim();
        if !rest.is_empty() {
            return rest.to_string();
        }
    }
    let names: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with(heading))
        .skip(1)
        .take_while(|l| l.starts_with(' '))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    names.join(", ")
}

#[test]
fn unknown_types_list_the_known_ones() {
    let modules = listed("module types:");
    assert!(
        modules.contains("iver2, iver2-sim") && modules.contains("nmea-gps, nmea-heading"),
        "{modules}"
    );
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"x\" type=\"gizmo\" medium=\"bus\"/>\n</seabus>\n",
        &format!("3:3: unknown module type `gizmo`; known types: {modules}"),
    );
    let schemes = listed("medium schemes:");
    assert!(schemes.contains("serial, pty"), "{schemes}");
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"tcp://1.2.3.4:5\"/>\n</seabus>\n",
        &format!(
            "2:22: unknown medium scheme `tcp://` in `tcp://1.2.3.4:5`; known schemes: {schemes}"
        ),
    );
    let bridges = listed("bridge types:");
    assert_eq!(bridges, "route");
    expect_error(
        "<seabus>\n  <medium name=\"a\" url=\"inproc://\"/>\n  <medium name=\"b\" url=\"inproc://\"/>\n  \
         <bridge name=\"x\" type=\"magic\" media=\"a b\"/>\n</seabus>\n",
        &format!("4:3: unknown bridge type `magic`; known types: {bridges}"),
    );
}

#[test]
fn missing_attributes_are_named() {
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"x\" medium=\"bus\"/>\n</seabus>\n",
        "3:3: <module> is missing attribute `type`",
    );
    expect_error(
        "<seabus>\n  <medium name=\"bus\"/>\n</seabus>\n",
        "2:3: <medium> is missing attribute `url`",
    );
}

#[test]
fn bad_urls_say_what_is_wrong() {
    expect_error(
        "<seabus>\n  <medium name=\"net\" url=\"udp://239.255.42.1\"/>\n</seabus>\n",
        "2:22: bad medium URL `udp://239.255.42.1`: needs a port (udp://HOST:PORT)",
    );
    expect_error(
        "<seabus>\n  <medium name=\"net\" url=\"udp://239.255.42.1:47800?tll=0\"/>\n</seabus>\n",
        "2:22: bad medium URL `udp://239.255.42.1:47800?tll=0`: unknown option `tll` for udp://; known options: \
         ttl, iface, peer, bind, broadcast, loop, recv_buf, max, send_gap",
    );
    expect_error(
        "<seabus>\n  <medium name=\"net\" url=\"239.255.42.1:47800\"/>\n</seabus>\n",
        "2:22: bad medium URL `239.255.42.1:47800`: expected `scheme://…` (for example udp://239.255.42.1:47800)",
    );
    expect_error(
        "<seabus>\n  <medium name=\"fleet\" url=\"zenoh://?prefix=fleet/auv*\"/>\n</seabus>\n",
        "2:24: bad medium URL `zenoh://?prefix=fleet/auv*`: option `prefix`: prefix `fleet/auv*`: \
         `auv*` holds `*`, which Zenoh reserves",
    );
    expect_error(
        "<seabus>\n  <medium name=\"fleet\" url=\"zenoh://?connect=tcp:shore\"/>\n</seabus>\n",
        "2:24: bad medium URL `zenoh://?connect=tcp:shore`: option `connect=tcp:shore`: not a Zenoh \
         endpoint (such as tcp/127.0.0.1:7447)",
    );
}

#[test]
fn bad_module_placement_and_parameters_are_refused() {
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"g\" type=\"generator\" medium=\"bsu\"/>\n</seabus>\n",
        "3:3: no medium called `bsu`; media: bus",
    );
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"g\" type=\"generator\" medium=\"bus\" rtae=\"5\"/>\n</seabus>\n",
        "3:50: module type `generator` has no parameter `rtae`",
    );
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"g\" type=\"generator\" medium=\"bus\" tick=\"fast\"/>\n</seabus>\n",
        "3:50: attribute `tick`: `fast` is not a rate (10, 10Hz) or a period (100ms, 2s)",
    );
}

#[test]
fn a_valid_file_checks_clean_and_a_missing_one_is_an_error() {
    let (_dir, path) = system_file(
        "ok.xml",
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"g\" type=\"generator\" medium=\"bus\"/>\n</seabus>\n",
    );
    let out = check(&path);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("valid (1 medium, 1 module, 0 bridges)"));
    let out = seabus()
        .args(["check", "/no/such/system.xml"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).starts_with("/no/such/system.xml:1:1: cannot read")
    );
}

/// Every system file in configs/ (files whose root is `<seabus>`), the demo's too (its console on
/// 127.0.0.1 makes its own users), and every console layout in configs/console/ with `seabus layout
/// check` against the demo.
#[test]
fn every_shipped_config_is_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let demo = dir.join("demo.xml");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        if path.extension().is_some_and(|e| e == "xml") && text.contains("<seabus") {
            let out = check(&path);
            assert_eq!(
                out.status.code(),
                Some(0),
                "{}: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
            checked += 1;
        }
    }
    assert!(checked >= 1);
    let mut layouts = 0;
    for entry in std::fs::read_dir(dir.join("console")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "xml") {
            continue;
        }
        let out = seabus()
            .args(["layout", "check"])
            .arg(&path)
            .arg(&demo)
            .output()
            .expect("seabus runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{}: {stderr}", path.display());
        // the demo has no health monitor: only a health table may lack its producer
        for line in stderr.lines() {
            assert!(
                line.contains("warning: no module of") && line.contains("`vehicle.health`"),
                "{}: {line}",
                path.display()
            );
        }
        layouts += 1;
    }
    assert!(layouts >= 2);
}

/// The fleet console's layouts, against the shore station they are for: valid, and every binding
/// and command reaches something (a vehicle's commands go out over the fleet's medium).
#[test]
fn the_fleet_consoles_layouts_check_clean_against_the_shore() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/fleet");
    for layout in ["fleet.xml", "vehicle.xml"] {
        let path = dir.join("console").join(layout);
        let out = seabus()
            .args(["layout", "check"])
            .arg(&path)
            .arg(dir.join("shore.xml"))
            .output()
            .expect("seabus runs");
        assert_eq!(
            (out.status.code(), String::from_utf8_lossy(&out.stderr)),
            (Some(0), "".into()),
            "{}",
            path.display()
        );
        assert!(
            String::from_utf8_lossy(&out.stdout).contains(": valid ("),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
    }
}

#[test]
fn a_routes_quality_of_service_needs_a_medium_that_carries_priorities() {
    expect_error(
        "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <medium name=\"radio\" url=\"udp://239.255.42.1:47800?ttl=0\"/>\n  \
         <bridge name=\"up\" media=\"bus radio\">\n    <route from=\"bus\" to=\"radio\" topics=\"nav.**\" priority=\"data-high\"/>\n  \
         </bridge>\n</seabus>\n",
        "5:50: attribute `priority`: the route delivers to medium `radio`, which carries no priority, \
         congestion control or express (a Zenoh medium does)",
    );
    let fleet = "zenoh://?listen=tcp/127.0.0.1:7447&amp;prefix=fleet/auv1&amp;scout=false";
    expect_error(
        &format!(
            "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <medium name=\"fleet\" url=\"{fleet}\"/>\n  \
             <bridge name=\"up\" media=\"bus fleet\">\n    <route from=\"bus\" topics=\"nav.**\" congestion=\"wait\"/>\n  \
             </bridge>\n</seabus>\n"
        ),
        "5:39: attribute `congestion`: `wait` is not a congestion control; expected block or drop",
    );
    let (_dir, path) = system_file(
        "fleet.xml",
        &format!(
            "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <medium name=\"fleet\" url=\"{fleet}\"/>\n  \
             <bridge name=\"up\" media=\"bus fleet\">\n    <route from=\"bus\" topics=\"nav.**\" priority=\"data-high\" \
             congestion=\"block\" express=\"true\"/>\n  </bridge>\n</seabus>\n"
        ),
    );
    let out = check(&path);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
