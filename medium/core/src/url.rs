//! Medium URLs: `scheme://host:port/path?key=value&…`.
//!
//! Every medium is named by a URL (`udp://239.255.42.1:47800?ttl=0`, `inproc://`,
//! `serial:///dev/ttyUSB0?baud=19200`). This reader keeps the parts each medium needs, decodes
//! `%XX` escapes in the query, and lets a medium take its options one by one so that an option nobody
//! took is reported by name.

use std::fmt;
use std::str::FromStr;
use thiserror::Error;

/// Why a medium URL is not valid.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("bad medium URL `{url}`: {reason}")]
pub struct UrlError {
    /// The URL as written.
    pub url: String,
    /// What is wrong with it.
    pub reason: String,
}

/// A parsed medium URL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MediumUrl {
    raw: String,
    /// The scheme, lower case (`udp`).
    pub scheme: String,
    /// The host, without IPv6 brackets; empty when absent.
    pub host: String,
    /// The port, when given.
    pub port: Option<u16>,
    /// The path, including its leading `/`; empty when absent.
    pub path: String,
    query: Vec<(String, String)>,
    taken: Vec<bool>,
}

impl MediumUrl {
    /// Parses `text`.
    pub fn parse(text: &str) -> Result<MediumUrl, UrlError> {
        let err = |reason: String| UrlError {
            url: text.to_string(),
            reason,
        };
        let (scheme, rest) = text.split_once("://").ok_or_else(|| {
            err("expected `scheme://…` (for example udp://239.255.42.1:47800)".into())
        })?;
        if scheme.is_empty()
            || !scheme
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '+' || c == '-' || c == '.')
        {
            return Err(err(format!("`{scheme}` is not a scheme")));
        }
        let (before_query, query_text) = match rest.split_once('?') {
            Some((b, q)) => (b, Some(q)),
            None => (rest, None),
        };
        let (authority, path) = match before_query.find('/') {
            Some(i) => (&before_query[..i], &before_query[i..]),
            None => (before_query, ""),
        };
        let (host, port_text) = if let Some(v6) = authority.strip_prefix('[') {
            let (h, after) = v6
                .split_once(']')
                .ok_or_else(|| err("unclosed `[` in IPv6 host".into()))?;
            match after {
                "" => (h, None),
                p => (
                    h,
                    Some(
                        p.strip_prefix(':')
                            .ok_or_else(|| err(format!("unexpected `{p}` after IPv6 host")))?,
                    ),
                ),
            }
        } else {
            match authority.rsplit_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (authority, None),
            }
        };
        let port = match port_text {
            None => None,
            Some(p) => Some(
                p.parse::<u16>()
                    .map_err(|_| err(format!("`{p}` is not a port number (0–65535)")))?,
            ),
        };
        let mut query = Vec::new();
        if let Some(q) = query_text {
            for pair in q.split('&').filter(|p| !p.is_empty()) {
                let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
                let k = percent_decode(k).ok_or_else(|| err(format!("bad %-escape in `{k}`")))?;
                let v = percent_decode(v).ok_or_else(|| err(format!("bad %-escape in `{v}`")))?;
                query.push((k, v));
            }
        }
        Ok(MediumUrl {
            raw: text.to_string(),
            scheme: scheme.to_ascii_lowercase(),
            host: host.to_string(),
            port,
            path: path.to_string(),
            taken: vec![false; query.len()],
            query,
        })
    }

    /// The URL as written.
    pub fn as_str(&self) -> &str {
        &self.raw
    }

    /// An error about this URL.
    pub fn error(&self, reason: impl Into<String>) -> UrlError {
        UrlError {
            url: self.raw.clone(),
            reason: reason.into(),
        }
    }

    /// Takes the last value of option `key`, marking every occurrence as used.
    pub fn take(&mut self, key: &str) -> Option<String> {
        let mut found = None;
        for (i, (k, v)) in self.query.iter().enumerate() {
            if k == key {
                self.taken[i] = true;
                found = Some(v.clone());
            }
        }
        found
    }

    /// Takes every value of a repeatable option (`peer=a&peer=b`); commas also separate values.
    pub fn take_all(&mut self, key: &str) -> Vec<String> {
        let mut out = Vec::new();
        for (i, (k, v)) in self.query.iter().enumerate() {
            if k == key {
                self.taken[i] = true;
                out.extend(v.split(',').filter(|s| !s.is_empty()).map(str::to_string));
            }
        }
        out
    }

    /// Takes option `key` and parses it, naming the option and the expected form on failure.
    pub fn take_parsed<T: FromStr>(
        &mut self,
        key: &str,
        expected: &str,
    ) -> Result<Option<T>, UrlError> {
        match self.take(key) {
            None => Ok(None),
            Some(v) => v
                .parse()
                .map(Some)
                .map_err(|_| self.error(format!("option `{key}={v}`: expected {expected}"))),
        }
    }

    /// Takes a boolean option: present without a value, `1`, `true`, `yes` or `on` mean true.
    pub fn take_flag(&mut self, key: &str) -> Result<Option<bool>, UrlError> {
        match self.take(key) {
            None => Ok(None),
            // a flag given without a value (`?broadcast`) is set
            Some(v) if v.is_empty() => Ok(Some(true)),
            Some(v) => crate::parse::parse_bool(&v)
                .map(Some)
                .ok_or_else(|| self.error(format!("option `{key}={v}`: expected true or false"))),
        }
    }

    /// Takes every option whose name starts with `prefix`, returning `(name without prefix, value)`.
    pub fn take_prefixed(&mut self, prefix: &str) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for (i, (k, v)) in self.query.iter().enumerate() {
            if let Some(rest) = k.strip_prefix(prefix) {
                self.taken[i] = true;
                out.push((rest.to_string(), v.clone()));
            }
        }
        out
    }

    /// Fails, naming the first option no one took and listing `known` ones.
    pub fn finish(&self, known: &[&str]) -> Result<(), UrlError> {
        match self.query.iter().zip(&self.taken).find(|(_, t)| !**t) {
            None => Ok(()),
            Some(((k, _), _)) => Err(self.error(format!(
                "unknown option `{k}` for {}://; known options: {}",
                self.scheme,
                if known.is_empty() {
                    "none".to_string()
                } else {
                    known.join(", ")
                }
            ))),
        }
    }
}

