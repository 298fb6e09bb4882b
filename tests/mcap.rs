//! MCAP recordings against the official readers and writers of other languages: what `seabus
//! record` writes is read by Python's `mcap` (its seeking reader, through the summary and indexes)
//! and by `@mcap/core` in Node (its indexed reader, as Foxglove reads files), with a channel and
//! JSON Schema per topic and the values sent; a recording cut short mid-chunk reads up to the
//! damage in Python and in `seabus replay`, which says where; an MCAP file Python writes with JSON
//! messages is replayed onto a medium; corrupt files are refused with their byte offset.
//!
//! Needs Python's `mcap` and Node with `@mcap/core` and `fzstd`, which `scripts/test` installs
//! (the Node packages under `target/node-mcap`, named in `SEABUS_MCAP_NODE`).

mod common;
use common::*;
use serde_json::Value as Json;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::Duration;

/// A loopback multicast medium of the test's own.
fn udp_url() -> String {
    format!("udp://{}:{}?ttl=0&iface=127.0.0.1", group(), free_port())
}

fn require_python_mcap() {
    let ok = Command::new("python3")
        .args(["-c", "import mcap, zstandard"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        ok,
        "the python3 package `mcap` is missing: run ./scripts/test, which installs it"
    );
}

/// Where `@mcap/core` and `fzstd` are: `SEABUS_MCAP_NODE`, else where `scripts/test` puts them.
fn node_modules() -> PathBuf {
    let modules = match std::env::var_os("SEABUS_MCAP_NODE") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-mcap/node_modules"),
    };
    assert!(
        modules.join("@mcap/core/package.json").is_file() && modules.join("fzstd").is_dir(),
        "@mcap/core and fzstd are not in {}: run ./scripts/test, which installs them",
        modules.display()
    );
    modules
}

fn publish(url: &str, args: &[&str]) {
    let out = seabus().arg("pub").arg(url).args(args).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
}

