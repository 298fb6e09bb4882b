//! The recent past of every plotted and tracked variable, sent to a page when it opens a layout
//! so that its plots and track are full at once (after a reload or a reconnect too).
//!
//! The variables are those the plots and tracks of the console's layouts bind (read when the
//! console starts, and when a page opens a layout with variables of its own). For each topic the
//! backlog keeps only the bound fields, over the console's `history` window (default 10 min), at
//! most one sample per window / [`SAMPLES`] (faster data is thinned), and at most [`TOPICS`]
//! topics: at most `TOPICS × SAMPLES` samples of a few numbers each. With the default window that
//! is one sample per 200 ms per topic. A page is sent what its widgets draw: a plot's window, a
//! track's trail.

use super::{Client, Hub, now_s};
use crate::layout::{Horizon, Layout, Plotted};
use seabus_medium::{DataMap, Pattern, Topic, Value};
use serde_json::{Map, Value as Json, json};
use std::collections::{HashMap, HashSet, VecDeque};
use std::time::Duration;

/// Samples kept per topic, at most.
pub const SAMPLES: usize = 3000;
/// Topics kept, at most (the first bound are kept).
pub const TOPICS: usize = 32;
/// Patterns of plotted or tracked variables followed, at most.
const PATTERNS: usize = 256;
/// Topics remembered as not followed (so most messages cost one lookup), at most.
const IGNORED: usize = 4096;
/// A stamp further ahead of the console's clock than this is not kept.
const AHEAD: f64 = 5.0;

/// A sample: its stamp and the values of its series' fields.
type Sample = (f64, Box<[Option<Value>]>);

/// What a page is sent of one topic: the fields (with their place in a sample) and the samples.
type Part = (Topic, Vec<(String, usize)>, Vec<Sample>);

/// One topic's samples: the bound fields, and each sample's stamp with their values.
#[derive(Debug, Default)]
struct Series {
    fields: Vec<String>,
    samples: VecDeque<Sample>,
}

impl Series {
    /// Adds the fields of `fields` the series does not have yet, with no value in the samples
    /// it holds.
    fn widen(&mut self, fields: Vec<String>) {
        let before = self.fields.len();
        for f in fields {
            if !self.fields.contains(&f) {
                self.fields.push(f);
            }
        }
        let width = self.fields.len();
        if width == before {
            return;
        }
        for (_, values) in self.samples.iter_mut() {
            let mut wider = std::mem::take(values).into_vec();
            wider.resize(width, None);
            *values = wider.into_boxed_slice();
        }
    }
}

/// The fields the followed patterns bind of `topic`, each once, in the order they were bound.
fn wanted_fields(wanted: &[(Pattern, Vec<String>)], topic: &Topic) -> Vec<String> {
    let mut fields: Vec<String> = Vec::new();
    for (_, f) in wanted.iter().filter(|(p, _)| p.matches(topic.as_str())) {
        for f in f {
            if !fields.contains(f) {
                fields.push(f.clone());
            }
        }
    }
    fields
}

/// The recent samples of the plotted and tracked variables.
#[derive(Debug)]
pub(super) struct Backlog {
    window: f64,
    /// The least time between two samples kept of a topic.
    gap: f64,
    /// What is followed: topic patterns and their fields.
    wanted: Vec<(Pattern, Vec<String>)>,
    series: HashMap<Topic, Series>,
    ignored: HashSet<Topic>,
}

impl Default for Backlog {
    fn default() -> Self {
        Backlog::new(Duration::from_secs(600))
    }
}

impl Backlog {
    /// A backlog over `window`.
    pub(super) fn new(window: Duration) -> Backlog {
        let window = window.as_secs_f64();
        Backlog {
            window,
            gap: window / SAMPLES as f64,
            wanted: Vec::new(),
            series: HashMap::new(),
            ignored: HashSet::new(),
        }
    }

    /// Follows what `layout`'s plots and tracks bind. A topic that gains a field keeps the
    /// samples it has: the new field has no value in them (a plot of it starts now).
    pub(super) fn follow(&mut self, layout: &Layout) {
        for Plotted { topic, fields, .. } in layout.plotted() {
            let Ok(p) = Pattern::new(&topic) else {
                continue;
            };
            let full = self.wanted.len() >= PATTERNS;
            let changed = match self
                .wanted
                .iter_mut()
                .find(|(q, _)| q.as_str() == p.as_str())
            {
                Some((_, have)) => {
                    let new: Vec<String> =
                        fields.into_iter().filter(|f| !have.contains(f)).collect();
                    have.extend(new.iter().cloned());
                    !new.is_empty()
                }
                None if !full => {
                    self.wanted.push((p.clone(), fields));
                    true
                }
                None => false,
            };
            if changed {
                self.ignored.clear();
                let wanted = &self.wanted;
                for (topic, s) in self.series.iter_mut() {
                    if p.matches(topic.as_str()) {
                        s.widen(wanted_fields(wanted, topic));
                    }
                }
            }
        }
    }

