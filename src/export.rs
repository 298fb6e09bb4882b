//! `seabus export`: a time window of the logs the `logger` module (or `seabus record`) writes —
//! LCM event logs or MCAP files — as JSON lines or as one CSV per topic.

use seabus_medium::{DataMap, Pattern, Payload, Topic, Value, binary, json};
use seabus_record::log::Reader;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// What `seabus export` was asked to do.
#[derive(clap::Args)]
pub struct ExportArgs {
    /// Log files (LCM event logs or MCAP), or folders whose logs are read (in name order): every
    /// file that is an LCM event log or MCAP file by its first bytes, whatever it is named; the
    /// others are named as skipped.
    #[arg(required = true)]
    pub logs: Vec<PathBuf>,
    /// Only events from this time on: seconds since 1970, or RFC 3339 (2026-11-21T10:00:00Z).
    #[arg(long, value_name = "TIME")]
    pub from: Option<String>,
    /// Only events before this time.
    #[arg(long, value_name = "TIME")]
    pub to: Option<String>,
    /// Only topics matching this pattern.
    #[arg(long, default_value = "**")]
    pub topics: String,
    /// `json` (one object per event, on standard output or `--out`) or `csv` (a file per topic in
    /// the `--out` directory).
    #[arg(long, default_value = "json")]
    pub format: String,
    /// Where to write: a file for JSON, a directory for CSV.
    #[arg(long, value_name = "PATH")]
    pub out: Option<PathBuf>,
}

/// Reads a time: seconds since 1970 or RFC 3339.
fn parse_time(text: &str) -> Option<f64> {
    text.parse::<f64>().ok().or_else(|| {
        humantime::parse_rfc3339_weak(text)
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map(|d| d.as_secs_f64())
    })
}

/// The logs a path names: the file itself, or the logs in a folder (the others are said to be
/// skipped); a folder without any is an error.
fn files(path: &Path) -> Result<Vec<PathBuf>, String> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let (logs, skipped) =
        seabus_record::log::logs_in(path).map_err(|e| format!("{}: {e}", path.display()))?;
    for (file, why) in &skipped {
        eprintln!("seabus export: skipped {}: {why}", file.display());
    }
    if logs.is_empty() {
        return Err(format!(
            "{}: no LCM event log or MCAP file in this folder",
            path.display()
        ));
    }
    Ok(logs)
}

/// An event's payload as a datamap: a datamap as it is, bytes that are a binary datamap decoded,
/// other bytes as `{"bytes": hex}`, XML as its datamap or `{"xml": text}`.
fn payload_of(payload: &Payload) -> DataMap {
    let data: &[u8] = match payload {
        Payload::Map(m) => return (**m).clone(),
        Payload::Xml(x) => {
            return match payload.to_map() {
                Ok(m) => (*m).clone(),
                Err(_) => DataMap::new().with("xml", &**x),
            };
        }
        Payload::Bytes(b) => b,
    };
    if data.starts_with(&binary::MAGIC)
        && let Ok(m) = binary::decode(data)
    {
        return m;
    }
    DataMap::new().with(
        "bytes",
        data.iter().map(|b| format!("{b:02x}")).collect::<String>(),
    )
}

/// The `--format csv` output: one file per topic.
struct CsvFiles {
    dir: PathBuf,
    files: BTreeMap<String, (std::io::BufWriter<std::fs::File>, Vec<String>)>,
}

impl CsvFiles {
    fn row(&mut self, topic: &str, time: f64, map: &DataMap) -> std::io::Result<()> {
        if !self.files.contains_key(topic) {
            let columns: Vec<String> = map.iter().map(|(k, _)| k.to_string()).collect();
            // (an LCM channel may hold a `/`: the file stays in the folder all the same)
            let name = topic.replace(['/', '\\'], "_");
            let mut out = std::io::BufWriter::new(std::fs::File::create(
                self.dir.join(format!("{name}.csv")),
            )?);
            writeln!(out, "time,{}", columns.join(","))?;
            self.files.insert(topic.to_string(), (out, columns));
        }
        let Some((out, columns)) = self.files.get_mut(topic) else {
            return Ok(());
        };
        let mut row = format!("{time:.6}");
        for c in columns.iter() {
            row.push(',');
            if let Some(v) = map.get(c) {
                row.push_str(&seabus_medium::csv::cell(v));
            }
        }
        writeln!(out, "{row}")
    }
}

