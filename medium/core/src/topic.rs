//! Topics (dotted names such as `nav.attitude`) and topic patterns.
//!
//! A pattern is a dotted name whose segments may be wildcards: `*` matches exactly one segment and
//! `**` matches any number of segments, none included. `nav.*` matches `nav.depth` but not
//! `nav.gps.raw`; `nav.**` matches both and `nav` itself. Patterns also rename: the segments a
//! pattern's wildcards captured fill the wildcards of a template in order
//! (`nav.*` → `auv1.nav.*` turns `nav.depth` into `auv1.nav.depth`).

use std::fmt;
use std::sync::Arc;
use thiserror::Error;

/// The topic on which a fleet medium (Zenoh) says which nodes are in the fleet: one message per
/// node with `node`, `online`, `since` and, when measured, `latency`.
pub const FLEET: &str = "seabus.fleet";

/// Longest topic, in bytes.
pub const MAX_TOPIC_LEN: usize = 255;

/// Why a topic or pattern is not valid.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum TopicError {
    /// The empty string.
    #[error("empty topic")]
    Empty,
    /// Longer than [`MAX_TOPIC_LEN`].
    #[error("topic is {0} bytes long, the limit is {MAX_TOPIC_LEN}")]
    TooLong(usize),
    /// Two dots in a row, or a dot at either end.
    #[error("empty segment in {0:?} (two dots in a row, or a dot at an end)")]
    EmptySegment(String),
    /// Whitespace, a control character, or a wildcard where none is allowed.
    #[error("character {1:?} not allowed in {0:?}")]
    BadChar(String, char),
    /// A wildcard that is not a whole segment (`na*v`).
    #[error("wildcard must be a whole segment (`*` or `**`) in {0:?}")]
    PartialWildcard(String),
}

fn check(text: &str, wildcards: bool) -> Result<(), TopicError> {
    if text.is_empty() {
        return Err(TopicError::Empty);
    }
    if text.len() > MAX_TOPIC_LEN {
        return Err(TopicError::TooLong(text.len()));
    }
    for seg in text.split('.') {
        if seg.is_empty() {
            return Err(TopicError::EmptySegment(text.to_string()));
        }
        if let Some(c) = seg.chars().find(|c| c.is_whitespace() || c.is_control()) {
            return Err(TopicError::BadChar(text.to_string(), c));
        }
        if seg.contains('*') {
            if !wildcards {
                return Err(TopicError::BadChar(text.to_string(), '*'));
            }
            if seg != "*" && seg != "**" {
                return Err(TopicError::PartialWildcard(text.to_string()));
            }
        }
    }
    Ok(())
}

/// A topic name. Cheap to clone (shared).
#[derive(Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Topic(Arc<str>);

impl Topic {
    /// Checks and wraps a topic name.
    pub fn new(name: &str) -> Result<Topic, TopicError> {
        check(name, false)?;
        Ok(Topic(Arc::from(name)))
    }

    /// A medium's own name for a message, kept as it came even when it is not a seabus topic: an
    /// LCM channel such as `POSE.`, `.POSE`, `a..b`, `cam*` or `with space`, which a recording
    /// keeps and a replay sends back to that medium as it was. A valid topic name gives the same
    /// topic as [`Topic::new`]. Refused: the empty name, one longer than [`MAX_TOPIC_LEN`], a NUL.
    pub fn channel(name: &str) -> Result<Topic, TopicError> {
        if name.is_empty() {
            return Err(TopicError::Empty);
        }
        if name.len() > MAX_TOPIC_LEN {
            return Err(TopicError::TooLong(name.len()));
        }
        if name.contains('\0') {
            return Err(TopicError::BadChar(name.to_string(), '\0'));
        }
        Ok(Topic(Arc::from(name)))
    }

    /// Whether the name is a seabus topic; only a [`Topic::channel`] may not be.
    pub fn is_topic(&self) -> bool {
        check(&self.0, false).is_ok()
    }

