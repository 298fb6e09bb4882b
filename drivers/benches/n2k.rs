//! NMEA 2000 decode rate: seabus against canboat's own JavaScript implementation, on the same frames.
//!
//! The frames: 30 000 PGNs from 12 sources — vessel heading, attitude, rate of turn, position,
//! COG & SOG (single frames) and GNSS position, engine parameters and DC status (fast packets of
//! 7, 4 and 2 frames) — encoded by seabus, as text lines. Both sides read every line, reassemble
//! the fast packets and decode each PGN into its fields by name:
//!
//! - seabus: slcan lines parsed into frames ([`seabus_medium_can::slcan`]), reassembled
//!   ([`seabus_drivers::n2k::frame::Assembler`]) and decoded into datamaps
//!   ([`seabus_drivers::n2k::pgn::PgnDef::decode`]), in one thread;
//! - canboatjs 3.20.0: the same frames as candump lines given to `FromPgn.parseString`
//!   (`benches/n2k_canboatjs.js`), in Node.
//!
//! Each side's best of 5 runs (3 in the smoke run); printed side by side, the ratio held to a goal
//! of at least 1.0 (seabus no slower than canboatjs). canboatjs is found as the tests find it
//! (`SEABUS_CANBOATJS`, else `target/node-canboat/node_modules`); without it (or without Node)
//! only seabus's figure is printed, and the smoke run (`SEABUS_BENCH_SMOKE=1`) fails saying what
//! is missing.
//!
//! Run: `cargo bench -p seabus-drivers --bench n2k`

use seabus_bench::{Goals, scale};
use seabus_drivers::n2k::builtin;
use seabus_drivers::n2k::frame::{Assembler, Header, Limits, fast_frames};
use seabus_drivers::n2k::pgn::Packet;
use seabus_medium::{DataMap, Value};
use seabus_medium_can::frame::CanFrame;
use seabus_medium_can::slcan::{self, Line};
use std::hint::black_box;
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};
use tokio::time::Instant as TokioInstant;

