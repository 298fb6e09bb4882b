//! Sockets for media that use IP: UDP endpoints as URLs name them ([`UdpEndpoint`]: unicast to
//! listed peers, broadcast, or a multicast group), the host's interface addresses, socket options
//! the standard library has no call for, and the datagrams waiting on a socket taken in one call
//! ([`RecvBatch`]).

use crate::url::{MediumUrl, UrlError};
use socket2::{Domain, Protocol, Socket, Type};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

/// The largest UDP payload over IPv4.
pub const MAX_DATAGRAM: usize = 65_507;
/// Default socket receive buffer.
pub const DEFAULT_RECV_BUF: usize = 4 << 20;
/// Bytes of received datagrams a medium gathers in one allocation, the payloads cut from it
/// sharing it: one allocation per chunk rather than per datagram. A chunk is given back once every
/// payload cut from it is dropped, so a quiet medium holds at most about this much in a chunk
/// filling slowly; at the allocator's threshold for mapped blocks, it goes back to the system.
pub const RECV_CHUNK: usize = 256 << 10;

/// How a UDP endpoint reaches its peers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mode {
    /// A multicast group.
    Multicast {
        /// The group address.
        group: Ipv4Addr,
        /// The interface address the group is joined on.
        iface: Ipv4Addr,
        /// Hop limit.
        ttl: u32,
    },
    /// Broadcast to an address.
    Broadcast(Ipv4Addr),
    /// Unicast to listed peers, as `(host, port)`; host names are resolved when the medium opens.
    Unicast(Vec<(String, u16)>),
}

/// A UDP endpoint's settings, read from a URL: a medium's own datagrams (`udp://`) or another
/// medium's frames over UDP (`dsaav+udp://`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UdpEndpoint {
    /// How peers are reached.
    pub mode: Mode,
    /// Local address to bind.
    pub bind: SocketAddrV4,
    /// Port datagrams are sent to (multicast and broadcast).
    pub port: u16,
    /// Multicast loopback.
    pub multicast_loop: bool,
    /// Requested receive buffer size.
    pub recv_buf: usize,
}

impl UdpEndpoint {
    /// The URL options an endpoint takes.
    pub const OPTIONS: [&'static str; 7] = [
        "ttl",
        "iface",
        "peer",
        "bind",
        "broadcast",
        "loop",
        "recv_buf",
    ];

    /// Reads the settings from a `SCHEME://HOST:PORT` URL, taking the options in
    /// [`UdpEndpoint::OPTIONS`] and leaving the rest for the caller to take and finish.
    pub fn from_url(url: &mut MediumUrl) -> Result<UdpEndpoint, UrlError> {
        let port = url
            .port
            .ok_or_else(|| url.error("needs a port (udp://HOST:PORT)"))?;
        let host: Ipv4Addr = if url.host.is_empty() {
            Ipv4Addr::UNSPECIFIED
        } else {
            url.host
                .parse()
                .map_err(|_| url.error(format!("`{}` is not an IPv4 address", url.host)))?
        };
        let ttl: Option<u32> = url.take_parsed("ttl", "a hop count 0–255")?;
        if ttl.is_some_and(|t| t > 255) {
            return Err(url.error("option `ttl`: expected a hop count 0–255"));
        }
        let iface = match url.take("iface") {
            None => None,
            Some(name) => Some(
                name.parse::<Ipv4Addr>()
                    .ok()
                    .or_else(|| interface_address(&name))
                    .ok_or_else(|| {
                        url.error(format!(
                            "option `iface={name}`: no such interface or IPv4 address"
                        ))
                    })?,
            ),
        };
        let mut peers = Vec::new();
        for p in url.take_all("peer") {
            let bad = || url.error(format!("option `peer={p}`: expected HOST:PORT"));
            let (host, port) = p.rsplit_once(':').ok_or_else(bad)?;
            let port: u16 = port.parse().map_err(|_| bad())?;
            let name_like = !host.is_empty()
                && host
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '.');
            if host.parse::<Ipv4Addr>().is_err() && !name_like {
                return Err(bad());
            }
            peers.push((host.to_string(), port));
        }
        let bind_override: Option<Ipv4Addr> = url.take_parsed("bind", "an IPv4 address")?;
        let broadcast = url.take_flag("broadcast")?.unwrap_or(false);
        let multicast_loop = url.take_flag("loop")?.unwrap_or(true);
        let recv_buf = url
            .take_parsed("recv_buf", "a size in bytes")?
            .unwrap_or(DEFAULT_RECV_BUF);

