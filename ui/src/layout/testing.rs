//! Layouts and helpers the layout tests share.

use super::Layout;
use seabus_medium::xml::FileError;
use std::collections::BTreeMap;

/// The example of `docs/console.md`, with a few more attributes.
pub const EXAMPLE: &str = r#"<layout name="pilot" title="Pilot — ${vehicle}" roles="pilot designer">
  <var name="vehicle" default="iver"/>
  <command name="course" topic="cmd.course" fields="heading=0, depth=0, speed=0.0"
           rate="5Hz" neutral="speed=0" max.speed="2.5"/>
  <command name="start" topic="cmd.mission" fields="action=start, name=&quot;survey, north&quot;" confirm="hold"/>
  <command name="stop" topic="cmd.mission" fields="action=stop" confirm="dialog" lease="false"/>
  <template name="nav">
    <readout bind="nav.depth.depth" label="${what}" unit="m" precision="1"/>
  </template>
  <row sizes="2 1">
    <track position="nav.position" heading="nav.attitude.yaw" waypoints="43.5,16.4; 43.6,16.5" grid="50"/>
    <column>
      <use template="nav" what="Depth of ${vehicle}"/>
      <gauge id="speed" bind="nav.velocity.speed" min="0" max="3" ranges="0:2:green, 2:3:#f00" fresh="5s"/>
      <slider command="course.heading" min="0" max="359" step="1"/>
      <slider command="course.speed" min="0" max="2.5" step="0.1"/>
      <button command="start" label="Start"/>
      <button command="stop" set="action=stop"/>
      <log/>
    </column>
  </row>
  <keys>
    <key key="ArrowLeft" command="course.heading" step="-5"/>
    <key key="w" command="course.speed" value="1.5"/>
    <key key=" " command="stop"/>
  </keys>
  <gamepad>
    <axis index="1" command="course.speed" expo="0.5" gain="-2.5"/>
    <axis index="0" command="course.heading" deadband="0.15" gain="30" offset="nav.attitude.yaw"/>
    <button index="0" command="start"/>
  </gamepad>
</layout>
"#;

/// `text` read as file `l.xml` with no variables given.
pub fn parse(text: &str) -> Result<Layout, FileError> {
    Layout::parse("l.xml", text, &BTreeMap::new())
}

/// [`EXAMPLE`], read.
pub fn example() -> Layout {
    parse(EXAMPLE).unwrap()
}

/// The error `text` gives, as `LINE:COL: message`.
pub fn error(text: &str) -> String {
    let e = parse(text).map(|_| ()).unwrap_err();
    let s = e.to_string();
    s.strip_prefix("l.xml:").unwrap_or(&s).to_string()
}

/// A layout with `body` inside, after a `course` command (line 2) and a `stop` command (line 3).
pub fn with(body: &str) -> String {
    format!(
        "<layout name=\"t\">\n<command name=\"course\" topic=\"cmd.course\" fields=\"heading=0, speed=0.0, name=x, on=true\" max.heading=\"360\"/>\n<command name=\"stop\" topic=\"cmd.mission\" fields=\"action=stop\"/>\n{body}\n</layout>"
    )
}

/// The cases whose layout (`wrap` of the case's text) does not give the error wanted, each with
/// the error it gives.
pub fn wrong_errors(cases: &[(&str, &str)], wrap: impl Fn(&str) -> String) -> Vec<String> {
    cases
        .iter()
        .filter_map(|(text, want)| {
            let got = error(&wrap(text));
            (got != *want).then(|| format!("{text}\n  got  {got}\n  want {want}"))
        })
        .collect()
}
