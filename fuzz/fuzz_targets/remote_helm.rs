//! Fuzzes the Iver Remote Helm protocol: any text is read as a frontseat sentence and as a backseat
//! command (in feet and in metres) without a panic, and every sentence read is written back to a
//! sentence that reads as the same kind of sentence. Text that is not a whole sentence with a
//! correct checksum is also read as the body of one.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
#[path = "../properties/drivers.rs"]
mod properties;

fuzz_target!(|data: &[u8]| {
    properties::remote_helm(data);
});
