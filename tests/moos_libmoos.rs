//! seabus and MOOS as MOOS ships: a real MOOSDB and a libMOOS app (`tests/peers/moos_peer.cpp`),
//! both built from core-moos by `scripts/peers moos` (see tests/common/moos.rs). MOOS strings are
//! read and written as libMOOS's `MOOSValFromString` reads them; the Iver2 backseat writes its
//! local grid position to the MOOSDB.

mod common;
use common::moos::*;
use common::*;
use serde_json::Value as Json;
use std::time::{Duration, Instant};

/// The text libMOOS would give for a field as seabus's JSON shows it.
fn same_text(moos: &str, seabus: &Json) -> bool {
    match seabus {
        Json::String(s) => moos == s,
        Json::Number(n) => moos.parse::<f64>().ok() == n.as_f64(),
        Json::Bool(b) => moos == if *b { "true" } else { "false" },
        _ => false,
    }
}

/// A libMOOS app writes strings; `seabus spy` on the MOOSDB shows each as the fields libMOOS
/// finds in it with `MOOSValFromString`, each with the value libMOOS finds — or, when the text
/// is not `key=value` pairs throughout, as the text itself.
#[test]
fn moos_strings_read_as_libmoos_reads_them() {
    // each text, and the keys it holds as MOOS reads it (none: not pairs)
    let cases: [(&str, &[&str]); 11] = [
        ("a = b , c = d", &["a", "c"]),
        ("k=v=w", &["k"]),
        ("a=1\nb=2", &["a"]),
        ("x=1,x=2", &["x"]),
        ("NAME=auv1,X=10.5,MODE=\"A\"", &["NAME", "X", "MODE"]),
        (" my key = 12 ,flag=true", &["my key", "flag"]),
        ("K1=5,K=2", &["K1", "K"]),
        ("a=,b=2,", &["a", "b"]),
        ("pts={0,0:10,10},label=a", &[]),
        ("hello world", &[]),
        ("=1", &[]),
    ];
    let mut db = MoosDb::start();
    let (_spy, rx) = spy_json(&db.url("spy", "&register=S_*"), 20);
    // the spy is registered once a first write reaches it
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut up = false;
    while !up && Instant::now() < deadline {
        moos_notify(db.port, "uProbe", &[("S_PROBE", MoosValue::Double(1.0))]);
        up = rx.recv_timeout(Duration::from_millis(500)).is_ok();
    }
    assert!(up, "seabus spy hears the MOOSDB within 10 s");
    let writes: Vec<(String, MoosValue)> = cases
        .iter()
        .enumerate()
        .map(|(i, (text, _))| (format!("S_{i}"), MoosValue::Text(text.to_string())))
        .collect();
    let borrowed: Vec<(&str, MoosValue)> = writes
        .iter()
        .map(|(v, m)| (v.as_str(), m.clone()))
        .collect();
    moos_notify(db.port, "uApp", &borrowed);
    let mut got = std::collections::BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while got.len() < cases.len() && Instant::now() < deadline {
        if let Ok(v) = rx.recv_timeout(Duration::from_millis(100))
            && let Some(t) = v["topic"].as_str()
            && t != "S_PROBE"
        {
            got.insert(t.to_string(), v["payload"].clone());
        }
    }
    assert_eq!(got.len(), cases.len(), "{got:?}");
    // what libMOOS finds for each key seabus found
    let asked: Vec<(&str, Vec<String>)> = cases
        .iter()
        .map(|(text, keys)| (*text, keys.iter().map(|k| k.to_string()).collect()))
        .collect();
    let found = lookups(&asked);
    for (i, (text, keys)) in cases.iter().enumerate() {
        let payload = &got[&format!("S_{i}")];
        let map = payload.as_object().expect("a datamap");
        if keys.is_empty() {
            assert_eq!(payload, &serde_json::json!({ "value": text }), "{text:?}");
            continue;
        }
        let mut want: Vec<&str> = keys.to_vec();
        want.sort_unstable();
        assert_eq!(
            map.keys().map(String::as_str).collect::<Vec<_>>(),
            want,
            "{text:?}: {payload}"
        );
        for (key, moos) in keys.iter().zip(&found[i]) {
            let moos = moos
                .as_deref()
                .unwrap_or_else(|| panic!("{text:?}: libMOOS finds no `{key}`"));
            assert!(
                same_text(moos, &map[*key]),
                "{text:?}: `{key}` is {moos:?} to libMOOS, {} to seabus",
                map[*key]
            );
        }
    }
    db.kill();
}

