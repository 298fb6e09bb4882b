//! A medium's backbone socket: the frames waiting taken in one recvmmsg(2) call
//! ([`seabus_medium::net::RecvBatch`]), a kernel filter that drops the frames the medium sent
//! itself before they are read, and sending on a socket watched for reading only.
//!
//! A socket the runtime watches for writing too wakes its thread after every send, when the kernel
//! frees what was sent; a medium's socket is watched for reading alone, and a send that finds it
//! full waits for room on a copy of its descriptor ([`writable`]).

use super::wire;
use seabus_medium::net::RecvBatch;
use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::{AsFd, BorrowedFd, RawFd};
use tokio::io::Interest;
use tokio::io::unix::AsyncFd;

/// Frames one recvmmsg(2) call takes at most.
pub(super) const BATCH: usize = 8;

/// Where one recvmmsg(2) call puts a backbone socket's frames, up to [`BATCH`] of `size` bytes.
pub(super) fn batch(size: usize) -> RecvBatch {
    RecvBatch::new(BATCH, size)
}

/// Waits until the socket `fd` has room for a datagram, watching a copy of its descriptor for
/// writing meanwhile.
pub(super) async fn writable(fd: BorrowedFd<'_>) -> io::Result<()> {
    let copy = fd.try_clone_to_owned()?;
    // SAFETY: the copy is a descriptor of our own, owned and closed by the AsyncFd alone
    let watch = unsafe { AsyncFd::register_with_interest(copy, Interest::WRITABLE) }
        .map_err(io::Error::from)?;
    watch.writable().await?.retain_ready();
    Ok(())
}

/// Sends datagram `d` to `to` on a UDP socket watched for reading only.
pub(super) async fn send_to(
    socket: &AsyncFd<UdpSocket>,
    d: &[u8],
    to: SocketAddr,
) -> io::Result<()> {
    loop {
        match socket.get_ref().send_to(d, to) {
            Ok(_) => return Ok(()),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => writable(socket.as_fd()).await?,
            Err(e) => return Err(e),
        }
    }
}

/// A classic BPF program for frames starting at byte `at` of what a socket reads: a DSAAV frame
/// from `node` is dropped; anything else (too short to say, or not a frame of this version) is
/// accepted, keeping up to `accept` bytes. Its last instruction is the drop.
pub(super) fn skip_own(at: u32, node: u16, accept: u32) -> Vec<libc::sock_filter> {
    let op = |code: u16, jt: u8, jf: u8, k: u32| libc::sock_filter { code, jt, jf, k };
    vec![
        // ld len; jge #(at + 8), next, accept
        op(0x80, 0, 0, 0),
        op(0x35, 0, 4, at + 8),
        // ldh [at] (magic and version); jeq, next, accept
        op(0x28, 0, 0, at),
        op(
            0x15,
            0,
            2,
            u32::from(u16::from_be_bytes([wire::MAGIC, wire::VERSION])),
        ),
        // ldh [at + 6] (source node); jeq #node, drop, accept
        op(0x28, 0, 0, at + 6),
        op(0x15, 1, 0, u32::from(node)),
        // ret #accept
        op(0x06, 0, 0, accept),
        // ret #0
        op(0x06, 0, 0, 0),
    ]
}

/// Gives a socket a classic BPF filter.
pub(super) fn set_filter(fd: RawFd, program: &[libc::sock_filter]) -> io::Result<()> {
    let prog = libc::sock_fprog {
        len: u16::try_from(program.len()).map_err(|_| io::ErrorKind::InvalidInput)?,
        filter: program.as_ptr().cast_mut(),
    };
    // SAFETY: setsockopt(2) reads the program through the sock_fprog, both alive for the call
    let r = unsafe {
        libc::setsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_ATTACH_FILTER,
            (&prog as *const libc::sock_fprog).cast(),
            std::mem::size_of::<libc::sock_fprog>() as libc::socklen_t,
        )
    };
    if r < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{Address, Destination, Frame, Param};
    use std::net::UdpSocket;
    use std::os::fd::AsRawFd;

    fn frame(node: u16, count: i32) -> Vec<u8> {
        Frame {
            src: Address { node, port: 0 },
            dst: Destination::Channel(0),
            id: 1,
            kind: 1,
            reference: 0,
            params: vec![(103, Param::Int(count))],
        }
        .encode()
        .unwrap()
    }

    #[test]
    fn the_filter_drops_only_frames_from_its_node_and_a_batch_takes_what_waits() {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        rx.set_nonblocking(true).unwrap();
        set_filter(rx.as_raw_fd(), &skip_own(8, 5, u32::MAX)).unwrap();
        let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
        let to = rx.local_addr().unwrap();
        let mut other_version = frame(5, 3);
        other_version[1] = 2;
        for d in [
            frame(5, 1),
            frame(6, 2),
            other_version.clone(),
            b"D".to_vec(),
            frame(5, 4),
        ] {
            tx.send_to(&d, to).unwrap();
        }
        let mut batch = batch(2048);
        assert_eq!(batch.receive(rx.as_raw_fd()).unwrap(), 3);
        assert_eq!(batch.taken(), 3);
        let got: Vec<&[u8]> = (0..3).map(|i| batch.get(i).1).collect();
        assert_eq!(got, [&frame(6, 2)[..], &other_version[..], b"D"]);
        assert_eq!(
            seabus_medium::net::inet(batch.get(0).0),
            tx.local_addr().ok()
        );
        let e = batch.receive(rx.as_raw_fd()).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::WouldBlock);
        // more than a batch waiting: a full batch, then the rest
        for i in 0..=BATCH as i32 {
            tx.send_to(&frame(7, i), to).unwrap();
        }
        assert_eq!(batch.receive(rx.as_raw_fd()).unwrap(), BATCH);
        assert_eq!(batch.receive(rx.as_raw_fd()).unwrap(), 1);
        assert_eq!(batch.get(0).1, &frame(7, BATCH as i32)[..]);
    }

    #[tokio::test]
    async fn a_full_socket_watched_for_reading_only_is_waited_on_until_it_has_room() {
        use std::os::unix::net::UnixDatagram;
        use std::time::Duration;
        let (a, b) = UnixDatagram::pair().unwrap();
        a.set_nonblocking(true).unwrap();
        // SAFETY: the socket is owned by the AsyncFd and closed only by it
        let a = unsafe { AsyncFd::register_with_interest(a, Interest::READABLE) }.unwrap();
        // the reader takes nothing yet: the writer fills up
        let mut sent = 0;
        while a.get_ref().send(&[1; 64]).is_ok() {
            sent += 1;
        }
        assert!(sent > 0);
        let wait = writable(a.as_fd());
        tokio::pin!(wait);
        let early = tokio::time::timeout(Duration::from_millis(50), &mut wait).await;
        assert!(early.is_err(), "no room yet");
        b.set_nonblocking(true).unwrap();
        let mut read = 0;
        while b.recv(&mut [0; 64]).is_ok() {
            read += 1;
        }
        assert_eq!(read, sent);
        tokio::time::timeout(Duration::from_secs(5), wait)
            .await
            .expect("room once the reader took what waited")
            .unwrap();
        a.get_ref().send(&[2; 64]).unwrap();
    }
}
