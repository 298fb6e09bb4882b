//! Attribute values as a layout writes them: names, numbers, durations, topics, `topic.field`
//! bindings, colours, lists and `F=V, …` field lists. Each reader refuses a value with an error
//! placed at its attribute (`FILE:LINE:COLUMN`).

use seabus_medium::parse::parse_duration;
use seabus_medium::xml::{Attr, Element, FileError};
use seabus_medium::{DataMap, Pattern, Topic, Value};
use std::time::Duration;

/// Colour names a layout may use besides `#rgb` and `#rrggbb`.
pub const COLOURS: [&str; 18] = [
    "black", "white", "gray", "grey", "red", "orange", "yellow", "green", "lime", "teal", "cyan",
    "blue", "navy", "purple", "magenta", "pink", "brown", "olive",
];

/// The items of a list separated by `sep`, trimmed, empty ones left out.
pub(super) fn list_items(text: &str, sep: char) -> impl Iterator<Item = &str> {
    text.split(sep).map(str::trim).filter(|s| !s.is_empty())
}

/// The words of a list separated by commas or blanks.
pub(super) fn list(text: &str) -> Vec<&str> {
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .collect()
}

/// A field value as written: `true`/`false`, an integer (no point), a number, or text.
pub(super) fn field_value(text: &str) -> Value {
    match text {
        "true" => return Value::Bool(true),
        "false" => return Value::Bool(false),
        _ => {}
    }
    let numeric = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '+' | '-' | '.' | 'e' | 'E'))
        && text.chars().any(|c| c.is_ascii_digit());
    if numeric {
        if let Ok(i) = text.parse::<i64>() {
            return Value::Int(i);
        }
        if let Some(f) = text.parse::<f64>().ok().filter(|f| f.is_finite()) {
            return Value::Float(f);
        }
    }
    Value::from(text)
}

/// `F=V, …` as a datamap in order, or the reason it does not read.
pub(super) fn field_list(text: &str) -> Result<DataMap, String> {
    let mut map = DataMap::new();
    for item in field_items(text)?
        .into_iter()
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        let Some((name, value)) = item.split_once('=') else {
            return Err(format!("`{item}` is not FIELD=VALUE"));
        };
        let name = name.trim();
        if !is_name(name) {
            return Err(format!(
                "`{name}` is not a field name: use letters, digits, `_` and `-`"
            ));
        }
        if map.get(name).is_some() {
            return Err(format!("field `{name}` is given twice"));
        }
        map.insert(name.to_string(), listed_value(value.trim())?);
    }
    Ok(map)
}

/// The items of a field list: split at the commas outside double quotes.
fn field_items(text: &str) -> Result<Vec<&str>, String> {
    let mut items = Vec::new();
    let mut start = 0;
    let mut quoted = false;
    for (i, c) in text.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => {
                items.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    if quoted {
        return Err("a double quote `\"` is not closed".to_string());
    }
    items.push(&text[start..]);
    Ok(items)
}

/// The value of one `F=V` item: quoted text as it is, anything else as [`field_value`] reads it.
fn listed_value(value: &str) -> Result<Value, String> {
    match value.strip_prefix('"') {
        Some(rest) => match rest.strip_suffix('"') {
            Some(inner) if !inner.contains('"') => Ok(Value::from(inner)),
            _ => Err(format!("`{value}` is not a quoted text (\"…\")")),
        },
        None if value.contains('"') => Err(format!("`{value}`: quote the whole value (\"…\")")),
        None => Ok(field_value(value)),
    }
}

/// Letters, digits, `_` and `-`, not empty.
pub fn is_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// A name (see [`is_name`]); `what` says what it names, with its article (`a role`).
pub(super) fn name_attr(a: &Attr, what: &str) -> Result<String, FileError> {
    let v = a.value.trim();
    if is_name(v) {
        Ok(v.to_string())
    } else {
        Err(a.error(format!(
            "`{v}` is not {what} name: use letters, digits, `_` and `-` (at most 64)"
        )))
    }
}

/// Role names separated by blanks, each once.
pub(super) fn roles(a: &Attr) -> Result<Vec<String>, FileError> {
    let mut out: Vec<String> = Vec::new();
    for r in a.value.split_whitespace() {
        if !is_name(r) {
            return Err(a.error(format!(
                "`{r}` is not a role name: use letters, digits, `_` and `-`"
            )));
        }
        if !out.iter().any(|x| x == r) {
            out.push(r.to_string());
        }
    }
    Ok(out)
}

/// A finite number.
pub(super) fn finite(a: &Attr) -> Result<f64, FileError> {
    a.value
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| a.error(format!("`{}` is not a number", a.value.trim())))
}