/// `seabus pub` writes fields as `key=value` pairs a libMOOS app reads field by field with
/// `MOOSValFromString`; a field MOOS would read otherwise (a comma in a value) is refused, named.
#[test]
fn fields_seabus_writes_are_what_libmoos_reads() {
    let db = MoosDb::start();
    let (_watch, rx) = moos_watch(db.port, "uWatch", 15, &["NODE_REPORT", "PLAIN"]);
    let fields = [
        ("NAME", "auv1"),
        ("X", "10.5"),
        ("N", "3"),
        ("MODE", "A=B"),
        ("Q", "say \"hi\""),
        ("OK", "true"),
    ];
    let args: Vec<String> = fields.iter().map(|(k, v)| format!("{k}={v}")).collect();
    succeeds(
        seabus()
            .args(["pub", &db.url("cli", ""), "NODE_REPORT"])
            .args(&args),
        "seabus pub NODE_REPORT",
    );
    // a single string `value` goes as the string itself, whatever it looks like
    succeeds(
        seabus().args(["pub", &db.url("cli2", ""), "PLAIN", "value=x=1"]),
        "seabus pub PLAIN",
    );
    let got = moos_received(&rx, Duration::from_secs(10), |g| g.len() >= 2);
    let text = |var: &str| match got.iter().find(|(v, _)| v == var) {
        Some((_, MoosValue::Text(t))) => t.clone(),
        other => panic!("{var}: {other:?} (all: {got:?})"),
    };
    assert_eq!(text("PLAIN"), "x=1");
    let report = text("NODE_REPORT");
    let keys: Vec<String> = fields.iter().map(|(k, _)| k.to_string()).collect();
    let found = lookups(&[(report.as_str(), keys)]);
    let read: Vec<(&str, Option<&str>)> = fields
        .iter()
        .zip(&found[0])
        .map(|((k, _), v)| (*k, v.as_deref()))
        .collect();
    let want: Vec<(&str, Option<&str>)> = fields.iter().map(|(k, v)| (*k, Some(*v))).collect();
    assert_eq!(read, want, "{report:?}");

    let out = seabus()
        .args(["pub", &db.url("cli3", ""), "NODE_REPORT", "MODE=A,B"])
        .output()
        .expect("seabus runs");
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("field `MODE`: a MOOS value cannot hold a comma"),
        "{}",
        stderr(&out)
    );
}

/// A bridge from MOOS to MOOS carries what a libMOOS app writes as libMOOS reads it: pairs field
/// by field (blanks MOOS ignores left out), a word as it is, a double as a double.
#[test]
fn a_moos_to_moos_bridge_carries_what_libmoos_reads() {
    let db = MoosDb::start();
    let system = format!(
        r#"<seabus node="gw">
  <medium name="in" url="{}"/>
  <medium name="out" url="{}"/>
  <bridge name="mirror" media="in out" report="0">
    <route from="in" topics="A_PAIRS" rename="B_PAIRS"/>
    <route from="in" topics="A_WORD" rename="B_WORD"/>
    <route from="in" topics="A_NUM" rename="B_NUM"/>
  </bridge>
</seabus>"#,
        db.url("gw-in", "&amp;register=A_PAIRS,A_WORD,A_NUM"),
        db.url("gw-out", "&amp;register=NONE"),
    );
    let (_dir, path) = system_file("mirror.xml", &system);
    let checked = check(&path);
    assert!(checked.status.success(), "{}", stderr(&checked));
    let (_watch, rx) = moos_watch(db.port, "uWatch", 20, &["B_PAIRS", "B_WORD", "B_NUM"]);
    let _run = spawn_run(&path, &[]);
    let written = [
        ("A_PAIRS", MoosValue::Text("a = b , c = d=e,x=1,x=2".into())),
        ("A_WORD", MoosValue::Text("survey".into())),
        ("A_NUM", MoosValue::Double(2.5)),
    ];
    // the bridge's clients connect: write until the first copy arrives (bounded)
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut got = Vec::new();
    while got.len() < 3 && Instant::now() < deadline {
        moos_notify(db.port, "uApp", &written);
        got = moos_received(&rx, Duration::from_secs(1), |g| g.len() >= 3);
    }
    let value = |var: &str| {
        got.iter()
            .find(|(v, _)| v == var)
            .map(|(_, m)| m.clone())
            .unwrap_or_else(|| panic!("{var} written: {got:?}"))
    };
    assert_eq!(value("B_WORD"), MoosValue::Text("survey".into()));
    assert_eq!(value("B_NUM"), MoosValue::Double(2.5));
    let MoosValue::Text(pairs) = value("B_PAIRS") else {
        panic!("B_PAIRS is a string: {got:?}")
    };
    assert_eq!(pairs, "a=b,c=d=e,x=1");
    let keys = vec!["a".to_string(), "c".to_string(), "x".to_string()];
    let found = lookups(&[
        ("a = b , c = d=e,x=1,x=2", keys.clone()),
        (pairs.as_str(), keys),
    ]);
    assert_eq!(found[0], found[1]);
    assert_eq!(
        found[1],
        [Some("b".into()), Some("d=e".into()), Some("1".into())]
    );
}