    /// Takes in a message: kept when a plot or track binds it and the last one kept of its
    /// topic is old enough.
    pub(super) fn record(&mut self, topic: &Topic, stamp: f64, map: &DataMap) {
        if self.wanted.is_empty() || !stamp.is_finite() || self.ignored.contains(topic) {
            return;
        }
        if !self.series.contains_key(topic) && !self.start(topic) {
            return;
        }
        let Some(s) = self.series.get_mut(topic) else {
            return;
        };
        if stamp > now_s() + AHEAD {
            return;
        }
        match s.samples.back() {
            // a source whose clock went back starts again
            Some((t, _)) if stamp < t - 1.0 => s.samples.clear(),
            Some((t, _)) if stamp < t + self.gap * 0.95 => return,
            _ => {}
        }
        let values: Box<[Option<Value>]> = s.fields.iter().map(|f| map.get(f).cloned()).collect();
        if values.iter().all(Option::is_none) {
            return;
        }
        s.samples.push_back((stamp, values));
        while s
            .samples
            .front()
            .is_some_and(|(t, _)| *t < stamp - self.window)
            || s.samples.len() > SAMPLES
        {
            s.samples.pop_front();
        }
    }

    /// Starts a series for `topic` when something binds it (and there is room); else remembers
    /// it is not followed.
    fn start(&mut self, topic: &Topic) -> bool {
        let fields = wanted_fields(&self.wanted, topic);
        if fields.is_empty() || self.series.len() >= TOPICS {
            if self.ignored.len() >= IGNORED {
                self.ignored.clear();
            }
            self.ignored.insert(topic.clone());
            return false;
        }
        let series = Series {
            fields,
            samples: VecDeque::new(),
        };
        self.series.insert(topic.clone(), series);
        true
    }

    /// What a layout's widgets draw of each followed topic: the topic, its fields (name, index
    /// in the series) and the samples within the widest horizon, oldest first.
    fn snapshot(&self, plotted: &[Plotted]) -> Vec<Part> {
        let mut out = Vec::new();
        for (topic, s) in &self.series {
            let mine: Vec<&Plotted> = plotted
                .iter()
                .filter(|p| Pattern::new(&p.topic).is_ok_and(|q| q.matches(topic.as_str())))
                .collect();
            let Some(last) = s.samples.back().map(|(t, _)| *t) else {
                continue;
            };
            let fields: Vec<(String, usize)> = s
                .fields
                .iter()
                .enumerate()
                .filter(|(_, f)| mine.iter().any(|p| p.fields.contains(f)))
                .map(|(i, f)| (f.clone(), i))
                .collect();
            if fields.is_empty() {
                continue;
            }
            let (mut secs, mut points) = (0.0_f64, 0_usize);
            for h in mine.iter().flat_map(|p| &p.horizons) {
                match h {
                    Horizon::Seconds(w) => secs = secs.max(*w),
                    Horizon::Points(n) => points = points.max(*n),
                }
            }
            let skip = s.samples.len().saturating_sub(points);
            let samples: Vec<Sample> = s
                .samples
                .iter()
                .enumerate()
                .filter(|(i, (t, _))| *i >= skip || *t >= last - secs)
                .filter(|(_, (_, v))| fields.iter().any(|(_, i)| v[*i].is_some()))
                .map(|(_, x)| x.clone())
                .collect();
            out.push((topic.clone(), fields, samples));
        }
        out
    }
}

/// The `backlog` message of a snapshot: `{TOPIC: [{stamp, fields}]}`.
fn backlog_json(snapshot: Vec<Part>) -> Option<Json> {
    let mut topics = Map::new();
    for (topic, fields, samples) in snapshot {
        let samples: Vec<Json> = samples
            .iter()
            .map(|(stamp, values)| {
                let fields: Map<String, Json> = fields
                    .iter()
                    .filter_map(|(f, i)| Some((f.clone(), json!(values.get(*i)?.as_ref()?))))
                    .collect();
                json!({"stamp": stamp, "fields": fields})
            })
            .collect();
        if !samples.is_empty() {
            topics.insert(topic.to_string(), Json::Array(samples));
        }
    }
    (!topics.is_empty()).then(|| json!({"type": "backlog", "topics": topics}))
}

impl Hub {
    /// Follows the plotted and tracked variables of every layout the console has (read without
    /// variables), so that their past is there for the first page; returns the topics their
    /// commands go on.
    pub fn follow_layouts(&self) -> Vec<Topic> {
        let mut commanded: Vec<Topic> = Vec::new();
        for path in &self.settings.layouts {
            if let Ok(layout) = self.load(path, &Default::default()) {
                self.state().backlog.follow(&layout);
                for c in layout.commands.values() {
                    if !commanded.contains(&c.topic) {
                        commanded.push(c.topic.clone());
                    }
                }
            }
        }
        commanded
    }

