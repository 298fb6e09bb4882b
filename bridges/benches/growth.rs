//! How a bridge's cost grows with the system: routes on one medium pair (1, 10, 100), media in a
//! chain (one hop, two hops), and distinct topics through it (10, 1 000, 100 000) with the memory
//! they take. In-process media, a 10-field datamap per message, messages sent in batches of
//! [`BATCH`] and each batch taken at the far end before the next. Prints each figure and the ratio
//! to the smallest case, measured in one run; the cases compared are taken in turn, round by
//! round, so that a slow spell of the machine falls on all of them.
//!
//! Run: `cargo bench -p seabus-bridges --bench growth`

// the sample message every medium benchmark sends
#[path = "../../medium/core/benches/common.rs"]
mod common;

use seabus_bench::{Goals, scale};
use seabus_medium::Topic;
use seabus_modules::runtime::Runtime;
use seabus_modules::{Catalogue, Registry, SystemSpec};
use std::time::{Duration, Instant};

/// Messages in flight at once, at most.
const BATCH: usize = 200;

/// This process's resident memory, bytes.
fn rss() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4096)
}

/// What a case measured.
struct Measured {
    /// Seconds per message.
    per_message: f64,
    /// Resident memory grown from before the system started to the end of the run.
    grown: u64,
}

/// Rounds of each case (the median is kept): a round of the short run takes some tens of
/// milliseconds, where one slow moment of the machine shows.
fn rounds() -> usize {
    scale(5, 5)
}