/// Records on `url` while `send` runs, then stops the recorder as Ctrl-C would.
fn record(url: &str, file: &Path, send: impl FnOnce()) -> Output {
    let recorder = seabus()
        .args(["record", url])
        .arg(file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("record starts");
    std::thread::sleep(Duration::from_millis(400));
    send();
    std::thread::sleep(Duration::from_millis(300));
    interrupt(&recorder);
    let out = finish(recorder);
    assert!(out.status.success(), "record failed: {}", stderr(&out));
    out
}

/// Python's reading of an MCAP file: summary, chunk indexes, channels and the messages by topic,
/// read through the index.
const PY_READ: &str = r#"
import json, sys
from mcap.reader import make_reader
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    summary = reader.get_summary()
    out = {
        "statistics": summary.statistics.message_count,
        "chunks": [
            {"start": c.chunk_start_offset, "length": c.chunk_length,
             "compression": c.compression, "first": c.message_start_time}
            for c in summary.chunk_indexes
        ],
        "channels": {},
    }
    for c in summary.channels.values():
        s = summary.schemas.get(c.schema_id)
        out["channels"][c.topic] = {
            "encoding": c.message_encoding,
            "schema": s.name if s else "",
            "schema_encoding": s.encoding if s else "",
            "schema_data": json.loads(s.data) if s else None,
            "metadata": dict(c.metadata),
            "messages": [],
        }
    for schema, channel, message in reader.iter_messages(log_time_order=True):
        data = json.loads(message.data) if channel.message_encoding == "json" else message.data.hex()
        out["channels"][channel.topic]["messages"].append(
            {"data": data, "log_time": message.log_time, "publish_time": message.publish_time})
print(json.dumps(out))
"#;

/// The messages Python's stream reader gets from a file before it fails, and whether it failed.
const PY_STREAM: &str = r#"
import json, sys
from mcap.stream_reader import StreamReader
from mcap.records import Message
count, failed = 0, None
with open(sys.argv[1], "rb") as f:
    try:
        for record in StreamReader(f, skip_magic=False).records:
            if isinstance(record, Message):
                count += 1
    except Exception as e:
        failed = type(e).__name__
print(json.dumps({"messages": count, "failed": failed}))
"#;

#[test]
fn python_and_node_read_what_seabus_records_with_channels_schemas_and_values() {
    require_python_mcap();
    let modules = node_modules();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("session.mcap");
    let url = udp_url();
    let out = record(&url, &file, || {
        publish(
            &url,
            &[
                "nav.attitude",
                "yaw=12.5",
                "pitch=-1.25",
                "roll=3.5",
                "--count",
                "20",
                "--rate",
                "100",
            ],
        );
        publish(
            &url,
            &["cmd.course", "heading=90", "depth=2.5", "--command"],
        );
        publish(&url, &["lab.thing", "n=3", "label=probe"]);
    });
    assert!(
        stderr(&out).contains("22 events"),
        "record says what it wrote: {}",
        stderr(&out)
    );

    let py: Json = serde_json::from_str(&python(PY_READ, &[file.to_str().unwrap()], &[])).unwrap();
    assert_eq!(py["statistics"], 22, "{py}");
    let chunks = py["chunks"].as_array().unwrap();
    assert!(!chunks.is_empty(), "chunk indexes in the summary: {py}");
    assert!(chunks.iter().all(|c| c["compression"] == "zstd"), "{py}");
    let channels = py["channels"].as_object().unwrap();
    let mut topics: Vec<&str> = channels.keys().map(String::as_str).collect();
    topics.sort_unstable();
    assert_eq!(topics, ["cmd.course", "lab.thing", "nav.attitude"]);

    let att = &channels["nav.attitude"];
    assert_eq!(
        (&att["encoding"], &att["schema"], &att["schema_encoding"]),
        (
            &Json::from("json"),
            &Json::from("seabus.attitude"),
            &Json::from("jsonschema")
        )
    );
    let props = &att["schema_data"]["properties"];
    assert_eq!(props["yaw"]["type"], "number");
    assert!(
        props["yaw"]["description"]
            .as_str()
            .unwrap()
            .contains("deg"),
        "units in the schema: {props}"
    );
    let messages = att["messages"].as_array().unwrap();
    assert_eq!(messages.len(), 20);
    for m in messages {
        assert_eq!(
            (&m["data"]["yaw"], &m["data"]["pitch"], &m["data"]["roll"]),
            (&Json::from(12.5), &Json::from(-1.25), &Json::from(3.5)),
            "{m}"
        );
        // recorded after it was published, on one machine's clock
        let (log, publish) = (
            m["log_time"].as_u64().unwrap(),
            m["publish_time"].as_u64().unwrap(),
        );
        assert!(publish <= log && log - publish < 5_000_000_000, "{m}");
    }
    let course = &channels["cmd.course"];
    assert_eq!(course["metadata"]["seabus.kind"], "command");
    assert_eq!(course["messages"][0]["data"]["heading"], 90.0);
    let lab = &channels["lab.thing"];
    assert_eq!(lab["schema"], "lab.thing");
    assert_eq!(lab["schema_data"]["properties"]["n"]["type"], "integer");
    assert_eq!(lab["messages"][0]["data"]["label"], "probe");

    let node = Command::new("node")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peers/mcap_read.js"))
        .arg(&file)
        .env("NODE_PATH", &modules)
        .output()
        .expect("node runs");
    assert!(node.status.success(), "{}", stderr(&node));
    let js: Json = serde_json::from_slice(&node.stdout).unwrap();
    assert_eq!(js["messageCount"], 22, "{js}");
    assert_eq!(js["compression"], serde_json::json!(["zstd"]));
    assert_eq!(js["chunks"].as_u64().unwrap(), chunks.len() as u64);
    let c = &js["channels"];
    assert_eq!(
        (
            &c["nav.attitude"]["count"],
            &c["cmd.course"]["count"],
            &c["lab.thing"]["count"]
        ),
        (&Json::from(20), &Json::from(1), &Json::from(1))
    );
    assert_eq!(c["nav.attitude"]["schema"], "seabus.attitude");
    assert_eq!(c["nav.attitude"]["first"]["roll"], 3.5);
    assert_eq!(c["cmd.course"]["metadata"]["seabus.kind"], "command");

    // seabus export reads it too
    let export = seabus()
        .args(["export"])
        .arg(&file)
        .args(["--topics", "cmd.**"])
        .output()
        .unwrap();
    assert!(export.status.success(), "{}", stderr(&export));
    let lines: Vec<Json> = String::from_utf8_lossy(&export.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 1);
    assert_eq!(lines[0]["topic"], "cmd.course");
    assert_eq!(lines[0]["payload"]["depth"], 2.5);
}

/// Replays `file` on a fresh medium as fast as it can; what a spy saw there, and replay's output.
fn replay_seen(file: &Path) -> (Vec<Json>, Output) {
    let url = udp_url();
    let (spy, rx) = spy_json(&url, 30);
    std::thread::sleep(Duration::from_millis(400));
    let mut child = seabus()
        .arg("replay")
        .arg(file)
        .args([&url, "--speed", "max"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_for(&mut child, Duration::from_secs(15));
    let out = child.wait_with_output().unwrap();
    assert!(status.is_some(), "replay did not end: {}", stderr(&out));
    std::thread::sleep(Duration::from_millis(400));
    drop(spy);
    let mut seen = Vec::new();
    while let Ok(v) = rx.recv_timeout(Duration::from_millis(200)) {
        seen.push(v);
    }
    (seen, out)
}

#[test]
fn a_recording_cut_short_mid_chunk_reads_up_to_the_damage() {
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cut.mcap");
    let url = udp_url();
    // a second of messages: the recorder closes a chunk every 200 ms
    record(&url, &file, || {
        publish(
            &url,
            &["nav.depth", "depth=4.5", "--count", "50", "--rate", "50"],
        )
    });
    let py: Json = serde_json::from_str(&python(PY_READ, &[file.to_str().unwrap()], &[])).unwrap();
    let chunks = py["chunks"].as_array().unwrap();
    assert!(chunks.len() >= 3, "several chunks: {py}");
    let damaged = &chunks[chunks.len() - 2];
    let start = damaged["start"].as_u64().unwrap();
    let cut = start + damaged["length"].as_u64().unwrap() / 2;
    // the messages of the chunks before the damaged one
    let before = py["channels"]["nav.depth"]["messages"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|m| m["log_time"].as_u64() < damaged["first"].as_u64())
        .count();
    assert!(before > 0);
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..cut as usize]).unwrap();

    let stream: Json =
        serde_json::from_str(&python(PY_STREAM, &[file.to_str().unwrap()], &[])).unwrap();
    assert_eq!(stream["messages"], before as u64, "{stream}");
    assert!(
        stream["failed"].is_string(),
        "Python says it is cut: {stream}"
    );

    let (seen, out) = replay_seen(&file);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let said = stderr(&out);
    assert!(
        said.contains(&format!(
            "damaged at byte {start}: the file ends at byte {cut} inside a chunk record"
        )),
        "{said}"
    );
    let depths: Vec<&Json> = seen.iter().filter(|v| v["topic"] == "nav.depth").collect();
    assert_eq!(depths.len(), before, "{said}");
    assert!(depths.iter().all(|v| v["payload"]["depth"] == 4.5));
}

#[test]
fn an_mcap_file_python_writes_is_replayed_onto_a_medium() {
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("python.mcap");
    let script = r#"
import json, sys
from mcap.writer import Writer
with open(sys.argv[1], "wb") as f:
    w = Writer(f)
    w.start()
    schema = w.register_schema(name="Fix", encoding="jsonschema",
        data=json.dumps({"type": "object", "properties": {"lat": {"type": "number"}}}).encode())
    fix = w.register_channel(topic="/gps/fix", message_encoding="json", schema_id=schema)
    raw = w.register_channel(topic="raw.bytes", message_encoding="cdr", schema_id=0)
    for i in range(5):
        t = 1_700_000_000_000_000_000 + i * 10_000_000
        w.add_message(channel_id=fix, log_time=t, publish_time=t, sequence=i,
            data=json.dumps({"lat": 43.5 + i, "lon": 16.25, "ok": True}).encode())
    w.add_message(channel_id=raw, log_time=t, publish_time=t, sequence=0, data=bytes([1, 2, 3]))
    w.finish()
"#;
    python(script, &[file.to_str().unwrap()], &[]);
    let (seen, out) = replay_seen(&file);
    assert!(out.status.success(), "{}", stderr(&out));
    let fixes: Vec<&Json> = seen.iter().filter(|v| v["topic"] == "/gps/fix").collect();
    let lats: Vec<f64> = fixes
        .iter()
        .map(|v| v["payload"]["lat"].as_f64().unwrap())
        .collect();
    assert_eq!(lats, [43.5, 44.5, 45.5, 46.5, 47.5], "{seen:?}");
    assert!(
        fixes
            .iter()
            .all(|v| v["kind"] == "data" && v["payload"]["ok"] == true)
    );
    let raw: Vec<&Json> = seen.iter().filter(|v| v["topic"] == "raw.bytes").collect();
    assert_eq!(raw.len(), 1, "{seen:?}");
    assert_eq!(raw[0]["format"], "bytes");
}

#[test]
fn corrupt_mcap_files_are_refused_with_the_byte_where_reading_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let url = udp_url();
    let good = dir.path().join("good.mcap");
    record(&url, &good, || {
        publish(
            &url,
            &["nav.depth", "depth=1", "--count", "20", "--rate", "40"],
        )
    });
    let bytes = std::fs::read(&good).unwrap();
    let replay = |name: &str, content: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, content).unwrap();
        let out = seabus()
            .arg("replay")
            .arg(&path)
            .args([&udp_url(), "--speed", "max"])
            .output()
            .unwrap();
        (out.status.code(), stderr(&out))
    };
    let mut bad_magic = bytes.clone();
    bad_magic[1] = b'X';
    let (code, said) = replay("magic.mcap", &bad_magic);
    assert_eq!(code, Some(1), "{said}");
    assert!(
        said.contains("damaged at byte 0: the file's opening magic is wrong: not an MCAP file"),
        "{said}"
    );
    // the first chunk starts after the magic and the header record
    let header_len = u64::from_le_bytes(bytes[9..17].try_into().unwrap());
    let first_record = 8 + 9 + header_len;
    let mut bad_crc = bytes.clone();
    bad_crc[first_record as usize + 80] ^= 0x5A;
    let (code, said) = replay("crc.mcap", &bad_crc);
    assert_eq!(code, Some(1), "{said}");
    assert!(
        said.contains(&format!("damaged at byte {first_record}: ")),
        "{said}"
    );
    let (code, said) = replay("short.mcap", &bytes[..12]);
    assert_eq!(code, Some(1), "{said}");
    assert!(
        said.contains("damaged at byte 8: the file ends inside a record's header"),
        "{said}"
    );
}

