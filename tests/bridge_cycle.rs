//! Three media joined by bridges into a cycle, each medium duplicating and reordering on purpose:
//! every message arrives exactly once on every medium, no message goes round, and `seabus check`
//! flags the cycle.

mod common;
use common::*;
use seabus_medium::{Interface, Node};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

const PER_GENERATOR: i64 = 300;

fn system(b: &str, c: &str) -> String {
    let faults = |seed: u32| {
        format!("fault.dup=0.3&amp;fault.reorder=0.3&amp;fault.hold=3ms&amp;fault.seed={seed}")
    };
    format!(
        r#"<seabus node="ring">
  <medium name="a" url="inproc://?{fa}"/>
  <medium name="b" url="{b}&amp;{fb}"/>
  <medium name="c" url="{c}&amp;{fc}"/>
  <module name="gen-a" type="generator" medium="a" topic="t.a" tick="400Hz" count="{n}"/>
  <module name="gen-b" type="generator" medium="b" topic="t.b" tick="400Hz" count="{n}" format="xml"/>
  <module name="gen-c" type="generator" medium="c" topic="t.c" tick="400Hz" count="{n}" format="bytes"/>
  <bridge name="ab" media="a b"><route topics="t.**"/></bridge>
  <bridge name="bc" media="b c"><route topics="t.**"/></bridge>
  <bridge name="ca" media="c a"><route topics="t.**"/></bridge>
</seabus>"#,
        fa = faults(1),
        fb = faults(2),
        fc = faults(3),
        n = PER_GENERATOR,
    )
}

