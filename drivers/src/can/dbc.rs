//! CAN databases (`.dbc` files): read with the `can-dbc` crate into [`Database`], whose messages
//! decode frame data into datamaps and encode datamaps back into frame data.
//!
//! - A signal's raw bits are taken in Intel (little-endian: the start bit is the least significant
//!   bit) or Motorola order (big-endian: the start bit is the most significant, numbered as DBC
//!   files number bits, 7…0 in byte 0, 15…8 in byte 1), signed (two's complement) or unsigned, or
//!   as an IEEE float or double (`SIG_VALTYPE_`); the physical value is `raw × factor + offset`.
//! - A physical value is an integer in the datamap when factor and offset are whole numbers, else a
//!   float. A signal with value descriptions (`VAL_`) also gives `SIGNAL_text`, the description of
//!   its raw value.
//! - A multiplexed message decodes its multiplexor (`M`) and then only the signals of that
//!   multiplexor value (`m3`). Extended multiplexing (`SG_MUL_VAL_`) is refused when the file is
//!   read.
//! - Encoding takes the physical values of a datamap (or a signal's description, for signals with
//!   value descriptions), refuses a value outside the signal's `[min|max]` (unless both are 0), one
//!   the raw field cannot hold, an unknown signal, or one of another multiplexor value, each with
//!   the reason; a signal not given takes its `GenSigStartValue` (raw) or 0.

use can_dbc::{ByteOrder, MultiplexIndicator, NumericValue, ValueType};
use seabus_medium::xml::{FileError, Pos};
use seabus_medium::{DataMap, Value};
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// How a signal's raw bits are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawType {
    /// Unsigned integer.
    Unsigned,
    /// Two's complement integer.
    Signed,
    /// IEEE 754 single precision (32 bits).
    Float,
    /// IEEE 754 double precision (64 bits).
    Double,
}

/// Which messages of a multiplexed message a signal is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mux {
    /// Always there.
    Plain,
    /// The multiplexor: its value says which multiplexed signals follow.
    Multiplexor,
    /// There when the multiplexor has this value.
    When(u64),
}

/// One signal of a message.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    /// Its name (a datamap key).
    pub name: String,
    /// The raw field's first bit (see the module's documentation).
    pub start: u32,
    /// The raw field's width in bits (1–64).
    pub size: u32,
    /// Intel (`true`) or Motorola order.
    pub little_endian: bool,
    /// How the raw bits are read.
    pub raw_type: RawType,
    /// Physical = raw × factor + offset.
    pub factor: f64,
    /// See `factor`.
    pub offset: f64,
    /// Smallest physical value (with `max`: no limit when both are 0).
    pub min: f64,
    /// Largest physical value.
    pub max: f64,
    /// The unit.
    pub unit: String,
    /// Its part in multiplexing.
    pub mux: Mux,
    /// Descriptions of raw values.
    pub values: BTreeMap<i64, String>,
    /// The raw value sent when a command does not give the signal.
    pub start_value: i64,
}

/// One message of a database.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageDef {
    /// The identifier.
    pub id: u32,
    /// Whether it is 29-bit.
    pub extended: bool,
    /// Its name (a topic segment).
    pub name: String,
    /// Its length in bytes.
    pub size: usize,
    /// The nodes that send it.
    pub senders: Vec<String>,
    /// Its signals, in file order.
    pub signals: Vec<Signal>,
}

/// A CAN database.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Database {
    /// The file it came from.
    pub file: Arc<str>,
    /// Its messages, in file order.
    pub messages: Vec<MessageDef>,
}

/// Why a datamap cannot be encoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}: {what}")]
pub struct EncodeError {
    /// The message's name.
    pub message: String,
    /// What was wrong.
    pub what: String,
}

fn pos_in(file: &Arc<str>, text: &str, needle: Option<&str>) -> Pos {
    let at = needle.and_then(|n| text.find(n)).unwrap_or(0);
    let before = &text[..at];
    let line = before.matches('\n').count() as u32 + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) as u32 + 1;
    Pos {
        file: file.clone(),
        line,
        col,
    }
}

fn number(v: &NumericValue) -> f64 {
    match v {
        NumericValue::Uint(u) => *u as f64,
        NumericValue::Int(i) => *i as f64,
        NumericValue::Double(d) => *d,
    }
}

