//! Address claim, as NMEA 2000 takes it from ISO 11783-5 (SAE J1939-81).
//!
//! Every device on an NMEA 2000 network has a 64-bit NAME ([`Name`]) and a source address
//! (0–251) it must claim before it sends anything else:
//!
//! - on start it asks everyone for their claims (ISO Request, PGN 59904, for PGN 60928), then
//!   claims its preferred address (ISO Address Claim, PGN 60928, its NAME as the data, to
//!   everyone), and sends nothing else for 250 ms;
//! - it answers a request for PGN 60928 (to it or to everyone) with its claim;
//! - when another NAME claims its address, the lower NAME (as a 64-bit number) wins: when its own
//!   is lower it claims the address again (defends it); when it is higher it gives the address
//!   up and, when arbitrary-address capable, claims the first address after it (wrapping at
//!   251) that no device it has heard holds; when it is not capable, or no address is free, it
//!   sends "cannot claim" (a claim from the null address 254) and stops sending;
//! - it keeps a table of the addresses claimed and their NAMEs.
//!
//! [`Claimer`] is the state machine, without I/O: it is given the whole messages heard and the
//! time, and returns the messages to send.

use super::frame::{GLOBAL, Header, Message};
use std::collections::BTreeMap;
use std::time::Duration;
use tokio::time::Instant;

/// The PGN of ISO Address Claim.
pub const ADDRESS_CLAIM: u32 = 60928;
/// The PGN of ISO Request.
pub const REQUEST: u32 = 59904;
/// The address of a device that has none ("cannot claim", and requests before a claim).
pub const NULL: u8 = 254;
/// The highest address a device may claim.
pub const MAX_ADDRESS: u8 = 251;
/// How long a device waits after its claim before it sends anything else.
pub const CLAIM_WAIT: Duration = Duration::from_millis(250);

/// The parts of an ISO NAME.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Name {
    /// The device's unique number (21 bits, a serial number).
    pub unique_number: u32,
    /// The manufacturer's code (11 bits, NMEA's list).
    pub manufacturer_code: u16,
    /// The device instance (8 bits: the lower 3 and the upper 5).
    pub device_instance: u8,
    /// The device function (8 bits, by class: 130 with class 25 is a PC gateway).
    pub device_function: u8,
    /// The device class (7 bits: 25 internetwork device, 60 navigation, …).
    pub device_class: u8,
    /// The system instance (4 bits).
    pub system_instance: u8,
    /// The industry group (3 bits: 4 is marine).
    pub industry_group: u8,
    /// Whether the device can take another address when it loses its own.
    pub arbitrary_address_capable: bool,
}

impl Name {
    /// The 64-bit NAME: unique number in bits 0–20, manufacturer code 21–31, device instance
    /// 32–39, device function 40–47, a reserved bit 48, device class 49–55, system instance
    /// 56–59, industry group 60–62, arbitrary address capable 63.
    pub fn value(&self) -> u64 {
        u64::from(self.unique_number & 0x1F_FFFF)
            | u64::from(self.manufacturer_code & 0x7FF) << 21
            | u64::from(self.device_instance) << 32
            | u64::from(self.device_function) << 40
            | u64::from(self.device_class & 0x7F) << 49
            | u64::from(self.system_instance & 0xF) << 56
            | u64::from(self.industry_group & 0x7) << 60
            | u64::from(self.arbitrary_address_capable) << 63
    }
}

/// Where a claimer is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// It claimed an address and waits before using it.
    Claiming {
        /// When the claim was sent.
        since: Instant,
    },
    /// It holds its address.
    Claimed,
    /// It holds no address and sends nothing.
    CannotClaim,
}

impl State {
    /// Its name on the status topic.
    pub fn name(&self) -> &'static str {
        match self {
            State::Claiming { .. } => "claiming",
            State::Claimed => "claimed",
            State::CannotClaim => "cannot-claim",
        }
    }
}

/// What happened to a device's address, for the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Event {
    /// It defended its address against a higher NAME.
    Defended {
        /// The address.
        address: u8,
        /// The other NAME.
        other: u64,
    },
    /// It lost its address to a lower NAME and claims another.
    Moved {
        /// The address lost.
        from: u8,
        /// The address claimed.
        to: u8,
        /// The NAME it lost to.
        other: u64,
    },
    /// It lost its address and cannot claim another.
    Lost {
        /// The address lost.
        from: u8,
        /// The NAME it lost to.
        other: u64,
    },
}

/// The address-claim state machine (see the module's documentation).
#[derive(Debug)]
pub struct Claimer {
    name: Name,
    value: u64,
    address: u8,
    state: State,
    /// address → NAME, of the other devices heard
    table: BTreeMap<u8, u64>,
    events: Vec<Event>,
}

/// A message to send: its header and data.
pub type Out = (Header, Vec<u8>);

