//! Payloads in the three formats of the communication interface, and conversions between them.
//!
//! | from \ to | bytes | datamap | XML |
//! |---|---|---|---|
//! | bytes | as is | binary datamap decode | via datamap |
//! | datamap | binary encode | as is | XML form |
//! | XML | via datamap | XML form read | as is |
//!
//! Datamap ↔ XML ↔ binary is lossless. Bytes that are not a binary datamap, and XML that is not a
//! `<datamap>` document, cannot become a datamap, and a datamap whose lists and maps nest deeper
//! than [`crate::datamap::MAX_DEPTH`] cannot become bytes or XML: the conversion fails with a
//! [`ConvertError`].
//! Payloads are cheap to clone: their contents are shared, never copied.

use crate::binary::{self, DecodeError};
use crate::datamap::DataMap;
use crate::datamap::TooDeep;
use crate::xmlform::{self, XmlFormError};
use bytes::Bytes;
use std::fmt;
use std::sync::Arc;
use thiserror::Error;

/// One of the three payload formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// A byte array.
    Bytes,
    /// A named datamap.
    Map,
    /// XML text.
    Xml,
}

impl Format {
    /// The format's name as written in files and URLs (`bytes`, `map`, `xml`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Bytes => "bytes",
            Format::Map => "map",
            Format::Xml => "xml",
        }
    }

    /// Reads a format name; `datamap` is accepted for `map`.
    pub fn parse(s: &str) -> Option<Format> {
        match s {
            "bytes" | "binary" => Some(Format::Bytes),
            "map" | "datamap" => Some(Format::Map),
            "xml" => Some(Format::Xml),
            _ => None,
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A message payload: bytes, a named datamap, or XML text.
#[derive(Debug, Clone)]
pub enum Payload {
    /// A byte array.
    Bytes(Bytes),
    /// A named datamap.
    Map(Arc<DataMap>),
    /// XML text.
    Xml(Arc<str>),
}

/// Why a payload could not be converted to the requested format.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConvertError {
    /// The bytes are not a binary datamap.
    #[error("bytes are not a binary datamap: {0}")]
    NotBinaryMap(#[from] DecodeError),
    /// The XML text is not a datamap document.
    #[error("XML is not a datamap document: {0}")]
    NotXmlMap(#[from] XmlFormError),
    /// The datamap's lists and maps nest too deep for the binary and XML forms.
    #[error("datamap has no binary or XML form: {0}")]
    TooDeep(#[from] TooDeep),
}

impl Payload {
    /// The payload's format.
    pub fn format(&self) -> Format {
        match self {
            Payload::Bytes(_) => Format::Bytes,
            Payload::Map(_) => Format::Map,
            Payload::Xml(_) => Format::Xml,
        }
    }

    /// Converts to `format`; a payload already in that format is returned as is (shared, not copied).
    pub fn convert(&self, format: Format) -> Result<Payload, ConvertError> {
        if self.format() == format {
            return Ok(self.clone());
        }
        Ok(match format {
            Format::Bytes => Payload::Bytes(Bytes::from(binary::encode(&*self.to_map()?)?)),
            Format::Map => Payload::Map(self.to_map()?),
            Format::Xml => Payload::Xml(Arc::from(xmlform::to_xml(&*self.to_map()?)?)),
        })
    }

    /// The payload as bytes: borrowed when it is a byte array, else encoded (for a transport that
    /// copies them into its frame, which need not share or convert the payload).
    pub fn to_bytes(&self) -> Result<std::borrow::Cow<'_, [u8]>, ConvertError> {
        match self {
            Payload::Bytes(b) => Ok(std::borrow::Cow::Borrowed(b)),
            other => Ok(std::borrow::Cow::Owned(binary::encode(&*other.to_map()?)?)),
        }
    }

    /// The payload as a datamap (converted when needed).
    pub fn to_map(&self) -> Result<Arc<DataMap>, ConvertError> {
        match self {
            Payload::Map(m) => Ok(m.clone()),
            Payload::Bytes(b) => Ok(Arc::new(binary::decode(b)?)),
            Payload::Xml(x) => Ok(Arc::new(xmlform::from_xml(x)?)),
        }
    }

    /// The datamap, when the payload is one (no conversion).
    pub fn as_map(&self) -> Option<&DataMap> {
        match self {
            Payload::Map(m) => Some(m),
            _ => None,
        }
    }

    /// The bytes, when the payload is a byte array (no conversion).
    pub fn as_bytes(&self) -> Option<&Bytes> {
        match self {
            Payload::Bytes(b) => Some(b),
            _ => None,
        }
    }

    /// The XML text, when the payload is XML (no conversion).
    pub fn as_xml(&self) -> Option<&str> {
        match self {
            Payload::Xml(x) => Some(x),
            _ => None,
        }
    }

    /// The size of the payload's own representation in bytes.
    pub fn len(&self) -> usize {
        match self {
            Payload::Bytes(b) => b.len(),
            Payload::Map(m) => binary::encoded_len(m),
            Payload::Xml(x) => x.len(),
        }
    }

    /// True for an empty byte array, datamap or XML text.
    pub fn is_empty(&self) -> bool {
        match self {
            Payload::Bytes(b) => b.is_empty(),
            Payload::Map(m) => m.is_empty(),
            Payload::Xml(x) => x.is_empty(),
        }
    }
}

/// Payloads are equal when they have the same format and content.
impl PartialEq for Payload {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Payload::Bytes(a), Payload::Bytes(b)) => a == b,
            (Payload::Map(a), Payload::Map(b)) => a == b,
            (Payload::Xml(a), Payload::Xml(b)) => a == b,
            _ => false,
        }
    }
}

