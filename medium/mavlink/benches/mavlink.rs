//! MAVLink parsing throughput, in memory: messages per second through the medium's per-frame work
//! on a byte stream — finding and checking each frame ([`frame::StreamReader`], which tells why
//! what is not a frame was refused), decoding it into a datamap by field name ([`Dialect::decode`])
//! and naming its topic `mavlink.SYSID.NAME` — against the bare `mavlink` crate reading the same
//! bytes with its own reader into its typed messages (`MavlinkReader::read_any_message`). The
//! stream is what an ArduSub ROV sends a ground station (HEARTBEAT, ATTITUDE, GLOBAL_POSITION_INT,
//! SCALED_PRESSURE, SYS_STATUS, VFR_HUD, BATTERY_STATUS, MAVLink 2), read in 4 KiB chunks as a
//! stream's reads come. No sockets, no tasks, no queues. Target: at least 0.8×.
//!
//! Run: `cargo bench -p seabus-medium-mavlink --bench mavlink` (`SEABUS_BENCH_SMOKE=1`: the
//! short run).

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MavHeader, MavlinkReader, MavlinkVersion};
use seabus_bench::{Goals, scale};
use seabus_medium::{DataMap, Topic, Value};
use seabus_medium_mavlink::Dialect;
use seabus_medium_mavlink::frame::{Item, StreamReader};
use std::collections::HashMap;
use std::hint::black_box;
use std::time::Instant;

const DIALECT: Dialect = Dialect::ArduPilotMega;

/// One second of an ArduSub ROV's telemetry, `n` times over.
fn stream(n: usize) -> (Vec<u8>, usize) {
    let msgs: Vec<(&str, DataMap)> = vec![
        (
            "HEARTBEAT",
            DataMap::new()
                .with("custom_mode", 19i64)
                .with("type", "MAV_TYPE_SUBMARINE")
                .with("autopilot", "MAV_AUTOPILOT_ARDUPILOTMEGA")
                .with(
                    "base_mode",
                    "MAV_MODE_FLAG_SAFETY_ARMED | MAV_MODE_FLAG_CUSTOM_MODE_ENABLED",
                )
                .with("system_status", "MAV_STATE_ACTIVE")
                .with("mavlink_version", 3i64),
        ),
        (
            "ATTITUDE",
            DataMap::new()
                .with("time_boot_ms", 123_456i64)
                .with("roll", 0.1)
                .with("pitch", -0.05)
                .with("yaw", 1.57)
                .with("rollspeed", 0.01)
                .with("pitchspeed", 0.0)
                .with("yawspeed", -0.02),
        ),
        (
            "GLOBAL_POSITION_INT",
            DataMap::new()
                .with("time_boot_ms", 123_456i64)
                .with("lat", 435_081_000i64)
                .with("lon", 164_402_000i64)
                .with("alt", -12_500i64)
                .with("relative_alt", -12_500i64)
                .with("vx", 30i64)
                .with("vy", -40i64)
                .with("vz", 2i64)
                .with("hdg", 9000i64),
        ),
        (
            "SCALED_PRESSURE",
            DataMap::new()
                .with("time_boot_ms", 123_456i64)
                .with("press_abs", 2250.5)
                .with("press_diff", 0.0)
                .with("temperature", 1850i64),
        ),
        (
            "SYS_STATUS",
            DataMap::new()
                .with("onboard_control_sensors_present", 3i64)
                .with("onboard_control_sensors_enabled", 3i64)
                .with("onboard_control_sensors_health", 3i64)
                .with("load", 250i64)
                .with("voltage_battery", 15_800i64)
                .with("current_battery", 420i64)
                .with("battery_remaining", 76i64)
                .with("drop_rate_comm", 0i64)
                .with("errors_comm", 0i64)
                .with("errors_count1", 0i64)
                .with("errors_count2", 0i64)
                .with("errors_count3", 0i64)
                .with("errors_count4", 0i64),
        ),
        (
            "VFR_HUD",
            DataMap::new()
                .with("airspeed", 0.0)
                .with("groundspeed", 0.5)
                .with("heading", 90i64)
                .with("throttle", 10i64)
                .with("alt", -12.5)
                .with("climb", 0.02),
        ),
        (
            "BATTERY_STATUS",
            DataMap::new()
                .with("current_consumed", 1200i64)
                .with("energy_consumed", -1i64)
                .with("temperature", 32767i64)
                .with("voltages", vec![Value::Int(15_800); 10])
                .with("current_battery", 420i64)
                .with("id", 0i64)
                .with("battery_function", "MAV_BATTERY_FUNCTION_ALL")
                .with("type", "MAV_BATTERY_TYPE_LION")
                .with("battery_remaining", 76i64),
        ),
    ];
    let mut out = Vec::new();
    let mut count = 0;
    let mut seq = 0u8;
    for _ in 0..n {
        for (name, map) in &msgs {
            let header = MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: seq,
            };
            seq = seq.wrapping_add(1);
            out.extend(
                DIALECT
                    .encode(MavlinkVersion::V2, header, name, map)
                    .expect("a message of the dialect"),
            );
            count += 1;
        }
    }
    (out, count)
}

