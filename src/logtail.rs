//! `seabus log tail`: follows a central log file as the logging server writes it, across rotation.

use std::fs::File;
use std::io::{BufRead, BufReader, Seek, SeekFrom, Write};
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// The last `n` lines of `text`.
fn last_lines(text: &str, n: usize) -> Vec<&str> {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].to_vec()
}

/// Prints the last `lines` lines of `path`, then every line written to it until `duration` passes
/// (or for ever); a rotated file (renamed, a new one begun) is followed to the new one.
pub fn tail(path: &Path, lines: usize, duration: Option<Duration>) -> ExitCode {
    let deadline = duration.map(|d| Instant::now() + d);
    let open = |path: &Path| -> std::io::Result<(BufReader<File>, u64)> {
        let f = File::open(path)?;
        let inode = f.metadata()?.ino();
        Ok((BufReader::new(f), inode))
    };
    let (mut reader, mut inode) = match open(path) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("seabus log tail: {}: {e}", path.display());
            return ExitCode::from(2);
        }
    };
    let mut out = std::io::stdout().lock();
    let mut start = String::new();
    if let Err(e) = std::io::Read::read_to_string(&mut reader, &mut start) {
        eprintln!("seabus log tail: {}: {e}", path.display());
        return ExitCode::from(2);
    }
    for l in last_lines(&start, lines) {
        let _ = writeln!(out, "{l}");
    }
    let _ = out.flush();
    let mut line = String::new();
    while deadline.is_none_or(|d| Instant::now() < d) {
        line.clear();
        match reader.read_line(&mut line) {
            Ok(0) => {
                // at the end: a new file in its place means the log was rotated
                let moved = std::fs::metadata(path).is_ok_and(|m| m.ino() != inode);
                if moved && let Ok(r) = open(path) {
                    (reader, inode) = r;
                    continue;
                }
                // a file cut short (rotation without renaming) is read again from its start
                if let (Ok(pos), Ok(m)) = (reader.stream_position(), std::fs::metadata(path))
                    && m.len() < pos
                {
                    let _ = reader.seek(SeekFrom::Start(0));
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            Ok(_) if line.ends_with('\n') => {
                let _ = out.write_all(line.as_bytes());
                let _ = out.flush();
            }
            // half a line: wait for the rest
            Ok(n) => {
                let _ = reader.seek(SeekFrom::Current(-(n as i64)));
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(e) => {
                eprintln!("seabus log tail: {}: {e}", path.display());
                return ExitCode::from(1);
            }
        }
    }
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_lines_are_kept() {
        assert_eq!(last_lines("a\nb\nc\n", 2), vec!["b", "c"]);
        assert_eq!(last_lines("a\n", 5), vec!["a"]);
        assert!(last_lines("", 3).is_empty());
    }
}
