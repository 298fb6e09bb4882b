//! `seabus spy`: a live table of the topics on a medium, or one JSON object per message; with
//! `--stats`, the medium's counters (what it read, rejected, dropped and lost) as well; with
//! `--n2k`, the CAN frames of an NMEA 2000 network as PGNs with named fields and units.

use crate::lcmtypes::Types;
use seabus_medium::{Interface, Medium, MediumStats, Message, Node, Payload, Topic};
use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::process::ExitCode;
use std::time::Duration;
use tokio::time::Instant;

/// One message as a JSON object, keys in this order: topic, kind, origin, seq, hops, stamp
/// (seconds), format, then `lcm_type` for an LCM message of a known type (its payload shown
/// decoded), then payload (a datamap's entries in their own order; `{"error": …}` for a map nested
/// too deep for the JSON form).
pub fn message_json(m: &Message, types: &Types) -> String {
    match types.recognise(&m.payload) {
        Some((name, map)) => {
            let mut m = m.clone();
            m.payload = Payload::from(map);
            message_json_as(&m, Some(name))
        }
        None => message_json_as(m, None),
    }
}

fn message_json_as(m: &Message, lcm_type: Option<&str>) -> String {
    let text = |s: &str| serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into());
    let payload = match &m.payload {
        Payload::Map(map) => seabus_medium::json::to_json(map)
            .unwrap_or_else(|e| format!("{{\"error\":{}}}", text(&e.to_string()))),
        Payload::Xml(x) => text(x),
        Payload::Bytes(b) => serde_json::to_string(&seabus_medium::Value::Bytes(b.to_vec()))
            .unwrap_or_else(|_| "null".into()),
    };
    let stamp = serde_json::to_string(&m.stamp.as_secs_f64()).unwrap_or_else(|_| "null".into());
    let lcm_type = lcm_type.map_or(String::new(), |t| format!(",\"lcm_type\":{}", text(t)));
    format!(
        "{{\"topic\":{},\"kind\":\"{}\",\"origin\":{},\"seq\":{},\"hops\":{},\"stamp\":{},\"format\":\"{}\"{lcm_type},\"payload\":{}}}",
        text(&m.topic),
        m.kind.name(),
        text(&m.origin().to_string()),
        m.seq(),
        m.provenance.hops,
        stamp,
        m.payload.format().name(),
        payload
    )
}

struct Row {
    count: u64,
    counted_at_refresh: u64,
    rate: f64,
    /// the latest message, shown when the table is printed
    last: Message,
}

fn shorten(text: String, max: usize) -> String {
    if text.chars().count() <= max {
        return text;
    }
    let mut s: String = text.chars().take(max.saturating_sub(1)).collect();
    s.push('…');
    s
}

fn print_table(rows: &BTreeMap<Topic, Row>, types: &Types, out: &mut impl Write, clear: bool) {
    if clear {
        let _ = write!(out, "\x1b[2J\x1b[H");
    }
    let _ = writeln!(
        out,
        "{:<32} {:>8} {:>9}  {:<22} last value",
        "topic", "count", "rate/s", "origin"
    );
    for (topic, r) in rows {
        let _ = writeln!(
            out,
            "{:<32} {:>8} {:>9.1}  {:<22} {}",
            // a channel name that is not a topic (LCM's `with space`) quoted
            shorten(topic.shown().into_owned(), 32),
            r.count,
            r.rate,
            shorten(r.last.origin().to_string(), 22),
            shorten(
                match types.recognise(&r.last.payload) {
                    Some((name, map)) => format!("{name} {map}"),
                    None => r.last.payload.to_string(),
                },
                70
            )
        );
    }
    let _ = out.flush();
}

/// How often `--stats` prints the medium's counters when the table is not drawn live.
const STATS_EVERY: Duration = Duration::from_secs(5);

