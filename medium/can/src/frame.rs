//! CAN frames and how they become seabus messages.
//!
//! A frame has an 11-bit (standard) or 29-bit (extended) identifier and is a data frame (up to 8
//! bytes, or up to 64 for CAN FD), a remote frame (a request, with a length code and no data) or an
//! error frame (the controller's error report). On a CAN medium a frame is the message
//!
//! - topic `can.ID`: the identifier in lower-case hex, three digits for a standard one
//!   (`can.123`), eight for an extended one (`can.18ff50e5`); `can.error` for error frames;
//! - payload a datamap: `data` (bytes), and only when they hold: `rtr = true` with `dlc` (a remote
//!   frame), `fd = true`, `brs = true`, `esi = true` (CAN FD and its flags), `error` (an error
//!   frame's class bits), `time_ms` (the adapter's timestamp, when it gives one).
//!
//! What is sent on a CAN medium is read the same way; bytes alone make a data frame (CAN FD when
//! longer than 8). A topic with one to three hex digits names a standard identifier, four to eight
//! an extended one; `ext = true` in the datamap makes a short one extended.

use seabus_medium::datamap::{DataMap, Value};
use seabus_medium::payload::Payload;
use std::fmt;

/// Largest standard identifier.
pub const MAX_STANDARD_ID: u32 = 0x7FF;
/// Largest extended identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;
/// Longest classic CAN payload.
pub const MAX_CLASSIC: usize = 8;
/// Longest CAN FD payload.
pub const MAX_FD: usize = 64;
/// The Linux `can_id` flag of an extended identifier.
pub const LINUX_EFF: u32 = 0x8000_0000;
/// The Linux `can_id` flag of a remote frame.
pub const LINUX_RTR: u32 = 0x4000_0000;
/// The Linux `can_id` flag of an error frame.
pub const LINUX_ERR: u32 = 0x2000_0000;
/// The topic of error frames.
pub const ERROR_TOPIC: &str = "can.error";

/// The payload length of each data length code (CAN FD: 9..15 are 12, 16, 20, 24, 32, 48, 64).
pub const DLC_LEN: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// The data length code for a payload of `len` bytes, if a frame can have that length.
pub fn len_to_dlc(len: usize) -> Option<u8> {
    DLC_LEN
        .iter()
        .position(|&l| usize::from(l) == len)
        .map(|d| d as u8)
}

/// What kind of frame it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameKind {
    /// A data frame.
    Data,
    /// A remote frame: a request for data of `dlc` bytes.
    Remote {
        /// The requested length code (0–8).
        dlc: u8,
    },
    /// An error frame; the identifier holds the error class bits.
    Error,
}

/// A CAN or CAN FD frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanFrame {
    id: u32,
    extended: bool,
    kind: FrameKind,
    /// `Some((brs, esi))` for a CAN FD frame.
    fd: Option<(bool, bool)>,
    data: Vec<u8>,
}

/// Why a frame cannot be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The identifier does not fit its format.
    #[error("identifier {id:#x} is past the {} limit {max:#x}", if *.extended { "29-bit" } else { "11-bit" })]
    Id {
        /// The identifier.
        id: u32,
        /// Whether it was to be extended.
        extended: bool,
        /// The largest allowed.
        max: u32,
    },
    /// The payload is too long, or an FD length no code gives.
    #[error("{len} data bytes: {why}")]
    Length {
        /// The length.
        len: usize,
        /// What is allowed.
        why: &'static str,
    },
}

/// The fields of a datamap that is a CAN frame ([`CanFrame::to_map`], [`CanFrame::from_message`]).
pub const FRAME_FIELDS: [&str; 9] = [
    "data", "ext", "rtr", "dlc", "fd", "brs", "esi", "error", "time_ms",
];

impl CanFrame {
    fn check_id(id: u32, extended: bool) -> Result<(), FrameError> {
        let max = if extended {
            MAX_EXTENDED_ID
        } else {
            MAX_STANDARD_ID
        };
        if id > max {
            return Err(FrameError::Id { id, extended, max });
        }
        Ok(())
    }

    /// A classic data frame (at most 8 bytes).
    pub fn data(id: u32, extended: bool, data: &[u8]) -> Result<CanFrame, FrameError> {
        CanFrame::check_id(id, extended)?;
        if data.len() > MAX_CLASSIC {
            return Err(FrameError::Length {
                len: data.len(),
                why: "a classic frame carries at most 8 (CAN FD up to 64)",
            });
        }
        Ok(CanFrame {
            id,
            extended,
            kind: FrameKind::Data,
            fd: None,
            data: data.to_vec(),
        })
    }