#[test]
fn an_lcm_log_converts_to_mcap_with_its_messages_decoded_by_their_lcm_types() {
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let types = dir.path().join("lab.lcm");
    std::fs::write(
        &types,
        "package lab;\nstruct probe_t {\n  int64_t utime;\n  double depth;\n  string label;\n}\n",
    )
    .unwrap();
    lcm_gen_python(dir.path(), &types);
    let log = dir.path().join("dive.lcm");
    let write = r#"
import sys, lcm
from lab import probe_t
log = lcm.EventLog(sys.argv[1], "w", overwrite=True)
for i in range(5):
    m = probe_t()
    m.utime = 1_700_000_000_000_000 + i * 100_000
    m.depth = 10.0 + i * 0.5
    m.label = "probe %d" % i
    log.write_event(m.utime, "PROBE", m.encode())
log.write_event(1_700_000_001_000_000, "RAW", bytes([1, 2, 3]))
log.close()
"#;
    python(
        write,
        &[log.to_str().unwrap()],
        &[("PYTHONPATH", dir.path().to_str().unwrap())],
    );
    let out_file = dir.path().join("dive.mcap");
    let out = seabus()
        .arg("convert")
        .arg(&log)
        .arg(&out_file)
        .arg("--lcm-types")
        .arg(&types)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("6 events from")
            && stderr(&out).contains("(5 decoded by their LCM type)"),
        "{}",
        stderr(&out)
    );
    let py: Json =
        serde_json::from_str(&python(PY_READ, &[out_file.to_str().unwrap()], &[])).unwrap();
    assert_eq!(py["statistics"], 6);
    let probe = &py["channels"]["PROBE"];
    assert_eq!(probe["encoding"], "json");
    assert_eq!(
        probe["schema_data"]["properties"]["depth"]["type"],
        "number"
    );
    assert_eq!(
        probe["schema_data"]["properties"]["label"]["type"],
        "string"
    );
    let messages = probe["messages"].as_array().unwrap();
    assert_eq!(messages.len(), 5);
    for (i, m) in messages.iter().enumerate() {
        assert_eq!(m["data"]["depth"], 10.0 + i as f64 * 0.5, "{m}");
        assert_eq!(m["data"]["label"], format!("probe {i}"));
        // the event's time, kept
        assert_eq!(
            m["log_time"].as_u64().unwrap(),
            (1_700_000_000_000_000 + i as u64 * 100_000) * 1000
        );
    }
    let raw = &py["channels"]["RAW"];
    assert_eq!(raw["encoding"], "application/octet-stream");
    assert_eq!(raw["messages"][0]["data"], "010203");
    // an existing output is kept unless told
    let again = seabus()
        .arg("convert")
        .arg(&log)
        .arg(&out_file)
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(2));
    assert!(stderr(&again).contains("the file exists (--force replaces it)"));
}

