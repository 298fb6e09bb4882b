//! LCM messages to and from seabus datamaps, for types read at run time ([`super::types`]).
//!
//! [`encode`] writes a datamap as a message of an LCM struct type (its fingerprint, then its
//! members), and [`decode`] reads such a message back into a datamap, checking the fingerprint
//! first. The mapping:
//!
//! | LCM                                 | datamap                                              |
//! |-------------------------------------|------------------------------------------------------|
//! | struct (the message itself)         | [`DataMap`], its members in declared order           |
//! | nested struct                       | [`Value::Map`]                                       |
//! | array                               | [`Value::List`]; lists of lists for more dimensions  |
//! | one-dimensional `byte` array        | [`Value::Bytes`] (encoding also takes a list of ints) |
//! | `int8_t`, `int16_t`, `int32_t`, `int64_t` | [`Value::Int`] (encoding also takes an integral float) |
//! | `byte`                              | [`Value::Int`] from 0 to 255                         |
//! | `boolean`                           | [`Value::Bool`] (encoding also takes the ints 0 and 1) |
//! | `float`, `double`                   | [`Value::Float`] (encoding also takes an int)        |
//! | `string`                            | [`Value::Str`]                                       |
//!
//! A `byte` array of more dimensions is lists of ints, like other arrays (encoding also takes
//! [`Value::Bytes`] for its innermost lists).
//!
//! Encoding checks every value against its member: a value of another type, or a number the
//! member's type cannot hold, is an error naming the field (`pose.position.x`, `children[3].num`)
//! and both types. Members missing from the map take defaults: NaN for `float` and `double` (so
//! that an absent measurement reads as unknown to LCM programs), 0 for integers and `byte`, false,
//! the empty string, a nested struct of defaults, a fixed-size array of defaults, an empty
//! variable-length array. The integer member that sizes variable-length arrays may be left out:
//! it is then the length of the first of those arrays present in the map (for an inner dimension,
//! the length of its first row), or 0 when none is. Given or not, it must equal the length of every
//! array it sizes, and every array it sizes must agree with the others. Keys the type does not
//! have are ignored.
//!
//! Decoding is as lenient as liblcm's generated decoders, and no more: it refuses a string whose
//! length does not count its terminating NUL or that does not end with one, a negative array size,
//! a message cut short. What liblcm reads, it reads too, and says so ([`Leniency`]): a boolean
//! byte other than 0 and 1 is `true`, and its byte is kept beside it, under the member's name and
//! `.raw` ([`RAW_SUFFIX`]: `name.raw`, an int; for an array of booleans, the same shape of lists,
//! every element's byte); a string that is not UTF-8 is decoded lossily (U+FFFD for what is not
//! UTF-8) and its bytes kept the same way (`name.raw`, bytes; for an array of strings, the same
//! shape of lists, every element's bytes); bytes left after the message are ignored. A member
//! whose values were all exact has no `name.raw`. Decoding errors name the field and the byte
//! offset where it starts, from the start of the message. Encoding writes a kept byte in place of
//! a boolean as long as the boolean is still `true`, and a string's kept bytes in place of its
//! text as long as the text is still what they decode to (a value changed since is written as it
//! is now), so a message decoded and encoded again is the same bytes, but for what followed the
//! message (left out).
//!
//! Both ways, lists and maps nest at most [`MAX_DEPTH`] deep (counted together, as every payload
//! form counts them), so that a recursive type nested deeper is an error rather than a deep
//! recursion, and a message holds at most [`MAX_ELEMENTS`] array elements (those of a
//! one-dimensional `byte` array, read as bytes, do not count). Array elements that may encode to
//! no bytes at all (empty structs, rows of arrays that may be empty) are decoded at most one per
//! byte of the message and [`FREE_ELEMENTS`] more, so that a few hostile bytes cannot make a
//! decoder build millions of values. The decoder reserves room for an array only as far as the
//! bytes left can fill it.

use super::types::{
    Dim, Member, MemberType, Primitive, ResolvedTypes, Size, StructType, primitive_min_size,
};
use seabus_medium::datamap::{DataMap, MAX_DEPTH, Value};
use std::borrow::Cow;
use std::fmt;

/// Most array elements, counted over all arrays, one message may hold.
pub const MAX_ELEMENTS: usize = 1 << 22;
/// Array elements that may encode to no bytes a message being decoded may hold besides one per
/// byte of the message.
pub const FREE_ELEMENTS: usize = 4096;

/// Bytes of the fingerprint that starts every message.
const FINGERPRINT_LEN: usize = 8;

/// Appended to a boolean or string member's name for the bytes of a boolean neither 0 nor 1 or of
/// a string that is not UTF-8.
pub const RAW_SUFFIX: &str = ".raw";

/// What a decoded message had that liblcm reads but an exact encoding would not have: each
/// counted, with where the first was.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Leniency {
    /// Booleans of a byte other than 0 and 1, read as `true` with their bytes kept.
    pub bools: u32,
    /// The first of them: its byte offset and value.
    pub first_bool: Option<(usize, u8)>,
    /// Strings that are not UTF-8, decoded lossily with their bytes kept.
    pub strings: u32,
    /// The byte offset of the first of them.
    pub first_string: Option<usize>,
    /// Bytes after the end of the message, ignored.
    pub trailing: usize,
    /// Where the message ended.
    pub end: usize,
}

impl Leniency {
    /// Whether the message was an exact encoding.
    pub fn is_exact(&self) -> bool {
        self.bools == 0 && self.strings == 0 && self.trailing == 0
    }

    /// Each case the message had: the reason it is counted under and what it was.
    pub fn cases(&self) -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        if let Some((offset, value)) = self.first_bool {
            out.push((
                "lcm-bool-not-0-1",
                format!(
                    "{} boolean(s) neither 0 nor 1 read as true, as liblcm reads them, their \
                     bytes kept (the first at byte {offset}: {value})",
                    self.bools
                ),
            ));
        }
        if let Some(offset) = self.first_string {
            out.push((
                "lcm-string-not-utf8",
                format!(
                    "{} string(s) not UTF-8 decoded with U+FFFD, their bytes kept (the first at \
                     byte {offset})",
                    self.strings
                ),
            ));
        }
        if self.trailing > 0 {
            out.push((
                "lcm-trailing-bytes",
                format!(
                    "{} byte(s) after the end of the message at byte {} ignored, as liblcm \
                     ignores them",
                    self.trailing, self.end
                ),
            ));
        }
        out
    }
}

/// Why a datamap does not encode as an LCM message, or bytes do not decode as one.
///
/// Fields are named by their path from the message (`pose.position.x`, `children[3].num`); decoding
/// errors give the byte offset from the start of the message, fingerprint included.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CodecError {
    /// The message starts with the fingerprint of another type.
    Fingerprint {
        /// Full name of the type expected.
        expected: String,
        /// Its fingerprint.
        expected_fingerprint: u64,
        /// The fingerprint the message starts with.
        received_fingerprint: u64,
        /// Full name of a known type with the received fingerprint, if any.
        received: Option<String>,
    },
    /// Encoding: a value of a type the field cannot take.
    WrongType {
        /// The field.
        path: String,
        /// The field's LCM type at that place (`double`, `double[3]`, `geo.point_t`).
        expected: String,
        /// The value's type ([`Value::type_name`]).
        found: &'static str,
    },
    /// Encoding: a number the field's type cannot hold.
    OutOfRange {
        /// The field.
        path: String,
        /// The field's type.
        ty: Primitive,
        /// The value, as written in the message.
        value: String,
    },
    /// Encoding: a fixed-size array given with another number of elements.
    Length {
        /// The array.
        path: String,
        /// Its LCM type at that place (`double[3]`).
        ty: String,
        /// Its size.
        expected: u32,
        /// The number of elements given.
        found: usize,
    },
    /// Encoding: a variable-length array whose length is not the value of its size member.
    SizeMismatch {
        /// The array.
        path: String,
        /// The number of elements given.
        len: usize,
        /// The member that sizes it.
        size_path: String,
        /// That member's value.
        size: i64,
        /// The array whose length gave that value, when the size member was left out.
        from: Option<String>,
    },
    /// Encoding: a size member left out, whose value would be an array's length it cannot hold.
    SizeOverflow {
        /// The size member.
        path: String,
        /// Its type.
        ty: Primitive,
        /// The array's length.
        len: usize,
        /// The array.
        from: String,
    },
    /// Decoding: an array whose size member holds a negative number.
    NegativeSize {
        /// The array.
        path: String,
        /// Where the array starts.
        offset: usize,
        /// The member that sizes it.
        size_path: String,
        /// That member's value.
        size: i64,
    },
    /// Decoding: a string that is not NUL-terminated.
    BadString {
        /// The field.
        path: String,
        /// Where its length starts.
        offset: usize,
        /// What is wrong with it.
        problem: StringProblem,
    },
    /// Decoding: the message ends before the field does.
    Truncated {
        /// The field; empty for the fingerprint.
        path: String,
        /// Where the missing bytes start.
        offset: usize,
        /// Bytes needed from there.
        needed: u64,
        /// Bytes left from there.
        left: usize,
    },
    /// Lists and maps nested deeper than [`MAX_DEPTH`].
    TooDeep {
        /// The field too deep.
        path: String,
        /// Decoding: where it starts.
        offset: Option<usize>,
    },
    /// More than [`MAX_ELEMENTS`] array elements in one message.
    TooManyElements {
        /// The array where the count goes over.
        path: String,
        /// Decoding: where it starts.
        offset: Option<usize>,
    },
    /// Decoding: more array elements that may encode to no bytes than the message's size allows
    /// (one per byte and [`FREE_ELEMENTS`] more).
    TooManyEmpty {
        /// The array where the count goes over.
        path: String,
        /// Where it starts.
        offset: usize,
        /// Its elements.
        count: usize,
        /// The message's size.
        size: usize,
    },
    /// A member's struct type is not among the types given.
    UnknownType {
        /// The member.
        path: String,
        /// Its type's full name.
        name: String,
    },
}

/// What is wrong with a string being decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StringProblem {
    /// A length that does not count a terminating NUL (zero or negative).
    Length(i32),
    /// The last byte is not a NUL.
    NoNul,
}

impl fmt::Display for CodecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_encoding() {
            self.fmt_encoding(f)
        } else {
            self.fmt_decoding(f)
        }
    }
}

impl CodecError {
    /// Whether the error was met encoding a datamap (rather than decoding bytes).
    fn is_encoding(&self) -> bool {
        matches!(
            self,
            CodecError::WrongType { .. }
                | CodecError::OutOfRange { .. }
                | CodecError::Length { .. }
                | CodecError::SizeMismatch { .. }
                | CodecError::SizeOverflow { .. }
                | CodecError::UnknownType { .. }
        )
    }