        let (mode, bind_ip) = if host.is_multicast() {
            let ttl = ttl.unwrap_or(0);
            // with ttl 0 nothing can leave this host: the loopback interface is the honest choice,
            // and it works on a machine with no network at all
            let iface = iface.unwrap_or(if ttl == 0 {
                Ipv4Addr::LOCALHOST
            } else {
                Ipv4Addr::UNSPECIFIED
            });
            (
                Mode::Multicast {
                    group: host,
                    iface,
                    ttl,
                },
                host,
            )
        } else if broadcast || host == Ipv4Addr::BROADCAST {
            (Mode::Broadcast(host), Ipv4Addr::UNSPECIFIED)
        } else {
            (Mode::Unicast(peers.clone()), host)
        };
        if !matches!(mode, Mode::Unicast(_)) && !peers.is_empty() {
            return Err(url.error(
                "option `peer` is for unicast URLs; multicast and broadcast reach every listener",
            ));
        }
        Ok(UdpEndpoint {
            mode,
            bind: SocketAddrV4::new(bind_override.unwrap_or(bind_ip), port),
            port,
            multicast_loop,
            recv_buf,
        })
    }

    /// Where datagrams go, resolving peer host names.
    pub fn destinations(&self) -> std::io::Result<Vec<SocketAddr>> {
        Ok(match &self.mode {
            Mode::Multicast { group, .. } => {
                vec![SocketAddr::V4(SocketAddrV4::new(*group, self.port))]
            }
            Mode::Broadcast(addr) => vec![SocketAddr::V4(SocketAddrV4::new(*addr, self.port))],
            Mode::Unicast(peers) => {
                let mut out = Vec::with_capacity(peers.len());
                for (host, port) in peers {
                    let addr = std::net::ToSocketAddrs::to_socket_addrs(&(host.as_str(), *port))?
                        .find(SocketAddr::is_ipv4)
                        .ok_or_else(|| {
                            std::io::Error::new(
                                std::io::ErrorKind::NotFound,
                                format!("{host} has no IPv4 address"),
                            )
                        })?;
                    out.push(addr);
                }
                out
            }
        })
    }
}

/// The first IPv4 address of a network interface.
pub fn interface_address(name: &str) -> Option<Ipv4Addr> {
    interface_addresses()
        .into_iter()
        .find(|(n, _)| n == name)
        .map(|(_, a)| a)
}

/// Every IPv4 address of this host's network interfaces, with the interface's name.
pub fn interface_addresses() -> Vec<(String, Ipv4Addr)> {
    let mut addrs: *mut libc::ifaddrs = std::ptr::null_mut();
    // SAFETY: getifaddrs fills `addrs` with a list we free below with freeifaddrs
    if unsafe { libc::getifaddrs(&mut addrs) } != 0 {
        return Vec::new();
    }
    let mut found = Vec::new();
    let mut cur = addrs;
    while !cur.is_null() {
        // SAFETY: `cur` is a node of the list getifaddrs returned, alive until freeifaddrs
        let ifa = unsafe { &*cur };
        if !ifa.ifa_addr.is_null() && !ifa.ifa_name.is_null() {
            // SAFETY: ifa_name is a NUL-terminated string owned by the list
            let ifname = unsafe { std::ffi::CStr::from_ptr(ifa.ifa_name) };
            // SAFETY: ifa_addr is non-null and points to a sockaddr of the family it states
            let family = unsafe { (*ifa.ifa_addr).sa_family };
            if i32::from(family) == libc::AF_INET {
                // SAFETY: the family is AF_INET, so the address is a sockaddr_in
                let sin = unsafe { &*(ifa.ifa_addr as *const libc::sockaddr_in) };
                found.push((
                    ifname.to_string_lossy().into_owned(),
                    Ipv4Addr::from(u32::from_be(sin.sin_addr.s_addr)),
                ));
            }
        }
        cur = ifa.ifa_next;
    }
    // SAFETY: `addrs` came from getifaddrs and is freed once
    unsafe { libc::freeifaddrs(addrs) };
    found
}