impl Database {
    /// Reads a `.dbc` file.
    pub fn load(path: &Path) -> Result<Database, FileError> {
        let file: Arc<str> = Arc::from(path.display().to_string());
        let bytes = std::fs::read(path).map_err(|e| FileError {
            pos: Pos {
                file: file.clone(),
                line: 1,
                col: 1,
            },
            message: format!("cannot read: {e}"),
        })?;
        // DBC files are often written in Windows-1252: bytes that are not UTF-8 are taken as such
        let text = match String::from_utf8(bytes) {
            Ok(t) => t,
            Err(e) => e.into_bytes().iter().map(|&b| char::from(b)).collect(),
        };
        Database::parse(&file, &text)
    }

    /// Reads a database from `text`, naming `file` in errors.
    pub fn parse(file: &str, text: &str) -> Result<Database, FileError> {
        let file: Arc<str> = Arc::from(file);
        let dbc = can_dbc::Dbc::try_from(text).map_err(|e| parse_error(&file, text, &e))?;
        let r = Reader {
            dbc: &dbc,
            file: &file,
            text,
        };
        if let Some(x) = dbc.extended_multiplex.first() {
            return Err(r.err(
                "SG_MUL_VAL_",
                format!(
                    "extended multiplexing (SG_MUL_VAL_, signal `{}`) is not supported",
                    x.signal_name
                ),
            ));
        }
        let messages = dbc
            .messages
            .iter()
            .map(|m| r.message(m))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Database { file, messages })
    }

    /// The message with identifier `id`.
    pub fn by_id(&self, id: u32, extended: bool) -> Option<&MessageDef> {
        self.messages
            .iter()
            .find(|m| m.id == id && m.extended == extended)
    }

    /// The message called `name`.
    pub fn by_name(&self, name: &str) -> Option<&MessageDef> {
        self.messages.iter().find(|m| m.name == name)
    }
}

/// A database read by `can-dbc`, turned into [`MessageDef`]s; errors are placed in the file's
/// text.
struct Reader<'a> {
    dbc: &'a can_dbc::Dbc,
    file: &'a Arc<str>,
    text: &'a str,
}

