//! seabus topics and patterns as Zenoh key expressions, under a medium's prefix.
//!
//! A topic's dots become slashes under the prefix: with `prefix=fleet/auv1`, `nav.attitude` is
//! `fleet/auv1/nav/attitude`, and a sample on `fleet/auv1/cmd/course` arrives as `cmd.course`. A
//! pattern's `*` and `**` are Zenoh's (one chunk; any number of chunks, none included), so
//! `nav.**` asks for `fleet/auv1/nav/**`. A shore station whose prefix is `fleet` sees the
//! vehicles' topics with the vehicle's name first (`auv1.nav.attitude`) and commands a vehicle
//! by naming it (`auv1.cmd.course` is `fleet/auv1/cmd/course`, the vehicle's `cmd.course`).
//!
//! A segment holding a character Zenoh reserves (`*`, `$`, `?`, `#`, `/`), or starting with `@`,
//! cannot be a key: such a topic is refused at send, such a prefix when the medium opens, and a
//! sample whose key is no seabus topic is counted and dropped.

use seabus_medium::{Pattern, Topic};
use std::fmt;

/// Why a name is no key expression, or a key no topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyError(pub String);

impl fmt::Display for KeyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Whether `chunk` is a literal chunk of a key expression.
fn literal(chunk: &str) -> Result<(), String> {
    if chunk.is_empty() {
        return Err("an empty chunk".to_string());
    }
    if chunk.starts_with('@') {
        return Err(format!("`{chunk}` starts with `@`, which Zenoh reserves"));
    }
    if let Some(c) = chunk
        .chars()
        .find(|c| matches!(c, '*' | '$' | '?' | '#' | '/'))
    {
        return Err(format!("`{chunk}` holds `{c}`, which Zenoh reserves"));
    }
    Ok(())
}

/// Checks a prefix: literal chunks separated by `/`.
pub fn check_prefix(prefix: &str) -> Result<(), KeyError> {
    for chunk in prefix.split('/') {
        literal(chunk).map_err(|e| KeyError(format!("prefix `{prefix}`: {e}")))?;
    }
    Ok(())
}

/// The key of `topic` under `prefix`.
pub fn topic_key(prefix: &str, topic: &Topic) -> Result<String, KeyError> {
    let mut key = String::with_capacity(prefix.len() + 1 + topic.as_str().len());
    key.push_str(prefix);
    for seg in topic.as_str().split('.') {
        literal(seg).map_err(|e| KeyError(format!("topic `{topic}` is no Zenoh key: {e}")))?;
        key.push('/');
        key.push_str(seg);
    }
    Ok(key)
}

/// The key expression asking for what `pattern` matches under `prefix`.
pub fn pattern_key(prefix: &str, pattern: &Pattern) -> Result<String, KeyError> {
    let text = pattern.as_str();
    let mut key = String::with_capacity(prefix.len() + 1 + text.len());
    key.push_str(prefix);
    for seg in text.split('.') {
        if seg != "*" && seg != "**" {
            literal(seg).map_err(|e| KeyError(format!("pattern `{text}` is no Zenoh key: {e}")))?;
        }
        key.push('/');
        key.push_str(seg);
    }
    Ok(key)
}

/// The topic of a sample on `key`, under `prefix`.
pub fn key_topic(prefix: &str, key: &str) -> Result<Topic, KeyError> {
    let rest = key
        .strip_prefix(prefix)
        .and_then(|r| r.strip_prefix('/'))
        .ok_or_else(|| KeyError(format!("key `{key}` is not under `{prefix}`")))?;
    let dotted = rest.replace('/', ".");
    Topic::new(&dotted).map_err(|e| KeyError(format!("key `{key}` is no seabus topic: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: &str) -> Topic {
        Topic::new(s).unwrap()
    }

    #[test]
    fn topics_and_patterns_become_keys_under_the_prefix() {
        assert_eq!(
            topic_key("fleet/auv1", &t("nav.attitude")).unwrap(),
            "fleet/auv1/nav/attitude"
        );
        let p = |s: &str| Pattern::new(s).unwrap();
        assert_eq!(pattern_key("fleet", &p("**")).unwrap(), "fleet/**");
        assert_eq!(
            pattern_key("fleet", &p("*.nav.position")).unwrap(),
            "fleet/*/nav/position"
        );
        assert_eq!(
            pattern_key("fleet/auv1", &p("cmd.**")).unwrap(),
            "fleet/auv1/cmd/**"
        );
        assert_eq!(
            key_topic("fleet", "fleet/auv1/nav/attitude").unwrap(),
            t("auv1.nav.attitude")
        );
        assert_eq!(
            key_topic("fleet/auv1", "fleet/auv1/cmd/course").unwrap(),
            t("cmd.course")
        );
    }

    #[test]
    fn what_is_no_key_or_no_topic_says_why() {
        let e = topic_key("fleet", &t("price.$5")).unwrap_err();
        assert_eq!(
            e.0,
            "topic `price.$5` is no Zenoh key: `$5` holds `$`, which Zenoh reserves"
        );
        let e = topic_key("fleet", &t("a/b.c")).unwrap_err();
        assert!(e.0.contains("`a/b` holds `/`"), "{e}");
        let e = check_prefix("fleet//auv1").unwrap_err();
        assert_eq!(e.0, "prefix `fleet//auv1`: an empty chunk");
        assert!(check_prefix("fleet/*").is_err());
        assert!(check_prefix("@admin").is_err());
        assert!(check_prefix("fleet/auv1").is_ok());
        let e = key_topic("fleet", "other/auv1/nav").unwrap_err();
        assert_eq!(e.0, "key `other/auv1/nav` is not under `fleet`");
        assert!(key_topic("fleet", "fleet/a b").is_err());
        assert!(key_topic("fleet", "fleet").is_err());
    }
}
