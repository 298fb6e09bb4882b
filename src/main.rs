//! `seabus`: the command-line program. It parses arguments and wires a system file to the runtime;
//! everything else lives in the library crates.

mod console;
mod export;
mod lcmtypes;
mod logtail;
mod media;
mod memory;
mod record;
mod sending;
use sending::{NotSent, Sending, Unfinished};
mod spy;

use clap::{Parser, Subcommand};
use seabus_medium::xml::FileError;
use seabus_medium::{Format, Kind, Node, Payload, Stamp};
use seabus_modules::system::{self, SystemSpec};
use seabus_modules::{Catalogue, Registry, Runtime};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

/// The demo system, built in.
const DEMO: &str = include_str!("../configs/demo.xml");

#[derive(Parser)]
#[command(
    name = "seabus",
    version,
    about = "Message-bus gateway and module framework for marine robots"
)]
struct Cli {
    /// More log output (-v debug, -vv trace); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a system file until Ctrl-C or SIGTERM.
    Run {
        /// The system file.
        file: PathBuf,
        /// Stop by itself after this many seconds.
        #[arg(long = "for", value_name = "SECS")]
        duration: Option<f64>,
    },
    /// Run the built-in demo (a simulated Iver2 and its backseat); traffic on udp://239.255.42.1:47800.
    Demo {
        /// Stop by itself after this many seconds.
        #[arg(long = "for", value_name = "SECS")]
        duration: Option<f64>,
    },
    /// Validate a system file: exit 0 when valid, 1 when valid with warnings, 2 when not valid.
    Check {
        /// The system file.
        file: PathBuf,
    },
    /// Show the traffic on a medium: a live table of topics, or one JSON object per message.
    Spy {
        /// The medium, for example udp://239.255.42.1:47800.
        url: String,
        /// Stop after this many seconds.
        #[arg(long = "for", value_name = "SECS")]
        duration: Option<f64>,
        /// Print one JSON object per message instead of the table.
        #[arg(long)]
        json: bool,
        /// Also print the medium's counters to stderr (received, rejected by reason, bytes
        /// dropped, overruns, queue drops, …) every 5 seconds and when the spy ends.
        #[arg(long)]
        stats: bool,
        /// Only topics matching this pattern.
        #[arg(long, default_value = "**")]
        topics: String,
        /// .lcm files or directories whose types are shown decoded (besides the built-in ones).
        #[arg(long = "lcm-types", value_name = "PATH")]
        lcm_types: Vec<PathBuf>,
        /// Show the CAN frames of an NMEA 2000 network as PGNs: reassembled (fast packets, ISO
        /// transport), decoded, with the names and units of their fields.
        #[arg(long)]
        n2k: bool,
        /// canboat's canboat.json, for the PGNs --n2k shows (besides the built-in ones).
        #[arg(long = "n2k-database", value_name = "FILE", requires = "n2k")]
        n2k_database: Option<PathBuf>,
    },
    /// Publish a message on a medium: fields, a JSON payload or raw bytes.
    ///
    /// Waits for the medium's link before the first message and, when the link is lost on the
    /// way, for its return (logged), then goes on. Exit 0 when all was sent; 1 when what was sent
    /// did not go out in time; 2 when the arguments or payload cannot be used; 3 when the medium
    /// refused the message (the reason is shown); 4 when the link did not come up or back within
    /// --link-wait, or messages were lost with it (counted).
    Pub(PubArgs),
    /// Record the traffic on a medium to an LCM event log, until Ctrl-C, SIGTERM or --for.
    ///
    /// The log is the file lcm-logger writes: one event per message, channel = topic, timestamp =
    /// arrival, data = the payload's bytes (datamaps in the binary form, XML as text, each
    /// channel's format said in a `seabus.log.format` event where it is not bytes). Exit 0; 1 when
    /// the file could not be written; 2 when the arguments, file or medium cannot be used.
    Record(record::RecordArgs),
    /// Publish the events of an LCM event log on a medium, paced by their timestamps.
    ///
    /// Each event is sent as data: channel = topic, payload = the data in the format the log
    /// keeps for it (datamaps and XML from seabus's recordings, bytes otherwise); channels that
    /// are not seabus topics are skipped and counted. A folder replays every log in it. The link
    /// is waited for as `seabus pub` does (pacing starts again when it comes back). Exit 0; 1
    /// when the log is damaged (the events before the damage are sent, and its byte offset is
    /// shown); 2 when the arguments, file or medium cannot be used; 3 when the medium refused
    /// events; 4 when the link did not come up or back within --link-wait, or events were lost
    /// with it.
    Replay(record::ReplayArgs),
    /// A time window of logger or record logs as JSON lines or a CSV per topic.
    ///
    /// Exit 0; 1 when a log is damaged (the events before the damage are exported) or the output
    /// cannot be written; 2 when the arguments or files cannot be used.
    Export(export::ExportArgs),
    /// A log of one kind to the other: an LCM event log to MCAP (its LCM messages decoded by
    /// their types, with schemas) or MCAP to an LCM event log.
    ///
    /// Exit 0; 1 when the input is damaged (the events before the damage are converted); 2 when
    /// the arguments or files cannot be used.
    Convert(record::ConvertArgs),
    /// The DSAAV central log.
    Log {
        #[command(subcommand)]
        command: LogCommand,
    },
    /// The console's layouts.
    Layout {
        #[command(subcommand)]
        command: LayoutCommand,
    },
    /// The console's users file.
    User {
        #[command(subcommand)]
        command: UserCommand,
    },
    /// List the module types, bridge types, medium schemes and standard datasets.
    Types,
    /// List the medium schemes compiled into this seabus, and the media left out.
    Schemes,
}