impl Reader<'_> {
    /// An error placed where `needle` first appears in the file.
    fn err(&self, needle: &str, message: String) -> FileError {
        FileError {
            pos: pos_in(self.file, self.text, Some(needle)),
            message,
        }
    }

    /// A message: its identifier, size (at most 64 bytes), signals and senders.
    fn message(&self, m: &can_dbc::Message) -> Result<MessageDef, FileError> {
        let (id, extended) = match m.id {
            can_dbc::MessageId::Standard(i) => (u32::from(i), false),
            can_dbc::MessageId::Extended(i) => (i, true),
        };
        let here = format!("BO_ {} {}", m.id.raw(), m.name);
        let size = usize::try_from(m.size).unwrap_or(usize::MAX);
        if size > 64 {
            return Err(self.err(
                &here,
                format!(
                    "message `{}` is {size} bytes; a CAN frame holds at most 64",
                    m.name
                ),
            ));
        }
        let signals = m
            .signals
            .iter()
            .map(|s| self.signal(m, size, s))
            .collect::<Result<Vec<_>, _>>()?;
        let mut senders: Vec<String> = m.transmitter.iter().cloned().collect();
        for t in self
            .dbc
            .message_transmitters
            .iter()
            .filter(|t| t.message_id == m.id)
        {
            senders.extend(t.transmitter.iter().cloned());
        }
        Ok(MessageDef {
            id,
            extended,
            name: m.name.clone(),
            size,
            senders,
            signals,
        })
    }

    /// A signal of message `m` (`size` bytes long): refused when its bits do not fit, its raw type
    /// does not match its width, or its factor and offset give no value.
    fn signal(
        &self,
        m: &can_dbc::Message,
        size: usize,
        s: &can_dbc::Signal,
    ) -> Result<Signal, FileError> {
        let sig_err = |what: String| {
            self.err(
                &format!("SG_ {}", s.name),
                format!("signal `{}` of `{}`: {what}", s.name, m.name),
            )
        };
        let raw_type = self.raw_type(m, s);
        let (start, size_bits) = (s.start_bit, s.size);
        if size_bits == 0 || size_bits > 64 {
            return Err(sig_err(format!("{size_bits} bits; a signal has 1 to 64")));
        }
        let little = s.byte_order == ByteOrder::LittleEndian;
        if !fits(start, size_bits, little, size) {
            return Err(sig_err(format!(
                "bits from {start} for {size_bits} do not fit in {size} bytes"
            )));
        }
        let needs = match raw_type {
            RawType::Float => Some(32),
            RawType::Double => Some(64),
            _ => None,
        };
        if needs.is_some_and(|n| n != size_bits) {
            return Err(sig_err(format!(
                "a {raw_type:?} signal of {size_bits} bits"
            )));
        }
        if s.factor == 0.0 || !s.factor.is_finite() || !s.offset.is_finite() {
            return Err(sig_err(format!(
                "factor {} and offset {} do not give a value",
                s.factor, s.offset
            )));
        }
        let values = self
            .dbc
            .value_descriptions_for_signal(m.id, &s.name)
            .map(|v| v.iter().map(|d| (d.id, d.description.clone())).collect())
            .unwrap_or_default();
        Ok(Signal {
            name: s.name.clone(),
            start: start as u32,
            size: size_bits as u32,
            little_endian: little,
            raw_type,
            factor: s.factor,
            offset: s.offset,
            min: number(&s.min),
            max: number(&s.max),
            unit: s.unit.clone(),
            mux: match s.multiplexer_indicator {
                MultiplexIndicator::Plain => Mux::Plain,
                MultiplexIndicator::Multiplexor => Mux::Multiplexor,
                MultiplexIndicator::MultiplexedSignal(v)
                | MultiplexIndicator::MultiplexorAndMultiplexedSignal(v) => Mux::When(v),
            },
            values,
            start_value: self.start_value(m, s),
        })
    }

    /// How a signal's raw bits are read: a float or double as `SIG_VALTYPE_` says, else a signed
    /// or unsigned integer.
    fn raw_type(&self, m: &can_dbc::Message, s: &can_dbc::Signal) -> RawType {
        match self
            .dbc
            .signal_extended_value_type_list
            .iter()
            .find(|x| x.message_id == m.id && x.signal_name == s.name)
            .map(|x| x.signal_extended_value_type)
        {
            Some(can_dbc::SignalExtendedValueType::IEEEfloat32Bit) => RawType::Float,
            Some(can_dbc::SignalExtendedValueType::IEEEdouble64bit) => RawType::Double,
            _ if s.value_type == ValueType::Signed => RawType::Signed,
            _ => RawType::Unsigned,
        }
    }

    /// A signal's `GenSigStartValue` (raw), or 0.
    fn start_value(&self, m: &can_dbc::Message, s: &can_dbc::Signal) -> i64 {
        self.dbc
            .attribute_values_signal
            .iter()
            .find(|a| {
                a.name == "GenSigStartValue" && a.message_id == m.id && a.signal_name == s.name
            })
            .and_then(|a| match &a.value {
                can_dbc::AttributeValue::Uint(u) => i64::try_from(*u).ok(),
                can_dbc::AttributeValue::Int(i) => Some(*i),
                can_dbc::AttributeValue::Double(d) => Some(*d as i64),
                _ => None,
            })
            .unwrap_or(0)
    }
}

/// A parse error of `can-dbc`, placed in the file.
fn parse_error(file: &Arc<str>, text: &str, e: &can_dbc::DbcError) -> FileError {
    let shown = e.to_string();
    // pest errors say ` --> LINE:COL` and end with `= what was expected`
    if let Some(at) = shown.split("--> ").nth(1) {
        let mut lc = at
            .split(|c: char| !c.is_ascii_digit())
            .filter(|s| !s.is_empty())
            .map(|n| n.parse::<u32>().unwrap_or(1));
        let (line, col) = (lc.next().unwrap_or(1), lc.next().unwrap_or(1));
        let what = shown
            .lines()
            .rev()
            .find_map(|l| l.trim().strip_prefix("= "))
            .unwrap_or("not DBC")
            .to_string();
        return FileError {
            pos: Pos {
                file: file.clone(),
                line,
                col,
            },
            message: what,
        };
    }
    let needle = match e {
        can_dbc::DbcError::InvalidFloat(s)
        | can_dbc::DbcError::InvalidInt(s)
        | can_dbc::DbcError::InvalidUint(s)
        | can_dbc::DbcError::InvalidNumericValue(s)
        | can_dbc::DbcError::UnknownMultiplexIndicator(s) => Some(s.as_str()),
        _ => None,
    };
    FileError {
        pos: pos_in(file, text, needle),
        message: shown,
    }
}

