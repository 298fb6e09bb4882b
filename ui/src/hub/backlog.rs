//! The recent past of every plotted and tracked variable, sent to a page when it opens a layout
//! so that its plots and track are full at once (after a reload or a reconnect too).
//!
//! The variables are those the plots and tracks of the console's layouts bind (read when the
//! console starts, and when a page opens a layout with variables of its own). For each topic the
//! backlog keeps only the bound fields, over the console's `history` window (default 10 min), at
//! most one sample per [`window`](Backlog::new) / [`SAMPLES`] (faster data is thinned), and at
//! most [`TOPICS`] topics: at most `TOPICS × SAMPLES` samples of a few numbers each. With the
//! default window that is one sample per 200 ms per topic.

use super::{Client, Hub};
use crate::layout::Layout;
use seabus_medium::{DataMap, Pattern, Topic, Value};
use serde_json::{Map, Value as Json, json};
use std::collections::{HashMap, VecDeque};
use std::time::Duration;

/// Samples kept per topic, at most.
pub const SAMPLES: usize = 3000;
/// Topics kept, at most (the first bound are kept).
pub const TOPICS: usize = 32;
/// Patterns of plotted or tracked variables followed, at most.
const PATTERNS: usize = 256;

/// One topic's samples: the bound fields, and each sample's stamp with their values.
#[derive(Debug, Default)]
struct Series {
    fields: Vec<String>,
    samples: VecDeque<(f64, Box<[Option<Value>]>)>,
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
        }
    }

    /// Follows what `layout`'s plots and tracks bind.
    pub(super) fn follow(&mut self, layout: &Layout) {
        for (topic, fields) in layout.plotted() {
            let Ok(p) = Pattern::new(&topic) else {
                continue;
            };
            let full = self.wanted.len() >= PATTERNS;
            match self
                .wanted
                .iter_mut()
                .find(|(q, _)| q.as_str() == p.as_str())
            {
                Some((_, have)) => {
                    for f in fields {
                        if !have.contains(&f) {
                            have.push(f);
                        }
                    }
                }
                None if !full => self.wanted.push((p, fields)),
                None => {}
            }
        }
    }

    /// Takes in a message: kept when a plot or track binds it and the last one kept of its
    /// topic is old enough.
    pub(super) fn record(&mut self, topic: &Topic, stamp: f64, map: &DataMap) {
        if self.wanted.is_empty() || !stamp.is_finite() {
            return;
        }
        if !self.series.contains_key(topic) {
            let fields: Vec<String> = self
                .wanted
                .iter()
                .filter(|(p, _)| p.matches(topic.as_str()))
                .flat_map(|(_, f)| f.iter().cloned())
                .collect();
            if fields.is_empty() || self.series.len() >= TOPICS {
                return;
            }
            let series = Series {
                fields,
                samples: VecDeque::new(),
            };
            self.series.insert(topic.clone(), series);
        }
        let Some(s) = self.series.get_mut(topic) else {
            return;
        };
        if s.samples
            .back()
            .is_some_and(|(t, _)| stamp < t + self.gap * 0.95)
        {
            return;
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

    /// The `backlog` message for a page whose layout binds `interest`: each wanted topic's
    /// samples, oldest first, with the fields the layout binds.
    fn json(&self, layout: &Layout) -> Option<Json> {
        let plotted = layout.plotted();
        let mut topics = Map::new();
        for (topic, s) in &self.series {
            let wanted: Vec<&str> = plotted
                .iter()
                .filter(|(t, _)| Pattern::new(t).is_ok_and(|p| p.matches(topic.as_str())))
                .flat_map(|(_, f)| f.iter().map(String::as_str))
                .collect();
            if wanted.is_empty() || s.samples.is_empty() {
                continue;
            }
            let samples: Vec<Json> = s
                .samples
                .iter()
                .map(|(stamp, values)| {
                    let fields: Map<String, Json> = s
                        .fields
                        .iter()
                        .zip(values.iter())
                        .filter(|(f, _)| wanted.contains(&f.as_str()))
                        .filter_map(|(f, v)| Some((f.clone(), json!(v.as_ref()?))))
                        .collect();
                    json!({"stamp": stamp, "fields": fields})
                })
                .collect();
            topics.insert(topic.to_string(), Json::Array(samples));
        }
        (!topics.is_empty()).then(|| json!({"type": "backlog", "topics": topics}))
    }
}

impl Hub {
    /// Follows the plotted and tracked variables of every layout the console has (read without
    /// variables), so that their past is there for the first page.
    pub fn follow_layouts(&self) {
        for path in &self.settings.layouts {
            if let Ok(layout) = self.load(path, &Default::default()) {
                self.state().backlog.follow(&layout);
            }
        }
    }

    /// The `backlog` message for the layout `client` opened, when there is anything in it.
    pub fn backlog(&self, client: &Client) -> Option<Json> {
        let layout = client.layout.as_ref()?;
        let mut st = self.state();
        st.backlog.follow(layout);
        st.backlog.json(layout)
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::Fixture;
    use super::*;
    use seabus_medium::Stamp;

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
        // a layout with no plot gets none
        page.layout = None;
        assert!(f.hub.backlog(&page).is_none());
    }
}
