//! Fuzzes the compact binary datamap decoder: any input decodes or is refused without a panic, and
//! every map it accepts encodes back to bytes that decode to the same map.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_medium::binary;

fuzz_target!(|data: &[u8]| {
    if let Ok(map) = binary::decode(data) {
        let bytes = binary::encode(&map);
        let back = binary::decode(&bytes).expect("an encoded datamap decodes");
        assert_eq!(back, map, "binary round trip changed the map");
    }
});
