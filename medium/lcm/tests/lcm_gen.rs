//! Checks the `.lcm` reader against the real lcm-gen: for the same files, every struct gets the
//! base hash lcm-gen prints (`lcm-gen -d`) and the fingerprint its generated Python code computes
//! (`lcm-gen -p`), and files lcm-gen refuses are refused. Every lcm-gen found is checked: the one on
//! PATH, Debian's `/usr/bin/lcm-gen` and the one of the Python package `lcm`.

#[path = "support/lcm_gen.rs"]
mod support;

use seabus_medium_lcm::types::{ResolvedTypes, TypeSet};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use support::{Generator, generators};

/// Files for every lcm-gen, in the order given to it (lcm-gen carries a `package` line on into the
/// files after it, so the file without one comes first).
const FILES: &[(&str, &str)] = &[
    (
        "plain.lcm",
        "// structs outside any package\n\
         struct temperature_t { int64_t utime; double deg_celsius; }\n\
         struct flags_t {\n\
             boolean ok, valid[3];\n\
             byte raw[4];\n\
             int32_t len; byte blob[len];\n\
             int8_t tiny; int16_t small; float f; string s;\n\
             const int32_t A = 1, B = -2;\n\
             const int64_t BIG = 0x7fffffffffffffff;\n\
             const double D = 2.5e-3;\n\
             const float F = 1.5;\n\
         }\n\
         struct empty_t { }\n",
    ),
    (
        "geo.lcm",
        "package geo;\n\
         /* points,\n * and polygons */\n\
         struct point_t { double x, y, z; }\n\
         struct polygon_t { int32_t n; point_t corners[n]; string label; }\n",
    ),
    (
        "nav.lcm",
        "package nav.msgs;\n\
         struct pose_t {\n\
             int64_t utime;\n\
             geo.point_t position;           // a struct of another package\n\
             double orientation[4];\n\
             int16_t rows; int8_t cols;\n\
             float covariance[rows][cols];  // variable, two dimensions\n\
             double grid[2][3];              // fixed, two dimensions\n\
             int32_t n;\n\
             geo.point_t track[n][3], last;  // variable then fixed; two members\n\
             string names[n];\n\
             boolean valid[2];\n\
             int32_t a,b [ 2 ] ,c /* odd spacing */;\n\
         }\n\
         struct path_t { int64_t count; pose_t poses[count]; pose_t first, final; geo.polygon_t area; }\n",
    ),
    (
        "tree.lcm",
        "package tree;\n\
         struct node_t { int32_t num_children; node_t children[num_children]; string name; }\n\
         struct forest_t { int32_t n; node_t trees[n]; node_t root; node_t spare; }\n\
         struct even_t { int32_t n; odd_t next[n]; double v; }\n\
         struct odd_t { int16_t n; even_t next[n]; tree.even_t back[n]; }\n",
    ),
];

/// A file with a member name longer than 127 bytes, whose length lcm-gen hashes as a negative
/// character.
fn long_name_file() -> (String, String) {
    let name = format!("m{}", "_long".repeat(40));
    (
        "long.lcm".into(),
        format!("package longs;\nstruct long_t {{ int32_t {name}; double {name}2[2]; }}\n"),
    )
}

/// A file with arrays sized by constants (lcm-gen 1.4 and later).
const CONST_SIZED: (&str, &str) = (
    "sized.lcm",
    "package sized;\n\
     struct grid_t {\n\
         const int32_t ROWS = 0x10, COLS = 3;\n\
         const int8_t DEPTH = 2;\n\
         int32_t n;\n\
         double cells[ROWS][COLS];\n\
         int8_t layers[DEPTH][n];\n\
     }\n",
);

/// Files lcm-gen refuses, and so must seabus.
const REFUSED: &[&str] = &[
    "struct a{ int32_t x; }",
    "struct a { int32_t x; };",
    "struct a { const byte X = 1; }",
    "struct a { const int8_t X = 128; }",
    "struct a { const float X = 1e39; }",
    "struct a { const double X = 1e+3; }",
    "struct a { const int32_t X = 1.5; }",
    "struct a { int32_t x[n]; int32_t n; }",
    "struct a { double n; int32_t x[n]; }",
    "struct a { byte n; int32_t x[n]; }",
    "struct a { int32_t n[2]; int32_t x[n]; }",
    "struct a { int32_t x[0]; }",
    "struct a { int32_t x[]; }",
    "struct a { int32_t x; int8_t x; }",
    "struct a { int32_t x; }\nstruct a { int32_t y; }",
    "struct a { int32_t x }",
    "struct a { struct b { int32_t x; } }",
    "package p struct a { }",
    "struct a { int32_t c/* a comment needs white space before it */; }",
];

/// The files for `generator`, in order.
fn files_for(generator: &Generator) -> Vec<(String, String)> {
    let mut files: Vec<(String, String)> = FILES
        .iter()
        .map(|(n, t)| (n.to_string(), t.to_string()))
        .collect();
    files.push(long_name_file());
    if generator.version >= (1, 4, 0) {
        files.push((CONST_SIZED.0.into(), CONST_SIZED.1.into()));
    }
    files
}

/// A hash, shown in hexadecimal.
#[derive(PartialEq, Eq)]
struct Hex(u64);

impl std::fmt::Debug for Hex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:016x}", self.0)
    }
}

