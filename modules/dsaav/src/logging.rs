//! The DSAAV logging service: one chronological central log for every component, with five levels
//! and size-based rotation.
//!
//! A component's [`Logger`] sends records to the logging server by RPC — reliably, except DATA
//! records (sensor data in volume), which go unreliably so that logging never becomes a
//! bottleneck. Each component logs at the level its configuration gives it (`LogLevel` in the
//! `[Logging]` section, overridden by `Logging.LogLevel` in its own section), changeable at run
//! time. The server writes one line per record to its file —
//! `2026-11-21T09:15:02.125Z INFO  MyDepthController  text` — and when the file passes its size
//! limit it is renamed `NAME.1` (older ones shifted up to the number kept) and a new one begun.

use super::config::Database;
use super::health::ComponentState;
use super::health_service::{health_reply, ops::HEALTH};
use super::rpc::{self, CallOptions, RpcClient, RpcError};
use seabus_medium::{DataMap, Medium};
use seabus_medium_dsaav::wire::Address;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::fmt;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use tokio::sync::watch;

/// The logging service's operation: one record.
pub const LOG_OP: i32 = 300;

/// How much a record matters; a component logs records at or above its level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Level {
    /// Critical or unrecoverable errors.
    Error = 0,
    /// Problems the component carries on through.
    Warning = 1,
    /// Versions, state changes, major events.
    Info = 2,
    /// Sensor data, sent unreliably.
    Data = 3,
    /// Debugging, enabled for troubleshooting.
    Debug = 4,
}

impl Level {
    /// Every level, most important first.
    pub const ALL: [Level; 5] = [
        Level::Error,
        Level::Warning,
        Level::Info,
        Level::Data,
        Level::Debug,
    ];

    /// The name used in configuration files (`LOG_INFO`).
    pub fn config_name(self) -> &'static str {
        match self {
            Level::Error => "LOG_ERROR",
            Level::Warning => "LOG_WARNING",
            Level::Info => "LOG_INFO",
            Level::Data => "LOG_DATA",
            Level::Debug => "LOG_DEBUG",
        }
    }

    /// Reads `LOG_INFO` (or `INFO`, any case).
    pub fn parse(text: &str) -> Option<Level> {
        let t = text.trim().to_ascii_uppercase();
        let t = t.strip_prefix("LOG_").unwrap_or(&t);
        Level::ALL
            .into_iter()
            .find(|l| l.config_name().strip_prefix("LOG_") == Some(t))
    }

    fn from_number(n: i64) -> Option<Level> {
        Level::ALL.into_iter().find(|l| *l as i64 == n)
    }
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.config_name().trim_start_matches("LOG_"))
    }
}

/// The central log file, rotated by size.
pub struct LogFile {
    path: PathBuf,
    file: File,
    size: u64,
    limit: u64,
    keep: u32,
}

impl LogFile {
    /// Opens (appending to) `path`, rotating when it passes `limit` bytes and keeping `keep` old
    /// files.
    pub fn open(path: PathBuf, limit: u64, keep: u32) -> io::Result<LogFile> {
        let file = OpenOptions::new().create(true).append(true).open(&path)?;
        let size = file.metadata()?.len();
        Ok(LogFile {
            path,
            file,
            size,
            limit: limit.max(1),
            keep,
        })
    }

    fn numbered(&self, n: u32) -> PathBuf {
        let mut p = self.path.clone().into_os_string();
        p.push(format!(".{n}"));
        PathBuf::from(p)
    }

    fn rotate(&mut self) -> io::Result<()> {
        self.file.flush()?;
        if self.keep == 0 {
            self.file = File::create(&self.path)?;
        } else {
            for n in (1..self.keep).rev() {
                let from = self.numbered(n);
                if from.exists() {
                    std::fs::rename(&from, self.numbered(n + 1))?;
                }
            }
            std::fs::rename(&self.path, self.numbered(1))?;
            self.file = OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)?;
        }
        self.size = 0;
        Ok(())
    }

    /// Appends one record's line, rotating first when the file is full.
    pub fn write(&mut self, line: &str) -> io::Result<()> {
        if self.size > 0 && self.size + line.len() as u64 + 1 > self.limit {
            self.rotate()?;
        }
        self.file.write_all(line.as_bytes())?;
        self.file.write_all(b"\n")?;
        self.size += line.len() as u64 + 1;
        Ok(())
    }
}

/// A record's line in the central log.
pub fn format_line(time_s: f64, level: Level, component: &str, text: &str) -> String {
    let clean = |s: &str| s.replace(['\n', '\r'], " ");
    let when =
        std::time::UNIX_EPOCH + std::time::Duration::try_from_secs_f64(time_s).unwrap_or_default();
    format!(
        "{} {:<7} {:<18} {}",
        humantime::format_rfc3339_millis(when),
        level.to_string(),
        clean(component),
        clean(text)
    )
}