impl Claimer {
    /// A claimer of `preferred` (0–251) for `name`; [`Claimer::start`] sends its claim.
    pub fn new(name: Name, preferred: u8, now: Instant) -> Claimer {
        Claimer {
            value: name.value(),
            name,
            address: preferred.min(MAX_ADDRESS),
            state: State::Claiming { since: now },
            table: BTreeMap::new(),
            events: Vec::new(),
        }
    }

    /// Its NAME.
    pub fn name(&self) -> u64 {
        self.value
    }

    /// Where it is.
    pub fn state(&self) -> State {
        self.state
    }

    /// The address it claims or holds ([`NULL`] when it cannot claim).
    pub fn address(&self) -> u8 {
        match self.state {
            State::CannotClaim => NULL,
            _ => self.address,
        }
    }

    /// The address to send from, once it holds one and its wait is over.
    pub fn source(&mut self, now: Instant) -> Option<u8> {
        self.poll(now);
        (self.state == State::Claimed).then_some(self.address)
    }

    /// The other devices heard: address → NAME.
    pub fn devices(&self) -> &BTreeMap<u8, u64> {
        &self.table
    }

    /// What happened since the last call.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// Ends the wait after a claim; returns whether the state changed.
    pub fn poll(&mut self, now: Instant) -> bool {
        if let State::Claiming { since } = self.state
            && now.saturating_duration_since(since) >= CLAIM_WAIT
        {
            self.state = State::Claimed;
            return true;
        }
        false
    }

    fn claim(&self) -> Out {
        (
            Header {
                priority: 6,
                pgn: ADDRESS_CLAIM,
                source: self.address(),
                destination: GLOBAL,
            },
            self.value.to_le_bytes().to_vec(),
        )
    }

    /// The request for everyone's claims, and its own claim.
    pub fn start(&mut self, now: Instant) -> Vec<Out> {
        self.state = State::Claiming { since: now };
        let request = (
            Header {
                priority: 6,
                pgn: REQUEST,
                source: NULL,
                destination: GLOBAL,
            },
            ADDRESS_CLAIM.to_le_bytes()[..3].to_vec(),
        );
        vec![request, self.claim()]
    }

    /// Takes a message heard on the network; returns what to send in answer.
    pub fn take(&mut self, msg: &Message, now: Instant) -> Vec<Out> {
        let h = msg.header;
        match h.pgn {
            REQUEST => {
                let wanted = msg.data.len() >= 3
                    && u32::from_le_bytes([msg.data[0], msg.data[1], msg.data[2], 0])
                        == ADDRESS_CLAIM;
                let to_us = h.destination == GLOBAL || h.destination == self.address();
                if wanted && to_us {
                    vec![self.claim()]
                } else {
                    Vec::new()
                }
            }
            ADDRESS_CLAIM => {
                let Some(bytes) = msg.data.get(..8) else {
                    return Vec::new();
                };
                let mut b = [0u8; 8];
                b.copy_from_slice(bytes);
                let other = u64::from_le_bytes(b);
                if other == self.value {
                    // our own claim, heard back
                    return Vec::new();
                }
                if h.source > MAX_ADDRESS {
                    // "cannot claim": the NAME holds no address
                    self.table.retain(|_, n| *n != other);
                    return Vec::new();
                }
                // a NAME holds one address: its new claim replaces its old
                self.table.retain(|_, n| *n != other);
                self.table.insert(h.source, other);
                if self.state == State::CannotClaim || h.source != self.address {
                    return Vec::new();
                }
                if self.value < other {
                    self.events.push(Event::Defended {
                        address: self.address,
                        other,
                    });
                    return vec![self.claim()];
                }
                let from = self.address;
                match self.free_after(from) {
                    Some(to) if self.name.arbitrary_address_capable => {
                        self.address = to;
                        self.state = State::Claiming { since: now };
                        self.events.push(Event::Moved { from, to, other });
                    }
                    _ => {
                        self.state = State::CannotClaim;
                        self.events.push(Event::Lost { from, other });
                    }
                }
                vec![self.claim()]
            }
            _ => Vec::new(),
        }
    }