/// What `seabus layout` does.
#[derive(Subcommand)]
enum LayoutCommand {
    /// Check a layout against a system file: exit 1 when either does not read or contradicts
    /// itself; warnings for bindings no module produces and commands no module accepts (exit 0).
    Check {
        /// The layout file.
        layout: PathBuf,
        /// The system file the layout is used with.
        system: PathBuf,
    },
}

/// What `seabus user` does.
#[derive(Subcommand)]
enum UserCommand {
    /// Add a user (or replace one of that name) to a users file, created when missing; the
    /// password (at least 8 characters) is asked for (read from stdin when it is not a terminal)
    /// and stored as an argon2id hash.
    Add {
        /// The users file.
        file: PathBuf,
        /// The user's log-in name.
        name: String,
        /// The user's roles, space-separated (for example "pilot designer").
        #[arg(long, default_value = "")]
        roles: String,
    },
}

/// What `seabus log` does.
#[derive(Subcommand)]
enum LogCommand {
    /// Print the end of the central log, then follow it as it grows (across rotation).
    Tail {
        /// The log file the logging server writes.
        file: PathBuf,
        /// Lines of the end to print first.
        #[arg(short = 'n', long, default_value_t = 10)]
        lines: usize,
        /// Stop after this many seconds.
        #[arg(long = "for", value_name = "SECS")]
        duration: Option<f64>,
    },
}