/// Runs the system of `media` and `bridges` (XML), sends `n` messages on the first medium cycling
/// through `topics` and takes them on the last.
fn run(media: &[&str], bridges: &str, topics: &[Topic], n: usize) -> Measured {
    let before = rss();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let mut xml = String::from(r#"<seabus node="bench">"#);
    for m in media {
        xml.push_str(&format!(r#"<medium name="{m}" url="inproc://"/>"#));
    }
    xml.push_str(bridges);
    xml.push_str("</seabus>");
    let spec = SystemSpec::parse("bench.xml", &xml).expect("the bench's system reads");
    let mut registry = Registry::new();
    seabus_bridges::register(&mut registry);
    rt.block_on(async {
        let runtime = Runtime::start(&spec, &registry, Catalogue::built_in())
            .await
            .expect("the bench's system starts");
        let tx = runtime.medium(media[0]).expect("first").attach("tx");
        let mut rx = runtime
            .medium(media[media.len() - 1])
            .expect("last")
            .attach_with("rx", 4 * BATCH, 16)
            .subscribed("**")
            .expect("pattern");
        // the bridges' subscriptions are in place once a message gets through
        loop {
            tx.send(&topics[0], common::ten_fields())
                .await
                .expect("sent");
            if tokio::time::timeout(Duration::from_millis(100), rx.recv())
                .await
                .is_ok()
            {
                break;
            }
        }
        while rx.try_recv().is_ok() {}
        let start = Instant::now();
        let mut sent = 0;
        while sent < n {
            let batch = BATCH.min(n - sent);
            for i in sent..sent + batch {
                tx.send(&topics[i % topics.len()], common::ten_fields())
                    .await
                    .expect("sent");
            }
            for _ in 0..batch {
                tokio::time::timeout(Duration::from_secs(10), rx.recv())
                    .await
                    .expect("every message crosses within 10 s")
                    .expect("the medium stays open");
            }
            sent += batch;
        }
        let per_message = start.elapsed().as_secs_f64() / n as f64;
        let grown = rss().saturating_sub(before);
        runtime.shutdown().await;
        Measured { per_message, grown }
    })
}

fn routes(count: usize) -> String {
    let mut b = String::from(r#"<bridge name="ab" media="a b">"#);
    for i in 0..count {
        b.push_str(&format!(r#"<route from="a" to="b" topics="r{i}.**"/>"#));
    }
    b + "</bridge>"
}

fn topics(count: usize, prefix: &str) -> Vec<Topic> {
    (0..count)
        .map(|i| Topic::new(&format!("{prefix}.t{i}")).expect("topic"))
        .collect()
}

/// Each of `cases` cases measured [`rounds`] times, the cases taken in turn within each round:
/// the median time per message of each (one lucky or unlucky round moves neither), and the
/// memory it grew in the first round (when only the cases before it in the list had run).
fn in_turn(cases: usize, mut measure: impl FnMut(usize) -> Measured) -> Vec<Measured> {
    let mut runs: Vec<Vec<Measured>> = (0..cases).map(|_| Vec::new()).collect();
    for _ in 0..rounds() {
        for (i, r) in runs.iter_mut().enumerate() {
            r.push(measure(i));
        }
    }
    runs.into_iter()
        .map(|r| {
            let mut times: Vec<f64> = r.iter().map(|m| m.per_message).collect();
            times.sort_by(f64::total_cmp);
            Measured {
                per_message: times[times.len() / 2],
                grown: r[0].grown,
            }
        })
        .collect()
}

fn main() {
    let n = scale(100_000, 20_000);
    let mut goals = Goals::new();
    println!("bridge growth, in-process media, 10-field datamap, {n} messages a case:");

    println!("  routes on one medium pair (the message matches the first of them only):");
    let one = topics(1, "r0");
    let counts = [1, 10, 100];
    let systems: Vec<String> = counts.iter().map(|c| routes(*c)).collect();
    let per_message: Vec<f64> = in_turn(systems.len(), |i| run(&["a", "b"], &systems[i], &one, n))
        .iter()
        .map(|m| m.per_message)
        .collect();
    for (count, s) in counts.iter().zip(&per_message) {
        println!("    {count:>4} routes: {:>7.0} ns per message", s * 1e9);
        if *count > 1 {
            goals.at_most(
                &format!("bridge cost per message, {count} routes / 1"),
                s / per_message[0],
                1.25,
            );
        }
    }

    println!("  a chain of media, every topic routed:");
    let all = |from: &str, to: &str| {
        format!(
            r#"<bridge name="{from}{to}" media="{from} {to}"><route from="{from}" to="{to}" topics="**"/></bridge>"#
        )
    };
    let t = topics(1, "nav");
    let chains = [
        (vec!["a", "b"], all("a", "b")),
        (vec!["a", "b", "c"], all("a", "b") + &all("b", "c")),
    ];
    let per_message: Vec<f64> = in_turn(chains.len(), |i| run(&chains[i].0, &chains[i].1, &t, n))
        .iter()
        .map(|m| m.per_message)
        .collect();
    let (hop, two) = (per_message[0], per_message[1]);
    println!("    one hop:  {:>7.0} ns per message", hop * 1e9);
    println!(
        "    two hops: {:>7.0} ns per message ({:.0} ns the second hop)",
        two * 1e9,
        (two - hop) * 1e9
    );
    goals.at_most(
        "bridge cost of a second hop / the first",
        (two - hop) / hop,
        1.25,
    );

    println!("  distinct topics through one bridge (memory: resident growth while it runs):");
    let counts = [10, 1_000, 100_000];
    let names: Vec<Vec<Topic>> = counts.iter().map(|c| topics(*c, "many")).collect();
    let measured = in_turn(counts.len(), |i| {
        run(&["a", "b"], &all("a", "b"), &names[i], n.max(2 * counts[i]))
    });
    for (count, m) in counts.iter().zip(&measured) {
        println!(
            "    {count:>7} topics: {:>7.0} ns per message, resident memory grown {:.1} MB",
            m.per_message * 1e9,
            m.grown as f64 / 1e6
        );
        if *count > 10 {
            goals.at_least(
                &format!("bridge rate, {count} topics / 10"),
                measured[0].per_message / m.per_message,
                0.8,
            );
        }
    }
    goals.finish();
}
