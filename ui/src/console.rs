//! The `<console>` element of a system file, and a running console.
//!
//! ```xml
//! <console medium="bus" listen="127.0.0.1:8080" users="console-users.xml"
//!          layouts="console/pilot.xml console/scientist.xml" ack_timeout="5s"/>
//! ```
//!
//! [`specs`] reads the elements; [`check`] is the one validation `seabus check` and `seabus run`
//! share (the system, then each console's attributes, users and layouts, and the layouts against
//! the system); [`Console::start`] binds the address, attaches to the medium and runs the
//! [`Hub`]'s reader and watchdog and the [`server`](crate::server).

use crate::auth::Sessions;
use crate::hub::{Hub, Settings};
use crate::layout::Layout;
use crate::users::Users;
use seabus_medium::xml::{Attr, Element, FileError};
use seabus_medium::{Kind, Medium, Pattern};
use seabus_modules::system::{self, Report, SystemSpec};
use seabus_modules::{Catalogue, Registry};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

/// The system-file element that starts a console.
pub const SECTION: &str = "console";
/// Where a console listens unless told.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8080";
/// How often the hub's watchdog runs (dead-man re-sends, acknowledgement timeouts, control).
pub const WATCH_EVERY: Duration = Duration::from_millis(50);

/// A `<console>` element, read.
#[derive(Debug, Clone)]
pub struct ConsoleSpec {
    /// The medium it reads and commands on.
    pub medium: String,
    /// The users file; without one, a console on a loopback address makes one-time users.
    pub users: Option<PathBuf>,
    /// The session file: attribute `sessions`, else beside the users file
    /// ([`sessions_beside`](crate::auth::sessions_beside)); none: sessions end with the console.
    pub sessions: Option<PathBuf>,
    /// Everything else.
    pub settings: Settings,
    /// The element, for errors.
    pub element: Element,
}

fn duration(el: &Element, name: &str, default: Duration) -> Result<Duration, FileError> {
    match el.attr(name) {
        None => Ok(default),
        Some(a) => seabus_medium::parse::parse_duration(&a.value)
            .ok_or_else(|| a.error(format!("`{}` is not a duration (such as 5s)", a.value))),
    }
}

/// The `history` attribute: how far back plotted and tracked variables are kept, from 10 s to
/// 24 h (default 10 min).
fn history(el: &Element) -> Result<Duration, FileError> {
    let d = duration(el, "history", Duration::from_secs(600))?;
    if d < Duration::from_secs(10) || d > Duration::from_secs(24 * 3600) {
        let a = el.required("history")?;
        return Err(a.error("`history` is how far back plots are kept: from 10s to 24h"));
    }
    Ok(d)
}

/// Reads the `<console>` elements of a system.
pub fn specs(spec: &SystemSpec) -> Result<Vec<ConsoleSpec>, FileError> {
    let mut out = Vec::new();
    for el in spec.sections(SECTION) {
        el.only_attrs(&[
            "medium",
            "listen",
            "users",
            "layouts",
            "ack_timeout",
            "log",
            "lease_role",
            "designer_role",
            "sessions",
            "history",
        ])?;
        el.only_children(&[])?;
        let medium = el
            .get("medium")
            .map_or_else(|| spec.default_medium().to_string(), str::to_string);
        if spec.medium(&medium).is_none() {
            let attr = el.required("medium")?;
            return Err(attr.error(format!("no medium called `{medium}`")));
        }
        let listen = match el.attr("listen") {
            None => DEFAULT_LISTEN
                .parse()
                .map_err(|_| el.error("bad default address"))?,
            Some(a) => a.value.trim().parse::<SocketAddr>().map_err(|_| {
                a.error(format!(
                    "`{}` is not an address and port (such as 127.0.0.1:8080)",
                    a.value
                ))
            })?,
        };
        let layouts_attr = el.required("layouts")?;
        let mut layouts = Vec::new();
        for item in layouts_attr.value.split_whitespace() {
            let path = seabus_modules::system::beside(&el.pos, item);
            if path.is_dir() {
                let mut files: Vec<PathBuf> = std::fs::read_dir(&path)
                    .map_err(|e| layouts_attr.error(format!("{}: {e}", path.display())))?
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.extension().is_some_and(|x| x == "xml"))
                    .collect();
                files.sort();
                layouts.extend(files);
            } else {
                layouts.push(path);
            }
        }
        if layouts.is_empty() {
            return Err(layouts_attr.error("no layout files"));
        }
        let role = |name: &str, default: &str| {
            el.get(name)
                .map_or_else(|| default.to_string(), |r| r.trim().to_string())
        };
        let users = el
            .get("users")
            .map(|u| seabus_modules::system::beside(&el.pos, u));
        out.push(ConsoleSpec {
            medium,
            sessions: el.get("sessions").map_or_else(
                || users.as_deref().map(crate::auth::sessions_beside),
                |s| Some(seabus_modules::system::beside(&el.pos, s)),
            ),
            users,
            settings: Settings {
                listen,
                ack_timeout: duration(el, "ack_timeout", Duration::from_secs(5))?,
                lease_role: role("lease_role", "pilot"),
                designer_role: role("designer_role", "designer"),
                log: el
                    .get("log")
                    .map(|l| seabus_modules::system::beside(&el.pos, l)),
                layouts,
                history: history(el)?,
                node: spec.node.clone(),
            },
            element: el.clone(),
        });
    }
    Ok(out)
}