/// How long the server holds a record before writing it, so that records from components whose
/// calls arrive a little late still go into the log in time order.
pub const HOLD: std::time::Duration = std::time::Duration::from_millis(500);

/// Records held for their turn, in time order, and the log they go to.
struct Ordered {
    log: LogFile,
    /// (time, arrival number, line), earliest first.
    held: BinaryHeap<Reverse<(TimeKey, u64, String)>>,
    arrivals: u64,
    /// Write failures so far.
    failures: u64,
    /// Keeps the failures' log lines to one per window.
    failure_log: seabus_medium::tally::Limiter,
    /// Whether the last write failed.
    failing: bool,
    /// How long records are held, in seconds: [`HOLD`], or nothing once the server drains.
    hold: f64,
}

/// A record's time as an ordered key (seconds since 1970, never NaN).
#[derive(Debug, Clone, Copy)]
struct TimeKey(f64);

impl PartialEq for TimeKey {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other).is_eq()
    }
}

impl Eq for TimeKey {}

impl PartialOrd for TimeKey {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for TimeKey {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

impl Ordered {
    /// Writes every held record made before `until` (all of them for `None`).
    fn write_due(&mut self, until: Option<f64>) -> io::Result<()> {
        while let Some(Reverse((t, _, _))) = self.held.peek() {
            if until.is_some_and(|u| t.0 > u) {
                break;
            }
            let Some(Reverse((_, _, line))) = self.held.pop() else {
                break;
            };
            self.log.write(&line)?;
        }
        Ok(())
    }

    /// Writes the records due now.
    fn flush_due(&mut self) -> io::Result<()> {
        let until = seabus_medium::Stamp::now().as_secs_f64() - self.hold;
        self.write_due(Some(until))
    }

    /// Writes the records due now, reporting a failure.
    fn flush_or_report(&mut self) {
        let written = self.flush_due();
        self.failing = written.is_err();
        if let Err(e) = written {
            self.failures += 1;
            let n = self.failures;
            if let Some(held) = self.failure_log.admit(std::time::Instant::now()) {
                tracing::error!("cannot write the central log ({n} so far): {e}{held}");
            }
        }
    }
}

/// Serves the logging operation on `port`, writing every record to `log` in time order (each is
/// held for [`HOLD`]), until the medium closes; then the records still held are written. Once
/// `drain` turns true (the system is stopping) nothing more is held: what is held is written, and
/// what arrives after is written at once. Records that cannot be written are refused to reliable
/// callers with status 6.
pub async fn serve(medium: &Medium, port: u16, log: LogFile, mut drain: watch::Receiver<bool>) {
    let ordered = Arc::new(Mutex::new(Ordered {
        log,
        held: BinaryHeap::new(),
        arrivals: 0,
        failures: 0,
        failure_log: Default::default(),
        failing: false,
        hold: HOLD.as_secs_f64(),
    }));
    let writer = {
        let ordered = ordered.clone();
        tokio::spawn(async move {
            let mut every = tokio::time::interval(HOLD / 5);
            // a sender gone means nobody will ask to drain: hold as usual
            let mut watching = true;
            loop {
                tokio::select! {
                    _ = every.tick() => {}
                    r = drain.changed(), if watching => watching = r.is_ok(),
                }
                let draining = *drain.borrow();
                let mut o = ordered.lock().unwrap_or_else(|p| p.into_inner());
                if draining {
                    o.hold = 0.0;
                }
                o.flush_or_report();
            }
        })
    };
    let handler_state = ordered.clone();
    rpc::serve(medium, port, &[], move |call| {
        match call.op {
            LOG_OP => {}
            HEALTH => {
                // a log it cannot write is a malfunction
                let o = handler_state.lock().unwrap_or_else(|p| p.into_inner());
                let state = if o.failing {
                    ComponentState::Malfunction
                } else {
                    ComponentState::Healthy
                };
                return Ok(health_reply(state, "Logging"));
            }
            op => return Err((3, format!("operation {op} is not a logging operation"))),
        }
        let p = &call.params;
        let level = p
            .get_i64("level")
            .and_then(Level::from_number)
            .ok_or((5, "a log record needs `level` 0–4".to_string()))?;
        let now = seabus_medium::Stamp::now().as_secs_f64();
        // a clock ahead of the server's cannot hold a record back
        let time = p.get_f64("time").filter(|t| t.is_finite()).unwrap_or(now);
        let component = p.get_str("component").unwrap_or("?");
        let text = p.get_str("text").unwrap_or("");
        let mut o = handler_state.lock().unwrap_or_else(|p| p.into_inner());
        o.arrivals += 1;
        let n = o.arrivals;
        o.held.push(Reverse((
            TimeKey(time.min(now)),
            n,
            format_line(time, level, component, text),
        )));
        let written = o.flush_due();
        o.failing = written.is_err();
        written
            .map(|()| DataMap::new())
            .map_err(|e| (6, format!("cannot write the log: {e}")))
    })
    .await;
    writer.abort();
    let mut o = ordered.lock().unwrap_or_else(|p| p.into_inner());
    if let Err(e) = o.write_due(None) {
        tracing::error!("cannot write the central log: {e}");
    }
}

/// A component's logger: its level, and the way to the logging server.
pub struct Logger {
    component: String,
    level: Level,
    server: Address,
    rpc: RpcClient,
    opts: CallOptions,
}

impl Logger {
    /// A logger for `component` on `port` of the medium's node, sending to the logging server
    /// and at the level the configuration gives (`Logging.LogLevel` of the component, else
    /// `LogLevel` of `[Logging]`, else INFO).
    pub fn new(
        medium: &Medium,
        port: u16,
        component: &str,
        cfg: &Database,
        opts: CallOptions,
    ) -> Result<Logger, String> {
        let server = cfg
            .server_of(component, "Logging")
            .map_err(|e| e.to_string())?;
        let level = match cfg.setting(component, "Logging", "LogLevel") {
            Ok(v) => Level::parse(v.as_str()).ok_or_else(|| {
                format!("{component}: LogLevel `{}` is not a log level", v.as_str())
            })?,
            Err(_) => Level::Info,
        };
        Ok(Logger::at(medium, port, component, server, level, opts))
    }

