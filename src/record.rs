//! `seabus record` and `seabus replay`: the traffic of any medium to and from LCM event logs (the
//! files `lcm-logger` writes and `lcm-logplayer` plays) and MCAP files (what Foxglove, ROS 2 and
//! Python's `mcap` read).
//!
//! Recording to an LCM event log writes one event per message: the channel is the topic, the
//! timestamp is when `seabus record` received the message (microseconds since the Unix epoch, never
//! going back, as `lcm-logger` stamps events on arrival), and the data is the payload's bytes: a
//! byte payload as it is (on an LCM medium, the LCM message), a datamap in seabus's binary form,
//! XML as its text; a channel whose payloads are not bytes has its format said in a
//! [`FORMAT_CHANNEL`](seabus_record::log::FORMAT_CHANNEL) event. Kind (data or command) and
//! provenance are not kept: a log has no room for them.
//!
//! Recording to MCAP (a file named `.mcap`, or `--format mcap`) writes one channel per topic with
//! its JSON Schema, datamaps as JSON, log time = when it was received, publish time = the message's
//! stamp, and marks command channels ([`seabus_record`]). Every [`FLUSH_EVERY`] the chunk under way
//! is closed, so a recording cut short by a crash reads up to there.
//!
//! Replaying publishes each event as data — never as a command, whatever it was recorded as — the
//! channel as topic, paced by the log's timestamps: an LCM event's data in the format its log
//! says (bytes unless a format event says otherwise), an MCAP message by its encoding (JSON as a
//! datamap, other encodings as bytes).

use crate::sending::{self, NotSent, Sending, Unfinished};
use seabus_medium::ChannelRegex;
use seabus_medium::{Kind, Message, Node, Stamp, Topic};
use seabus_modules::Catalogue;
use seabus_record::log::{Damage, Kind as LogKind, Reader, WriteError, Writer};
use std::collections::{HashMap, HashSet};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;
use tokio::time::Instant;

/// How often a recording passes what it buffered on to the file.
const FLUSH_EVERY: Duration = Duration::from_millis(200);

/// `seabus record` exit code when the log could not be written.
const WRITE_FAILED: u8 = 1;

/// `seabus replay` exit code when the log is damaged: the events before the damage were replayed.
const DAMAGED: u8 = 1;

/// Exit code for arguments, a file or a medium that cannot be used.
const USAGE: u8 = 2;

/// `seabus replay` exit code when the medium refused some events.
const NOT_SENT: u8 = 3;

/// What `seabus record` was asked to do.
#[derive(clap::Args)]
pub struct RecordArgs {
    /// The medium, for example udp://239.255.42.1:47800.
    pub url: String,
    /// The log file to write: MCAP when it is named `.mcap`, else an LCM event log.
    pub file: PathBuf,
    /// `lcm` or `mcap`, whatever the file is named.
    #[arg(long, value_name = "FORMAT")]
    pub format: Option<String>,
    /// Stop after this many seconds.
    #[arg(long = "for", value_name = "SECS")]
    pub duration: Option<f64>,
    /// Only topics matching this seabus pattern.
    #[arg(long, default_value = "**")]
    pub topics: String,
    /// Only topics this regular expression matches whole (as LCM channels are matched).
    #[arg(long, value_name = "REGEX")]
    pub channels: Option<String>,
    /// Replace the file if it exists.
    #[arg(long)]
    pub force: bool,
}

fn compile_channels(cmd: &str, regex: Option<&str>) -> Result<Option<ChannelRegex>, ExitCode> {
    regex
        .map(|r| {
            ChannelRegex::new(r).map_err(|e| {
                eprintln!("seabus {cmd}: --channels {r}: {e}");
                ExitCode::from(USAGE)
            })
        })
        .transpose()
}

/// `n` and `word`, in the plural unless `n` is 1 (`1 event`, `3 events`).
fn count(n: impl Into<u64>, word: &str) -> String {
    crate::counted(n.into(), word, &format!("{word}s"))
}

