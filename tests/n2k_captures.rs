//! canboat's real captures (`candumpSample1.txt`: a Garmin 17X GPS, a Garmin GMI-10 and an Airmar
//! DST800; `candumpSample3.txt`: Raymarine autopilot, display and AIS) decoded by seabus and by
//! canboat's own C analyzer, built from the shared peers' source by `scripts/peers canboat`.
//!
//! python-can plays each capture frame by frame into an slcan pseudo-terminal that `seabus spy
//! --n2k --json` opens (`tests/peers/n2k_capture.py`, which also writes the frames in the
//! analyzer's PLAIN format); `tests/peers/n2k_compare.py` compares the two decodings PGN by PGN,
//! field by field, after docs/nmea2000.md's forms (dates and times, bytes, seabus's units, no
//! reserved fields) and with lookup names as the canboat database names them where the
//! analyzer's newer tables rename a value (read from both files).

mod common;
use common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

/// canboat's analyzer and its samples, built once (by `scripts/peers canboat` unless the
/// environment names them).
fn canboat_peer() -> &'static (PathBuf, PathBuf) {
    static BUILT: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    BUILT.get_or_init(|| {
        let mut paths = peer_paths(
            "canboat",
            &["SEABUS_CANBOAT_ANALYZER", "SEABUS_CANBOAT_SAMPLES"],
        )
        .into_iter();
        let (analyzer, samples) = (paths.next(), paths.next());
        (
            analyzer.expect("the analyzer"),
            samples.expect("the samples"),
        )
    })
}

/// canboat's database file (`@canboat/pgns`, installed by `scripts/test`).
fn canboat_json() -> PathBuf {
    let json = std::env::var_os("SEABUS_CANBOAT_JSON").map_or_else(
        || {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("target/node-canboat/node_modules/@canboat/pgns/canboat.json")
        },
        PathBuf::from,
    );
    assert!(
        json.is_file(),
        "canboat.json at {} (scripts/test installs @canboat/pgns)",
        json.display()
    );
    json
}

/// Decodes `sample` with seabus (the built-in set, or `database`) and with the analyzer, and
/// returns the comparison's report. `late`: the spy's output is read only once the capture has
/// been played (the spy held up by a full pipe meanwhile).
fn decode_both(sample: &str, database: Option<&Path>, late: bool) -> Value {
    let (analyzer, samples) = canboat_peer();
    let dir = tempfile::tempdir().expect("dir");
    let pty = dir.path().join("can");
    let url = format!("slcan+pty://{}", pty.display());
    let mut args = vec![url.as_str(), "--n2k", "--json"];
    let db = database.map(|d| d.display().to_string());
    if let Some(db) = &db {
        args.extend(["--n2k-database", db]);
    }
    let mut spy = Running(
        seabus()
            .arg("spy")
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(dir.path().join("spy.err")).expect("a file"))
            .spawn()
            .expect("seabus spy starts"),
    );
    let stdout = spy.0.stdout.take().expect("piped");
    let mut reader = Some(stdout);
    let mut lines = None;
    if !late {
        lines = reader
            .take()
            .map(|out| lines_of(out, |l| Some(l.to_string())));
    }
    assert!(
        wait_for_path(&pty, Duration::from_secs(10)),
        "the spy's pseudo-terminal {}",
        pty.display()
    );
    let plain = dir.path().join("frames.plain");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/n2k_capture.py");
    let capture = samples.join(sample);
    let sent = succeeds(
        Command::new("python3")
            .arg(script)
            .arg(&capture)
            .arg(&plain)
            .arg(&pty),
        "python-can plays the capture",
    );
    let frames: u64 = String::from_utf8_lossy(&sent.stdout)
        .trim()
        .strip_prefix("sent ")
        .and_then(|n| n.parse().ok())
        .expect("the player says how many frames it sent");
    assert!(frames > 2000, "{frames} frames in {sample}");
    let lines = lines.unwrap_or_else(|| {
        lines_of(reader.take().expect("not read yet"), |l| {
            Some(l.to_string())
        })
    });
    // the spy has read them all once its output stops growing (bounded)
    let seabus_out = dir.path().join("seabus.json");
    let mut got = Vec::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while std::time::Instant::now() < deadline {
        match lines.recv_timeout(Duration::from_secs(3)) {
            Ok(l) => got.push(l),
            Err(_) => break,
        }
    }
    drop(spy);
    std::fs::write(&seabus_out, got.join("\n") + "\n").expect("written");
    let analyzer_out = dir.path().join("analyzer.json");
    let decoded = Command::new(analyzer)
        .args(["-json", "-camel"])
        .stdin(std::fs::File::open(&plain).expect("the PLAIN frames"))
        .stdout(std::fs::File::create(&analyzer_out).expect("the analyzer's output"))
        .stderr(Stdio::null())
        .status()
        .expect("canboat's analyzer runs");
    assert!(decoded.success(), "the analyzer decoded {sample}");
    let lookups = analyzer
        .ancestors()
        .nth(3)
        .expect("the analyzer's tree")
        .join("analyzer/lookup-generated-data.h");
    let compare = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/peers/n2k_compare.py");
    let out = succeeds(
        Command::new("python3")
            .arg(compare)
            .arg(&analyzer_out)
            .arg(&seabus_out)
            .arg(&lookups)
            .arg(canboat_json()),
        "the comparison",
    );
    let mut report: Value = serde_json::from_slice(&out.stdout).expect("the comparison's report");
    report["spy"] =
        Value::from(std::fs::read_to_string(dir.path().join("spy.err")).unwrap_or_default());
    report
}

