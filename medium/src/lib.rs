//! seabus-medium: the message model, its payload formats, and the communication media.
//!
//! How the parts fit:
//!
//! - [`message`] — a [`Message`] has a [`Topic`], a [`Kind`] (data or command), a [`Provenance`]
//!   (origin node and medium, per-origin sequence number, hop count), a [`Stamp`] and a [`Payload`].
//! - [`payload`] — a payload is bytes, a named [`DataMap`] ([`datamap`]) or XML text; receivers state the
//!   [`Format`] they accept and get it converted, losslessly, through the compact binary form
//!   ([`binary`]) and the XML form ([`xmlform`]).
//! - [`medium`] — a [`Medium`] fans messages out to the [`Interface`]s attached to it (passive mode:
//!   the module polls and pushes) and to its [`Transport`], if any, for the wire. [`active`] drives a
//!   module's handlers from an interface (active mode). Every interface has bounded queues
//!   ([`queue`]: data drops oldest, commands hold the sender back) and drops duplicates by provenance
//!   ([`dedup`]).
//! - Media: in-process (no transport), [`udp`], [`serial`] (serial devices and pseudo-terminals,
//!   with NMEA, line, COBS or SLIP framing), [`can`] (CAN frames through slcan adapters, or a
//!   pseudo-terminal behaving as one, cannelloni, SocketCAN), [`moos`] (a client of a MOOSDB), [`lcm`] (LCM's UDP multicast, its types and event
//!   logs) and [`dsaav`] (DSAAV IComms on raw Ethernet, UDP or in-process). Any medium opens from
//!   a URL ([`url`], [`Medium::open`]) and can carry a fault stage ([`fault`]) for tests.
//! - [`xml`] — a small positioned XML tree for the files users write (every error names file, line
//!   and column).

pub mod active;
pub mod binary;
pub mod can;
pub mod datamap;
pub mod dedup;
pub mod dsaav;
pub mod fault;
pub mod json;
pub mod lcm;
pub mod medium;
pub mod message;
pub mod moos;
pub mod parse;
pub mod payload;
pub mod queue;
pub mod serial;
pub mod tally;
pub mod topic;
pub mod udp;
pub mod url;
pub mod xml;
pub mod xmlform;

pub use active::{ActiveInterface, Handler, Outgoing, TxWaker};
pub use datamap::{DataMap, Key, Text, Value};
pub use fault::FaultConfig;
pub use medium::{
    Ingress, Interface, InterfaceStats, IntoTopic, LinkState, Medium, MediumStats, Node, OpenError,
    SendError, Transport, TryRecvError,
};
pub use message::{Kind, Message, Origin, Provenance, Stamp};
pub use payload::{ConvertError, Format, Payload};
pub use topic::{Pattern, Topic, TopicError};