/// Sets an integer socket option that socket2 has no call for.
pub fn set_int_option(
    s: &impl std::os::fd::AsRawFd,
    level: libc::c_int,
    name: libc::c_int,
    value: libc::c_int,
) -> std::io::Result<()> {
    // SAFETY: setsockopt reads an int from a valid pointer of the stated length
    let r = unsafe {
        libc::setsockopt(
            s.as_raw_fd(),
            level,
            name,
            (&value as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Sets a socket's receive buffer to `bytes`, beyond the system's limit (`net.core.rmem_max`)
/// when the process may (`SO_RCVBUFFORCE`, for root); returns the size the kernel granted.
pub fn set_recv_buffer(s: &Socket, bytes: usize) -> usize {
    // Linux reports double what it grants (its bookkeeping overhead): compared as granted, a
    // request capped at the limit is not mistaken for one met
    let granted = |s: &Socket| s.recv_buffer_size().unwrap_or(0) / 2;
    let _ = s.set_recv_buffer_size(bytes);
    if granted(s) < bytes {
        let size = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
        // a refusal (not root) leaves the buffer as it was
        let _ = set_int_option(s, libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, size);
    }
    granted(s)
}

/// Whether the process may go beyond the system's buffer limits (it runs as root).
pub fn may_force_buffers() -> bool {
    // SAFETY: geteuid(2) has no preconditions
    unsafe { libc::geteuid() == 0 }
}

/// The send buffer a medium's socket asks for. With the kernel's default (about 200 kB: a few
/// hundred small datagrams) a sender faster than the device fills it within a millisecond and
/// stops until half is free, and the device can run dry while the sender's task is woken; with
/// this much, the datagrams of a burst wait in the kernel instead.
pub const SEND_BUFFER: usize = 1 << 20;

/// Asks for a send buffer of [`SEND_BUFFER`] on `s` (Linux grants up to `net.core.wmem_max`);
/// returns the size granted.
pub fn set_send_buffer(s: &impl std::os::fd::AsFd) -> usize {
    let s = socket2::SockRef::from(s);
    let _ = s.set_send_buffer_size(SEND_BUFFER);
    // Linux reports double what was asked for (its bookkeeping overhead)
    s.send_buffer_size().unwrap_or(0) / 2
}

/// A socket set up for an endpoint (a shared port for multicast and broadcast, the group joined, the
/// receive and send buffers sized), non-blocking, and the receive buffer the kernel granted.
pub fn socket(cfg: &UdpEndpoint) -> std::io::Result<(std::net::UdpSocket, usize)> {
    let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))?;
    let shared = !matches!(cfg.mode, Mode::Unicast(_));
    if shared {
        // several listeners on one host share a multicast or broadcast port
        s.set_reuse_address(true)?;
    }
    let got = set_recv_buffer(&s, cfg.recv_buf);
    set_send_buffer(&s);
    match &cfg.mode {
        Mode::Multicast { iface, ttl, .. } => {
            s.set_multicast_ttl_v4(*ttl)?;
            s.set_multicast_loop_v4(cfg.multicast_loop)?;
            if !iface.is_unspecified() {
                s.set_multicast_if_v4(iface)?;
            }
        }
        Mode::Broadcast(_) => s.set_broadcast(true)?,
        Mode::Unicast(_) => {}
    }
    s.bind(&SocketAddr::V4(cfg.bind).into())?;
    if let Mode::Multicast { group, iface, .. } = &cfg.mode
        && let Err(e) = s.join_multicast_v4(group, iface)
    {
        if !iface.is_unspecified() {
            return Err(e);
        }
        // no route for multicast (a machine with no network): fall back to loopback
        tracing::info!("joining {group} on the default interface failed ({e}); using loopback");
        s.join_multicast_v4(group, &Ipv4Addr::LOCALHOST)?;
        s.set_multicast_if_v4(&Ipv4Addr::LOCALHOST)?;
    }
    s.set_nonblocking(true)?;
    Ok((s.into(), got))
}

/// A socket set up for an endpoint, and the addresses its datagrams go to.
pub fn bind(cfg: &UdpEndpoint) -> std::io::Result<(std::net::UdpSocket, Vec<SocketAddr>)> {
    Ok((socket(cfg)?.0, cfg.destinations()?))
}

/// The most datagrams a [`RecvBatch`] takes in one call.
pub const MAX_RECV_BATCH: usize = 32;

/// Where one recvmmsg(2) call puts the datagrams (or frames) waiting on a socket: `count` slots of
/// `size` bytes, with each one's length and its sender's address. A datagram longer than a slot is
/// cut to it. Its slots are mapped as they are first written, so a quiet socket keeps only the
/// first resident.
pub struct RecvBatch {
    slots: Vec<u8>,
    size: usize,
    count: usize,
    addrs: Vec<libc::sockaddr_storage>,
    lens: [usize; MAX_RECV_BATCH],
    /// taken by the last call
    taken: usize,
}

impl RecvBatch {
    /// Room for `count` (at most [`MAX_RECV_BATCH`]) datagrams of up to `size` bytes.
    pub fn new(count: usize, size: usize) -> RecvBatch {
        let count = count.clamp(1, MAX_RECV_BATCH);
        RecvBatch {
            slots: vec![0; count * size],
            size,
            count,
            // SAFETY: sockaddr_storage is plain data, all zeroes is a valid value
            addrs: vec![unsafe { std::mem::zeroed() }; count],
            lens: [0; MAX_RECV_BATCH],
            taken: 0,
        }
    }

    /// Datagrams one call takes at most.
    pub fn capacity(&self) -> usize {
        self.count
    }

    /// Takes the datagrams waiting on `fd`, up to [`capacity`](Self::capacity), without waiting;
    /// `WouldBlock` when there are none. Fewer than the capacity means the socket had no more (a
    /// datagram socket reports errors by waking its readers again, so nothing else stops the call
    /// early).
    pub fn receive(&mut self, fd: std::os::fd::RawFd) -> std::io::Result<usize> {
        self.taken = 0;
        // every pointer handed to the kernel comes from these two, taken once
        let slots = self.slots.as_mut_ptr();
        let addrs = self.addrs.as_mut_ptr();
        let size = self.size;
        let mut iovs: [libc::iovec; MAX_RECV_BATCH] = std::array::from_fn(|i| libc::iovec {
            // SAFETY: `slots` holds `count` slots of `size` bytes; only the first `count` of these
            // are handed to the kernel, and slot i < count lies inside it
            iov_base: unsafe { slots.add(i.min(self.count - 1) * size) }.cast(),
            iov_len: size,
        });
        let iov = iovs.as_mut_ptr();
        // SAFETY: mmsghdr is plain data; zeroed means no control data and no flags
        let mut msgs: [libc::mmsghdr; MAX_RECV_BATCH] = unsafe { std::mem::zeroed() };
        for (i, m) in msgs.iter_mut().enumerate().take(self.count) {
            // SAFETY: `iovs` holds MAX_RECV_BATCH entries and `addrs` `count`: entry i < count
            // lies inside both
            unsafe {
                m.msg_hdr.msg_iov = iov.add(i);
                m.msg_hdr.msg_name = addrs.add(i).cast();
            }
            m.msg_hdr.msg_iovlen = 1;
            m.msg_hdr.msg_namelen =
                std::mem::size_of::<libc::sockaddr_storage>() as libc::socklen_t;
        }
        // SAFETY: each of the first `count` headers points at a slot, an iovec and an address
        // that outlive the call, with their true sizes
        let n = unsafe {
            libc::recvmmsg(
                fd,
                msgs.as_mut_ptr(),
                self.count as libc::c_uint,
                libc::MSG_DONTWAIT,
                std::ptr::null_mut(),
            )
        };
        if n < 0 {
            return Err(std::io::Error::last_os_error());
        }
        let n = n as usize;
        for (len, m) in self.lens.iter_mut().zip(&msgs[..n]) {
            *len = (m.msg_len as usize).min(size);
        }
        self.taken = n;
        Ok(n)
    }

    /// Whether a call that took `n` datagrams emptied the socket: a batch not filled did, so a
    /// reader woken by edge-triggered readiness may wait for the next datagram instead of trying a
    /// read that would block (a datagram that comes after the call is reported anew).
    pub fn drained(&self, n: usize) -> bool {
        n < self.count
    }

    /// Datagrams the last call took.
    pub fn taken(&self) -> usize {
        self.taken
    }

    /// Datagram `i` of the last call and its sender's address.
    pub fn get(&self, i: usize) -> (&libc::sockaddr_storage, &[u8]) {
        let start = i * self.size;
        (&self.addrs[i], &self.slots[start..start + self.lens[i]])
    }
}

/// The address and port of a datagram's sender as recvmmsg(2) gives it on an IP socket (IPv4, or
/// IPv6); `None` for another family.
pub fn inet(a: &libc::sockaddr_storage) -> Option<SocketAddr> {
    match i32::from(a.ss_family) {
        libc::AF_INET => {
            // SAFETY: the family says the storage holds a sockaddr_in, smaller than the storage
            // and no more strictly aligned
            let a = unsafe { &*(a as *const libc::sockaddr_storage).cast::<libc::sockaddr_in>() };
            Some(SocketAddr::from((
                Ipv4Addr::from(u32::from_be(a.sin_addr.s_addr)),
                u16::from_be(a.sin_port),
            )))
        }
        libc::AF_INET6 => {
            // SAFETY: as above, for sockaddr_in6
            let a = unsafe { &*(a as *const libc::sockaddr_storage).cast::<libc::sockaddr_in6>() };
            Some(SocketAddr::from((
                std::net::Ipv6Addr::from(a.sin6_addr.s6_addr),
                u16::from_be(a.sin6_port),
            )))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(url: &str) -> Result<UdpEndpoint, UrlError> {
        let mut url = MediumUrl::parse(url).unwrap();
        let ep = UdpEndpoint::from_url(&mut url)?;
        url.finish(&UdpEndpoint::OPTIONS)?;
        Ok(ep)
    }

    /// Beyond `net.core.rmem_max` (by half of it: within the kernel's doubled report of what it
    /// capped), root gets what it asked for; another user the limit, and says so.
    #[test]
    fn a_receive_buffer_beyond_the_limit_is_forced_for_root() {
        let max: usize = std::fs::read_to_string("/proc/sys/net/core/rmem_max")
            .expect("net.core.rmem_max")
            .trim()
            .parse()
            .expect("a number");
        let want = max + max / 2;
        let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).unwrap();
        let granted = set_recv_buffer(&s, want);
        if may_force_buffers() {
            assert!(granted >= want, "granted {granted} of {want} (limit {max})");
        } else {
            assert!(
                std::env::var_os("SEABUS_REQUIRE_PRIVILEGES").is_none_or(|v| v == "0"),
                "SEABUS_REQUIRE_PRIVILEGES is set, and this test does not run as root"
            );
            assert_eq!(granted, max, "not root: the limit");
        }
    }

    #[test]
    fn modes_follow_the_address() {
        let c = cfg("udp://239.255.42.1:47800").unwrap();
        assert_eq!(
            c.mode,
            Mode::Multicast {
                group: Ipv4Addr::new(239, 255, 42, 1),
                iface: Ipv4Addr::LOCALHOST,
                ttl: 0
            }
        );
        let c = cfg("udp://239.255.42.1:47800?ttl=1").unwrap();
        assert!(matches!(c.mode, Mode::Multicast { iface, ttl: 1, .. } if iface.is_unspecified()));
        let c = cfg("udp://255.255.255.255:5000").unwrap();
        assert_eq!(c.mode, Mode::Broadcast(Ipv4Addr::BROADCAST));
        assert_eq!(c.bind, SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, 5000));
        let c = cfg("udp://127.0.0.1:5000?peer=127.0.0.1:5001,127.0.0.1:5002").unwrap();
        assert_eq!(c.destinations().unwrap().len(), 2);
        let c = cfg("udp://239.255.42.1:47800?iface=lo").unwrap();
        assert!(matches!(c.mode, Mode::Multicast { iface, .. } if iface == Ipv4Addr::LOCALHOST));
    }

    #[test]
    fn bad_urls_say_why() {
        assert!(
            cfg("udp://239.255.42.1")
                .unwrap_err()
                .reason
                .contains("needs a port")
        );
        assert!(
            cfg("udp://example:1")
                .unwrap_err()
                .reason
                .contains("not an IPv4 address")
        );
        assert!(
            cfg("udp://239.1.1.1:1?ttl=300")
                .unwrap_err()
                .reason
                .contains("hop count")
        );
        assert!(
            cfg("udp://239.1.1.1:1?iface=nosuch0")
                .unwrap_err()
                .reason
                .contains("no such interface")
        );
        assert!(
            cfg("udp://239.1.1.1:1?peer=1.2.3.4:5")
                .unwrap_err()
                .reason
                .contains("for unicast")
        );
        assert!(
            cfg("udp://1.2.3.4:1?peer=nonsense")
                .unwrap_err()
                .reason
                .contains("HOST:PORT")
        );
        assert!(
            cfg("udp://1.2.3.4:1?max=10").is_err(),
            "not an endpoint's option"
        );
    }

    #[test]
    fn a_batch_takes_what_waits_up_to_its_capacity_with_each_sender() {
        use std::os::fd::AsRawFd;
        let rx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        rx.set_nonblocking(true).unwrap();
        let to = rx.local_addr().unwrap();
        let (a, b) = (
            std::net::UdpSocket::bind("127.0.0.1:0").unwrap(),
            std::net::UdpSocket::bind("127.0.0.1:0").unwrap(),
        );
        let mut batch = RecvBatch::new(4, 16);
        assert_eq!(batch.capacity(), 4);
        let e = batch.receive(rx.as_raw_fd()).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::WouldBlock);
        a.send_to(b"one", to).unwrap();
        b.send_to(b"a datagram longer than a slot", to).unwrap();
        a.send_to(b"", to).unwrap();
        assert_eq!(batch.receive(rx.as_raw_fd()).unwrap(), 3);
        assert_eq!(batch.taken(), 3);
        let got: Vec<(Option<SocketAddr>, &[u8])> = (0..3)
            .map(|i| (inet(batch.get(i).0), batch.get(i).1))
            .collect();
        let (a_at, b_at) = (a.local_addr().ok(), b.local_addr().ok());
        assert_eq!(
            got,
            [
                (a_at, &b"one"[..]),
                (b_at, &b"a datagram longe"[..]),
                (a_at, &b""[..])
            ]
        );
        // more than a batch waiting: a full batch, then the rest
        for i in 0..6u8 {
            a.send_to(&[i], to).unwrap();
        }
        assert_eq!(batch.receive(rx.as_raw_fd()).unwrap(), 4);
        assert_eq!(batch.get(3).1, [3]);
        assert_eq!(batch.receive(rx.as_raw_fd()).unwrap(), 2);
        assert_eq!((batch.get(0).1, batch.get(1).1), (&[4u8][..], &[5u8][..]));
        assert_eq!(RecvBatch::new(100, 8).capacity(), MAX_RECV_BATCH);
    }

    #[test]
    fn a_send_buffer_is_asked_for_up_to_what_the_system_allows() {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let granted = set_send_buffer(&s);
        let most: usize = std::fs::read_to_string("/proc/sys/net/core/wmem_max")
            .expect("net.core.wmem_max")
            .trim()
            .parse()
            .expect("a number");
        // Linux takes what is asked up to net.core.wmem_max
        assert_eq!(granted, SEND_BUFFER.min(most), "wmem_max {most}");
    }
}
