//! The Iver2/Iver3 frontseat: the Remote Helm protocol ([`protocol`]), the backseat driver that
//! speaks it ([`driver`], module type `iver2`), and a simulated frontseat ([`sim`], module type
//! `iver2-sim`).

pub mod driver;
pub mod protocol;
pub mod sim;