    /// The words of an error met encoding.
    fn fmt_encoding(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CodecError::WrongType {
                path,
                expected,
                found,
            } => write!(
                f,
                "field `{path}` ({expected}) cannot take {} {found} value",
                article(found)
            ),
            CodecError::OutOfRange { path, ty, value } => {
                write!(f, "field `{path}` ({ty}) cannot take {value}: ")?;
                range_text(f, *ty)
            }
            CodecError::Length {
                path,
                ty,
                expected,
                found,
            } => write!(
                f,
                "field `{path}` ({ty}) has {found} element{}, not {expected}",
                plural(*found)
            ),
            CodecError::SizeMismatch {
                path,
                len,
                size_path,
                size,
                from,
            } => {
                write!(
                    f,
                    "field `{path}` has {len} element{}, but its size `{size_path}` is {size}",
                    plural(*len)
                )?;
                match from {
                    Some(from) => write!(f, " (the length of `{from}`)"),
                    None => Ok(()),
                }
            }
            CodecError::SizeOverflow {
                path,
                ty,
                len,
                from,
            } => {
                write!(
                    f,
                    "field `{path}` ({ty}) cannot take {len}, the length of `{from}`: "
                )?;
                range_text(f, *ty)
            }
            CodecError::UnknownType { path, name } => write!(
                f,
                "field `{path}` has type `{name}`, which is not among the types given"
            ),
            _ => self.fmt_decoding(f),
        }
    }

    /// The words of an error met decoding.
    fn fmt_decoding(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CodecError::Fingerprint {
                expected,
                expected_fingerprint,
                received_fingerprint,
                received,
            } => {
                write!(
                    f,
                    "expected {expected} (0x{expected_fingerprint:016x}), received "
                )?;
                match received {
                    Some(name) => write!(f, "{name} (0x{received_fingerprint:016x})"),
                    None => write!(
                        f,
                        "an unknown type (fingerprint 0x{received_fingerprint:016x})"
                    ),
                }
            }
            CodecError::NegativeSize {
                path,
                offset,
                size_path,
                size,
            } => write!(
                f,
                "field `{path}` at byte {offset} is sized by `{size_path}` = {size}, a negative \
                 size"
            ),
            CodecError::BadString {
                path,
                offset,
                problem,
            } => {
                write!(f, "field `{path}` at byte {offset}: ")?;
                match problem {
                    StringProblem::Length(n) => {
                        write!(f, "string length {n} does not count a terminating NUL")
                    }
                    StringProblem::NoNul => f.write_str("string does not end with a NUL"),
                }
            }
            CodecError::Truncated {
                path,
                offset,
                needed,
                left,
            } => {
                if path.is_empty() {
                    f.write_str("the message ends inside its fingerprint")?;
                } else {
                    write!(f, "the message ends inside field `{path}`")?;
                }
                write!(
                    f,
                    ": {needed} byte{} needed at byte {offset}, {left} left",
                    plural(*needed)
                )
            }
            CodecError::TooDeep { path, offset } => {
                write!(f, "field `{path}`")?;
                at_offset(f, *offset)?;
                write!(f, ": lists and maps nested deeper than {MAX_DEPTH}")
            }
            CodecError::TooManyElements { path, offset } => {
                write!(f, "field `{path}`")?;
                at_offset(f, *offset)?;
                write!(
                    f,
                    ": more than {MAX_ELEMENTS} array elements in one message"
                )
            }
            CodecError::TooManyEmpty {
                path,
                offset,
                count,
                size,
            } => write!(
                f,
                "field `{path}` at byte {offset}: {count} elements that may take no bytes, more \
                 than a message of {size} bytes may hold"
            ),
            _ => self.fmt_encoding(f),
        }
    }
}

impl std::error::Error for CodecError {}

/// `" at byte N"` for a decoding error.
fn at_offset(f: &mut fmt::Formatter<'_>, offset: Option<usize>) -> fmt::Result {
    match offset {
        Some(offset) => write!(f, " at byte {offset}"),
        None => Ok(()),
    }
}

/// The values `ty` holds, for an out-of-range error.
fn range_text(f: &mut fmt::Formatter<'_>, ty: Primitive) -> fmt::Result {
    match ty {
        Primitive::Boolean => f.write_str("a boolean is true, false, 0 or 1"),
        Primitive::Float => f.write_str("beyond the range of float"),
        Primitive::String => f.write_str("longer than an LCM string can be"),
        Primitive::Double => f.write_str("beyond the range of double"),
        _ => {
            let (min, max) = int_range(ty);
            write!(f, "not an integer from {min} to {max}")
        }
    }
}

/// "a" or "an" before a value's type name.
fn article(word: &str) -> &'static str {
    if word.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    }
}

/// "s" after a count other than one.
fn plural(n: impl TryInto<u64>) -> &'static str {
    if n.try_into().ok() == Some(1) {
        ""
    } else {
        "s"
    }
}

/// The smallest and largest values of an integer type (and of `byte`).
fn int_range(ty: Primitive) -> (i64, i64) {
    match ty {
        Primitive::Int8 => (i8::MIN.into(), i8::MAX.into()),
        Primitive::Int16 => (i16::MIN.into(), i16::MAX.into()),
        Primitive::Int32 => (i32::MIN.into(), i32::MAX.into()),
        Primitive::Byte => (0, 255),
        _ => (i64::MIN, i64::MAX),
    }
}

/// The LCM type of member `m` inside `level` of its array dimensions (`double[3]` for the rows of
/// `double grid[2][3]`).
fn type_text(m: &Member, level: usize) -> String {
    let mut text = m.ty.to_string();
    for d in m.dims.iter().skip(level) {
        text.push('[');
        text.push_str(&d.text);
        text.push(']');
    }
    text
}

/// One step of a field path.
#[derive(Debug, Clone, Copy)]
enum Seg<'t> {
    /// A member.
    Name(&'t str),
    /// An array element.
    Index(usize),
}

/// An error on its way out of the members and arrays it happened in, which add their steps to its
/// path as it passes: paths are built only when something fails.
///
/// The error's `path` starts empty and becomes the whole path (`segs`, innermost first). Its other
/// paths (`size_path`, `from`) start as paths within the struct the error happened in and get only
/// the steps from outside that struct (`segs[outer..]`).
#[derive(Debug)]
struct Fail<'t> {
    error: CodecError,
    segs: Vec<Seg<'t>>,
    outer: Option<usize>,
}

/// A result whose error carries its path so far.
type Res<'t, T> = Result<T, Box<Fail<'t>>>;

/// A new error, at the place where it happens.
fn fail<'t>(error: CodecError) -> Box<Fail<'t>> {
    Box::new(Fail {
        error,
        segs: Vec::new(),
        outer: None,
    })
}

impl<'t> Fail<'t> {
    /// The error passing out of element `i` of an array.
    fn index(mut self: Box<Self>, i: usize) -> Box<Self> {
        self.segs.push(Seg::Index(i));
        self
    }

    /// The error passing out of member `name`; the first member passed is in the struct where the
    /// error happened.
    fn member(mut self: Box<Self>, name: &'t str) -> Box<Self> {
        self.segs.push(Seg::Name(name));
        if self.outer.is_none() {
            self.outer = Some(self.segs.len());
        }
        self
    }

    /// The error with its paths complete.
    fn finish(self) -> CodecError {
        let Fail {
            mut error,
            segs,
            outer,
        } = self;
        let whole = render(&segs);
        let outside = render(segs.get(outer.unwrap_or(segs.len())..).unwrap_or_default());
        let (path, others): (Option<&mut String>, [Option<&mut String>; 2]) = match &mut error {
            CodecError::WrongType { path, .. }
            | CodecError::OutOfRange { path, .. }
            | CodecError::Length { path, .. }
            | CodecError::BadString { path, .. }
            | CodecError::Truncated { path, .. }
            | CodecError::TooDeep { path, .. }
            | CodecError::TooManyElements { path, .. }
            | CodecError::TooManyEmpty { path, .. }
            | CodecError::UnknownType { path, .. } => (Some(path), [None, None]),
            CodecError::SizeMismatch {
                path,
                size_path,
                from,
                ..
            } => (Some(path), [Some(size_path), from.as_mut()]),
            CodecError::SizeOverflow { path, from, .. } => (Some(path), [Some(from), None]),
            CodecError::NegativeSize {
                path, size_path, ..
            } => (Some(path), [Some(size_path), None]),
            CodecError::Fingerprint { .. } => (None, [None, None]),
        };
        if let Some(path) = path {
            *path = join(&whole, path);
        }
        for other in others.into_iter().flatten() {
            *other = join(&outside, other);
        }
        error
    }
}

/// The path of `segs`, innermost first: `pose.track[2][0].x`.
fn render(segs: &[Seg<'_>]) -> String {
    let mut out = String::new();
    for seg in segs.iter().rev() {
        match seg {
            Seg::Name(name) => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(name);
            }
            Seg::Index(i) => {
                out.push('[');
                out.push_str(&i.to_string());
                out.push(']');
            }
        }
    }
    out
}

/// `path` within the field `prefix`.
fn join(prefix: &str, path: &str) -> String {
    if path.is_empty() {
        prefix.to_string()
    } else if prefix.is_empty() || path.starts_with('[') {
        format!("{prefix}{path}")
    } else {
        format!("{prefix}.{path}")
    }
}

/// The struct whose members are being written or read: its members, and where its slots start in
/// the stack of sizes.
#[derive(Debug, Clone, Copy)]
struct Within<'t> {
    members: &'t [Member],
    base: usize,
}

/// What the elements of an array member are.
#[derive(Debug, Clone, Copy)]
enum Elem<'t> {
    /// A primitive.
    Prim(Primitive),
    /// A struct.
    Struct(&'t StructType),
}

/// The element type of member `m`.
fn elem<'t>(types: &'t ResolvedTypes, m: &Member) -> Res<'t, Elem<'t>> {
    match &m.ty {
        MemberType::Primitive(p) => Ok(Elem::Prim(*p)),
        MemberType::Struct(name) => match types.get(name) {
            Some(t) => Ok(Elem::Struct(t)),
            None => Err(fail(CodecError::UnknownType {
                path: String::new(),
                name: name.clone(),
            })),
        },
    }
}

/// True for a one-dimensional `byte` array, which is [`Value::Bytes`].
fn is_byte_vector(m: &Member) -> bool {
    m.dims.len() == 1 && m.ty == MemberType::Primitive(Primitive::Byte)
}

/// Counts `n` more array elements into `total`, refusing to go over [`MAX_ELEMENTS`].
fn count_elements<'t>(total: &mut usize, n: usize, offset: Option<usize>) -> Res<'t, ()> {
    if n > MAX_ELEMENTS - *total {
        return Err(fail(CodecError::TooManyElements {
            path: String::new(),
            offset,
        }));
    }
    *total += n;
    Ok(())
}

/// The error for a list or map found inside `MAX_DEPTH` others.
fn too_deep<'t>(offset: Option<usize>) -> Box<Fail<'t>> {
    fail(CodecError::TooDeep {
        path: String::new(),
        offset,
    })
}

/// `m`'s path `[0]` `level` times, naming the array a size was taken from.
fn first_path(m: &Member, level: usize) -> String {
    let mut path = m.name.clone();
    for _ in 0..level {
        path.push_str("[0]");
    }
    path
}

/// A float as `float` keeps it; a NaN keeps its sign and the top of its payload (and stays a NaN).
fn to_f32(x: f64) -> f32 {
    if x.is_nan() {
        let bits = x.to_bits();
        let sign = ((bits >> 32) as u32) & 0x8000_0000;
        let payload = ((bits >> 29) as u32) & 0x007f_ffff;
        let payload = if payload == 0 { 0x0040_0000 } else { payload };
        f32::from_bits(sign | 0x7f80_0000 | payload)
    } else {
        x as f32
    }
}

