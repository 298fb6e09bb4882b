//! Fuzzes the readers of the files users write: the positioned XML tree and system files. Any text
//! is read or refused with a placed error, never a panic.

#![no_main]

use libfuzzer_sys::fuzz_target;
use seabus_medium::xml;
use seabus_modules::system::SystemSpec;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = xml::parse("fuzz.xml", text);
    let _ = SystemSpec::parse("fuzz.xml", text);
});