    /// The name as shown to people: a topic as it is, a channel name that is not a topic quoted
    /// (`"with space"`, `"a..b"`), so that its dots and spaces show.
    pub fn shown(&self) -> std::borrow::Cow<'_, str> {
        if self.is_topic() {
            std::borrow::Cow::Borrowed(&self.0)
        } else {
            std::borrow::Cow::Owned(format!("{:?}", &*self.0))
        }
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", &*self.0)
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl AsRef<str> for Topic {
    fn as_ref(&self) -> &str {
        &self.0
    }
}

impl std::ops::Deref for Topic {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl TryFrom<&str> for Topic {
    type Error = TopicError;
    fn try_from(s: &str) -> Result<Self, Self::Error> {
        Topic::new(s)
    }
}

impl TryFrom<String> for Topic {
    type Error = TopicError;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        Topic::new(&s)
    }
}

impl TryFrom<&String> for Topic {
    type Error = TopicError;
    fn try_from(s: &String) -> Result<Self, Self::Error> {
        Topic::new(s)
    }
}

impl TryFrom<&Topic> for Topic {
    type Error = TopicError;
    fn try_from(t: &Topic) -> Result<Self, Self::Error> {
        Ok(t.clone())
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Seg {
    Lit(Box<str>),
    One,
    Any,
}

/// How a pattern is matched: the common shapes without splitting the topic.
#[derive(Clone, PartialEq, Eq)]
enum Shape {
    /// No wildcard.
    Exact,
    /// `**`.
    All,
    /// `a.b.**`: the prefix `a.b` itself, or anything under `a.b.`.
    Under,
    /// `a.b.*`: exactly one segment under `a.b.`.
    Child,
    /// Anything else, matched segment by segment.
    General,
}

/// A segment of a pattern as a subscription index files it.
pub(crate) enum Step<'a> {
    /// This very segment.
    Lit(&'a str),
    /// `*`: any one segment.
    One,
    /// `**`: any number of segments, none included.
    Any,
}

/// A topic pattern with `*` (one segment) and `**` (any number of segments) wildcards.
#[derive(Clone, PartialEq, Eq)]
pub struct Pattern {
    text: Arc<str>,
    segs: Arc<[Seg]>,
    shape: Shape,
}

impl Pattern {
    /// Parses a pattern.
    pub fn new(text: &str) -> Result<Pattern, TopicError> {
        check(text, true)?;
        let segs: Vec<Seg> = text
            .split('.')
            .map(|s| match s {
                "*" => Seg::One,
                "**" => Seg::Any,
                lit => Seg::Lit(lit.into()),
            })
            .collect();
        let literal_prefix = segs[..segs.len() - 1]
            .iter()
            .all(|s| matches!(s, Seg::Lit(_)));
        let shape = match segs.last() {
            _ if segs.iter().all(|s| matches!(s, Seg::Lit(_))) => Shape::Exact,
            Some(Seg::Any) if segs.len() == 1 => Shape::All,
            Some(Seg::Any) if literal_prefix => Shape::Under,
            Some(Seg::One) if literal_prefix && segs.len() > 1 => Shape::Child,
            _ => Shape::General,
        };
        Ok(Pattern {
            text: Arc::from(text),
            segs: segs.into(),
            shape,
        })
    }

    /// The pattern's segments, for a subscription index.
    pub(crate) fn steps(&self) -> impl Iterator<Item = Step<'_>> {
        self.segs.iter().map(|s| match s {
            Seg::Lit(l) => Step::Lit(l),
            Seg::One => Step::One,
            Seg::Any => Step::Any,
        })
    }

    /// The pattern that matches every topic (`**`).
    pub fn all() -> Pattern {
        Pattern::new("**").expect("`**` is a valid pattern")
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// Number of wildcard segments.
    pub fn wildcards(&self) -> usize {
        self.segs
            .iter()
            .filter(|s| !matches!(s, Seg::Lit(_)))
            .count()
    }

    /// True when `topic` matches.
    pub fn matches(&self, topic: &str) -> bool {
        match self.shape {
            Shape::Exact => *self.text == *topic,
            Shape::All => true,
            Shape::Under => {
                // `a.b.**`: the text without `.**` is the prefix
                let prefix = &self.text[..self.text.len() - 3];
                topic
                    .strip_prefix(prefix)
                    .is_some_and(|rest| rest.is_empty() || rest.starts_with('.'))
            }
            Shape::Child => {
                // `a.b.*`: the text without `*` is the prefix, dot included
                let prefix = &self.text[..self.text.len() - 1];
                topic
                    .strip_prefix(prefix)
                    .is_some_and(|rest| !rest.is_empty() && !rest.contains('.'))
            }
            Shape::General => {
                let parts = smallvec_lite::Parts::new(topic);
                match_segs(&self.segs, parts.as_slice())
            }
        }
    }

    /// The segments each wildcard captured when `topic` matches (a `**` may capture none).
    pub fn captures<'t>(&self, topic: &'t str) -> Option<Vec<Vec<&'t str>>> {
        let parts: Vec<&str> = topic.split('.').collect();
        capture_segs(&self.segs, &parts)
    }

