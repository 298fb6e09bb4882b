//! One error type for bytes a wire delivered that do not read: [`WireError`].
//!
//! Every medium's parser (datagrams, packets, frames, lines) refuses input with a `WireError`: a
//! short, stable [`kind`](WireError::kind) under which the medium counts the rejection
//! ([`crate::Ingress::reject`]), the byte offset where reading stopped when there is one, and what
//! was wrong in words.

use std::fmt;

/// Why bytes read from a wire were refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WireError {
    kind: &'static str,
    offset: Option<usize>,
    detail: String,
}

impl WireError {
    /// Input refused at byte `offset`, counted under `kind`.
    pub fn at(offset: usize, kind: &'static str, detail: impl Into<String>) -> WireError {
        WireError {
            kind,
            offset: Some(offset),
            detail: detail.into(),
        }
    }

    /// Input refused as a whole (a line, a value), counted under `kind`.
    pub fn new(kind: &'static str, detail: impl Into<String>) -> WireError {
        WireError {
            kind,
            offset: None,
            detail: detail.into(),
        }
    }

    /// The short, stable name the rejection is counted under (`truncated`, `bad-magic`, …).
    pub fn kind(&self) -> &'static str {
        self.kind
    }

    /// The byte where reading stopped, when the input is a buffer.
    pub fn offset(&self) -> Option<usize> {
        self.offset
    }

    /// What was wrong.
    pub fn detail(&self) -> &str {
        &self.detail
    }
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.offset {
            Some(o) => write!(f, "byte {o}: {}", self.detail),
            None => f.write_str(&self.detail),
        }
    }
}

impl std::error::Error for WireError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_their_place_and_kind() {
        let e = WireError::at(7, "bad-magic", "not a seabus datagram");
        assert_eq!(e.to_string(), "byte 7: not a seabus datagram");
        assert_eq!((e.kind(), e.offset()), ("bad-magic", Some(7)));
        let e = WireError::new("slcan-bad-hex", "`G` is not a hex digit");
        assert_eq!(e.to_string(), "`G` is not a hex digit");
        assert_eq!(e.offset(), None);
    }
}