/// The exit for output that cannot be written: a reader that stopped reading (`seabus export |
/// head`) ends the export quietly, as with any command-line filter; anything else is an error.
fn write_failed(e: &std::io::Error) -> ExitCode {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        return ExitCode::SUCCESS;
    }
    eprintln!("seabus export: cannot write: {e}");
    ExitCode::from(1)
}

/// Runs `seabus export`.
pub fn export(args: ExportArgs) -> ExitCode {
    let usage = |what: String| {
        eprintln!("seabus export: {what}");
        ExitCode::from(2)
    };
    let time = |t: &Option<String>, which: &str| -> Result<Option<f64>, String> {
        t.as_deref()
            .map(|s| {
                parse_time(s).ok_or_else(|| {
                    format!("--{which} `{s}`: expected seconds since 1970 or an RFC 3339 time")
                })
            })
            .transpose()
    };
    let (from, to) = match (time(&args.from, "from"), time(&args.to, "to")) {
        (Ok(f), Ok(t)) => (f, t),
        (Err(e), _) | (_, Err(e)) => return usage(e),
    };
    let pattern = match Pattern::new(&args.topics) {
        Ok(p) => p,
        Err(e) => return usage(format!("--topics `{}`: {e}", args.topics)),
    };
    let mut csv = match args.format.as_str() {
        "json" => None,
        "csv" => {
            let Some(dir) = &args.out else {
                return usage("--format csv needs --out DIR".into());
            };
            if let Err(e) = std::fs::create_dir_all(dir) {
                return usage(format!("{}: {e}", dir.display()));
            }
            Some(CsvFiles {
                dir: dir.clone(),
                files: BTreeMap::new(),
            })
        }
        f => return usage(format!("--format `{f}`: expected json or csv")),
    };
    let mut json_out: Box<dyn Write> = match (&csv, &args.out) {
        (None, Some(path)) => match std::fs::File::create(path) {
            Ok(f) => Box::new(std::io::BufWriter::new(f)),
            Err(e) => return usage(format!("{}: {e}", path.display())),
        },
        _ => Box::new(std::io::BufWriter::new(std::io::stdout().lock())),
    };
    let mut damaged = false;
    let mut exported = 0u64;
    for path in &args.logs {
        let list = match files(path) {
            Ok(l) => l,
            Err(e) => return usage(e),
        };
        for file in list {
            let mut reader = match Reader::open(&file) {
                Ok(r) => r,
                Err(e) => return usage(format!("{}: {e}", file.display())),
            };
            loop {
                let event = match reader.next_event() {
                    Ok(Some(e)) => e,
                    Ok(None) => break,
                    Err(d) => {
                        eprintln!("seabus export: {}: {d}", file.display());
                        damaged = true;
                        break;
                    }
                };
                let t = event.micros as f64 / 1e6;
                if from.is_some_and(|f| t < f) || to.is_some_and(|e| t >= e) {
                    continue;
                }
                // every channel as it was logged, a name that is not a seabus topic too
                let Ok(topic) = Topic::channel(&event.channel) else {
                    continue;
                };
                if !pattern.matches(&topic) {
                    continue;
                }
                let map = payload_of(&event.payload);
                let written = match &mut csv {
                    Some(c) => c.row(&event.channel, t, &map),
                    None => {
                        let line = DataMap::new()
                            .with("time", t)
                            .with("topic", event.channel.as_str())
                            .with("payload", Value::Map(map));
                        match json::to_json(&line) {
                            Ok(j) => writeln!(json_out, "{j}"),
                            Err(_) => Ok(()),
                        }
                    }
                };
                if let Err(e) = written {
                    return write_failed(&e);
                }
                exported += 1;
            }
        }
    }
    let flushed = json_out.flush().and_then(|()| {
        csv.iter_mut()
            .flat_map(|c| c.files.values_mut())
            .try_for_each(|(f, _)| f.flush())
    });
    if let Err(e) = flushed {
        return write_failed(&e);
    }
    eprintln!("seabus export: {exported} events");
    if damaged {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}