/// Whether a field of `size` bits from `start`, in Intel (`little`) or Motorola order, lies within
/// `bytes` bytes.
pub fn fits(start: u64, size: u64, little: bool, bytes: usize) -> bool {
    if size == 0 || size > 64 || start >= 512 {
        return false;
    }
    if little {
        start + size <= 8 * bytes as u64
    } else {
        motorola_bits(start as u32, size as u32, bytes).is_some()
    }
}

/// The bit positions of a Motorola signal, most significant first, if it fits in `bytes`.
fn motorola_bits(start: u32, size: u32, bytes: usize) -> Option<Vec<u32>> {
    let mut out = Vec::with_capacity(size as usize);
    let mut pos = start;
    for i in 0..size {
        if pos as usize >= 8 * bytes {
            return None;
        }
        out.push(pos);
        if i + 1 < size {
            pos = if pos.is_multiple_of(8) {
                pos + 15
            } else {
                pos - 1
            };
        }
    }
    Some(out)
}

fn bit(data: &[u8], pos: u32) -> u64 {
    data.get(pos as usize / 8)
        .map_or(0, |b| u64::from((b >> (pos % 8)) & 1))
}

fn set_bit(data: &mut [u8], pos: u32, on: bool) {
    if let Some(b) = data.get_mut(pos as usize / 8) {
        let mask = 1u8 << (pos % 8);
        if on {
            *b |= mask;
        } else {
            *b &= !mask;
        }
    }
}

impl Signal {
    /// The raw bits of this signal in `data` (missing bytes read as 0).
    pub fn raw_bits(&self, data: &[u8]) -> u64 {
        if self.little_endian {
            (0..self.size).fold(0u64, |v, k| v | (bit(data, self.start + k) << k))
        } else {
            let positions = motorola_bits(self.start, self.size, 64).unwrap_or_default();
            positions.iter().fold(0u64, |v, &p| (v << 1) | bit(data, p))
        }
    }

    /// Writes the raw bits of this signal into `data` (bits past its end are dropped).
    pub fn put_bits(&self, data: &mut [u8], raw: u64) {
        if self.little_endian {
            for k in 0..self.size {
                set_bit(data, self.start + k, (raw >> k) & 1 == 1);
            }
        } else {
            let positions = motorola_bits(self.start, self.size, 64).unwrap_or_default();
            let n = positions.len();
            for (i, &p) in positions.iter().enumerate() {
                set_bit(data, p, (raw >> (n - 1 - i)) & 1 == 1);
            }
        }
    }

    /// The raw value as an integer (signed ones sign-extended).
    fn raw_int(&self, bits: u64) -> i64 {
        match self.raw_type {
            RawType::Signed if self.size < 64 && (bits >> (self.size - 1)) & 1 == 1 => {
                (bits | (u64::MAX << self.size)) as i64
            }
            _ => bits as i64,
        }
    }

    fn whole(&self) -> bool {
        self.factor.fract() == 0.0
            && self.offset.fract() == 0.0
            && matches!(self.raw_type, RawType::Signed | RawType::Unsigned)
    }

    /// The physical value in `data`.
    pub fn decode(&self, data: &[u8]) -> Value {
        let bits = self.raw_bits(data);
        let raw = match self.raw_type {
            RawType::Float => f64::from(f32::from_bits(bits as u32)),
            RawType::Double => f64::from_bits(bits),
            RawType::Unsigned => bits as f64,
            RawType::Signed => self.raw_int(bits) as f64,
        };
        let physical = raw * self.factor + self.offset;
        if self.whole() && physical.abs() < 9.0e15 {
            Value::Int(physical as i64)
        } else {
            Value::Float(physical)
        }
    }

