//! A MAVLink medium's URL: where its wire is and who it is on it.
//!
//! ```text
//! mavlink://udpin:0.0.0.0:14550            listens; answers every peer heard (a ground station's usual port)
//! mavlink://udpout:192.168.2.2:14550       sends there and hears the answers (a vehicle listening)
//! mavlink://udpbcast:192.168.2.255:14550   broadcasts there and hears the answers
//! mavlink://tcpout:127.0.0.1:5760          connects (ArduPilot's SITL), again when the connection is lost
//! mavlink://tcpin:0.0.0.0:5760             listens; one client at a time
//! mavlink://serial/dev/ttyUSB0:57600       a serial device at a baud rate (57600 when left out)
//! ```
//!
//! The address forms are the `mavlink` crate's (and MAVProxy's), written after `mavlink://`; a
//! serial device is written `serial/DEVICE[:BAUD]`, with a slash where the crate writes a colon.
//!
//! Options: `sysid` and `compid` (this medium's system and component ids on the wire, default
//! 255 and 190, a ground station's), `dialect` (`ardupilotmega`, the default, or `common`),
//! `heartbeat` (how often this medium sends its own HEARTBEAT, default `1s`; `0` sends none),
//! `role` (what that heartbeat says this medium is: `gcs`, the default, or `companion`),
//! `version` (the MAVLink version it sends, `2` by default or `1`; both are read), `timeout` (how
//! long a vehicle's heartbeat counts, default `3s`), and for `tcpout` and `serial` `reopen` and
//! `reopen_max` (waits between attempts to connect or reopen: 500ms doubling up to 5s;
//! [`Backoff`]).

use crate::dialect::Dialect;
use crate::frame::MAX_FRAME;
use mavlink::MavlinkVersion;
use seabus_medium::caps::{Capabilities, Carries, Framing};
use seabus_medium::link::Backoff;
use seabus_medium::parse::parse_duration;
use seabus_medium::url::{MediumUrl, UrlError};
use std::fmt;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, SocketAddrV4};
use std::path::PathBuf;
use std::time::Duration;

/// Where a MAVLink medium's wire is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Address {
    /// `udpin:ADDRESS:PORT`: listens there and sends to every peer heard.
    UdpIn(SocketAddr),
    /// `udpout:HOST:PORT`: sends there and hears what comes back.
    UdpOut(String, u16),
    /// `udpbcast:ADDRESS:PORT`: broadcasts there (IPv4) and hears what comes back.
    UdpBcast(SocketAddrV4),
    /// `tcpout:HOST:PORT`: connects there.
    TcpOut(String, u16),
    /// `tcpin:ADDRESS:PORT`: listens there for one client at a time.
    TcpIn(SocketAddr),
    /// `serial/DEVICE:BAUD`: a serial device.
    Serial(PathBuf, u32),
}

impl Address {
    /// Whether the wire is UDP (one frame per datagram).
    pub fn is_udp(&self) -> bool {
        matches!(
            self,
            Address::UdpIn(_) | Address::UdpOut(..) | Address::UdpBcast(_)
        )
    }
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Address::UdpIn(a) => write!(f, "udpin:{a}"),
            Address::UdpOut(h, p) => write!(f, "udpout:{h}:{p}"),
            Address::UdpBcast(a) => write!(f, "udpbcast:{a}"),
            Address::TcpOut(h, p) => write!(f, "tcpout:{h}:{p}"),
            Address::TcpIn(a) => write!(f, "tcpin:{a}"),
            Address::Serial(d, b) => write!(f, "serial {}:{b}", d.display()),
        }
    }
}

/// What this medium's own heartbeat says it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A ground control station (`MAV_TYPE_GCS`).
    Gcs,
    /// A companion computer on the vehicle (`MAV_TYPE_ONBOARD_CONTROLLER`).
    Companion,
}

impl Role {
    /// The `MAV_TYPE` its heartbeat carries.
    pub fn mav_type(self) -> &'static str {
        match self {
            Role::Gcs => "MAV_TYPE_GCS",
            Role::Companion => "MAV_TYPE_ONBOARD_CONTROLLER",
        }
    }
}

/// A MAVLink medium's settings, read from its URL.
#[derive(Debug, Clone, PartialEq)]
pub struct MavlinkConfig {
    /// Where the wire is.
    pub address: Address,
    /// This medium's system id.
    pub sysid: u8,
    /// This medium's component id.
    pub compid: u8,
    /// The message set.
    pub dialect: Dialect,
    /// How often this medium's own HEARTBEAT goes out; `None`: never.
    pub heartbeat: Option<Duration>,
    /// What that heartbeat says this medium is.
    pub role: Role,
    /// The MAVLink version of what it sends.
    pub version: MavlinkVersion,
    /// How long a vehicle's heartbeat counts.
    pub timeout: Duration,
    /// Waits between attempts to connect or reopen.
    pub reopen: Backoff,
}