    /// Fills this pattern's wildcards, in order, with captured segments.
    /// Returns `None` when the captures do not fit (different wildcard count).
    pub fn fill(&self, caps: &[Vec<&str>]) -> Option<String> {
        if caps.len() != self.wildcards() {
            return None;
        }
        let mut caps = caps.iter();
        let mut out: Vec<&str> = Vec::with_capacity(self.segs.len());
        for seg in self.segs.iter() {
            match seg {
                Seg::Lit(l) => out.push(l),
                Seg::One | Seg::Any => out.extend(caps.next()?.iter().copied()),
            }
        }
        if out.is_empty() {
            return None;
        }
        Some(out.join("."))
    }

    /// True when some topic matches both patterns.
    pub fn overlaps(&self, other: &Pattern) -> bool {
        let (a, b) = (&*self.segs, &*other.segs);
        // memo[i][j]: can a[i..] and b[j..] match a common suffix
        let mut memo = vec![vec![None; b.len() + 1]; a.len() + 1];
        overlap(a, b, 0, 0, &mut memo)
    }
}

/// `can[i * (m + 1) + j]`: `segs[i..]` matches `parts[j..]`. Quadratic in the worst case, never
/// exponential, whatever the pattern and topic.
fn match_table(segs: &[Seg], parts: &[&str]) -> Vec<bool> {
    let (n, m) = (segs.len(), parts.len());
    let w = m + 1;
    let mut can = vec![false; (n + 1) * w];
    can[n * w + m] = true;
    for i in (0..n).rev() {
        for j in (0..=m).rev() {
            can[i * w + j] = match &segs[i] {
                Seg::Lit(l) => j < m && *parts[j] == **l && can[(i + 1) * w + j + 1],
                Seg::One => j < m && can[(i + 1) * w + j + 1],
                Seg::Any => can[(i + 1) * w + j] || (j < m && can[i * w + j + 1]),
            };
        }
    }
    can
}

fn match_segs(segs: &[Seg], parts: &[&str]) -> bool {
    match_table(segs, parts)[0]
}

/// The segments each wildcard takes when `segs` matches `parts`; a `**` takes as few as it can.
fn capture_segs<'t>(segs: &[Seg], parts: &[&'t str]) -> Option<Vec<Vec<&'t str>>> {
    let can = match_table(segs, parts);
    let w = parts.len() + 1;
    if !can[0] {
        return None;
    }
    let mut caps = Vec::new();
    let mut j = 0;
    for (i, seg) in segs.iter().enumerate() {
        match seg {
            Seg::Lit(_) => j += 1,
            Seg::One => {
                caps.push(vec![parts[j]]);
                j += 1;
            }
            Seg::Any => {
                let take = (0..=parts.len() - j).find(|k| can[(i + 1) * w + j + k])?;
                caps.push(parts[j..j + take].to_vec());
                j += take;
            }
        }
    }
    Some(caps)
}