/// A whole number from `min` to `max`.
pub(super) fn count(a: &Attr, min: u64, max: u64) -> Result<u64, FileError> {
    a.value
        .trim()
        .parse::<u64>()
        .ok()
        .filter(|n| (min..=max).contains(n))
        .ok_or_else(|| {
            a.error(format!(
                "`{}` is not a whole number from {min} to {max}",
                a.value.trim()
            ))
        })
}

/// A duration above zero.
pub(super) fn duration(a: &Attr) -> Result<Duration, FileError> {
    parse_duration(&a.value)
        .filter(|d| !d.is_zero())
        .ok_or_else(|| {
            a.error(format!(
                "`{}` is not a duration (250ms, 2s, 1min)",
                a.value.trim()
            ))
        })
}

/// `text` (part of `a`'s value) as a topic.
pub(super) fn topic(a: &Attr, text: &str) -> Result<Topic, FileError> {
    Topic::new(text.trim()).map_err(|e| a.error(format!("`{}` is not a topic: {e}", text.trim())))
}

/// `text` (part of `a`'s value) as a topic pattern.
pub(super) fn pattern(a: &Attr, text: &str) -> Result<Pattern, FileError> {
    Pattern::new(text.trim())
        .map_err(|e| a.error(format!("`{}` is not a topic pattern: {e}", text.trim())))
}

/// `topic.field`, split at the last dot: the topic part and the field.
fn split_bind(a: &Attr) -> Result<(&str, String), FileError> {
    let text = a.value.trim();
    let Some((t, field)) = text.rsplit_once('.') else {
        return Err(a.error(format!(
            "`{text}` is not topic.field (the field is after the last dot: nav.depth.depth)"
        )));
    };
    if !is_name(field) {
        return Err(a.error(format!("`{field}` is not a field name in `{text}`")));
    }
    Ok((t, field.to_string()))
}

/// `topic.field`, split at the last dot.
pub(super) fn bind(a: &Attr) -> Result<(Topic, String), FileError> {
    let (t, field) = split_bind(a)?;
    Ok((topic(a, t)?, field))
}

/// `pattern.field` (`*.nav.attitude.yaw`), split at the last dot.
pub(super) fn bind_pattern(a: &Attr) -> Result<(Pattern, String), FileError> {
    let (t, field) = split_bind(a)?;
    Ok((pattern(a, t)?, field))
}

/// `text` (part of `a`'s value) as a colour: `#rgb`, `#rrggbb` or one of [`COLOURS`].
pub(super) fn colour(a: &Attr, text: &str) -> Result<(), FileError> {
    let t = text.trim();
    let hex = t.strip_prefix('#').is_some_and(|h| {
        (h.len() == 3 || h.len() == 6) && h.chars().all(|c| c.is_ascii_hexdigit())
    });
    if hex || COLOURS.contains(&t) {
        Ok(())
    } else {
        Err(a.error(format!(
            "`{t}` is not a colour: #rgb, #rrggbb or one of {}",
            COLOURS.join(", ")
        )))
    }
}

/// Refuses any element inside `el`.
pub(super) fn no_children(el: &Element) -> Result<(), FileError> {
    el.only_children(&[])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_values_are_typed() {
        let m =
            field_list("a=1, b=1.5, c=-2, d=true, e=false, f=survey, g=\"x, y\", h=1e3").unwrap();
        let want = [
            ("a", Value::Int(1)),
            ("b", Value::Float(1.5)),
            ("c", Value::Int(-2)),
            ("d", Value::Bool(true)),
            ("e", Value::Bool(false)),
            ("f", Value::from("survey")),
            ("g", Value::from("x, y")),
            ("h", Value::Float(1000.0)),
        ];
        for (k, v) in want {
            assert_eq!(m.get(k), Some(&v), "{k}");
        }
        assert_eq!(field_value("nan"), Value::from("nan"));
        assert_eq!(field_value("1e999"), Value::from("1e999"));
    }
}
