//! `logger`: the central data logger. Sensors' clocks disagree; the logger stamps everything with
//! seabus's own clock, in one place.
//!
//! ```xml
//! <module name="logger" type="logger" medium="bus" dir="logs" topics="nav.**, cmd.**"/>
//! ```
//!
//! It keeps, in `dir` (relative to the system file, made if missing):
//!
//! - one complete binary log of every message: with `format="lcm"` (the default)
//!   `seabus-<start>.lcmlog`, an LCM event log (timestamp = the message's seabus stamp in µs;
//!   channel = topic; data = the payload, datamaps in seabus's binary form); with `format="mcap"`
//!   `seabus-<start>.mcap`, an MCAP file (a channel per topic with its JSON Schema, datamaps as
//!   JSON, log time = the message's seabus stamp; see `seabus-record`), which Foxglove, Lichtblick,
//!   PlotJuggler and Python's `mcap` open — `seabus export` and `seabus replay` read both;
//! - one CSV per topic, `<topic>.csv`: a `time` column (the seabus stamp, seconds) and one column
//!   per field of the topic's first message; later fields the header lacks are in the binary log
//!   only (counted). Nested values are written as JSON.
//!
//! Files are flushed every second, so a crash loses at most the last second (an MCAP file closes
//! its chunk under way each second: cut short, it reads up to there). When a file passes
//! `max_size` (bytes, default 100 MB), or the binary log is older than `max_age` (`30min`, `2h`;
//! default none), it is closed and a new one begun: the binary log under a new start time (an MCAP
//! file finished with its summary and indexes), a CSV as `<topic>.<n>.csv`. Parameters: `dir`
//! (required), `format` (`lcm` or `mcap`), `topics` (patterns, comma-separated; default everything
//! but `seabus.*` reports), `max_size`, `max_age`, `csv` (default true).

use async_trait::async_trait;
use seabus_medium::csv::cell;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Stamp, Topic, Value};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use seabus_record::log::{Kind as LogKind, WriteError, Writer};
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// The `logger` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "logger",
    kind: ModuleKind::Service,
    summary: "central data logger: one binary log and a CSV per topic, stamped by seabus",
    build,
};

const FLUSH: TimerId = 1;
/// How often files are flushed: what a crash can lose.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

struct Csv {
    out: BufWriter<File>,
    columns: Vec<String>,
    bytes: u64,
    part: u32,
}

/// The binary log being written.
struct Binary {
    writer: Writer,
    path: PathBuf,
    /// Its size at the last flush.
    size: u64,
    opened: tokio::time::Instant,
}

struct Logger {
    dir: PathBuf,
    format: LogKind,
    catalogue: Arc<Catalogue>,
    max_size: u64,
    max_age: Option<Duration>,
    csv: bool,
    binary: Option<Binary>,
    csvs: HashMap<Topic, Csv>,
    tally: Tally,
}

fn build(cfg: &ModuleConfig, catalogue: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let format = match p.get("format") {
        None => LogKind::Lcm,
        Some(a) => LogKind::parse(&a.value)
            .ok_or_else(|| a.error(format!("`{}` is not lcm or mcap", a.value)))?,
    };
    let Some(dir) = p.get("dir") else {
        return Err(cfg
            .pos
            .error("a logger needs `dir`, the directory of its files"));
    };
    let mut decl = Declaration::new(ModuleKind::Service);
    match p.str("topics") {
        None => decl = decl.consumes(TopicDecl::topic("**")),
        Some(list) => {
            for t in list.split(',').map(str::trim).filter(|t| !t.is_empty()) {
                seabus_medium::Pattern::new(t).map_err(|e| {
                    p.get("topics").map_or_else(
                        || cfg.pos.error(e.to_string()),
                        |a| a.error(format!("`{t}`: {e}")),
                    )
                })?;
                decl = decl.consumes(TopicDecl::topic(t));
            }
        }
    }
    Ok(Built {
        decl,
        module: Box::new(Logger {
            dir: seabus_modules::system::beside(&cfg.pos, &dir.value),
            format,
            catalogue: Arc::new(catalogue.clone()),
            max_age: match p.get("max_age") {
                None => None,
                Some(_) => Some(p.duration_or("max_age", Duration::ZERO)?),
            },
            max_size: p
                .parse("max_size", "a size in bytes")?
                .unwrap_or(100_000_000),
            csv: p.flag_or("csv", true)?,
            binary: None,
            csvs: HashMap::new(),
            tally: Tally::new(),
        }),
    })
}

impl Logger {
    fn open_binary(&mut self, stamp: Stamp) -> std::io::Result<()> {
        let when = std::time::UNIX_EPOCH + Duration::from_secs_f64(stamp.as_secs_f64().max(0.0));
        let name = format!(
            "seabus-{}.{}",
            humantime::format_rfc3339_millis(when)
                .to_string()
                .replace(':', "-"),
            match self.format {
                LogKind::Lcm => "lcmlog",
                LogKind::Mcap => "mcap",
            }
        );
        let path = self.dir.join(name);
        let writer = Writer::create(&path, self.format, true, self.catalogue.clone())?;
        self.binary = Some(Binary {
            writer,
            path,
            size: 0,
            opened: tokio::time::Instant::now(),
        });
        Ok(())
    }