/// A `float` as a double, NaN payload kept (so that it encodes back to the same bits).
fn from_f32(x: f32) -> f64 {
    if x.is_nan() {
        let bits = u64::from(x.to_bits());
        f64::from_bits(
            ((bits & 0x8000_0000) << 32) | 0x7ff0_0000_0000_0000 | ((bits & 0x007f_ffff) << 29),
        )
    } else {
        f64::from(x)
    }
}

// ---------------------------------------------------------------------------------------------
// Encoding

/// Encodes `map` as a message of type `ty`: its fingerprint, then its members (see the module
/// documentation for the mapping and the defaults of missing members).
pub fn encode(
    types: &ResolvedTypes,
    ty: &StructType,
    map: &DataMap,
) -> Result<Vec<u8>, CodecError> {
    let mut encoder = Encoder {
        types,
        out: Vec::with_capacity(128),
        sizes: Vec::new(),
        elements: 0,
        raws: (Vec::new(), 0),
    };
    encoder
        .out
        .extend_from_slice(&ty.fingerprint().to_be_bytes());
    encoder
        .write_struct(ty, Some(map), 0)
        .map_err(|f| (*f).finish())?;
    Ok(encoder.out)
}

/// The value of a size member while its struct is written.
#[derive(Debug, Clone, Copy)]
struct SizeValue {
    /// The size.
    n: i64,
    /// When the member was left out: the member and array level whose length it is.
    from: Option<(usize, usize)>,
}

/// Writes messages.
struct Encoder<'t> {
    types: &'t ResolvedTypes,
    out: Vec<u8>,
    /// The size members of the structs being written, one slot per member (a stack: each struct
    /// pushes its slots and pops them when done).
    sizes: Vec<Option<SizeValue>>,
    /// Array elements written so far.
    elements: usize,
    /// What was kept for the booleans or strings of the member being written (`name.raw`), one
    /// value for each of them in order, and how many of them were written.
    raws: (Vec<Value>, usize),
}

/// What was kept for the next boolean or string of the member being written (`raws`, an
/// [`Encoder`]'s), if anything.
fn next_raw((kept, n): &mut (Vec<Value>, usize)) -> Option<&Value> {
    let raw = kept.get(*n);
    *n += 1;
    raw
}

/// The value of member `name` in `map`: looked for first at the next entry of `entries` (the map's
/// entries in order, for maps whose keys come in member order), then anywhere.
fn lookup<'m, I>(
    map: Option<&'m DataMap>,
    entries: &mut std::iter::Peekable<I>,
    name: &str,
) -> Option<&'m Value>
where
    I: Iterator<Item = (&'m str, &'m Value)>,
{
    let map = map?;
    if let Some(&(key, value)) = entries.peek()
        && key == name
    {
        entries.next();
        return Some(value);
    }
    map.get(name)
}

/// The member and array level whose length gives the size member `j` when it is left out: the
/// first array it sizes that is present, reached through the first elements of the outer levels.
fn observe(members: &[Member], map: Option<&DataMap>, j: usize) -> Option<(usize, usize, usize)> {
    let map = map?;
    for (k, m) in members.iter().enumerate() {
        for (level, d) in m.dims.iter().enumerate() {
            if d.size != Size::Member(j) {
                continue;
            }
            let Some(mut value) = map.get(&m.name) else {
                continue;
            };
            let mut reached = true;
            for _ in 0..level {
                match value.as_list().and_then(<[Value]>::first) {
                    Some(first) => value = first,
                    None => {
                        reached = false;
                        break;
                    }
                }
            }
            if !reached {
                continue;
            }
            match value {
                Value::List(items) => return Some((k, level, items.len())),
                Value::Bytes(bytes) => return Some((k, level, bytes.len())),
                _ => {}
            }
        }
    }
    None
}

/// An integer value for type `ty` (an integer type or `byte`), range-checked; an integral float
/// converts.
fn int_value<'t>(ty: Primitive, m: &Member, level: usize, value: &Value) -> Res<'t, i64> {
    let (min, max) = int_range(ty);
    let n = match value {
        Value::Int(i) => Some(*i).filter(|i| (min..=max).contains(i)),
        Value::Float(x) => {
            // every integral float from -2^63 up to (not including) 2^63 is an i64
            let integral = x.fract() == 0.0
                && *x >= -9_223_372_036_854_775_808.0
                && *x < 9_223_372_036_854_775_808.0;
            Some(*x as i64).filter(|i| integral && (min..=max).contains(i))
        }
        other => {
            return Err(fail(CodecError::WrongType {
                path: String::new(),
                expected: type_text(m, level),
                found: other.type_name(),
            }));
        }
    };
    n.ok_or_else(|| {
        let value = match value {
            Value::Float(x) => format!("{x:?}"),
            other => other.to_string(),
        };
        fail(CodecError::OutOfRange {
            path: String::new(),
            ty,
            value,
        })
    })
}