/// Makes, with lcm-gen, the Python classes of the types in `lcm_file` in `dir`.
fn lcm_gen_python(dir: &Path, lcm_file: &Path) {
    let status = Command::new("lcm-gen")
        .arg("-p")
        .arg("--ppath")
        .arg(dir)
        .arg(lcm_file)
        .status()
        .expect("lcm-gen runs (install it with ./scripts/test: pip install lcm)");
    assert!(status.success());
}

/// An LCM type with nested structs, arrays and floats of both widths, for the round trip.
const ROUND_TRIP_TYPES: &str = "package rt;\n\
struct inner_t {\n  double x;\n  float y;\n}\n\
struct outer_t {\n  int64_t utime;\n  double depth;\n  inner_t pos;\n  int32_t n;\n  \
double ranges[n];\n  inner_t pair[2];\n  string name;\n  boolean ok;\n}\n";

/// The messages of the round trip (Python, with the lcm-gen classes on its path): NaN and ±inf
/// in scalars, in nested structs, in arrays and in arrays of structs.
const ROUND_TRIP_MESSAGES: &str = r#"
import math
from rt import outer_t, inner_t
nan, inf = math.nan, math.inf
def inner(x, y):
    i = inner_t()
    i.x, i.y = x, y
    return i
def messages():
    out = []
    depths = [1.5, nan, inf, -inf, 2.5, nan]
    for k, d in enumerate(depths):
        m = outer_t()
        m.utime = 1_700_000_000_000_000 + k * 100_000
        m.depth = d
        m.pos = inner([inf, 0.5, -inf, nan, 3.25, 0.0][k], [nan, 0.25, inf, -inf, 1.5, nan][k])
        m.ranges = [[], [1.0], [1.0, nan, -inf], [inf], [2.0, 3.0], [nan, nan]][k]
        m.n = len(m.ranges)
        m.pair = [inner(float(k), nan if k % 2 else 0.5), inner(-inf if k == 3 else 1.0, 2.0)]
        m.name = "msg %d" % k
        m.ok = k % 2 == 0
        out.append(m)
    return out