/// What `seabus pub` sends.
#[derive(clap::Args)]
struct PubArgs {
    /// The medium, for example udp://239.255.42.1:47800.
    url: String,
    /// The topic.
    topic: String,
    /// Fields as key=value (true/false, integers and numbers are typed; "quoted" is a string;
    /// hex:0102 and base64:AQI= are bytes).
    fields: Vec<String>,
    /// The payload in seabus's JSON form, as `spy --json` prints payloads: an object whose values
    /// may be lists and nested objects, bytes as {"base64": "…"}, NaN and ±inf as
    /// {"float": "NaN"}, {"float": "inf"}, {"float": "-inf"}.
    #[arg(long, value_name = "JSON", conflicts_with_all = ["fields", "json_file", "raw", "raw_file"])]
    json: Option<String>,
    /// The payload in seabus's JSON form (as --json) read from a file.
    #[arg(long = "json-file", value_name = "FILE", conflicts_with_all = ["fields", "raw", "raw_file"])]
    json_file: Option<PathBuf>,
    /// Send these bytes as the payload, hex:0102 or base64:AQI= (on a CAN topic, the frame's
    /// data).
    #[arg(long, value_name = "BYTES", conflicts_with_all = ["fields", "lcm", "raw_file"])]
    raw: Option<String>,
    /// Send the bytes of this file as the payload, as they are (`-`: standard input), for
    /// payloads too long for the command line.
    #[arg(long = "raw-file", value_name = "FILE", conflicts_with_all = ["fields", "lcm"])]
    raw_file: Option<PathBuf>,
    /// How many messages to send.
    #[arg(long, default_value_t = 1)]
    count: u64,
    /// Messages per second when sending several.
    #[arg(long, default_value_t = 1.0)]
    rate: f64,
    /// Send as a command rather than data.
    #[arg(long)]
    command: bool,
    /// Payload format: map, xml or bytes.
    #[arg(long, default_value = "map")]
    format: String,
    /// Send an LCM message of this type (package.name_t) made from the fields, for LCM programs.
    #[arg(long, value_name = "TYPE")]
    lcm: Option<String>,
    /// .lcm files or directories with the type (besides the built-in ones).
    #[arg(long = "lcm-types", value_name = "PATH")]
    lcm_types: Vec<PathBuf>,
    /// With --lcm: send the type's members not given with their defaults (NaN, 0, false, "")
    /// rather than refuse the message.
    #[arg(long = "allow-missing", requires = "lcm")]
    allow_missing: bool,
    /// Seconds to wait for the medium's link to come up, or to come back when it is lost, and
    /// for what was sent to go out at the end.
    #[arg(long = "link-wait", value_name = "SECS", default_value_t = 5.0)]
    link_wait: f64,
}

/// What `seabus pub` sends before any conversion: from its fields, its JSON, or raw bytes.
fn pub_payload(
    fields: &[String],
    json: Option<&str>,
    json_file: Option<&Path>,
    raw: Option<&str>,
    raw_file: Option<&Path>,
) -> Result<Payload, String> {
    if let Some(file) = raw_file {
        let bytes = if file == Path::new("-") {
            let mut bytes = Vec::new();
            std::io::Read::read_to_end(&mut std::io::stdin(), &mut bytes)
                .map_err(|e| format!("--raw-file -: standard input: {e}"))?;
            bytes
        } else {
            std::fs::read(file).map_err(|e| format!("--raw-file {}: {e}", file.display()))?
        };
        return Ok(Payload::from(bytes));
    }
    if let Some(raw) = raw {
        return match seabus_medium::parse::parse_bytes(raw) {
            Some(bytes) => bytes.map(Payload::from).map_err(|e| format!("--raw: {e}")),
            None => Err(format!(
                "--raw `{raw}`: bytes are written hex:0102 or base64:AQI="
            )),
        };
    }
    let from_json = |source: &str, text: &str| {
        seabus_medium::json::from_json(text).map_err(|e| {
            // serde says where as " at line L column C": said first, as everywhere else
            let text = e.to_string();
            let what = text.split(" at line ").next().unwrap_or(&text);
            format!("{source}:{}:{}: {what}", e.line(), e.column())
        })
    };
    let map = match (json, json_file) {
        (Some(text), _) => from_json("--json", text)?,
        (None, Some(file)) => {
            let text = std::fs::read_to_string(file)
                .map_err(|e| format!("--json-file {}: {e}", file.display()))?;
            from_json(&file.display().to_string(), &text)?
        }
        (None, None) => seabus_medium::parse::parse_fields(fields.iter().map(String::as_str))?,
    };
    Ok(Payload::from(map))
}

fn registry() -> Registry {
    let mut reg = Registry::new();
    reg.set_schemes(media::schemes());
    seabus_support::register(&mut reg);
    #[cfg(feature = "dsaav")]
    seabus_dsaav::register(&mut reg);
    seabus_drivers::register(&mut reg);
    seabus_bridges::register(&mut reg);
    seabus_ui::register(&mut reg);
    reg
}

