//! seabus-medium-mavlink, the MAVLink medium: vehicles and ground stations speaking MAVLink
//! (ArduSub ROVs, ArduRover boats, any ArduPilot or PX4 system) over UDP, TCP or a serial line,
//! their messages as datamaps.
//!
//! ```text
//! mavlink://udpin:0.0.0.0:14550?sysid=255&compid=190     a ground station where ArduSub sends
//! mavlink://tcpout:127.0.0.1:5760?dialect=ardupilotmega   ArduPilot's simulator
//! mavlink://serial/dev/ttyUSB0:57600?role=companion       a companion computer on the autopilot's port
//! ```
//! ([`config`] has every address form and option.)
//!
//! **Receiving.** Every message heard becomes a datamap on topic `mavlink.SYSID.NAME` (the
//! sender's system id and the message's name: `mavlink.1.ATTITUDE`), with the message's fields by
//! their MAVLink names (enums as their names, bitmasks as `A | B`, arrays as lists; [`convert`])
//! and the sender's `sysid` and `compid`. The medium numbers what it hears as a medium on a wire
//! without seabus's provenance does (each message originates here); gaps in a sender's sequence
//! numbers are counted as messages missed (`mavlink.SYSID` in its counters). Frames with the
//! medium's own ids (its own, come back through a router) are not delivered. What is not a good
//! frame is counted by reason (`garbage`, `truncated`, `bad-crc`, `unknown-message`, and
//! `bad-value` for a payload that does not read, such as a value its enum does not have),
//! dropped, and warned of at most once in 10 s per reason; the next good frame reads ([`frame`]).
//!
//! **Vehicles and the link.** The medium sends its own HEARTBEAT every `heartbeat` (a ground
//! station's or a companion computer's, with its URL's ids) and keeps the vehicles it hears, each
//! published on `mavlink.vehicles` when it changes and every 5 s ([`vehicles`]). Its link is up
//! while a vehicle's heartbeat was heard within `timeout`, down otherwise, each change logged once.
//!
//! **Sending.** A datamap sent on `mavlink.SYSID.NAME`, data or command alike, is encoded as
//! message NAME of the medium's dialect, its fields by name (a missing field or one the message
//! does not have is refused, naming it; target fields are the datamap's `target_system` and
//! `target_component`), and sent with the medium's own system and component ids, MAVLink 2 unless
//! `version=1`. Nothing else can be sent here: the medium's capabilities say its wire has a
//! message model of its own (`native = "mavlink"`), so reports and other datamaps stay off it.
//!
//! Frames are found, checked and decoded with the `mavlink` crate's message sets (`common` and
//! `ardupilotmega`, MAVLink 2 extension fields included); seabus walks the bytes itself only to
//! tell why what is not a frame was refused.
//!
//! Who may depend on it: the program (to register `mavlink://`) and, behind the program's
//! `mavlink` feature, drivers that work on MAVLink messages. It depends on the core and
//! `seabus-tty` only.

pub mod config;
pub mod convert;
pub mod dialect;
pub mod frame;
pub mod transport;
pub mod vehicles;

pub use config::{Address, MavlinkConfig, Role};
pub use dialect::Dialect;
pub use transport::MavlinkTransport;

use seabus_medium::{Opened, Scheme, Schemes};

/// Adds `mavlink://`.
pub fn register(schemes: &mut Schemes) {
    schemes.add(Scheme {
        name: "mavlink",
        family: "mavlink",
        summary: "MAVLink vehicles and ground stations over UDP, TCP or a serial line",
        check: |url| Ok(MavlinkConfig::from_url(url)?.capabilities()),
        open: |o| Ok(Opened::from(transport::open(o)?)),
    });
}

/// A registry with `mavlink://` and the in-process medium, for a program or test that uses only
/// these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}