impl<'t> Encoder<'t> {
    /// Writes the members of `ty` from `map` (`None`: all defaults); its members' values are found
    /// inside `depth` lists and maps.
    fn write_struct(
        &mut self,
        ty: &'t StructType,
        map: Option<&DataMap>,
        depth: usize,
    ) -> Res<'t, ()> {
        let members = ty.members();
        let base = self.sizes.len();
        self.sizes.resize(base + members.len(), None);
        self.size_members(members, map, base)?;
        let within = Within { members, base };
        let mut entries = map.map(DataMap::iter).into_iter().flatten().peekable();
        for (i, m) in members.iter().enumerate() {
            let value = lookup(map, &mut entries, &m.name);
            let size = self.sizes.get(base + i).copied().flatten();
            let kept = match (&m.ty, map) {
                (MemberType::Primitive(Primitive::String | Primitive::Boolean), Some(map)) => {
                    map.get(&format!("{}{RAW_SUFFIX}", m.name))
                }
                _ => None,
            };
            let mut raws = Vec::new();
            if let Some(kept) = kept {
                raw_leaves(kept, &mut raws);
            }
            self.raws = (raws, 0);
            let written = match (size, &m.ty) {
                (Some(size), MemberType::Primitive(p)) => {
                    self.put_int(*p, size.n);
                    Ok(())
                }
                _ => self.write_member(within, m, value, depth),
            };
            self.raws = (Vec::new(), 0);
            written.map_err(|f| f.member(&m.name))?;
        }
        self.sizes.truncate(base);
        Ok(())
    }

    /// Finds the value of every member of a struct that sizes an array: from `map`, or else from
    /// the length of an array it sizes.
    fn size_members(
        &mut self,
        members: &'t [Member],
        map: Option<&DataMap>,
        base: usize,
    ) -> Res<'t, ()> {
        for m in members {
            for d in &m.dims {
                let Size::Member(j) = d.size else {
                    continue;
                };
                let Some(slot) = self.sizes.get(base + j) else {
                    continue;
                };
                let Some(sizer) = members.get(j) else {
                    continue;
                };
                let MemberType::Primitive(p) = sizer.ty else {
                    continue;
                };
                if slot.is_some() {
                    continue;
                }
                let given = map.and_then(|map| map.get(&sizer.name));
                let size = match given {
                    Some(value) => SizeValue {
                        n: int_value(p, sizer, 0, value).map_err(|f| f.member(&sizer.name))?,
                        from: None,
                    },
                    None => match observe(members, map, j) {
                        Some((k, level, len)) => {
                            let (min, max) = int_range(p);
                            let n = i64::try_from(len).ok().filter(|n| (min..=max).contains(n));
                            let Some(n) = n else {
                                let from = members
                                    .get(k)
                                    .map_or_else(String::new, |a| first_path(a, level));
                                return Err(fail(CodecError::SizeOverflow {
                                    path: String::new(),
                                    ty: p,
                                    len,
                                    from,
                                })
                                .member(&sizer.name));
                            };
                            SizeValue {
                                n,
                                from: Some((k, level)),
                            }
                        }
                        None => SizeValue { n: 0, from: None },
                    },
                };
                if let Some(slot) = self.sizes.get_mut(base + j) {
                    *slot = Some(size);
                }
            }
        }
        Ok(())
    }

    /// Writes member `m` of a struct whose members are `members`, from `value` (`None`: its
    /// default), found inside `depth` lists and maps.
    fn write_member(
        &mut self,
        within: Within<'t>,
        m: &'t Member,
        value: Option<&Value>,
        depth: usize,
    ) -> Res<'t, ()> {
        let elem = elem(self.types, m)?;
        self.write_level(within, m, 0, elem, value, depth)
    }

    /// Writes the part of member `m` inside `level` of its array dimensions from `value`, found
    /// inside `depth` lists and maps.
    fn write_level(
        &mut self,
        within: Within<'t>,
        m: &'t Member,
        level: usize,
        elem: Elem<'t>,
        value: Option<&Value>,
        depth: usize,
    ) -> Res<'t, ()> {
        let Some(dim) = m.dims.get(level) else {
            return self.write_elem(m, level, elem, value, depth);
        };
        let vector = is_byte_vector(m);
        if !vector && depth >= MAX_DEPTH {
            return Err(too_deep(None));
        }
        let innermost_bytes =
            level + 1 == m.dims.len() && matches!(elem, Elem::Prim(Primitive::Byte));
        let len = match value {
            None => match dim.size {
                Size::Fixed(n) => n as usize,
                Size::Member(_) => 0,
            },
            Some(Value::List(items)) => items.len(),
            Some(Value::Bytes(bytes)) if innermost_bytes => bytes.len(),
            Some(other) => {
                return Err(fail(CodecError::WrongType {
                    path: String::new(),
                    expected: type_text(m, level),
                    found: other.type_name(),
                }));
            }
        };
        self.check_len(within, m, level, dim, len)?;
        if !vector {
            count_elements(&mut self.elements, len, None)?;
        }
        match value {
            None if innermost_bytes => {
                self.out.resize(self.out.len() + len, 0);
            }
            None => {
                for i in 0..len {
                    self.write_level(within, m, level + 1, elem, None, depth + 1)
                        .map_err(|f| f.index(i))?;
                }
            }
            Some(Value::Bytes(bytes)) => self.out.extend_from_slice(bytes),
            Some(Value::List(items)) => {
                for (i, item) in items.iter().enumerate() {
                    self.write_level(within, m, level + 1, elem, Some(item), depth + 1)
                        .map_err(|f| f.index(i))?;
                }
            }
            Some(_) => {}
        }
        Ok(())
    }

    /// Checks that `len` elements fit dimension `dim`, at `level` of member `m`.
    fn check_len(
        &self,
        within: Within<'t>,
        m: &'t Member,
        level: usize,
        dim: &Dim,
        len: usize,
    ) -> Res<'t, ()> {
        match dim.size {
            Size::Fixed(n) => {
                if len != n as usize {
                    return Err(fail(CodecError::Length {
                        path: String::new(),
                        ty: type_text(m, level),
                        expected: n,
                        found: len,
                    }));
                }
            }
            Size::Member(j) => {
                let Within { members, base } = within;
                let size = self
                    .sizes
                    .get(base + j)
                    .copied()
                    .flatten()
                    .unwrap_or(SizeValue { n: 0, from: None });
                if i64::try_from(len).ok() != Some(size.n) {
                    let from = size
                        .from
                        .and_then(|(k, lvl)| members.get(k).map(|a| first_path(a, lvl)));
                    return Err(fail(CodecError::SizeMismatch {
                        path: String::new(),
                        len,
                        size_path: members.get(j).map_or_else(String::new, |s| s.name.clone()),
                        size: size.n,
                        from,
                    }));
                }
            }
        }
        Ok(())
    }

    /// Writes one value of member `m` (inside `level` array dimensions, all of them) from `value`,
    /// found inside `depth` lists and maps.
    fn write_elem(
        &mut self,
        m: &'t Member,
        level: usize,
        elem: Elem<'t>,
        value: Option<&Value>,
        depth: usize,
    ) -> Res<'t, ()> {
        let p = match elem {
            Elem::Struct(t) => {
                if depth >= MAX_DEPTH {
                    return Err(too_deep(None));
                }
                return match value {
                    None => self.write_struct(t, None, depth + 1),
                    Some(Value::Map(map)) => self.write_struct(t, Some(map), depth + 1),
                    Some(other) => Err(fail(CodecError::WrongType {
                        path: String::new(),
                        expected: type_text(m, level),
                        found: other.type_name(),
                    })),
                };
            }
            Elem::Prim(p) => p,
        };
        let wrong = |other: &Value| {
            fail(CodecError::WrongType {
                path: String::new(),
                expected: type_text(m, level),
                found: other.type_name(),
            })
        };
        match (p, value) {
            (Primitive::Float, None) => self.out.extend_from_slice(&f32::NAN.to_be_bytes()),
            (Primitive::Double, None) => self.out.extend_from_slice(&f64::NAN.to_be_bytes()),
            (Primitive::String, None) => self.out.extend_from_slice(&[0, 0, 0, 1, 0]),
            (_, None) => self.put_int(p, 0),
            (Primitive::Boolean, Some(value)) => {
                let b = match value {
                    Value::Bool(b) => *b,
                    Value::Int(0) => false,
                    Value::Int(1) => true,
                    Value::Int(i) => {
                        return Err(fail(CodecError::OutOfRange {
                            path: String::new(),
                            ty: p,
                            value: i.to_string(),
                        }));
                    }
                    other => return Err(wrong(other)),
                };
                // the byte it was read from, when it was neither 0 nor 1 and it is still true
                let kept = next_raw(&mut self.raws).and_then(|raw| match raw {
                    Value::Int(byte) if b => u8::try_from(*byte).ok().filter(|&byte| byte != 0),
                    _ => None,
                });
                self.out.push(kept.unwrap_or(u8::from(b)));
            }
            (Primitive::Float, Some(value)) => {
                let x = match value {
                    Value::Float(x) => *x,
                    Value::Int(i) => *i as f64,
                    other => return Err(wrong(other)),
                };
                let y = to_f32(x);
                if y.is_infinite() && x.is_finite() {
                    return Err(fail(CodecError::OutOfRange {
                        path: String::new(),
                        ty: p,
                        value: format!("{x:?}"),
                    }));
                }
                self.out.extend_from_slice(&y.to_be_bytes());
            }
            (Primitive::Double, Some(value)) => {
                let x = match value {
                    Value::Float(x) => *x,
                    Value::Int(i) => *i as f64,
                    other => return Err(wrong(other)),
                };
                self.out.extend_from_slice(&x.to_be_bytes());
            }
            (Primitive::String, Some(value)) => {
                let Value::Str(text) = value else {
                    return Err(wrong(value));
                };
                // the bytes it was read from, when they were not UTF-8 and it is still their text
                let raw = next_raw(&mut self.raws).and_then(|raw| match raw {
                    Value::Bytes(raw) if String::from_utf8_lossy(raw) == text.as_ref() => {
                        Some(raw.as_slice())
                    }
                    _ => None,
                });
                let s: &[u8] = raw.unwrap_or(text.as_bytes());
                let Some(len) = i32::try_from(s.len()).ok().and_then(|n| n.checked_add(1)) else {
                    return Err(fail(CodecError::OutOfRange {
                        path: String::new(),
                        ty: p,
                        value: format!("a string of {} bytes", s.len()),
                    }));
                };
                self.out.extend_from_slice(&len.to_be_bytes());
                self.out.extend_from_slice(s);
                self.out.push(0);
            }
            (_, Some(value)) => {
                let n = int_value(p, m, level, value)?;
                self.put_int(p, n);
            }
        }
        Ok(())
    }

    /// Writes `n`, known to be in range, as integer type `ty` (or `byte`).
    fn put_int(&mut self, ty: Primitive, n: i64) {
        match ty {
            Primitive::Int8 | Primitive::Byte | Primitive::Boolean => self.out.push(n as u8),
            Primitive::Int16 => self.out.extend_from_slice(&(n as i16).to_be_bytes()),
            Primitive::Int32 => self.out.extend_from_slice(&(n as i32).to_be_bytes()),
            _ => self.out.extend_from_slice(&n.to_be_bytes()),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Decoding

/// Decodes a message of type `ty`: checks its fingerprint, then reads its members into a datamap
/// (see the module documentation for the mapping), with what liblcm would have read leniently.
/// Any input is read or refused without a panic.
pub fn decode(
    types: &ResolvedTypes,
    ty: &StructType,
    bytes: &[u8],
) -> Result<(DataMap, Leniency), CodecError> {
    let Some((fingerprint, _)) = bytes.split_first_chunk::<FINGERPRINT_LEN>() else {
        return Err(CodecError::Truncated {
            path: String::new(),
            offset: 0,
            needed: FINGERPRINT_LEN as u64,
            left: bytes.len(),
        });
    };
    let received = u64::from_be_bytes(*fingerprint);
    if received != ty.fingerprint() {
        return Err(CodecError::Fingerprint {
            expected: ty.full_name().to_string(),
            expected_fingerprint: ty.fingerprint(),
            received_fingerprint: received,
            received: types
                .by_fingerprint(received)
                .map(|t| t.full_name().to_string()),
        });
    }
    let mut decoder = Decoder {
        types,
        bytes,
        pos: FINGERPRINT_LEN,
        sizes: Vec::new(),
        elements: 0,
        free: bytes.len().saturating_add(FREE_ELEMENTS),
        lenient: Leniency::default(),
        raws: Vec::new(),
    };
    let map = decoder.read_struct(ty, 0).map_err(|f| (*f).finish())?;
    let mut lenient = decoder.lenient;
    lenient.end = decoder.pos;
    lenient.trailing = bytes.len().saturating_sub(decoder.pos);
    Ok((map, lenient))
}

/// Reads messages.
struct Decoder<'t, 'b> {
    types: &'t ResolvedTypes,
    bytes: &'b [u8],
    /// The next byte to read.
    pos: usize,
    /// The integer members of the structs being read, one slot per member (a stack, as in the
    /// encoder): the sizes of later arrays.
    sizes: Vec<i64>,
    /// Array elements read so far.
    elements: usize,
    /// Array elements that may encode to no bytes still allowed.
    free: usize,
    /// What was read leniently.
    lenient: Leniency,
    /// The booleans and strings read, in order, while a member is read: the byte of a boolean
    /// neither 0 nor 1 (an int), the bytes of a string not UTF-8.
    raws: Vec<Option<Value>>,
}

/// `value` with each boolean in it replaced by its byte (an int) and each string by its bytes:
/// those kept in `raws` (in order) or its own.
fn raw_shadow(value: &Value, raws: &mut impl Iterator<Item = Option<Value>>) -> Value {
    let own = match value {
        Value::List(items) => {
            return Value::List(items.iter().map(|v| raw_shadow(v, raws)).collect());
        }
        Value::Bool(b) => Value::Int(i64::from(*b)),
        Value::Str(s) => Value::Bytes(s.as_bytes().to_vec()),
        other => return other.clone(),
    };
    raws.next().flatten().unwrap_or(own)
}

/// The values kept in `value` (the `name.raw` of a boolean or string member), in order: one for
/// each boolean or string of the member.
fn raw_leaves(value: &Value, out: &mut Vec<Value>) {
    match value {
        Value::List(items) => items.iter().for_each(|v| raw_leaves(v, out)),
        leaf => out.push(leaf.clone()),
    }
}

impl<'t> Decoder<'t, '_> {
    /// Bytes left to read.
    fn left(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }

    /// The error for `needed` bytes at the read position, of which fewer are left.
    fn truncated(&self, needed: u64) -> Box<Fail<'t>> {
        fail(CodecError::Truncated {
            path: String::new(),
            offset: self.pos,
            needed,
            left: self.left(),
        })
    }

    /// The next `n` bytes.
    fn take(&mut self, n: usize) -> Res<'t, &[u8]> {
        let start = self.pos;
        match start
            .checked_add(n)
            .and_then(|end| self.bytes.get(start..end))
        {
            Some(taken) => {
                self.pos = start + n;
                Ok(taken)
            }
            None => Err(self.truncated(n as u64)),
        }
    }

    /// The next `N` bytes.
    fn take_array<const N: usize>(&mut self) -> Res<'t, [u8; N]> {
        let chunk = self
            .bytes
            .get(self.pos..)
            .and_then(<[u8]>::first_chunk::<N>)
            .copied();
        match chunk {
            Some(chunk) => {
                self.pos += N;
                Ok(chunk)
            }
            None => Err(self.truncated(N as u64)),
        }
    }

    /// Reads the members of `ty`, whose values are found inside `depth` lists and maps.
    fn read_struct(&mut self, ty: &'t StructType, depth: usize) -> Res<'t, DataMap> {
        let members = ty.members();
        let base = self.sizes.len();
        self.sizes.resize(base + members.len(), 0);
        let mut map = DataMap::with_capacity(members.len());
        for (i, m) in members.iter().enumerate() {
            let raws = self.raws.len();
            let value = self
                .read_member(Within { members, base }, m, depth)
                .map_err(|f| f.member(&m.name))?;
            if let (Value::Int(n), true) = (&value, m.dims.is_empty())
                && let Some(slot) = self.sizes.get_mut(base + i)
            {
                *slot = *n;
            }
            let kept = (self.raws.len() > raws && self.raws[raws..].iter().any(Option::is_some))
                .then(|| raw_shadow(&value, &mut self.raws.drain(raws..)));
            self.raws.truncate(raws);
            map.push(m.name.clone(), value);
            if let Some(kept) = kept {
                map.push(format!("{}{RAW_SUFFIX}", m.name), kept);
            }
        }
        self.sizes.truncate(base);
        Ok(map)
    }

    /// Reads member `m` of a struct whose members are `members`.
    fn read_member(&mut self, within: Within<'t>, m: &'t Member, depth: usize) -> Res<'t, Value> {
        let elem = elem(self.types, m)?;
        self.read_level(within, m, 0, elem, depth)
    }

    /// Reads the part of member `m` inside `level` of its array dimensions, found inside `depth`
    /// lists and maps.
    fn read_level(
        &mut self,
        within: Within<'t>,
        m: &'t Member,
        level: usize,
        elem: Elem<'t>,
        depth: usize,
    ) -> Res<'t, Value> {
        let Some(dim) = m.dims.get(level) else {
            return self.read_elem(elem, depth);
        };
        let offset = self.pos;
        let count = match dim.size {
            Size::Fixed(n) => n as usize,
            Size::Member(j) => {
                let Within { members, base } = within;
                let n = self.sizes.get(base + j).copied().unwrap_or(0);
                if n < 0 {
                    return Err(fail(CodecError::NegativeSize {
                        path: String::new(),
                        offset,
                        size_path: members.get(j).map_or_else(String::new, |s| s.name.clone()),
                        size: n,
                    }));
                }
                // a size beyond the address space is beyond MAX_ELEMENTS too
                usize::try_from(n).unwrap_or(usize::MAX)
            }
        };
        if is_byte_vector(m) {
            return Ok(Value::Bytes(self.take(count)?.to_vec()));
        }
        if depth >= MAX_DEPTH {
            return Err(too_deep(Some(offset)));
        }
        count_elements(&mut self.elements, count, Some(offset))?;
        let innermost = level + 1 == m.dims.len();
        if count > 0 && item_min_size(m, level, elem) == 0 {
            if count > self.free {
                return Err(fail(CodecError::TooManyEmpty {
                    path: String::new(),
                    offset,
                    count,
                    size: self.bytes.len(),
                }));
            }
            self.free -= count;
        }
        if innermost
            && let Elem::Prim(p) = elem
            && let Some(width) = width(p)
        {
            // count ≤ MAX_ELEMENTS, so this does not overflow
            let needed = count * width;
            if needed > self.left() {
                return Err(self.truncated(needed as u64));
            }
        }
        let mut items = Vec::with_capacity(count.min(self.left()));
        for i in 0..count {
            let item = if innermost {
                self.read_elem(elem, depth + 1)
            } else {
                self.read_level(within, m, level + 1, elem, depth + 1)
            };
            items.push(item.map_err(|f| f.index(i))?);
        }
        Ok(Value::List(items))
    }

    /// Reads one value, found inside `depth` lists and maps.
    fn read_elem(&mut self, elem: Elem<'t>, depth: usize) -> Res<'t, Value> {
        match elem {
            Elem::Struct(t) => {
                if depth >= MAX_DEPTH {
                    return Err(too_deep(Some(self.pos)));
                }
                Ok(Value::Map(self.read_struct(t, depth + 1)?))
            }
            Elem::Prim(p) => self.read_prim(p),
        }
    }

    /// Reads one value of primitive type `p`.
    fn read_prim(&mut self, p: Primitive) -> Res<'t, Value> {
        let offset = self.pos;
        Ok(match p {
            Primitive::Int8 => Value::Int(i8::from_be_bytes(self.take_array()?).into()),
            Primitive::Int16 => Value::Int(i16::from_be_bytes(self.take_array()?).into()),
            Primitive::Int32 => Value::Int(i32::from_be_bytes(self.take_array()?).into()),
            Primitive::Int64 => Value::Int(i64::from_be_bytes(self.take_array()?)),
            Primitive::Byte => Value::Int(u8::from_be_bytes(self.take_array()?).into()),
            Primitive::Boolean => match self.take_array::<1>()? {
                [byte @ (0 | 1)] => {
                    self.raws.push(None);
                    Value::Bool(byte == 1)
                }
                [byte] => {
                    // liblcm's decoders read any other byte as true, and hand it over as it is
                    self.lenient.bools += 1;
                    self.lenient.first_bool.get_or_insert((offset, byte));
                    self.raws.push(Some(Value::Int(byte.into())));
                    Value::Bool(true)
                }
            },
            Primitive::Float => Value::Float(from_f32(f32::from_be_bytes(self.take_array()?))),
            Primitive::Double => Value::Float(f64::from_be_bytes(self.take_array()?)),
            Primitive::String => {
                let len = i32::from_be_bytes(self.take_array()?);
                let bad = |problem| {
                    fail(CodecError::BadString {
                        path: String::new(),
                        offset,
                        problem,
                    })
                };
                let Ok(n @ 1..) = usize::try_from(len) else {
                    return Err(bad(StringProblem::Length(len)));
                };
                let body = self.take(n)?;
                let Some((0, text)) = body.split_last() else {
                    return Err(bad(StringProblem::NoNul));
                };
                match std::str::from_utf8(text) {
                    Ok(text) => {
                        let text = text.to_string();
                        self.raws.push(None);
                        Value::Str(Cow::Owned(text))
                    }
                    Err(_) => {
                        // liblcm hands the bytes over as they are
                        let (lossy, raw) =
                            (String::from_utf8_lossy(text).into_owned(), text.to_vec());
                        self.lenient.strings += 1;
                        self.lenient.first_string.get_or_insert(offset);
                        self.raws.push(Some(Value::Bytes(raw)));
                        Value::Str(Cow::Owned(lossy))
                    }
                }
            }
        })
    }
}

