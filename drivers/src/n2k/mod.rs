//! NMEA 2000 on a CAN medium: frames ([`frame`]: 29-bit identifiers, fast-packet and transport
//! protocol reassembly), PGN definitions and their decoding ([`pgn`]) and encoding ([`encode`]), canboat's PGN database
//! read at run time ([`json`]) and a built-in set of the common PGNs ([`builtin`]), the standard
//! datasets the navigation PGNs give ([`nav`]), address claim ([`claim`]), PGNs shown with the names and units of their fields ([`describe`]), and the `nmea2000` driver module ([`driver`]).

pub mod builtin;
pub mod claim;
pub mod describe;
pub mod driver;
pub mod encode;
pub mod frame;
pub mod json;
pub mod nav;
pub mod pgn;
