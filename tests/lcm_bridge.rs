//! Typed LCM routes against real LCM programs: `seabus run` bridges a bus to an LCM medium with a
//! type read from a `.lcm` file; Python classes made by lcm-gen read what it sends and send to it;
//! a message of another type on the channel is refused, naming the channel and both types. The
//! demo's vehicle is read the same way with the built-in dataset types.
//!
//! The Python `lcm` package (with lcm-gen) is installed by `./scripts/test`.

mod common;
use common::*;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const LAB_TYPES: &str = "package lab;

struct sample_t {
    int64_t utime;
    int64_t counter;
    double wave;
    string label;
    double pos[3];
}

struct other_t {
    int32_t x;
}
";

/// Makes Python classes for `lcm_file` with lcm-gen in `dir`.
fn lcm_gen(dir: &Path, lcm_file: &Path) {
    let status = Command::new("lcm-gen")
        .arg("-p")
        .arg("--ppath")
        .arg(dir)
        .arg(lcm_file)
        .status()
        .expect("lcm-gen runs (install it with ./scripts/test: pip install lcm)");
    assert!(status.success(), "lcm-gen made the Python classes");
}

/// A directory with Python's classes of seabus's own LCM types (`configs/lcm/seabus.lcm`).
fn seabus_types() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    lcm_gen(
        dir.path(),
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/lcm/seabus.lcm"),
    );
    dir
}

