//! Runs the seed corpus of a fuzz target (`fuzz/corpus/<target>/`) through its property check with
//! the ordinary tests, without libFuzzer.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

/// The seed files of fuzz target `target`, sorted by name; fails when there are none.
pub fn seeds(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    // the crate is somewhere below the repository's root, which holds fuzz/corpus
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|a| a.join("fuzz/corpus"))
        .find(|c| c.is_dir())
        .unwrap_or_else(|| panic!("no fuzz/corpus above {}", env!("CARGO_MANIFEST_DIR")))
        .join(target);
    let entries =
        std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()));
    let mut out = Vec::new();
    for entry in entries {
        let path = entry.expect("a readable directory entry").path();
        let hidden = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if path.is_file() && !hidden {
            let data = std::fs::read(&path)
                .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
            out.push((path, data));
        }
    }
    out.sort();
    assert!(!out.is_empty(), "no seed files in {}", dir.display());
    out
}

/// Runs `check` on every seed of `target`, failing with the seed's path when a check panics, and
/// fails unless at least one seed was accepted.
pub fn replay(target: &str, check: impl Fn(&[u8]) -> bool) {
    let mut accepted = 0;
    for (path, data) in seeds(target) {
        match catch_unwind(AssertUnwindSafe(|| check(&data))) {
            Ok(true) => accepted += 1,
            Ok(false) => {}
            Err(payload) => {
                let message = payload
                    .downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| payload.downcast_ref::<&str>().copied())
                    .unwrap_or("a panic without a message");
                panic!("seed {} breaks a property: {message}", path.display());
            }
        }
    }
    assert!(accepted > 0, "no seed of {target} is a valid input");
}

/// One test per fuzz target: `test => target` defines test `test`, which replays the seeds of
/// `target` through `properties::target`; the including test crate declares the `properties` and
/// `replay` modules at its root. Attributes and doc comments before an entry go to its test.
macro_rules! seed_tests {
    ($($(#[$attr:meta])* $test:ident => $target:ident,)*) => {
        $(
            $(#[$attr])*
            #[test]
            fn $test() {
                $crate::replay::replay(stringify!($target), $crate::properties::$target);
            }
        )*
    };
}