/// The medium's counters as `--stats` prints them, on one line: `seabus spy: stats of URL after
/// SECS s: ` and every counter `name=value` as `seabus.media` carries it (`received=…
/// rejected={garbage=2} dropped_bytes=… overruns=… queue_dropped={spy=…} …`).
fn stats_line(url: &str, after: Duration, st: &MediumStats) -> String {
    format!(
        "seabus spy: stats of {url} after {:.1} s: {}",
        after.as_secs_f64(),
        st.to_map()
    )
}

/// Opens the medium and attaches the spy to it, subscribed to `topics`.
fn open(url: &str, topics: &str) -> Result<(Medium, Interface), ExitCode> {
    let node = Node::new(&format!("spy-{}", std::process::id()));
    let medium = crate::media::schemes()
        .open("spy", url, &node)
        .map_err(|e| {
            eprintln!("seabus spy: {e}");
            ExitCode::from(2)
        })?;
    let port = medium
        .attach_with("spy", 1 << 16, 1 << 10)
        .subscribed(topics)
        .map_err(|e| {
            eprintln!("seabus spy: --topics: {e}");
            ExitCode::from(2)
        })?;
    Ok((medium, port))
}

/// Counts `m` in the table.
fn count(rows: &mut BTreeMap<Topic, Row>, m: Message) {
    match rows.get_mut(&m.topic) {
        Some(row) => {
            row.count += 1;
            row.last = m;
        }
        None => {
            let row = Row {
                count: 1,
                counted_at_refresh: 0,
                rate: 0.0,
                last: m,
            };
            rows.insert(row.last.topic.clone(), row);
        }
    }
}

/// `--n2k`: CAN frames shown as the NMEA 2000 PGNs they make.
struct N2k {
    #[cfg(feature = "can")]
    listener: seabus_drivers::n2k::describe::Listener,
    /// frames that made no PGN, by reason
    refused: BTreeMap<&'static str, u64>,
}

impl N2k {
    #[cfg(feature = "can")]
    fn new(database: Option<&std::path::Path>) -> Result<N2k, String> {
        Ok(N2k {
            listener: seabus_drivers::n2k::describe::Listener::new(database)
                .map_err(|e| e.to_string())?,
            refused: BTreeMap::new(),
        })
    }

    #[cfg(not(feature = "can"))]
    fn new(_: Option<&std::path::Path>) -> Result<N2k, String> {
        Err("--n2k: this seabus was built without CAN (the `can` feature)".into())
    }

    /// What a message gives: `None` when it is no CAN frame (shown as it is); else the PGN it
    /// completes, as a message on `n2k.SOURCE.ID` (its fields by name, with units, for the
    /// table) and as the JSON object `--json` prints.
    #[cfg(feature = "can")]
    fn take(&mut self, m: &Message) -> Option<Option<(Message, String)>> {
        use seabus_medium_can::frame::CanFrame;
        let frame = CanFrame::from_message(m.topic.as_str(), &m.payload).ok()?;
        // timed by when the frame was read: a spy held up by its output (a full pipe) does not
        // time out a fast packet whose frames all came in time
        let got = self.listener.push(&frame, m.stamp.instant());
        for r in self.listener.take_rejections() {
            *self.refused.entry(r.reason).or_default() += 1;
        }
        let d = got?;
        let topic = Topic::new(&d.topic()).ok()?;
        let mut map = d.to_map();
        map.insert("topic", seabus_medium::Value::from(d.topic()));
        let json = seabus_medium::json::to_json(&map).unwrap_or_else(|e| {
            format!(
                "{{\"error\":{}}}",
                serde_json::to_string(&e.to_string()).unwrap_or_default()
            )
        });
        Some(Some((
            Message {
                topic,
                payload: Payload::from(d.named()),
                ..m.clone()
            },
            json,
        )))
    }

    #[cfg(not(feature = "can"))]
    fn take(&mut self, _: &Message) -> Option<Option<(Message, String)>> {
        None
    }
}