fn init_logs(verbose: u8) {
    let ours = [
        "seabus",
        "seabus_medium",
        "seabus_modules",
        "seabus_drivers",
        "seabus_bridges",
        "seabus_ui",
    ];
    let level = match verbose {
        0 => "info",
        1 => "debug",
        _ => "trace",
    };
    // the Foxglove server logs every malformed client message: the live view takes those reports,
    // counts them and logs them without flooding
    // Zenoh's subscriber logs each gap it sees in a publisher's samples ("Sample missed", several
    // times a gap): the Zenoh medium counts them by topic and logs them once, rate-limited
    let default: Vec<String> = [
        "warn",
        "foxglove=off",
        "zenoh_ext::advanced_subscriber=error",
    ]
    .into_iter()
    .map(str::to_string)
    .chain(ours.iter().map(|c| format!("{c}={level}")))
    .collect();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default.join(",")));
    use tracing_subscriber::prelude::*;
    let terminal = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .with_filter(filter);
    // services that send this program's log elsewhere (a system's <log>, the Foxglove view's Log
    // panel) take their records through this layer
    tracing_subscriber::registry()
        .with(terminal)
        .with(seabus_modules::logs::layer())
        .init();
}

fn main() -> ExitCode {
    use clap::{CommandFactory, FromArgMatches};
    memory::bound();
    // `--version` names the media compiled in; made once, for the life of the program
    let version: &'static str = Box::leak(media::long_version().into_boxed_str());
    let cli = match Cli::command()
        .long_version(version)
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m))
    {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    init_logs(cli.verbose);
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("seabus: cannot start the runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let code = rt.block_on(async move {
        match cli.command {
            Command::Run { file, duration } => match SystemSpec::load(&file) {
                Ok(spec) => run(spec, duration, None).await,
                Err(e) => file_error(&e),
            },
            Command::Demo { duration } => {
                // the demo's files, written where its relative paths find them
                let written = console::write_demo(DEMO).and_then(|(dir, file)| {
                    SystemSpec::load(&file)
                        .map(|spec| (dir, spec))
                        .map_err(|e| e.to_string())
                });
                match written {
                    Ok((dir, spec)) => {
                        eprintln!(
                            "seabus demo: a simulated Iver2 frontseat on a pseudo-terminal, the Iver2 driver on the\n  \
                             backseat, NMEA GPS and compass, and a helm driving the vehicle around a square.\n  \
                             The traffic is on udp://239.255.42.1:47800 (loopback only): in another terminal run\n  \
                             seabus spy udp://239.255.42.1:47800\n  Ctrl-C stops."
                        );
                        run(spec, duration, Some(dir)).await
                    }
                    Err(e) => {
                        eprintln!("seabus demo: {e}");
                        ExitCode::from(2)
                    }
                }
            }
            Command::Check { file } => check(&file),
            Command::Spy {
                url,
                duration,
                json,
                stats,
                topics,
                lcm_types,
                n2k,
                n2k_database,
            } => match seconds(duration) {
                Ok(d) => {
                    let n2k = n2k.then_some(n2k_database);
                    spy::spy(&url, d, json, stats, &topics, &lcm_types, n2k).await
                }
                Err(code) => code,
            },
            Command::Pub(args) => publish(args).await,
            Command::Record(args) => record::record(args).await,
            Command::Replay(args) => record::replay(args).await,
            Command::Export(args) => export::export(args),
            Command::Convert(args) => record::convert(args),
            Command::Log {
                command:
                    LogCommand::Tail {
                        file,
                        lines,
                        duration,
                    },
            } => match seconds(duration) {
                Ok(d) => logtail::tail(&file, lines, d),
                Err(code) => code,
            },
            Command::Layout {
                command: LayoutCommand::Check { layout, system },
            } => layout_check(&layout, &system),
            Command::User {
                command: UserCommand::Add { file, name, roles },
            } => console::user_add(&file, &name, &roles),
            Command::Schemes => {
                print!("{}", media::describe());
                ExitCode::SUCCESS
            }
            Command::Types => {
                types();
                ExitCode::SUCCESS
            }
        }
    });
    // modules that ignored the shutdown must not hold the process
    rt.shutdown_timeout(Duration::from_millis(200));
    code
}

fn file_error(e: &FileError) -> ExitCode {
    eprintln!("{e}");
    ExitCode::from(2)
}

/// Completes on Ctrl-C or SIGTERM.
async fn terminated() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(s) => s,
                Err(_) => {
                    let _ = ctrl_c.await;
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    {
        let _ = ctrl_c.await;
    }
}