/// The frames: (identifier, data).
fn frames() -> Vec<(u32, Vec<u8>)> {
    let db = builtin::database();
    let f = |k: &'static str, v: f64| (k, Value::Float(v));
    let maps: Vec<(u32, Vec<(&'static str, Value)>)> = vec![
        (127250, vec![f("heading", 123.4), f("deviation", -1.5)]),
        (
            127257,
            vec![f("yaw", 12.0), f("pitch", 3.0), f("roll", -4.0)],
        ),
        (127251, vec![f("rate", 1.5)]),
        (129025, vec![f("latitude", 43.5), f("longitude", 16.25)]),
        (129026, vec![f("cog", 45.0), f("sog", 3.2)]),
        (
            129029,
            vec![
                f("latitude", 43.5),
                f("longitude", -16.25),
                f("altitude", 12.5),
                ("method", Value::from("GNSS fix")),
                f("hdop", 0.9),
            ],
        ),
        (
            127489,
            vec![f("oilPressure", 350000.0), f("temperature", 80.0)],
        ),
        (
            127506,
            vec![f("stateOfCharge", 87.0), f("timeRemaining", 7200.0)],
        ),
    ];
    let mut out = Vec::new();
    let mut seq = 0u8;
    for i in 0..30_000usize {
        let (pgn, fields) = &maps[i % maps.len()];
        let def = &db.definitions(*pgn)[0];
        let mut m = DataMap::new().and("sid", Value::Int((i % 250) as i64));
        for (k, v) in fields {
            m.insert(*k, v.clone());
        }
        if *pgn == 127489 || *pgn == 129025 {
            m.remove("sid");
        }
        let data = def.encode(&m).expect("the bench's PGNs encode");
        let id = Header {
            priority: def.priority.unwrap_or(6),
            pgn: *pgn,
            source: 10 + (i % 12) as u8,
            destination: 255,
        }
        .id();
        if def.packet == Packet::Fast {
            seq = (seq + 1) & 7;
            out.extend(fast_frames(seq, &data).into_iter().map(|d| (id, d)));
        } else {
            out.push((id, data));
        }
    }
    out
}

/// Runs of each side; the best is taken.
fn runs() -> u32 {
    scale(5, 3)
}

fn seabus_rate(frames: &[(u32, Vec<u8>)]) -> (usize, usize, Duration) {
    let db = builtin::database();
    let lines: Vec<Vec<u8>> = frames
        .iter()
        .map(|(id, d)| {
            let mut l = slcan::encode_frame(&CanFrame::data(*id, true, d).unwrap(), None).unwrap();
            l.pop(); // the CR
            l
        })
        .collect();
    let mut best = None;
    for _ in 0..runs() {
        let mut asm = Assembler::new(Limits::default());
        let now = TokioInstant::now();
        let start = Instant::now();
        let mut pgns = 0;
        for l in &lines {
            let Ok(Line::Frame(f, _)) = slcan::parse_line(l) else {
                continue;
            };
            if let Some(m) = asm.push(
                f.id(),
                f.is_extended(),
                false,
                f.payload(),
                |p| db.packet(p),
                now,
            ) && let Some(def) = db.select(m.header.pgn, &m.data)
            {
                black_box(def.decode(&m.data));
                pgns += 1;
            }
        }
        let took = start.elapsed();
        if best.is_none_or(|(_, t)| took < t) {
            best = Some((pgns, took));
        }
    }
    let (pgns, took) = best.unwrap();
    (lines.len(), pgns, took)
}

fn canboatjs() -> Option<PathBuf> {
    let modules = match std::env::var_os("SEABUS_CANBOATJS") {
        Some(m) => PathBuf::from(m),
        None => {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/node-canboat/node_modules")
        }
    };
    modules
        .join("@canboat/canboatjs/package.json")
        .is_file()
        .then_some(modules)
}

fn canboatjs_rate(frames: &[(u32, Vec<u8>)], modules: &PathBuf) -> Option<(usize, usize, f64)> {
    let mut text = String::new();
    for (id, d) in frames {
        let hex: String = d.iter().map(|b| format!("{b:02X}")).collect();
        text.push_str(&format!("(0.000000) can0 {id:08X}#{hex}\n"));
    }
    let file = std::env::temp_dir().join(format!("seabus-n2k-bench-{}.log", std::process::id()));
    std::fs::write(&file, text).ok()?;
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/n2k_canboatjs.js");
    let out = Command::new("node")
        .arg(script)
        .arg(&file)
        .arg(runs().to_string())
        .env("NODE_PATH", modules)
        .output();
    let _ = std::fs::remove_file(&file);
    let out = match out {
        Ok(out) => out,
        Err(e) => {
            eprintln!("canboatjs: node: {e}");
            return None;
        }
    };
    if !out.status.success() {
        eprintln!("canboatjs: {}", String::from_utf8_lossy(&out.stderr));
        return None;
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).ok()?;
    Some((
        v["frames"].as_u64()? as usize,
        v["pgns"].as_u64()? as usize,
        v["seconds"].as_f64()?,
    ))
}

/// The reference cannot be measured: said and skipped, except in the smoke run, which must
/// compare and fails saying what is missing.
fn missing(what: &str) {
    if seabus_bench::smoke() {
        eprintln!("n2k decode: smoke run without its reference: {what}");
        std::process::exit(1);
    }
    println!("n2k decode, canboatjs: {what}; only seabus measured");
}

fn main() {
    let frames = frames();
    let (n, pgns, took) = seabus_rate(&frames);
    let ours = n as f64 / took.as_secs_f64();
    let runs = runs();
    println!(
        "n2k decode, seabus:    {:>10.0} frames/s ({n} frames, {pgns} PGNs in {:.1} ms, best of {runs})",
        ours,
        took.as_secs_f64() * 1e3
    );
    let Some(modules) = canboatjs() else {
        missing(
            "canboatjs is not installed (scripts/test installs it under target/node-canboat and \
             sets SEABUS_CANBOATJS)",
        );
        return;
    };
    let Some((n, their_pgns, secs)) = canboatjs_rate(&frames, &modules) else {
        missing(&format!(
            "canboatjs could not be run (`node` with NODE_PATH={})",
            modules.display()
        ));
        return;
    };
    let theirs = n as f64 / secs;
    println!(
        "n2k decode, canboatjs: {:>10.0} frames/s ({n} frames, {their_pgns} PGNs in {:.1} ms, best of {runs})",
        theirs,
        secs * 1e3
    );
    if their_pgns != pgns {
        println!("(the two decoded different numbers of PGNs: {pgns} and {their_pgns})");
    }
    let mut goals = Goals::new();
    goals.at_least("n2k decode, seabus / canboatjs", ours / theirs, 1.0);
    goals.finish();
}
