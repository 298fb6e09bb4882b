//! seabus-medium-lcm: LCM (Lightweight Communications and Marshalling) — its UDP multicast
//! medium, its message types read at run time, and its messages to and from datamaps ([`codec`]).
//!
//! LCM names a message by its channel; on an LCM medium the channel is the seabus topic and the
//! payload is the LCM message's bytes (an 8-byte type fingerprint, then the encoded fields).
//! Subscriptions, as in LCM, are regular expressions matched against the whole channel name
//! ([`ChannelRegex`](seabus_medium::ChannelRegex)).
//!
//! - [`wire`] — the LC02 and LC03 packets, byte for byte as liblcm's; [`reassembly`] puts
//!   fragmented messages together; [`udpm`] is the medium (`udpm://` URLs) built on both.
//! - [`types`] — `.lcm` files read at run time, with lcm-gen's fingerprints; [`codec`] encodes and
//!   decodes LCM messages of those types to and from datamaps.
//!
//! LCM's event-log files, seabus's recording format for every medium, are in the core
//! ([`seabus_medium::eventlog`]).
//!
//! Who may depend on it: the program (to register `udpm://`), and the crates that map LCM types
//! (the bridges, the program's `spy` and `pub`). It depends on the core only.

pub mod codec;
pub mod reassembly;
pub mod types;
pub mod udpm;
pub mod wire;

use seabus_medium::{Opened, Scheme, Schemes};

/// Longest channel name LCM carries, in bytes.
pub const MAX_CHANNEL_LEN: usize = 63;

/// Adds `udpm://`.
pub fn register(schemes: &mut Schemes) {
    schemes.add(Scheme {
        name: "udpm",
        family: "lcm",
        summary: "LCM's UDP multicast, wire-compatible with liblcm",
        check: |url| Ok(udpm::LcmConfig::from_url(url)?.capabilities()),
        open: |o| Ok(Opened::from(udpm::open(o)?)),
    });
}

/// A registry with `udpm://` and the in-process medium, for a program or test that uses only these.
pub fn schemes() -> Schemes {
    Schemes::with(&[register])
}