/// Microseconds since the Unix epoch, now.
fn now_micros() -> i64 {
    Stamp::now().0 / 1000
}

/// Records the traffic on `args.url` to `args.file` until Ctrl-C, SIGTERM or `args.duration`.
pub async fn record(args: RecordArgs) -> ExitCode {
    let usage = |msg: String| {
        eprintln!("seabus record: {msg}");
        ExitCode::from(USAGE)
    };
    let duration = match crate::seconds(args.duration) {
        Ok(d) => d,
        Err(code) => return code,
    };
    let channels = match compile_channels("record", args.channels.as_deref()) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let kind = match args.format.as_deref() {
        None => LogKind::of_name(&args.file),
        Some(f) => match LogKind::parse(f) {
            Some(k) => k,
            None => return usage(format!("--format {f}: expected lcm or mcap")),
        },
    };
    let node = Node::new(&format!("record-{}", std::process::id()));
    let medium = match crate::media::schemes().open("record", &args.url, &node) {
        Ok(m) => m,
        Err(e) => return usage(e.to_string()),
    };
    let mut port = match medium
        .attach_with("record", 1 << 16, 1 << 10)
        .subscribed(&args.topics)
    {
        Ok(p) => p,
        Err(e) => return usage(format!("--topics: {e}")),
    };
    let file = args.file.display();
    let created = Writer::create(&args.file, kind, args.force, Catalogue::built_in());
    let writer = match created {
        Ok(w) => w,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            return usage(format!("{file}: the file exists (--force replaces it)"));
        }
        Err(e) => return usage(format!("{file}: cannot create: {e}")),
    };
    let deadline = duration.map(|d| Instant::now() + d);
    let mut flush = tokio::time::interval(FLUSH_EVERY);
    let mut unflushed = false;
    let mut log = Recording {
        writer,
        channels,
        seen: HashSet::new(),
        last_stamp: i64::MIN,
        unwritable: 0,
    };
    let mut failure = None;
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
            _ = flush.tick(), if unflushed => {
                if let Err(e) = log.writer.flush() {
                    failure = Some(e.to_string());
                    break;
                }
                unflushed = false;
            }
            m = port.recv() => {
                let Some(m) = m else { break };
                if let Err(e) = log.take(&m) {
                    failure = Some(e);
                    break;
                }
                unflushed = true;
            }
        }
    }
    if failure.is_none() {
        // what arrived before the stop is recorded too
        let pending = port.stats().pending;
        for _ in 0..pending {
            let Ok(m) = port.try_recv() else { break };
            if let Err(e) = log.take(&m) {
                failure = Some(e);
                break;
            }
        }
    }
    let events = log.writer.messages();
    let finished = log.writer.finish();
    if failure.is_none()
        && let Err(e) = finished
    {
        failure = Some(e.to_string());
    }
    let bytes = std::fs::metadata(&args.file).map_or(0, |m| m.len());
    eprintln!(
        "seabus record: {}, {}, {} in {file}",
        count(events, "event"),
        count(bytes, "byte"),
        count(log.seen.len() as u64, "channel")
    );
    let st = port.stats();
    if st.dropped_oldest > 0 || log.unwritable > 0 {
        eprintln!(
            "seabus record: {} messages dropped (the file was too slow), {} datamaps with no binary form",
            st.dropped_oldest, log.unwritable
        );
    }
    match failure {
        Some(e) => {
            eprintln!("seabus record: {file}: cannot write: {e}");
            ExitCode::from(WRITE_FAILED)
        }
        None => ExitCode::SUCCESS,
    }
}

/// A log being recorded.
struct Recording {
    writer: Writer,
    /// `--channels`.
    channels: Option<ChannelRegex>,
    /// The topics recorded.
    seen: HashSet<Topic>,
    /// The last event's timestamp.
    last_stamp: i64,
    /// Datamaps with no binary form, not recorded.
    unwritable: u64,
}