    /// The first address after `from` (wrapping past 251 to 0) that no device heard holds.
    fn free_after(&self, from: u8) -> Option<u8> {
        let span = u16::from(MAX_ADDRESS) + 1;
        (1..span)
            .map(|i| ((u16::from(from) + i) % span) as u8)
            .find(|a| !self.table.contains_key(a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn name(unique: u32, capable: bool) -> Name {
        Name {
            unique_number: unique,
            manufacturer_code: 999,
            device_instance: 0,
            device_function: 130,
            device_class: 25,
            system_instance: 0,
            industry_group: 4,
            arbitrary_address_capable: capable,
        }
    }

    fn claim_from(src: u8, n: u64) -> Message {
        Message {
            header: Header {
                priority: 6,
                pgn: ADDRESS_CLAIM,
                source: src,
                destination: GLOBAL,
            },
            data: n.to_le_bytes().to_vec(),
        }
    }

    #[test]
    fn a_name_is_the_bits_the_standard_places() {
        let n = name(123456, true);
        // canboat's decoder reads the same fields back from these bytes
        let db = super::super::builtin::database();
        let m = db.definitions(ADDRESS_CLAIM)[0]
            .decode(&n.value().to_le_bytes())
            .map;
        assert_eq!(m.get_i64("uniqueNumber"), Some(123456));
        assert_eq!(m.get_i64("manufacturerCode"), Some(999));
        assert_eq!(m.get_str("deviceFunction"), Some("PC Gateway"));
        assert_eq!(m.get_str("deviceClass"), Some("Internetwork device"));
        assert_eq!(m.get_str("industryGroup"), Some("Marine"));
        assert_eq!(m.get_str("arbitraryAddressCapable"), Some("Yes"));
    }

    #[test]
    fn it_waits_250_ms_then_holds_its_address() {
        let t = Instant::now();
        let mut c = Claimer::new(name(5, true), 40, t);
        let out = c.start(t);
        assert_eq!(out.len(), 2);
        assert_eq!((out[0].0.pgn, out[0].0.source), (REQUEST, NULL));
        assert_eq!(out[0].1, [0x00, 0xEE, 0x00]);
        assert_eq!((out[1].0.pgn, out[1].0.source), (ADDRESS_CLAIM, 40));
        assert_eq!(c.source(t + Duration::from_millis(249)), None);
        assert_eq!(c.source(t + CLAIM_WAIT), Some(40));
        // a request for its claim is answered
        let req = Message {
            header: Header {
                priority: 6,
                pgn: REQUEST,
                source: 7,
                destination: 40,
            },
            data: vec![0x00, 0xEE, 0x00],
        };
        let out = c.take(&req, t);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].1, c.name().to_le_bytes());
        // a request for another PGN is not
        let mut other = req.clone();
        other.data = vec![0x14, 0xF0, 0x01];
        assert!(c.take(&other, t).is_empty());
    }

    #[test]
    fn the_lower_name_keeps_the_address_the_higher_moves_to_a_free_one() {
        let t = Instant::now();
        let mut low = Claimer::new(name(5, true), 40, t);
        low.start(t);
        let high = name(9, true).value();
        // a higher NAME claims our address: we defend
        let out = low.take(&claim_from(40, high), t);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].0.source, 40);
        assert_eq!(low.address(), 40);
        assert!(matches!(
            low.take_events()[0],
            Event::Defended { address: 40, .. }
        ));

        let mut c = Claimer::new(name(9, true), 40, t);
        c.start(t);
        // 41 is taken by someone else, so 42
        assert!(c.take(&claim_from(41, name(1, true).value()), t).is_empty());
        let out = c.take(&claim_from(40, name(5, true).value()), t);
        assert_eq!((out[0].0.pgn, out[0].0.source), (ADDRESS_CLAIM, 42));
        assert_eq!(c.state(), State::Claiming { since: t });
        assert_eq!(c.source(t + CLAIM_WAIT), Some(42));
        assert_eq!(c.devices().len(), 2);
        assert_eq!(
            c.take_events(),
            [Event::Moved {
                from: 40,
                to: 42,
                other: name(5, true).value()
            }]
        );
    }

    #[test]
    fn a_device_that_cannot_move_says_so_and_stops() {
        let t = Instant::now();
        let mut c = Claimer::new(name(9, false), 40, t);
        c.start(t);
        let out = c.take(&claim_from(40, name(5, false).value()), t);
        assert_eq!((out[0].0.pgn, out[0].0.source), (ADDRESS_CLAIM, NULL));
        assert_eq!(c.state(), State::CannotClaim);
        assert_eq!(c.source(t + Duration::from_secs(1)), None);
        // it answers a request with "cannot claim"
        let req = Message {
            header: Header {
                priority: 6,
                pgn: REQUEST,
                source: 7,
                destination: GLOBAL,
            },
            data: vec![0x00, 0xEE, 0x00],
        };
        assert_eq!(c.take(&req, t)[0].0.source, NULL);
        // a full network: nowhere to go
        let mut full = Claimer::new(name(9, true), 0, t);
        for a in 1..=MAX_ADDRESS {
            full.take(&claim_from(a, 1000 + u64::from(a)), t);
        }
        full.take(&claim_from(0, 1), t);
        assert_eq!(full.state(), State::CannotClaim);
    }

    #[test]
    fn short_claims_and_requests_are_ignored() {
        let t = Instant::now();
        let mut c = Claimer::new(name(9, true), 40, t);
        let mut m = claim_from(40, 1);
        m.data.truncate(5);
        assert!(c.take(&m, t).is_empty());
        m.header.pgn = REQUEST;
        m.data.truncate(2);
        assert!(c.take(&m, t).is_empty());
        assert_eq!(c.address(), 40);
    }
}
