//! seabus-tty: serial devices and pseudo-terminals, for the media that run over a serial line (the
//! serial medium, slcan CAN adapters).
//!
//! - [`device_path`] reads the device of a `SCHEME:///path/to/device` URL.
//! - [`open_device`] opens a device for a link kept by [`seabus_medium::link`] (which reopens it
//!   when it goes away).
//! - [`run_pty`] makes a pseudo-terminal whose other end is linked at a path of the user's choice,
//!   for any program to open as if it were a device, and runs a session on it; [`PtyLink`] removes
//!   that link when the medium closes.
//! - [`Overruns`] reads how many characters a serial device lost before they were read: the
//!   kernel's overrun counters (`TIOCGICOUNT`), where the device's driver keeps them.
//!
//! Who may depend on it: medium crates whose wire is a serial line. It depends on the core only.

use seabus_medium::link::LinkQueue;
use seabus_medium::url::{MediumUrl, UrlError};
use seabus_medium::{BoxFuture, LinkState, OpenError, Opening};
use std::os::fd::{AsRawFd, RawFd};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
pub use tokio_serial::SerialStream;

/// The device path of a `SCHEME:///path` URL.
pub fn device_path(url: &MediumUrl) -> Result<PathBuf, UrlError> {
    if !url.host.is_empty() || url.path.len() < 2 {
        return Err(url.error(format!(
            "expected {}:///path/to/device (three slashes, an absolute path)",
            url.scheme
        )));
    }
    Ok(PathBuf::from(&url.path))
}

/// Opens the device at `path` at `baud`, with the other settings `configure` makes; the error
/// names the device.
pub fn open_device(
    path: &Path,
    baud: u32,
    configure: impl FnOnce(tokio_serial::SerialPortBuilder) -> tokio_serial::SerialPortBuilder,
) -> Result<SerialStream, String> {
    let name = path.to_string_lossy();
    let builder = configure(tokio_serial::new(name.as_ref(), baud));
    tokio_serial::SerialPortBuilderExt::open_native_async(builder)
        .map_err(|e| format!("cannot open {name}: {e}"))
}

/// The overrun counters of a serial device, as the kernel keeps them: characters the UART's
/// hardware FIFO lost (`overrun`) and characters the kernel's buffer had no room for
/// (`buf_overrun`). A device whose driver keeps no counters (a pseudo-terminal, some USB
/// adapters) has none: [`Overruns::of`] says so once, and nothing is asked again.
#[derive(Debug)]
pub struct Overruns {
    fd: RawFd,
    /// the sum of both counters when last read
    last: u32,
}

impl Overruns {
    /// The counters of the device open as `port`, read now so that later reads count from here;
    /// `None` when the device keeps none. `port` must stay open while this is used.
    pub fn of(port: &impl AsRawFd) -> Option<Overruns> {
        let fd = port.as_raw_fd();
        overrun_count(fd).ok().map(|last| Overruns { fd, last })
    }

    /// Characters lost since the last look (0 when the device can no longer be asked).
    pub fn take(&mut self) -> u64 {
        match overrun_count(self.fd) {
            Ok(now) => {
                let new = since(self.last, now);
                self.last = now;
                new
            }
            Err(_) => 0,
        }
    }
}

/// How far a kernel counter (a C `int` that wraps) went from `before` to `now`.
fn since(before: u32, now: u32) -> u64 {
    u64::from(now.wrapping_sub(before))
}

/// `struct serial_icounter_struct` of `<linux/serial.h>`.
#[cfg(target_os = "linux")]
#[repr(C)]
#[derive(Default)]
struct IcounterStruct {
    cts: libc::c_int,
    dsr: libc::c_int,
    rng: libc::c_int,
    dcd: libc::c_int,
    rx: libc::c_int,
    tx: libc::c_int,
    frame: libc::c_int,
    overrun: libc::c_int,
    parity: libc::c_int,
    brk: libc::c_int,
    buf_overrun: libc::c_int,
    reserved: [libc::c_int; 9],
}

/// The device's `overrun` and `buf_overrun` counters, summed (wrapping as the kernel's do); an
/// error when its driver keeps none (`EINVAL`, `ENOTTY`: a pseudo-terminal).
#[cfg(target_os = "linux")]
fn overrun_count(fd: RawFd) -> std::io::Result<u32> {
    let mut counts = IcounterStruct::default();
    // SAFETY: TIOCGICOUNT writes one serial_icounter_struct, which `counts` is, and nothing else
    let r = unsafe { libc::ioctl(fd, libc::TIOCGICOUNT, &mut counts as *mut IcounterStruct) };
    if r < 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok((counts.overrun as u32).wrapping_add(counts.buf_overrun as u32))
}