impl Recording {
    /// Writes `m`, unless `--channels` leaves it out.
    fn take(&mut self, m: &Message) -> Result<(), String> {
        if let Some(c) = &self.channels
            && !c.matches(&m.topic)
        {
            return Ok(());
        }
        // arrival time, never going back (a log player waits on the differences)
        self.last_stamp = now_micros().max(self.last_stamp);
        match self
            .writer
            .write(m, Stamp(self.last_stamp.saturating_mul(1000)))
        {
            Ok(()) => {}
            Err(WriteError::File(e)) => return Err(e),
            Err(WriteError::Unwritable(e)) => {
                self.unwritable += 1;
                tracing::warn!(topic = %m.topic, "not recorded: {e}");
                return Ok(());
            }
        }
        if !self.seen.contains(&m.topic) {
            self.seen.insert(m.topic.clone());
        }
        Ok(())
    }
}

/// What `seabus replay` was asked to do.
#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The log file: an LCM event log (seabus record, lcm-logger, any LCM event-log writer) or an
    /// MCAP file (seabus record, Foxglove, ROS 2, Python's mcap), told apart by its first bytes; or
    /// a folder, whose logs (its files that are either, whatever they are named) are replayed one
    /// after another in name order.
    pub file: PathBuf,
    /// The medium, for example udp://239.255.42.1:47800.
    pub url: String,
    /// Speed factor, 0.001 to 1e6: 2 plays twice as fast; max (or 0) sends as fast as possible.
    #[arg(
        long,
        default_value = "1",
        value_name = "X",
        allow_negative_numbers = true
    )]
    pub speed: String,
    /// Skip the events of the first SECS seconds of the log.
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "SECS",
        allow_negative_numbers = true
    )]
    pub from: f64,
    /// Only channels this regular expression matches whole.
    #[arg(long, value_name = "REGEX")]
    pub channels: Option<String>,
    /// Start again from the beginning at the end of the log, until Ctrl-C or SIGTERM.
    #[arg(long = "loop")]
    pub looping: bool,
    /// Seconds to wait for the medium's link to come up, or to come back when it is lost, and
    /// for what was sent to go out at the end.
    #[arg(long = "link-wait", value_name = "SECS", default_value_t = 5.0)]
    pub link_wait: f64,
    /// .lcm files or directories with the LCM types (besides the built-in ones) of an MCAP
    /// file's messages that were decoded from LCM: replayed onto LCM, they are encoded with their
    /// type again.
    #[arg(long = "lcm-types", value_name = "PATH")]
    pub lcm_types: Vec<PathBuf>,
}

/// Slowest `--speed`.
const MIN_SPEED: f64 = 1e-3;
/// Fastest `--speed` other than `max`.
const MAX_SPEED: f64 = 1e6;

/// Reads `--speed`: `None` for as fast as possible (`max` or `0`), else the factor.
fn parse_speed(text: &str) -> Option<Option<f64>> {
    match text {
        "max" => Some(None),
        _ => match text.parse::<f64>() {
            Ok(0.0) => Some(None),
            Ok(x) if (MIN_SPEED..=MAX_SPEED).contains(&x) => Some(Some(x)),
            _ => None,
        },
    }
}

/// When the event logged at `timestamp` is due, pacing from the event logged at `log0` sent at
/// `clock0`, at `speed`; `None` when that is beyond any clock (it never is).
fn due(clock0: Instant, log0: i64, timestamp: i64, speed: f64) -> Option<Instant> {
    let after = timestamp.saturating_sub(log0).max(0) as f64 / 1e6 / speed;
    clock0.checked_add(Duration::try_from_secs_f64(after).ok()?)
}

/// One channel of the log, as replay sees it.
struct Channel {
    /// Whether `--channels` lets it through.
    allowed: bool,
    /// The topic: the channel when it is a seabus topic, or when the medium takes channel names
    /// that are not (LCM), the channel as it is.
    topic: Option<Topic>,
    /// Events sent.
    sent: u64,
}

