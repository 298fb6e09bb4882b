//! Checks the LCM codec against the Python code the real lcm-gen generates (`lcm-gen -p`): Python
//! decodes what seabus encodes from datamaps, and seabus decodes what Python encodes, each side's
//! reading compared through a JSON view of the message. Every lcm-gen found is checked: the one on
//! PATH and Debian's `/usr/bin/lcm-gen`.

#[path = "support/lcm_gen.rs"]
mod support;

use seabus_medium::{DataMap, Value};
use seabus_medium_lcm::codec::{decode, encode};
use seabus_medium_lcm::types::{ResolvedTypes, TypeSet};
use serde_json::json;
use std::process::Command;
use support::generators;

/// Structs of another package, used by the ones below.
const GEO: &str = "package geo;\n\
    struct point_t { double x, y; float z; }\n";

/// A struct with every primitive type, arrays of every kind, nested structs and a recursive type.
const INTEROP: &str = "package interop;\n\
    struct node_t { int32_t num_children; node_t children[num_children]; string name; }\n\
    struct all_t {\n\
        int8_t i8; int16_t i16; int32_t i32; int64_t i64;\n\
        byte b; boolean flag; float f; double d; string s;\n\
        int8_t i8s[2]; int16_t i16s[2]; int32_t i32s[2]; int64_t i64s[2];\n\
        float fs[4]; double ds[4]; boolean flags[2];\n\
        byte raw[4];\n\
        int32_t n; byte blob[n];\n\
        int16_t rows; int8_t cols;\n\
        double grid[rows][cols];\n\
        int32_t fixed2[2][3];\n\
        geo.point_t position;\n\
        geo.point_t track[n][2];\n\
        string names[rows];\n\
        byte planes[2][cols];\n\
        node_t tree;\n\
    }\n";

/// Python's side: `decode TYPE HEX` prints the JSON view of a message; `build` prints messages
/// built in Python, one a line: type, hex, JSON view. The view: floats by their bits, byte strings
/// of a member as `{"b": hex}` (inside a list, as a list of ints, as seabus maps byte matrices),
/// structs as `{"m": [[name, value], ...]}` in member order.
const PYTHON: &str = r#"
import importlib, json, struct, sys
sys.path.insert(0, 'py')

def view(v, member=True):
    if isinstance(v, bool):
        return v
    if isinstance(v, int):
        return v
    if isinstance(v, float):
        return {"f": struct.pack('>d', v).hex()}
    if isinstance(v, str):
        return v
    if isinstance(v, (bytes, bytearray)):
        return {"b": bytes(v).hex()} if member else list(bytes(v))
    if hasattr(v, '__slots__'):
        return {"m": [[k, view(getattr(v, k))] for k in v.__slots__]}
    return [view(x, False) for x in v]

def cls(name):
    package, _, short = name.rpartition('.')
    return getattr(importlib.import_module(package + '.' + short), short)

def point(x, y, z):
    p = cls('geo.point_t')()
    p.x, p.y, p.z = x, y, z
    return p

def node(name, children):
    n = cls('interop.node_t')()
    n.num_children = len(children)
    n.children = children
    n.name = name
    return n

def full():
    m = cls('interop.all_t')()
    m.i8, m.i16, m.i32, m.i64 = -128, 32767, -2147483648, 9223372036854775807
    m.b, m.flag, m.f, m.d, m.s = 200, True, -2.5, 1e-300, 'grüße, ✓'
    m.i8s, m.i16s = [127, -1], [-32768, 0]
    m.i32s, m.i64s = [2147483647, 5], [-9223372036854775808, -2]
    m.fs = [0.25, float('-inf'), -0.0, 3.4028234663852886e38]
    m.ds = [float('nan'), 5e-324, -1.7976931348623157e308, float('inf')]
    m.flags = [False, True]
    m.raw = b'\x00\x7f\x80\xff'
    m.n, m.blob = 2, b'\x01\x00'
    m.rows, m.cols = 3, 2
    m.grid = [[1.0, 2.0], [3.0, 4.0], [5.5, -6.0]]
    m.fixed2 = [[1, 2, 3], [-4, -5, -6]]
    m.position = point(1.0, 2.0, 3.0)
    m.track = [[point(1.5, 0.0, 0.0), point(0.0, 2.5, 0.0)],
               [point(0.0, 0.0, -1.0), point(9.0, 8.0, 7.0)]]
    m.names = ['', 'a', 'ünï']
    m.planes = [b'\x01\x02', b'\xfe\xff']
    m.tree = node('root', [node('a', []), node('b', [node('c', [])])])
    return m