/// Reads everything an observer gets until the medium has been quiet for a while.
async fn drain(port: &mut Interface, quiet: Duration) -> Vec<seabus_medium::Message> {
    let mut got = Vec::new();
    let limit = tokio::time::Instant::now() + Duration::from_secs(20);
    while tokio::time::Instant::now() < limit {
        match tokio::time::timeout(quiet, port.recv()).await {
            Ok(Some(m)) => got.push(m),
            _ => break,
        }
    }
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cycle_of_faulty_media_delivers_each_message_exactly_once_everywhere() {
    let b_url = format!(
        "udp://{}:{}?ttl=0&amp;iface=127.0.0.1",
        group(),
        free_port()
    );
    let c_url = format!(
        "udp://{}:{}?ttl=0&amp;iface=127.0.0.1",
        group(),
        free_port()
    );
    let text = system(&b_url, &c_url);
    let (_dir, path) = system_file("ring.xml", &text);

    // check flags the cycle (exit 1, a warning naming the media and bridges)
    let out = check(&path);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("warning: route cycle a -> b -> c -> a through bridges ab, bc, ca"),
        "{stderr}"
    );

    // observers: one on the runtime's in-process medium, and separate nodes on the wire for b and c
    let spec = SystemSpec::parse(&path.display().to_string(), &text).unwrap();
    let mut reg = seabus_support::registry();
    seabus_bridges::register(&mut reg);
    reg.set_schemes(schemes());
    let plain = |u: &str| u.replace("&amp;", "&");
    let watcher = Node::new("watcher");
    let wire_b = schemes().open("b", &plain(&b_url), &watcher).unwrap();
    let wire_c = schemes().open("c", &plain(&c_url), &watcher).unwrap();
    let mut obs_b = wire_b.attach("observer").subscribed("t.**").unwrap();
    let mut obs_c = wire_c.attach("observer").subscribed("t.**").unwrap();
    let mut reports_b = wire_b
        .attach("reports")
        .subscribed("seabus.bridge.*")
        .unwrap();
    let mut reports_c = wire_c
        .attach("reports")
        .subscribed("seabus.bridge.ca")
        .unwrap();

    let runtime = Runtime::start(&spec, &reg, Catalogue::built_in())
        .await
        .unwrap();
    let mut obs_a = runtime
        .medium("a")
        .unwrap()
        .attach("observer")
        .subscribed("t.**")
        .unwrap();

    let quiet = Duration::from_millis(1500);
    let (got_a, got_b, got_c) = tokio::join!(
        drain(&mut obs_a, quiet),
        drain(&mut obs_b, quiet),
        drain(&mut obs_c, quiet)
    );

    let expected: BTreeSet<(String, i64)> = ["t.a", "t.b", "t.c"]
        .iter()
        .flat_map(|t| (0..PER_GENERATOR).map(move |i| (t.to_string(), i)))
        .collect();
    for (name, got) in [("a", &got_a), ("b", &got_b), ("c", &got_c)] {
        let mut seen: BTreeMap<(String, i64), usize> = BTreeMap::new();
        for m in got.iter() {
            let map = m
                .payload
                .to_map()
                .expect("every generator payload reads as a datamap");
            let i = map.get_i64("counter").unwrap();
            *seen.entry((m.topic.to_string(), i)).or_default() += 1;
            assert!(
                m.provenance.hops <= 2,
                "on {name}: {} crossed {} bridges",
                m.topic,
                m.provenance.hops
            );
        }
        let twice: Vec<_> = seen.iter().filter(|(_, n)| **n > 1).collect();
        assert!(
            twice.is_empty(),
            "on {name}, delivered more than once: {twice:?}"
        );
        let keys: BTreeSet<_> = seen.keys().cloned().collect();
        let missing: Vec<_> = expected.difference(&keys).take(5).collect();
        assert!(
            missing.is_empty(),
            "on {name}, never delivered: {missing:?}…"
        );
        assert_eq!(got.len(), expected.len(), "on {name}");
    }
    // the media really did duplicate, and the duplicates were caught
    let dups: u64 = [&obs_a, &obs_b, &obs_c]
        .iter()
        .map(|o| o.stats().duplicates)
        .sum();
    assert!(dups > 0, "no duplicate ever reached an observer");
    assert!(runtime.medium("a").unwrap().stats().fault_duplicated > 0);

    // no message went round: each bridge dealt with each message once (forwarded it, or saw it was
    // heading back to where it was first published); every later sighting was a duplicate
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let mut last: BTreeMap<String, seabus_medium::DataMap> = BTreeMap::new();
    for port in [&mut reports_b, &mut reports_c] {
        while let Ok(m) = port.try_recv() {
            last.insert(m.topic.to_string(), (*m.payload.to_map().unwrap()).clone());
        }
    }
    for bridge in ["ab", "bc", "ca"] {
        let r = last
            .get(&format!("seabus.bridge.{bridge}"))
            .unwrap_or_else(|| panic!("no report from {bridge}"));
        let field = |k: &str| r.get_i64(k).unwrap();
        assert_eq!(
            field("forwarded") + field("returned"),
            3 * PER_GENERATOR,
            "bridge {bridge}: {r}"
        );
        assert_eq!(field("hop_limited"), 0, "bridge {bridge}: {r}");
        assert!(
            field("duplicates") > 0,
            "bridge {bridge} never met a message twice: {r}"
        );
    }
    runtime.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn regression_parallel_bridges_never_wait_on_each_other() {
    // three bridges side by side between a and b, commands flooding in from c: bridges forward
    // without waiting (refusing and counting what does not fit), so none of them can block another
    let text = r#"<seabus node="par">
  <medium name="a" url="inproc://"/><medium name="b" url="inproc://"/><medium name="c" url="inproc://"/>
  <bridge name="x" media="a b"><route topics="cmd.**" kind="command"/></bridge>
  <bridge name="y" media="a b"><route topics="cmd.**" kind="command"/></bridge>
  <bridge name="z" media="a b"><route topics="cmd.**" kind="command"/></bridge>
  <bridge name="in" media="c a"><route from="c" topics="cmd.**"/></bridge>
</seabus>"#;
    let spec = SystemSpec::parse("par.xml", text).unwrap();
    let mut reg = seabus_support::registry();
    seabus_bridges::register(&mut reg);
    reg.set_schemes(schemes());
    let runtime = Runtime::start(&spec, &reg, Catalogue::built_in())
        .await
        .unwrap();
    let mut sink = runtime
        .medium("b")
        .unwrap()
        .attach("sink")
        .subscribed("cmd.**")
        .unwrap();
    let sender = runtime.medium("c").unwrap().attach("sender");
    // the bridges are running once a probe crosses from c to b
    let ready = Instant::now() + Duration::from_secs(10);
    loop {
        sender
            .command("cmd.probe", seabus_medium::DataMap::new())
            .await
            .unwrap();
        if tokio::time::timeout(Duration::from_millis(100), sink.recv())
            .await
            .is_ok()
        {
            break;
        }
        assert!(Instant::now() < ready, "the bridges never started");
    }
    while let Ok(Some(_)) = tokio::time::timeout(Duration::from_millis(200), sink.recv()).await {}
    let total = 2000i64;
    let send = tokio::spawn(async move {
        for i in 0..total {
            sender
                .command("cmd.x", seabus_medium::DataMap::new().with("i", i))
                .await
                .unwrap();
        }
    });
    let mut got = BTreeSet::new();
    let mut twice = 0;
    for m in drain(&mut sink, Duration::from_millis(1500)).await {
        if m.topic.as_str() == "cmd.probe" {
            continue;
        }
        if !got.insert(m.payload.to_map().unwrap().get_i64("i").unwrap()) {
            twice += 1;
        }
    }
    tokio::time::timeout(Duration::from_secs(5), send)
        .await
        .expect("the sender is never held up for good")
        .unwrap();
    assert_eq!(twice, 0);
    let refused: u64 = runtime
        .media()
        .map(|(_, m)| m.stats().commands_refused)
        .sum();
    let missing = total as u64 - got.len() as u64;
    assert!(
        missing <= refused,
        "{missing} commands missing, {refused} refused and counted"
    );
    assert!(!got.is_empty());
    runtime.shutdown().await;
}
