//! What each page is sent: the `hello` with the layouts its user may open, the layout it opens
//! (with which of its topics have a producer), and the data its layout binds, as it changes.

use super::{Client, Hub, State, error_json, now_s};
use crate::auth::Session;
use crate::layout::Layout;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Pattern, Topic};
use serde::ser::{Serialize, SerializeMap, Serializer};
use serde_json::{Map, Value as Json, json};
use std::collections::BTreeMap;
use std::path::Path;

/// What a layout binds: topic patterns and the fields wanted (`None`: all).
type Interest = Vec<(Pattern, Option<Vec<String>>)>;

/// The name a layout file goes by when it does not read: its file name without `.xml`.
fn stem(path: &Path) -> Option<String> {
    path.file_stem().map(|s| s.to_string_lossy().into_owned())
}

impl Hub {
    /// Layout file `path` read with `vars`; without variables it is read again only when the
    /// file has changed since (every connection lists every layout).
    pub(super) fn load(
        &self,
        path: &Path,
        vars: &BTreeMap<String, String>,
    ) -> Result<Layout, FileError> {
        if !vars.is_empty() {
            return Layout::load(path, vars);
        }
        let modified = std::fs::metadata(path).and_then(|m| m.modified()).ok();
        let mut cache = self.layouts.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((when, read)) = cache.get(path)
            && modified.is_some()
            && *when == modified
        {
            return read.clone();
        }
        let read = Layout::load(path, vars);
        cache.insert(path.to_path_buf(), (modified, read.clone()));
        read
    }

    /// The layouts `session`'s user may open: (name, title) or, for a file that does not read,
    /// its error.
    pub fn layouts_for(&self, session: &Session) -> Vec<Json> {
        let mut out = Vec::new();
        for path in &self.settings.layouts {
            match self.load(path, &BTreeMap::new()) {
                Ok(l) if l.visible_to(&session.roles) => {
                    out.push(json!({"name": l.name, "title": l.title}))
                }
                Ok(_) => {}
                Err(e) => out.push(json!({
                    "name": stem(path).unwrap_or_default(),
                    "error": error_json(&e),
                })),
            }
        }
        out
    }

    /// The `hello` message for a new connection.
    pub fn hello(&self, client: &Client) -> Json {
        json!({
            "type": "hello",
            "user": client.session.user,
            // which log-in this page is: control is held by one (`lease`'s `session`)
            "session": client.session.id,
            // the console's own origin on the bus (`commanded`'s `by` when it sent the values)
            "origin": self.origin,
            "roles": client.session.roles,
            "layouts": self.layouts_for(&client.session),
            "lease": self.lease_json(),
            "leases": self.leases_json()["held"],
            "lease_role": self.settings.lease_role,
            "node": self.settings.node,
            "designer_role": self.settings.designer_role,
        })
    }

    /// Whether a module declares producing `topic`, or data on it has been seen.
    fn produced(&self, topic: &str, st: &State) -> bool {
        self.produced.iter().any(|p| p.matches(topic))
            || Topic::new(topic).is_ok_and(|t| st.latest.contains_key(&t))
            || Pattern::new(topic).is_ok_and(|p| st.latest.keys().any(|t| p.matches(t.as_str())))
    }

    /// What `layout` binds, and for each bound topic whether anything produces it.
    fn interest(&self, layout: &Layout) -> (Interest, Map<String, Json>) {
        let mut interest: Interest = Vec::new();
        let mut producers = Map::new();
        let st = self.state();
        for b in layout.bindings() {
            producers.insert(b.topic.clone(), Json::Bool(self.produced(&b.topic, &st)));
            let Ok(p) = Pattern::new(&b.topic) else {
                continue;
            };
            match interest.iter_mut().find(|(q, _)| q.as_str() == p.as_str()) {
                Some((_, fields)) => match (fields.as_mut(), &b.field) {
                    (Some(list), Some(f)) if list.contains(f) => {}
                    (Some(list), Some(f)) => list.push(f.clone()),
                    _ => *fields = None,
                },
                None => interest.push((p, b.field.clone().map(|f| vec![f]))),
            }
        }
        (interest, producers)
    }