    /// The raw bits for a physical value, or why it cannot be sent.
    pub fn encode_value(&self, v: &Value) -> Result<u64, String> {
        let physical = match v {
            Value::Str(label) => {
                let Some((raw, _)) = self.values.iter().find(|(_, d)| d.as_str() == &**label)
                else {
                    let known: Vec<&str> = self.values.values().map(String::as_str).collect();
                    return Err(if known.is_empty() {
                        format!("`{label}` is not a number")
                    } else {
                        format!("`{label}` is not one of {}", known.join(", "))
                    });
                };
                *raw as f64 * self.factor + self.offset
            }
            other => other
                .as_f64()
                .ok_or_else(|| format!("{other} is not a number"))?,
        };
        if !physical.is_finite() {
            return Err(format!("{physical} is not a value"));
        }
        let limited = !(self.min == 0.0 && self.max == 0.0);
        if limited && (physical < self.min || physical > self.max) {
            return Err(format!(
                "{physical} {} is outside [{} … {}]",
                self.unit, self.min, self.max
            )
            .replace("  ", " "));
        }
        let raw = (physical - self.offset) / self.factor;
        match self.raw_type {
            RawType::Float => Ok(u64::from((raw as f32).to_bits())),
            RawType::Double => Ok(raw.to_bits()),
            RawType::Unsigned | RawType::Signed => {
                let raw = raw.round();
                let (lo, hi) = match (self.raw_type, self.size) {
                    (RawType::Signed, 64) => (i64::MIN as f64, i64::MAX as f64),
                    (RawType::Signed, n) => {
                        (-((1u64 << (n - 1)) as f64), ((1u64 << (n - 1)) - 1) as f64)
                    }
                    (_, 64) => (0.0, u64::MAX as f64),
                    (_, n) => (0.0, ((1u64 << n) - 1) as f64),
                };
                if raw < lo || raw > hi {
                    return Err(format!(
                        "{physical} needs raw value {raw}, which {} bits cannot hold",
                        self.size
                    ));
                }
                let int = if raw < 0.0 {
                    raw as i64 as u64
                } else {
                    raw as u64
                };
                Ok(if self.size < 64 {
                    int & ((1u64 << self.size) - 1)
                } else {
                    int
                })
            }
        }
    }
}

impl MessageDef {
    /// The multiplexor signal, if the message is multiplexed.
    pub fn multiplexor(&self) -> Option<&Signal> {
        self.signals.iter().find(|s| s.mux == Mux::Multiplexor)
    }

    /// The signals present in `data`: all plain ones, the multiplexor, and the multiplexed ones of
    /// its value.
    fn present<'a>(&'a self, mux: Option<u64>) -> impl Iterator<Item = &'a Signal> + 'a {
        self.signals.iter().filter(move |s| match s.mux {
            Mux::Plain | Mux::Multiplexor => true,
            Mux::When(v) => Some(v) == mux,
        })
    }

    /// The datamap of a frame's data.
    pub fn decode(&self, data: &[u8]) -> DataMap {
        let mux = self.multiplexor().map(|m| m.raw_bits(data));
        let mut map = DataMap::with_capacity(self.signals.len());
        for s in self.present(mux) {
            map.push(s.name.clone(), s.decode(data));
            if !s.values.is_empty() {
                let raw = s.raw_int(s.raw_bits(data));
                if let Some(d) = s.values.get(&raw) {
                    map.push(format!("{}_text", s.name), d.clone());
                }
            }
        }
        map
    }

    /// The frame data for a datamap of physical values.
    pub fn encode(&self, values: &DataMap) -> Result<Vec<u8>, EncodeError> {
        let fail = |what: String| EncodeError {
            message: self.name.clone(),
            what,
        };
        let mux = match self.multiplexor() {
            None => None,
            Some(m) => {
                let v = values.get(&m.name).ok_or_else(|| {
                    fail(format!(
                        "a multiplexed message needs its multiplexor `{}`",
                        m.name
                    ))
                })?;
                Some(
                    m.encode_value(v)
                        .map_err(|e| fail(format!("signal `{}`: {e}", m.name)))?,
                )
            }
        };
        for (key, _) in values.iter() {
            match self.signals.iter().find(|s| s.name == key) {
                None => {
                    let known: Vec<&str> = self.signals.iter().map(|s| s.name.as_str()).collect();
                    return Err(fail(format!(
                        "`{key}` is not a signal of it; its signals: {}",
                        known.join(", ")
                    )));
                }
                Some(Signal {
                    mux: Mux::When(v), ..
                }) if Some(*v) != mux => {
                    return Err(fail(format!(
                        "signal `{key}` is sent with multiplexor value {v}, not {}",
                        mux.unwrap_or(0)
                    )));
                }
                Some(_) => {}
            }
        }
        let mut data = vec![0u8; self.size];
        for s in self.present(mux) {
            let raw = match values.get(&s.name) {
                Some(v) => s
                    .encode_value(v)
                    .map_err(|e| fail(format!("signal `{}`: {e}", s.name)))?,
                None => s.start_value as u64,
            };
            s.put_bits(&mut data, raw);
        }
        Ok(data)
    }
}