    /// A CAN FD data frame: 0–8, 12, 16, 20, 24, 32, 48 or 64 bytes; `brs` switches to the data
    /// bit rate, `esi` says the sender is error passive.
    pub fn fd(
        id: u32,
        extended: bool,
        data: &[u8],
        brs: bool,
        esi: bool,
    ) -> Result<CanFrame, FrameError> {
        CanFrame::check_id(id, extended)?;
        if len_to_dlc(data.len()).is_none() {
            return Err(FrameError::Length {
                len: data.len(),
                why: "a CAN FD frame carries 0–8, 12, 16, 20, 24, 32, 48 or 64",
            });
        }
        Ok(CanFrame {
            id,
            extended,
            kind: FrameKind::Data,
            fd: Some((brs, esi)),
            data: data.to_vec(),
        })
    }

    /// A remote frame asking for `dlc` bytes (0–8).
    pub fn remote(id: u32, extended: bool, dlc: u8) -> Result<CanFrame, FrameError> {
        CanFrame::check_id(id, extended)?;
        if dlc > 8 {
            return Err(FrameError::Length {
                len: dlc.into(),
                why: "a remote frame asks for at most 8",
            });
        }
        Ok(CanFrame {
            id,
            extended,
            kind: FrameKind::Remote { dlc },
            fd: None,
            data: Vec::new(),
        })
    }

    /// An error frame with these error class bits and the controller's detail bytes.
    pub fn error(class: u32, detail: &[u8]) -> CanFrame {
        CanFrame {
            id: class & MAX_EXTENDED_ID,
            extended: false,
            kind: FrameKind::Error,
            fd: None,
            data: detail[..detail.len().min(MAX_CLASSIC)].to_vec(),
        }
    }

    /// The identifier (the error class bits of an error frame).
    pub fn id(&self) -> u32 {
        self.id
    }

    /// Whether the identifier is 29-bit.
    pub fn is_extended(&self) -> bool {
        self.extended
    }

    /// Data, remote or error.
    pub fn kind(&self) -> FrameKind {
        self.kind
    }

    /// Whether it is a CAN FD frame.
    pub fn is_fd(&self) -> bool {
        self.fd.is_some()
    }

    /// Whether a CAN FD frame switches bit rate.
    pub fn brs(&self) -> bool {
        self.fd.is_some_and(|(b, _)| b)
    }

    /// Whether a CAN FD frame's sender is error passive.
    pub fn esi(&self) -> bool {
        self.fd.is_some_and(|(_, e)| e)
    }

    /// The payload bytes.
    pub fn payload(&self) -> &[u8] {
        &self.data
    }

    /// The data length code: a remote frame's requested code, else the payload's.
    pub fn dlc(&self) -> u8 {
        match self.kind {
            FrameKind::Remote { dlc } => dlc,
            _ => len_to_dlc(self.data.len()).unwrap_or(0),
        }
    }

    /// The Linux `can_id` word of this frame: the identifier with the EFF (extended), RTR
    /// (remote) and ERR (error) flags, as SocketCAN and cannelloni carry it.
    pub fn linux_id(&self) -> u32 {
        let mut word = self.id;
        if self.extended {
            word |= LINUX_EFF;
        }
        match self.kind {
            FrameKind::Remote { .. } => word | LINUX_RTR,
            FrameKind::Error => word | LINUX_ERR,
            FrameKind::Data => word,
        }
    }

    /// The frame a Linux `can_id` word stands for, with its length (a remote frame's requested
    /// length), data (none for a remote frame) and CAN FD flags (`None` for a classic frame; bit
    /// 0x01 bit-rate switch, 0x02 error-state indicator, other bits ignored).
    pub fn from_linux(
        can_id: u32,
        len: usize,
        data: &[u8],
        fd_flags: Option<u8>,
    ) -> Result<CanFrame, String> {
        let extended = can_id & LINUX_EFF != 0;
        let bits = can_id & MAX_EXTENDED_ID;
        if can_id & LINUX_ERR != 0 {
            if fd_flags.is_some() || data.len() > MAX_CLASSIC {
                return Err(format!(
                    "an error frame of {} bytes{}",
                    data.len(),
                    if fd_flags.is_some() {
                        ", marked CAN FD"
                    } else {
                        ""
                    }
                ));
            }
            return Ok(CanFrame::error(bits, data));
        }
        if !extended && bits > MAX_STANDARD_ID {
            return Err(format!("identifier {bits:#x} without the extended flag"));
        }
        if can_id & LINUX_RTR != 0 {
            if fd_flags.is_some() {
                return Err("a remote frame marked CAN FD (CAN FD has no remote frames)".into());
            }
            let dlc = u8::try_from(len).unwrap_or(u8::MAX);
            return CanFrame::remote(bits, extended, dlc).map_err(|e| e.to_string());
        }
        match fd_flags {
            Some(f) => CanFrame::fd(bits, extended, data, f & 0x01 != 0, f & 0x02 != 0),
            None => CanFrame::data(bits, extended, data),
        }
        .map_err(|e| e.to_string())
    }

