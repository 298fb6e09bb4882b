//! Fuzzes the `mavlink` driver's reading of MAVLink messages: any frames become datasets with
//! finite numbers and their required fields, or none, unknown values never published, a stick's
//! values never changed.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/mavlink_driver.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::mavlink_datasets(data);
});
