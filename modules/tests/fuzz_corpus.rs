//! Replays the system-file seeds of the fuzz corpus (`fuzz/corpus/system_file/`) through the same
//! readers as the fuzz target, so that every seed runs with the ordinary tests, without libFuzzer.

use seabus_medium::xml;
use seabus_modules::system::SystemSpec;
use std::path::Path;

/// Every system-file seed is read or refused without a panic, and at least one is a valid system.
#[test]
fn system_file_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus/system_file");
    let entries =
        std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()));
    let mut paths: Vec<_> = entries
        .map(|e| e.expect("a readable directory entry").path())
        .filter(|p| p.is_file())
        .filter(|p| {
            !p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'))
        })
        .collect();
    paths.sort();
    assert!(!paths.is_empty(), "no seed files in {}", dir.display());
    let mut accepted = 0;
    for path in &paths {
        let data =
            std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let Ok(text) = std::str::from_utf8(&data) else {
            continue;
        };
        let _ = xml::parse("fuzz.xml", text);
        if SystemSpec::parse("fuzz.xml", text).is_ok() {
            accepted += 1;
        }
    }
    assert!(accepted > 0, "no system-file seed is a valid system");
}
