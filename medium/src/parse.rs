//! Reading the small values users write in files, URLs and on the command line: booleans,
//! durations, rates. One reader each, shared by every place that takes them.

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

/// Parses `250ms`, `2s`, `0.5s`, `100us`, `1min` or a bare number of milliseconds.
pub fn parse_duration(text: &str) -> Option<Duration> {
    let t = text.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix("us") {
        (n, 1e-6)
    } else if let Some(n) = t.strip_suffix("min") {
        (n, 60.0)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse() {
        assert_eq!(parse_duration("5ms"), Some(Duration::from_millis(5)));
        assert_eq!(parse_duration("0.5s"), Some(Duration::from_millis(500)));
        assert_eq!(parse_duration("2min"), Some(Duration::from_secs(120)));
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
}
