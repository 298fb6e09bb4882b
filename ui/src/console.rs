//! The `<console>` element of a system file, and a running console.
//!
//! ```xml
//! <console medium="bus" listen="127.0.0.1:8080" users="console-users.xml"
//!          layouts="console/pilot.xml console/scientist.xml" ack_timeout="5s"/>
//! ```
//!
//! [`specs`] reads the elements (`seabus check` and `seabus run` both use it); [`Console::start`]
//! binds the address, attaches to the medium and runs the [`Hub`]'s reader and watchdog and the
//! [`server`](crate::server).

use crate::hub::{Hub, Settings};
use crate::users::Users;
use seabus_medium::xml::{Element, FileError};
use seabus_medium::{Kind, Medium, Pattern};
use seabus_modules::system::SystemSpec;
use std::net::SocketAddr;
use std::path::PathBuf;
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
    /// The users file (required except where users are given in code).
    pub users: Option<PathBuf>,
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
        out.push(ConsoleSpec {
            medium,
            users: el
                .get("users")
                .map(|u| seabus_modules::system::beside(&el.pos, u)),
            settings: Settings {
                listen,
                ack_timeout: duration(el, "ack_timeout", Duration::from_secs(5))?,
                lease_role: role("lease_role", "pilot"),
                designer_role: role("designer_role", "designer"),
                log: el
                    .get("log")
                    .map(|l| seabus_modules::system::beside(&el.pos, l)),
                layouts,
            },
            element: el.clone(),
        });
    }
    Ok(out)
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
        let mut reader = medium.attach_with("console", 1 << 14, 256);
        reader
            .subscribe_kind("**", Some(Kind::Data))
            .map_err(|e| e.to_string())?;
        let hub = Arc::new(Hub::new(
            spec.settings.clone(),
            users,
            medium.attach("console-commands"),
            produced,
        ));
        let mut tasks = Vec::new();
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
    }
}
