//! The MAVLink dialects a medium can speak (`dialect=` in its URL): which messages it knows, their
//! checksums, and their encoding, all from the `mavlink` crate's generated message sets.

use crate::convert;
use mavlink::consts;
use mavlink::error::MessageWriteError;
use mavlink::{
    MAVLinkMessageRaw, MAVLinkV1MessageRaw, MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message,
};
use seabus_medium::datamap::DataMap;
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::fmt;

/// A MAVLink dialect: a message set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Dialect {
    /// `common`: the messages every MAVLink system shares.
    Common,
    /// `ardupilotmega`: common and ArduPilot's own (ArduSub, ArduRover, ArduCopter, ArduPlane).
    ArduPilotMega,
}

/// Runs `$body` with `$m` the message type of `$dialect`.
macro_rules! with_messages {
    ($dialect:expr, $m:ident => $body:expr) => {
        match $dialect {
            Dialect::Common => {
                type $m = mavlink::dialects::common::MavMessage;
                $body
            }
            Dialect::ArduPilotMega => {
                type $m = mavlink::dialects::ardupilotmega::MavMessage;
                $body
            }
        }
    };
}

impl Dialect {
    /// Every dialect, by name.
    pub const ALL: [Dialect; 2] = [Dialect::Common, Dialect::ArduPilotMega];

    /// Its name, as `dialect=` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Dialect::Common => "common",
            Dialect::ArduPilotMega => "ardupilotmega",
        }
    }

    /// The dialect called `name`.
    pub fn from_name(name: &str) -> Option<Dialect> {
        Dialect::ALL.into_iter().find(|d| d.name() == name)
    }

    /// Whether message `id` is in the dialect.
    pub fn knows(self, id: u32) -> bool {
        with_messages!(self, M => M::all_ids().binary_search(&id).is_ok())
    }

    /// The name of message `id`, when the dialect has it.
    pub fn message_name(self, id: u32) -> Option<&'static str> {
        with_messages!(self, M => M::default_message_from_id(id).map(|m| m.message_name()))
    }

    /// The id of message `name`, when the dialect has it.
    pub fn message_id(self, name: &str) -> Option<u32> {
        with_messages!(self, M => M::message_id_from_name(name))
    }

    /// Whether a frame's checksum holds (with its message's CRC_EXTRA in this dialect).
    pub fn checksum_holds(self, raw: &MAVLinkMessageRaw) -> bool {
        let extra = with_messages!(self, M => M::extra_crc(raw.message_id()));
        let (bytes, trailer, sum) = match raw {
            MAVLinkMessageRaw::V1(r) => (r.raw_bytes(), consts::CHECKSUM_SIZE, r.checksum()),
            MAVLinkMessageRaw::V2(r) => (
                r.raw_bytes(),
                consts::CHECKSUM_SIZE
                    + if r.incompatibility_flags() & consts::v2::IFLAG_SIGNED != 0 {
                        consts::v2::SIGNATURE_SIZE
                    } else {
                        0
                    },
                r.checksum(),
            ),
        };
        bytes.len() >= consts::STX_SIZE + trailer
            && crc(&bytes[consts::STX_SIZE..bytes.len() - trailer], extra) == sum
    }

    /// The message a frame carries: its name and its fields as a datamap ([`convert`]); the error
    /// says why the payload does not read (a value its enum does not have, text that is not UTF-8).
    pub fn decode(self, raw: &MAVLinkMessageRaw) -> Result<(&'static str, DataMap), String> {
        with_messages!(self, M => decode_as::<M>(raw))
    }

    /// Message `name` made of the fields of `map`, framed in `version` with `header`; the error
    /// names the message and the field.
    pub fn encode(
        self,
        version: MavlinkVersion,
        header: MavHeader,
        name: &str,
        map: &DataMap,
    ) -> Result<Vec<u8>, String> {
        with_messages!(self, M => encode_as::<M>(version, header, name, map))
    }
}

/// MAVLink's checksum (CRC-16/MCRF4XX, as `mavlink::calculate_crc`) of `data` and then `extra`,
/// a byte at a time from a table.
fn crc(data: &[u8], extra: u8) -> u16 {
    let step = |crc: u16, b: u8| (crc >> 8) ^ CRC_TABLE[usize::from(crc as u8 ^ b)];
    step(data.iter().fold(0xFFFF, |c, &b| step(c, b)), extra)
}