    /// The message topic of this frame (`can.123`, `can.18ff50e5`, `can.error`).
    pub fn topic(&self) -> String {
        match (self.kind, self.extended) {
            (FrameKind::Error, _) => ERROR_TOPIC.to_string(),
            (_, false) => format!("can.{:03x}", self.id),
            (_, true) => format!("can.{:08x}", self.id),
        }
    }

    /// The message payload of this frame, with the adapter's timestamp when there is one.
    pub fn to_map(&self, time_ms: Option<u32>) -> DataMap {
        let mut m = DataMap::with_capacity(3);
        m.push("data", Value::Bytes(self.data.clone()));
        match self.kind {
            FrameKind::Remote { dlc } => {
                m.push("rtr", true);
                m.push("dlc", i64::from(dlc));
            }
            FrameKind::Error => m.push("error", i64::from(self.id)),
            FrameKind::Data => {}
        }
        if let Some((brs, esi)) = self.fd {
            m.push("fd", true);
            if brs {
                m.push("brs", true);
            }
            if esi {
                m.push("esi", true);
            }
        }
        if let Some(t) = time_ms {
            m.push("time_ms", i64::from(t));
        }
        m
    }

    /// The frame a message on a CAN medium stands for (see the module's documentation).
    pub fn from_message(topic: &str, payload: &Payload) -> Result<CanFrame, String> {
        let digits = topic
            .strip_prefix("can.")
            .ok_or_else(|| format!("topic `{topic}`: a CAN medium carries topics can.ID"))?;
        let map;
        let (map, raw): (Option<&DataMap>, &[u8]) = match payload {
            Payload::Bytes(b) => (None, b),
            Payload::Map(m) => {
                let data = match m.get("data") {
                    None => &[][..],
                    Some(Value::Bytes(b)) => &b[..],
                    Some(v) => return Err(format!("`data` must be bytes, not {v}")),
                };
                (Some(&**m), data)
            }
            Payload::Xml(_) => {
                map = payload.to_map().map_err(|e| e.to_string())?;
                let data = match map.get("data") {
                    None => &[][..],
                    Some(Value::Bytes(b)) => &b[..],
                    Some(v) => return Err(format!("`data` must be bytes, not {v}")),
                };
                (Some(&map), data)
            }
        };
        // a datamap with other fields is not a frame (fields meant for a DBC mapping, a typo)
        if let Some((key, _)) = map
            .into_iter()
            .flat_map(|m| m.iter())
            .find(|(k, _)| !FRAME_FIELDS.contains(k))
        {
            return Err(format!(
                "topic `{topic}`: `{key}` is not a CAN frame's field ({}); send the frame's data \
                 as `data` bytes",
                FRAME_FIELDS.join(", ")
            ));
        }
        let flag = |key: &str| -> Result<bool, String> {
            match map.and_then(|m| m.get(key)) {
                None => Ok(false),
                Some(Value::Bool(b)) => Ok(*b),
                Some(v) => Err(format!("`{key}` must be true or false, not {v}")),
            }
        };
        if digits == "error" {
            return Err("error frames are the controller's to send".to_string());
        }
        let id = if !digits.is_empty() && digits.len() <= 8 {
            u32::from_str_radix(digits, 16).ok()
        } else {
            None
        }
        .ok_or_else(|| {
            format!("topic `{topic}`: `{digits}` is not a CAN identifier (1–8 hex digits)")
        })?;
        let extended = digits.len() > 3 || flag("ext")?;
        let text = |e: FrameError| format!("topic `{topic}`: {e}");
        if flag("rtr")? {
            let dlc = match map.and_then(|m| m.get("dlc")) {
                None => 0,
                Some(v) => v
                    .as_i64()
                    .and_then(|d| u8::try_from(d).ok())
                    .ok_or_else(|| format!("`dlc` must be 0–8, not {v}"))?,
            };
            return CanFrame::remote(id, extended, dlc).map_err(text);
        }
        if flag("fd")? || raw.len() > MAX_CLASSIC {
            CanFrame::fd(id, extended, raw, flag("brs")?, flag("esi")?).map_err(text)
        } else {
            CanFrame::data(id, extended, raw).map_err(text)
        }
    }
}

