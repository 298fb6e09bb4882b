//! The real lcm-gen, found and run: the reference the LCM type and codec tests check seabus against.
//! Shared by the LCM tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// An lcm-gen to run: the command and its version.
pub struct Generator {
    /// The program and its first arguments.
    pub command: Vec<String>,
    /// The version it reports.
    pub version: (u32, u32, u32),
}

impl Generator {
    /// Runs it with `args` in `dir`; its output.
    pub fn run(&self, dir: &Path, args: &[&str]) -> Output {
        let (program, first) = self.command.split_first().expect("a command");
        Command::new(program)
            .args(first)
            .args(args)
            .current_dir(dir)
            .output()
            .unwrap_or_else(|e| panic!("cannot run {:?}: {e}", self.command))
    }

    /// The command and its version, for messages.
    pub fn name(&self) -> String {
        let (a, b, c) = self.version;
        format!("{} ({a}.{b}.{c})", self.command.join(" "))
    }
}

/// The version an lcm-gen reports (`lcm-gen 1.5.3`), if it runs.
fn version(command: &[String]) -> Option<(u32, u32, u32)> {
    let (program, first) = command.split_first()?;
    let out = Command::new(program)
        .args(first)
        .arg("--version")
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let v = text.split_whitespace().nth(1)?;
    let mut parts = v.split('.').map(|p| p.parse().ok());
    Some((parts.next()??, parts.next()??, parts.next()??))
}

/// The executable `name` names: on PATH, or as given when it holds a `/`.
fn executable(name: &str) -> Option<PathBuf> {
    if name.contains('/') {
        return Path::new(name).canonicalize().ok();
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| p.is_file())
        .and_then(|p| p.canonicalize().ok())
}

/// Every lcm-gen found, one per version: the one on PATH, Debian's `/usr/bin/lcm-gen` and, with
/// `python_package`, the one of the Python package `lcm`; fails, saying how to install one, when
/// there is none.
pub fn generators(python_package: bool) -> Vec<Generator> {
    let mut seen = Vec::new();
    let mut out: Vec<Generator> = Vec::new();
    for name in ["lcm-gen", "/usr/bin/lcm-gen"] {
        let Some(exe) = executable(name) else {
            continue;
        };
        if seen.contains(&exe) {
            continue;
        }
        let command = vec![exe.display().to_string()];
        if let Some(version) = version(&command).filter(|v| out.iter().all(|g| g.version != *v)) {
            seen.push(exe);
            out.push(Generator { command, version });
        }
    }
    if python_package {
        let python = [
            "python3",
            "-c",
            "import sys; from lcm import run_gen; sys.argv[0] = 'lcm-gen'; run_gen()",
        ]
        .map(String::from)
        .to_vec();
        if let Some(version) = version(&python).filter(|v| out.iter().all(|g| g.version != *v)) {
            out.push(Generator {
                command: python,
                version,
            });
        }
    }
    assert!(
        !out.is_empty(),
        "lcm-gen is not installed: run ./scripts/test, or install Debian's liblcm-bin or Python's \
         lcm package (pip install lcm)"
    );
    out
}
