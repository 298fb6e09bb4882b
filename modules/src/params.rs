//! Module parameters from a system file, with their places, so that a bad value names file, line
//! and column, and a parameter no module reads (a typo) is reported rather than ignored.
//!
//! A parameter is written either as an attribute of `<module>` (`topic="nav.depth"`) or as a child
//! `<param name="topic" value="nav.depth"/>`.

use seabus_medium::parse::{parse_bool, parse_duration};
use seabus_medium::xml::{FileError, Pos};
use seabus_medium::{Pattern, Topic};
use std::str::FromStr;
use std::sync::Mutex;
use std::time::Duration;

/// One parameter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Param {
    /// Its name.
    pub name: String,
    /// Its value as written.
    pub value: String,
    /// Where it was written.
    pub pos: Pos,
}

impl Param {
    /// An error about this parameter's value.
    pub fn error(&self, message: impl std::fmt::Display) -> FileError {
        self.pos
            .error(format!("parameter `{}`: {message}", self.name))
    }
}

/// The parameters of one module, tracking which ones were read.
#[derive(Debug)]
pub struct Params {
    items: Vec<Param>,
    used: Mutex<Vec<bool>>,
    /// Where the owning element is.
    pub pos: Pos,
}

impl PartialEq for Params {
    fn eq(&self, other: &Self) -> bool {
        self.items == other.items
    }
}

impl Clone for Params {
    fn clone(&self) -> Self {
        Params {
            items: self.items.clone(),
            used: Mutex::new(self.used().clone()),
            pos: self.pos.clone(),
        }
    }
}

impl Params {
    fn used(&self) -> std::sync::MutexGuard<'_, Vec<bool>> {
        self.used.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Parameters from a list.
    pub fn new(items: Vec<Param>, pos: Pos) -> Params {
        let used = Mutex::new(vec![false; items.len()]);
        Params { items, used, pos }
    }

    /// Parameters from `name=value` pairs (for modules built in code).
    pub fn from_pairs(pairs: &[(&str, &str)]) -> Params {
        let pos = Pos {
            file: "<code>".into(),
            line: 1,
            col: 1,
        };
        Params::new(
            pairs
                .iter()
                .map(|(k, v)| Param {
                    name: k.to_string(),
                    value: v.to_string(),
                    pos: pos.clone(),
                })
                .collect(),
            pos,
        )
    }

    /// Every parameter.
    pub fn iter(&self) -> impl Iterator<Item = &Param> {
        self.items.iter()
    }

    /// The parameter `name`, marking it read.
    pub fn get(&self, name: &str) -> Option<&Param> {
        let i = self.items.iter().rposition(|p| p.name == name)?;
        for (j, p) in self.items.iter().enumerate() {
            if p.name == name {
                self.used()[j] = true;
            }
        }
        Some(&self.items[i])
    }

    /// Every parameter whose name starts with `prefix`, marking them read.
    pub fn with_prefix<'a>(&'a self, prefix: &'a str) -> Vec<&'a Param> {
        let mut out = Vec::new();
        for (j, p) in self.items.iter().enumerate() {
            if p.name.starts_with(prefix) {
                self.used()[j] = true;
                out.push(p);
            }
        }
        out
    }

    /// The text of parameter `name`.
    pub fn str(&self, name: &str) -> Option<&str> {
        self.get(name).map(|p| p.value.as_str())
    }

    /// An error at the element the parameters belong to.
    pub fn error(&self, message: impl std::fmt::Display) -> FileError {
        self.pos.error(message.to_string())
    }

    /// The text of parameter `name`, or an error saying the module needs it.
    pub fn required(&self, name: &str) -> Result<&Param, FileError> {
        self.get(name)
            .ok_or_else(|| self.pos.error(format!("missing parameter `{name}`")))
    }

    /// Parses parameter `name` when present.
    pub fn parse<T: FromStr>(&self, name: &str, expected: &str) -> Result<Option<T>, FileError> {
        match self.get(name) {
            None => Ok(None),
            Some(p) => p
                .value
                .trim()
                .parse()
                .map(Some)
                .map_err(|_| p.error(format!("`{}` is not {expected}", p.value))),
        }
    }

    /// Parses parameter `name`, or gives `default`.
    pub fn parse_or<T: FromStr>(
        &self,
        name: &str,
        default: T,
        expected: &str,
    ) -> Result<T, FileError> {
        Ok(self.parse(name, expected)?.unwrap_or(default))
    }