/// Counts shown in the summary.
#[derive(Default)]
struct Tally {
    sent: u64,
    /// Events on channels that are not seabus topics.
    invalid: u64,
    /// Events on channels `--channels` leaves out.
    filtered: u64,
    /// Events before `--from`.
    early: u64,
    /// Events the medium refused, and the first reason.
    failed: u64,
    first_failure: Option<String>,
    passes: u64,
}

/// How one pass over the log ended.
enum PassEnd {
    /// The end of the log.
    Done,
    /// Ctrl-C or SIGTERM.
    Stopped,
    /// A log is damaged.
    Damaged(PathBuf, Damage),
    /// A log could not be opened.
    Unreadable(PathBuf, std::io::Error),
    /// The medium was closed.
    Closed,
    /// The link did not come up or back within the wait: why.
    LinkLost(String),
}

/// Where pacing counts from in a pass: its first event's log time, the log time and clock time of
/// the event pacing started again from, and the last event's log time.
struct Pacing {
    first: Option<i64>,
    base: Option<(i64, Instant)>,
    previous: i64,
}

/// Replays a log: options checked, pacing and counts kept across passes.
struct Replay<'a> {
    /// What was given: a log or a folder.
    file: &'a Path,
    /// The logs, in the order they are replayed.
    logs: Vec<PathBuf>,
    /// Whether the medium takes channel names that are not seabus topics (LCM).
    names_channels: bool,
    /// The LCM types that encode, onto such a medium, an MCAP message decoded from one.
    types: crate::lcmtypes::Types,
    sending: Sending,
    speed: Option<f64>,
    from_micros: i64,
    filter: Option<ChannelRegex>,
    channels: HashMap<Box<str>, Channel>,
    tally: Tally,
    bar: indicatif::ProgressBar,
}