impl fmt::Display for MessageDef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "{} ({:08X})", self.name, self.id)
        } else {
            write!(f, "{} ({:03X})", self.name, self.id)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Database {
        Database::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/can/vehicle.dbc"))
            .expect("the example database loads")
    }

    fn float(m: &DataMap, key: &str) -> f64 {
        m.get(key)
            .and_then(Value::as_f64)
            .unwrap_or_else(|| panic!("{key} in {m:?}"))
    }

    #[test]
    fn the_example_reads() {
        let db = example();
        let names: Vec<String> = db.messages.iter().map(ToString::to_string).collect();
        assert_eq!(
            names,
            [
                "ThrusterCommand (100)",
                "ThrusterStatus (101)",
                "BatteryStatus (18FF50E5)",
                "BatteryCells (18FF50E6)"
            ]
        );
        let cmd = db.by_name("ThrusterCommand").unwrap();
        assert_eq!(cmd.senders, ["SEABUS"]);
        assert_eq!(cmd.signals[2].start_value, 10);
        assert_eq!(db.by_id(0x18FF_50E5, true).unwrap().name, "BatteryStatus");
        assert!(db.by_id(0x18FF_50E5, false).is_none());
    }

    #[test]
    fn intel_signed_scaled_and_described_signals_decode_as_computed_by_hand() {
        let db = example();
        // Rpm −1500 = 0xFA24, Current 12.34 A = 1234 = 0x04D2, Temperature 25 °C = 65 (offset −40),
        // Fault 2
        let m = db
            .by_name("ThrusterStatus")
            .unwrap()
            .decode(&[0x24, 0xFA, 0xD2, 0x04, 0x41, 0x02, 0, 0]);
        assert_eq!(m.get("Rpm"), Some(&Value::Int(-1500)));
        assert!((float(&m, "Current") - 12.34).abs() < 1e-9);
        assert_eq!(m.get("Temperature"), Some(&Value::Int(25)));
        assert_eq!(m.get("Fault"), Some(&Value::Int(2)));
        assert_eq!(m.get_str("Fault_text"), Some("OverTemp"));
    }

    #[test]
    fn motorola_signals_decode_as_computed_by_hand() {
        let db = example();
        // Voltage 48.00 V = 4800 = 0x12C0 (bytes 0–1, high first); Current −12.5 A = −125 = 0xFF83;
        // StateOfCharge 87.5 % = 175 = 0xAF; Temperature −5 °C = 0xFB
        let m = db
            .by_name("BatteryStatus")
            .unwrap()
            .decode(&[0x12, 0xC0, 0xFF, 0x83, 0xAF, 0xFB, 0, 0]);
        assert!((float(&m, "Voltage") - 48.0).abs() < 1e-9);
        assert!((float(&m, "Current") + 12.5).abs() < 1e-9);
        assert!((float(&m, "StateOfCharge") - 87.5).abs() < 1e-9);
        assert_eq!(m.get("Temperature"), Some(&Value::Int(-5)));
        // a 12-bit Motorola signal from bit 3: the low nibble of byte 0, then byte 1
        let db = Database::parse(
            "t.dbc",
            "VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: A\n\nBO_ 5 M: 2 A\n SG_ X : 3|12@0+ (1,0) [0|0] \"\" A\n",
        )
        .unwrap();
        let m = &db.messages[0];
        assert_eq!(m.decode(&[0x0A, 0xBC]).get("X"), Some(&Value::Int(0xABC)));
        assert_eq!(
            m.encode(&DataMap::new().with("X", 0xABCi64)).unwrap(),
            [0x0A, 0xBC]
        );
    }

    #[test]
    fn multiplexed_signals_follow_their_multiplexor() {
        let db = example();
        let cells = db.by_name("BatteryCells").unwrap();
        // page 1: Cell3 3.301 V = 0x0CE5, Cell4 3.299 V = 0x0CE3
        let data = [0x01, 0xE5, 0x0C, 0xE3, 0x0C, 0, 0, 0];
        let m = cells.decode(&data);
        let keys: Vec<&str> = m.iter().map(|(k, _)| k).collect();
        assert_eq!(keys, ["Page", "Cell3", "Cell4"]);
        assert!((float(&m, "Cell3") - 3.301).abs() < 1e-9);
        assert!((float(&m, "Cell4") - 3.299).abs() < 1e-9);
        let back = cells
            .encode(
                &DataMap::new()
                    .with("Page", 1i64)
                    .with("Cell3", 3.301)
                    .with("Cell4", 3.299),
            )
            .unwrap();
        assert_eq!(back, data);
        assert_eq!(
            cells
                .encode(&DataMap::new().with("Page", 1i64).with("Cell1", 3.3))
                .unwrap_err()
                .to_string(),
            "BatteryCells: signal `Cell1` is sent with multiplexor value 0, not 1"
        );
        assert_eq!(
            cells
                .encode(&DataMap::new().with("Cell1", 3.3))
                .unwrap_err()
                .to_string(),
            "BatteryCells: a multiplexed message needs its multiplexor `Page`"
        );
    }

    #[test]
    fn commands_encode_and_refuse_what_the_database_forbids() {
        let db = example();
        let cmd = db.by_name("ThrusterCommand").unwrap();
        // Mode "Rpm" = 1, Rpm 1200 = 0x04B0, RampTime 2.5 s = 25
        let data = cmd
            .encode(
                &DataMap::new()
                    .with("Mode", "Rpm")
                    .with("Rpm", 1200i64)
                    .with("RampTime", 2.5),
            )
            .unwrap();
        assert_eq!(data, [0x01, 0xB0, 0x04, 0x19, 0, 0, 0, 0]);
        // a signal not given takes its start value (RampTime 10 = 1.0 s)
        let data = cmd
            .encode(&DataMap::new().with("Mode", 2i64).with("Rpm", -3000i64))
            .unwrap();
        assert_eq!(data, [0x02, 0x48, 0xF4, 0x0A, 0, 0, 0, 0]);
        let refused = |m: DataMap| cmd.encode(&m).unwrap_err().to_string();
        assert_eq!(
            refused(DataMap::new().with("Rpm", 3500i64)),
            "ThrusterCommand: signal `Rpm`: 3500 rpm is outside [-3000 … 3000]"
        );
        assert_eq!(
            refused(DataMap::new().with("Mode", "Fast")),
            "ThrusterCommand: signal `Mode`: `Fast` is not one of Off, Rpm, Hold"
        );
        assert_eq!(
            refused(DataMap::new().with("Thrust", 1i64)),
            "ThrusterCommand: `Thrust` is not a signal of it; its signals: Mode, Rpm, RampTime"
        );
        assert_eq!(
            refused(DataMap::new().with("Rpm", "fast")),
            "ThrusterCommand: signal `Rpm`: `fast` is not a number"
        );
    }

    #[test]
    fn every_signal_survives_encode_and_decode() {
        let db = example();
        let status = db.by_name("ThrusterStatus").unwrap();
        let values = DataMap::new()
            .with("Rpm", -3200i64)
            .with("Current", 199.99)
            .with("Temperature", 150i64)
            .with("Fault", 4i64);
        let data = status.encode(&values).unwrap();
        let back = status.decode(&data);
        assert_eq!(back.get("Rpm"), Some(&Value::Int(-3200)));
        assert!((float(&back, "Current") - 199.99).abs() < 1e-9);
        assert_eq!(back.get("Temperature"), Some(&Value::Int(150)));
        assert_eq!(back.get_str("Fault_text"), Some("Stall"));
    }

    #[test]
    fn bad_files_name_the_place() {
        let e = Database::parse("bad.dbc", "VERSION \"\"\n\nBO_ x M: 8 A\n").unwrap_err();
        assert_eq!((e.pos.line, e.pos.file.as_ref()), (3, "bad.dbc"), "{e}");
        let e = Database::parse(
            "big.dbc",
            "VERSION \"\"\n\nNS_ :\n\nBS_:\n\nBU_: A\n\nBO_ 5 M: 2 A\n SG_ X : 12|8@1+ (1,0) [0|0] \"\" A\n",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "big.dbc:10:2: signal `X` of `M`: bits from 12 for 8 do not fit in 2 bytes"
        );
    }
}