/// Elsewhere the counters are not read.
#[cfg(not(target_os = "linux"))]
fn overrun_count(_: RawFd) -> std::io::Result<u32> {
    Err(std::io::Error::from(std::io::ErrorKind::Unsupported))
}

/// The link at which a pseudo-terminal's other end is found, removed when the medium closes.
pub struct PtyLink(Mutex<Option<PathBuf>>);

impl PtyLink {
    /// Removes the link (once).
    pub fn remove(&self) {
        if let Some(link) = self.0.lock().unwrap_or_else(|p| p.into_inner()).take() {
            let _ = std::fs::remove_file(link);
        }
    }
}

impl Drop for PtyLink {
    fn drop(&mut self) {
        self.remove();
    }
}

/// Makes a pseudo-terminal linked at `at` and runs `session` on its master side until it fails:
/// the link is up meanwhile, down with the reason after (a pseudo-terminal is not reopened).
pub fn run_pty<F: Send + 'static>(
    o: &Opening,
    at: &Path,
    mut queue: LinkQueue<F>,
    session: impl for<'q> FnOnce(SerialStream, &'q mut LinkQueue<F>) -> BoxFuture<'q, String>
    + Send
    + 'static,
) -> Result<PtyLink, OpenError> {
    let (master, held) = new_pty(o, at)?;
    let ingress = o.ingress.clone();
    queue.set_up(true);
    let task = tokio::spawn(async move {
        let _held = held;
        let reason = session(master, &mut queue).await;
        queue.set_up(false);
        ingress.set_link(LinkState::Down(reason));
        queue.drop_waiting();
    });
    o.ingress.own_task(task.abort_handle());
    o.ingress.set_link(LinkState::Up);
    Ok(PtyLink(Mutex::new(Some(at.to_path_buf()))))
}

/// A new pseudo-terminal whose other end is linked at `at`: its master side, and the other end
/// held open (by a plain file, without the lock a serial port takes, so that any program can open
/// it) so that the terminal lives while nobody has it open.
fn new_pty(o: &Opening, at: &Path) -> Result<(SerialStream, std::fs::File), OpenError> {
    let (master, slave) = SerialStream::pair()
        .map_err(|e| std::io::Error::other(e.to_string()))
        .map_err(o.io_error("creating a pseudo-terminal"))?;
    let slave_path = tokio_serial::SerialPort::name(&slave)
        .ok_or_else(|| std::io::Error::other("the pseudo-terminal has no name"))
        .map_err(o.io_error("naming the pseudo-terminal"))?;
    let held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&slave_path)
        .map_err(o.io_error(format!("opening {slave_path}")))?;
    drop(slave);
    link(at, Path::new(&slave_path)).map_err(o.io_error(format!("linking {}", at.display())))?;
    Ok((master, held))
}

/// Links `at` to `target`, replacing an earlier link but never a file or directory.
fn link(at: &Path, target: &Path) -> std::io::Result<()> {
    match std::fs::symlink_metadata(at) {
        Ok(m) if m.file_type().is_symlink() => std::fs::remove_file(at)?,
        Ok(_) => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "something other than a link is there; seabus only replaces its own links",
            ));
        }
        Err(_) => {}
    }
    std::os::unix::fs::symlink(target, at)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_urls_need_an_absolute_path() {
        let p = |u: &str| device_path(&MediumUrl::parse(u).unwrap());
        assert_eq!(
            p("serial:///dev/ttyUSB0").unwrap(),
            PathBuf::from("/dev/ttyUSB0")
        );
        assert!(
            p("serial://dev/ttyUSB0")
                .unwrap_err()
                .reason
                .contains("three slashes")
        );
    }

    #[test]
    fn overrun_counts_go_on_across_the_wrap_of_the_kernels_counters() {
        assert_eq!(since(10, 10), 0);
        assert_eq!(since(10, 17), 7);
        assert_eq!(since(u32::MAX - 2, 4), 7);
        assert_eq!(since(i32::MAX as u32, i32::MIN as u32), 1);
    }

    #[tokio::test]
    async fn a_pseudo_terminal_keeps_no_overrun_counters() {
        let (master, slave) = SerialStream::pair().unwrap();
        assert!(Overruns::of(&master).is_none());
        assert!(Overruns::of(&slave).is_none());
        // nor does a file that is no terminal
        let file = tempfile::tempfile().unwrap();
        assert!(Overruns::of(&file).is_none());
    }

    #[test]
    fn a_link_never_replaces_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let at = dir.path().join("gps");
        std::fs::write(&at, "data").unwrap();
        let e = link(&at, Path::new("/dev/null")).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::AlreadyExists);
        std::fs::remove_file(&at).unwrap();
        link(&at, Path::new("/dev/null")).unwrap();
        link(&at, Path::new("/dev/zero")).unwrap();
        assert_eq!(std::fs::read_link(&at).unwrap(), PathBuf::from("/dev/zero"));
    }
}