    /// Opens layout `name` with `vars` for `client`: the `layout` message (with the layout, or the
    /// error that stops it loading).
    pub fn open(&self, client: &mut Client, name: &str, vars: &BTreeMap<String, String>) -> Json {
        for path in &self.settings.layouts {
            let layout = match self.load(path, vars) {
                Ok(l) => l,
                Err(e) if stem(path).as_deref() == Some(name) => {
                    return json!({"type": "layout", "name": name, "error": error_json(&e)});
                }
                Err(_) => continue,
            };
            if layout.name != name {
                continue;
            }
            if !layout.visible_to(&client.session.roles) {
                break;
            }
            let (interest, producers) = self.interest(&layout);
            client.offers = layout
                .commands
                .keys()
                .map(|n| (n.clone(), layout.offers(n)))
                .collect();
            let chosen: Map<String, Json> = client
                .offers
                .iter()
                .map(|(n, o)| (n.clone(), json!(o.free)))
                .collect();
            let message = json!({
                "type": "layout",
                "name": name,
                "layout": layout.to_json(),
                "producers": producers,
                "chosen": chosen,
                "commanded": self.commanded_for(&layout),
                "commanded_by": self.commanded_by(&layout),
                "kept": self.state().keeps.json(),
            });
            client.interest = interest;
            client.wants_at = None;
            client.seen = 0;
            client.layout = Some(layout);
            return message;
        }
        json!({"type": "error", "message": format!("no layout `{name}` for you")})
    }

    /// What a page that missed events is sent again about commands: the values last commanded
    /// on its layout's command topics and the kept commands (`commanded` and `kept` messages).
    pub fn commands_again(&self, client: &Client) -> Vec<Json> {
        let Some(layout) = &client.layout else {
            return Vec::new();
        };
        let mut out: Vec<Json> = self
            .commanded_for(layout)
            .into_iter()
            .map(|(topic, fields)| {
                let by = Topic::new(&topic)
                    .ok()
                    .and_then(|t| self.state().commanded.by_json(&t))
                    .unwrap_or_default();
                json!({"type": "commanded", "topic": topic, "fields": fields,
                       "by": by["by"], "console": by["console"], "since": by["since"]})
            })
            .collect();
        out.extend(self.state().keeps.json());
        out
    }

    /// The values last commanded on the topics of `layout`'s commands, by topic.
    fn commanded_for(&self, layout: &Layout) -> Map<String, Json> {
        let st = self.state();
        layout
            .commands
            .values()
            .filter_map(|c| {
                let fields = st.commanded.get(&c.topic)?;
                Some((c.topic.to_string(), json!(fields)))
            })
            .collect()
    }

    /// Who commanded the values last commanded on the topics of `layout`'s commands, and since
    /// when they stand: `{TOPIC: {by, since}}`.
    fn commanded_by(&self, layout: &Layout) -> Map<String, Json> {
        let st = self.state();
        layout
            .commands
            .values()
            .filter_map(|c| Some((c.topic.to_string(), st.commanded.by_json(&c.topic)?)))
            .collect()
    }

    /// The `data` message with what changed since the client's last one, if anything did, as
    /// JSON text. Written straight from the latest values under the hub's lock: no copy of a
    /// value is made for a page, however many pages there are. Which topics the page binds is
    /// worked out only when the hub has seen a new topic, so a page's cost does not grow with
    /// the topics on the bus that it does not show.
    pub fn data_for(&self, client: &mut Client) -> Option<String> {
        if client.interest.is_empty() {
            return None;
        }
        let st = self.state();
        if st.version == client.seen {
            return None;
        }
        if client.wants_at != Some(st.topics_known) {
            client.wants = st
                .latest
                .keys()
                .filter_map(|t| Some((t.clone(), wanted(&client.interest, t)?)))
                .collect();
            client.wants_at = Some(st.topics_known);
        }
        let seen = std::mem::replace(&mut client.seen, st.version);
        let topics: Vec<TopicData<'_>> = client
            .wants
            .iter()
            .filter_map(|(topic, fields)| {
                let latest = st.latest.get(topic).filter(|l| l.version > seen)?;
                Some(TopicData {
                    topic,
                    stamp: latest.stamp,
                    fields: match fields {
                        None => Fields::All(&latest.map),
                        Some(list) => Fields::These(
                            list.iter()
                                .filter_map(|f| Some((f.as_str(), latest.map.get(f)?)))
                                .collect(),
                        ),
                    },
                })
            })
            .collect();
        if topics.is_empty() {
            return None;
        }
        serde_json::to_string(&Data {
            topics,
            now: now_s(),
        })
        .ok()
    }
}

