//! A hub on an in-process bus, with a layout, sessions and a command log, for the hub's tests.

use super::{Client, Hub, Settings};
use crate::auth::Session;
use crate::users::Users;
use seabus_medium::{Interface, Kind, Medium, Message, Node, Value};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

/// The layout the tests open: a dead-man command, a held one, a confirmed one, the safe action, one that needs no
/// control, one only a `captain` may send and one the console keeps (its depth measured).
pub const PILOT: &str = r#"<layout name="pilot" title="Pilot" roles="pilot observer">
  <command name="course" topic="cmd.course" fields="heading=0, speed=0" rate="5Hz"
           neutral="speed=0" max.speed="3"/>
  <command name="start" topic="cmd.mission" fields="action=start" confirm="hold" hold="300ms"/>
  <command name="abort" topic="cmd.mission" fields="action=abort" confirm="dialog"/>
  <command name="stop" topic="cmd.mission" fields="action=stop" safe="true"/>
  <command name="camera" topic="cmd.camera" fields="on=false, note=x" lease="false"/>
  <command name="anchor" topic="cmd.anchor" fields="drop=true" role="captain"/>
  <command name="helm" topic="cmd.helm" fields="heading=0, depth=0.0, speed=0.0" keep="1s"
           rate="5Hz" neutral="speed=0" from.depth="nav.depth.depth" min.depth="0"/>
  <column>
    <readout bind="nav.depth.depth"/>
    <slider command="course.heading" min="0" max="360"/>
    <slider command="course.speed" min="0" max="3"/>
    <button command="start"/>
    <button command="abort"/>
    <button command="stop"/>
    <toggle command="camera.on"/>
    <button command="anchor"/>
    <slider command="helm.heading" min="0" max="360"/>
    <slider command="helm.depth" min="0" max="50"/>
    <slider command="helm.speed" min="0" max="2"/>
    <plot window="15min"><series bind="nav.depth.depth"/></plot>
  </column>
</layout>
"#;

/// How long the fixture's commands wait for their acknowledgement.
pub const ACK_TIMEOUT: Duration = Duration::from_secs(5);

/// A hub with [`PILOT`] on an in-process bus, logging commands to `commands.csv`.
pub struct Fixture {
    _dir: tempfile::TempDir,
    /// The directory of the layout and the log.
    pub dir: PathBuf,
    /// The bus the hub sends on.
    pub bus: Medium,
    /// The hub.
    pub hub: Hub,
}

impl Fixture {
    pub fn new() -> Fixture {
        Fixture::with_layouts(&[])
    }

    /// A hub with [`PILOT`] and the layouts `(file name, text)` of `more`.
    pub fn with_layouts(more: &[(&str, &str)]) -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().to_path_buf();
        std::fs::write(d.join("pilot.xml"), PILOT).unwrap();
        let mut layouts = vec![d.join("pilot.xml")];
        for (file, text) in more {
            std::fs::write(d.join(file), text).unwrap();
            layouts.push(d.join(file));
        }
        let bus = Medium::in_process("bus", &Node::new("t"));
        let settings = Settings {
            listen: "127.0.0.1:0".parse().unwrap(),
            ack_timeout: ACK_TIMEOUT,
            lease_role: "pilot".into(),
            designer_role: "designer".into(),
            log: Some(d.join("commands.csv")),
            layouts,
            history: Duration::from_secs(600),
            node: None,
        };
        let hub = Hub::new(
            settings,
            Users::default(),
            bus.attach("console-commands"),
            Vec::new(),
        );
        Fixture {
            _dir: dir,
            dir: d,
            bus,
            hub,
        }
    }

    /// A session of `name`: `ana` (pilot, designer), `bo` (pilot), `ivo` (observer) or `dee`
    /// (designer, observer).
    pub fn session(&self, name: &str) -> Session {
        let roles: &[&str] = match name {
            "ana" => &["pilot", "designer"],
            "bo" => &["pilot"],
            "ivo" => &["observer"],
            "dee" => &["designer", "observer"],
            "eve" => &[],
            other => panic!("no user {other}"),
        };
        let roles: Vec<String> = roles.iter().map(|r| r.to_string()).collect();
        let token = self.hub.sessions.start(name, &roles).unwrap();
        self.hub.sessions.get(&token).unwrap()
    }

    /// A connection of `name` with [`PILOT`] open.
    pub fn client(&self, name: &str) -> Client {
        let mut client = self.hub.connect(self.session(name));
        let opened = self.hub.open(&mut client, "pilot", &BTreeMap::new());
        assert_eq!(opened["type"], "layout", "{opened}");
        client
    }

    /// A connection of `name` with [`PILOT`] open and control taken.
    pub async fn pilot(&self, name: &str) -> Client {
        let client = self.client(name);
        self.hub.lease(&client.session, "", true).await.unwrap();
        client
    }

    /// An interface on the bus receiving data on `pattern`.
    pub fn listener(&self, pattern: &str) -> Interface {
        let mut i = self.bus.attach("listener");
        i.subscribe_kind(pattern, Some(Kind::Data)).unwrap();
        i
    }

    /// An interface on the bus receiving the commands.
    pub fn driver(&self) -> Interface {
        let mut d = self.bus.attach("driver");
        d.subscribe_kind("cmd.**", Some(Kind::Command)).unwrap();
        d
    }

    /// The command log's lines.
    pub fn log(&self) -> Vec<String> {
        std::fs::read_to_string(self.dir.join("commands.csv"))
            .unwrap_or_default()
            .lines()
            .map(str::to_string)
            .collect()
    }
}

/// The messages waiting on `i`.
pub fn waiting(i: &mut Interface) -> Vec<Message> {
    std::iter::from_fn(|| i.try_recv().ok()).collect()
}

/// Field `k` of message `m`.
pub fn field(m: &Message, k: &str) -> Option<Value> {
    m.payload.as_map().and_then(|p| p.get(k)).cloned()
}

/// The holders the `console.control` messages waiting on `i` name.
pub fn control_messages(i: &mut Interface) -> Vec<String> {
    waiting(i)
        .iter()
        .map(|m| {
            field(m, "holder")
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap()
        })
        .collect()
}