    fn at(
        medium: &Medium,
        port: u16,
        component: &str,
        server: Address,
        level: Level,
        opts: CallOptions,
    ) -> Logger {
        Logger {
            component: component.to_string(),
            level,
            server,
            rpc: RpcClient::new(medium, port),
            opts,
        }
    }

    /// A logger for `component` whose server and level come from the configuration service.
    pub async fn from_service(
        medium: &Medium,
        port: u16,
        component: &str,
        cfg: &super::config_service::ConfigClient,
        opts: CallOptions,
    ) -> Result<Logger, RpcError> {
        let server = cfg.server_of(component, "Logging").await?;
        let level = level_from_service(cfg, component).await;
        Ok(Logger::at(medium, port, component, server, level, opts))
    }

    /// The level records are logged at or above.
    pub fn level(&self) -> Level {
        self.level
    }

    /// Changes the level at run time.
    pub fn set_level(&mut self, level: Level) {
        self.level = level;
    }

    /// Logs `text` at `level` if the component's level lets it through: DATA unreliably, the
    /// others reliably. Returns whether it was sent.
    pub async fn log(&self, level: Level, text: &str) -> Result<bool, RpcError> {
        self.log_at(seabus_medium::Stamp::now().as_secs_f64(), level, text)
            .await
    }

    /// As [`Logger::log`], for a record made at `time` (seconds since 1970).
    pub async fn log_at(&self, time: f64, level: Level, text: &str) -> Result<bool, RpcError> {
        if level > self.level {
            return Ok(false);
        }
        let to = Recipient {
            rpc: &self.rpc,
            server: self.server,
            opts: self.opts,
        };
        to.send(&self.component, time, level, text).await?;
        Ok(true)
    }
}

/// The level the configuration service gives `component` (`Logging.LogLevel` in its section, else
/// `LogLevel` of `[Logging]`); INFO when it gives none or something that is not a level.
pub async fn level_from_service(
    cfg: &super::config_service::ConfigClient,
    component: &str,
) -> Level {
    match cfg.setting(component, "Logging", "LogLevel").await {
        Ok(v) => Level::parse(&v).unwrap_or(Level::Info),
        Err(_) => Level::Info,
    }
}

/// Where records go: a logging server, called through a client.
pub struct Recipient<'a> {
    /// The client the calls go through.
    pub rpc: &'a RpcClient,
    /// The logging server.
    pub server: Address,
    /// How reliable calls wait and retry.
    pub opts: CallOptions,
}

impl Recipient<'_> {
    /// Sends one record of `component`, made at `time`: DATA unreliably, the others reliably.
    pub async fn send(
        &self,
        component: &str,
        time: f64,
        level: Level,
        text: &str,
    ) -> Result<(), RpcError> {
        let record = DataMap::new()
            .with("level", level as i64)
            .with("component", component)
            .with("text", text)
            .with("time", time);
        if level == Level::Data {
            self.rpc
                .call_unreliable(self.server, LOG_OP, &record)
                .await?;
        } else {
            self.rpc
                .call(self.server, LOG_OP, &record, self.opts)
                .await?;
        }
        Ok(())
    }
}
