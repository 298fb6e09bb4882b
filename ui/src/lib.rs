//! seabus-ui: the operator console, served by seabus itself.
//!
//! This crate is the home of the user-interface modules of a system: the web console with its
//! per-user XML layouts, widgets bound to `topic.field` variables, inputs from keyboard and gamepad,
//! roles and command safety. It depends on `seabus-modules` (and `seabus-medium` for topics,
//! datamaps and the positioned XML reader), like the other module crates, and the `seabus` program
//! registers what it provides next to the drivers and bridges.
//!
//! How the parts fit:
//!
//! - [`layout`] reads the layout files: their commands ([`CommandDecl`], which also checks the
//!   fields a page proposes before they are sent), widget tree ([`Node`]), keyboard and gamepad
//!   bindings, and the variables they display ([`Binding`]); it gives the page its JSON form and
//!   checks a layout against a system (`seabus layout check LAYOUT SYSTEM`).
//! - [`users`] reads the users file (argon2id hashes, roles); [`auth`] holds sessions and limits
//!   log-in attempts.
//! - [`hub`] is the console's shared state and every rule the server enforces: the latest bus
//!   values, the control lease, confirmations, dead-man commands, the command history and its
//!   acknowledgements.
//! - [`server`] serves the page ([`assets`], embedded), log-in and the WebSocket; each connection
//!   is a [`hub::Client`].
//! - [`console`] reads the `<console>` element of a system file and starts all of it.
//! - [`foxglove`] serves a medium's traffic to Foxglove and Lichtblick (the `<foxglove>` element),
//!   through the `foxglove` crate's WebSocket server.
//!
//! Who may depend on it: the program. It depends on the core and the module framework.

pub mod assets;
pub mod auth;
pub mod console;
pub mod foxglove;
pub mod hub;
pub mod layout;
pub mod server;
pub mod users;

pub use layout::{
    AxisBinding, Binding, CommandDecl, Confirm, KeyBinding, Layout, Node, Offset, PadButton,
};

/// Registers what this crate reads in system files (the `<console>` and `<foxglove>` elements).
pub fn register(reg: &mut seabus_modules::Registry) {
    reg.add_section(console::SECTION);
    reg.add_section(foxglove::SECTION);
}
