//! Fuzzes the console-layout reader: any text is read or refused with a placed error, never a
//! panic, and a layout that reads keeps its ids in its JSON form.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/ui.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::layout(data);
});