/// What a console without a `users` attribute that listens beyond this machine is told.
const NEEDS_USERS: &str = "needs `users`, a users file with password hashes (`seabus user add FILE \
     NAME --roles pilot` writes one): only a console on a loopback address (such as 127.0.0.1) makes \
     one-time users of its own";

/// A console ready to start: its element read, its users and its layouts loaded.
#[derive(Debug, Clone)]
pub struct Ready {
    /// The `<console>` element, read.
    pub spec: ConsoleSpec,
    /// Who may log in: the users file's users, or `None` for a console on a loopback address
    /// without a users file, which gets one-time users (made with fresh passwords at each start,
    /// and printed).
    pub users: Option<Users>,
    /// Its layouts, read with their variables' defaults.
    pub layouts: Vec<Layout>,
}

/// What [`check`] found in a system it accepts.
#[derive(Debug)]
pub struct Checked {
    /// The system's own warnings (route cycles).
    pub report: Report,
    /// Every console, ready to start.
    pub consoles: Vec<Ready>,
    /// Warnings about the consoles' layouts against the system (`FILE:LINE:COL: warning: …`).
    pub warnings: Vec<FileError>,
}

/// Validates a system before anything of it starts; `seabus check` and `seabus run` both call it,
/// so that they refuse the same files with the same message. In order, the first error wins: the
/// system itself ([`system::check`]); every `<console>` element ([`specs`]: attributes, medium);
/// two consoles on one port; then for each console its users file (it must exist and read, each
/// user well formed) and each layout file (it must exist, read and expand). A layout that reads is
/// compared with the system ([`Layout::check_on`]): what it finds are warnings. A console without
/// a users file is accepted on a loopback address only (its users are made when it starts, see
/// [`Ready::users`]).
///
/// What only the running system can tell is not checked: a medium that cannot be opened, an
/// address already in use.
pub fn check(
    spec: &SystemSpec,
    registry: &Registry,
    catalogue: &Catalogue,
) -> Result<Checked, FileError> {
    let report = system::check(spec, registry, catalogue)?;
    let foxgloves = crate::foxglove::specs(spec)?;
    let specs = specs(spec)?;
    distinct_addresses(&specs)?;
    distinct_sessions(&specs)?;
    let mut consoles = Vec::new();
    let mut warnings = Vec::new();
    for cs in specs {
        let users = users_of(&cs)?;
        let attr = cs.element.required("layouts")?;
        let mut layouts = Vec::new();
        for path in &cs.settings.layouts {
            readable(attr, path, "layout")?;
            let layout = Layout::load(path, &Default::default())?;
            warnings.extend(layout.check_on(spec, registry, catalogue, &cs.medium));
            layouts.push(layout);
        }
        consoles.push(Ready {
            spec: cs,
            users,
            layouts,
        });
    }
    for fs in &foxgloves {
        for topic in &fs.commands {
            if !crate::layout::command_accepted(
                spec,
                registry,
                catalogue,
                &fs.medium,
                topic.as_str(),
            ) {
                let at = fs
                    .element
                    .attr("commands")
                    .map_or(&fs.element.pos, |a| &a.pos);
                warnings.push(at.error(format!(
                    "warning: no module of {} accepts command `{topic}` on `{}`, which Foxglove \
                     clients may send",
                    spec.file, fs.medium
                )));
            }
        }
    }
    Ok(Checked {
        report,
        consoles,
        warnings,
    })
}

/// The users of a console: its `users` file, which must exist and read; none (one-time users)
/// for a console on a loopback address without one.
fn users_of(cs: &ConsoleSpec) -> Result<Option<Users>, FileError> {
    let (Some(path), Some(attr)) = (&cs.users, cs.element.attr("users")) else {
        let listen = cs.settings.listen;
        if listen.ip().is_loopback() {
            return Ok(None);
        }
        return Err(cs
            .element
            .error(format!("a console listening on {listen} {NEEDS_USERS}")));
    };
    readable(attr, path, "users file")?;
    Users::load(path).map(Some)
}

/// Refuses a file named by `attr` that cannot be opened; the error is placed at the attribute.
fn readable(attr: &Attr, path: &Path, what: &str) -> Result<(), FileError> {
    std::fs::File::open(path)
        .map(drop)
        .map_err(|e| attr.error(format!("cannot read the {what} {}: {e}", path.display())))
}