fn python(dir: &Path, script: &str, args: &[&str]) -> std::process::Child {
    Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .env("PYTHONPATH", dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("python3 runs")
}

const LAB_SCRIPT: &str = r#"
import json, math, sys, time
import lcm
from lab import sample_t, other_t
lc = lcm.LCM(sys.argv[1])
got = []
def on_sample(channel, data):
    m = sample_t.decode(data)
    got.append(dict(counter=m.counter, wave=m.wave, label=m.label,
                    pos_unknown=all(map(math.isnan, m.pos)), utime=m.utime))
lc.subscribe("SAMPLE", on_sample)
end = time.time() + 10
while len(got) < 3 and time.time() < end:
    lc.handle_timeout(100)
print(json.dumps(got), flush=True)
# then send typed messages the other way, and one of another type on the same channel
m = sample_t()
m.utime, m.counter, m.wave, m.label, m.pos = 5, 42, 1.5, "from python", [1.0, 2.0, 3.0]
o = other_t()
o.x = 7
for _ in range(20):
    lc.publish("FROM_PY", m.encode())
    lc.publish("FROM_PY", o.encode())
    time.sleep(0.1)
"#;

#[test]
fn typed_routes_carry_datasets_to_and_from_lcm_programs() {
    let lcm_url = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="lab">
  <medium name="bus" url="inproc://"/>
  <medium name="lcm" url="{lcm_url}"/>
  <medium name="net" url="{net}"/>
  <module name="gen" type="generator" medium="bus" topic="lab.sample" tick="20Hz"/>
  <bridge name="to-lcm" media="bus lcm" lcm_types="lab.lcm">
    <route from="bus" to="lcm" topics="lab.sample" rename="SAMPLE" lcm="lab.sample_t">
      <field name="sine" rename="wave"/>
    </route>
    <route from="lcm" to="bus" topics="FROM_PY" rename="lab.from_py" lcm="lab.sample_t"/>
  </bridge>
  <bridge name="out" media="bus net">
    <route from="bus" to="net" topics="lab.from_py"/>
    <route from="bus" to="net" topics="seabus.bridge.**"/>
  </bridge>
</seabus>"#
    );
    let (dir, path) = system_file("lab.xml", &system);
    let types = dir.path().join("lab.lcm");
    std::fs::write(&types, LAB_TYPES).unwrap();
    lcm_gen(dir.path(), &types);
    let check = check(&path);
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );

    let run = spawn_run(&path, &[]);
    let mut spy = seabus()
        .args(["spy", &net, "--json", "--for", "12"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spy starts");
    let mut py = python(dir.path(), LAB_SCRIPT, &[&lcm_url]);
    let mut line = String::new();
    BufReader::new(py.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let samples: serde_json::Value =
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("python printed JSON ({e}): {line}"));
    let samples = samples.as_array().expect("a list");
    assert_eq!(samples.len(), 3, "three typed samples decoded by Python");
    let now_us = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_micros() as i64;
    for (i, s) in samples.iter().enumerate() {
        let utime = s["utime"].as_i64().unwrap();
        assert!((now_us - utime).abs() < 10_000_000, "utime is the stamp");
        assert!(
            s["wave"].as_f64().unwrap().abs() <= 1.0,
            "sine renamed to wave"
        );
        assert_eq!(s["label"], "", "a missing string is empty");
        assert_eq!(s["pos_unknown"], true, "missing doubles are NaN");
        if i > 0 {
            assert!(s["counter"].as_i64() > samples[i - 1]["counter"].as_i64());
        }
    }

    // the typed message from Python arrives on the bus as a datamap, and the other type is refused
    let deadline = Instant::now() + Duration::from_secs(12);
    let mut from_py = None;
    let mut refused = 0;
    let lines = BufReader::new(spy.stdout.take().unwrap()).lines();
    for l in lines.map_while(Result::ok) {
        let msg: serde_json::Value = serde_json::from_str(&l).unwrap();
        match msg["topic"].as_str() {
            Some("lab.from_py") => from_py = Some(msg["payload"].clone()),
            Some("seabus.bridge.to-lcm") => {
                refused = msg["payload"]["errors"].as_i64().unwrap_or(0);
            }
            _ => {}
        }
        if (from_py.is_some() && refused > 0) || Instant::now() > deadline {
            break;
        }
    }
    let _ = py.wait();
    terminate(&run);
    let _ = spy.kill();
    let _ = spy.wait();
    let (status, stderr) = ended(run, Duration::from_secs(5));
    assert!(status.is_some());
    assert_eq!(
        from_py,
        Some(serde_json::json!({
            "utime": 5, "counter": 42, "wave": 1.5, "label": "from python", "pos": [1.0, 2.0, 3.0]
        }))
    );
    assert!(refused > 0, "the other type counted as an error");
    assert!(
        stderr.contains("channel `FROM_PY`: expected lab.sample_t")
            && stderr.contains("received lab.other_t"),
        "the refusal names channel and both types: {stderr}"
    );
}

const DEMO_SCRIPT: &str = r#"
import json, sys, time
import lcm
from seabus import position_t, vehicle_state_t
lc = lcm.LCM("udpm://239.255.76.67:7667?ttl=0")
seen = {}
def on(t):
    def f(channel, data):
        seen[channel] = t.decode(data)
    return f
lc.subscribe("NAV_POSITION", on(position_t))
lc.subscribe("VEHICLE_STATE", on(vehicle_state_t))
end = time.time() + 20
def ready():
    v = seen.get("VEHICLE_STATE")
    return "NAV_POSITION" in seen and v is not None and v.control == "in-control"
while not ready() and time.time() < end:
    lc.handle_timeout(100)
p, v = seen.get("NAV_POSITION"), seen.get("VEHICLE_STATE")
print(json.dumps(dict(lat=p and p.lat, lon=p and p.lon, mode=v and v.mode, control=v and v.control)))
"#;

#[test]
fn lcm_programs_see_the_demo_vehicle() {
    let dir = tempfile::tempdir().unwrap();
    let types = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/lcm/seabus.lcm");
    lcm_gen(dir.path(), &types);
    let mut demo = seabus()
        .args(["demo", "--for", "25"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("demo starts");
    let out = python(dir.path(), DEMO_SCRIPT, &[])
        .wait_with_output()
        .unwrap();
    terminate(&demo);
    assert!(wait_for(&mut demo, Duration::from_secs(5)).is_some());
    let seen: serde_json::Value = serde_json::from_slice(&out.stdout).expect("python printed JSON");
    let lat = seen["lat"].as_f64().expect("NAV_POSITION decoded");
    let lon = seen["lon"].as_f64().expect("NAV_POSITION decoded");
    assert!(
        (lat - 43.508).abs() < 0.01 && (lon - 16.44).abs() < 0.01,
        "{seen}"
    );
    assert_eq!(seen["control"], "in-control", "{seen}");
}

#[test]
fn udpm_alone_is_the_lcm_default_url() {
    let url = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let mut spy = seabus()
        .args(["spy", "udpm://", "--json", "--for", "10"])
        .env("LCM_DEFAULT_URL", &url)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spy starts");
    // Python publishes until the spy has had time to start listening
    let mut publisher = Command::new("python3")
        .arg("-c")
        .arg(
            "import lcm, sys, time\n\
             lc = lcm.LCM(sys.argv[1])\n\
             for i in range(40):\n    lc.publish('DEFAULT_URL', b'hello'); time.sleep(0.1)\n",
        )
        .arg(&url)
        .spawn()
        .expect("python3 runs");
    let mut line = String::new();
    BufReader::new(spy.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let _ = spy.kill();
    let _ = spy.wait();
    let _ = publisher.kill();
    let _ = publisher.wait();
    let msg: serde_json::Value = serde_json::from_str(&line)
        .unwrap_or_else(|e| panic!("spy printed a message as JSON ({e}): {line}"));
    assert_eq!(msg["topic"], "DEFAULT_URL");
    assert_eq!(msg["payload"]["base64"], "aGVsbG8=");
}

#[test]
fn pub_sends_typed_lcm_messages_that_lcm_programs_read() {
    let dir = seabus_types();
    let url = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let mut reader = python(
        dir.path(),
        "import json, sys, time\n\
         import lcm\n\
         from seabus import depth_t\n\
         lc = lcm.LCM(sys.argv[1])\n\
         got = []\n\
         lc.subscribe('NAV_DEPTH', lambda c, d: got.append(depth_t.decode(d)))\n\
         print('ready', flush=True)\n\
         end = time.time() + 10\n\
         while not got and time.time() < end:\n    lc.handle_timeout(100)\n\
         m = got[0]\n\
         print(json.dumps(dict(depth=m.depth, utime=m.utime, unknown=m.pressure != m.pressure)))\n",
        &[&url],
    );
    let mut lines = BufReader::new(reader.stdout.take().unwrap()).lines();
    assert_eq!(lines.next().unwrap().unwrap(), "ready");
    let sent = seabus()
        .args([
            "pub",
            &url,
            "NAV_DEPTH",
            "depth=3.5",
            "--lcm",
            "seabus.depth_t",
            "--allow-missing",
        ])
        .output()
        .unwrap();
    assert!(
        sent.status.success(),
        "{}",
        String::from_utf8_lossy(&sent.stderr)
    );
    let line = lines.next().unwrap().unwrap();
    let _ = reader.wait();
    let got: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(got["depth"], 3.5);
    assert_eq!(got["unknown"], true, "a field not given is NaN");
    let now_us = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_micros() as i64;
    assert!((now_us - got["utime"].as_i64().unwrap()).abs() < 10_000_000);

    let bad = seabus()
        .args(["pub", &url, "X", "depth=1", "--lcm", "seabus.nope_t"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("--lcm seabus.nope_t: no such LCM type") && err.contains("seabus.depth_t"),
        "{err}"
    );
}

#[test]
fn a_burst_from_pub_reaches_an_lcm_program_whole_and_in_order() {
    // sent as fast as pub can, as a stream however slow this build (a gap of a second): the
    // datagrams go out in batches, and the last of them before pub exits; liblcm (through
    // Python's `lcm`) hears every one
    let dir = seabus_types();
    let url = format!("udpm://{}:{}?ttl=0", group(), free_port());
    let n = 400;
    let mut reader = python(
        dir.path(),
        "import json, sys, time\n\
         import lcm\n\
         from seabus import depth_t\n\
         lc = lcm.LCM(sys.argv[1] + '&recv_buf_size=4194304')\n\
         got = []\n\
         s = lc.subscribe('BURST', lambda c, d: got.append(depth_t.decode(d).utime))\n\
         s.set_queue_capacity(100000)\n\
         print('ready', flush=True)\n\
         end = time.time() + 10\n\
         while len(got) < int(sys.argv[2]) and time.time() < end:\n    lc.handle_timeout(100)\n\
         while lc.handle_timeout(300) > 0:\n    pass\n\
         print(json.dumps(got))\n",
        &[&url, &n.to_string()],
    );
    let mut lines = BufReader::new(reader.stdout.take().unwrap()).lines();
    assert_eq!(lines.next().unwrap().unwrap(), "ready");
    succeeds(
        seabus()
            .args(["pub", &format!("{url}&send_gap=1s"), "BURST", "depth=1"])
            .args(["--lcm", "seabus.depth_t", "--allow-missing"])
            .args(["--count", &n.to_string(), "--rate", "1000000"]),
        "seabus pub",
    );
    let got: Vec<i64> = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
    let _ = reader.wait();
    assert_eq!(got.len(), n, "every message of the burst");
    assert!(
        got.windows(2).all(|w| w[0] <= w[1]),
        "in the order they were sent"
    );
}