/// Messages per second of the fastest of `rounds` runs of each of `a` and `b`, taken in turns so
/// that both see the same machine.
fn best_rates(
    n: usize,
    rounds: usize,
    mut a: impl FnMut() -> usize,
    mut b: impl FnMut() -> usize,
) -> (f64, f64) {
    let rate = |f: &mut dyn FnMut() -> usize| {
        let start = Instant::now();
        let got = f();
        assert_eq!(got, n, "every message read");
        n as f64 / start.elapsed().as_secs_f64()
    };
    (0..rounds).fold((0.0, 0.0), |(ra, rb), _| {
        (ra.max(rate(&mut a)), rb.max(rate(&mut b)))
    })
}

fn main() {
    let (bytes, n) = stream(scale(3000, 1000));
    let rounds = scale(9, 5);
    let bare = || {
        let mut reader = MavlinkReader::new(&bytes[..]);
        let mut got = 0;
        while let Ok((header, msg)) = reader.read_any_message::<MavMessage>() {
            black_box((header, msg));
            got += 1;
        }
        got
    };
    let ours = || {
        let mut reader = StreamReader::default();
        let mut topics: HashMap<(u32, &'static str), Topic> = HashMap::new();
        let mut got = 0;
        for chunk in bytes.chunks(4096) {
            reader.push(DIALECT, black_box(chunk), |item| {
                if let Item::Frame(f) = item {
                    let sysid = f.raw.system_id();
                    let compid = f.raw.component_id();
                    if let Ok((name, mut map)) = DIALECT.decode(&f.raw) {
                        map.push("sysid", Value::Int(sysid.into()));
                        map.push("compid", Value::Int(compid.into()));
                        let topic = topics
                            .entry((sysid, name))
                            .or_insert_with(|| {
                                Topic::new(&format!("mavlink.{sysid}.{name}")).expect("a topic")
                            })
                            .clone();
                        black_box((topic, map));
                        got += 1;
                    }
                }
            });
        }
        got
    };
    // what the medium's path is built of, measured in the same rounds
    let found = || {
        let mut reader = StreamReader::default();
        let mut got = 0;
        for chunk in bytes.chunks(4096) {
            reader.push(DIALECT, black_box(chunk), |item| {
                if let Item::Frame(f) = item {
                    black_box(f.raw.message_id());
                    got += 1;
                }
            });
        }
        got
    };
    let typed = || {
        let mut reader = StreamReader::default();
        let mut got = 0;
        for chunk in bytes.chunks(4096) {
            reader.push(DIALECT, black_box(chunk), |item| {
                if let Item::Frame(f) = item
                    && let Ok(m) = <MavMessage as mavlink::Message>::parse(
                        f.raw.version(),
                        f.raw.message_id(),
                        f.raw.payload(),
                    )
                {
                    black_box(m);
                    got += 1;
                }
            });
        }
        got
    };
    let (found, typed) = best_rates(n, 5, found, typed);
    let (bare, ours) = best_rates(n, rounds, bare, ours);
    println!(
        "MAVLink 2 messages of an ArduSub ROV (7 kinds), in memory, best of {rounds} x {n}, taken in turns:"
    );
    println!("  bare mavlink crate: MavlinkReader into typed messages   {bare:>10.0} messages/s");
    println!("  seabus: frame, check, datamap by field name, topic     {ours:>10.0} messages/s");
    println!("  built of (best of 5):");
    println!("    frames found and checked only                        {found:>10.0} messages/s");
    println!("    found, checked and decoded into the crate's types    {typed:>10.0} messages/s");
    let mut goals = Goals::new();
    goals.aim_at_least(
        "parsing, seabus / mavlink crate",
        ours / bare,
        0.8,
        "the crate's typed decode alone runs at 0.72-0.76 of the bare reader (BENCHMARKS.md)",
    );
    goals.finish();
}