/// The options a `mavlink://` URL takes.
pub const OPTIONS: &[&str] = &[
    "sysid",
    "compid",
    "dialect",
    "heartbeat",
    "role",
    "version",
    "timeout",
    "reopen",
    "reopen_max",
];

const FORMS: &str = "expected mavlink://udpin:ADDRESS:PORT, udpout:HOST:PORT, \
     udpbcast:ADDRESS:PORT, tcpout:HOST:PORT, tcpin:ADDRESS:PORT or serial/DEVICE:BAUD \
     (mavlink://serial/dev/ttyUSB0:57600)";

/// A host as written, without IPv6 brackets.
fn unbracket(host: &str) -> &str {
    host.strip_prefix('[')
        .and_then(|h| h.strip_suffix(']'))
        .unwrap_or(host)
}

fn address(url: &MediumUrl) -> Result<Address, UrlError> {
    let (kind, host) = url.host.split_once(':').unwrap_or((url.host.as_str(), ""));
    if kind == "serial" {
        if !host.is_empty() || url.port.is_some() || url.path.len() < 2 {
            return Err(url.error(FORMS));
        }
        let (device, baud) = match url.path.rsplit_once(':') {
            Some((d, b)) if !b.is_empty() && b.bytes().all(|c| c.is_ascii_digit()) => {
                let baud = b.parse::<u32>().ok().filter(|b| *b > 0).ok_or_else(|| {
                    url.error(format!("`{b}` is not a baud rate (such as 57600)"))
                })?;
                (d, baud)
            }
            _ => (url.path.as_str(), 57_600),
        };
        return Ok(Address::Serial(PathBuf::from(device), baud));
    }
    if !["udpin", "udpout", "udpbcast", "tcpout", "tcpin"].contains(&kind) {
        return Err(url.error(FORMS));
    }
    let host = unbracket(host);
    let (Some(port), false) = (url.port, host.is_empty()) else {
        return Err(url.error(format!(
            "`{kind}` needs an address and a port: mavlink://{kind}:ADDRESS:PORT"
        )));
    };
    if !url.path.is_empty() {
        return Err(url.error(format!(
            "nothing follows the port of mavlink://{kind}:ADDRESS:PORT (found `{}`)",
            url.path
        )));
    }
    let ip = || {
        host.parse::<IpAddr>().map_err(|_| {
            url.error(format!(
                "`{host}` is not an IP address to listen on (such as 0.0.0.0)"
            ))
        })
    };
    if port == 0 && matches!(kind, "udpout" | "udpbcast" | "tcpout") {
        return Err(url.error(format!("`{kind}` needs a port to send to, not 0")));
    }
    Ok(match kind {
        "udpin" => Address::UdpIn(SocketAddr::new(ip()?, port)),
        "tcpin" => Address::TcpIn(SocketAddr::new(ip()?, port)),
        "udpout" => Address::UdpOut(host.to_string(), port),
        "tcpout" => Address::TcpOut(host.to_string(), port),
        _ => {
            let ip = host.parse::<Ipv4Addr>().map_err(|_| {
                url.error(format!(
                    "`{host}` is not an IPv4 address to broadcast to (such as 192.168.2.255)"
                ))
            })?;
            Address::UdpBcast(SocketAddrV4::new(ip, port))
        }
    })
}

/// A system or component id option: 1–255 (0 addresses everyone and names no one).
fn id(url: &mut MediumUrl, name: &str, default: u8) -> Result<u8, UrlError> {
    match url.take_parsed::<u8>(name, "an id 1–255")? {
        None => Ok(default),
        Some(0) => Err(url.error(format!("option `{name}=0`: expected an id 1–255"))),
        Some(v) => Ok(v),
    }
}

/// A duration option above zero.
fn duration(
    url: &mut MediumUrl,
    name: &str,
    default: Duration,
    off: bool,
) -> Result<Option<Duration>, UrlError> {
    match url.take(name) {
        None => Ok(Some(default)),
        Some(v) => match parse_duration(&v) {
            Some(d) if d.is_zero() && off => Ok(None),
            Some(d) if !d.is_zero() => Ok(Some(d)),
            _ => Err(url.error(format!(
                "option `{name}={v}`: expected a duration such as 1s or 500ms{}",
                if off { " (0: none)" } else { "" }
            ))),
        },
    }
}

