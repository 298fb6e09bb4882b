//! NMEA 0183: sentence parsing and building ([`sentence`]) and the sensor drivers that turn
//! sentences into standard datasets ([`sensors`]), sharing one parse per sentence ([`mod@line`]). Framing (bytes → sentences, checksums) is the
//! serial medium's (`seabus_medium::framing`).

pub mod attitude;
pub mod line;
mod read;
pub mod sensors;
pub mod sentence;
