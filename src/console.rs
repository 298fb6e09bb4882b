//! Starting the consoles a system file asks for (`<console>`), the demo's console with its own
//! users, and `seabus user add`.

use seabus_modules::system::SystemSpec;
use seabus_modules::{Catalogue, Registry, Runtime};
use seabus_ui::console::{self, Console};
use seabus_ui::users::{self, Users};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The demo's layouts, built in: written to a directory of their own when the demo starts, so the
/// designer can save them there.
const DEMO_LAYOUTS: [(&str, &str); 2] = [
    ("pilot.xml", include_str!("../configs/console/pilot.xml")),
    (
        "scientist.xml",
        include_str!("../configs/console/scientist.xml"),
    ),
];

/// The demo's users: name and roles; their passwords are made at each start and printed.
const DEMO_USERS: [(&str, &[&str]); 4] = [
    ("pilot", &["pilot", "designer"]),
    ("copilot", &["pilot"]),
    ("scientist", &["scientist"]),
    ("observer", &["observer"]),
];

/// Starts every console of `spec` on the runtime's media. In the demo (`demo_dir` given) the
/// consoles get the demo's users, with fresh passwords printed, and the built-in layouts written
/// there; elsewhere a console needs its users file.
pub async fn start(
    spec: &SystemSpec,
    registry: &Registry,
    runtime: &Runtime,
    demo_dir: Option<&Path>,
) -> Result<Vec<Console>, String> {
    let specs = console::specs(spec).map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    for mut cs in specs {
        let users = match (demo_dir, &cs.users) {
            (Some(dir), _) => {
                let mut layouts = Vec::new();
                for (name, text) in DEMO_LAYOUTS {
                    let path = dir.join(name);
                    std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
                    layouts.push(path);
                }
                cs.settings.layouts = layouts;
                demo_users()?
            }
            (None, Some(path)) => Users::load(path).map_err(|e| e.to_string())?,
            (None, None) => {
                return Err(cs
                    .element
                    .error(
                        "a console needs `users`, a users file with password hashes (`seabus user \
                         add FILE NAME --roles pilot` writes one); only `seabus demo` makes its own \
                         users",
                    )
                    .to_string());
            }
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
            // the demo takes any free port when its usual one is taken
            Err(e) if demo_dir.is_some() => {
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

/// The demo's users with fresh passwords, printed.
fn demo_users() -> Result<Users, String> {
    let passwords: Vec<String> = DEMO_USERS
        .iter()
        .map(|_| users::random_password())
        .collect::<Result<_, _>>()?;
    let list: Vec<(&str, &[&str], &str)> = DEMO_USERS
        .iter()
        .zip(&passwords)
        .map(|((name, roles), pw)| (*name, *roles, pw.as_str()))
        .collect();
    let users = Users::with_passwords(&list)?;
    eprintln!("  The console's users for this run (name / password / roles):");
    for (name, roles, pw) in &list {
        eprintln!("    {name:<10} {pw}   {}", roles.join(", "));
    }
    Ok(users)
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

/// A directory of the demo's own, under the system's temporary directory.
pub fn demo_dir() -> Result<PathBuf, String> {
    let dir = std::env::temp_dir().join(format!("seabus-demo-console-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    Ok(dir)
}
