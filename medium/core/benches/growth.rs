//! How the cost of handing out a message grows with the system: against the number of
//! subscribers that take it (1, 10, 100, 1 000), and against the number of subscription patterns
//! that do not match it (1, 100, 10 000, wildcards included). Prints the cost per delivery and its
//! ratio to the smallest case, measured in one run.
//!
//! Run: `cargo bench -p seabus-medium --bench growth`

mod common;

use seabus_medium::{Interface, Medium, Node, Payload, Topic};
use std::time::Instant;

use seabus_bench::{Goals, scale};

/// Publishes `n` messages on `nav.attitude` to a bus where `takers` interfaces subscribe
/// `nav.*` and idle interfaces hold `idle` patterns that never match; returns nanoseconds per
/// delivered message, the best of the rounds.
fn cost(rt: &tokio::runtime::Runtime, takers: usize, idle: usize, n: usize) -> f64 {
    let bus = Medium::in_process("bus", &Node::new("bench"));
    let publisher = bus.attach("pub");
    let mut ports: Vec<Interface> = (0..takers)
        .map(|i| {
            bus.attach_with(&format!("sub{i}"), n, 16)
                .subscribed("nav.*")
                .expect("valid pattern")
        })
        .collect();
    // idle patterns, a hundred to an interface, of every shape: exact, `x.**`, `x.*`, `*.x`, `**.x`
    let mut idlers = Vec::new();
    for chunk in 0..idle.div_ceil(100) {
        let mut port = bus.attach(&format!("idle{chunk}"));
        for i in chunk * 100..((chunk + 1) * 100).min(idle) {
            let p = match i % 5 {
                0 => format!("other{i}.value"),
                1 => format!("other{i}.**"),
                2 => format!("nav.attitude.other{i}.*"),
                3 => format!("*.other{i}"),
                _ => format!("**.other{i}"),
            };
            port.subscribe(&p).expect("valid pattern");
        }
        idlers.push(port);
    }
    let topic = Topic::new("nav.attitude").expect("valid topic");
    let payload = Payload::from(common::ten_fields());
    let mut best = f64::INFINITY;
    for _ in 0..scale(5, 3) {
        let start = Instant::now();
        rt.block_on(async {
            for _ in 0..n {
                publisher.send(&topic, payload.clone()).await.expect("sent");
            }
        });
        let took = start.elapsed().as_secs_f64();
        for p in &mut ports {
            let mut got = 0;
            while p.try_recv().is_ok() {
                got += 1;
            }
            assert_eq!(got, n, "every taker got every message");
        }
        for p in &mut idlers {
            assert!(p.try_recv().is_err(), "no idle pattern matched");
        }
        best = best.min(took * 1e9 / (n * takers.max(1)) as f64);
    }
    best
}

fn main() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    println!(
        "growth: cost of handing out one message (10-field datamap), best of {} rounds",
        scale(5, 3)
    );
    let mut goals = Goals::new();
    let per = scale(100_000, 20_000);
    println!("  subscribers that take it (each `nav.*`):");
    let mut first = None;
    for takers in [1, 10, 100, 1000] {
        let n = (per / takers).max(1000);
        let ns = cost(&rt, takers, 0, n);
        let base = *first.get_or_insert(ns);
        println!("    {takers:>5}: {ns:>7.1} ns per delivery");
        if takers > 1 {
            goals.at_most(
                &format!("cost per delivery, {takers} takers / 1"),
                ns / base,
                2.0,
            );
        }
    }
    println!("  patterns that do not match it (one subscriber takes it):");
    let few = cost(&rt, 1, 1, per);
    let hundred = cost(&rt, 1, 100, per);
    let many = cost(&rt, 1, 10_000, per);
    println!("         1: {few:>7.1} ns per message   (tried one by one)");
    println!(
        "       100: {hundred:>7.1} ns per message   {:.2}× the cost with 1 (the index's own cost)",
        hundred / few
    );
    println!("     10000: {many:>7.1} ns per message");
    goals.at_most(
        "cost per message, 10 000 idle patterns / 100",
        many / hundred,
        1.25,
    );
    goals.finish();
}