/// Refuses a console that listens on the port of an earlier one (port 0 takes any free port).
fn distinct_addresses(specs: &[ConsoleSpec]) -> Result<(), FileError> {
    for (i, b) in specs.iter().enumerate() {
        let x = b.settings.listen;
        let clash = |a: &&ConsoleSpec| {
            let y = a.settings.listen;
            x.port() != 0
                && y.port() == x.port()
                && (y.ip() == x.ip() || y.ip().is_unspecified() || x.ip().is_unspecified())
        };
        if let Some(a) = specs[..i].iter().find(clash) {
            let msg = format!(
                "`{x}`: the console at line {} listens on {} already; give each console a port \
                 of its own",
                a.element.pos.line, a.settings.listen
            );
            return Err(match b.element.attr("listen") {
                Some(attr) => attr.error(msg),
                None => b
                    .element
                    .error(format!("{msg} (this one listens on the default)")),
            });
        }
    }
    Ok(())
}

/// Refuses a console whose session file is an earlier one's (two consoles would overwrite each
/// other's sessions).
fn distinct_sessions(specs: &[ConsoleSpec]) -> Result<(), FileError> {
    for (i, b) in specs.iter().enumerate() {
        let Some(path) = &b.sessions else {
            continue;
        };
        if let Some(a) = specs[..i]
            .iter()
            .find(|a| a.sessions.as_ref() == Some(path))
        {
            let msg = format!(
                "the console at line {} keeps its sessions in {} already; give each console a \
                 `sessions` file of its own",
                a.element.pos.line,
                path.display()
            );
            return Err(match b.element.attr("sessions") {
                Some(attr) => attr.error(msg),
                None => b.element.error(msg),
            });
        }
    }
    Ok(())
}

/// A running console.
pub struct Console {
    addr: SocketAddr,
    hub: Arc<Hub>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

impl Console {
    /// Starts a console for `spec` on `medium` with these users; `produced` are the topics the
    /// system declares. Fails when the address cannot be bound.
    pub async fn start(
        spec: &ConsoleSpec,
        users: Users,
        medium: &Medium,
        produced: Vec<Pattern>,
    ) -> Result<Console, String> {
        let listener = tokio::net::TcpListener::bind(spec.settings.listen)
            .await
            .map_err(|e| format!("console: cannot listen on {}: {e}", spec.settings.listen))?;
        let addr = listener.local_addr().map_err(|e| e.to_string())?;
        let mut hub = Hub::new(
            spec.settings.clone(),
            users,
            medium.attach("console-commands"),
            produced,
        );
        if let Some(path) = &spec.sessions {
            hub.sessions = Sessions::open(path, &hub.users);
        }
        let commanded = hub.follow_layouts();
        let mut reader = medium.attach_with("console", 1 << 14, 256);
        reader
            .subscribe_kind("**", Some(Kind::Data))
            .map_err(|e| e.to_string())?;
        // the commands others send on the layouts' command topics: what pages' inputs start
        // from, and what ends a command the console keeps
        for topic in &commanded {
            reader
                .subscribe_kind(topic.as_str(), Some(Kind::Command))
                .map_err(|e| e.to_string())?;
        }
        let hub = Arc::new(hub);
        let mut tasks = Vec::new();
        tasks.push(tokio::spawn({
            let hub = hub.clone();
            async move { hub.sessions.keep().await }
        }));
        tasks.push(tokio::spawn({
            let hub = hub.clone();
            async move { hub.read(reader).await }
        }));
        tasks.push(tokio::spawn({
            let hub = hub.clone();
            async move {
                let mut every = tokio::time::interval(WATCH_EVERY);
                loop {
                    every.tick().await;
                    hub.watch().await;
                }
            }
        }));
        // kept commands in a task of their own: a publish waiting for room on the bus never
        // holds up the watchdog
        tasks.push(tokio::spawn({
            let hub = hub.clone();
            async move {
                let mut every = tokio::time::interval(WATCH_EVERY);
                every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
                loop {
                    every.tick().await;
                    hub.keep(tokio::time::Instant::now()).await;
                }
            }
        }));
        tasks.push(tokio::spawn({
            let hub = hub.clone();
            async move {
                if let Err(e) = crate::server::serve(listener, hub).await {
                    tracing::error!(component = "console", "server stopped: {e}");
                }
            }
        }));
        tracing::info!(component = "console", "console at http://{addr}");
        Ok(Console { addr, hub, tasks })
    }

    /// Where it listens.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Its shared state.
    pub fn hub(&self) -> &Arc<Hub> {
        &self.hub
    }
}

impl Drop for Console {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
        // sessions started since the last write are kept too
        self.hub.sessions.save_now();
    }
}
