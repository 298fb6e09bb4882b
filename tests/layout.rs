//! `seabus layout check` on good and bad layouts: warnings and the summary, or the error placed.

mod common;
use common::*;
use std::path::Path;

fn layout_check(layout: &Path, system: &Path) -> std::process::Output {
    seabus()
        .args(["layout", "check"])
        .arg(layout)
        .arg(system)
        .output()
        .expect("seabus runs")
}

const SYSTEM: &str = "<seabus>\n  <medium name=\"bus\" url=\"inproc://\"/>\n  <module name=\"g\" type=\"generator\" medium=\"bus\" topic=\"nav.depth\"/>\n</seabus>\n";

#[test]
fn a_good_layout_is_valid_with_warnings_for_what_the_system_lacks() {
    let (dir, system) = system_file("system.xml", SYSTEM);
    let layout = dir.path().join("page.xml");
    std::fs::write(
        &layout,
        "<layout name=\"p\">\n  <column>\n    <readout bind=\"nav.depth.sine\"/>\n    <readout bind=\"nav.velocity.speed\"/>\n  </column>\n</layout>\n",
    )
    .unwrap();
    let out = layout_check(&layout, &system);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert_eq!(
        stderr.trim(),
        format!(
            "{}:4:5: warning: no module of {} produces `nav.velocity` on medium `bus` (widget `readout-2`)",
            layout.display(),
            system.display()
        )
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim(),
        format!(
            "{}: valid (2 widgets, 0 commands, 2 bindings)",
            layout.display()
        )
    );
}

#[test]
fn a_bad_layout_is_an_error_with_line_and_column() {
    let (dir, system) = system_file("system.xml", SYSTEM);
    let layout = dir.path().join("page.xml");
    std::fs::write(
        &layout,
        "<layout name=\"p\">\n  <command name=\"go\" topic=\"cmd.go\" fields=\"speed=0\"/>\n  <slider command=\"go.sped\"/>\n</layout>\n",
    )
    .unwrap();
    let out = layout_check(&layout, &system);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr).trim(),
        format!(
            "{0}:3:11: attribute `command`: command `go` has no field `sped`; fields: speed\n\
             {0}: 1 error",
            layout.display()
        )
    );
    assert!(out.stdout.is_empty());
    let out = layout_check(&layout, Path::new("/no/such/system.xml"));
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn every_error_of_a_layout_is_reported_in_the_order_of_the_file() {
    let (dir, system) = system_file("system.xml", SYSTEM);
    let layout = dir.path().join("page.xml");
    std::fs::write(
        &layout,
        r#"<layout name="p">
  <command name="go" topic="cmd.go" fields="speed=0" rate="fast"/>
  <command name="stop" topic="cmd.stop" fields="now=true" safe="true"/>
  <column>
    <slider command="stop.speed"/>
    <readout bind="nav.depth.depth" digits="99"/>
    <row>
      <button command="go"/>
      <gauge bind="nav.depth.depth" min="5" max="1"/>
    </row>
    <readout bind="nav.depth.depth" colour="plaid"/>
  </column>
  <keys><key key="x" command="nothing"/></keys>
</layout>
"#,
    )
    .unwrap();
    let out = layout_check(&layout, &system);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let at: Vec<&str> = stderr
        .lines()
        .map(|l| {
            let rest = l.strip_prefix(&*layout.to_string_lossy()).unwrap_or(l);
            rest.split(' ').next().unwrap_or_default()
        })
        .collect();
    assert_eq!(
        at,
        [
            ":2:54:", ":5:13:", ":6:37:", ":8:15:", ":9:45:", ":11:37:", ":13:22:", ":"
        ],
        "{stderr}"
    );
    assert!(
        stderr.contains("command `go` is in error where it is declared (line 2)"),
        "{stderr}"
    );
    assert!(stderr.trim_end().ends_with(": 7 errors"), "{stderr}");
    assert!(out.stdout.is_empty());
}