/// A `data` message: `{"type": "data", "topics": {TOPIC: {"stamp", "fields"}}, "now"}`.
struct Data<'a> {
    topics: Vec<TopicData<'a>>,
    now: f64,
}

/// One topic's entry of a `data` message.
struct TopicData<'a> {
    topic: &'a Topic,
    stamp: f64,
    fields: Fields<'a>,
}

/// The fields of a topic's latest message a page wants.
enum Fields<'a> {
    All(&'a DataMap),
    These(Vec<(&'a str, &'a seabus_medium::Value)>),
}

impl Serialize for Data<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        struct Topics<'b>(&'b [TopicData<'b>]);
        impl Serialize for Topics<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut m = s.serialize_map(Some(self.0.len()))?;
                for t in self.0 {
                    m.serialize_entry(t.topic.as_str(), t)?;
                }
                m.end()
            }
        }
        let mut m = s.serialize_map(Some(3))?;
        m.serialize_entry("type", "data")?;
        m.serialize_entry("topics", &Topics(&self.topics))?;
        m.serialize_entry("now", &self.now)?;
        m.end()
    }
}

impl Serialize for TopicData<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(2))?;
        m.serialize_entry("stamp", &self.stamp)?;
        m.serialize_entry("fields", &self.fields)?;
        m.end()
    }
}

impl Serialize for Fields<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Fields::All(map) => map.serialize(s),
            Fields::These(these) => {
                let mut m = s.serialize_map(Some(these.len()))?;
                for (k, v) in these {
                    m.serialize_entry(k, v)?;
                }
                m.end()
            }
        }
    }
}

/// The fields of `topic` that `interest` wants, if it wants any: all of them (`None`) when a
/// pattern binding the whole message matches, else each field a matching pattern names, once, in
/// the order first named.
fn wanted(interest: &Interest, topic: &Topic) -> Option<Option<Vec<String>>> {
    let mut wanted: Option<Vec<String>> = None;
    for (p, fields) in interest {
        if !p.matches(topic.as_str()) {
            continue;
        }
        let out = wanted.get_or_insert_with(Vec::new);
        match fields {
            None => return Some(None),
            Some(list) => {
                for f in list {
                    if !out.contains(f) {
                        out.push(f.clone());
                    }
                }
            }
        }
    }
    wanted.map(Some)
}

#[cfg(test)]
mod tests {
    use super::super::LATEST_TOPICS;
    use super::super::testing::Fixture;
    use super::*;
    use seabus_medium::Stamp;

    #[test]
    fn a_user_lists_and_opens_only_the_layouts_of_their_roles() {
        let f = Fixture::new();
        let ivo = f.session("ivo");
        assert_eq!(
            f.hub.layouts_for(&ivo),
            [json!({"name": "pilot", "title": "Pilot"})]
        );
        let mut eve = f.hub.connect(f.session("eve"));
        assert!(f.hub.layouts_for(&eve.session).is_empty());
        let refused = f.hub.open(&mut eve, "pilot", &BTreeMap::new());
        assert_eq!(
            refused,
            json!({"type": "error", "message": "no layout `pilot` for you"})
        );
        assert!(eve.layout.is_none());
    }

    #[test]
    fn a_layout_file_that_does_not_read_is_listed_and_opened_with_its_error() {
        let f = Fixture::new();
        let path = f.dir.join("pilot.xml");
        std::fs::write(&path, "<layout name=\"pilot\"><dial/></layout>").unwrap();
        let listed = f.hub.layouts_for(&f.session("ana"));
        assert_eq!(listed.len(), 1);
        assert_eq!(listed[0]["name"], "pilot");
        assert_eq!(
            (&listed[0]["error"]["line"], &listed[0]["error"]["col"]),
            (&json!(1), &json!(22))
        );
        let mut ana = f.hub.connect(f.session("ana"));
        let opened = f.hub.open(&mut ana, "pilot", &BTreeMap::new());
        assert_eq!(opened["type"], "layout");
        assert_eq!(opened["error"], listed[0]["error"]);
    }