/// The fewest bytes one element at `level` of member `m`'s dimensions encodes to: one value of
/// the element type, or a row of the dimensions inside.
fn item_min_size(m: &Member, level: usize, elem: Elem<'_>) -> u64 {
    let one = match elem {
        Elem::Prim(p) => primitive_min_size(p),
        Elem::Struct(t) => t.min_size(),
    };
    m.dims
        .iter()
        .skip(level + 1)
        .fold(one, |n, d| match d.size {
            Size::Fixed(k) => n.saturating_mul(u64::from(k)),
            Size::Member(_) => 0,
        })
}

/// Bytes of one value of `p`, for the types of one size.
fn width(p: Primitive) -> Option<usize> {
    match p {
        Primitive::Int8 | Primitive::Byte | Primitive::Boolean => Some(1),
        Primitive::Int16 => Some(2),
        Primitive::Int32 | Primitive::Float => Some(4),
        Primitive::Int64 | Primitive::Double => Some(8),
        Primitive::String => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::TypeSet;

    /// The types of `text`, read as file `t.lcm`.
    fn types(text: &str) -> ResolvedTypes {
        let mut set = TypeSet::new();
        set.add_text("t.lcm", text)
            .unwrap_or_else(|e| panic!("{e}"));
        set.resolve().unwrap_or_else(|e| panic!("{e}"))
    }

    /// Struct `name` of `types`.
    fn get<'a>(types: &'a ResolvedTypes, name: &str) -> &'a StructType {
        types
            .get(name)
            .unwrap_or_else(|| panic!("no struct {name}"))
    }

    /// A list value.
    fn list<V: Into<Value>>(items: impl IntoIterator<Item = V>) -> Value {
        Value::List(items.into_iter().map(Into::into).collect())
    }

    /// `map` encoded as `name`, or the error as printed.
    fn enc(types: &ResolvedTypes, name: &str, map: &DataMap) -> Result<Vec<u8>, String> {
        encode(types, get(types, name), map).map_err(|e| e.to_string())
    }

    /// The error `map` gets when encoded as `name`.
    fn enc_err(types: &ResolvedTypes, name: &str, map: &DataMap) -> String {
        match enc(types, name, map) {
            Ok(bytes) => panic!("{map} encodes as {bytes:02x?}"),
            Err(e) => e,
        }
    }

    /// `body` decoded as `name`, after `name`'s fingerprint.
    fn dec(types: &ResolvedTypes, name: &str, body: &[u8]) -> Result<DataMap, String> {
        dec_lenient(types, name, body).map(|(map, _)| map)
    }

    /// `body` decoded as `name`, after `name`'s fingerprint, with what was read leniently.
    fn dec_lenient(
        types: &ResolvedTypes,
        name: &str,
        body: &[u8],
    ) -> Result<(DataMap, Leniency), String> {
        let ty = get(types, name);
        let mut bytes = ty.fingerprint().to_be_bytes().to_vec();
        bytes.extend_from_slice(body);
        decode(types, ty, &bytes).map_err(|e| e.to_string())
    }

    /// The error `body` gets when decoded as `name`, after `name`'s fingerprint.
    fn dec_err(types: &ResolvedTypes, name: &str, body: &[u8]) -> String {
        match dec(types, name, body) {
            Ok(map) => panic!("{body:02x?} decodes, to {} members", map.len()),
            Err(e) => e,
        }
    }

    /// Encodes `map` as `name`, checks that the body is `body` and that it decodes as `back`.
    fn round_trip(types: &ResolvedTypes, name: &str, map: &DataMap, body: &[u8], back: &DataMap) {
        let bytes = enc(types, name, map).unwrap_or_else(|e| panic!("{e}"));
        let fp = get(types, name).fingerprint().to_be_bytes();
        assert_eq!(bytes.get(..8), Some(&fp[..]), "fingerprint");
        assert_eq!(bytes.get(8..), Some(body), "body of {map}");
        let got = dec(types, name, body).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(&got, back);
        let keys: Vec<&str> = got.iter().map(|(k, _)| k).collect();
        let names: Vec<&str> = get(types, name)
            .members()
            .iter()
            .map(|m| m.name.as_str())
            .collect();
        assert_eq!(keys, names, "members in declared order");
    }

    const PRIMITIVES: &str = "struct prim_t {\n\
        int8_t a; int16_t b; int32_t c; int64_t d; byte e; boolean f; float g; double h;\n\
        string s;\n\
    }\n";

    #[test]
    fn temperature_message_bytes() {
        let t = types("struct temperature_t { int64_t utime; double deg_celsius; }");
        let map = DataMap::new()
            .and("utime", 1_700_000_000_000_000i64)
            .and("deg_celsius", 21.5f64);
        let bytes = enc(&t, "temperature_t", &map).unwrap_or_else(|e| panic!("{e}"));
        let mut want = 0x543e51f55d3644f6u64.to_be_bytes().to_vec();
        want.extend_from_slice(&1_700_000_000_000_000i64.to_be_bytes());
        want.extend_from_slice(&21.5f64.to_be_bytes());
        assert_eq!(bytes, want);
        let back = decode(&t, get(&t, "temperature_t"), &bytes)
            .unwrap_or_else(|e| panic!("{e}"))
            .0;
        assert_eq!(back, map);
    }

    #[test]
    fn every_primitive_maps_to_its_value() {
        let t = types(PRIMITIVES);
        let map = DataMap::new()
            .and("a", -128i64)
            .and("b", -32768i64)
            .and("c", i64::from(i32::MAX))
            .and("d", i64::MIN)
            .and("e", 255i64)
            .and("f", true)
            .and("g", 1.5f64)
            .and("h", -0.0f64)
            .and("s", "héllo");
        let mut body = vec![0x80, 0x80, 0x00, 0x7f, 0xff, 0xff, 0xff];
        body.extend_from_slice(&i64::MIN.to_be_bytes());
        body.extend_from_slice(&[0xff, 0x01]);
        body.extend_from_slice(&1.5f32.to_be_bytes());
        body.extend_from_slice(&(-0.0f64).to_be_bytes());
        body.extend_from_slice(&[0, 0, 0, 7]);
        body.extend_from_slice("héllo\0".as_bytes());
        round_trip(&t, "prim_t", &map, &body, &map);
    }

    #[test]
    fn lenient_encodings_decode_as_the_plain_value() {
        let t = types(PRIMITIVES);
        // an integral float for integers, ints for booleans and floats
        let map = DataMap::new()
            .and("a", -3.0f64)
            .and("b", 7.0f64)
            .and("c", -0.0f64)
            .and("d", 9.007_199_254_740_992e15f64)
            .and("e", 200.0f64)
            .and("f", 1i64)
            .and("g", 3i64)
            .and("h", -4i64)
            .and("s", "");
        let mut body = vec![0xfd, 0x00, 0x07, 0, 0, 0, 0];
        body.extend_from_slice(&9_007_199_254_740_992i64.to_be_bytes());
        body.extend_from_slice(&[200, 1]);
        body.extend_from_slice(&3.0f32.to_be_bytes());
        body.extend_from_slice(&(-4.0f64).to_be_bytes());
        body.extend_from_slice(&[0, 0, 0, 1, 0]);
        let back = DataMap::new()
            .and("a", -3i64)
            .and("b", 7i64)
            .and("c", 0i64)
            .and("d", 9_007_199_254_740_992i64)
            .and("e", 200i64)
            .and("f", true)
            .and("g", 3.0f64)
            .and("h", -4.0f64)
            .and("s", "");
        round_trip(&t, "prim_t", &map, &body, &back);
        let zero = DataMap::new().and("f", 0i64);
        let bytes = enc(&t, "prim_t", &zero).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bytes.get(8 + 15), Some(&0), "boolean 0");
    }

    #[test]
    fn numbers_out_of_range_are_refused_naming_the_field() {
        let t = types(PRIMITIVES);
        let int8 = "not an integer from -128 to 127";
        let int16 = "not an integer from -32768 to 32767";
        let int32 = "not an integer from -2147483648 to 2147483647";
        let int64 = "not an integer from -9223372036854775808 to 9223372036854775807";
        let byte = "not an integer from 0 to 255";
        let boolean = "a boolean is true, false, 0 or 1";
        let float = "beyond the range of float";
        // field, its type, a value, that value as printed, and what the error says of the type
        let cases = [
            ("a", "int8_t", Value::Int(128), "128", int8),
            ("a", "int8_t", Value::Int(-129), "-129", int8),
            ("b", "int16_t", Value::Int(32768), "32768", int16),
            ("c", "int32_t", Value::Int(1 << 31), "2147483648", int32),
            ("c", "int32_t", Value::Float(1.5), "1.5", int32),
            ("d", "int64_t", Value::Float(9.3e18), "9.3e18", int64),
            ("d", "int64_t", Value::Float(f64::NAN), "NaN", int64),
            ("e", "byte", Value::Int(256), "256", byte),
            ("e", "byte", Value::Int(-1), "-1", byte),
            ("f", "boolean", Value::Int(2), "2", boolean),
            ("g", "float", Value::Float(1e39), "1e39", float),
        ];
        for (field, ty, value, shown, why) in cases {
            let want = format!("field `{field}` ({ty}) cannot take {shown}: {why}");
            let e = enc_err(&t, "prim_t", &DataMap::new().and(field, value));
            assert!(e.starts_with(&want), "got {e:?}, wanted {want:?}");
        }
        // infinities are floats too
        let inf = DataMap::new()
            .and("g", f64::INFINITY)
            .and("h", f64::NEG_INFINITY);
        let bytes = enc(&t, "prim_t", &inf).unwrap_or_else(|e| panic!("{e}"));
        let back = decode(&t, get(&t, "prim_t"), &bytes)
            .unwrap_or_else(|e| panic!("{e}"))
            .0;
        assert_eq!(back.get("g"), Some(&Value::Float(f64::INFINITY)));
        assert_eq!(back.get("h"), Some(&Value::Float(f64::NEG_INFINITY)));
    }

    #[test]
    fn values_of_the_wrong_type_are_refused_naming_both_types() {
        let t = types(
            "package seabus;\n\
             struct position_t { double x, y; float z; }\n\
             struct pose_t { int64_t utime; position_t position; int32_t grid[2][3]; byte raw[2]; \
                             byte planes[2][2]; string name; boolean ok; }\n",
        );
        let pose = |k: &'static str, v: Value| DataMap::new().and(k, v);
        let position = |v: Value| DataMap::new().and("x", v);
        let cases: Vec<(DataMap, &str)> = vec![
            (
                pose("utime", Value::from("now")),
                "field `utime` (int64_t) cannot take a string value",
            ),
            (
                pose("utime", Value::Bool(true)),
                "field `utime` (int64_t) cannot take a bool value",
            ),
            (
                pose("position", list([1.0f64])),
                "field `position` (seabus.position_t) cannot take a list value",
            ),
            (
                pose("position", Value::Map(position(Value::from("e")))),
                "field `position.x` (double) cannot take a string value",
            ),
            (
                pose("position", Value::Map(position(Value::Map(DataMap::new())))),
                "field `position.x` (double) cannot take a map value",
            ),
            (
                pose("grid", Value::Int(1)),
                "field `grid` (int32_t[2][3]) cannot take an int value",
            ),
            (
                pose("grid", list([list([1i64, 2, 3]), list(Vec::<i64>::new())])),
                "field `grid[1]` (int32_t[3]) has 0 elements, not 3",
            ),
            (
                pose("grid", list([list([1i64, 2, 3])])),
                "field `grid` (int32_t[2][3]) has 1 element, not 2",
            ),
            (
                pose(
                    "grid",
                    list([
                        list([1i64, 2, 3]),
                        list([Value::Int(4), Value::Float(0.5), Value::Int(6)]),
                    ]),
                ),
                "field `grid[1][1]` (int32_t) cannot take 0.5: not an integer",
            ),
            (
                pose(
                    "grid",
                    list([Value::Bytes(vec![1, 2, 3]), list([1i64, 2, 3])]),
                ),
                "field `grid[0]` (int32_t[3]) cannot take a bytes value",
            ),
            (
                pose("raw", Value::Bytes(vec![1, 2, 3])),
                "field `raw` (byte[2]) has 3 elements, not 2",
            ),
            (
                pose("raw", list([Value::Int(1), Value::Float(2.5)])),
                "field `raw[1]` (byte) cannot take 2.5: not an integer from 0 to 255",
            ),
            (
                pose("raw", Value::from("ab")),
                "field `raw` (byte[2]) cannot take a string value",
            ),
            (
                pose("planes", Value::Bytes(vec![1, 2, 3, 4])),
                "field `planes` (byte[2][2]) cannot take a bytes value",
            ),
            (
                pose("name", Value::Bytes(b"x".to_vec())),
                "field `name` (string) cannot take a bytes value",
            ),
            (
                pose("ok", Value::Float(1.0)),
                "field `ok` (boolean) cannot take a float value",
            ),
        ];
        for (map, want) in cases {
            let e = enc_err(&t, "seabus.pose_t", &map);
            assert!(e.starts_with(want), "{map}: got {e:?}, wanted {want:?}");
        }
    }

    #[test]
    fn nested_structs_and_arrays_round_trip() {
        let t = types(
            "package nav;\n\
             struct point_t { double x; float y; }\n\
             struct track_t {\n\
                 int16_t rows; int8_t cols;\n\
                 double grid[rows][cols];\n\
                 int32_t fixed[2][3];\n\
                 int32_t n;\n\
                 point_t points[n][2];\n\
                 string names[n];\n\
                 boolean flags[2];\n\
                 point_t last;\n\
             }\n",
        );
        let point = |x: f64, y: f64| Value::Map(DataMap::new().and("x", x).and("y", y));
        let map = DataMap::new()
            .and("rows", 2i64)
            .and("cols", 1i64)
            .and("grid", list([list([1.0f64]), list([2.0f64])]))
            .and("fixed", list([list([1i64, 2, 3]), list([4i64, 5, 6])]))
            .and("n", 1i64)
            .and("points", list([list([point(1.0, 2.0), point(3.0, 4.0)])]))
            .and("names", list(["a"]))
            .and("flags", list([true, false]))
            .and("last", point(-1.0, 0.25));
        let mut body = vec![0, 2, 1];
        body.extend_from_slice(&1.0f64.to_be_bytes());
        body.extend_from_slice(&2.0f64.to_be_bytes());
        for i in 1..=6i32 {
            body.extend_from_slice(&i.to_be_bytes());
        }
        body.extend_from_slice(&1i32.to_be_bytes());
        for (x, y) in [(1.0f64, 2.0f32), (3.0, 4.0), (-1.0, 0.25)] {
            if x < 0.0 {
                body.extend_from_slice(&[0, 0, 0, 2, b'a', 0, 1, 0]);
            }
            body.extend_from_slice(&x.to_be_bytes());
            body.extend_from_slice(&y.to_be_bytes());
        }
        round_trip(&t, "nav.track_t", &map, &body, &map);
    }

    #[test]
    fn byte_arrays_are_bytes_in_one_dimension_lists_in_more() {
        let t = types(
            "struct blob_t { byte raw[3]; int32_t n; byte data[n]; int8_t w; byte planes[2][w]; }",
        );
        let map = DataMap::new()
            .and("raw", vec![1u8, 2, 3])
            .and("n", 2i64)
            .and("data", vec![0xffu8, 0])
            .and("w", 1i64)
            .and("planes", list([list([7i64]), list([8i64])]));
        let body = [1, 2, 3, 0, 0, 0, 2, 0xff, 0, 1, 7, 8];
        round_trip(&t, "blob_t", &map, &body, &map);
        // lists of ints for a byte vector, bytes for the rows of a byte matrix
        let lenient = DataMap::new()
            .and("raw", list([1i64, 2, 3]))
            .and("data", list([255.0f64, 0.0]))
            .and(
                "planes",
                list([Value::Bytes(vec![7]), Value::Bytes(vec![8])]),
            );
        round_trip(&t, "blob_t", &lenient, &body, &map);
    }

    #[test]
    fn missing_members_take_defaults() {
        let t = types(
            "package d;\n\
             struct point_t { double x; float y; int8_t k; boolean ok; string s; }\n\
             struct all_t { int32_t n; double v[n]; point_t p; int16_t fixed[2]; point_t two[2];\n\
                            byte raw[2]; int8_t m; byte rows[2][m]; string s; }\n",
        );
        let nan64 = f64::NAN.to_be_bytes();
        let nan32 = f32::NAN.to_be_bytes();
        let mut point = Vec::new();
        point.extend_from_slice(&nan64);
        point.extend_from_slice(&nan32);
        point.extend_from_slice(&[0, 0, 0, 0, 0, 1, 0]);
        let mut body = vec![0, 0, 0, 0];
        body.extend_from_slice(&point);
        body.extend_from_slice(&[0, 0, 0, 0]);
        body.extend_from_slice(&point);
        body.extend_from_slice(&point);
        body.extend_from_slice(&[0, 0, 0, 0, 0, 0, 1, 0]);
        let point_map = || {
            Value::Map(
                DataMap::new()
                    .and("x", f64::NAN)
                    .and("y", f64::from(f32::NAN))
                    .and("k", 0i64)
                    .and("ok", false)
                    .and("s", ""),
            )
        };
        let back = DataMap::new()
            .and("n", 0i64)
            .and("v", list(Vec::<f64>::new()))
            .and("p", point_map())
            .and("fixed", list([0i64, 0]))
            .and("two", list([point_map(), point_map()]))
            .and("raw", vec![0u8, 0])
            .and("m", 0i64)
            .and(
                "rows",
                list([list(Vec::<i64>::new()), list(Vec::<i64>::new())]),
            )
            .and("s", "");
        // keys the type does not have are ignored
        let map = DataMap::new().and("unknown", "ignored");
        round_trip(&t, "d.all_t", &map, &body, &back);
        // a nested struct given in part
        let partial = DataMap::new().and("p", DataMap::new().and("k", 5i64));
        let bytes = enc(&t, "d.all_t", &partial).unwrap_or_else(|e| panic!("{e}"));
        let got = decode(&t, get(&t, "d.all_t"), &bytes)
            .unwrap_or_else(|e| panic!("{e}"))
            .0;
        assert_eq!(got.get_path("p.k"), Some(&Value::Int(5)));
        assert_eq!(
            got.get_path("p.x").and_then(Value::as_f64).map(f64::is_nan),
            Some(true)
        );
    }

    #[test]
    fn members_are_found_in_any_order() {
        let t = types("struct a_t { int8_t x; int8_t y; int8_t z; }");
        let map = DataMap::new()
            .and("z", 3i64)
            .and("extra", 9i64)
            .and("x", 1i64)
            .and("y", 2i64);
        let bytes = enc(&t, "a_t", &map).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bytes.get(8..), Some(&[1u8, 2, 3][..]));
    }

    const SIZED: &str =
        "struct s_t { int8_t n; int32_t m; double a[n]; string b[n]; int16_t g[2][m]; }";

    #[test]
    fn sizes_left_out_are_taken_from_the_arrays() {
        let t = types(SIZED);
        let map = DataMap::new()
            .and("a", list([1.0f64, 2.0]))
            .and("b", list(["x", "y"]))
            .and("g", list([list([1i64, 2, 3]), list([4i64, 5, 6])]));
        let bytes = enc(&t, "s_t", &map).unwrap_or_else(|e| panic!("{e}"));
        let back = decode(&t, get(&t, "s_t"), &bytes)
            .unwrap_or_else(|e| panic!("{e}"))
            .0;
        assert_eq!(back.get("n"), Some(&Value::Int(2)));
        assert_eq!(back.get("m"), Some(&Value::Int(3)));
        assert_eq!(back.get("g"), map.get("g"));
        // an empty outer array leaves the inner size unseen: 0
        let map = DataMap::new().and(
            "g",
            list([list(Vec::<i64>::new()), list(Vec::<i64>::new())]),
        );
        let bytes = enc(&t, "s_t", &map).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bytes.get(8..13), Some(&[0u8, 0, 0, 0, 0][..]));
    }

    #[test]
    fn sizes_must_agree_with_every_array() {
        let t = types(SIZED);
        let two = || list([1.0f64, 2.0]);
        let cases: Vec<(DataMap, &str)> = vec![
            (
                DataMap::new().and("n", 3i64).and("a", two()),
                "field `a` has 2 elements, but its size `n` is 3",
            ),
            (
                DataMap::new().and("a", two()).and("b", list(["x"])),
                "field `b` has 1 element, but its size `n` is 2 (the length of `a`)",
            ),
            (
                DataMap::new().and("b", list(["x"])),
                "field `a` has 0 elements, but its size `n` is 1 (the length of `b`)",
            ),
            (
                DataMap::new().and("g", list([list([1i64, 2]), list([3i64])])),
                "field `g[1]` has 1 element, but its size `m` is 2 (the length of `g[0]`)",
            ),
            (
                DataMap::new().and("m", 1i64),
                "field `g[0]` has 0 elements, but its size `m` is 1",
            ),
            (
                DataMap::new().and("n", -1i64),
                "field `a` has 0 elements, but its size `n` is -1",
            ),
            (
                DataMap::new().and("a", list(vec![0.0f64; 128])),
                "field `n` (int8_t) cannot take 128, the length of `a`: not an integer from -128 to 127",
            ),
            (
                DataMap::new().and("n", 1000i64),
                "field `n` (int8_t) cannot take 1000: not an integer from -128 to 127",
            ),
            (
                DataMap::new().and("n", "two"),
                "field `n` (int8_t) cannot take a string value",
            ),
        ];
        for (map, want) in cases {
            let e = enc_err(&t, "s_t", &map);
            assert_eq!(e, want, "{map}");
        }
        let nested = types(&format!("{SIZED}\nstruct o_t {{ s_t items[2]; }}"));
        let map = DataMap::new().and(
            "items",
            list([
                Value::Map(DataMap::new()),
                Value::Map(DataMap::new().and("a", two()).and("b", list(["x"]))),
            ]),
        );
        assert_eq!(
            enc_err(&nested, "o_t", &map),
            "field `items[1].b` has 1 element, but its size `items[1].n` is 2 (the length of \
             `items[1].a`)"
        );
    }

    const TREE: &str = "package tree;\n\
        struct node_t { int32_t num; node_t children[num]; string name; }\n";

    /// A tree of `depth` levels below its root, each node with one child but the last.
    fn chain(depth: usize) -> DataMap {
        let mut node = DataMap::new()
            .and("num", 0i64)
            .and("children", list(Vec::<Value>::new()))
            .and("name", "leaf");
        for _ in 0..depth {
            node = DataMap::new()
                .and("num", 1i64)
                .and("children", list([node]))
                .and("name", "inner");
        }
        node
    }

    #[test]
    fn recursive_trees_round_trip() {
        let t = types(TREE);
        let leaf = |name: &str| {
            Value::Map(
                DataMap::new()
                    .and("num", 0i64)
                    .and("children", list(Vec::<Value>::new()))
                    .and("name", name),
            )
        };
        let mid = DataMap::new()
            .and("num", 2i64)
            .and("children", list([leaf("b"), leaf("c")]))
            .and("name", "m");
        let root = DataMap::new()
            .and("num", 2i64)
            .and("children", list([leaf("a"), Value::Map(mid)]))
            .and("name", "");
        let mut body = vec![0, 0, 0, 2];
        body.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 2, b'a', 0]);
        body.extend_from_slice(&[0, 0, 0, 2]);
        body.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 2, b'b', 0]);
        body.extend_from_slice(&[0, 0, 0, 0, 0, 0, 0, 2, b'c', 0]);
        body.extend_from_slice(&[0, 0, 0, 2, b'm', 0]);
        body.extend_from_slice(&[0, 0, 0, 1, 0]);
        round_trip(&t, "tree.node_t", &root, &body, &root);
        // the deepest tree a datamap holds: each level a list and a map
        let deepest = chain(MAX_DEPTH / 2 - 1);
        let bytes = enc(&t, "tree.node_t", &deepest).unwrap_or_else(|e| panic!("{e}"));
        let back = decode(&t, get(&t, "tree.node_t"), &bytes)
            .unwrap_or_else(|e| panic!("{e}"))
            .0;
        assert_eq!(back, deepest);
        assert!(
            seabus_medium::binary::encode(&back).is_ok(),
            "the binary form carries it"
        );
    }

    #[test]
    fn trees_too_deep_are_refused_both_ways() {
        let t = types(TREE);
        let path = "children[0].".repeat(MAX_DEPTH / 2);
        let e = enc_err(&t, "tree.node_t", &chain(MAX_DEPTH / 2));
        assert_eq!(
            e,
            format!("field `{path}children`: lists and maps nested deeper than {MAX_DEPTH}")
        );
        // the bytes of a chain 40 deep, written by hand
        let mut body = Vec::new();
        for _ in 0..40 {
            body.extend_from_slice(&[0, 0, 0, 1]);
        }
        let e = dec_err(&t, "tree.node_t", &body);
        assert_eq!(
            e,
            format!(
                "field `{path}children` at byte {}: lists and maps nested deeper than {MAX_DEPTH}",
                8 + 4 * (MAX_DEPTH / 2 + 1)
            )
        );
        // a map nested far deeper is refused at the same place, not followed all the way down
        let e = enc_err(&t, "tree.node_t", &chain(2000));
        assert!(e.ends_with("nested deeper than 32"), "{e}");
    }

    #[test]
    fn long_chains_of_structs_are_too_deep_not_a_stack_overflow() {
        let mut text = String::from("struct s0 { int32_t x; }\n");
        for i in 1..5000 {
            text.push_str(&format!("struct s{i} {{ s{} x; }}\n", i - 1));
        }
        let t = types(&text);
        let e = enc_err(&t, "s4999", &DataMap::new());
        assert_eq!(
            e,
            format!(
                "field `{}x`: lists and maps nested deeper than 32",
                "x.".repeat(32)
            )
        );
        let e = dec_err(&t, "s4999", &[0, 0, 0, 0]);
        assert!(e.ends_with(": lists and maps nested deeper than 32"), "{e}");
        let ok = enc(&t, "s32", &DataMap::new()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(ok.len(), 12);
    }

    #[test]
    fn fingerprints_are_checked_first() {
        let t = types(
            "package seabus;\n\
             struct position_t { double x, y; }\n\
             struct heading_t { double deg; }\n",
        );
        let heading = enc(&t, "seabus.heading_t", &DataMap::new().and("deg", 90.0f64))
            .unwrap_or_else(|e| panic!("{e}"));
        let position = get(&t, "seabus.position_t");
        let e = decode(&t, position, &heading).map(|_| ()).unwrap_err();
        let (pf, hf) = (
            position.fingerprint(),
            get(&t, "seabus.heading_t").fingerprint(),
        );
        assert_eq!(
            e,
            CodecError::Fingerprint {
                expected: "seabus.position_t".into(),
                expected_fingerprint: pf,
                received_fingerprint: hf,
                received: Some("seabus.heading_t".into()),
            }
        );
        assert_eq!(
            e.to_string(),
            format!(
                "expected seabus.position_t (0x{pf:016x}), received seabus.heading_t (0x{hf:016x})"
            )
        );
        let mut unknown = heading.clone();
        unknown[0] ^= 0x80;
        let e = decode(&t, position, &unknown).map(|_| ()).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "expected seabus.position_t (0x{pf:016x}), received an unknown type (fingerprint \
                 0x{:016x})",
                hf ^ (0x80 << 56)
            )
        );
        let e = decode(&t, position, &heading[..5]).map(|_| ()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the message ends inside its fingerprint: 8 bytes needed at byte 0, 5 left"
        );
    }

    #[test]
    fn malformed_bytes_are_refused_with_field_and_offset() {
        let t = types(
            "struct leaf_t { int32_t num; boolean ok; }\n\
             struct node_t { int16_t n; leaf_t children[n]; string name; double v; }\n",
        );
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (
                vec![0xff, 0xff],
                "field `children` at byte 10 is sized by `n` = -1, a negative size",
            ),
            (
                vec![0, 1, 0, 0],
                "the message ends inside field `children[0].num`: 4 bytes needed at byte 10, 2 left",
            ),
            (
                vec![0, 0, 0, 0, 0, 0],
                "field `name` at byte 10: string length 0 does not count a terminating NUL",
            ),
            (
                vec![0, 0, 0xff, 0xff, 0xff, 0xfe],
                "field `name` at byte 10: string length -2 does not count a terminating NUL",
            ),
            (
                vec![0, 0, 0, 0, 0, 2, b'a', b'b'],
                "field `name` at byte 10: string does not end with a NUL",
            ),
            (
                vec![0, 0, 0, 0, 0, 9, b'a', 0],
                "the message ends inside field `name`: 9 bytes needed at byte 14, 2 left",
            ),
            (
                vec![0, 0, 0, 0, 0, 1, 0, 1, 2],
                "the message ends inside field `v`: 8 bytes needed at byte 15, 2 left",
            ),
        ];
        for (body, want) in cases {
            assert_eq!(dec_err(&t, "node_t", &body), want, "{body:02x?}");
        }
    }

    #[test]
    fn what_liblcm_reads_is_read_and_said_and_encodes_back_as_it_came() {
        let t = types(
            "struct leaf_t { int32_t num; boolean ok; }\n\
             struct node_t { int16_t n; leaf_t children[n]; string name; string tags[2]; double v;\n\
                             boolean flags[2][2]; }\n",
        );
        let ty = get(&t, "node_t");
        // children[1].ok holds 2 (at byte 19), name is Latin-1 `caf\xe9` (at 20), tags[1] is
        // `\xff` (at 35), flags[0][0] holds 4 (at 49) and flags[1][1] 255 (at 52), and two bytes
        // follow the message (at 53)
        let mut body = vec![0, 2, 0, 0, 0, 1, 1, 0, 0, 0, 2, 2];
        body.extend_from_slice(&[0, 0, 0, 5, b'c', b'a', b'f', 0xe9, 0]);
        body.extend_from_slice(&[0, 0, 0, 2, b'a', 0, 0, 0, 0, 2, 0xff, 0]);
        body.extend_from_slice(&1.0f64.to_be_bytes());
        body.extend_from_slice(&[4, 0, 1, 255]);
        let exact_len = 8 + body.len();
        body.extend_from_slice(&[1, 2]);
        let (map, lenient) = dec_lenient(&t, "node_t", &body).unwrap();
        let children = map.get("children").and_then(Value::as_list).unwrap();
        let child = |i: usize| children[i].as_map().unwrap();
        assert_eq!(child(1).get("ok"), Some(&Value::Bool(true)));
        assert_eq!(child(1).get("ok.raw"), Some(&Value::Int(2)));
        assert_eq!(child(0).get("ok"), Some(&Value::Bool(true)));
        assert_eq!(child(0).get("ok.raw"), None, "a boolean of 1 keeps nothing");
        assert_eq!(
            map.get("flags"),
            Some(&list([list([true, false]), list([true, true])]))
        );
        assert_eq!(
            map.get("flags.raw"),
            Some(&list([list([4i64, 0]), list([1i64, 255])]))
        );
        assert_eq!(map.get_str("name"), Some("caf\u{fffd}"));
        assert_eq!(
            map.get("name.raw"),
            Some(&Value::Bytes(b"caf\xe9".to_vec()))
        );
        assert_eq!(
            map.get("tags.raw"),
            Some(&Value::List(vec![
                Value::Bytes(b"a".to_vec()),
                Value::Bytes(vec![0xff])
            ]))
        );
        assert_eq!(
            lenient,
            Leniency {
                bools: 3,
                first_bool: Some((19, 2)),
                strings: 2,
                first_string: Some(20),
                trailing: 2,
                end: exact_len,
            }
        );
        let cases: Vec<&str> = lenient.cases().iter().map(|c| c.0).collect();
        assert_eq!(
            cases,
            [
                "lcm-bool-not-0-1",
                "lcm-string-not-utf8",
                "lcm-trailing-bytes"
            ]
        );
        // encoded again: the bytes liblcm would have had, booleans and strings as they came,
        // nothing after
        let again = encode(&t, ty, &map).unwrap();
        let mut want = ty.fingerprint().to_be_bytes().to_vec();
        want.extend_from_slice(&body[..exact_len - 8]);
        assert_eq!(again, want);
        // text changed since is written as it is now
        let mut changed = map.clone();
        changed.insert("name", "tea");
        let bytes = encode(&t, ty, &changed).unwrap();
        assert_eq!(
            dec(&t, "node_t", &bytes[8..]).unwrap().get_str("name"),
            Some("tea")
        );
        // a boolean made false since is written 0, its kept byte left; one still true (as a bool
        // or as the int 1) keeps its byte
        let mut changed = map.clone();
        changed.insert("flags", list([list([false, false]), list([true, true])]));
        let mut leaf = child(1).clone();
        leaf.insert("ok", false);
        let mut first = child(0).clone();
        first.insert("ok", 1i64);
        changed.insert("children", list([first.clone(), leaf]));
        let bytes = encode(&t, ty, &changed).unwrap();
        let mut want_changed = want.clone();
        want_changed[8 + 11] = 0;
        want_changed[8 + 41] = 0;
        assert_eq!(bytes, want_changed);
        let mut leaf = child(1).clone();
        leaf.insert("ok", 1i64);
        changed.insert("children", list([first, leaf]));
        changed.insert("flags", list([list([1i64, 0]), list([true, true])]));
        assert_eq!(encode(&t, ty, &changed).unwrap(), want);
        // read again: the same map, its booleans and strings still the bytes they were
        let (back, lenient) = dec_lenient(&t, "node_t", &again[8..]).unwrap();
        assert_eq!(back, map);
        assert_eq!(
            (lenient.bools, lenient.strings, lenient.trailing),
            (3, 2, 0)
        );
        assert!(!lenient.is_exact());
    }

    #[test]
    fn a_string_not_utf8_with_a_nul_inside_is_sent_back_as_it_came() {
        let t = types("struct s_t { string s; }");
        // `c\xfc`, a NUL, `f`: liblcm hands over all four bytes
        let body = [0, 0, 0, 5, b'c', 0xfc, 0, b'f', 0];
        let (map, lenient) = dec_lenient(&t, "s_t", &body).unwrap();
        assert_eq!(map.get_str("s"), Some("c\u{fffd}\0f"));
        assert_eq!(
            map.get("s.raw"),
            Some(&Value::Bytes(vec![b'c', 0xfc, 0, b'f']))
        );
        assert_eq!(lenient.strings, 1);
        let again = enc(&t, "s_t", &map).unwrap();
        assert_eq!(again.get(8..), Some(&body[..]));
    }

    #[test]
    fn kept_bytes_that_cannot_stand_for_the_value_are_left() {
        let t = types("struct b_t { boolean ok; boolean on[2]; string s; }");
        let exact = enc(
            &t,
            "b_t",
            &DataMap::new()
                .and("ok", true)
                .and("on", list([true, true]))
                .and("s", "x"),
        )
        .unwrap();
        // a kept 0 would read as false, 256 is no byte, a string's bytes are no boolean's, and
        // text bytes that do not decode to the text are not the string's
        let map = DataMap::new()
            .and("ok", true)
            .and("ok.raw", 0i64)
            .and("on", list([true, true]))
            .and("on.raw", list([Value::Int(256), Value::Bytes(vec![7])]))
            .and("s", "x")
            .and("s.raw", Value::Bytes(b"y".to_vec()));
        assert_eq!(enc(&t, "b_t", &map).unwrap(), exact);
    }

    #[test]
    fn hostile_sizes_allocate_nothing_they_cannot_fill() {
        let t = types(
            "struct e_t { }\n\
             struct big_t { int32_t n; double v[n]; }\n\
             struct empty_t { int32_t n; e_t items[n]; }\n\
             struct grid_t { int32_t n; int32_t m; int8_t g[n][m]; }\n\
             struct bytes_t { int64_t n; byte b[n]; }\n",
        );
        assert_eq!(
            dec_err(&t, "big_t", &[0x7f, 0xff, 0xff, 0xff]),
            "field `v` at byte 12: more than 4194304 array elements in one message"
        );
        assert_eq!(
            dec_err(&t, "big_t", &[0, 0x10, 0, 0]),
            "the message ends inside field `v`: 8388608 bytes needed at byte 12, 0 left"
        );
        assert_eq!(
            dec_err(
                &t,
                "bytes_t",
                &[0x7f, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff]
            ),
            "the message ends inside field `b`: 9223372036854775807 bytes needed at byte 16, 0 left"
        );
        // structs of no bytes: counted, not read
        let n = (MAX_ELEMENTS as u32 + 1).to_be_bytes();
        assert_eq!(
            dec_err(&t, "empty_t", &n),
            "field `items` at byte 12: more than 4194304 array elements in one message"
        );
        let few = dec(&t, "empty_t", &[0, 0, 0, 3]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            few.get("items")
                .and_then(Value::as_list)
                .map(<[Value]>::len),
            Some(3)
        );
        // under that, as many as the message has bytes and a few more: 12 bytes are not read
        // as millions of maps
        let n = ((MAX_ELEMENTS - 1) as u32).to_be_bytes();
        assert_eq!(
            dec_err(&t, "empty_t", &n),
            "field `items` at byte 12: 4194303 elements that may take no bytes, more than a \
             message of 12 bytes may hold"
        );
        let n = ((FREE_ELEMENTS + 12) as u32).to_be_bytes();
        assert!(dec(&t, "empty_t", &n).is_ok());
        let n = ((FREE_ELEMENTS + 13) as u32).to_be_bytes();
        assert!(dec(&t, "empty_t", &n).is_err());
        // nor millions of empty rows
        assert_eq!(
            dec_err(&t, "grid_t", &[0, 0x3f, 0xff, 0xff, 0, 0, 0, 0]),
            "field `g` at byte 16: 4194303 elements that may take no bytes, more than a message \
             of 16 bytes may hold"
        );
        // nor structs of empty structs
        let t2 = types(
            "struct e_t { }\nstruct z_t { e_t a[1000]; }\nstruct m_t { int32_t n; z_t z[n]; }",
        );
        assert!(
            dec_err(&t2, "m_t", &[0, 0, 0, 100]).contains("elements that may take no bytes"),
            "100 × 1000 empty maps from 12 bytes"
        );
        // rows of nothing count too
        let rows = (MAX_ELEMENTS as u32 + 1).to_be_bytes();
        assert_eq!(
            dec_err(
                &t,
                "grid_t",
                &[rows[0], rows[1], rows[2], rows[3], 0, 0, 0, 0]
            ),
            "field `g` at byte 16: more than 4194304 array elements in one message"
        );
        // and so do defaults written for missing members
        let t = types("struct huge_t { double v[5000000]; }");
        assert_eq!(
            enc_err(&t, "huge_t", &DataMap::new()),
            "field `v`: more than 4194304 array elements in one message"
        );
    }

    #[test]
    fn float_nans_keep_their_bits() {
        let t = types("struct f_t { float f[3]; double d; }");
        let mut body = Vec::new();
        for bits in [0x7fa0_0001u32, 0xffc0_0000, 0x7f80_0001] {
            body.extend_from_slice(&bits.to_be_bytes());
        }
        body.extend_from_slice(&0x7ff0_0000_0000_0001u64.to_be_bytes());
        let map = dec(&t, "f_t", &body).unwrap_or_else(|e| panic!("{e}"));
        let bytes = enc(&t, "f_t", &map).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bytes.get(8..), Some(&body[..]));
        // a double NaN whose payload `float` cannot keep stays a NaN
        let map = DataMap::new().and("f", list([f64::from_bits(0x7ff0_0000_0000_0001), 0.0, 0.0]));
        let bytes = enc(&t, "f_t", &map).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(bytes.get(8..12), Some(&[0x7f, 0xc0, 0, 0][..]));
    }

    #[test]
    fn struct_types_must_be_among_the_types_given() {
        let full = types("struct p_t { double x; }\nstruct q_t { p_t p; }");
        let other = types("struct q_t { int8_t p; }");
        let q = get(&full, "q_t");
        let e = encode(&other, q, &DataMap::new()).map(|_| ()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "field `p` has type `p_t`, which is not among the types given"
        );
        let mut bytes = q.fingerprint().to_be_bytes().to_vec();
        bytes.extend_from_slice(&1.0f64.to_be_bytes());
        let e = decode(&other, q, &bytes).map(|_| ()).unwrap_err();
        assert!(matches!(e, CodecError::UnknownType { .. }), "{e}");
    }
}
