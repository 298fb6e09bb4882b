//! Fuzzes the XML form of a datamap: any text reads or is refused without a panic, and every map it
//! reads writes back to XML that reads as the same map.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_medium::xmlform;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(map) = xmlform::from_xml(text) {
        let xml = xmlform::to_xml(&map);
        let back = xmlform::from_xml(&xml).expect("written XML reads back");
        assert_eq!(back, map, "XML round trip changed the map: {xml}");
    }
});