impl Replay<'_> {
    /// The channel's entry, made on first sight.
    fn channel(&mut self, name: &str) -> &mut Channel {
        if !self.channels.contains_key(name) {
            let channel = Channel {
                allowed: self.filter.as_ref().is_none_or(|f| f.matches(name)),
                topic: if self.names_channels {
                    Topic::channel(name).ok()
                } else {
                    Topic::new(name).ok()
                },
                sent: 0,
            };
            self.channels.insert(name.into(), channel);
        }
        // inserted above when missing
        self.channels
            .get_mut(name)
            .unwrap_or_else(|| unreachable!("channel {name} was just inserted"))
    }

    /// One pass over the logs: one after another, paced as one.
    async fn pass(&mut self, stop: &mut (impl Future<Output = ()> + Unpin)) -> PassEnd {
        self.tally.passes += 1;
        let mut pacing = Pacing {
            first: None,
            base: None,
            previous: i64::MIN,
        };
        for log in self.logs.clone() {
            match self.pass_one(&log, &mut pacing, stop).await {
                PassEnd::Done => {}
                end => return end,
            }
        }
        PassEnd::Done
    }

    /// One log of a pass.
    async fn pass_one(
        &mut self,
        log: &Path,
        pacing: &mut Pacing,
        stop: &mut (impl Future<Output = ()> + Unpin),
    ) -> PassEnd {
        let mut reader = match Reader::open(log) {
            Ok(r) => r,
            Err(e) => return PassEnd::Unreadable(log.to_path_buf(), e),
        };
        self.bar.set_length(reader.size().unwrap_or(0));
        self.bar.set_position(0);
        let Pacing {
            first,
            base,
            previous,
        } = pacing;
        let mut shown = Instant::now();
        loop {
            let (timestamp, topic, payload) = {
                let event = match reader.next_event() {
                    Ok(Some(e)) => e,
                    Ok(None) => return PassEnd::Done,
                    Err(d) => return PassEnd::Damaged(log.to_path_buf(), d),
                };
                let start = *first.get_or_insert(event.micros);
                if event.micros < start.saturating_add(self.from_micros) {
                    self.tally.early += 1;
                    continue;
                }
                let channel = self.channel(&event.channel);
                if !channel.allowed {
                    self.tally.filtered += 1;
                    continue;
                }
                let Some(topic) = channel.topic.clone() else {
                    self.tally.invalid += 1;
                    continue;
                };
                channel.sent += 1;
                let payload = match (&event.lcm_type, event.payload.as_map()) {
                    // an MCAP message decoded from LCM goes onto LCM as LCM
                    (Some(name), Some(map)) if self.names_channels => {
                        match self.types.encode(name, map) {
                            Ok(bytes) => bytes,
                            Err(e) => {
                                self.tally.failed += 1;
                                if self.tally.first_failure.is_none() {
                                    self.tally.first_failure = Some(format!("`{topic}`: {e}"));
                                }
                                continue;
                            }
                        }
                    }
                    _ => event.payload,
                };
                (event.micros, topic, payload)
            };
            if let Some(speed) = self.speed {
                // a timestamp going back starts the pacing again from this event
                let (log0, clock0) = match base {
                    Some(b) if timestamp >= *previous => *b,
                    _ => *base.insert((timestamp, Instant::now())),
                };
                *previous = timestamp;
                match due(clock0, log0, timestamp, speed) {
                    Some(at) if at <= Instant::now() => {}
                    // waiting beyond any clock: until stopped
                    None => {
                        stop.await;
                        return PassEnd::Stopped;
                    }
                    Some(at) => {
                        tokio::select! {
                            _ = &mut *stop => return PassEnd::Stopped,
                            _ = tokio::time::sleep_until(at) => {}
                        }
                    }
                }
            } else if futures_ready(stop) {
                return PassEnd::Stopped;
            }
            match self.sending.send(Kind::Data, &topic, payload).await {
                Ok(resumed) => {
                    self.tally.sent += 1;
                    if resumed {
                        // the link came back: pacing counts again from this event
                        *base = Some((timestamp, Instant::now()));
                    }
                }
                Err(NotSent::Closed) => return PassEnd::Closed,
                Err(NotSent::LinkLost(why)) => return PassEnd::LinkLost(why),
                Err(NotSent::Refused(e)) => {
                    self.tally.failed += 1;
                    if self.tally.first_failure.is_none() {
                        self.tally.first_failure = Some(format!("the medium refused: {e}"));
                    }
                }
            }
            self.bar.set_position(reader.offset());
            if shown.elapsed() >= Duration::from_millis(100) {
                shown = Instant::now();
                self.bar.set_message(format!("{} sent", self.tally.sent));
            }
        }
    }

    /// The one-line summary.
    fn summary(&self, elapsed: Duration) -> String {
        let t = &self.tally;
        let sent_on = self.channels.values().filter(|c| c.sent > 0).count();
        let mut line = format!(
            "seabus replay: {}: {} sent on {} in {:.1} s",
            self.file.display(),
            count(t.sent, "event"),
            count(sent_on as u64, "channel"),
            elapsed.as_secs_f64()
        );
        if t.passes > 1 {
            line += &format!(" ({} passes)", t.passes);
        }
        if t.invalid > 0 {
            let mut names: Vec<&str> = self
                .channels
                .iter()
                .filter(|(_, c)| c.allowed && c.topic.is_none())
                .map(|(name, _)| &**name)
                .collect();
            names.sort_unstable();
            let shown: Vec<String> = names.iter().take(3).map(|n| format!("{n:?}")).collect();
            let more = if names.len() > 3 { ", …" } else { "" };
            line += &format!(
                "; {} skipped on {} ({}{more})",
                t.invalid,
                match names.len() {
                    1 => "1 channel that is not a seabus topic".to_string(),
                    n => format!("{n} channels that are not seabus topics"),
                },
                shown.join(", ")
            );
        }
        if t.filtered > 0 {
            line += &format!("; {} left out by --channels", t.filtered);
        }
        if t.early > 0 {
            line += &format!("; {} before --from", t.early);
        }
        if let Some(e) = &t.first_failure {
            line += &format!("; {} not sent ({e})", t.failed);
        }
        line
    }
}