impl MavlinkConfig {
    /// Reads the settings of a `mavlink://` URL (taking its options).
    pub fn from_url(url: &mut MediumUrl) -> Result<MavlinkConfig, UrlError> {
        let address = address(url)?;
        let sysid = id(url, "sysid", 255)?;
        let compid = id(url, "compid", 190)?;
        let dialect = match url.take("dialect") {
            None => Dialect::ArduPilotMega,
            Some(d) => Dialect::from_name(&d).ok_or_else(|| {
                url.error(format!(
                    "option `dialect={d}`: expected ardupilotmega or common"
                ))
            })?,
        };
        let heartbeat = duration(url, "heartbeat", Duration::from_secs(1), true)?;
        let role = match url.take("role").as_deref() {
            None | Some("gcs") => Role::Gcs,
            Some("companion") => Role::Companion,
            Some(r) => {
                return Err(url.error(format!("option `role={r}`: expected gcs or companion")));
            }
        };
        let version = match url.take("version").as_deref() {
            None | Some("2") => MavlinkVersion::V2,
            Some("1") => MavlinkVersion::V1,
            Some(v) => return Err(url.error(format!("option `version={v}`: expected 1 or 2"))),
        };
        let timeout = duration(url, "timeout", Duration::from_secs(3), false)?
            .unwrap_or(Duration::from_secs(3));
        // only a connection or a device is reopened
        let reopen = match address {
            Address::TcpOut(..) | Address::Serial(..) => Backoff::from_url(url)?,
            _ => Backoff::default(),
        };
        url.finish(OPTIONS)?;
        Ok(MavlinkConfig {
            address,
            sysid,
            compid,
            dialect,
            heartbeat,
            role,
            version,
            timeout,
            reopen,
        })
    }