/// `configs/iver2-backseat.xml`, with its frontseat on a pseudo-terminal (a simulated Iver2) and
/// its shore on a real MOOSDB: both routes of `nav.local` forward, and a libMOOS app reads NAV_X
/// and NAV_Y as doubles, with NAV_DEPTH beside them.
#[test]
fn the_iver2_backseat_writes_nav_x_and_nav_y_to_a_moosdb() {
    let db = MoosDb::start();
    let dir = tempfile::tempdir().expect("dir");
    let tty = dir.path().join("frontseat");
    let configs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let shipped = std::fs::read_to_string(configs.join("iver2-backseat.xml")).expect("shipped");
    let system = shipped
        .replace(
            "serial:///dev/ttyS1?",
            &format!("serial://{}?", tty.display()),
        )
        .replace(
            "moos://192.168.1.10:9000?",
            &format!("moos://127.0.0.1:{}?", db.port),
        )
        .replace(
            "/var/log/seabus",
            &dir.path().join("log").display().to_string(),
        )
        .replace(
            "rules=\"iver2-backseat-health.xml\"",
            &format!(
                "rules=\"{}\"",
                configs.join("iver2-backseat-health.xml").display()
            ),
        );
    assert_ne!(system, shipped);
    let backseat = dir.path().join("backseat.xml");
    std::fs::write(&backseat, &system).expect("written");
    let frontseat = dir.path().join("frontseat.xml");
    std::fs::write(
        &frontseat,
        format!(
            r#"<seabus node="iver2">
  <medium name="tty" url="pty://{}?framing=lines"/>
  <module name="sim" type="iver2-sim" medium="tty" lat="43.5081" lon="16.4402" autostart="true"/>
</seabus>"#,
            tty.display()
        ),
    )
    .expect("written");
    let (_watch, rx) = moos_watch(db.port, "uWatch", 40, &["NAV_X", "NAV_Y", "NAV_DEPTH"]);
    let _sim = spawn_run(&frontseat, &[]);
    assert!(
        wait_for_path(&tty, Duration::from_secs(10)),
        "the simulator's terminal"
    );
    let _run = spawn_run(&backseat, &[]);
    let got = moos_received(&rx, Duration::from_secs(30), |g| {
        ["NAV_X", "NAV_Y", "NAV_DEPTH"]
            .iter()
            .all(|v| g.iter().filter(|(k, _)| k == v).count() >= 2)
    });
    for var in ["NAV_X", "NAV_Y", "NAV_DEPTH"] {
        let values: Vec<f64> = got
            .iter()
            .filter(|(k, _)| k == var)
            .map(|(_, v)| match v {
                MoosValue::Double(d) => *d,
                other => panic!("{var} is a double, not {other:?}"),
            })
            .collect();
        assert!(values.len() >= 2, "{var}: {got:?}");
        // the simulated vehicle starts at the grid's origin: within a kilometre of it
        assert!(
            values.iter().all(|v| v.is_finite() && v.abs() < 1000.0),
            "{var}: {values:?}"
        );
    }
}