impl fmt::Display for CanFrame {
    /// `123#0102`, `18FF50E5#R2`, `123##1AABB` (FD, flags digit first), as `cansend` writes them.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "{:08X}", self.id)?;
        } else {
            write!(f, "{:03X}", self.id)?;
        }
        match (self.kind, self.fd) {
            (FrameKind::Remote { dlc }, _) => return write!(f, "#R{dlc}"),
            (_, Some((brs, esi))) => write!(f, "##{:X}", u8::from(brs) | (u8::from(esi) << 1))?,
            _ => f.write_str("#")?,
        }
        for b in &self.data {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_check_their_identifiers_and_lengths() {
        assert!(CanFrame::data(0x7FF, false, &[1; 8]).is_ok());
        assert_eq!(
            CanFrame::data(0x800, false, &[]).unwrap_err().to_string(),
            "identifier 0x800 is past the 11-bit limit 0x7ff"
        );
        assert!(CanFrame::data(0x1FFF_FFFF, true, &[]).is_ok());
        assert!(CanFrame::data(0x2000_0000, true, &[]).is_err());
        assert!(CanFrame::data(1, false, &[0; 9]).is_err());
        assert!(CanFrame::fd(1, false, &[0; 12], true, false).is_ok());
        assert!(CanFrame::fd(1, false, &[0; 13], true, false).is_err());
        assert!(CanFrame::remote(1, false, 9).is_err());
        assert_eq!(len_to_dlc(48), Some(14));
        assert_eq!(len_to_dlc(9), None);
    }

    #[test]
    fn frames_become_messages_and_back() {
        let cases = [
            (CanFrame::data(0x123, false, &[1, 2]).unwrap(), "can.123"),
            (
                CanFrame::data(0x18FF_50E5, true, &[]).unwrap(),
                "can.18ff50e5",
            ),
            (CanFrame::remote(0x5, false, 4).unwrap(), "can.005"),
            (
                CanFrame::fd(0x10, true, &[7; 16], true, true).unwrap(),
                "can.00000010",
            ),
        ];
        for (frame, topic) in cases {
            assert_eq!(frame.topic(), topic);
            let map = frame.to_map(None);
            let back = CanFrame::from_message(topic, &Payload::from(map)).unwrap();
            assert_eq!(back, frame);
        }
        let remote = CanFrame::remote(0x5, false, 4).unwrap().to_map(Some(1234));
        assert_eq!(remote.get_i64("dlc"), Some(4));
        assert_eq!(remote.get_i64("time_ms"), Some(1234));
        // bytes alone: a data frame, FD when long; a short topic made extended by `ext`
        let b = |v: &[u8]| Payload::Bytes(bytes::Bytes::copy_from_slice(v));
        assert_eq!(
            CanFrame::from_message("can.7ff", &b(&[1])).unwrap(),
            CanFrame::data(0x7FF, false, &[1]).unwrap()
        );
        assert!(
            CanFrame::from_message("can.1", &b(&[0; 20]))
                .unwrap()
                .is_fd()
        );
        let ext = DataMap::new().with("ext", true);
        assert!(
            CanFrame::from_message("can.12", &Payload::from(ext))
                .unwrap()
                .is_extended()
        );
    }

    #[test]
    fn bad_messages_say_what_is_wrong() {
        let b = |v: &[u8]| Payload::Bytes(bytes::Bytes::copy_from_slice(v));
        let err = |t: &str, p: &Payload| CanFrame::from_message(t, p).unwrap_err();
        assert_eq!(
            err("nav.depth", &b(&[])),
            "topic `nav.depth`: a CAN medium carries topics can.ID"
        );
        assert_eq!(
            err("can.xyz", &b(&[])),
            "topic `can.xyz`: `xyz` is not a CAN identifier (1–8 hex digits)"
        );
        assert_eq!(
            err("can.800", &b(&[])),
            "topic `can.800`: identifier 0x800 is past the 11-bit limit 0x7ff"
        );
        assert_eq!(
            err("can.1", &b(&[0; 13])),
            "topic `can.1`: 13 data bytes: a CAN FD frame carries 0–8, 12, 16, 20, 24, 32, 48 or 64"
        );
        let bad = Payload::from(DataMap::new().with("data", "text"));
        assert_eq!(err("can.1", &bad), "`data` must be bytes, not \"text\"");
        let fields = Payload::from(DataMap::new().with("x", 1i64));
        assert_eq!(
            err("can.1", &fields),
            "topic `can.1`: `x` is not a CAN frame's field (data, ext, rtr, dlc, fd, brs, esi, \
             error, time_ms); send the frame's data as `data` bytes"
        );
    }

    #[test]
    fn frames_print_as_cansend_writes_them() {
        assert_eq!(
            CanFrame::data(0x123, false, &[0xDE, 0xAD])
                .unwrap()
                .to_string(),
            "123#DEAD"
        );
        assert_eq!(
            CanFrame::remote(0x1ABCDEF, true, 2).unwrap().to_string(),
            "01ABCDEF#R2"
        );
        assert_eq!(
            CanFrame::fd(0x1, false, &[1], true, false)
                .unwrap()
                .to_string(),
            "001##101"
        );
    }
}