    /// What a MAVLink medium can do: MAVLink messages as datamaps on `mavlink.SYSID.NAME`,
    /// without seabus's provenance, at most one frame each; its link follows the vehicles'
    /// heartbeats.
    pub fn capabilities(&self) -> Capabilities {
        Capabilities {
            provenance: false,
            framing: if self.address.is_udp() {
                Framing::Datagram
            } else {
                Framing::Frame
            },
            max_frame: Some(MAX_FRAME),
            hears_own: false,
            carries: Carries::DataMap,
            link_state: true,
            native: Some("mavlink"),
            qos: false,
            lists: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(text: &str) -> Result<MavlinkConfig, String> {
        let mut url = MediumUrl::parse(text).map_err(|e| e.to_string())?;
        MavlinkConfig::from_url(&mut url).map_err(|e| e.reason)
    }

    #[test]
    fn every_address_form_reads() {
        let addr = |t: &str| config(t).map(|c| c.address);
        assert_eq!(
            addr("mavlink://udpin:0.0.0.0:14550"),
            Ok(Address::UdpIn("0.0.0.0:14550".parse().unwrap()))
        );
        assert_eq!(
            addr("mavlink://udpin:[::1]:14550"),
            Ok(Address::UdpIn("[::1]:14550".parse().unwrap()))
        );
        assert_eq!(
            addr("mavlink://udpout:127.0.0.1:14550"),
            Ok(Address::UdpOut("127.0.0.1".into(), 14550))
        );
        assert_eq!(
            addr("mavlink://udpout:blueos.local:14550"),
            Ok(Address::UdpOut("blueos.local".into(), 14550))
        );
        assert_eq!(
            addr("mavlink://udpbcast:192.168.2.255:14550"),
            Ok(Address::UdpBcast("192.168.2.255:14550".parse().unwrap()))
        );
        assert_eq!(
            addr("mavlink://tcpout:localhost:5760"),
            Ok(Address::TcpOut("localhost".into(), 5760))
        );
        assert_eq!(
            addr("mavlink://tcpin:0.0.0.0:5760"),
            Ok(Address::TcpIn("0.0.0.0:5760".parse().unwrap()))
        );
        assert_eq!(
            addr("mavlink://serial/dev/ttyUSB0:115200"),
            Ok(Address::Serial("/dev/ttyUSB0".into(), 115_200))
        );
        assert_eq!(
            addr("mavlink://serial/dev/serial/by-id/usb-ArduPilot_Pixhawk1"),
            Ok(Address::Serial(
                "/dev/serial/by-id/usb-ArduPilot_Pixhawk1".into(),
                57_600
            ))
        );
        assert_eq!(
            config("mavlink://udpin:0.0.0.0:14550")
                .unwrap()
                .address
                .to_string(),
            "udpin:0.0.0.0:14550"
        );
    }

    #[test]
    fn bad_addresses_say_what_is_expected() {
        for bad in [
            "mavlink://",
            "mavlink://udp:0.0.0.0:14550",
            "mavlink://14550",
            "mavlink://serial",
        ] {
            let e = config(bad).unwrap_err();
            assert!(
                e.starts_with("expected mavlink://udpin:ADDRESS:PORT"),
                "{bad}: {e}"
            );
        }
        assert_eq!(
            config("mavlink://udpin").unwrap_err(),
            "`udpin` needs an address and a port: mavlink://udpin:ADDRESS:PORT"
        );
        assert_eq!(
            config("mavlink://udpin:somehost:14550").unwrap_err(),
            "`somehost` is not an IP address to listen on (such as 0.0.0.0)"
        );
        assert_eq!(
            config("mavlink://udpout:127.0.0.1:0").unwrap_err(),
            "`udpout` needs a port to send to, not 0"
        );
        assert_eq!(
            config("mavlink://udpbcast:broadcast:14550").unwrap_err(),
            "`broadcast` is not an IPv4 address to broadcast to (such as 192.168.2.255)"
        );
        assert!(
            config("mavlink://udpin:0.0.0.0:14550/x")
                .unwrap_err()
                .contains("nothing follows the port")
        );
        assert_eq!(
            config("mavlink://serial/dev/ttyUSB0:0").unwrap_err(),
            "`0` is not a baud rate (such as 57600)"
        );
    }

    #[test]
    fn options_read_with_their_defaults() {
        let c = config("mavlink://udpin:0.0.0.0:14550").unwrap();
        assert_eq!(
            (
                c.sysid,
                c.compid,
                c.dialect,
                c.heartbeat,
                c.role,
                c.version,
                c.timeout
            ),
            (
                255,
                190,
                Dialect::ArduPilotMega,
                Some(Duration::from_secs(1)),
                Role::Gcs,
                MavlinkVersion::V2,
                Duration::from_secs(3)
            )
        );
        let c = config(
            "mavlink://tcpout:127.0.0.1:5760?sysid=250&compid=191&dialect=common&heartbeat=500ms\
             &role=companion&version=1&timeout=2s&reopen=1s",
        )
        .unwrap();
        assert_eq!(
            (
                c.sysid,
                c.compid,
                c.dialect,
                c.heartbeat,
                c.role,
                c.version,
                c.timeout,
                c.reopen.first
            ),
            (
                250,
                191,
                Dialect::Common,
                Some(Duration::from_millis(500)),
                Role::Companion,
                MavlinkVersion::V1,
                Duration::from_secs(2),
                Duration::from_secs(1)
            )
        );
        assert_eq!(
            config("mavlink://udpin:0.0.0.0:14550?heartbeat=0")
                .unwrap()
                .heartbeat,
            None
        );
        let serial = config("mavlink://serial/dev/ttyUSB0?reopen=2s&reopen_max=10s").unwrap();
        assert_eq!(
            (serial.reopen.first, serial.reopen.max),
            (Duration::from_secs(2), Duration::from_secs(10))
        );
        // nothing is reopened on UDP
        assert!(
            config("mavlink://udpin:0.0.0.0:14550?reopen=1s")
                .unwrap_err()
                .starts_with("unknown option `reopen`")
        );
    }

    #[test]
    fn bad_options_are_named() {
        let e = |q: &str| config(&format!("mavlink://udpin:0.0.0.0:14550?{q}")).unwrap_err();
        assert_eq!(e("sysid=0"), "option `sysid=0`: expected an id 1–255");
        assert_eq!(e("compid=256"), "option `compid=256`: expected an id 1–255");
        assert_eq!(
            e("dialect=px4"),
            "option `dialect=px4`: expected ardupilotmega or common"
        );
        assert_eq!(
            e("heartbeat=often"),
            "option `heartbeat=often`: expected a duration such as 1s or 500ms (0: none)"
        );
        assert_eq!(
            e("timeout=0"),
            "option `timeout=0`: expected a duration such as 1s or 500ms"
        );
        assert_eq!(e("version=3"), "option `version=3`: expected 1 or 2");
        assert_eq!(
            e("role=boat"),
            "option `role=boat`: expected gcs or companion"
        );
        assert!(
            e("sysidd=1").starts_with(
                "unknown option `sysidd` for mavlink://; known options: sysid, compid"
            ),
            "{}",
            e("sysidd=1")
        );
    }

    #[test]
    fn udp_is_datagrams_and_the_rest_frames_on_a_stream() {
        use seabus_medium::caps::Framing;
        let udp = config("mavlink://udpin:0.0.0.0:14550")
            .unwrap()
            .capabilities();
        assert_eq!(
            (udp.framing, udp.provenance, udp.native, udp.link_state),
            (Framing::Datagram, false, Some("mavlink"), true)
        );
        assert!(!udp.carries_datamaps());
        let tcp = config("mavlink://tcpout:127.0.0.1:5760")
            .unwrap()
            .capabilities();
        assert_eq!(tcp.framing, Framing::Frame);
    }
}