impl fmt::Display for MediumUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.raw)
    }
}

fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'%' => {
                let hex = s.get(i + 1..i + 3)?;
                out.push(u8::from_str_radix(hex, 16).ok()?);
                i += 3;
            }
            b'+' => {
                out.push(b' ');
                i += 1;
            }
            b => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_parts() {
        let mut u =
            MediumUrl::parse("udp://239.255.42.1:47800?ttl=0&peer=a:1,b:2&peer=c:3").unwrap();
        assert_eq!(
            (u.scheme.as_str(), u.host.as_str(), u.port),
            ("udp", "239.255.42.1", Some(47800))
        );
        assert_eq!(u.take("ttl").as_deref(), Some("0"));
        assert_eq!(u.take_all("peer"), ["a:1", "b:2", "c:3"]);
        assert!(u.finish(&[]).is_ok());

        let u = MediumUrl::parse("serial:///dev/ttyUSB0?baud=19200").unwrap();
        assert_eq!(
            (u.host.as_str(), u.path.as_str(), u.port),
            ("", "/dev/ttyUSB0", None)
        );
        let u = MediumUrl::parse("udp://[::1]:5000").unwrap();
        assert_eq!((u.host.as_str(), u.port), ("::1", Some(5000)));
        let u = MediumUrl::parse("inproc://").unwrap();
        assert_eq!(u.host, "");
    }

    #[test]
    fn errors_say_what_is_wrong() {
        let e = MediumUrl::parse("239.255.42.1:47800").unwrap_err();
        assert!(e.reason.contains("scheme://"), "{e}");
        let e = MediumUrl::parse("udp://host:99999").unwrap_err();
        assert!(e.reason.contains("`99999` is not a port"), "{e}");
        let u = MediumUrl::parse("udp://h:1?tll=0").unwrap();
        let e = u.finish(&["ttl", "iface"]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "bad medium URL `udp://h:1?tll=0`: unknown option `tll` for udp://; known options: ttl, iface"
        );
        let mut u = MediumUrl::parse("udp://h:1?ttl=x").unwrap();
        let e = u.take_parsed::<u8>("ttl", "a number 0–255").unwrap_err();
        assert_eq!(e.reason, "option `ttl=x`: expected a number 0–255");
    }

    #[test]
    fn query_escapes_are_decoded() {
        let mut u = MediumUrl::parse("moos://h:9000?name=my%20app&x=a+b").unwrap();
        assert_eq!(u.take("name").as_deref(), Some("my app"));
        assert_eq!(u.take("x").as_deref(), Some("a b"));
        assert!(MediumUrl::parse("moos://h?x=%zz").is_err());
    }
}