impl fmt::Display for Payload {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Payload::Map(m) => write!(f, "{m}"),
            Payload::Xml(x) => write!(f, "{x}"),
            Payload::Bytes(b) => write!(f, "{}", crate::datamap::Value::Bytes(b.to_vec())),
        }
    }
}

impl From<DataMap> for Payload {
    fn from(m: DataMap) -> Self {
        Payload::Map(Arc::new(m))
    }
}

impl From<Arc<DataMap>> for Payload {
    fn from(m: Arc<DataMap>) -> Self {
        Payload::Map(m)
    }
}

impl From<Bytes> for Payload {
    fn from(b: Bytes) -> Self {
        Payload::Bytes(b)
    }
}

impl From<Vec<u8>> for Payload {
    fn from(b: Vec<u8>) -> Self {
        Payload::Bytes(Bytes::from(b))
    }
}

impl From<&[u8]> for Payload {
    fn from(b: &[u8]) -> Self {
        Payload::Bytes(Bytes::copy_from_slice(b))
    }
}

/// Builds an XML payload from text.
pub fn xml(text: impl Into<Arc<str>>) -> Payload {
    Payload::Xml(text.into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datamap::Value;

    #[test]
    fn every_format_reaches_every_other() {
        let map = DataMap::new()
            .with("a", 1i64)
            .with("b", Value::List(vec![true.into()]))
            .with(
                "pose",
                DataMap::new()
                    .with("x", 1.5f64)
                    .with("wps", Value::List(vec![DataMap::new().into()])),
            );
        let start = Payload::from(map.clone());
        for via in [Format::Bytes, Format::Xml, Format::Map] {
            let p = start.convert(via).unwrap();
            assert_eq!(p.format(), via);
            for to in [Format::Bytes, Format::Xml, Format::Map] {
                let q = p.convert(to).unwrap();
                assert_eq!(*q.to_map().unwrap(), map, "{via} -> {to}");
            }
        }
    }

    #[test]
    fn impossible_conversions_are_typed() {
        let raw = Payload::from(b"$GPGGA,1*00".as_slice());
        assert!(matches!(
            raw.convert(Format::Map),
            Err(ConvertError::NotBinaryMap(_))
        ));
        assert!(matches!(
            raw.convert(Format::Xml),
            Err(ConvertError::NotBinaryMap(_))
        ));
        let doc = xml("<mission><wp/></mission>");
        assert!(matches!(
            doc.convert(Format::Bytes),
            Err(ConvertError::NotXmlMap(_))
        ));
        // a payload already in the asked format is never touched
        assert_eq!(raw.convert(Format::Bytes).unwrap(), raw);
        assert_eq!(doc.convert(Format::Xml).unwrap(), doc);
    }

    #[test]
    fn bytes_are_lent_as_they_are_and_a_map_is_encoded() {
        let raw = Payload::from(vec![1u8, 2, 3]);
        let lent = raw.to_bytes().unwrap();
        assert!(matches!(lent, std::borrow::Cow::Borrowed(_)));
        assert_eq!(lent.as_ptr(), raw.as_bytes().unwrap().as_ptr());
        let map = DataMap::new().with("depth", 12.5).with("ok", true);
        let payload = Payload::from(map.clone());
        let encoded = payload.to_bytes().unwrap();
        assert!(matches!(encoded, std::borrow::Cow::Owned(_)));
        assert_eq!(binary::decode(&encoded).unwrap(), map);
        assert!(matches!(
            xml("<mission><wp/></mission>").to_bytes(),
            Err(ConvertError::NotXmlMap(_))
        ));
    }

    #[test]
    fn a_map_too_deep_to_decode_does_not_become_bytes() {
        // lists, maps, and the two alternating, nested `levels` deep
        let nested = |levels, maps: fn(usize) -> bool| {
            let mut v = Value::Int(1);
            for i in 0..levels {
                v = if maps(i) {
                    Value::Map(DataMap::new().with("k", v))
                } else {
                    Value::List(vec![v])
                };
            }
            DataMap::new().with("deep", v)
        };
        let kinds: [fn(usize) -> bool; 3] = [|_| false, |_| true, |i| i % 2 == 0];
        for maps in kinds {
            let deep = Payload::from(nested(crate::datamap::MAX_DEPTH + 1, maps));
            for to in [Format::Bytes, Format::Xml] {
                assert_eq!(deep.convert(to), Err(ConvertError::TooDeep(TooDeep)));
            }
            // the deepest map the binary and XML forms carry converts and reads back
            let deepest = nested(crate::datamap::MAX_DEPTH, maps);
            for to in [Format::Bytes, Format::Xml] {
                let p = Payload::from(deepest.clone()).convert(to).unwrap();
                assert_eq!(*p.to_map().unwrap(), deepest);
            }
        }
    }

    #[test]
    fn same_format_conversion_shares_the_contents() {
        let p = Payload::from(DataMap::new().with("x", 1i64));
        let q = p.convert(Format::Map).unwrap();
        match (&p, &q) {
            (Payload::Map(a), Payload::Map(b)) => assert!(Arc::ptr_eq(a, b)),
            _ => unreachable!(),
        }
    }
}