/// True when `stop` has completed (polled once, without waiting).
fn futures_ready(stop: &mut (impl Future<Output = ()> + Unpin)) -> bool {
    let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
    std::pin::Pin::new(stop).poll(&mut cx).is_ready()
}

/// Replays `args.file` on `args.url`.
pub async fn replay(args: ReplayArgs) -> ExitCode {
    let usage = |msg: String| {
        eprintln!("seabus replay: {msg}");
        ExitCode::from(USAGE)
    };
    let Some(speed) = parse_speed(&args.speed) else {
        return usage(format!(
            "--speed {}: expected a factor from {MIN_SPEED} to {MAX_SPEED:e}, or max (or 0) for as \
             fast as possible",
            args.speed
        ));
    };
    let Some(from) = seabus_medium::parse::secs(args.from) else {
        return usage(format!(
            "--from {}: expected a number of seconds from 0 to 1e9",
            args.from
        ));
    };
    let Some(link_wait) = sending::link_wait(args.link_wait) else {
        return usage(format!(
            "--link-wait {}: expected a number of seconds from 0 to 1e9",
            args.link_wait
        ));
    };
    let filter = match compile_channels("replay", args.channels.as_deref()) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let types = match crate::lcmtypes::load(&args.lcm_types) {
        Ok(t) => t,
        Err(e) => return usage(e),
    };
    // the logs must be there before anything is sent
    let logs = if args.file.is_dir() {
        match seabus_record::log::logs_in(&args.file) {
            Err(e) => return usage(format!("{}: {e}", args.file.display())),
            Ok((logs, skipped)) => {
                for (file, why) in &skipped {
                    eprintln!("seabus replay: skipped {}: {why}", file.display());
                }
                if logs.is_empty() {
                    return usage(format!(
                        "{}: no LCM event log or MCAP file in this folder",
                        args.file.display()
                    ));
                }
                logs
            }
        }
    } else {
        if let Err(e) = std::fs::File::open(&args.file) {
            return usage(format!("{}: cannot open: {e}", args.file.display()));
        }
        vec![args.file.clone()]
    };
    let node = Node::new(&format!("replay-{}", std::process::id()));
    let medium = match crate::media::schemes().open("replay", &args.url, &node) {
        Ok(m) => m,
        Err(e) => return usage(e.to_string()),
    };
    let names_channels = medium.capabilities().names_channels();
    // nothing is sent before the link is up (a MOOSDB's takes a moment)
    let sending = match Sending::open("seabus replay", medium, link_wait).await {
        Ok(s) => s,
        Err(e) => return crate::not_sent("seabus replay", e),
    };
    let bar = if std::io::stderr().is_terminal() {
        let bar = indicatif::ProgressBar::new(0);
        let style = indicatif::ProgressStyle::with_template(
            "{elapsed:>4} [{bar:30}] {bytes}/{total_bytes} {msg}",
        )
        .map(|s| s.progress_chars("=> "));
        if let Ok(style) = style {
            bar.set_style(style);
        }
        bar
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut replay = Replay {
        file: &args.file,
        logs,
        names_channels,
        types,
        sending,
        speed,
        from_micros: from.as_micros().min(i64::MAX as u128) as i64,
        filter,
        channels: HashMap::new(),
        tally: Tally::default(),
        bar,
    };
    let started = Instant::now();
    let stop = crate::terminated();
    tokio::pin!(stop);
    let end = loop {
        let sent_before = replay.tally.sent + replay.tally.failed;
        match replay.pass(&mut stop).await {
            // a pass that sent nothing would loop without end
            PassEnd::Done
                if args.looping && replay.tally.sent + replay.tally.failed > sent_before => {}
            end => break end,
        }
    };
    replay.bar.finish_and_clear();
    // what the medium still holds goes out, in order, before the process ends
    let finished = replay.sending.finish().await;
    eprintln!("{}", replay.summary(started.elapsed()));
    match finished {
        Ok(()) => {}
        // said below, with what the link took
        Err(_) if matches!(end, PassEnd::LinkLost(_)) => {}
        Err(e) => {
            eprintln!("seabus replay: {e}");
            return ExitCode::from(match e {
                Unfinished::Lost(_) => sending::LINK_LOST,
                Unfinished::Late(_) => NOT_SENT,
            });
        }
    }
    match end {
        PassEnd::Damaged(file, d) => {
            eprintln!(
                "seabus replay: {}: damaged at {d}; the events before it were replayed, nothing after it",
                file.display()
            );
            ExitCode::from(DAMAGED)
        }
        PassEnd::Unreadable(file, e) => {
            eprintln!("seabus replay: {}: cannot open: {e}", file.display());
            ExitCode::from(USAGE)
        }
        PassEnd::Closed => {
            eprintln!("seabus replay: the medium was closed");
            ExitCode::from(NOT_SENT)
        }
        PassEnd::LinkLost(why) => {
            eprintln!("seabus replay: {why}; nothing after was sent");
            ExitCode::from(sending::LINK_LOST)
        }
        PassEnd::Done | PassEnd::Stopped if replay.tally.failed > 0 => ExitCode::from(NOT_SENT),
        PassEnd::Done | PassEnd::Stopped => ExitCode::SUCCESS,
    }
}

/// What `seabus convert` was asked to do.
#[derive(clap::Args)]
pub struct ConvertArgs {
    /// The log to read: an LCM event log or an MCAP file (told apart by its first bytes).
    pub input: PathBuf,
    /// The log to write: MCAP when it is named `.mcap`, else an LCM event log.
    pub output: PathBuf,
    /// `lcm` or `mcap`, whatever the output is named.
    #[arg(long, value_name = "FORMAT")]
    pub format: Option<String>,
    /// .lcm files or directories whose types decode the LCM messages of the input (besides the
    /// built-in ones): a message of a known type is written as its fields, with a schema.
    #[arg(long = "lcm-types", value_name = "PATH")]
    pub lcm_types: Vec<PathBuf>,
    /// Replace the output if it exists.
    #[arg(long)]
    pub force: bool,
}

/// Converts a log to the other kind (or the same): every event, its time kept, its payload
/// decoded by the LCM types when it is an LCM message of a known type.
pub fn convert(args: ConvertArgs) -> ExitCode {
    let usage = |msg: String| {
        eprintln!("seabus convert: {msg}");
        ExitCode::from(USAGE)
    };
    let kind = match args.format.as_deref() {
        None => LogKind::of_name(&args.output),
        Some(f) => match LogKind::parse(f) {
            Some(k) => k,
            None => return usage(format!("--format {f}: expected lcm or mcap")),
        },
    };
    let types = match crate::lcmtypes::load(&args.lcm_types) {
        Ok(t) => t,
        Err(e) => return usage(e),
    };
    let (input, output) = (args.input.display(), args.output.display());
    let mut reader = match Reader::open(&args.input) {
        Ok(r) => r,
        Err(e) => return usage(format!("{input}: cannot open: {e}")),
    };
    let mut writer = match Writer::create(&args.output, kind, args.force, Catalogue::built_in()) {
        Ok(w) => w,
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            return usage(format!("{output}: the file exists (--force replaces it)"));
        }
        Err(e) => return usage(format!("{output}: cannot create: {e}")),
    };
    let node = Node::new("convert");
    let origin = seabus_medium::Origin::new(&node.name, "log", 0);
    let (mut written, mut decoded, mut encoded, mut skipped) = (0u64, 0u64, 0u64, 0u64);
    // channels whose LCM type is not known, said once each
    let mut unencoded = HashSet::new();
    let mut damage = None;
    loop {
        let event = match reader.next_event() {
            Ok(Some(e)) => e,
            Ok(None) => break,
            Err(d) => {
                damage = Some(d);
                break;
            }
        };
        let Ok(topic) = Topic::new(&event.channel) else {
            skipped += 1;
            continue;
        };
        // an LCM message: its fields, with its type said in an MCAP file; an MCAP message decoded
        // from an LCM type: encoded with it again in an LCM log
        let (payload, lcm_type) = match (types.recognise(&event.payload), kind) {
            (Some((name, map)), LogKind::Mcap) => {
                decoded += 1;
                (seabus_medium::Payload::from(map), Some(name.to_string()))
            }
            (_, LogKind::Lcm) if event.lcm_type.is_some() && event.payload.as_map().is_some() => {
                let name = event.lcm_type.as_deref().unwrap_or_default();
                let map = event.payload.as_map().expect("a map, looked at above");
                match types.encode(name, map) {
                    Ok(bytes) => {
                        encoded += 1;
                        (bytes, None)
                    }
                    Err(e) => {
                        skipped += 1;
                        if unencoded.insert(event.channel.clone()) {
                            eprintln!("seabus convert: `{}`: not converted: {e}", event.channel);
                        }
                        continue;
                    }
                }
            }
            _ => (event.payload, event.lcm_type),
        };
        let stamp = Stamp(event.micros.saturating_mul(1000));
        let message = Message {
            topic,
            kind: Kind::Data,
            provenance: seabus_medium::Provenance {
                origin: origin.clone(),
                seq: written + 1,
                hops: 0,
            },
            stamp,
            payload,
        };
        match writer.write_typed(&message, stamp, lcm_type.as_deref()) {
            Ok(()) => written += 1,
            Err(WriteError::Unwritable(e)) => {
                skipped += 1;
                tracing::warn!("not converted: {e}");
            }
            Err(WriteError::File(e)) => return usage(format!("{output}: cannot write: {e}")),
        }
    }
    if let Err(e) = writer.finish() {
        return usage(format!("{output}: cannot write: {e}"));
    }
    let typed = match (decoded, encoded) {
        (0, 0) => String::new(),
        (d, 0) => format!(" ({d} decoded by their LCM type)"),
        (0, e) => format!(" ({e} encoded with their LCM type again)"),
        (d, e) => format!(" ({d} decoded by their LCM type, {e} encoded with it again)"),
    };
    eprintln!(
        "seabus convert: {} from {input} to {output}{typed}{}",
        count(written, "event"),
        if skipped > 0 {
            format!("; {skipped} skipped: not seabus topics or no form the output holds")
        } else {
            String::new()
        }
    );
    match damage {
        Some(d) => {
            eprintln!(
                "seabus convert: {input}: damaged at {d}; the events before it were converted"
            );
            ExitCode::from(DAMAGED)
        }
        None => ExitCode::SUCCESS,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speeds_read_as_factors_or_unpaced() {
        assert_eq!(parse_speed("max"), Some(None));
        assert_eq!(parse_speed("0"), Some(None));
        assert_eq!(parse_speed("2.5"), Some(Some(2.5)));
        assert_eq!(parse_speed("0.001"), Some(Some(0.001)));
        for bad in ["-1", "nan", "inf", "fast", "1e7", "", "1e-18", "0.0009"] {
            assert_eq!(parse_speed(bad), None, "{bad}");
        }
    }

    #[test]
    fn pacing_stays_within_the_clock() {
        let now = Instant::now();
        let s = Duration::from_secs;
        assert_eq!(due(now, 0, 2_000_000, 2.0), Some(now + s(1)));
        assert_eq!(due(now, 5, 5, MIN_SPEED), Some(now));
        // timestamps as far apart as they go, at the slowest speed: no overflow, no panic
        for (log0, timestamp) in [(i64::MIN, i64::MAX), (0, i64::MAX), (i64::MIN, 0)] {
            let at = due(now, log0, timestamp, MIN_SPEED);
            assert!(at.is_none_or(|at| at > now + s(1 << 40)), "{at:?}");
        }
        // speeds below the slowest would be refused; the pacing itself does not panic on them
        assert!(due(now, 0, i64::MAX, 1e-18).is_none());
    }
}
