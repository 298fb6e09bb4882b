//! LCM (Lightweight Communications and Marshalling): its UDP multicast medium, its message types
//! read at run time, its messages to and from datamaps ([`codec`]), and its event-log files.
//!
//! LCM names a message by its channel; on an LCM medium the channel is the seabus topic and the
//! payload is the LCM message's bytes (an 8-byte type fingerprint, then the encoded fields).
//! Subscriptions, as in LCM, are regular expressions matched against the whole channel name
//! ([`ChannelRegex`]).
//!
//! - [`wire`] — the LC02 and LC03 packets, byte for byte as liblcm's; [`reassembly`] puts
//!   fragmented messages together; [`udpm`] is the medium (`udpm://` URLs) built on both.
//! - [`types`] — `.lcm` files read at run time, with lcm-gen's fingerprints; [`codec`] encodes and
//!   decodes LCM messages of those types to and from datamaps.
//! - [`eventlog`] — LCM's event-log files, as lcm-logger writes them (`seabus record` and
//!   `seabus replay`).

pub mod codec;
pub mod eventlog;
pub mod reassembly;
pub mod types;
pub mod udpm;
pub mod wire;

use std::fmt;

/// Longest channel name LCM carries, in bytes.
pub const MAX_CHANNEL_LEN: usize = 63;

/// A channel subscription: a regular expression matched against the whole channel name
/// (`POSE.*` matches `POSE_EST` but not `MY_POSE`), as LCM's own subscriptions are.
#[derive(Clone)]
pub struct ChannelRegex {
    text: String,
    re: regex::Regex,
}

impl ChannelRegex {
    /// Compiles `pattern`, anchored at both ends.
    pub fn new(pattern: &str) -> Result<ChannelRegex, regex::Error> {
        Ok(ChannelRegex {
            text: pattern.to_string(),
            re: regex::Regex::new(&format!("^(?:{pattern})$"))?,
        })
    }

    /// True when the whole of `channel` matches.
    pub fn matches(&self, channel: &str) -> bool {
        self.re.is_match(channel)
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.text
    }
}

impl fmt::Debug for ChannelRegex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ChannelRegex({:?})", self.text)
    }
}

impl fmt::Display for ChannelRegex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_patterns_match_whole_names() {
        let r = ChannelRegex::new("POSE.*").unwrap();
        assert!(r.matches("POSE") && r.matches("POSE_EST"));
        assert!(!r.matches("MY_POSE"));
        let r = ChannelRegex::new("A|B").unwrap();
        assert!(r.matches("A") && r.matches("B") && !r.matches("AB"));
        assert!(ChannelRegex::new("(").is_err());
    }
}
