//! NMEA 0183 as instruments send it: the corpus in `tests/data/field.nmea` (sentences of many
//! kinds and forms, well and badly made) is written into a real pseudo-terminal at the pace of a
//! 4800 and a 38 400 baud line, read by a serial medium and the NMEA drivers of a system (GPS,
//! compass with a table of its own for a proprietary sentence, echo sounder, wind, speed log,
//! steering), and what they publish is checked field by field against the corpus: every dataset,
//! in order on its topic, with no field more or less, positions to 1e-7°, depths to 1 cm; and every
//! rejected sentence counted on the line under its reason.

use seabus_medium::{DataMap, LinkState, Message, Value};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::collections::BTreeMap;
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::time::{Instant, timeout};

const CORPUS: &str = include_str!("data/field.nmea");

/// What one corpus entry says.
struct Entry {
    /// The bytes sent.
    bytes: Vec<u8>,
    /// The corpus line, for messages.
    line: String,
    /// Datasets published for it: topic and fields.
    published: Vec<(String, Vec<(String, Value)>)>,
    /// Why it is rejected.
    rejected: Option<String>,
}

/// `\r`, `\n` and `\xNN` escapes of a `raw` line.
fn unescape(s: &str) -> Vec<u8> {
    let mut out = Vec::new();
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match (b[i], b.get(i + 1)) {
            (b'\\', Some(b'r')) => (out.push(b'\r'), i += 2).1,
            (b'\\', Some(b'n')) => (out.push(b'\n'), i += 2).1,
            (b'\\', Some(b'x')) => {
                let hex = std::str::from_utf8(&b[i + 2..i + 4]).expect("two hex digits");
                out.push(u8::from_str_radix(hex, 16).expect("hex"));
                i += 4;
            }
            (c, _) => (out.push(c), i += 1).1,
        }
    }
    out
}

/// A value as the corpus writes it: `true`/`false`, `"text"`, a number with a point or an
/// exponent (float), or an integer.
fn value(s: &str) -> Value {
    match s {
        "true" => Value::Bool(true),
        "false" => Value::Bool(false),
        _ if s.starts_with('"') => Value::from(s.trim_matches('"')),
        _ if s.contains(['.', 'e', 'E']) || s.contains("inf") => {
            Value::Float(s.parse().unwrap_or_else(|_| panic!("a number: {s}")))
        }
        _ => Value::Int(s.parse().unwrap_or_else(|_| panic!("an integer: {s}"))),
    }
}

/// `name=value` pairs, a quoted value holding spaces.
fn fields(s: &str) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    let mut rest = s.trim();
    while !rest.is_empty() {
        let (name, after) = rest.split_once('=').expect("name=value");
        let (text, next) = if let Some(q) = after.strip_prefix('"') {
            let end = q.find('"').expect("a closing quote");
            (&after[..end + 2], &after[end + 2..])
        } else {
            after.split_once(' ').unwrap_or((after, ""))
        };
        out.push((name.to_string(), value(text)));
        rest = next.trim_start();
    }
    out
}

fn corpus() -> Vec<Entry> {
    let mut entries: Vec<Entry> = Vec::new();
    for line in CORPUS.lines() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        if let Some(expect) = line.strip_prefix("  ") {
            let e = entries.last_mut().expect("an entry before what it gives");
            if let Some(reason) = expect.strip_prefix("! ") {
                e.rejected = Some(reason.to_string());
            } else {
                let (topic, rest) = expect.split_once(' ').expect("a topic and fields");
                e.published.push((topic.to_string(), fields(rest)));
            }
            continue;
        }
        let bytes = match line.strip_prefix("raw ") {
            Some(raw) => unescape(raw),
            None => format!("{line}\r\n").into_bytes(),
        };
        entries.push(Entry {
            bytes,
            line: line.to_string(),
            published: Vec::new(),
            rejected: None,
        });
    }
    entries
}

/// How close a published float must be to the corpus's: positions to 1e-7°, depths to 1 cm,
/// anything else to one part in 10⁹.
fn tolerance(field: &str, want: f64) -> f64 {
    match field {
        "lat" | "lon" => 1e-7,
        "altitude" => 0.01,
        _ => 1e-9 * want.abs().max(1.0),
    }
}

fn same(field: &str, want: &Value, got: &Value) -> bool {
    match (want, got) {
        (Value::Float(w), Value::Float(g)) => (w - g).abs() <= tolerance(field, *w),
        (w, g) => w == g,
    }
}

const TABLE: &str = r#"<attitude-sentences>
  <sentence address="PXYZ" when="1=ATT" summary="the vehicle's own IMU">
    <value name="pitch" field="2" scale="57.29577951308232"/>
    <value name="roll" field="3" negative-when="4=P"/>
    <value name="heading" field="5"/>
  </sentence>
</attitude-sentences>"#;