/// The checksum's remainder of each byte (polynomial 0x1021, reflected).
static CRC_TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u16;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0x8408
            } else {
                c >> 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

impl fmt::Display for Dialect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A frame's bytes in the crate's raw message type of its version (`bytes` is one whole frame,
/// at most [`crate::frame::MAX_FRAME`] bytes).
pub fn raw(version: MavlinkVersion, bytes: &[u8]) -> MAVLinkMessageRaw {
    match version {
        MavlinkVersion::V1 => {
            let mut r = MAVLinkV1MessageRaw::new();
            r.as_mut_slice()[..bytes.len()].copy_from_slice(bytes);
            MAVLinkMessageRaw::V1(r)
        }
        MavlinkVersion::V2 => {
            let mut r = MAVLinkV2MessageRaw::new();
            r.as_mut_slice()[..bytes.len()].copy_from_slice(bytes);
            MAVLinkMessageRaw::V2(r)
        }
    }
}

fn decode_as<M: Message + Serialize>(
    raw: &MAVLinkMessageRaw,
) -> Result<(&'static str, DataMap), String> {
    let msg =
        M::parse(raw.version(), raw.message_id(), raw.payload()).map_err(|e| e.to_string())?;
    let map = convert::to_map(&msg).map_err(|e| format!("{}: {e}", msg.message_name()))?;
    Ok((msg.message_name(), map))
}

fn encode_as<M: Message + Serialize + DeserializeOwned>(
    version: MavlinkVersion,
    header: MavHeader,
    name: &str,
    map: &DataMap,
) -> Result<Vec<u8>, String> {
    let msg: M = convert::from_map(name, map)?;
    let mut out = Vec::with_capacity(crate::frame::MAX_FRAME);
    mavlink::write_versioned_msg(&mut out, version, header, &msg).map_err(|e| match e {
        MessageWriteError::MAVLink2Only => format!(
            "{name} (id {}) exists only in MAVLink 2, and this medium sends MAVLink 1 (version=1)",
            msg.message_id()
        ),
        other => other.to_string(),
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checksum_is_the_crates() {
        let data: Vec<u8> = (0..300u32).map(|i| (i * 7919 % 251) as u8).collect();
        for len in [0, 1, 2, 9, 17, 40, 255, 300] {
            for extra in [0, 50, 39, 255] {
                assert_eq!(
                    crc(&data[..len], extra),
                    mavlink::calculate_crc(&data[..len], extra),
                    "{len} bytes, extra {extra}"
                );
            }
        }
    }

    #[test]
    fn dialects_know_their_messages() {
        for d in Dialect::ALL {
            assert_eq!(Dialect::from_name(d.name()), Some(d));
            assert_eq!(d.message_name(30), Some("ATTITUDE"));
            assert_eq!(d.message_id("COMMAND_LONG"), Some(76));
            assert!(!d.knows(16_000_000));
        }
        assert_eq!(Dialect::from_name("ArduPilotMega"), None);
        // ArduPilot's own messages (RANGEFINDER is 173) are not common's
        assert!(Dialect::ArduPilotMega.knows(173));
        assert!(!Dialect::Common.knows(173));
    }

    #[test]
    fn an_encoded_frame_decodes_to_the_same_fields_in_either_version() {
        let map = DataMap::new()
            .with("time_boot_ms", 77i64)
            .with("roll", 0.5)
            .with("pitch", -0.125)
            .with("yaw", 3.0)
            .with("rollspeed", 0.0)
            .with("pitchspeed", 0.0)
            .with("yawspeed", 0.25);
        let header = MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: 9,
        };
        for version in [MavlinkVersion::V1, MavlinkVersion::V2] {
            let bytes = Dialect::ArduPilotMega
                .encode(version, header, "ATTITUDE", &map)
                .unwrap();
            let raw = raw(version, &bytes);
            assert!(Dialect::Common.checksum_holds(&raw));
            assert_eq!(
                (raw.system_id(), raw.component_id(), raw.sequence()),
                (255, 190, 9)
            );
            let (name, back) = Dialect::Common.decode(&raw).unwrap();
            assert_eq!((name, back), ("ATTITUDE", map.clone()));
        }
        // a MAVLink 2 message has no MAVLink 1 frame
        let e = Dialect::Common
            .encode(
                MavlinkVersion::V1,
                header,
                "PROTOCOL_VERSION",
                &DataMap::new()
                    .with("version", 200i64)
                    .with("min_version", 100i64)
                    .with("max_version", 200i64)
                    .with("spec_version_hash", Vec::<seabus_medium::Value>::new())
                    .with("library_version_hash", Vec::<seabus_medium::Value>::new()),
            )
            .unwrap_err();
        assert_eq!(
            e,
            "PROTOCOL_VERSION (id 300) exists only in MAVLink 2, and this medium sends MAVLink 1 (version=1)"
        );
    }

    #[test]
    fn a_value_its_enum_does_not_have_does_not_decode() {
        let map = DataMap::new()
            .with("custom_mode", 0i64)
            .with("type", "MAV_TYPE_SUBMARINE")
            .with("autopilot", "MAV_AUTOPILOT_ARDUPILOTMEGA")
            .with("base_mode", 0i64)
            .with("system_status", "MAV_STATE_ACTIVE")
            .with("mavlink_version", 3i64);
        let mut bytes = Dialect::Common
            .encode(MavlinkVersion::V1, MavHeader::default(), "HEARTBEAT", &map)
            .unwrap();
        // the type byte (after custom_mode) set to a value MAV_TYPE does not have, checksum redone
        bytes[6 + 4] = 250;
        let crc = mavlink::calculate_crc(&bytes[1..bytes.len() - 2], 50);
        let n = bytes.len();
        bytes[n - 2..].copy_from_slice(&crc.to_le_bytes());
        let raw = raw(MavlinkVersion::V1, &bytes);
        assert!(Dialect::Common.checksum_holds(&raw));
        let e = Dialect::Common.decode(&raw).unwrap_err();
        assert!(e.contains("MavType") && e.contains("250"), "{e}");
    }
}