    /// Whether the binary log is due to be closed and a new one begun.
    fn binary_full(&self) -> bool {
        self.binary.as_ref().is_none_or(|b| {
            b.size > self.max_size || self.max_age.is_some_and(|age| b.opened.elapsed() >= age)
        })
    }

    fn csv_path(&self, topic: &Topic, part: u32) -> PathBuf {
        if part == 0 {
            self.dir.join(format!("{topic}.csv"))
        } else {
            self.dir.join(format!("{topic}.{part}.csv"))
        }
    }

    fn new_csv(&self, topic: &Topic, map: &DataMap, part: u32) -> std::io::Result<Csv> {
        let columns: Vec<String> = map.iter().map(|(k, _)| k.to_string()).collect();
        let mut out = BufWriter::new(File::create(self.csv_path(topic, part))?);
        let header = std::iter::once("time".to_string())
            .chain(columns.iter().map(|c| cell(&Value::from(c.as_str()))))
            .collect::<Vec<_>>()
            .join(",");
        writeln!(out, "{header}")?;
        Ok(Csv {
            out,
            columns,
            bytes: header.len() as u64 + 1,
            part,
        })
    }

    fn write_csv(&mut self, msg: &Message) -> std::io::Result<()> {
        let Some(map) = msg.payload.as_map() else {
            return Ok(());
        };
        if !self.csvs.contains_key(&msg.topic) {
            let csv = self.new_csv(&msg.topic, map, 0)?;
            self.csvs.insert(msg.topic.clone(), csv);
        }
        if self
            .csvs
            .get(&msg.topic)
            .is_some_and(|c| c.bytes > self.max_size)
        {
            let part = self.csvs.get(&msg.topic).map_or(0, |c| c.part) + 1;
            let csv = self.new_csv(&msg.topic, map, part)?;
            if let Some(mut old) = self.csvs.insert(msg.topic.clone(), csv) {
                old.out.flush()?;
            }
        }
        let Some(csv) = self.csvs.get_mut(&msg.topic) else {
            return Ok(());
        };
        let mut row = format!("{:.6}", msg.stamp.as_secs_f64());
        for c in &csv.columns {
            row.push(',');
            if let Some(v) = map.get(c) {
                row.push_str(&cell(v));
            }
        }
        if map.iter().any(|(k, _)| !csv.columns.iter().any(|c| c == k)) {
            self.tally.record(
                "logger",
                "csv-new-field",
                format_args!(
                    "`{}` has fields its CSV header lacks (kept in the binary log)",
                    msg.topic
                ),
            );
        }
        writeln!(csv.out, "{row}")?;
        csv.bytes += row.len() as u64 + 1;
        Ok(())
    }

    fn take(&mut self, msg: &Message) -> std::io::Result<()> {
        if msg.topic.starts_with("seabus.") {
            return Ok(());
        }
        if self.binary_full() {
            if let Some(b) = self.binary.take() {
                b.writer.finish()?;
            }
            std::fs::create_dir_all(&self.dir)?;
            self.open_binary(msg.stamp)?;
        }
        if let Some(b) = &mut self.binary {
            match b.writer.write(msg, msg.stamp) {
                Ok(()) => {}
                Err(WriteError::File(e)) => return Err(std::io::Error::other(e)),
                Err(WriteError::Unwritable(e)) => {
                    self.tally
                        .record("logger", "unwritable", format_args!("{e}"));
                }
            }
        }
        if self.csv {
            self.write_csv(msg)?;
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(b) = &mut self.binary {
            b.writer.flush()?;
            b.size = std::fs::metadata(&b.path)?.len();
        }
        for c in self.csvs.values_mut() {
            c.out.flush()?;
        }
        Ok(())
    }
}

#[async_trait]
impl Module for Logger {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        std::fs::create_dir_all(&self.dir)
            .map_err(|e| ModuleError::msg(format!("cannot make {}: {e}", self.dir.display())))?;
        ctx.every(FLUSH, FLUSH_EVERY);
        Ok(())
    }

    async fn on_message(
        &mut self,
        _ctx: &mut Context,
        _port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        self.take(&msg)
            .map_err(|e| ModuleError::msg(format!("cannot write in {}: {e}", self.dir.display())))
    }

    async fn on_timer(&mut self, _ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        self.flush()
            .map_err(|e| ModuleError::msg(format!("cannot write in {}: {e}", self.dir.display())))
    }

    async fn stop(&mut self, _ctx: &mut Context) {
        let finished = self
            .flush()
            .and_then(|()| self.binary.take().map_or(Ok(()), |b| b.writer.finish()));
        if let Err(e) = finished {
            tracing::error!("logger: {}: {e}", self.dir.display());
        }
    }
}
