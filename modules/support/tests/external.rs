//! An external-program module written in Python: it doubles a value; killed mid-run, the runtime
//! starts it again and it doubles again. Lines it writes that are not declared outputs are not
//! published.

use seabus_medium::{DataMap, Interface};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::time::{Duration, Instant};

const DOUBLER: &str = r#"
import json, os, sys
with open(sys.argv[1], "w") as f:
    f.write(str(os.getpid()))
print("doubler started", file=sys.stderr, flush=True)
for line in sys.stdin:
    m = json.loads(line)
    v = m["payload"]["value"]
    print(json.dumps({"topic": "test.doubled", "payload": {"value": 2 * v}}), flush=True)
    # not among its outputs: never published
    print(json.dumps({"topic": "test.secret", "payload": {"value": v}}), flush=True)
"#;

/// Sends `value` until its double comes back (at most 10 s); returns it.
async fn doubled(tx: &Interface, rx: &mut Interface, value: i64) -> Option<i64> {
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        let _ = tx
            .send("test.value", DataMap::new().with("value", value))
            .await;
        let until = Instant::now() + Duration::from_millis(200);
        while let Ok(Some(m)) = tokio::time::timeout_at(until.into(), rx.recv()).await {
            assert_eq!(
                m.topic.as_str(),
                "test.doubled",
                "only declared outputs are published"
            );
            let v = m.payload.as_map().and_then(|p| p.get_i64("value"));
            if v == Some(2 * value) {
                return v;
            }
        }
    }
    None
}

fn pid(path: &std::path::Path) -> Option<i32> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_python_doubler_doubles_dies_and_is_started_again() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("doubler.py"), DOUBLER).unwrap();
    let pid_file = dir.path().join("pid");
    let system = format!(
        r#"<seabus node="t">
  <medium name="bus" url="inproc://"/>
  <module name="doubler" type="external" medium="bus" command="python3 doubler.py {}"
          inputs="test.value" outputs="test.doubled"/>
</seabus>"#,
        pid_file.display()
    );
    let path = dir.path().join("system.xml");
    std::fs::write(&path, &system).unwrap();
    let spec = SystemSpec::load(&path).unwrap();
    let rt = Runtime::start(&spec, &seabus_support::registry(), Catalogue::built_in())
        .await
        .unwrap();
    let bus = rt.medium("bus").unwrap().clone();
    let tx = bus.attach("tx");
    let mut rx = bus.attach("rx");
    rx.subscribe("test.doubled").unwrap();
    rx.subscribe("test.secret").unwrap();

    assert_eq!(doubled(&tx, &mut rx, 21).await, Some(42));
    let first = pid(&pid_file).expect("the program wrote its pid");

    // killed mid-run: the runtime starts it again
    // SAFETY: kill(2) on the program this test started
    unsafe {
        libc::kill(first, libc::SIGKILL);
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while pid(&pid_file).is_none_or(|p| p == first) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let second = pid(&pid_file).expect("a pid");
    assert_ne!(second, first, "a new program runs");
    assert_eq!(doubled(&tx, &mut rx, 50).await, Some(100));
    let status = rt.status();
    let me = status.iter().find(|s| s.name == "doubler").unwrap();
    assert!(me.restarts >= 1, "{me:?}");
    assert!(
        me.error
            .as_deref()
            .is_none_or(|e| e.contains("exited") || e.contains("lost")),
        "{me:?}"
    );
    rt.shutdown().await;
    // the program goes with the system
    let deadline = Instant::now() + Duration::from_secs(5);
    // SAFETY: signal 0 only asks whether the process exists
    while unsafe { libc::kill(second, 0) } == 0 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_ne!(
        unsafe { libc::kill(second, 0) },
        0,
        "the program stops with the system"
    );
}
