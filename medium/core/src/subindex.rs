//! An index of topic patterns: which of many patterns match a topic, found by walking the
//! topic's segments through a tree of the patterns' segments rather than trying every pattern, so
//! that patterns that do not match cost a message (almost) nothing, wildcards included. A medium
//! files its interfaces' subscriptions in one; a bridge its routes.
//!
//! Each pattern is a path from the root: a literal segment is a branch by name, `*` the branch
//! taking any one segment, `**` the branch taking any number (none included). A topic is matched
//! the way an automaton reads it: the set of places reached after each segment, kept without
//! repeats, so even patterns full of `**` cost at most the tree's size per segment.

use crate::message::Kind;
use crate::topic::{Pattern, Step};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// FNV-1a: segments are short and the index is built from the program's own subscriptions, so a
/// fast hash that needs no defence against chosen keys.
#[derive(Default)]
struct Fnv(u64);

impl Hasher for Fnv {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        let mut h = if self.0 == 0 {
            0xcbf2_9ce4_8422_2325
        } else {
            self.0
        };
        for &b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        self.0 = h;
    }
}

type Branches = HashMap<Box<str>, usize, BuildHasherDefault<Fnv>>;

/// One pattern filed in the index: the number it was filed under (an interface's place in a
/// medium's list, a route's), and the kind it takes (`None`: both).
#[derive(Debug, Clone, Copy)]
struct Entry {
    at: u32,
    kind: Option<Kind>,
}

/// A place in the tree: the subscriptions whose patterns end here, and the branches on.
#[derive(Debug, Default)]
struct Place {
    ends: Vec<Entry>,
    lit: Branches,
    one: Option<usize>,
    any: Option<usize>,
    /// Reached by `**`: it takes any further segment itself.
    loops: bool,
}

/// Patterns, each filed under a number, by their segments.
#[derive(Debug)]
pub struct SubIndex {
    places: Vec<Place>,
}

impl Default for SubIndex {
    fn default() -> Self {
        SubIndex {
            places: vec![Place::default()],
        }
    }
}

/// Starts a new set of places: a new mark, the marks cleared when they wrap.
fn bump(round: &mut u32, seen: &mut [u32]) {
    *round = round.wrapping_add(1);
    if *round == 0 {
        seen.fill(0);
        *round = 1;
    }
}

/// The scratch a match uses, kept between messages.
#[derive(Debug, Default)]
pub struct Scratch {
    /// What the last [`SubIndex::matching`] found: the numbers, ascending.
    pub found: Vec<u32>,
    now: Vec<usize>,
    next: Vec<usize>,
    seen: Vec<u32>,
    round: u32,
}

impl SubIndex {
    fn branch(&mut self, from: usize, step: Step<'_>) -> usize {
        let made = self.places.len();
        let place = &mut self.places[from];
        let (to, loops) = match step {
            Step::Lit(l) => match place.lit.get(l) {
                Some(&to) => return to,
                None => {
                    place.lit.insert(l.into(), made);
                    (made, false)
                }
            },
            Step::One => (*place.one.get_or_insert(made), false),
            Step::Any => (*place.any.get_or_insert(made), true),
        };
        if to == made {
            self.places.push(Place {
                loops,
                ..Place::default()
            });
        }
        to
    }

    /// Files `pattern` (for `kind`, or both) under the number `at`.
    pub fn insert(&mut self, at: u32, pattern: &Pattern, kind: Option<Kind>) {
        let mut here = 0;
        for step in pattern.steps() {
            here = self.branch(here, step);
        }
        self.places[here].ends.push(Entry { at, kind });
    }

    /// Adds `p` and the places its `**` branches reach without taking a segment.
    fn enter(&self, p: usize, set: &mut Vec<usize>, scratch_seen: &mut [u32], round: u32) {
        let mut p = Some(p);
        while let Some(q) = p {
            if scratch_seen[q] == round {
                return;
            }
            scratch_seen[q] = round;
            set.push(q);
            p = self.places[q].any;
        }
    }

