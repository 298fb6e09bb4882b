//! seabus-ui: the operator console, served by seabus itself.
//!
//! This crate is the home of the user-interface modules of a system: the web console with its
//! per-user XML layouts, widgets bound to `topic.field` variables, inputs from keyboard and gamepad,
//! roles and command safety. It depends on `seabus-modules` (and `seabus-medium` for topics,
//! datamaps and the positioned XML reader), like the other module crates, and the `seabus` program
//! registers what it provides next to the drivers and bridges.
//!
//! [`layout`] reads the layout files: their commands ([`CommandDecl`], which also checks the
//! fields a page proposes before they are sent), widget tree ([`Node`]), keyboard and gamepad
//! bindings, and the variables they display ([`Binding`]); it gives the page its JSON form and
//! checks a layout against a system (`seabus layout check LAYOUT SYSTEM`).

pub mod layout;

pub use layout::{
    AxisBinding, Binding, CommandDecl, Confirm, KeyBinding, Layout, Node, Offset, PadButton,
};
