//! Fuzzes the JSON form of a datamap: any text reads or is refused without a panic, and every map it
//! reads writes back to JSON that reads as the same map.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_medium::json;
use seabus_medium::{DataMap, Value};

/// True when `v` is a NaN float or a list holding one at any depth.
fn has_nan(v: &Value) -> bool {
    match v {
        Value::Float(f) => f.is_nan(),
        Value::List(items) => items.iter().any(has_nan),
        _ => false,
    }
}

/// True when any value of `map` holds a NaN: JSON writes every NaN as `{"float": "NaN"}`, so the
/// bits of a NaN do not survive a round trip.
fn map_has_nan(map: &DataMap) -> bool {
    map.iter().any(|(_, v)| has_nan(v))
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(map) = json::from_json(text) {
        let written = json::to_json(&map);
        let back = json::from_json(&written).expect("written JSON reads back");
        if !map_has_nan(&map) {
            assert_eq!(back, map, "JSON round trip changed the map: {written}");
        }
    }
});
