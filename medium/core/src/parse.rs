//! Reading the small values users write in files, URLs and on the command line: booleans,
//! durations, rates, and typed `key=value` fields. One reader each, shared by every place that
//! takes them.

use crate::datamap::{DataMap, Value};
use std::time::Duration;

/// Longest duration seabus accepts anywhere (about 31 years).
pub const MAX_SECS: f64 = 1e9;

/// `true`/`yes`/`on`/`1` or `false`/`no`/`off`/`0`.
pub fn parse_bool(text: &str) -> Option<bool> {
    match text.trim() {
        "true" | "yes" | "on" | "1" => Some(true),
        "false" | "no" | "off" | "0" => Some(false),
        _ => None,
    }
}

/// A duration from seconds, when the number is finite, not negative and at most [`MAX_SECS`].
pub fn secs(seconds: f64) -> Option<Duration> {
    if seconds.is_finite() && (0.0..=MAX_SECS).contains(&seconds) {
        Duration::try_from_secs_f64(seconds).ok()
    } else {
        None
    }
}

/// Parses `250ms`, `2s`, `0.5s`, `100us`, `1min`, `2h` or a bare number of milliseconds.
pub fn parse_duration(text: &str) -> Option<Duration> {
    let t = text.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix("us") {
        (n, 1e-6)
    } else if let Some(n) = t.strip_suffix("min") {
        (n, 60.0)
    } else if let Some(n) = t.strip_suffix('h') {
        (n, 3600.0)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else {
        (t, 1e-3)
    };
    let v: f64 = num.trim().parse().ok()?;
    secs(v * scale)
}

/// Parses a rate as the period between events: `10` or `10Hz` (per second), or a period such as
/// `500ms` or `2s`. Zero, negative and absurd rates are refused.
pub fn parse_rate(text: &str) -> Option<Duration> {
    let t = text.trim();
    let hz = t
        .strip_suffix("Hz")
        .or_else(|| t.strip_suffix("hz"))
        .unwrap_or(t);
    if let Ok(f) = hz.trim().parse::<f64>() {
        return rate_period(f);
    }
    parse_duration(t).filter(|d| !d.is_zero())
}

/// The period of a rate in events per second (above 0, at most a million per second).
pub fn rate_period(per_second: f64) -> Option<Duration> {
    if per_second.is_finite() && per_second > 0.0 && per_second <= 1e6 {
        secs(1.0 / per_second).filter(|d| !d.is_zero())
    } else {
        None
    }
}

/// Splits `text` into words at blanks. A double-quoted run keeps its blanks inside its word and its
/// quotes in the word (`reason="no depth"` is one word); a quote left open is an error.
pub fn split_words(text: &str) -> Result<Vec<&str>, String> {
    let mut words = Vec::new();
    let mut start: Option<usize> = None;
    let mut quoted = false;
    for (i, c) in text.char_indices() {
        if c == '"' {
            quoted = !quoted;
        }
        if c.is_whitespace() && !quoted {
            if let Some(s) = start.take() {
                words.push(&text[s..i]);
            }
        } else if start.is_none() {
            start = Some(i);
        }
    }
    if quoted {
        return Err("a double quote `\"` is not closed".to_string());
    }
    if let Some(s) = start {
        words.push(&text[s..]);
    }
    Ok(words)
}

/// One `key=value` field: the key is what comes before the first `=` (not empty), the value is
/// bytes when written `hex:0102ff` or `base64:AQL/` ([`parse_bytes`]), else typed by
/// [`Value::parse_loose`] (`1` an integer, `2.5` a float, `true` a boolean, `"7"` and anything
/// else a string).
pub fn parse_field(text: &str) -> Result<(&str, Value), String> {
    let (key, value) = text
        .split_once('=')
        .ok_or_else(|| format!("`{text}` is not key=value"))?;
    if key.is_empty() {
        return Err(format!("`{text}` has an empty key"));
    }
    match parse_bytes(value) {
        Some(bytes) => Ok((
            key,
            Value::Bytes(bytes.map_err(|e| format!("`{key}`: {e}"))?),
        )),
        None => Ok((key, Value::parse_loose(value))),
    }
}

/// Bytes written `hex:0102ff` (two hex digits a byte, upper or lower case; `hex:` alone is no
/// bytes) or `base64:AQL/` (standard base64 with its padding); `None` when `text` is neither form.
pub fn parse_bytes(text: &str) -> Option<Result<Vec<u8>, String>> {
    use base64::Engine as _;
    if let Some(hex) = text.strip_prefix("hex:") {
        if let Some((i, c)) = hex.char_indices().find(|(_, c)| !c.is_ascii_hexdigit()) {
            return Some(Err(format!("`{text}`: `{c}` at {i} is not a hex digit")));
        }
        if hex.len() % 2 != 0 {
            return Some(Err(format!(
                "`{text}`: hex bytes are two digits each, {} digits given",
                hex.len()
            )));
        }
        let digit = |c: u8| (c as char).to_digit(16).unwrap_or(0) as u8;
        let bytes = hex
            .as_bytes()
            .chunks(2)
            .map(|p| digit(p[0]) << 4 | digit(p[1]))
            .collect();
        return Some(Ok(bytes));
    }
    let b64 = text.strip_prefix("base64:")?;
    Some(
        base64::engine::general_purpose::STANDARD
            .decode(b64)
            .map_err(|e| format!("`{text}`: not base64 ({e})")),
    )
}

/// A datamap of `key=value` fields ([`parse_field`]) in order; a key given again replaces its
/// earlier value.
pub fn parse_fields<'a>(fields: impl IntoIterator<Item = &'a str>) -> Result<DataMap, String> {
    let mut map = DataMap::new();
    for f in fields {
        let (key, value) = parse_field(f)?;
        map.insert(key.to_string(), value);
    }
    Ok(map)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse() {
        assert_eq!(parse_duration("5ms"), Some(Duration::from_millis(5)));
        assert_eq!(parse_duration("0.5s"), Some(Duration::from_millis(500)));
        assert_eq!(parse_duration("2min"), Some(Duration::from_secs(120)));
        assert_eq!(parse_duration("1.5h"), Some(Duration::from_secs(5400)));
        assert_eq!(parse_duration("250"), Some(Duration::from_millis(250)));
        assert_eq!(parse_duration("-1s"), None);
        assert_eq!(parse_duration("1e300s"), None);
        assert_eq!(parse_duration("x"), None);
    }

    #[test]
    fn rates_read_as_hertz_or_periods() {
        assert_eq!(parse_rate("10"), Some(Duration::from_millis(100)));
        assert_eq!(parse_rate("2Hz"), Some(Duration::from_millis(500)));
        assert_eq!(parse_rate("250ms"), Some(Duration::from_millis(250)));
        assert_eq!(parse_rate("0"), None);
        assert_eq!(parse_rate("1e-300"), None);
        assert_eq!(parse_rate("1e-20Hz"), None);
        assert_eq!(parse_rate("1e10"), None);
        assert_eq!(parse_rate("fast"), None);
    }

    #[test]
    fn seconds_are_bounded() {
        assert_eq!(secs(1.5), Some(Duration::from_millis(1500)));
        assert_eq!(secs(-1.0), None);
        assert_eq!(secs(f64::NAN), None);
        assert_eq!(secs(1e30), None);
        assert_eq!(parse_bool(" yes "), Some(true));
        assert_eq!(parse_bool("maybe"), None);
    }

    #[test]
    fn fields_are_typed() {
        let m = parse_fields(["a=1", "b=2.5", "c=true", "d=\"7\"", "e=x=y", "a=2"]).unwrap();
        assert_eq!(m.len(), 5);
        assert_eq!(m.get("a"), Some(&Value::Int(2)));
        assert_eq!(m.get("b"), Some(&Value::Float(2.5)));
        assert_eq!(m.get("c"), Some(&Value::Bool(true)));
        assert_eq!(m.get("d"), Some(&Value::Str("7".into())));
        assert_eq!(m.get("e"), Some(&Value::Str("x=y".into())));
        assert_eq!(
            parse_fields(["novalue"]).unwrap_err(),
            "`novalue` is not key=value"
        );
        assert_eq!(parse_fields(["=1"]).unwrap_err(), "`=1` has an empty key");
    }

    #[test]
    fn words_split_at_blanks_outside_quotes() {
        assert_eq!(
            split_words("  cmd.x a=1\treason=\"no  depth\" \"b c\"d ").unwrap(),
            ["cmd.x", "a=1", "reason=\"no  depth\"", "\"b c\"d"]
        );
        assert_eq!(split_words(" \n ").unwrap(), Vec::<&str>::new());
        assert_eq!(
            split_words("a b=\"open").unwrap_err(),
            "a double quote `\"` is not closed"
        );
        assert_eq!(
            parse_field("data=hex:01fF").unwrap(),
            ("data", Value::Bytes(vec![1, 255]))
        );
        assert_eq!(
            parse_field("data=base64:AQI=").unwrap(),
            ("data", Value::Bytes(vec![1, 2]))
        );
        assert_eq!(
            parse_field("data=hex:").unwrap(),
            ("data", Value::Bytes(vec![]))
        );
        assert_eq!(
            parse_field("data=hex:012").unwrap_err(),
            "`data`: `hex:012`: hex bytes are two digits each, 3 digits given"
        );
        assert_eq!(
            parse_field("data=hex:0g").unwrap_err(),
            "`data`: `hex:0g`: `g` at 1 is not a hex digit"
        );
        assert!(
            parse_field("data=base64:A")
                .unwrap_err()
                .starts_with("`data`: `base64:A`: not base64")
        );
        assert_eq!(
            parse_field("word=hexagon").unwrap(),
            ("word", Value::from("hexagon"))
        );
        let (k, v) = parse_field("reason=\"no  depth\"").unwrap();
        assert_eq!((k, v), ("reason", Value::Str("no  depth".into())));
    }
}