/// The base hash lcm-gen prints for each struct (`struct NAME [hash=0x…]`).
fn lcm_gen_base_hashes(generator: &Generator, dir: &Path, files: &[&str]) -> BTreeMap<String, Hex> {
    let mut args = vec!["-d"];
    args.extend(files);
    let out = generator.run(dir, &args);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{} -d failed:\n{text}",
        generator.name()
    );
    let mut hashes = BTreeMap::new();
    for line in text.lines() {
        let Some(rest) = line.strip_prefix("struct ") else {
            continue;
        };
        let (name, hash) = rest
            .split_once(" [hash=0x")
            .expect("a hash on a struct line");
        let hash = hash.trim_end_matches(']').trim();
        // before 1.5.1, lcm-gen prints the hash in signed decimal after its `0x`
        let parsed = if generator.version >= (1, 5, 1) {
            u64::from_str_radix(hash, 16).ok()
        } else {
            hash.parse::<i64>().ok().map(|h| h as u64)
        };
        let hash = parsed.unwrap_or_else(|| panic!("{line:?}: no hash"));
        hashes.insert(name.to_string(), Hex(hash));
    }
    hashes
}

/// The fingerprint that the Python code lcm-gen generates computes for each struct of `names`.
fn lcm_gen_fingerprints(
    generator: &Generator,
    dir: &Path,
    files: &[&str],
    names: &[String],
) -> BTreeMap<String, Hex> {
    let mut args = vec!["-p", "--ppath", "py"];
    args.extend(files);
    let out = generator.run(dir, &args);
    assert!(
        out.status.success(),
        "{} -p failed:\n{}",
        generator.name(),
        String::from_utf8_lossy(&out.stdout)
    );
    let script = "import importlib, sys\n\
                  sys.path.insert(0, 'py')\n\
                  for name in sys.argv[1:]:\n\
                  \x20   module = importlib.import_module(name)\n\
                  \x20   cls = getattr(module, name.rpartition('.')[2])\n\
                  \x20   print(name, '%016x' % cls._get_hash_recursive([]))\n";
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(names)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("cannot run python3 for the generated code: {e}"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the generated Python code fails:\n{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text.lines()
        .map(|line| {
            let (name, fp) = line.split_once(' ').expect("a name and a fingerprint");
            let fp = u64::from_str_radix(fp, 16).expect("a hexadecimal fingerprint");
            (name.to_string(), Hex(fp))
        })
        .collect()
}

/// seabus's reading of `files`.
fn seabus(dir: &Path, files: &[&str]) -> ResolvedTypes {
    let mut set = TypeSet::new();
    for file in files {
        set.add_path(&dir.join(file))
            .unwrap_or_else(|e| panic!("seabus refuses {file}: {e}"));
    }
    set.resolve()
        .unwrap_or_else(|e| panic!("seabus cannot resolve: {e}"))
}

#[test]
fn hashes_and_fingerprints_match_lcm_gen() {
    for generator in generators(true) {
        eprintln!("checking against {}", generator.name());
        let dir = tempfile::tempdir().expect("a temporary directory");
        let files = files_for(&generator);
        for (name, text) in &files {
            std::fs::write(dir.path().join(name), text).expect("a written .lcm file");
        }
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        let types = seabus(dir.path(), &names);
        let ours_base: BTreeMap<String, Hex> = types
            .iter()
            .map(|s| (s.full_name().to_string(), Hex(s.base_hash())))
            .collect();
        let ours_fp: BTreeMap<String, Hex> = types
            .iter()
            .map(|s| (s.full_name().to_string(), Hex(s.fingerprint())))
            .collect();
        let struct_names: Vec<String> = ours_fp.keys().cloned().collect();
        assert!(struct_names.len() >= 12, "{struct_names:?}");

        let base = lcm_gen_base_hashes(&generator, dir.path(), &names);
        assert_eq!(ours_base, base, "base hashes, {}", generator.name());
        let fp = lcm_gen_fingerprints(&generator, dir.path(), &names, &struct_names);
        assert_eq!(ours_fp, fp, "fingerprints, {}", generator.name());
        for s in types.iter() {
            let found = types
                .by_fingerprint(s.fingerprint())
                .map(|t| t.fingerprint());
            assert_eq!(found, Some(s.fingerprint()), "{}", s.full_name());
        }
    }
}

#[test]
fn files_lcm_gen_refuses_are_refused() {
    for generator in generators(true) {
        let dir = tempfile::tempdir().expect("a temporary directory");
        for (i, text) in REFUSED.iter().enumerate() {
            let name = format!("bad{i}.lcm");
            std::fs::write(dir.path().join(&name), text).expect("a written .lcm file");
            let out = generator.run(dir.path(), &["-d", &name]);
            assert!(
                !out.status.success(),
                "{} accepts {text:?}; the list of refused files is wrong",
                generator.name()
            );
            let mut set = TypeSet::new();
            let read = set
                .add_text(&name, text)
                .and_then(|()| set.resolve().map(|_| ()));
            let e = read
                .err()
                .unwrap_or_else(|| panic!("seabus accepts {text:?}"));
            assert!(
                e.to_string().starts_with(&format!("{name}:1:")) || e.pos.line == 2,
                "{e}"
            );
        }
    }
}
