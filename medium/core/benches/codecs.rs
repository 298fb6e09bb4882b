//! Encode + decode of a ten-field datamap in the binary form, the XML form, and (for reference)
//! JSON through serde_json. Prints nanoseconds per round trip and the XML/JSON ratio.
//!
//! Run: `cargo bench -p seabus-medium --bench codecs`

mod common;

use seabus_medium::{binary, json, xmlform};
use std::hint::black_box;
use std::time::Instant;

fn time_per_op(iters: u32, mut f: impl FnMut()) -> f64 {
    // best of five runs, in nanoseconds per operation
    (0..5)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..iters {
                f();
            }
            start.elapsed().as_secs_f64() * 1e9 / f64::from(iters)
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let map = common::ten_fields();
    let iters = seabus_bench::scale(200_000, 20_000);
    let bin_bytes = binary::encode(&map).expect("a ten-field map has a binary form");
    let xml_text = xmlform::to_xml(&map).expect("an XML form");
    let json_text = json::to_json(&map).expect("a JSON form");

    let bin = time_per_op(iters, || {
        let b = binary::encode(black_box(&map)).expect("binary form");
        black_box(binary::decode(&b).expect("decodes"));
    });
    let xml = time_per_op(iters, || {
        let x = xmlform::to_xml(black_box(&map)).expect("an XML form");
        black_box(xmlform::from_xml(&x).expect("decodes"));
    });
    let json = time_per_op(iters, || {
        let j = json::to_json(black_box(&map)).expect("a JSON form");
        black_box(json::from_json(&j).expect("decodes"));
    });
    let xml_enc = time_per_op(iters, || {
        black_box(xmlform::to_xml(black_box(&map)).expect("an XML form"));
    });
    let json_enc = time_per_op(iters, || {
        black_box(json::to_json(black_box(&map)).expect("a JSON form"));
    });
    println!("  (encode only: xml {xml_enc:.0} ns, json {json_enc:.0} ns)");
    println!("datamap codecs, 10 fields, encode + decode (best of 5 x {iters}):");
    println!("  binary  {bin:8.0} ns   {:4} bytes", bin_bytes.len());
    println!("  xml     {xml:8.0} ns   {:4} bytes", xml_text.len());
    println!(
        "  json    {json:8.0} ns   {:4} bytes   (serde_json, reference)",
        json_text.len()
    );
    let mut goals = seabus_bench::Goals::new();
    goals.at_most("xml / json round trip", xml / json, 3.0);
    goals.finish();
}
