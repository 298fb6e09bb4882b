//! Fuzzes the readers of the files users write: the positioned XML tree and system files. Any text
//! is read or refused with a placed error, never a panic.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/modules.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::system_file(data);
});