fn overlap(a: &[Seg], b: &[Seg], i: usize, j: usize, memo: &mut Vec<Vec<Option<bool>>>) -> bool {
    if let Some(v) = memo[i][j] {
        return v;
    }
    let v = match (a.get(i), b.get(j)) {
        (None, None) => true,
        (Some(Seg::Any), _) => {
            overlap(a, b, i + 1, j, memo) || (j < b.len() && overlap(a, b, i, j + 1, memo))
        }
        (_, Some(Seg::Any)) => {
            overlap(a, b, i, j + 1, memo) || (i < a.len() && overlap(a, b, i + 1, j, memo))
        }
        (None, Some(_)) | (Some(_), None) => false,
        (Some(x), Some(y)) => {
            let compatible = match (x, y) {
                (Seg::Lit(p), Seg::Lit(q)) => p == q,
                _ => true,
            };
            compatible && overlap(a, b, i + 1, j + 1, memo)
        }
    };
    memo[i][j] = Some(v);
    v
}

impl fmt::Debug for Pattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Pattern({:?})", &*self.text)
    }
}

impl fmt::Display for Pattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// Splitting a topic without allocating for the usual handful of segments.
mod smallvec_lite {
    const INLINE: usize = 8;

    pub enum Parts<'t> {
        Inline([&'t str; INLINE], usize),
        Heap(Vec<&'t str>),
    }

    impl<'t> Parts<'t> {
        pub fn new(topic: &'t str) -> Self {
            let mut arr = [""; INLINE];
            let mut n = 0;
            for part in topic.split('.') {
                if n == INLINE {
                    return Parts::Heap(topic.split('.').collect());
                }
                arr[n] = part;
                n += 1;
            }
            Parts::Inline(arr, n)
        }

        pub fn as_slice(&self) -> &[&'t str] {
            match self {
                Parts::Inline(arr, n) => &arr[..*n],
                Parts::Heap(v) => v,
            }
        }
    }
}

/// A channel subscription: a regular expression matched against the whole channel name
/// (`POSE.*` matches `POSE_EST` but not `MY_POSE`), as LCM's own subscriptions are.
#[derive(Clone)]
pub struct ChannelRegex {
    text: String,
    re: regex::Regex,
}

impl ChannelRegex {
    /// Compiles `pattern`, anchored at both ends.
    pub fn new(pattern: &str) -> Result<ChannelRegex, regex::Error> {
        Ok(ChannelRegex {
            text: pattern.to_string(),
            re: regex::Regex::new(&format!("^(?:{pattern})$"))?,
        })
    }

    /// True when the whole of `channel` matches.
    pub fn matches(&self, channel: &str) -> bool {
        self.re.is_match(channel)
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.text
    }
}

impl fmt::Debug for ChannelRegex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ChannelRegex({:?})", self.text)
    }
}

