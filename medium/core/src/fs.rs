//! Writing files so that a crash or a power cut leaves the old file or the new one, never half of
//! one: every file seabus writes whole (users, layouts, configuration, a recording's side files)
//! goes through [`atomic_write`].

use std::ffi::OsString;
use std::fs::{OpenOptions, Permissions};
use std::io::{self, Write};
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Replaces the file at `path` with `contents` atomically: writes a temporary file with a name of
/// its own (`.NAME.PID.N.tmp`, so that two writers never share one) in the same directory, syncs
/// it, gives it the permissions of the file it replaces, renames it over `path` and syncs the
/// directory. A new file gets `0o644` less the process's umask.
pub fn atomic_write(path: &Path, contents: &[u8]) -> io::Result<()> {
    atomic_write_with(path, contents, 0o644, true)
}

/// [`atomic_write`] for a file that holds secrets: a new file gets `0o600`; an existing one keeps
/// its permissions.
pub fn atomic_write_private(path: &Path, contents: &[u8]) -> io::Result<()> {
    atomic_write_with(path, contents, 0o600, true)
}

/// [`atomic_write`] for a file only its owner may ever read or write (what grants access, such as
/// log-in sessions): `0o600`, whatever the file it replaces had.
pub fn atomic_write_owner_only(path: &Path, contents: &[u8]) -> io::Result<()> {
    atomic_write_with(path, contents, 0o600, false)
}

fn atomic_write_with(path: &Path, contents: &[u8], new_mode: u32, keep: bool) -> io::Result<()> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} does not name a file", path.display()),
        )
    })?;
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let kept = match std::fs::metadata(path) {
        Ok(m) => keep.then(|| m.permissions()),
        Err(e) if e.kind() == io::ErrorKind::NotFound => None,
        Err(e) => return Err(e),
    };
    let mut temp_name = OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(
        ".{}.{}.tmp",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let temp = dir.join(temp_name);
    let written = (|| {
        let mut file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(new_mode)
            .open(&temp)?;
        file.write_all(contents)?;
        if let Some(p) = &kept {
            file.set_permissions(Permissions::from_mode(p.mode()))?;
        }
        file.sync_all()?;
        drop(file);
        std::fs::rename(&temp, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&temp);
        return Err(e);
    }
    std::fs::File::open(dir)?.sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_replaced_whole_and_keeps_its_permissions() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("users.xml");
        atomic_write_private(&path, b"first").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"first");
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&path), 0o600, "a new private file is 0600");
        std::fs::set_permissions(&path, Permissions::from_mode(0o640)).unwrap();
        atomic_write(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        assert_eq!(
            mode(&path),
            0o640,
            "the permissions of the file replaced are kept"
        );
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(
            left,
            vec![OsString::from("users.xml")],
            "no temporary file is left"
        );
    }

    #[test]
    fn writers_in_parallel_never_share_a_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("layout.xml");
        let threads: Vec<_> = (0..8)
            .map(|i| {
                let path = path.clone();
                std::thread::spawn(move || {
                    for _ in 0..20 {
                        atomic_write(&path, format!("writer {i}").repeat(100).as_bytes()).unwrap();
                    }
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let first = &text[..8];
        assert_eq!(
            text,
            first.repeat(100),
            "the file is one writer's whole text"
        );
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cfg");
        atomic_write(&path, b"old").unwrap();
        // a directory where the file should be: the rename fails
        let blocked = dir.path().join("sub");
        std::fs::create_dir(&blocked).unwrap();
        std::fs::create_dir(blocked.join("x")).unwrap();
        assert!(atomic_write(&blocked, b"new").is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert!(
            atomic_write(Path::new("/"), b"x").is_err(),
            "a path without a file name"
        );
    }
}
