//! seabus-medium: the core every other seabus crate stands on — the message model, its payload
//! formats, media and their interfaces, the transport contract with its capabilities, and the
//! scheme registry through which medium crates plug in.
//!
//! How the parts fit:
//!
//! - [`message`] — a [`Message`] has a [`Topic`], a [`Kind`] (data or command), a [`Provenance`]
//!   (origin node and medium, per-origin sequence number, hop count), a [`Stamp`] (the wall clock
//!   as [`clock`] reads it cheaply) and a [`Payload`].
//! - [`payload`] — a payload is bytes, a named [`DataMap`] ([`datamap`]) or XML text; receivers state the
//!   [`Format`] they accept and get it converted, losslessly, through the compact binary form
//!   ([`binary`]), the XML form ([`xmlform`]) and JSON ([`json`]).
//! - [`medium`] — a [`Medium`] fans messages out to the [`Interface`]s attached to it (the module
//!   polls and pushes; the runtime of `seabus-modules` drives modules' handlers from them, the
//!   active mode) and to its [`Transport`], if any, for the wire. Every interface has bounded
//!   queues ([`queue`]: data drops oldest, commands hold the sender back) and drops duplicates by
//!   provenance ([`dedup`]). Any medium can carry a fault stage ([`fault`]). What a medium loses
//!   (messages its receivers' full queues drop, characters a serial device overruns) is counted
//!   in its [`MediumStats`] and warned of once per burst ([`loss`]).
//! - [`caps`] — what a transport declares it can do ([`Capabilities`]); code asks these, never a
//!   URL's scheme.
//! - [`qos`] — quality of service ([`Qos`]: priority, congestion control, express) that a medium
//!   carrying priorities gives the topics declared with it ([`Medium::set_qos`]).
//! - [`schemes`] — the registry of URL schemes ([`Schemes`]): each medium crate adds its own with
//!   `register(&mut Schemes)`; the in-process medium (`inproc://`) is built in.
//! - Shared machinery of the medium crates: [`link`] (one reconnect loop with back-off and link
//!   state), [`wire`] (one error type for input a wire delivered), [`datagram`] (a whole message
//!   with its provenance in bytes, as the UDP and Zenoh media carry it), [`net`] (UDP endpoints,
//!   socket options, datagrams received in batches), [`outbox`] (datagrams sent at once or in
//!   batches), [`framing`] (NMEA, line, COBS and SLIP framing of byte streams), [`url`]
//!   (medium URLs), [`tally`] (rate-limited counting of rejected input), [`subindex`] (which of
//!   many topic patterns match a topic: a medium's subscriptions, a bridge's routes).
//! - Files: [`csv`] (table cells), [`xml`] (a small positioned XML tree for the files users write: every error names file,
//!   line and column), [`fs`] (atomic writes), [`eventlog`] (LCM event logs, seabus's recording
//!   format), [`parse`] (durations, rates, field lists).
//!
//! Who may depend on it: every seabus crate. It depends on no other seabus crate.

pub mod binary;
pub mod caps;
pub mod clock;
pub mod csv;
pub mod datagram;
pub mod datamap;
pub mod dedup;
pub mod eventlog;
pub mod fault;
pub mod framing;
pub mod fs;
pub mod json;
pub mod link;
pub mod loss;
pub mod medium;
pub mod message;
pub mod net;
pub mod outbox;
pub mod parse;
pub mod payload;
pub mod qos;
pub mod queue;
pub mod schemes;
pub mod subindex;
pub mod tally;
pub mod topic;
pub mod url;
pub mod wire;
pub mod xml;
pub mod xmlform;

pub use caps::{Capabilities, Carries};
pub use datamap::{DataMap, Key, Text, Value};
pub use fault::FaultConfig;
pub use link::{Backoff, Encode, LinkQueue, LinkSender, Linked, link_queue, spawn_link};
pub use medium::{
    BoxFuture, Ingress, Interface, InterfaceStats, IntoTopic, LinkState, Medium, MediumStats, Node,
    OpenError, Opening, SendError, Transport, TryRecvError,
};
pub use message::{Kind, Message, Origin, Provenance, Stamp};
pub use payload::{ConvertError, Format, Payload};
pub use qos::Qos;
pub use schemes::{Opened, Scheme, Schemes};
pub use topic::{ChannelRegex, Pattern, Topic, TopicError};
pub use wire::WireError;