def same(a, b):
    if isinstance(a, float) or isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if hasattr(a, "__slots__"):
        return all(same(getattr(a, s), getattr(b, s)) for s in a.__slots__)
    return a == b
"#;

/// An LCM log with NaN, ±inf and nested types converted to MCAP and back: every MCAP message is
/// strict JSON (no NaN literal, as JavaScript readers need) valid against its channel's JSON
/// Schema (Python's `jsonschema`, draft 2020-12), its channel names the LCM type, and the LCM log
/// made from the MCAP file holds only the original channel's events, which the lcm-gen Python
/// classes decode to the original values, and a C program on liblcm (`tests/peers/lcm_round_trip.c`,
/// lcm-gen's C types) to the original values bit for bit.
#[test]
fn lcm_to_mcap_to_lcm_keeps_nan_infinities_and_nested_types() {
    require_python_mcap();
    let dir = tempfile::tempdir().unwrap();
    let types = dir.path().join("rt.lcm");
    std::fs::write(&types, ROUND_TRIP_TYPES).unwrap();
    lcm_gen_python(dir.path(), &types);
    let path = [("PYTHONPATH", dir.path().to_str().unwrap())];
    let log = dir.path().join("in.lcm");
    let write = format!(
        "{ROUND_TRIP_MESSAGES}\nimport sys, lcm\n\
         log = lcm.EventLog(sys.argv[1], 'w', overwrite=True)\n\
         for m in messages():\n    log.write_event(m.utime, 'NAV', m.encode())\n\
         log.close()\n"
    );
    python(&write, &[log.to_str().unwrap()], &path);
    let mcap_file = dir.path().join("mid.mcap");
    let convert = |from: &Path, to: &Path| {
        seabus()
            .arg("convert")
            .arg(from)
            .arg(to)
            .arg("--lcm-types")
            .arg(&types)
            .output()
            .unwrap()
    };
    let out = convert(&log, &mcap_file);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("6 events from")
            && stderr(&out).contains("(6 decoded by their LCM type)"),
        "{}",
        stderr(&out)
    );
    let check = r#"