/// Runs the spy until `duration` passes (or Ctrl-C or SIGTERM). LCM messages of the built-in types or those
/// of `lcm_types` are shown decoded. With `stats`, the medium's counters are printed to stderr
/// ([`stats_line`]) every [`STATS_EVERY`] (under the table at each refresh when it is drawn live)
/// and when the spy ends. With `n2k` (and canboat's database file, when given), CAN frames are
/// shown as the NMEA 2000 PGNs they make ([`N2k`]); the frames that make none are counted and
/// said when the spy ends.
pub async fn spy(
    url: &str,
    duration: Option<Duration>,
    json: bool,
    stats: bool,
    topics: &str,
    lcm_types: &[std::path::PathBuf],
    n2k: Option<Option<std::path::PathBuf>>,
) -> ExitCode {
    let mut n2k = match n2k.map(|db| N2k::new(db.as_deref())).transpose() {
        Ok(n) => n,
        Err(e) => {
            eprintln!("seabus spy: {e}");
            return ExitCode::from(2);
        }
    };
    let types = match crate::lcmtypes::load(lcm_types) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("seabus spy: {e}");
            return ExitCode::from(2);
        }
    };
    let (medium, mut port) = match open(url, topics) {
        Ok(opened) => opened,
        Err(code) => return code,
    };
    let started = Instant::now();
    let deadline = duration.map(|d| started + d);
    let live = !json && std::io::stdout().is_terminal();
    let mut rows: BTreeMap<Topic, Row> = BTreeMap::new();
    let mut refresh = tokio::time::interval(Duration::from_secs(1));
    let mut last_refresh = Instant::now();
    let mut stats_every = tokio::time::interval_at(started + STATS_EVERY, STATS_EVERY);
    let stdout = std::io::stdout();
    // Ctrl-C and SIGTERM (`timeout`, a service manager) both end it with the table printed
    let stop = crate::terminated();
    tokio::pin!(stop);
    loop {
        tokio::select! {
            _ = &mut stop => break,
            _ = async {
                match deadline {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            } => break,
            _ = refresh.tick(), if !json => {
                let elapsed = last_refresh.elapsed().as_secs_f64().max(1e-3);
                last_refresh = Instant::now();
                for r in rows.values_mut() {
                    r.rate = (r.count - r.counted_at_refresh) as f64 / elapsed;
                    r.counted_at_refresh = r.count;
                }
                if live {
                    print_table(&rows, &types, &mut stdout.lock(), true);
                    if stats {
                        eprintln!("{}", stats_line(url, started.elapsed(), &medium.stats()));
                    }
                }
            }
            _ = stats_every.tick(), if stats && !live => {
                eprintln!("{}", stats_line(url, started.elapsed(), &medium.stats()));
            }
            m = port.recv() => {
                let Some(m) = m else { break };
                let m = match n2k.as_mut().and_then(|n| n.take(&m)) {
                    None => m,
                    Some(None) => continue,
                    Some(Some((pgn, line))) => {
                        if json {
                            let mut out = stdout.lock();
                            if writeln!(out, "{line}").is_err() {
                                break;
                            }
                        } else {
                            count(&mut rows, pgn);
                        }
                        continue;
                    }
                };
                if json {
                    let mut out = stdout.lock();
                    if writeln!(out, "{}", message_json(&m, &types)).is_err() {
                        break;
                    }
                } else {
                    count(&mut rows, m);
                }
            }
        }
    }
    if !json {
        print_table(&rows, &types, &mut stdout.lock(), false);
    }
    if let Some(n) = n2k.as_ref().filter(|n| !n.refused.is_empty()) {
        eprintln!(
            "seabus spy: NMEA 2000 frames that made no PGN: {:?}",
            n.refused
        );
    }
    let st = medium.stats();
    if stats {
        eprintln!("{}", stats_line(url, started.elapsed(), &st));
    } else if st.queue_dropped_total() > 0 || st.rejected_total() > 0 {
        eprintln!(
            "seabus spy: {} messages dropped (too slow), {} rejected from the wire: {:?} (--stats shows every counter)",
            st.queue_dropped_total(),
            st.rejected_total(),
            st.rejected
        );
    }
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;
    use seabus_medium::message::{Kind, Origin, Provenance, Stamp};
    use seabus_medium::{DataMap, Value};

    fn built_in() -> Types {
        crate::lcmtypes::load(&[]).unwrap()
    }

    #[cfg(feature = "lcm")]
    #[test]
    fn lcm_messages_of_known_types_show_decoded() {
        let types = built_in();
        let ty = types.0.get("seabus.depth_t").unwrap();
        let bytes = seabus_medium_lcm::codec::encode(
            &types.0,
            ty,
            &DataMap::new().with("utime", 1i64).with("depth", 12.5f64),
        )
        .unwrap();
        let m = message(DataMap::new());
        let m = Message {
            payload: Payload::from(bytes),
            ..m
        };
        let json: serde_json::Value = serde_json::from_str(&message_json(&m, &types)).unwrap();
        assert_eq!(json["lcm_type"], "seabus.depth_t");
        assert_eq!(json["payload"]["depth"], 12.5);
        let text = table_of(&m, &types);
        assert!(
            text.contains("seabus.depth_t") && text.contains("depth=12.5"),
            "{text}"
        );
        // bytes that are not a known type stay bytes
        let plain = Message {
            payload: Payload::from(b"12345678 not lcm".to_vec()),
            ..message(DataMap::new())
        };
        let json: serde_json::Value = serde_json::from_str(&message_json(&plain, &types)).unwrap();
        assert!(json.get("lcm_type").is_none());
        assert_eq!(json["format"], "bytes");
    }

    /// The table `seabus spy` prints after seeing `m` once.
    fn table_of(m: &Message, types: &Types) -> String {
        let mut rows = BTreeMap::new();
        rows.insert(
            m.topic.clone(),
            Row {
                count: 1,
                counted_at_refresh: 0,
                rate: 0.0,
                last: m.clone(),
            },
        );
        let mut out = Vec::new();
        print_table(&rows, types, &mut out, false);
        String::from_utf8(out).unwrap()
    }

    fn message(payload: DataMap) -> Message {
        Message {
            topic: Topic::new("nav.pose").unwrap(),
            kind: Kind::Data,
            provenance: Provenance {
                origin: Origin::new("auv1", "bus", 1),
                seq: 3,
                hops: 0,
            },
            stamp: Stamp(1_500_000_000),
            payload: Payload::from(payload),
        }
    }

    #[test]
    fn nested_maps_print_in_braces_in_the_table_and_as_objects_in_json() {
        let m = message(
            DataMap::new()
                .with("pose", DataMap::new().with("x", 1i64).with("y", 2i64))
                .with(
                    "wps",
                    Value::List(vec![DataMap::new().with("z", 0.5f64).into()]),
                ),
        );
        let table = table_of(&m, &built_in());
        assert!(table.contains("pose={x=1, y=2} wps=[{z=0.5}]"), "{table}");
        let json: serde_json::Value = serde_json::from_str(&message_json(&m, &built_in())).unwrap();
        assert_eq!(
            json["payload"],
            serde_json::json!({"pose": {"x": 1, "y": 2}, "wps": [{"z": 0.5}]})
        );
    }

    #[test]
    fn a_map_too_deep_for_json_prints_an_error_object() {
        let mut v = Value::Int(1);
        for _ in 0..=seabus_medium::datamap::MAX_DEPTH {
            v = Value::Map(DataMap::new().with("k", v));
        }
        let json: serde_json::Value = serde_json::from_str(&message_json(
            &message(DataMap::new().with("deep", v)),
            &built_in(),
        ))
        .unwrap();
        assert_eq!(
            json["payload"]["error"],
            "lists and maps nested deeper than 32"
        );
    }
}
