//! What a transport can do, declared by the transport itself.
//!
//! Code that has to treat media differently (a bridge remembering what it wrote to a wire without
//! provenance, the LCM type mapping, a report that only fits some wires, `seabus check`) asks a
//! medium's [`Capabilities`], never its URL's scheme. A scheme declares them for a URL before
//! anything is opened ([`crate::Schemes::check`]), and an opened medium reports the same
//! ([`crate::Medium::capabilities`]).

/// How a wire delimits what it carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Framing {
    /// Whole messages handed over in memory (the in-process medium).
    Memory,
    /// One message per datagram (UDP, LCM, DSAAV).
    Datagram,
    /// Text lines on a byte stream (NMEA sentences, slcan).
    Line,
    /// Delimited binary frames on a byte stream (COBS, SLIP), or fixed frames (CAN).
    Frame,
    /// Length-prefixed messages on a connected byte stream (MOOS over TCP).
    Stream,
}

/// What payloads a wire carries as they are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Carries {
    /// All three payload formats (bytes, datamap, XML text), told apart on the wire.
    Any,
    /// Named datamaps (key-value messages); bytes only where the wire has a byte value.
    DataMap,
    /// Bytes (or text) only; a datamap cannot be sent.
    Bytes,
}

/// What a transport can do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Capabilities {
    /// The wire carries seabus's provenance (origin, sequence number, hops) with every message.
    /// A medium without it (a serial line, CAN, MOOS) numbers what it reads itself, so a bridge
    /// must remember what it wrote there to recognise the echo.
    pub provenance: bool,
    /// How messages are delimited on the wire.
    pub framing: Framing,
    /// The largest message the wire carries, in bytes as encoded, when there is a limit.
    pub max_frame: Option<usize>,
    /// The medium hears what it sends itself (a shared bus such as CAN, or a multicast group
    /// looped back), so that a listener on this node sees its own sends as received.
    pub hears_own: bool,
    /// What payloads the wire carries.
    pub carries: Carries,
    /// The medium reports its link going down and up (a device, a connection), rather than being
    /// always up.
    pub link_state: bool,
    /// The wire's own message model when it has one that seabus messages must be mapped to
    /// (`"lcm"`: typed LCM messages on channels; `"dsaav"`: DSAAV IComms messages and services),
    /// `None` when the wire takes seabus messages as they are.
    pub native: Option<&'static str>,
    /// The wire gives each message a priority, a congestion control and an express flag, and
    /// honours those declared for some topics ([`crate::Medium::set_qos`]): a bridge route's
    /// `priority`, `congestion` and `express` apply to what it delivers here (Zenoh).
    pub qos: bool,
    /// The wire's datamaps carry lists as values (UDP, Zenoh, the in-process medium; LCM and
    /// MAVLink through their types' arrays). A datamap with lists goes to a medium that does not
    /// (MOOS `key=value` pairs, DSAAV IComms, CAN signals) with each list flattened into one field
    /// per element ([`crate::DataMap::flatten_lists`]).
    pub lists: bool,
}

impl Capabilities {
    /// The in-process medium's: whole messages in memory, nothing lost, never down.
    pub const IN_PROCESS: Capabilities = Capabilities {
        provenance: true,
        framing: Framing::Memory,
        max_frame: None,
        hears_own: false,
        carries: Carries::Any,
        link_state: false,
        native: None,
        qos: false,
        lists: true,
    };

    /// Whether the wire names messages by channels of its own that need not be seabus topics
    /// (LCM: any channel liblcm sends, `POSE.` or `with space` too), which it delivers as
    /// [`Topic::channel`](crate::Topic::channel)s and takes back as they were.
    pub fn names_channels(&self) -> bool {
        self.native == Some("lcm")
    }

    /// Whether a datamap can be sent here (a report, a standard dataset) as it is.
    pub fn carries_datamaps(&self) -> bool {
        self.carries != Carries::Bytes && self.native.is_none()
    }

    /// Whether the wire's own message model is `model` (see [`Capabilities::native`]).
    pub fn is_native(&self, model: &str) -> bool {
        self.native == Some(model)
    }
}