import sys, json, jsonschema
from mcap.reader import make_reader
def no_literal(name):
    raise ValueError("a %s literal is not JSON" % name)
valid, types, moved = 0, set(), 0
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        s = json.loads(schema.data)
        jsonschema.Draft202012Validator.check_schema(s)
        data = json.loads(message.data, parse_constant=no_literal)
        jsonschema.Draft202012Validator(s).validate(data)
        types.add(channel.metadata.get("lcm.type"))
        moved += "$nonfinite" in data
        valid += 1
print(json.dumps({"valid": valid, "types": sorted(map(str, types)), "moved": moved}))
"#;
    let seen: Json = serde_json::from_str(&python(check, &[mcap_file.to_str().unwrap()], &[]))
        .expect("the checker's report");
    // every message but the fifth (all finite) has values under `$nonfinite`
    assert_eq!(
        seen,
        serde_json::json!({"valid": 6, "types": ["rt.outer_t"], "moved": 5})
    );
    let back = dir.path().join("back.lcm");
    let out = convert(&mcap_file, &back);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("(6 encoded with their LCM type again)"),
        "{}",
        stderr(&out)
    );
    let decode = format!(
        "{ROUND_TRIP_MESSAGES}\nimport sys, lcm\n\
         events = list(lcm.EventLog(sys.argv[1], 'r'))\n\
         assert [e.channel for e in events] == ['NAV'] * 6, [e.channel for e in events]\n\
         for e, m in zip(events, messages()):\n\
         \x20   got = outer_t.decode(e.data)\n\
         \x20   assert same(got, m), (e.timestamp, got.depth, got.pos.x, got.ranges)\n\
         \x20   assert e.timestamp == m.utime, e.timestamp\n\
         print('decoded', len(events))\n"
    );
    assert_eq!(
        python(&decode, &[back.to_str().unwrap()], &path).trim(),
        "decoded 6"
    );
    // and a C program on liblcm, with lcm-gen's C types, reads the same values bit for bit
    let run = |program: &str, args: &[&str]| {
        succeeds(
            Command::new(program).args(args).current_dir(dir.path()),
            &format!("{program} {args:?} (./scripts/test installs liblcm-bin and liblcm-dev)"),
        )
    };
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/lcm_round_trip.c"),
        dir.path().join("lcm_round_trip.c"),
    )
    .unwrap();
    run("/usr/bin/lcm-gen", &["-c", "rt.lcm"]);
    run(
        "cc",
        &[
            "-Wall",
            "-Werror",
            "-o",
            "lcm_round_trip",
            "lcm_round_trip.c",
            "rt_outer_t.c",
            "rt_inner_t.c",
            "-I.",
            "-llcm",
            "-lm",
        ],
    );
    let c_lines = String::from_utf8(
        run(
            dir.path().join("lcm_round_trip").to_str().unwrap(),
            &[back.to_str().unwrap()],
        )
        .stdout,
    )
    .unwrap();
    let wanted = format!(
        "{ROUND_TRIP_MESSAGES}\nimport math, struct\n\
         def d(v): return ' nan' if math.isnan(v) else ' %016x' % struct.unpack('<Q', struct.pack('<d', v))[0]\n\
         def f(v): return ' nan' if math.isnan(v) else ' %08x' % struct.unpack('<I', struct.pack('<f', v))[0]\n\
         for m in messages():\n\
         \x20   line = 'NAV %d %d' % (m.utime, m.utime) + d(m.depth) + d(m.pos.x) + f(m.pos.y) + ' %d' % m.n\n\
         \x20   line += ''.join(d(r) for r in m.ranges) + ''.join(d(p.x) + f(p.y) for p in m.pair)\n\
         \x20   print(line + ' %s %d' % (m.name, 1 if m.ok else 0))\n"
    );
    assert_eq!(c_lines, python(&wanted, &[], &path));
}