/// Replays the corpus at `baud` and checks everything published and rejected.
async fn replay(baud: u32) {
    let entries = corpus();
    assert!(entries.len() >= 300, "{} sentences", entries.len());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mux").display().to_string();
    std::fs::write(dir.path().join("imu.xml"), TABLE).unwrap();
    let text = format!(
        r#"<seabus node="usv">
  <medium name="bus" url="inproc://"/>
  <medium name="line" url="serial://{path}?baud={baud}&amp;reopen=50ms"/>
  <module name="gps" type="nmea-gps" media="line bus"/>
  <module name="compass" type="nmea-heading" media="line bus" fresh="3600s" attitude_table="imu.xml"/>
  <module name="sounder" type="nmea-sounder" media="line bus"/>
  <module name="wind" type="nmea-wind" media="line bus"/>
  <module name="log" type="nmea-log" media="line bus"/>
  <module name="steering" type="nmea-steering" media="line bus"/>
</seabus>"#
    );
    let file = dir.path().join("usv.xml").display().to_string();
    let spec = SystemSpec::parse(&file, &text).unwrap();
    let mut reg = seabus_modules::Registry::new();
    reg.set_schemes(seabus_medium_serial::schemes());
    seabus_drivers::register(&mut reg);
    let rt = Runtime::start(&spec, &reg, Catalogue::built_in())
        .await
        .unwrap();
    let mut watch = rt.medium("bus").unwrap().attach_with("watch", 4096, 64);
    for pattern in ["nav.**", "env.**", "device.**", "vehicle.**"] {
        watch.subscribe(pattern).unwrap();
    }
    // the multiplexer: a bare pseudo-terminal whose far end is linked at the path
    let (mut master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let name = tokio_serial::SerialPort::name(&slave).unwrap();
    let held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&name)
        .unwrap();
    drop(slave);
    std::os::unix::fs::symlink(&name, &path).unwrap();
    let line = rt.medium("line").unwrap();
    let mut link = line.watch_link();
    timeout(
        Duration::from_secs(5),
        link.wait_for(|s| *s == LinkState::Up),
    )
    .await
    .expect("the line opens")
    .unwrap();
    let expected: usize = entries.iter().map(|e| e.published.len()).sum();
    // written at the pace of the line: ten bits a byte; what arrives is gathered meanwhile
    let gather = tokio::spawn(async move {
        let mut got: Vec<Message> = Vec::new();
        while got.len() < expected {
            match timeout(Duration::from_secs(5), watch.recv()).await {
                Ok(Some(m)) => got.push(m),
                _ => break,
            }
        }
        // anything more than the corpus says would come now
        while let Ok(Some(m)) = timeout(Duration::from_millis(500), watch.recv()).await {
            got.push(m);
        }
        got
    });
    let start = Instant::now();
    let mut sent = 0usize;
    for e in &entries {
        master.write_all(&e.bytes).await.unwrap();
        sent += e.bytes.len();
        let due = start + Duration::from_secs_f64(sent as f64 * 10.0 / f64::from(baud));
        tokio::time::sleep_until(due).await;
    }
    let got = gather.await.unwrap();
    check(&entries, &got, &line.stats().rejected, baud);
    drop(held);
    rt.shutdown().await;
}

/// Compares what was published, topic by topic in order, and the rejections by reason.
fn check(entries: &[Entry], got: &[Message], rejected: &BTreeMap<String, u64>, baud: u32) {
    type Wanted<'a> = Vec<(&'a Entry, &'a [(String, Value)])>;
    let mut want: BTreeMap<&str, Wanted> = BTreeMap::new();
    for e in entries {
        for (topic, f) in &e.published {
            want.entry(topic).or_default().push((e, f));
        }
    }
    let mut by_topic: BTreeMap<String, Vec<DataMap>> = BTreeMap::new();
    for m in got {
        let map = (*m.payload.to_map().expect("a dataset")).clone();
        by_topic.entry(m.topic.to_string()).or_default().push(map);
    }
    let topics: Vec<&str> = by_topic.keys().map(String::as_str).collect();
    assert_eq!(
        topics,
        want.keys().copied().collect::<Vec<_>>(),
        "topics at {baud} baud"
    );
    let mut checked = 0;
    for (topic, list) in &want {
        let maps = &by_topic[*topic];
        for (k, (entry, fields)) in list.iter().enumerate() {
            let Some(map) = maps.get(k) else {
                panic!("{baud} baud: {topic}: nothing for\n{}", entry.line);
            };
            let names: Vec<&str> = map.iter().map(|(n, _)| n).collect();
            let wanted: Vec<&str> = fields.iter().map(|(n, _)| n.as_str()).collect();
            assert_eq!(
                names, wanted,
                "{baud} baud: {topic} for\n{}\n{map:?}",
                entry.line
            );
            for (name, w) in fields.iter() {
                let g = map.get(name).expect("named above");
                assert!(
                    same(name, w, g),
                    "{baud} baud: {topic} field {name}: {g:?}, the corpus says {w:?}, for\n{}",
                    entry.line
                );
                checked += 1;
            }
        }
        assert_eq!(
            maps.len(),
            list.len(),
            "{baud} baud: {topic}: more than the corpus says"
        );
    }
    let mut reasons: BTreeMap<String, u64> = BTreeMap::new();
    for e in entries {
        if let Some(r) = &e.rejected {
            *reasons.entry(r.clone()).or_default() += 1;
        }
    }
    assert_eq!(rejected, &reasons, "{baud} baud: rejections by reason");
    assert!(checked > 1000, "{checked} values checked");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_field_corpus_at_4800_baud() {
    replay(4800).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_field_corpus_at_38400_baud() {
    replay(38_400).await;
}
