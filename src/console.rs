//! Starting the consoles a system file asks for (`<console>`), the demo's console with its own
//! users, and `seabus user add`.

use seabus_modules::system::SystemSpec;
use seabus_modules::{Catalogue, Registry, Runtime};
use seabus_ui::console::{self, Console};
use seabus_ui::users::{self, Users};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The demo's files besides its system file, built in: written with it to a directory of its
/// own when the demo starts, where its relative paths find them (and the designer can save).
const DEMO_FILES: [(&str, &str); 3] = [
    (
        "console/pilot.xml",
        include_str!("../configs/console/pilot.xml"),
    ),
    (
        "console/scientist.xml",
        include_str!("../configs/console/scientist.xml"),
    ),
    (
        "demo-health.xml",
        include_str!("../configs/demo-health.xml"),
    ),
];

/// The one-time users of a console on a loopback address without a users file (the demo's):
/// name and roles; their passwords are made at each start and printed.
const DEMO_USERS: [(&str, &[&str]); 4] = [
    ("pilot", &["pilot", "designer"]),
    ("copilot", &["pilot"]),
    ("scientist", &["scientist"]),
    ("observer", &["observer"]),
];

/// Starts the consoles [`console::check`] made ready, on the runtime's media. The demo's take any
/// free port when their usual one is taken.
pub async fn start(
    ready: Vec<console::Ready>,
    spec: &SystemSpec,
    registry: &Registry,
    runtime: &Runtime,
    demo: bool,
) -> Result<Vec<Console>, String> {
    let mut out = Vec::new();
    for console::Ready {
        spec: mut cs,
        users,
        ..
    } in ready
    {
        let Some(users) = users else {
            return Err(cs.element.error("the console has no users").to_string());
        };
        let Some(medium) = runtime.medium(&cs.medium) else {
            return Err(cs
                .element
                .error(format!("no medium `{}`", cs.medium))
                .to_string());
        };
        let produced: Vec<seabus_medium::Pattern> =
            seabus_ui::layout::producers(spec, registry, &Catalogue::built_in(), &cs.medium)
                .into_iter()
                .map(|p| p.pattern)
                .collect();
        let console = match Console::start(&cs, users.clone(), medium, produced.clone()).await {
            Err(e) if demo => {
                eprintln!("  {e}; the console takes another port");
                cs.settings.listen.set_port(0);
                Console::start(&cs, users, medium, produced).await?
            }
            other => other?,
        };
        out.push(console);
    }
    Ok(out)
}

/// Gives the consoles without a users file (those on a loopback address) one-time users: the
/// demo's names and roles with fresh passwords, made once for all of them, and printed.
pub fn one_time_users(ready: &mut [console::Ready]) -> Result<(), String> {
    if ready.iter().all(|r| r.users.is_some()) {
        return Ok(());
    }
    let passwords: Vec<String> = DEMO_USERS
        .iter()
        .map(|_| users::random_password())
        .collect::<Result<_, _>>()?;
    let list: Vec<(&str, &[&str], &str)> = DEMO_USERS
        .iter()
        .zip(&passwords)
        .map(|((name, roles), pw)| (*name, *roles, pw.as_str()))
        .collect();
    let made = Users::with_passwords(&list)?;
    eprintln!("  The console's users for this run (name / password / roles):");
    for (name, roles, pw) in &list {
        eprintln!("    {name:<10} {pw}   {}", roles.join(", "));
    }
    for r in ready.iter_mut().filter(|r| r.users.is_none()) {
        r.users = Some(made.clone());
    }
    Ok(())
}

/// `seabus user add FILE NAME --roles "…"`: asks for the password (twice on a terminal, once
/// from a pipe) and writes the user.
pub fn user_add(file: &Path, name: &str, roles: &str) -> ExitCode {
    let roles: Vec<String> = roles.split_whitespace().map(str::to_string).collect();
    let password = match read_password(name) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("seabus user add: {e}");
            return ExitCode::from(2);
        }
    };
    match users::add_user(file, name, &roles, &password) {
        Ok(()) => {
            eprintln!("{}: user {name} ({})", file.display(), roles.join(", "));
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("seabus user add: {e}");
            ExitCode::from(2)
        }
    }
}

fn read_password(name: &str) -> Result<String, String> {
    use std::io::IsTerminal;
    if std::io::stdin().is_terminal() {
        let first = rpassword::prompt_password(format!("password for {name}: "))
            .map_err(|e| e.to_string())?;
        let again = rpassword::prompt_password("again: ").map_err(|e| e.to_string())?;
        if first != again {
            return Err("the passwords differ".into());
        }
        Ok(first)
    } else {
        let mut line = String::new();
        std::io::stdin()
            .read_line(&mut line)
            .map_err(|e| e.to_string())?;
        Ok(line.trim_end_matches(['\n', '\r']).to_string())
    }
}

/// Writes the demo's system file `text` and its other files to a directory of its own under the
/// system's temporary directory; returns the directory and the system file's path.
pub fn write_demo(text: &str) -> Result<(PathBuf, PathBuf), String> {
    let dir = std::env::temp_dir().join(format!("seabus-demo-{}", std::process::id()));
    let write = |rel: &str, text: &str| -> Result<PathBuf, String> {
        let path = dir.join(rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        seabus_medium::fs::atomic_write(&path, text.as_bytes())
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(path)
    };
    for (rel, body) in DEMO_FILES {
        write(rel, body)?;
    }
    let system = write("demo.xml", text)?;
    Ok((dir, system))
}

/// Starts the Foxglove servers a system file asks for (`<foxglove>`), on the runtime's media. The
/// demo's takes any free port when its usual one is taken.
pub async fn start_foxglove(
    spec: &SystemSpec,
    runtime: &Runtime,
    demo: bool,
) -> Result<Vec<seabus_ui::foxglove::Foxglove>, String> {
    use seabus_ui::foxglove::{Foxglove, specs};
    let mut out = Vec::new();
    for mut fs in specs(spec).map_err(|e| e.to_string())? {
        let Some(medium) = runtime.medium(&fs.medium) else {
            return Err(fs
                .element
                .error(format!("no medium `{}`", fs.medium))
                .to_string());
        };
        let server = match Foxglove::start(&fs, medium, Catalogue::built_in()).await {
            Err(e) if demo => {
                eprintln!("  {e}; the Foxglove server takes another port");
                fs.listen.set_port(0);
                Foxglove::start(&fs, medium, Catalogue::built_in()).await?
            }
            other => other?,
        };
        out.push(server);
    }
    Ok(out)
}
