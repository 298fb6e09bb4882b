//! seabus-ui: the operator console, served by seabus itself.
//!
//! This crate is the home of the user-interface modules of a system: the web console with its
//! per-user XML layouts, widgets bound to `topic.field` variables, inputs from keyboard and gamepad,
//! roles and command safety. It depends on `seabus-modules` only, like the other module crates, and
//! the `seabus` program registers what it provides next to the drivers and bridges.