    /// The `backlog` message for the layout `client` opened, when there is anything in it: what
    /// its plots and tracks draw (copied under the hub's lock, written out after).
    pub fn backlog(&self, client: &Client) -> Option<Json> {
        let layout = client.layout.as_ref()?;
        let plotted = layout.plotted();
        let snapshot = {
            let mut st = self.state();
            st.backlog.follow(layout);
            st.backlog.snapshot(&plotted)
        };
        backlog_json(snapshot)
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::Fixture;
    use super::*;
    use seabus_medium::Stamp;
    use std::collections::BTreeMap;

    fn at(secs: f64) -> Stamp {
        Stamp((secs * 1e9) as i64)
    }

    #[test]
    fn a_page_opening_a_layout_gets_the_plotted_past_thinned_and_bounded() {
        let f = Fixture::new();
        f.hub.follow_layouts();
        let depth = Topic::new("nav.depth").unwrap();
        let other = Topic::new("nav.other").unwrap();
        // 20 minutes at 50 Hz: only the last 10 minutes are kept, one sample per 200 ms
        let t0 = 1_700_000_000.0;
        for i in 0..60_000 {
            let t = t0 + i as f64 * 0.02;
            let m = DataMap::new().with("depth", i as f64).with("temp", 3.0);
            f.hub.observe(&depth, at(t), &m);
            f.hub.observe(&other, at(t), &m);
        }
        let mut page = f.client("ana");
        let b = f.hub.backlog(&page).unwrap();
        assert_eq!(b["type"], "backlog");
        let samples = b["topics"]["nav.depth"].as_array().unwrap();
        assert!(
            (SAMPLES - 2..=SAMPLES + 1).contains(&samples.len()),
            "{} samples",
            samples.len()
        );
        let first = samples[0]["stamp"].as_f64().unwrap();
        let last = samples[samples.len() - 1]["stamp"].as_f64().unwrap();
        assert!((last - first - 600.0).abs() < 0.5, "{first} .. {last}");
        assert!((last - (t0 + 59_999.0 * 0.02)).abs() < 0.2);
        // only the bound field, and nothing of topics no plot binds
        assert_eq!(
            samples[0]["fields"]
                .as_object()
                .unwrap()
                .keys()
                .collect::<Vec<_>>(),
            ["depth"]
        );
        assert!(b["topics"].get("nav.other").is_none());
        // a stamp from a clock far ahead is not kept
        let ahead = now_s() + 60.0;
        f.hub
            .observe(&depth, at(ahead), &DataMap::new().with("depth", -1.0));
        let b = f.hub.backlog(&page).unwrap();
        let samples = b["topics"]["nav.depth"].as_array().unwrap();
        assert!(samples.iter().all(|s| s["fields"]["depth"] != -1.0));
        // a layout with no plot gets none
        page.layout = None;
        assert!(f.hub.backlog(&page).is_none());
    }

    #[test]
    fn a_layout_plotting_a_new_field_keeps_the_past_of_the_fields_already_kept() {
        const TEMP: &str = r#"<layout name="temp" title="Temperature" roles="pilot">
  <column><plot window="15min"><series bind="nav.depth.temp"/></plot></column>
</layout>"#;
        // the console starts with the pilot layout followed: of nav.depth, `depth` only
        let f = Fixture::new();
        f.hub.follow_layouts();
        let depth = Topic::new("nav.depth").unwrap();
        let t0 = now_s() - 180.0;
        for i in 0..900 {
            let m = DataMap::new().with("depth", i as f64).with("temp", 4.0);
            f.hub.observe(&depth, at(t0 + i as f64 * 0.2), &m);
        }
        let mut page = f.client("ana");
        let before = f.hub.backlog(&page).unwrap()["topics"]["nav.depth"]
            .as_array()
            .unwrap()
            .len();
        assert!(before >= 850, "{before} samples before");
        // a page opens a layout the console did not start with, plotting `temp`
        page.layout = Some(Layout::parse("temp.xml", TEMP, &BTreeMap::new()).unwrap());
        assert!(f.hub.backlog(&page).is_none(), "temp has no past");
        // the depth of the pilot layout still spans its 180 s
        let mut pilot = f.client("bo");
        let b = f.hub.backlog(&pilot).unwrap();
        let samples = b["topics"]["nav.depth"].as_array().unwrap();
        assert_eq!(samples.len(), before, "the depth plot's past was cut");
        let first = samples[0]["stamp"].as_f64().unwrap();
        let last = samples[samples.len() - 1]["stamp"].as_f64().unwrap();
        assert!(last - first > 179.0, "{first} .. {last}");
        // the new field has no past, and it is kept from now on
        assert!(samples.iter().all(|s| s["fields"].get("temp").is_none()));
        f.hub.observe(
            &depth,
            at(now_s() + 1.0),
            &DataMap::new().with("depth", 1.0).with("temp", 5.0),
        );
        let b = f.hub.backlog(&page).unwrap();
        let temps = b["topics"]["nav.depth"].as_array().unwrap();
        assert_eq!(temps.len(), 1, "{temps:?}");
        assert_eq!(temps[0]["fields"]["temp"], 5.0);
        assert!(temps[0]["fields"].get("depth").is_none());
        let b = f.hub.backlog(&pilot).unwrap();
        assert_eq!(
            b["topics"]["nav.depth"].as_array().unwrap().len(),
            before + 1
        );
        pilot.layout = None;
        assert!(f.hub.backlog(&pilot).is_none());
    }
}
