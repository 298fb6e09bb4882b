//! Properties of system files that every input must keep. Each function panics when an input
//! breaks a property and tells whether the input was a valid one.

use seabus_medium::xml;
use seabus_modules::system::SystemSpec;

/// The readers of the files users write: the positioned XML tree and system files. Any text is read
/// or refused with a placed error, never a panic. True when `data` is UTF-8 text that reads as a
/// system.
pub fn system_file(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let _ = xml::parse("fuzz.xml", text);
    SystemSpec::parse("fuzz.xml", text).is_ok()
}