/// With the built-in set: every PGN both decode has every field equal, in both captures, and
/// neither decodes a message of those PGNs the other does not.
#[test]
fn the_built_in_set_decodes_canboat_s_captures_as_canboat_s_analyzer_does() {
    for (sample, at_least) in [("candumpSample1.txt", 1600), ("candumpSample3.txt", 790)] {
        let report = decode_both(sample, None, false);
        let compared = report["compared"].as_u64().unwrap_or(0);
        assert!(compared >= at_least, "{sample}: {report}");
        assert_eq!(
            report["differences"],
            Value::Array(vec![]),
            "{sample}: {}",
            report["spy"]
        );
        assert_eq!(
            report["only"],
            serde_json::json!({}),
            "{sample}: {}",
            report["spy"]
        );
        // the navigation PGNs are among them
        for id in [
            "isoAddressClaim",
            "positionRapidUpdate",
            "cogSogRapidUpdate",
        ] {
            assert!(
                report["pgns"][id].as_u64().unwrap_or(0) > 0,
                "{sample}: {id}"
            );
        }
    }
}

/// With canboat's database file: the cases canboat's analyzer decodes otherwise than seabus did
/// — a signed temperature in kelvin is a difference (Airmar's calibration offset, −8.333), another
/// manufacturer's proprietary PGN takes the generic definition (Raymarine's 65306, not Airmar's),
/// and a proprietary payload shorter than its definition keeps its bytes — now decode alike, with
/// the positions, headings and the rest of both captures.
#[test]
fn canboat_s_database_decodes_the_captures_proprietary_pgns_as_the_analyzer_does() {
    let db = canboat_json();
    let one = decode_both("candumpSample1.txt", Some(&db), false);
    let three = decode_both("candumpSample3.txt", Some(&db), false);
    let clean = |report: &Value, id: &str, at_least: u64| {
        let n = report["pgns"][id].as_u64().unwrap_or(0);
        assert!(n >= at_least, "{id}: {n} compared");
        let differing: Vec<&Value> = report["differences"]
            .as_array()
            .expect("a list")
            .iter()
            .filter(|d| d["id"] == id)
            .collect();
        assert!(differing.is_empty(), "{id}: {differing:?}");
    };
    clean(&one, "airmarCalibrateTemperature", 1);
    clean(
        &one,
        "0xef00ManufacturerProprietarySingleFrameAddressed",
        13,
    );
    clean(
        &one,
        "0x1ef00ManufacturerProprietaryFastPacketAddressed",
        100,
    );
    clean(
        &three,
        "0xff000xffffManufacturerProprietarySingleFrameNonAddressed",
        34,
    );
    for id in [
        "gnssPositionData",
        "positionRapidUpdate",
        "waterDepth",
        "environmentalParameters",
        "systemTime",
    ] {
        clean(&one, id, 90);
    }
    for id in [
        "vesselHeading",
        "attitude",
        "rateOfTurn",
        "rudder",
        "windData",
    ] {
        clean(&three, id, 18);
    }
}

/// A spy whose output is read only after the capture was played (its pipe full meanwhile, the
/// spy held up printing) times each frame by when it was read, not when it got to it: no fast
/// packet times out, and every message decodes as the analyzer has it.
#[test]
fn a_spy_held_up_by_its_output_loses_no_fast_packet() {
    let report = decode_both("candumpSample1.txt", None, true);
    assert_eq!(
        report["differences"],
        Value::Array(vec![]),
        "{}",
        report["spy"]
    );
    assert_eq!(report["only"], serde_json::json!({}), "{}", report["spy"]);
    assert_eq!(report["pgns"]["gnssPositionData"], 97, "{report}");
}