/// `--for SECS` as a duration; a bad value is reported (exit code 2).
fn seconds(value: Option<f64>) -> Result<Option<Duration>, ExitCode> {
    match value {
        None => Ok(None),
        Some(v) => seabus_medium::parse::secs(v).map(Some).ok_or_else(|| {
            eprintln!("seabus: --for {v}: expected a number of seconds from 0 to 1e9");
            ExitCode::from(2)
        }),
    }
}

/// Runs a system until Ctrl-C, SIGTERM or `duration`; `demo_dir` is the demo's own directory
/// (removed at the end). Nothing starts unless the system
/// passes the same validation as `seabus check`; its warnings are logged.
async fn run(spec: SystemSpec, duration: Option<f64>, demo_dir: Option<PathBuf>) -> ExitCode {
    let duration = match seconds(duration) {
        Ok(d) => d,
        Err(code) => return code,
    };
    let registry = registry();
    let catalogue = Catalogue::built_in();
    let mut checked = match seabus_ui::console::check(&spec, &registry, &catalogue) {
        Ok(c) => c,
        Err(e) => return file_error(&e),
    };
    // the system's own warnings are logged by the runtime as it starts
    for w in &checked.warnings {
        tracing::warn!("{w}");
    }
    if let Err(e) = console::one_time_users(&mut checked.consoles) {
        eprintln!("seabus: {e}");
        return ExitCode::from(2);
    }
    let runtime = match Runtime::start(&spec, &registry, catalogue).await {
        Ok(r) => r,
        Err(e) => return file_error(&e),
    };
    let demo = demo_dir.is_some();
    let consoles = match console::start(checked.consoles, &spec, &registry, &runtime, demo).await {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{e}");
            runtime.shutdown().await;
            return ExitCode::from(2);
        }
    };
    for c in &consoles {
        eprintln!("  Console: http://{}", c.addr());
    }
    let foxgloves = match console::start_foxglove(&spec, &runtime, demo).await {
        Ok(f) => f,
        Err(e) => {
            eprintln!("{e}");
            drop(consoles);
            runtime.shutdown().await;
            return ExitCode::from(2);
        }
    };
    for f in &foxgloves {
        eprintln!(
            "  Foxglove: {} (open it in Foxglove or Lichtblick)",
            f.url()
        );
    }
    tracing::info!(
        node = %runtime.node().name,
        "running {}: media {}; modules {}",
        spec.file,
        spec.media.iter().map(|m| format!("{} ({})", m.name, m.url)).collect::<Vec<_>>().join(", "),
        spec.modules
            .iter()
            .map(|m| m.name.as_str())
            .chain(spec.bridges.iter().map(|b| b.name.as_str()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    // what starting took (the users' password hashes above all) is given back at once
    let giving_back = tokio::spawn(memory::keep_giving_back());
    match duration {
        Some(d) => {
            tokio::select! {
                _ = terminated() => {}
                _ = tokio::time::sleep(d) => {}
            }
        }
        None => terminated().await,
    }
    giving_back.abort();
    tracing::info!("shutting down");
    drop(foxgloves);
    drop(consoles);
    if let Some(dir) = demo_dir {
        let _ = std::fs::remove_dir_all(dir);
    }
    runtime.shutdown().await;
    ExitCode::SUCCESS
}

/// `seabus check FILE`: the validation `seabus run` makes before it starts anything.
fn check(file: &std::path::Path) -> ExitCode {
    let spec = match SystemSpec::load(file) {
        Ok(s) => s,
        Err(e) => return file_error(&e),
    };
    let checked = seabus_ui::console::check(&spec, &registry(), &Catalogue::built_in());
    match checked {
        Err(e) => file_error(&e),
        Ok(c) if c.report.warnings.is_empty() && c.warnings.is_empty() => {
            println!(
                "{}: valid ({}, {}, {})",
                spec.file,
                counted(spec.media.len(), "medium", "media"),
                counted(spec.modules.len(), "module", "modules"),
                counted(spec.bridges.len(), "bridge", "bridges")
            );
            ExitCode::SUCCESS
        }
        Ok(c) => {
            for w in c.report.warnings.iter().chain(&c.warnings) {
                eprintln!("{w}");
            }
            ExitCode::from(1)
        }
    }
}

/// `seabus layout check LAYOUT SYSTEM`.
fn layout_check(layout: &std::path::Path, system: &std::path::Path) -> ExitCode {
    let fail = |e: &FileError| {
        eprintln!("{e}");
        ExitCode::from(1)
    };
    let layout = match seabus_ui::Layout::load_all(layout, &Default::default()) {
        Ok(l) => l,
        Err(errors) => {
            for e in &errors {
                eprintln!("{e}");
            }
            eprintln!(
                "{}: {}",
                layout.display(),
                counted(errors.len(), "error", "errors")
            );
            return ExitCode::from(1);
        }
    };
    let spec = match SystemSpec::load(system) {
        Ok(s) => s,
        Err(e) => return fail(&e),
    };
    let registry = registry();
    let catalogue = Catalogue::built_in();
    if let Err(e) = system::check(&spec, &registry, &catalogue) {
        return fail(&e);
    }
    for w in layout.check(&spec, &registry, &catalogue) {
        eprintln!("{w}");
    }
    println!(
        "{}: valid ({}, {}, {})",
        layout.file,
        counted(layout.widget_count(), "widget", "widgets"),
        counted(layout.commands.len(), "command", "commands"),
        counted(layout.bindings().len(), "binding", "bindings")
    );
    ExitCode::SUCCESS
}

async fn publish(args: PubArgs) -> ExitCode {
    let usage = |msg: String| {
        eprintln!("seabus pub: {msg}");
        ExitCode::from(2)
    };
    let PubArgs {
        url,
        topic,
        fields,
        count,
        rate,
        command,
        format,
        lcm,
        lcm_types,
        json,
        json_file,
        raw,
        raw_file,
        allow_missing,
        link_wait,
    } = args;
    let payload = match pub_payload(
        &fields,
        json.as_deref(),
        json_file.as_deref(),
        raw.as_deref(),
        raw_file.as_deref(),
    ) {
        Ok(p) => p,
        Err(e) => return usage(e),
    };
    let topic = match seabus_medium::Topic::new(&topic) {
        Ok(t) => t,
        Err(e) => return usage(e.to_string()),
    };
    let Some(link_wait) = sending::link_wait(link_wait) else {
        return usage(format!(
            "--link-wait {link_wait}: expected a number of seconds from 0 to 1e9"
        ));
    };
    let Some(format) = Format::parse(&format) else {
        return usage(format!("`{format}` is not a format: map, xml or bytes"));
    };
    let Some(period) = seabus_medium::parse::rate_period(rate) else {
        return usage(format!(
            "--rate {rate}: expected above 0 and at most a million per second"
        ));
    };
    let outgoing = match (&lcm, payload.as_map()) {
        (Some(name), Some(map)) => {
            match lcmtypes::LcmMessage::new(name, &lcm_types, map, allow_missing) {
                Ok(m) => Outgoing::Lcm(m),
                Err(e) => return usage(e),
            }
        }
        // raw bytes go as they are, whatever the format
        _ if raw.is_some() || raw_file.is_some() => Outgoing::Same(payload),
        _ => match payload.convert(format) {
            Ok(p) => Outgoing::Same(p),
            Err(e) => return usage(e.to_string()),
        },
    };
    let node = Node::new(&format!("pub-{}", std::process::id()));
    // a unicast UDP address is where to send, not where to listen
    #[cfg(feature = "udp")]
    let url = seabus_medium_udp::sending_url(&url);
    let medium = match media::schemes().open("pub", &url, &node) {
        Ok(m) => m,
        Err(e) => return usage(e.to_string()),
    };
    let mut sending = match Sending::open("seabus pub", medium, link_wait).await {
        Ok(s) => s,
        Err(e) => return not_sent("seabus pub", e),
    };
    let kind = if command { Kind::Command } else { Kind::Data };
    let mut ticker = tokio::time::interval(period);
    for _ in 0..count {
        ticker.tick().await;
        let payload = match outgoing.payload(Stamp::now()) {
            Ok(p) => p,
            Err(e) => return usage(e),
        };
        match sending.send(kind, &topic, payload).await {
            // the link came back: the rate counts from now, without a burst for the time lost
            Ok(true) => ticker.reset(),
            Ok(false) => {}
            Err(e) => return not_sent("seabus pub", e),
        }
    }
    // what a connection's task still holds goes out before the process ends
    match sending.finish().await {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("seabus pub: medium `pub`: {e}");
            match e {
                Unfinished::Lost(_) => ExitCode::from(sending::LINK_LOST),
                Unfinished::Late(_) => ExitCode::from(1),
            }
        }
    }
}

/// Says why a command's message was not sent, and exits with the code that says so.
fn not_sent(command: &str, e: NotSent) -> ExitCode {
    match e {
        NotSent::LinkLost(why) => {
            eprintln!("{command}: {why}");
            ExitCode::from(sending::LINK_LOST)
        }
        NotSent::Refused(e) => {
            eprintln!("{command}: not sent: {e}");
            ExitCode::from(3)
        }
        NotSent::Closed => {
            eprintln!("{command}: the medium was closed");
            ExitCode::from(3)
        }
    }
}

/// What `seabus pub` sends: the same payload every time, or an LCM message made anew for each,
/// with the time it is sent in its `utime`.
enum Outgoing {
    Same(Payload),
    Lcm(lcmtypes::LcmMessage),
}

impl Outgoing {
    /// The payload of the message sent at `stamp`.
    fn payload(&self, stamp: Stamp) -> Result<Payload, String> {
        match self {
            Outgoing::Same(p) => Ok(p.clone()),
            Outgoing::Lcm(m) => m.payload(stamp),
        }
    }
}

/// `n` and the word for it: `one` when `n` is 1, else `many` (`1 medium`, `3 media`).
pub(crate) fn counted(n: impl TryInto<u64>, one: &str, many: &str) -> String {
    match n.try_into().unwrap_or(u64::MAX) {
        1 => format!("1 {one}"),
        n => format!("{n} {many}"),
    }
}

/// `seabus types`: each list in columns as wide as their longest entry.
fn types() {
    let reg = registry();
    let width = |names: &mut dyn Iterator<Item = usize>| names.max().unwrap_or(0);
    let modules: Vec<_> = reg.module_types().collect();
    let (name_w, kind_w) = (
        width(&mut modules.iter().map(|t| t.name.len())),
        width(&mut modules.iter().map(|t| t.kind.name().len())),
    );
    println!("module types:");
    for t in &modules {
        println!(
            "  {:<name_w$}  {:<kind_w$}  {}",
            t.name,
            t.kind.name(),
            t.summary
        );
    }
    let bridges: Vec<_> = reg.bridge_types().collect();
    let name_w = width(&mut bridges.iter().map(|t| t.name.len()));
    println!("bridge types:");
    for t in &bridges {
        println!("  {:<name_w$}  {}", t.name, t.summary);
    }
    println!("medium schemes: {}", media::schemes().names().join(", "));
    println!("standard datasets:");
    let catalogue = Catalogue::built_in();
    let (name_w, topic_w) = (
        width(&mut catalogue.iter().map(|d| d.name.len())),
        width(&mut catalogue.iter().map(|d| d.topic.len())),
    );
    for d in catalogue.iter() {
        let required: Vec<&str> = d.required().map(|f| f.name.as_str()).collect();
        println!(
            "  {:<name_w$}  {:<topic_w$}  required: {}",
            d.name,
            d.topic,
            required.join(", ")
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (The demo's system has an LCM medium: a build without LCM refuses it, as it should.)
    #[test]
    #[cfg(feature = "lcm")]
    fn the_demo_system_is_valid() {
        // as `seabus demo` runs it: from its own directory, with its built-in files and users
        let (dir, file) = console::write_demo(DEMO).unwrap();
        let spec = SystemSpec::load(&file).unwrap();
        let checked = seabus_ui::console::check(&spec, &registry(), &Catalogue::built_in());
        std::fs::remove_dir_all(dir).unwrap();
        let checked = checked.unwrap();
        assert!(
            checked.report.warnings.is_empty(),
            "{:?}",
            checked.report.warnings
        );
        assert!(checked.warnings.is_empty(), "{:?}", checked.warnings);
        assert_eq!(checked.consoles.len(), 1);
        assert_eq!(checked.consoles[0].layouts.len(), 2);
        // a console on 127.0.0.1 without a users file: its users are made as it starts
        assert!(checked.consoles[0].users.is_none());
    }
}