    /// A float parameter, checked to be finite.
    pub fn float_or(&self, name: &str, default: f64) -> Result<f64, FileError> {
        let v: f64 = self.parse_or(name, default, "a number")?;
        if !v.is_finite() {
            return Err(self.get(name).map_or_else(
                || self.pos.error("not finite"),
                |p| p.error("must be finite"),
            ));
        }
        Ok(v)
    }

    /// A float parameter that must be above zero, or `default`.
    pub fn positive_or(&self, name: &str, default: f64) -> Result<f64, FileError> {
        let v = self.float_or(name, default)?;
        match self.get(name) {
            Some(p) if v <= 0.0 => Err(p.error("must be above zero")),
            _ => Ok(v),
        }
    }

    /// A float parameter that must not be negative, or `default`.
    pub fn non_negative_or(&self, name: &str, default: f64) -> Result<f64, FileError> {
        let v = self.float_or(name, default)?;
        match self.get(name) {
            Some(p) if v < 0.0 => Err(p.error("must not be negative")),
            _ => Ok(v),
        }
    }

    /// A topic parameter, or `default`.
    pub fn topic_or(&self, name: &str, default: &str) -> Result<Topic, FileError> {
        match self.get(name) {
            None => Topic::new(default)
                .map_err(|e| self.pos.error(format!("default topic `{default}`: {e}"))),
            Some(p) => Topic::new(p.value.trim()).map_err(|e| p.error(e)),
        }
    }

    /// A topic parameter, or the topic the catalogue gives `dataset` (`fallback` when it has none).
    pub fn dataset_topic_or(
        &self,
        name: &str,
        cat: &crate::Catalogue,
        dataset: &str,
        fallback: &str,
    ) -> Result<Topic, FileError> {
        self.topic_or(name, &cat.topic_of(dataset, fallback))
    }

    /// The topic the catalogue gives `dataset` (`fallback` when it has none), for a module that
    /// takes no parameter for it.
    pub fn dataset_topic(
        &self,
        cat: &crate::Catalogue,
        dataset: &str,
        fallback: &str,
    ) -> Result<Topic, FileError> {
        let topic = cat.topic_of(dataset, fallback);
        Topic::new(&topic).map_err(|e| self.pos.error(format!("topic `{topic}`: {e}")))
    }

    /// A topic-pattern parameter, or `default`.
    pub fn pattern_or(&self, name: &str, default: &str) -> Result<Pattern, FileError> {
        match self.get(name) {
            None => Pattern::new(default)
                .map_err(|e| self.pos.error(format!("default pattern `{default}`: {e}"))),
            Some(p) => Pattern::new(p.value.trim()).map_err(|e| p.error(e)),
        }
    }

    /// A duration parameter (`250ms`, `2s`, a bare number of milliseconds), or `default`.
    pub fn duration_or(&self, name: &str, default: Duration) -> Result<Duration, FileError> {
        match self.get(name) {
            None => Ok(default),
            Some(p) => parse_duration(&p.value).ok_or_else(|| {
                p.error(format!(
                    "`{}` is not a duration such as 500ms or 2s",
                    p.value
                ))
            }),
        }
    }

    /// A boolean parameter, or `default`.
    pub fn flag_or(&self, name: &str, default: bool) -> Result<bool, FileError> {
        match self.get(name) {
            None => Ok(default),
            Some(p) => parse_bool(&p.value)
                .ok_or_else(|| p.error(format!("`{}` is not true or false", p.value.trim()))),
        }
    }

    /// Fails on the first parameter nothing read, naming the module type.
    pub fn finish(&self, module_type: &str) -> Result<(), FileError> {
        let used = self.used();
        match self.items.iter().zip(used.iter()).find(|(_, u)| !**u) {
            None => Ok(()),
            Some((p, _)) => Err(p.pos.error(format!(
                "module type `{module_type}` has no parameter `{}`",
                p.name
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unread_parameters_are_reported() {
        let p = Params::from_pairs(&[("topic", "a.b"), ("rtae", "5")]);
        assert_eq!(p.topic_or("topic", "x").unwrap().as_str(), "a.b");
        let e = p.finish("generator").unwrap_err();
        assert!(e.message.contains("has no parameter `rtae`"), "{e}");
    }

    #[test]
    fn values_are_checked() {
        let p = Params::from_pairs(&[("n", "x"), ("t", "a..b"), ("d", "5 parsecs")]);
        assert!(
            p.parse::<i64>("n", "an integer")
                .unwrap_err()
                .message
                .contains("`x` is not an integer")
        );
        assert!(p.topic_or("t", "x").is_err());
        assert!(p.duration_or("d", Duration::ZERO).is_err());
        assert_eq!(p.parse_or("missing", 3, "n").unwrap(), 3);
    }
}