    /// Puts into `scratch.found` the numbers of the patterns that match a message
    /// of `kind` on `topic`, in ascending order, each once.
    pub fn matching(&self, topic: &str, kind: Kind, scratch: &mut Scratch) {
        let Scratch {
            found: out,
            now,
            next,
            seen,
            round,
        } = scratch;
        out.clear();
        if seen.len() < self.places.len() {
            seen.clear();
            seen.resize(self.places.len(), 0);
            *round = 0;
        }
        now.clear();
        bump(round, seen);
        self.enter(0, now, seen, *round);
        for segment in topic.split('.') {
            next.clear();
            bump(round, seen);
            for &p in now.iter() {
                let place = &self.places[p];
                if let Some(&to) = place.lit.get(segment) {
                    self.enter(to, next, seen, *round);
                }
                if let Some(to) = place.one {
                    self.enter(to, next, seen, *round);
                }
                if place.loops {
                    self.enter(p, next, seen, *round);
                }
            }
            std::mem::swap(now, next);
            if now.is_empty() {
                return;
            }
        }
        for &p in now.iter() {
            for e in &self.places[p].ends {
                if e.kind.is_none_or(|k| k == kind) {
                    out.push(e.at);
                }
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_index_finds_what_trying_every_pattern_finds() {
        let patterns = [
            ("nav.attitude", None),
            ("nav.**", Some(Kind::Data)),
            ("nav.*", None),
            ("nav.attitude.**", None),
            ("cmd.*", Some(Kind::Command)),
            ("**", Some(Kind::Command)),
            ("*.depth", None),
            ("a.**.z", None),
            ("nav", None),
            ("power.battery", Some(Kind::Data)),
            ("**.**.z", None),
            ("a.*.**", None),
            ("**.c.*", None),
        ];
        let subs: Vec<(u32, Pattern, Option<Kind>)> = patterns
            .iter()
            .enumerate()
            .map(|(i, (p, k))| (i as u32 % 4, Pattern::new(p).unwrap(), *k))
            .collect();
        let mut index = SubIndex::default();
        for (at, p, k) in &subs {
            index.insert(*at, p, *k);
        }
        let topics = [
            "nav",
            "nav.attitude",
            "nav.attitude.yaw",
            "nav.depth",
            "navx.depth",
            "cmd.course",
            "cmd.course.x",
            "a.z",
            "a.b.c.z",
            "power.battery",
            "power",
            "x",
        ];
        let mut scratch = Scratch::default();
        for topic in topics {
            for kind in [Kind::Data, Kind::Command] {
                let mut want: Vec<u32> = subs
                    .iter()
                    .filter(|(_, p, k)| k.is_none_or(|k| k == kind) && p.matches(topic))
                    .map(|(at, _, _)| *at)
                    .collect();
                want.sort_unstable();
                want.dedup();
                index.matching(topic, kind, &mut scratch);
                assert_eq!(scratch.found, want, "{topic} {kind:?}");
            }
        }
    }

    #[test]
    fn random_patterns_and_topics_match_as_the_patterns_say() {
        // a fixed pseudo-random sequence: 300 patterns over a, b, c, * and **, 300 topics
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % n
        };
        let mut word = |segs: &[&str]| -> String {
            let len = 1 + next(4) as usize;
            (0..len)
                .map(|_| segs[next(segs.len() as u64) as usize])
                .collect::<Vec<_>>()
                .join(".")
        };
        let patterns: Vec<Pattern> = (0..300)
            .map(|_| Pattern::new(&word(&["a", "b", "c", "*", "**"])).unwrap())
            .collect();
        let topics: Vec<String> = (0..300).map(|_| word(&["a", "b", "c"])).collect();
        let mut index = SubIndex::default();
        for (i, p) in patterns.iter().enumerate() {
            index.insert(i as u32, p, None);
        }
        let mut scratch = Scratch::default();
        for t in &topics {
            let want: Vec<u32> = (0..patterns.len() as u32)
                .filter(|&i| patterns[i as usize].matches(t))
                .collect();
            index.matching(t, Kind::Data, &mut scratch);
            assert_eq!(scratch.found, want, "{t}");
        }
    }
}