impl fmt::Display for ChannelRegex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> Pattern {
        Pattern::new(s).unwrap()
    }

    #[test]
    fn topics_are_checked() {
        assert!(Topic::new("nav.attitude").is_ok());
        assert_eq!(Topic::new(""), Err(TopicError::Empty));
        assert!(matches!(
            Topic::new("nav..x"),
            Err(TopicError::EmptySegment(_))
        ));
        assert!(matches!(
            Topic::new("nav.x "),
            Err(TopicError::BadChar(_, ' '))
        ));
        assert!(matches!(
            Topic::new("nav.*"),
            Err(TopicError::BadChar(_, '*'))
        ));
        assert!(matches!(
            Pattern::new("nav.a*"),
            Err(TopicError::PartialWildcard(_))
        ));
        assert!(matches!(
            Topic::new(&"x".repeat(256)),
            Err(TopicError::TooLong(256))
        ));
    }

    #[test]
    fn wildcards_match_segments() {
        assert!(p("nav.*").matches("nav.depth"));
        assert!(!p("nav.*").matches("nav.gps.raw"));
        assert!(!p("nav.*").matches("nav"));
        assert!(p("nav.**").matches("nav"));
        assert!(p("nav.**").matches("nav.gps.raw"));
        assert!(p("**").matches("anything.at.all"));
        assert!(p("**.raw").matches("nav.gps.raw"));
        assert!(p("a.**.z").matches("a.z"));
        assert!(p("a.**.z").matches("a.b.c.z"));
        assert!(!p("a.**.z").matches("a.b.c"));
        assert!(p("nav.depth").matches("nav.depth"));
        assert!(!p("nav.depth").matches("nav.depths"));
        assert!(p("*.*.*.*.*.*.*.*.*.j").matches("a.b.c.d.e.f.g.h.i.j"));
    }

    #[test]
    fn renames_fill_captures_in_order() {
        let from = p("nav.*.**");
        let caps = from.captures("nav.gps.raw.x").unwrap();
        assert_eq!(caps, vec![vec!["gps"], vec!["raw", "x"]]);
        assert_eq!(
            p("auv1.*.data.**").fill(&caps).unwrap(),
            "auv1.gps.data.raw.x"
        );
        let caps = p("nav.**").captures("nav").unwrap();
        assert_eq!(p("auv1.nav.**").fill(&caps).unwrap(), "auv1.nav");
        assert!(p("x.*").fill(&[]).is_none());
    }

    #[test]
    fn adversarial_patterns_match_in_polynomial_time() {
        let p = Pattern::new("**.**.**.**.**.**.**.z").unwrap();
        let topic = vec!["a"; 120].join(".");
        // segment-by-segment backtracking would not finish this
        assert!(!p.matches(&topic));
        assert!(p.captures(&topic).is_none());
        assert!(p.matches(&format!("{topic}.z")));
    }

    #[test]
    fn overlap_is_decided_on_segments() {
        assert!(p("nav.*").overlaps(&p("*.depth")));
        assert!(!p("nav.*").overlaps(&p("cmd.*")));
        assert!(p("**").overlaps(&p("a.b.c")));
        assert!(p("a.**.c").overlaps(&p("**.b.c")));
        assert!(!p("a.*").overlaps(&p("a.*.*")));
        assert!(p("a.**").overlaps(&p("a")));
        assert!(!p("a.*").overlaps(&p("a")));
    }

    #[test]
    fn channel_patterns_match_whole_names() {
        let r = ChannelRegex::new("POSE.*").unwrap();
        assert!(r.matches("POSE") && r.matches("POSE_EST"));
        assert!(!r.matches("MY_POSE"));
        let r = ChannelRegex::new("A|B").unwrap();
        assert!(r.matches("A") && r.matches("B") && !r.matches("AB"));
        assert!(ChannelRegex::new("(").is_err());
    }

    #[test]
    fn channel_names_are_kept_as_they_came_and_shown_quoted() {
        for name in ["POSE.", ".POSE", "a..b", "cam*", "with space"] {
            assert!(Topic::new(name).is_err(), "{name}");
            let t = Topic::channel(name).unwrap();
            assert_eq!(t.as_str(), name);
            assert!(!t.is_topic());
            assert_eq!(t.shown(), format!("{name:?}"));
        }
        let t = Topic::channel("nav.depth").unwrap();
        assert!(t.is_topic());
        assert_eq!(t, Topic::new("nav.depth").unwrap());
        assert_eq!(t.shown(), "nav.depth");
        assert_eq!(Topic::channel(""), Err(TopicError::Empty));
        assert!(Topic::channel("a\0b").is_err());
        assert!(Topic::channel(&"x".repeat(MAX_TOPIC_LEN + 1)).is_err());
    }
}
