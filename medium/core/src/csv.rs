//! CSV cells for the files seabus writes (the logger's tables, `seabus export`, the console's
//! command log): one writer, so that every table reads the same.

use crate::datamap::{DataMap, Value};
use crate::json;

/// A CSV cell: plain when it can be, quoted when it holds a comma, quote or line break; bytes in
/// hex, lists and maps as JSON.
pub fn cell(v: &Value) -> String {
    let text = match v {
        Value::Str(s) => s.to_string(),
        Value::Int(n) => n.to_string(),
        Value::Float(f) => format!("{f}"),
        Value::Bool(b) => b.to_string(),
        Value::Bytes(b) => b.iter().map(|x| format!("{x:02x}")).collect(),
        Value::List(_) | Value::Map(_) => json::to_json(&DataMap::new().with("v", v.clone()))
            .map(|j| {
                j.trim_start_matches("{\"v\":")
                    .trim_end_matches('}')
                    .to_string()
            })
            .unwrap_or_default(),
    };
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_quoted_only_when_they_must_be() {
        assert_eq!(cell(&Value::from("plain")), "plain");
        assert_eq!(cell(&Value::from("a,b")), "\"a,b\"");
        assert_eq!(cell(&Value::from("say \"hi\"")), "\"say \"\"hi\"\"\"");
        assert_eq!(cell(&Value::Int(-3)), "-3");
        assert_eq!(cell(&Value::Bytes(vec![0xab, 1])), "ab01");
        assert_eq!(
            cell(&Value::List(vec![Value::Int(1), Value::Int(2)])),
            "\"[1,2]\""
        );
    }
}