    #[test]
    fn a_page_gets_the_fields_it_binds_once_each_time_they_change() {
        let f = Fixture::new();
        let mut ana = f.client("ana");
        assert_eq!(f.hub.data_for(&mut ana), None);
        let depth = Topic::new("nav.depth").unwrap();
        let reading = DataMap::new().with("depth", 3.5).with("temperature", 9);
        f.hub.observe(&depth, Stamp(10_000_000_000), &reading);
        let data: Json = serde_json::from_str(&f.hub.data_for(&mut ana).unwrap()).unwrap();
        assert_eq!(
            data["topics"],
            json!({"nav.depth": {"stamp": 10.0, "fields": {"depth": 3.5}}})
        );
        assert_eq!(f.hub.data_for(&mut ana), None);
        let elsewhere = Topic::new("nav.speed").unwrap();
        f.hub.observe(&elsewhere, Stamp(11_000_000_000), &reading);
        assert_eq!(f.hub.data_for(&mut ana), None);
    }

    #[test]
    fn a_field_bound_twice_is_sent_once_beside_the_other_fields_of_its_topics() {
        let twice = r#"<layout name="twice" roles="observer">
            <readout bind="nav.depth.depth"/><readout bind="nav.depth.depth"/>
            <plot><series bind="nav.depth.depth"/></plot>
            <readout bind="nav.speed.knots"/><readout bind="nav.speed.metres"/>
        </layout>"#;
        let f = Fixture::with_layouts(&[("twice.xml", twice)]);
        let mut ivo = f.hub.connect(f.session("ivo"));
        let opened = f.hub.open(&mut ivo, "twice", &BTreeMap::new());
        assert_eq!(opened["type"], "layout", "{opened}");
        let reading = DataMap::new().with("depth", 3.5).with("temperature", 9);
        f.hub.observe(
            &Topic::new("nav.depth").unwrap(),
            Stamp(1_000_000_000),
            &reading,
        );
        let speed = DataMap::new().with("metres", 1.5).with("knots", 2.9);
        f.hub.observe(
            &Topic::new("nav.speed").unwrap(),
            Stamp(2_000_000_000),
            &speed,
        );
        let text = f.hub.data_for(&mut ivo).unwrap();
        assert_eq!(text.matches(r#""depth":3.5"#).count(), 1, "{text}");
        let data: Json = serde_json::from_str(&text).unwrap();
        assert_eq!(data["type"], "data");
        assert_eq!(
            data["topics"],
            json!({"nav.depth": {"stamp": 1.0, "fields": {"depth": 3.5}},
                   "nav.speed": {"stamp": 2.0, "fields": {"knots": 2.9, "metres": 1.5}}})
        );
        assert!(data["now"].as_f64().unwrap() > 1.7e9, "{text}");
    }

    /// A layout binding one field each of `nav.depth` and `nav.speed`.
    const TWO: &str = r#"<layout name="two" roles="observer">
            <readout bind="nav.depth.depth"/><readout bind="nav.speed.knots"/>
        </layout>"#;

    /// A fixture with layout `two` and `more`, and a page of `ivo`'s that has opened `two`.
    fn two_open(more: &[(&str, &str)]) -> (Fixture, Client) {
        let mut layouts = vec![("two.xml", TWO)];
        layouts.extend_from_slice(more);
        let f = Fixture::with_layouts(&layouts);
        let mut ivo = f.hub.connect(f.session("ivo"));
        assert_eq!(
            f.hub.open(&mut ivo, "two", &BTreeMap::new())["type"],
            "layout"
        );
        (f, ivo)
    }

    /// The console hears `field` = `value` on `topic`, stamped `secs` after the epoch.
    fn hear(f: &Fixture, topic: &str, secs: i64, field: &'static str, value: f64) {
        let map = DataMap::new().with(field, value);
        f.hub.observe(
            &Topic::new(topic).unwrap(),
            Stamp(secs * 1_000_000_000),
            &map,
        );
    }

    /// The topics of the `data` message `client` is sent now.
    fn topics_sent(f: &Fixture, client: &mut Client) -> Json {
        let data: Json = serde_json::from_str(&f.hub.data_for(client).unwrap()).unwrap();
        data["topics"].clone()
    }

    #[test]
    fn a_bound_topic_first_heard_after_a_page_was_sent_data_reaches_it() {
        let deep =
            r#"<layout name="deep" roles="observer"><readout bind="nav.depth.depth"/></layout>"#;
        let (f, mut ivo) = two_open(&[("deep.xml", deep)]);
        hear(&f, "nav.depth", 1, "depth", 3.5);
        assert_eq!(
            topics_sent(&f, &mut ivo),
            json!({"nav.depth": {"stamp": 1.0, "fields": {"depth": 3.5}}})
        );
        hear(&f, "nav.heading", 2, "yaw", 1.0);
        assert_eq!(f.hub.data_for(&mut ivo), None);
        hear(&f, "nav.speed", 3, "knots", 2.9);
        assert_eq!(
            topics_sent(&f, &mut ivo),
            json!({"nav.speed": {"stamp": 3.0, "fields": {"knots": 2.9}}})
        );
        // another layout opened on the same connection: its own topics, from the start
        assert_eq!(
            f.hub.open(&mut ivo, "deep", &BTreeMap::new())["type"],
            "layout"
        );
        assert_eq!(
            topics_sent(&f, &mut ivo),
            json!({"nav.depth": {"stamp": 1.0, "fields": {"depth": 3.5}}})
        );
    }

    #[test]
    fn beyond_its_topic_bound_the_console_forgets_the_topics_heard_from_longest_ago() {
        let (f, mut ivo) = two_open(&[]);
        hear(&f, "nav.depth", 1, "depth", 3.5);
        for i in 0..LATEST_TOPICS {
            hear(&f, &format!("flood.t{i}"), 2, "x", 1.0);
        }
        let kept = f.hub.state().latest.len();
        assert_eq!(kept, LATEST_TOPICS + 1 - LATEST_TOPICS / 8);
        assert_eq!(f.hub.state().forgotten, 512);
        let depth = Topic::new("nav.depth").unwrap();
        assert!(!f.hub.state().latest.contains_key(&depth));
        let last = Topic::new(&format!("flood.t{}", LATEST_TOPICS - 1)).unwrap();
        assert!(f.hub.state().latest.contains_key(&last));
        hear(&f, "nav.speed", 3, "knots", 2.9);
        assert_eq!(
            topics_sent(&f, &mut ivo),
            json!({"nav.speed": {"stamp": 3.0, "fields": {"knots": 2.9}}})
        );
        // heard again, a forgotten topic is shown again
        hear(&f, "nav.depth", 4, "depth", 4.0);
        assert_eq!(
            topics_sent(&f, &mut ivo),
            json!({"nav.depth": {"stamp": 4.0, "fields": {"depth": 4.0}}})
        );
    }

    #[test]
    fn a_health_table_gets_the_snapshot_whole_with_the_media_that_lost_anything() {
        let diag = r#"<layout name="diag" roles="observer"><health/></layout>"#;
        let f = Fixture::with_layouts(&[("diag.xml", diag)]);
        let mut ivo = f.hub.connect(f.session("ivo"));
        let opened = f.hub.open(&mut ivo, "diag", &BTreeMap::new());
        assert_eq!(opened["type"], "layout", "{opened}");
        let lossy = seabus_medium::MediumStats {
            received: 24_450,
            queue_dropped: [("gps".to_string(), 412)].into(),
            rejected: [("garbage".to_string(), 2)].into(),
            dropped_bytes: 57,
            ..Default::default()
        };
        let snapshot = DataMap::new()
            .with("severity", "NONE")
            .with("components", DataMap::new().with("Sensors", "HEALTHY"))
            .with("media", DataMap::new().with("gps-line", lossy.to_map()));
        let health = Topic::new("vehicle.health").unwrap();
        f.hub.observe(&health, Stamp(5_000_000_000), &snapshot);
        let data: Json = serde_json::from_str(&f.hub.data_for(&mut ivo).unwrap()).unwrap();
        let line = &data["topics"]["vehicle.health"]["fields"]["media"]["gps-line"];
        assert_eq!(line["queue_dropped"], json!({"gps": 412}), "{data}");
        assert_eq!(line["rejected"], json!({"garbage": 2}), "{data}");
        assert_eq!(
            (&line["received"], &line["dropped_bytes"], &line["overruns"]),
            (&json!(24_450), &json!(57), &json!(0)),
            "{data}"
        );
    }

    #[tokio::test]
    async fn a_page_that_missed_events_is_sent_what_was_commanded_and_kept() {
        let f = Fixture::new();
        let mut ana = f.pilot("ana").await;
        let bo = f.client("bo");
        assert_eq!(f.hub.commands_again(&bo), Vec::<Json>::new());
        let course = DataMap::new()
            .with("heading", 90)
            .with("depth", 5.0)
            .with("speed", 1.5);
        f.hub
            .send(&mut ana, "pilot", "helm", &course, None)
            .await
            .unwrap();
        let again = f.hub.commands_again(&bo);
        assert_eq!(again.len(), 2, "{again:?}");
        assert_eq!(
            again[0],
            json!({"type": "commanded", "topic": "cmd.helm",
                   "fields": {"heading": 90, "depth": 5.0, "speed": 1.5},
                   "by": f.hub.origin, "console": true, "since": again[0]["since"]})
        );
        assert!(again[0]["since"].as_f64().unwrap() > 1.0e9, "{again:?}");
        assert_eq!(
            (&again[1]["type"], &again[1]["command"], &again[1]["user"]),
            (&json!("kept"), &json!("helm"), &json!("ana"))
        );
    }

    #[test]
    fn a_fleet_table_gets_every_node_announced_and_each_vehicles_bound_fields() {
        let table = r#"<layout name="fleet" roles="observer"><fleet open="vehicle"/></layout>"#;
        let f = Fixture::with_layouts(&[("fleet.xml", table)]);
        let mut ivo = f.hub.connect(f.session("ivo"));
        let opened = f.hub.open(&mut ivo, "fleet", &BTreeMap::new());
        assert_eq!(opened["type"], "layout", "{opened}");
        let fleet = Topic::new("seabus.fleet").unwrap();
        let said = |node: &str, online: bool| {
            DataMap::new()
                .with("node", node)
                .with("online", online)
                .with("since", 1.0)
        };
        // three nodes speak between two frames of the page: all three are in the table
        f.hub
            .observe(&fleet, Stamp(1_000_000_000), &said("auv1", true));
        f.hub
            .observe(&fleet, Stamp(1_000_000_000), &said("auv2", true));
        f.hub
            .observe(&fleet, Stamp(1_000_000_000), &said("shore", true));
        let state = Topic::new("auv1.vehicle.state").unwrap();
        let mode = DataMap::new().with("mode", "mission").with("error", "none");
        f.hub.observe(&state, Stamp(2_000_000_000), &mode);
        let battery = Topic::new("auv2.power.battery").unwrap();
        let charge = DataMap::new().with("percent", 81.0).with("voltage", 15.1);
        f.hub.observe(&battery, Stamp(2_000_000_000), &charge);
        let data: Json = serde_json::from_str(&f.hub.data_for(&mut ivo).unwrap()).unwrap();
        let nodes = &data["topics"]["seabus.fleet"]["fields"];
        let names: Vec<&String> = nodes.as_object().unwrap().keys().collect();
        assert_eq!(names, ["auv1", "auv2", "shore"], "{data}");
        assert_eq!(nodes["auv2"]["online"], true);
        assert_eq!(
            data["topics"]["auv1.vehicle.state"]["fields"],
            json!({"mode": "mission"})
        );
        assert_eq!(
            data["topics"]["auv2.power.battery"]["fields"],
            json!({"percent": 81.0})
        );
        // auv1 goes: its row stays, offline
        f.hub
            .observe(&fleet, Stamp(3_000_000_000), &said("auv1", false));
        let data: Json = serde_json::from_str(&f.hub.data_for(&mut ivo).unwrap()).unwrap();
        let nodes = &data["topics"]["seabus.fleet"]["fields"];
        assert_eq!(
            (&nodes["auv1"]["online"], &nodes["auv2"]["online"]),
            (&json!(false), &json!(true))
        );
    }
}
