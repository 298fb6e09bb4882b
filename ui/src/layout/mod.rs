//! Console layouts: the XML files that place widgets on a page, bind them to `topic.field`
//! variables and declare the commands the page may send (see `docs/console.md`).
//!
//! [`Layout::parse`] reads a layout: it substitutes `${name}` variables, expands `<template>`s
//! where they are `<use>`d, checks every element and attribute, and gives ids to the widgets that
//! have none. Every error names file, line and column. A parsed layout answers what the console
//! needs: its JSON form for the page ([`Layout::to_json`]), the variables it displays
//! ([`Layout::bindings`]), who sees it ([`Layout::visible_to`]) and whether a command the page
//! proposes is one it declares, with fields of the right types and in range ([`CommandDecl::build`]).
//! [`Layout::check`] compares it with a system: bindings whose topic no module produces and commands
//! no module accepts are warnings.
//!
//! The parts: `model` (the types), `expand` (`${…}`, `<template>` and `<use>`), `read` (the
//! `<layout>` element into the model), `values` (attribute values), `widgets`, `commands` and
//! `inputs` (the checks of each element), `system` (a layout against a system) and `json` (the
//! form the page reads).

mod commands;
mod expand;
mod inputs;
mod json;
mod model;
mod read;
mod system;
#[cfg(test)]
mod testing;
mod values;
mod widgets;

pub use expand::{MAX_ELEMENTS, MAX_TEMPLATE_DEPTH, MAX_TEXT};
pub use model::{
    AxisBinding, Binding, CommandDecl, Confirm, DEFAULT_FRESH, DEFAULT_HEALTH, DEFAULT_HOLD,
    DEFAULT_LOG_TOPICS, FLEET_COLUMNS, Horizon, KeyBinding, Layout, Node, Offers, Offset,
    PadButton, Plotted,
};
pub use system::{Producer, command_accepted, producers};
pub use values::{COLOURS, is_name};