def empty():
    m = full()
    m.n, m.blob, m.track = 0, b'', []
    m.rows, m.cols, m.grid, m.names = 0, 0, [], []
    m.planes = [b'', b'']
    m.tree = node('', [])
    return m

if sys.argv[1] == 'decode':
    print(json.dumps(view(cls(sys.argv[2]).decode(bytes.fromhex(sys.argv[3])))))
else:
    for name, msg in [('interop.all_t', full()), ('interop.all_t', empty()),
                      ('interop.node_t', full().tree), ('geo.point_t', point(-1.0, 0.5, 0.125))]:
        print(name, msg.encode().hex(), json.dumps(view(msg)))
"#;

/// An lcm-gen and the directory with its generated Python code, the `.lcm` files and the script.
struct Setup {
    name: String,
    dir: tempfile::TempDir,
    types: ResolvedTypes,
}

/// Every lcm-gen found, one per version, each with its Python code generated; fails, saying how
/// to install them, when there is none or Python is missing.
fn setups() -> Vec<Setup> {
    let python = Command::new("python3").arg("--version").output();
    assert!(
        python.is_ok_and(|o| o.status.success()),
        "python3 is not installed: run ./scripts/test"
    );
    let mut out = Vec::new();
    for generator in generators(false) {
        let dir = tempfile::tempdir().expect("a temporary directory");
        std::fs::write(dir.path().join("geo.lcm"), GEO).expect("a written file");
        std::fs::write(dir.path().join("interop.lcm"), INTEROP).expect("a written file");
        std::fs::write(dir.path().join("view.py"), PYTHON).expect("a written file");
        let gen_out = generator.run(
            dir.path(),
            &["-p", "--ppath", "py", "geo.lcm", "interop.lcm"],
        );
        assert!(
            gen_out.status.success(),
            "{} -p failed:\n{}{}",
            generator.name(),
            String::from_utf8_lossy(&gen_out.stdout),
            String::from_utf8_lossy(&gen_out.stderr)
        );
        let mut set = TypeSet::new();
        set.add_text("geo.lcm", GEO)
            .and_then(|()| set.add_text("interop.lcm", INTEROP))
            .unwrap_or_else(|e| panic!("{e}"));
        let types = set.resolve().unwrap_or_else(|e| panic!("{e}"));
        out.push(Setup {
            name: generator.name(),
            dir,
            types,
        });
    }
    out
}

impl Setup {
    /// Runs the Python script with `args`; its standard output.
    fn python(&self, args: &[&str]) -> String {
        let out = Command::new("python3")
            .arg("view.py")
            .args(args)
            .current_dir(self.dir.path())
            .output()
            .unwrap_or_else(|e| panic!("cannot run python3: {e}"));
        assert!(
            out.status.success(),
            "Python code of {} fails:\n{}",
            self.name,
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }
}

/// The JSON view of a value, as the Python script writes it.
fn view(v: &Value) -> serde_json::Value {
    match v {
        Value::Bool(b) => json!(b),
        Value::Int(i) => json!(i),
        Value::Float(x) => json!({ "f": format!("{:016x}", x.to_bits()) }),
        Value::Str(s) => json!(s),
        Value::Bytes(b) => {
            let hex: String = b.iter().map(|byte| format!("{byte:02x}")).collect();
            json!({ "b": hex })
        }
        Value::List(items) => serde_json::Value::Array(items.iter().map(view).collect()),
        Value::Map(map) => view_map(map),
    }
}

/// The JSON view of a struct.
fn view_map(map: &DataMap) -> serde_json::Value {
    let members: Vec<serde_json::Value> = map.iter().map(|(k, v)| json!([k, view(v)])).collect();
    json!({ "m": members })
}

/// Bytes from hexadecimal text.
fn unhex(text: &str) -> Vec<u8> {
    assert!(text.len().is_multiple_of(2), "odd hex {text:?}");
    (0..text.len() / 2)
        .map(|i| {
            text.get(2 * i..2 * i + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .unwrap_or_else(|| panic!("bad hex {text:?}"))
        })
        .collect()
}

/// A list value.
fn list<V: Into<Value>>(items: impl IntoIterator<Item = V>) -> Value {
    Value::List(items.into_iter().map(Into::into).collect())
}

/// A `geo.point_t`.
fn point(x: f64, y: f64, z: f32) -> Value {
    Value::Map(
        DataMap::new()
            .and("x", x)
            .and("y", y)
            .and("z", f64::from(z)),
    )
}

/// An `interop.node_t`.
fn node(name: &str, children: Vec<Value>) -> Value {
    Value::Map(
        DataMap::new()
            .and("num_children", children.len() as i64)
            .and("children", children)
            .and("name", name),
    )
}

/// An `interop.all_t` with every member set, as seabus reads it back.
fn full() -> DataMap {
    DataMap::new()
        .and("i8", 127i64)
        .and("i16", -32768i64)
        .and("i32", i64::from(i32::MAX))
        .and("i64", i64::MIN)
        .and("b", 255i64)
        .and("flag", true)
        .and("f", f64::from(0.1f32))
        .and("d", 0.1f64)
        .and("s", "héllo ✓ wörld")
        .and("i8s", list([-128i64, 127]))
        .and("i16s", list([-32768i64, 32767]))
        .and("i32s", list([i64::from(i32::MIN), i64::from(i32::MAX)]))
        .and("i64s", list([i64::MIN, i64::MAX]))
        .and("fs", list([1.5, -0.0, f64::INFINITY, f64::from(f32::MAX)]))
        .and(
            "ds",
            list([f64::MIN_POSITIVE, -1e300, f64::NEG_INFINITY, f64::NAN]),
        )
        .and("flags", list([true, false]))
        .and("raw", vec![0u8, 1, 0xfe, 0xff])
        .and("n", 2i64)
        .and("blob", vec![0x10u8, 0x20])
        .and("rows", 3i64)
        .and("cols", 2i64)
        .and(
            "grid",
            list([list([1.0, 2.0]), list([3.0, 4.0]), list([5.0, 6.5])]),
        )
        .and("fixed2", list([list([1i64, 2, 3]), list([4i64, 5, -6])]))
        .and("position", point(1.0, -2.0, 0.5))
        .and(
            "track",
            list([
                list([point(1.0, 2.0, 3.0), point(4.0, 5.0, 6.0)]),
                list([point(-1.0, -2.0, -3.0), point(0.0, 0.0, 0.25)]),
            ]),
        )
        .and("names", list(["a", "", "ünï"]))
        .and("planes", list([list([1i64, 2]), list([3i64, 4])]))
        .and(
            "tree",
            node(
                "root",
                vec![node("a", vec![]), node("b", vec![node("c", vec![])])],
            ),
        )
}

/// A few members of an `interop.all_t`, and a key it does not have.
fn sparse() -> DataMap {
    DataMap::new()
        .and("unknown", "ignored")
        .and("s", "x")
        .and("i32", 7.0)
        .and("flags", list([1i64, 0]))
        .and("position", DataMap::new().and("y", 2i64))
        .and("tree", DataMap::new().and("name", "root"))
}

/// What seabus writes for [`sparse`]: every other member at its default.
fn sparse_filled() -> DataMap {
    let nan = f64::NAN;
    let nan32 = f64::from(f32::NAN);
    DataMap::new()
        .and("i8", 0i64)
        .and("i16", 0i64)
        .and("i32", 7i64)
        .and("i64", 0i64)
        .and("b", 0i64)
        .and("flag", false)
        .and("f", nan32)
        .and("d", nan)
        .and("s", "x")
        .and("i8s", list([0i64, 0]))
        .and("i16s", list([0i64, 0]))
        .and("i32s", list([0i64, 0]))
        .and("i64s", list([0i64, 0]))
        .and("fs", list([nan32; 4]))
        .and("ds", list([nan; 4]))
        .and("flags", list([true, false]))
        .and("raw", vec![0u8; 4])
        .and("n", 0i64)
        .and("blob", Vec::<u8>::new())
        .and("rows", 0i64)
        .and("cols", 0i64)
        .and("grid", list(Vec::<Value>::new()))
        .and("fixed2", list([list([0i64; 3]), list([0i64; 3])]))
        .and(
            "position",
            DataMap::new().and("x", nan).and("y", 2.0).and("z", nan32),
        )
        .and("track", list(Vec::<Value>::new()))
        .and("names", list(Vec::<Value>::new()))
        .and(
            "planes",
            list([list(Vec::<Value>::new()), list(Vec::<Value>::new())]),
        )
        .and("tree", node("root", vec![]))
}

#[test]
fn python_reads_what_seabus_writes() {
    for setup in setups() {
        eprintln!("checking against {}", setup.name);
        let cases = [
            ("interop.all_t", full(), full()),
            ("interop.all_t", sparse(), sparse_filled()),
            (
                "interop.node_t",
                match node("r", vec![node("s", vec![node("t", vec![])])]) {
                    Value::Map(map) => map,
                    _ => unreachable!("a node is a map"),
                },
                DataMap::new(),
            ),
        ];
        for (name, map, expected) in cases {
            let expected = if expected.is_empty() {
                map.clone()
            } else {
                expected
            };
            let ty = setup.types.get(name).unwrap_or_else(|| panic!("no {name}"));
            let bytes = encode(&setup.types, ty, &map).unwrap_or_else(|e| panic!("{e}"));
            let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            let text = setup.python(&["decode", name, &hex]);
            let python: serde_json::Value = serde_json::from_str(text.trim())
                .unwrap_or_else(|e| panic!("Python prints {text:?}: {e}"));
            assert_eq!(
                python,
                view_map(&expected),
                "{name} as {}: Python read, then what seabus expected",
                setup.name
            );
            let (back, _) = decode(&setup.types, ty, &bytes).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(back, expected, "{name}: seabus reads back");
        }
    }
}

#[test]
fn seabus_reads_what_python_writes() {
    for setup in setups() {
        eprintln!("checking against {}", setup.name);
        let text = setup.python(&["build"]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        for line in lines {
            let mut parts = line.splitn(3, ' ');
            let (Some(name), Some(hex), Some(python)) = (parts.next(), parts.next(), parts.next())
            else {
                panic!("a line of Python output: {line:?}");
            };
            let python: serde_json::Value =
                serde_json::from_str(python).unwrap_or_else(|e| panic!("{python:?}: {e}"));
            let ty = setup.types.get(name).unwrap_or_else(|| panic!("no {name}"));
            let bytes = unhex(hex);
            let (map, _) = decode(&setup.types, ty, &bytes)
                .unwrap_or_else(|e| panic!("{name} from {}: {e}", setup.name));
            assert_eq!(view_map(&map), python, "{name} from {}", setup.name);
            let again = encode(&setup.types, ty, &map).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(again, bytes, "{name}: seabus writes the same bytes");
        }
    }
}
