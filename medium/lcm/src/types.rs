//! LCM message types read at run time: the structs of `.lcm` files, parsed as lcm-gen parses them,
//! checked, and fingerprinted as lcm-gen's generated code fingerprints them.
//!
//! A [`TypeSet`] collects the structs of one or more files ([`TypeSet::add_text`],
//! [`TypeSet::add_path`]); [`TypeSet::resolve`] checks that every member type exists and gives
//! [`ResolvedTypes`], where every [`StructType`] has its fingerprint and is found by full name
//! (`package.name`, or the bare name outside any package) or by fingerprint. A struct lists its
//! [`Member`]s in wire order, each with a [`MemberType`] and its array [`Dim`]ensions, and its
//! [`Constant`]s.
//!
//! ```text
//! package nav;                      // the package of the structs after it in this file
//! struct pose_t {
//!     const int32_t MODE_A = 1, MODE_B = 2;
//!     const int32_t CORNERS = 4;
//!     int64_t utime;
//!     double position[3], orientation[4];
//!     int32_t n;
//!     nav.point_t track[n][2];      // sized by an earlier integer member
//!     point_t box[CORNERS];         // sized by a constant; same package: nav.point_t
//!     string name;                  // also: int8_t int16_t byte boolean float
//! }
//! ```
//!
//! As in lcm-gen, tokens end only at white space and at `( ) ; " , : ' [ ]` and operator
//! characters, so `struct a{` and `};` are errors. Enums (deprecated in LCM) are refused. Where
//! lcm-gen accepts what no generated code can use, this reader refuses it: names that are not C
//! identifiers, an array sized by itself or by a constant below 1, integer constants beyond
//! int64_t, constants that are not finite, a comment never closed, and a struct that contains
//! itself other than through a variable-length array (it has no finite encoding). A `package` line
//! holds to the end of its file (lcm-gen carries it on into the next file named).

use seabus_medium::xml::{FileError, Pos};
use std::collections::HashMap;
use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// Most steps the fingerprints of one set may take: recursive types that reach one another in many
/// ways take exponentially many, and lcm-gen's generated code would take as many at run time.
pub const MAX_FINGERPRINT_STEPS: u64 = 1 << 22;

/// Largest constant array size.
pub const MAX_ARRAY_SIZE: u32 = i32::MAX as u32;

/// An LCM primitive type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Primitive {
    /// `int8_t`.
    Int8,
    /// `int16_t`.
    Int16,
    /// `int32_t`.
    Int32,
    /// `int64_t`.
    Int64,
    /// `byte` (unsigned 8 bits).
    Byte,
    /// `boolean` (one byte).
    Boolean,
    /// `float` (IEEE 754, 32 bits).
    Float,
    /// `double` (IEEE 754, 64 bits).
    Double,
    /// `string` (UTF-8, length-prefixed, NUL-terminated).
    String,
}

impl Primitive {
    /// Every primitive type.
    pub const ALL: [Primitive; 9] = [
        Primitive::Int8,
        Primitive::Int16,
        Primitive::Int32,
        Primitive::Int64,
        Primitive::Byte,
        Primitive::Boolean,
        Primitive::Float,
        Primitive::Double,
        Primitive::String,
    ];

    /// The type's name in `.lcm` files.
    pub fn name(self) -> &'static str {
        match self {
            Primitive::Int8 => "int8_t",
            Primitive::Int16 => "int16_t",
            Primitive::Int32 => "int32_t",
            Primitive::Int64 => "int64_t",
            Primitive::Byte => "byte",
            Primitive::Boolean => "boolean",
            Primitive::Float => "float",
            Primitive::Double => "double",
            Primitive::String => "string",
        }
    }

    /// The primitive type called `name`, if any.
    pub fn from_name(name: &str) -> Option<Primitive> {
        Primitive::ALL.into_iter().find(|p| p.name() == name)
    }

    /// True for the types that can size an array: int8_t, int16_t, int32_t and int64_t.
    pub fn is_integer(self) -> bool {
        matches!(
            self,
            Primitive::Int8 | Primitive::Int16 | Primitive::Int32 | Primitive::Int64
        )
    }
}

impl fmt::Display for Primitive {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The type of a member: a primitive or a struct.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum MemberType {
    /// A primitive type.
    Primitive(Primitive),
    /// A struct, by full name (`package.name`, or the bare name outside any package).
    Struct(String),
}

impl fmt::Display for MemberType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MemberType::Primitive(p) => f.write_str(p.name()),
            MemberType::Struct(name) => f.write_str(name),
        }
    }
}

/// The size of one array dimension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Size {
    /// A fixed size, written as a number or as an integer constant of the struct.
    Fixed(u32),
    /// Sized by an earlier integer member of the same struct: its index in [`StructType::members`].
    Member(usize),
}

/// One array dimension of a member.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Dim {
    /// The dimension's size.
    pub size: Size,
    /// The size as the fingerprint hashes it: the number as written, the constant's value as
    /// written, or the sizing member's name.
    pub text: String,
}

/// A member of a struct, in wire order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Member {
    /// The member's name.
    pub name: String,
    /// Its type.
    pub ty: MemberType,
    /// Its array dimensions, outermost first; empty for a single value.
    pub dims: Vec<Dim>,
    /// Where its name is written.
    pub pos: Pos,
    /// Where its type is written.
    pub type_pos: Pos,
}

/// The value of a constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConstValue {
    /// The value of an integer constant.
    Int(i64),
    /// The value of a `float` (rounded to 32 bits) or `double` constant.
    Float(f64),
}

/// A constant of a struct (`const int32_t A = 1;`): not sent, and not part of the fingerprint.
#[derive(Debug, Clone, PartialEq)]
pub struct Constant {
    /// The constant's name.
    pub name: String,
    /// Its type: an integer type, `float` or `double`.
    pub ty: Primitive,
    /// Its value.
    pub value: ConstValue,
    /// Its value as written.
    pub text: String,
    /// Where its name is written.
    pub pos: Pos,
}

/// An LCM struct type: its names, members, constants and hashes.
#[derive(Debug, Clone, PartialEq)]
pub struct StructType {
    package: String,
    name: String,
    full_name: String,
    members: Vec<Member>,
    constants: Vec<Constant>,
    pos: Pos,
    base_hash: u64,
    fingerprint: u64,
    min_size: u64,
}

impl StructType {
    /// The package (`a.b`), empty outside any package.
    pub fn package(&self) -> &str {
        &self.package
    }

    /// The struct's own name, without its package.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The full name: `package.name`, or the bare name outside any package.
    pub fn full_name(&self) -> &str {
        &self.full_name
    }

    /// The members in wire order.
    pub fn members(&self) -> &[Member] {
        &self.members
    }

    /// The member called `name`, with its index.
    pub fn member(&self, name: &str) -> Option<(usize, &Member)> {
        self.members
            .iter()
            .enumerate()
            .find(|(_, m)| m.name == name)
    }

    /// The constants in the order written.
    pub fn constants(&self) -> &[Constant] {
        &self.constants
    }

    /// The constant called `name`.
    pub fn constant(&self, name: &str) -> Option<&Constant> {
        self.constants.iter().find(|c| c.name == name)
    }

    /// Where the struct's name is written.
    pub fn pos(&self) -> &Pos {
        &self.pos
    }

    /// The hash of the struct's own declaration (member names, primitive type names, dimensions).
    pub fn base_hash(&self) -> u64 {
        self.base_hash
    }

    /// The fingerprint that starts every encoded message of this type.
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// The fewest bytes a value of this type encodes to, not counting the fingerprint (0 for a
    /// struct with no members, or with only arrays that may be empty); `u64::MAX` when more.
    pub fn min_size(&self) -> u64 {
        self.min_size
    }

    /// Whether `other` declares the same struct: same full name, members and constants, so same
    /// fingerprint (wherever each is written).
    fn same_declaration(&self, other: &StructType) -> bool {
        let members = |s: &StructType| {
            s.members
                .iter()
                .map(|m| (m.name.clone(), m.ty.clone(), m.dims.clone()))
                .collect::<Vec<_>>()
        };
        let constants = |s: &StructType| {
            s.constants
                .iter()
                .map(|c| (c.name.clone(), c.ty, c.text.clone()))
                .collect::<Vec<_>>()
        };
        self.full_name == other.full_name
            && self.base_hash == other.base_hash
            && members(self) == members(other)
            && constants(self) == constants(other)
    }
}

/// The fewest bytes one value of primitive type `p` encodes to.
pub fn primitive_min_size(p: Primitive) -> u64 {
    match p {
        Primitive::Int8 | Primitive::Byte | Primitive::Boolean => 1,
        Primitive::Int16 => 2,
        Primitive::Int32 | Primitive::Float => 4,
        Primitive::Int64 | Primitive::Double => 8,
        // its length, and the terminating NUL
        Primitive::String => 5,
    }
}

/// Structs read from `.lcm` files, not yet resolved.
#[derive(Debug, Clone, Default)]
pub struct TypeSet {
    structs: Vec<StructType>,
    index: HashMap<String, usize>,
}

impl TypeSet {
    /// An empty set.
    pub fn new() -> TypeSet {
        TypeSet::default()
    }

    /// Number of structs read so far.
    pub fn len(&self) -> usize {
        self.structs.len()
    }

    /// True before any struct is read.
    pub fn is_empty(&self) -> bool {
        self.structs.is_empty()
    }

    /// Reads the structs of `text`, the contents of a file called `file`; on an error nothing of it
    /// is added.
    pub fn add_text(&mut self, file: &str, text: &str) -> Result<(), FileError> {
        let parsed = parse(file, text)?;
        self.insert(parsed)
    }

    /// Reads a `.lcm` file, or every `*.lcm` file of a directory (not its subdirectories, in name
    /// order); on an error nothing of them is added.
    pub fn add_path(&mut self, path: &Path) -> Result<(), FileError> {
        let files = if path.is_dir() {
            let entries = std::fs::read_dir(path).map_err(|e| read_error(path, &e))?;
            let mut files = Vec::new();
            for entry in entries {
                let entry = entry.map_err(|e| read_error(path, &e))?;
                let p = entry.path();
                if p.extension().is_some_and(|x| x == "lcm") && p.is_file() {
                    files.push(p);
                }
            }
            files.sort();
            files
        } else {
            vec![path.to_path_buf()]
        };
        let mut parsed = Vec::new();
        for file in files {
            let bytes = std::fs::read(&file).map_err(|e| read_error(&file, &e))?;
            let text = String::from_utf8_lossy(&bytes);
            parsed.extend(parse(&file.display().to_string(), &text)?);
        }
        self.insert(parsed)
    }

    /// Adds `parsed`, refusing all of it when one of its structs is already declared otherwise.
    /// A struct declared again exactly as before (a copy of a file read already) is the same
    /// struct, and is kept once, from its first declaration.
    fn insert(&mut self, parsed: Vec<StructType>) -> Result<(), FileError> {
        let mut new: HashMap<&str, &StructType> = HashMap::new();
        let mut again = vec![false; parsed.len()];
        for (s, again) in parsed.iter().zip(&mut again) {
            let prior = self
                .index
                .get(&s.full_name)
                .and_then(|&i| self.structs.get(i))
                .or_else(|| new.get(s.full_name.as_str()).copied());
            match prior {
                Some(prior) if prior.same_declaration(s) => *again = true,
                Some(prior) => {
                    return Err(s.pos.error(format!(
                        "struct `{}` is declared twice; first at {}",
                        s.full_name, prior.pos
                    )));
                }
                None => {
                    new.insert(&s.full_name, s);
                }
            }
        }
        for (s, again) in parsed.into_iter().zip(again) {
            if !again {
                self.index.insert(s.full_name.clone(), self.structs.len());
                self.structs.push(s);
            }
        }
        Ok(())
    }

    /// Checks that every member's struct type is in the set and that no struct contains itself
    /// other than through a variable-length array, then fingerprints every struct.
    pub fn resolve(self) -> Result<ResolvedTypes, FileError> {
        let TypeSet { mut structs, index } = self;
        // the struct types of each struct's members, in member order: all of them, and those
        // held by value (a single value or in fixed-size arrays only)
        let mut edges: Vec<Vec<usize>> = Vec::with_capacity(structs.len());
        let mut by_value: Vec<Vec<usize>> = Vec::with_capacity(structs.len());
        for s in &structs {
            let mut all = Vec::new();
            let mut fixed = Vec::new();
            for m in &s.members {
                let MemberType::Struct(name) = &m.ty else {
                    continue;
                };
                let Some(&target) = index.get(name) else {
                    return Err(unknown_type(&structs, s, m, name));
                };
                all.push(target);
                if m.dims.iter().all(|d| matches!(d.size, Size::Fixed(_))) {
                    fixed.push(target);
                }
            }
            edges.push(all);
            by_value.push(fixed);
        }
        check_finite(&structs, &by_value)?;
        min_sizes(&mut structs, &index, &by_value);
        let fingerprints = fingerprints(&structs, &edges)?;
        let mut by_fingerprint: HashMap<u64, Vec<usize>> = HashMap::new();
        for (i, (s, fp)) in structs.iter_mut().zip(fingerprints).enumerate() {
            s.fingerprint = fp;
            by_fingerprint.entry(fp).or_default().push(i);
        }
        Ok(ResolvedTypes {
            structs,
            index,
            by_fingerprint,
        })
    }
}

/// Structs whose member types are all known, each with its fingerprint.
#[derive(Debug, Clone)]
pub struct ResolvedTypes {
    structs: Vec<StructType>,
    index: HashMap<String, usize>,
    by_fingerprint: HashMap<u64, Vec<usize>>,
}

impl ResolvedTypes {
    /// Reads and resolves a `.lcm` file or a directory of them.
    pub fn load(path: &Path) -> Result<ResolvedTypes, FileError> {
        let mut set = TypeSet::new();
        set.add_path(path)?;
        set.resolve()
    }

    /// Number of structs.
    pub fn len(&self) -> usize {
        self.structs.len()
    }

    /// True when there is no struct.
    pub fn is_empty(&self) -> bool {
        self.structs.is_empty()
    }

    /// The struct with full name `full_name` (`package.name`, or the bare name outside any package).
    pub fn get(&self, full_name: &str) -> Option<&StructType> {
        self.index.get(full_name).and_then(|&i| self.structs.get(i))
    }

    /// The first struct read with fingerprint `fingerprint`; structs alike in all but their names
    /// share a fingerprint ([`ResolvedTypes::with_fingerprint`] lists them all).
    pub fn by_fingerprint(&self, fingerprint: u64) -> Option<&StructType> {
        self.with_fingerprint(fingerprint).next()
    }

    /// Every struct with fingerprint `fingerprint`, in the order read.
    pub fn with_fingerprint(&self, fingerprint: u64) -> impl Iterator<Item = &StructType> {
        self.by_fingerprint
            .get(&fingerprint)
            .into_iter()
            .flatten()
            .filter_map(|&i| self.structs.get(i))
    }

    /// Every struct, in the order read.
    pub fn iter(&self) -> impl Iterator<Item = &StructType> {
        self.structs.iter()
    }
}

/// The error for a file that cannot be read.
fn read_error(path: &Path, e: &std::io::Error) -> FileError {
    Pos {
        file: Arc::from(path.display().to_string()),
        line: 1,
        col: 1,
    }
    .error(format!("cannot read: {e}"))
}

/// The error for member `m` of `s`, whose type `name` is not in the set.
fn unknown_type(structs: &[StructType], s: &StructType, m: &Member, name: &str) -> FileError {
    let short = name.rsplit('.').next().unwrap_or(name);
    let mut message = format!("unknown type `{name}` of member `{}`", m.name);
    if let Some(other) = structs.iter().find(|o| o.name == short) {
        message.push_str(&format!("; did you mean `{}`?", other.full_name));
    } else if matches!(
        short,
        "int" | "long" | "short" | "char" | "bool" | "uint8_t"
    ) {
        message.push_str(
            "; LCM's primitive types are int8_t, int16_t, int32_t, int64_t, byte, boolean, \
             float, double and string",
        );
    } else if !s.package.is_empty() && name == format!("{}.{short}", s.package) {
        message.push_str(&format!(
            " (a name without a package is looked up in package `{}`)",
            s.package
        ));
    }
    m.type_pos.error(message)
}

/// Refuses a struct that contains itself through members that are single values or fixed-size
/// arrays (`by_value`): it would have no finite encoding.
fn check_finite(structs: &[StructType], by_value: &[Vec<usize>]) -> Result<(), FileError> {
    let component = components(by_value).of;
    for (i, s) in structs.iter().enumerate() {
        let mut targets = by_value.get(i).into_iter().flatten();
        let Some(&target) = targets.find(|&&t| component.get(t) == component.get(i)) else {
            continue;
        };
        let Some(target_name) = structs.get(target).map(|t| t.full_name.as_str()) else {
            continue;
        };
        let member = s.members.iter().find(|m| {
            matches!(&m.ty, MemberType::Struct(n) if n == target_name)
                && m.dims.iter().all(|d| matches!(d.size, Size::Fixed(_)))
        });
        let pos = member.map_or(&s.pos, |m| &m.pos);
        return Err(pos.error(format!(
            "struct `{}` contains itself through `{target_name}` with no variable-length array \
             on the way, so it has no finite encoding",
            s.full_name
        )));
    }
    Ok(())
}

/// Sets every struct's [`StructType::min_size`]. `by_value` has no cycle (checked before), so
/// the structs held by value are done before those holding them.
fn min_sizes(structs: &mut [StructType], index: &HashMap<String, usize>, by_value: &[Vec<usize>]) {
    let order = components(by_value).list;
    for i in order.into_iter().flatten() {
        let Some(s) = structs.get(i) else {
            continue;
        };
        let mut size = 0u64;
        for m in &s.members {
            let one = match &m.ty {
                MemberType::Primitive(p) => primitive_min_size(*p),
                MemberType::Struct(name) => index
                    .get(name)
                    .and_then(|&t| structs.get(t))
                    .map_or(0, StructType::min_size),
            };
            let n = m.dims.iter().fold(one, |n, d| match d.size {
                Size::Fixed(k) => n.saturating_mul(u64::from(k)),
                // it may be empty
                Size::Member(_) => 0,
            });
            size = size.saturating_add(n);
        }
        if let Some(s) = structs.get_mut(i) {
            s.min_size = size;
        }
    }
}

/// The strongly connected components of a graph.
struct Components {
    /// The components, each after the components it reaches.
    list: Vec<Vec<usize>>,
    /// The component of each node: its index in `list`.
    of: Vec<usize>,
}

/// The strongly connected components of the graph whose node `v` has edges `edges[v]` (Tarjan's
/// algorithm, with its own stack so that long chains of types take no deep recursion).
fn components(edges: &[Vec<usize>]) -> Components {
    const UNSEEN: usize = usize::MAX;
    let n = edges.len();
    let mut order = vec![UNSEEN; n];
    let mut low = vec![0; n];
    let mut on_stack = vec![false; n];
    let mut stack: Vec<usize> = Vec::new();
    let mut list = Vec::new();
    let mut of = vec![0; n];
    let mut next = 0;
    // the depth-first path: a node and how many of its edges it has followed
    let mut path: Vec<(usize, usize)> = Vec::new();
    for root in 0..n {
        if order[root] != UNSEEN {
            continue;
        }
        order[root] = next;
        low[root] = next;
        next += 1;
        stack.push(root);
        on_stack[root] = true;
        path.push((root, 0));
        while let Some(&(v, followed)) = path.last() {
            if let Some(&w) = edges[v].get(followed) {
                if let Some(top) = path.last_mut() {
                    top.1 += 1;
                }
                if order[w] == UNSEEN {
                    order[w] = next;
                    low[w] = next;
                    next += 1;
                    stack.push(w);
                    on_stack[w] = true;
                    path.push((w, 0));
                } else if on_stack[w] {
                    low[v] = low[v].min(order[w]);
                }
                continue;
            }
            path.pop();
            if let Some(&(u, _)) = path.last() {
                low[u] = low[u].min(low[v]);
            }
            if low[v] == order[v] {
                let mut component = Vec::new();
                while let Some(w) = stack.pop() {
                    on_stack[w] = false;
                    of[w] = list.len();
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                list.push(component);
            }
        }
    }
    Components { list, of }
}

/// The fingerprint of every struct, as lcm-gen's generated code computes it:
/// `H(T, parents) = 0` when `T` is among `parents`, else `rotl1(base(T) + Σ H(M, parents + T))`
/// over the struct-typed members `M` of `T` (`edges`), in wrapping 64-bit arithmetic.
///
/// `H(T, parents)` depends only on the parents in `T`'s strongly connected component (any other
/// parent is not reachable from `T`), so components are done reached-first and a member outside
/// its struct's component adds that member type's finished fingerprint.
fn fingerprints(structs: &[StructType], edges: &[Vec<usize>]) -> Result<Vec<u64>, FileError> {
    struct Frame {
        t: usize,
        followed: usize,
        sum: u64,
    }
    let n = structs.len();
    let Components {
        list: components,
        of: component,
    } = components(edges);
    let base = |t: usize| structs.get(t).map_or(0, |s| s.base_hash);
    let mut fp = vec![0u64; n];
    let mut in_path = vec![false; n];
    let mut steps: u64 = 0;
    for members in &components {
        for &root in members {
            let c = component.get(root).copied();
            let mut frames = vec![Frame {
                t: root,
                followed: 0,
                sum: base(root),
            }];
            in_path[root] = true;
            while let Some(top) = frames.last_mut() {
                steps += 1;
                if steps > MAX_FINGERPRINT_STEPS {
                    let s = &structs[root];
                    return Err(s.pos.error(format!(
                        "the recursive types reachable from `{}` reach one another in too many \
                         ways to fingerprint (more than {MAX_FINGERPRINT_STEPS} steps)",
                        s.full_name
                    )));
                }
                if let Some(&u) = edges[top.t].get(top.followed) {
                    top.followed += 1;
                    if component.get(u).copied() != c {
                        top.sum = top.sum.wrapping_add(fp.get(u).copied().unwrap_or(0));
                    } else if !in_path[u] {
                        in_path[u] = true;
                        frames.push(Frame {
                            t: u,
                            followed: 0,
                            sum: base(u),
                        });
                    }
                    continue;
                }
                let t = top.t;
                let h = top.sum.rotate_left(1);
                in_path[t] = false;
                frames.pop();
                match frames.last_mut() {
                    Some(parent) => parent.sum = parent.sum.wrapping_add(h),
                    None => fp[root] = h,
                }
            }
        }
    }
    Ok(fp)
}

/// lcm-gen's hash step: shifts in one character, which C reads as signed.
fn hash_update(v: i64, c: i8) -> i64 {
    ((v << 8) ^ (v >> 55)).wrapping_add(i64::from(c))
}

/// lcm-gen's string hash: the length (cut to a signed character), then every byte.
fn hash_string(v: i64, s: &str) -> i64 {
    let mut v = hash_update(v, s.len() as u8 as i8);
    for b in s.bytes() {
        v = hash_update(v, b as i8);
    }
    v
}

/// The hash of a struct's own declaration: per member its name, its type name when primitive, its
/// number of dimensions, and per dimension whether it is variable and its size as written.
fn base_hash(members: &[Member]) -> u64 {
    let mut v: i64 = 0x1234_5678;
    for m in members {
        v = hash_string(v, &m.name);
        if let MemberType::Primitive(p) = &m.ty {
            v = hash_string(v, p.name());
        }
        v = hash_update(v, m.dims.len() as u8 as i8);
        for d in &m.dims {
            v = hash_update(v, i8::from(matches!(d.size, Size::Member(_))));
            v = hash_string(v, &d.text);
        }
    }
    v as u64
}

/// Characters that are tokens on their own.
const SINGLE: &str = "();\",:'[]";
/// Characters that make up operator tokens.
const OPERATORS: &str = "!~<>=&|^%*+";

/// White space as C's `isspace` has it.
fn is_space(c: char) -> bool {
    matches!(c, ' ' | '\t' | '\n' | '\x0b' | '\x0c' | '\r')
}

/// True for a C identifier: a letter or `_`, then letters, digits or `_`.
fn is_ident(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// True for identifiers joined by dots (`a.b.c`).
fn is_dotted(s: &str) -> bool {
    s.split('.').all(is_ident)
}

/// A token and where it starts.
#[derive(Debug, Clone, Copy)]
struct Tok<'a> {
    text: &'a str,
    line: u32,
    col: u32,
}

/// Cuts `.lcm` text into tokens as lcm-gen does, dropping comments.
struct Lexer<'a> {
    file: Arc<str>,
    text: &'a str,
    at: usize,
    line: u32,
    col: u32,
}

impl<'a> Lexer<'a> {
    fn pos(&self, line: u32, col: u32) -> Pos {
        Pos {
            file: self.file.clone(),
            line,
            col,
        }
    }

    fn peek_char(&self) -> Option<char> {
        self.text.get(self.at..).and_then(|s| s.chars().next())
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek_char()?;
        self.at += c.len_utf8();
        if c == '\n' {
            self.line = self.line.saturating_add(1);
            self.col = 1;
        } else {
            self.col = self.col.saturating_add(1);
        }
        Some(c)
    }

    /// The next token, or None at the end of the text.
    fn next(&mut self) -> Result<Option<Tok<'a>>, FileError> {
        loop {
            while self.peek_char().is_some_and(is_space) {
                self.bump();
            }
            let (start, line, col) = (self.at, self.line, self.col);
            let Some(c) = self.bump() else {
                return Ok(None);
            };
            if c == '/' && self.peek_char() == Some('/') {
                while self.peek_char().is_some_and(|c| c != '\n') {
                    self.bump();
                }
                continue;
            }
            if c == '/' && self.peek_char() == Some('*') {
                self.bump();
                let rest = self.text.get(self.at..).unwrap_or("");
                let Some(end) = rest.find("*/") else {
                    return Err(self
                        .pos(line, col)
                        .error("comment `/*` is never closed: expected `*/`"));
                };
                let stop = self.at + end + 2;
                while self.at < stop && self.bump().is_some() {}
                continue;
            }
            if OPERATORS.contains(c) {
                while self.peek_char().is_some_and(|c| OPERATORS.contains(c)) {
                    self.bump();
                }
            } else if c != '/' && !SINGLE.contains(c) {
                while self
                    .peek_char()
                    .is_some_and(|c| !is_space(c) && !SINGLE.contains(c) && !OPERATORS.contains(c))
                {
                    self.bump();
                }
            }
            let text = self.text.get(start..self.at).unwrap_or("");
            return Ok(Some(Tok { text, line, col }));
        }
    }
}

/// `text` for an error message, cut when long.
fn shown(text: &str) -> String {
    const MAX: usize = 40;
    match text.char_indices().nth(MAX) {
        Some((at, _)) => format!("`{}…`", text.get(..at).unwrap_or("")),
        None => format!("`{text}`"),
    }
}

/// Reads the structs of one file.
struct Parser<'a> {
    lex: Lexer<'a>,
    peeked: Option<Tok<'a>>,
    package: String,
}

/// Reads the structs of `text`, the contents of a file called `file`.
fn parse(file: &str, text: &str) -> Result<Vec<StructType>, FileError> {
    let mut p = Parser {
        lex: Lexer {
            file: Arc::from(file),
            text,
            at: 0,
            line: 1,
            col: 1,
        },
        peeked: None,
        package: String::new(),
    };
    let mut structs = Vec::new();
    while let Some(t) = p.next()? {
        match t.text {
            "package" => {
                let name = p.expect("a package name")?;
                if !is_dotted(name.text) {
                    return Err(p.unexpected(
                        name,
                        "a package name (identifiers joined by `.`, such as `nav.msgs`)",
                    ));
                }
                p.require(";")?;
                p.package = name.text.to_string();
            }
            "struct" => structs.push(p.parse_struct()?),
            "enum" => {
                return Err(p.pos(t).error(
                    "enums are not supported (LCM deprecates them): use an integer member and \
                     integer constants",
                ));
            }
            ";" => {
                return Err(p.unexpected(
                    t,
                    "`package` or `struct` (a struct's `}` is not followed by `;`)",
                ));
            }
            _ => return Err(p.unexpected(t, "`package` or `struct`")),
        }
    }
    Ok(structs)
}

impl<'a> Parser<'a> {
    fn pos(&self, t: Tok<'_>) -> Pos {
        self.lex.pos(t.line, t.col)
    }

    fn next(&mut self) -> Result<Option<Tok<'a>>, FileError> {
        match self.peeked.take() {
            Some(t) => Ok(Some(t)),
            None => self.lex.next(),
        }
    }

    fn peek(&mut self) -> Result<Option<Tok<'a>>, FileError> {
        if self.peeked.is_none() {
            self.peeked = self.lex.next()?;
        }
        Ok(self.peeked)
    }

    /// The error for token `t` where `what` was expected.
    fn unexpected(&self, t: Tok<'_>, what: &str) -> FileError {
        let mut message = format!("expected {what}, found {}", shown(t.text));
        if t.text.len() > 1 && (t.text.contains('{') || t.text.contains('}')) {
            message.push_str(" (`{` and `}` need white space around them)");
        }
        self.pos(t).error(message)
    }

    /// The next token, which must exist.
    fn expect(&mut self, what: &str) -> Result<Tok<'a>, FileError> {
        match self.next()? {
            Some(t) => Ok(t),
            None => Err(self
                .lex
                .pos(self.lex.line, self.lex.col)
                .error(format!("expected {what}, found the end of the file"))),
        }
    }

    /// The next token, which must be `text`.
    fn require(&mut self, text: &str) -> Result<Tok<'a>, FileError> {
        let what = format!("`{text}`");
        let t = self.expect(&what)?;
        if t.text == text {
            Ok(t)
        } else {
            Err(self.unexpected(t, &what))
        }
    }

    /// Takes the next token when it is `text`.
    fn take(&mut self, text: &str) -> Result<bool, FileError> {
        if self.peek()?.is_some_and(|t| t.text == text) {
            self.peeked = None;
            return Ok(true);
        }
        Ok(false)
    }

    /// After a member or constant: true when a `,` announces another name, false when a `;` ends
    /// the declaration; `what` names what may stand there, for the error.
    fn another_name(&mut self, what: &str) -> Result<bool, FileError> {
        let t = self.expect("`,` or `;`")?;
        match t.text {
            "," => Ok(true),
            ";" => Ok(false),
            _ => Err(self.unexpected(t, what)),
        }
    }

    /// A struct, after its `struct` keyword.
    fn parse_struct(&mut self) -> Result<StructType, FileError> {
        let name = self.expect("a struct name")?;
        if !is_dotted(name.text) {
            return Err(self.unexpected(
                name,
                "a struct name (a letter or `_`, then letters, digits or `_`)",
            ));
        }
        let (package, short) = match name.text.rsplit_once('.') {
            Some((package, short)) => (package.to_string(), short.to_string()),
            None => (self.package.clone(), name.text.to_string()),
        };
        if Primitive::from_name(&short).is_some() {
            return Err(self
                .pos(name)
                .error(format!("`{short}` is a primitive type, not a struct name")));
        }
        let full_name = if package.is_empty() {
            short.clone()
        } else {
            format!("{package}.{short}")
        };
        self.require("{")?;
        let mut s = StructType {
            package,
            name: short,
            full_name,
            members: Vec::new(),
            constants: Vec::new(),
            pos: self.pos(name),
            base_hash: 0,
            fingerprint: 0,
            min_size: 0,
        };
        loop {
            let Some(t) = self.peek()? else {
                return Err(self.lex.pos(self.lex.line, self.lex.col).error(format!(
                    "expected a member, a constant or `}}` closing struct `{}`, found the end \
                     of the file",
                    s.full_name
                )));
            };
            if t.text == "}" {
                self.peeked = None;
                break;
            }
            self.parse_member(&mut s)?;
        }
        s.base_hash = base_hash(&s.members);
        Ok(s)
    }

    /// A member or constant name, which must be new in `s`.
    fn new_name(&mut self, s: &StructType) -> Result<Tok<'a>, FileError> {
        let t = self.expect("a member name")?;
        if !is_ident(t.text) {
            return Err(self.unexpected(
                t,
                "a member name (a letter or `_`, then letters, digits or `_`)",
            ));
        }
        let prior = s
            .members
            .iter()
            .map(|m| (&m.name, &m.pos))
            .chain(s.constants.iter().map(|c| (&c.name, &c.pos)))
            .find(|(n, _)| n.as_str() == t.text);
        if let Some((_, pos)) = prior {
            return Err(self.pos(t).error(format!(
                "duplicate member name `{}`; first at {pos}",
                t.text
            )));
        }
        Ok(t)
    }

    /// One declaration in a struct: members (`int32_t a, b[4];`) or constants.
    fn parse_member(&mut self, s: &mut StructType) -> Result<(), FileError> {
        let ty = self.expect("a member type")?;
        match ty.text {
            "const" => return self.parse_const(s),
            "struct" | "enum" => {
                return Err(self.pos(ty).error(format!(
                    "a {} cannot be declared inside a struct: declare it on its own and name it",
                    ty.text
                )));
            }
            _ => {}
        }
        if !is_dotted(ty.text) {
            return Err(self.unexpected(ty, "a member type, a constant or `}`"));
        }
        let member_type = match Primitive::from_name(ty.text) {
            Some(p) => MemberType::Primitive(p),
            None if ty.text.contains('.') || self.package.is_empty() => {
                MemberType::Struct(ty.text.to_string())
            }
            None => MemberType::Struct(format!("{}.{}", self.package, ty.text)),
        };
        loop {
            let name = self.new_name(s)?;
            let mut dims = Vec::new();
            while self.take("[")? {
                dims.push(self.parse_dim(s, name)?);
                self.require("]")?;
            }
            s.members.push(Member {
                name: name.text.to_string(),
                ty: member_type.clone(),
                dims,
                pos: self.pos(name),
                type_pos: self.pos(ty),
            });
            if !self.another_name("`[`, `,` or `;`")? {
                return Ok(());
            }
        }
    }

    /// The size of one array dimension of member `name`, after its `[`.
    fn parse_dim(&mut self, s: &StructType, name: Tok<'_>) -> Result<Dim, FileError> {
        const EXPECTED: &str =
            "an array size (a number, an integer constant, or an earlier integer member)";
        let t = self.expect(EXPECTED)?;
        if t.text.starts_with(|c: char| c.is_ascii_digit()) {
            let Some(v) = parse_c_int(t.text) else {
                return Err(self.unexpected(t, EXPECTED));
            };
            let size = self.check_size(t, v, "")?;
            return Ok(Dim {
                size: Size::Fixed(size),
                text: t.text.to_string(),
            });
        }
        if !is_ident(t.text) {
            return Err(self.unexpected(t, EXPECTED));
        }
        if let Some(c) = s.constant(t.text) {
            let ConstValue::Int(v) = c.value else {
                return Err(self.pos(t).error(format!(
                    "array size `{}` is a {} constant; sizes are integers",
                    t.text, c.ty
                )));
            };
            let size = self.check_size(t, i128::from(v), &format!("constant `{}` = ", c.name))?;
            return Ok(Dim {
                size: Size::Fixed(size),
                text: c.text.clone(),
            });
        }
        if t.text == name.text {
            return Err(self.pos(t).error(format!(
                "array `{}` cannot be sized by itself: name an earlier integer member",
                t.text
            )));
        }
        let Some((index, m)) = s.member(t.text) else {
            return Err(self.pos(t).error(format!(
                "unknown array size `{}`: a size names a constant or an integer member declared \
                 earlier in the struct",
                t.text
            )));
        };
        let integer = matches!(m.ty, MemberType::Primitive(p) if p.is_integer());
        if !m.dims.is_empty() || !integer {
            let kind = if m.dims.is_empty() {
                format!("a {}", m.ty)
            } else {
                "an array".to_string()
            };
            return Err(self.pos(t).error(format!(
                "array size `{}` is {kind}; it must be a single int8_t, int16_t, int32_t or \
                 int64_t",
                t.text
            )));
        }
        Ok(Dim {
            size: Size::Member(index),
            text: t.text.to_string(),
        })
    }

    /// A constant array size `v`, which must be from 1 to [`MAX_ARRAY_SIZE`].
    fn check_size(&self, t: Tok<'_>, v: i128, what: &str) -> Result<u32, FileError> {
        match u32::try_from(v) {
            Ok(size) if (1..=MAX_ARRAY_SIZE).contains(&size) => Ok(size),
            _ => Err(self.pos(t).error(format!(
                "array size {what}{v} is out of range: sizes are from 1 to {MAX_ARRAY_SIZE}"
            ))),
        }
    }

    /// Constants (`const int32_t A = 1, B = 2;`), after the `const` keyword.
    fn parse_const(&mut self, s: &mut StructType) -> Result<(), FileError> {
        const TYPES: &str = "a constant type: int8_t, int16_t, int32_t, int64_t, float or double";
        let ty = self.expect(TYPES)?;
        let prim = match Primitive::from_name(ty.text) {
            Some(p) if p.is_integer() || matches!(p, Primitive::Float | Primitive::Double) => p,
            _ => return Err(self.unexpected(ty, TYPES)),
        };
        loop {
            let name = self.new_name(s)?;
            self.require("=")?;
            let v = self.expect("a constant value")?;
            let value = if prim.is_integer() {
                let Some(n) = parse_c_int(v.text) else {
                    return Err(self.unexpected(v, &format!("an integer value for {prim}")));
                };
                let (min, max) = match prim {
                    Primitive::Int8 => (i128::from(i8::MIN), i128::from(i8::MAX)),
                    Primitive::Int16 => (i128::from(i16::MIN), i128::from(i16::MAX)),
                    Primitive::Int32 => (i128::from(i32::MIN), i128::from(i32::MAX)),
                    _ => (i128::from(i64::MIN), i128::from(i64::MAX)),
                };
                match i64::try_from(n) {
                    Ok(n) if (min..=max).contains(&i128::from(n)) => ConstValue::Int(n),
                    _ => {
                        return Err(self.pos(v).error(format!(
                            "`{}` is out of range for {prim} ({min} to {max})",
                            v.text
                        )));
                    }
                }
            } else {
                let Some(x) = parse_c_float(v.text) else {
                    return Err(self.unexpected(v, &format!("a number for {prim}")));
                };
                if !x.is_finite() || (prim == Primitive::Float && x.abs() > f64::from(f32::MAX)) {
                    return Err(self.pos(v).error(format!(
                        "`{}` is out of range for {prim}: constants are finite numbers",
                        v.text
                    )));
                }
                ConstValue::Float(if prim == Primitive::Float {
                    f64::from(x as f32)
                } else {
                    x
                })
            };
            s.constants.push(Constant {
                name: name.text.to_string(),
                ty: prim,
                value,
                text: v.text.to_string(),
                pos: self.pos(name),
            });
            if !self.another_name("`,` or `;`")? {
                return Ok(());
            }
        }
    }
}

/// A whole C integer literal as `strtoll(_, _, 0)` reads one: an optional sign, then `0x` and hex
/// digits, `0` and octal digits, or decimal digits. Values too large for i128 saturate.
fn parse_c_int(s: &str) -> Option<i128> {
    let (negative, digits) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s.strip_prefix('+').unwrap_or(s)),
    };
    let (radix, body) = if let Some(hex) = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        (16, hex)
    } else if digits.len() > 1 {
        match digits.strip_prefix('0') {
            Some(octal) => (8, octal),
            None => (10, digits),
        }
    } else {
        (10, digits)
    };
    if body.is_empty() {
        return None;
    }
    let mut v: i128 = 0;
    for c in body.chars() {
        let d = c.to_digit(radix)?;
        v = v
            .saturating_mul(i128::from(radix))
            .saturating_add(i128::from(d));
    }
    Some(if negative { -v } else { v })
}

/// A whole C floating-point literal in decimal (`1.5`, `-2e-3`, `.5`), or a hex integer.
fn parse_c_float(s: &str) -> Option<f64> {
    let unsigned = s.strip_prefix('-').unwrap_or(s);
    if unsigned.starts_with("0x") || unsigned.starts_with("0X") {
        return parse_c_int(s).map(|v| v as f64);
    }
    // Rust also reads `inf` and `nan`, which are not finite and refused after
    if !unsigned.starts_with(|c: char| c.is_ascii_digit() || c == '.') {
        return None;
    }
    s.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn resolve(files: &[(&str, &str)]) -> Result<ResolvedTypes, FileError> {
        let mut set = TypeSet::new();
        for (file, text) in files {
            set.add_text(file, text)?;
        }
        set.resolve()
    }

    fn one(text: &str) -> ResolvedTypes {
        resolve(&[("t.lcm", text)]).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The error `text` (file `t.lcm`) gets, as printed.
    fn error(text: &str) -> String {
        match resolve(&[("t.lcm", text)]) {
            Ok(_) => panic!("accepted: {text}"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn temperature_vector() {
        let types = one("struct temperature_t { int64_t utime; double deg_celsius; }");
        let t = types.get("temperature_t").expect("temperature_t");
        assert_eq!(t.base_hash(), 0x2a1f28faae9b227b);
        assert_eq!(t.fingerprint(), 0x543e51f55d3644f6);
        assert_eq!(t.package(), "");
        assert_eq!(t.members().len(), 2);
        assert_eq!(
            types
                .by_fingerprint(0x543e51f55d3644f6)
                .map(|s| s.full_name()),
            Some("temperature_t")
        );
    }

    #[test]
    fn nested_vectors() {
        let types = one("package p;\n\
             struct a { int32_t foo; int16_t bar; }\n\
             struct b { int32_t baz; a cross; }\n");
        let a = types.get("p.a").expect("p.a");
        assert_eq!(a.fingerprint(), 0x25d9ba38e29c7a14);
        let b = types.get("p.b").expect("p.b");
        assert_eq!(b.base_hash(), 0x57572d3ae19f2ed0);
        assert_eq!(b.fingerprint(), 0xfa61cee7887751c8);
        assert_eq!(b.members()[1].ty, MemberType::Struct("p.a".into()));
        assert!(types.get("a").is_none());
    }

    #[test]
    fn recursive_vector() {
        let types = one("struct node_t { int32_t num_children; node_t children[num_children]; }");
        let node = types.get("node_t").expect("node_t");
        assert_eq!(node.fingerprint(), 0x31fe946c75d6e4e7);
        assert_eq!(
            node.members()[1].dims,
            [Dim {
                size: Size::Member(0),
                text: "num_children".into()
            }]
        );
    }

    #[test]
    fn a_type_used_twice_counts_twice() {
        let types = one("struct a { int32_t x; }\nstruct b { a one; a two; }\nstruct c { a one; }");
        let a = types.get("a").expect("a").fingerprint();
        let b = types.get("b").expect("b");
        let c = types.get("c").expect("c");
        assert_eq!(
            b.fingerprint(),
            b.base_hash().wrapping_add(a).wrapping_add(a).rotate_left(1)
        );
        assert_eq!(
            c.fingerprint(),
            c.base_hash().wrapping_add(a).rotate_left(1)
        );
    }

    #[test]
    fn mutual_recursion_counts_each_path() {
        // H(x) = rotl(bx + H(y, {x})), H(y, {x}) = rotl(by + 0)
        let types = one("struct x { int32_t n; y ys[n]; }\nstruct y { int32_t n; x xs[n]; }");
        let (x, y) = (types.get("x").expect("x"), types.get("y").expect("y"));
        let inner = y.base_hash().rotate_left(1);
        assert_eq!(
            x.fingerprint(),
            x.base_hash().wrapping_add(inner).rotate_left(1)
        );
        let inner = x.base_hash().rotate_left(1);
        assert_eq!(
            y.fingerprint(),
            y.base_hash().wrapping_add(inner).rotate_left(1)
        );
    }

    #[test]
    fn hash_sign_extends_and_cuts_lengths() {
        // a 200-character name hashes its length as the signed character -56
        let name = "n".repeat(200);
        let mut v = hash_update(0x1234_5678, -56);
        for _ in 0..200 {
            v = hash_update(v, b'n' as i8);
        }
        assert_eq!(hash_string(0x1234_5678, &name), v);
        assert_eq!(hash_update(0, b'\xe9' as i8), -23);
        assert_eq!(hash_update(-1, 0), (-1i64 << 8) ^ -1);
    }

    #[test]
    fn model_of_members_constants_and_dims() {
        let types = one("package nav.msgs; // a comment\n\
             /* a block\n comment */ struct pose_t {\n\
               const int32_t A = 1, B = -0x10;\n\
               const double D = 2.5e-3;\n\
               const float F = 1.5;\n\
               const int8_t N = 3;\n\
               int64_t utime;\n\
               int16_t n, m;\n\
               double grid[n][4][m], fixed[N];\n\
               string name; boolean ok; byte raw[010]; float f;\n\
               nav.msgs.pose_t more[n];\n\
             }\n");
        let p = types.get("nav.msgs.pose_t").expect("pose_t");
        assert_eq!((p.package(), p.name()), ("nav.msgs", "pose_t"));
        let names: Vec<_> = p.members().iter().map(|m| m.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "utime", "n", "m", "grid", "fixed", "name", "ok", "raw", "f", "more"
            ]
        );
        let grid = &p.members()[3];
        let sizes: Vec<_> = grid.dims.iter().map(|d| d.size).collect();
        assert_eq!(sizes, [Size::Member(1), Size::Fixed(4), Size::Member(2)]);
        assert_eq!(grid.ty, MemberType::Primitive(Primitive::Double));
        assert_eq!(
            p.members()[4].dims,
            [Dim {
                size: Size::Fixed(3),
                text: "3".into()
            }]
        );
        assert_eq!(p.members()[7].dims[0].size, Size::Fixed(8));
        assert_eq!(p.members()[7].dims[0].text, "010");
        assert_eq!(
            p.members()[9].ty,
            MemberType::Struct("nav.msgs.pose_t".into())
        );
        let consts: Vec<_> = p
            .constants()
            .iter()
            .map(|c| (c.name.as_str(), c.ty, c.value))
            .collect();
        assert_eq!(
            consts,
            [
                ("A", Primitive::Int32, ConstValue::Int(1)),
                ("B", Primitive::Int32, ConstValue::Int(-16)),
                ("D", Primitive::Double, ConstValue::Float(2.5e-3)),
                ("F", Primitive::Float, ConstValue::Float(1.5)),
                ("N", Primitive::Int8, ConstValue::Int(3)),
            ]
        );
        assert_eq!(p.constant("B").map(|c| c.text.as_str()), Some("-0x10"));
        assert_eq!(p.pos().to_string(), "t.lcm:3:20");
        assert_eq!(p.members()[1].pos.to_string(), "t.lcm:9:9");
        assert_eq!(p.members()[1].type_pos.to_string(), "t.lcm:9:1");
    }

    #[test]
    fn qualified_struct_names_and_packages_per_file() {
        let types = resolve(&[
            (
                "one.lcm",
                "package p; struct a { int32_t x; } struct q.b { a y; }",
            ),
            ("two.lcm", "struct c { p.a z; }"),
        ])
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(types.get("q.b").is_some() && types.get("c").is_some());
        // `a` in `q.b` is looked up in the package in effect, p
        assert_eq!(
            types.get("q.b").expect("q.b").members()[0].ty,
            MemberType::Struct("p.a".into())
        );
        let names: Vec<_> = types.iter().map(|s| s.full_name()).collect();
        assert_eq!(names, ["p.a", "q.b", "c"]);
    }

    #[test]
    fn same_layout_shares_a_fingerprint() {
        let types = one("struct a { int32_t x; }\nstruct b { int32_t x; }");
        let fp = types.get("a").expect("a").fingerprint();
        assert_eq!(types.get("b").expect("b").fingerprint(), fp);
        let all: Vec<_> = types.with_fingerprint(fp).map(|s| s.full_name()).collect();
        assert_eq!(all, ["a", "b"]);
        assert_eq!(types.by_fingerprint(fp).map(|s| s.name()), Some("a"));
        assert!(types.by_fingerprint(fp ^ 1).is_none());
    }

    #[test]
    fn parse_errors_name_file_line_and_column() {
        let cases = [
            (
                "struct a{ int32_t x; }",
                "t.lcm:1:8: expected a struct name",
            ),
            (
                "struct a { int32_t x; };",
                "t.lcm:1:24: expected `package` or `struct` (a struct's `}` is not followed by `;`), found `;`",
            ),
            (
                "struct a {\n  int32_t x\n}",
                "t.lcm:3:1: expected `[`, `,` or `;`, found `}`",
            ),
            (
                "struct a {\n  int32_t x;\n",
                "t.lcm:3:1: expected a member, a constant or `}` closing struct `a`, found the end of the file",
            ),
            (
                "struct a { int32_t x; int8_t x; }",
                "t.lcm:1:30: duplicate member name `x`; first at t.lcm:1:20",
            ),
            (
                "struct a { const int8_t x = 1; int8_t x; }",
                "t.lcm:1:39: duplicate member name `x`; first at t.lcm:1:25",
            ),
            (
                "struct a { int32_t v[n]; }",
                "t.lcm:1:22: unknown array size `n`: a size names a constant or an integer member declared earlier in the struct",
            ),
            (
                "struct a { int32_t v[n]; int32_t n; }",
                "t.lcm:1:22: unknown array size `n`",
            ),
            (
                "struct a { double n; int32_t v[n]; }",
                "t.lcm:1:32: array size `n` is a double; it must be a single int8_t, int16_t, int32_t or int64_t",
            ),
            (
                "struct a { byte n; int32_t v[n]; }",
                "t.lcm:1:30: array size `n` is a byte",
            ),
            (
                "struct a { int8_t n[2]; int32_t v[n]; }",
                "t.lcm:1:35: array size `n` is an array",
            ),
            (
                "struct a { int32_t v[v]; }",
                "t.lcm:1:22: array `v` cannot be sized by itself",
            ),
            (
                "struct a { int32_t v[0]; }",
                "t.lcm:1:22: array size 0 is out of range",
            ),
            (
                "struct a { int32_t v[10abc]; }",
                "t.lcm:1:22: expected an array size",
            ),
            (
                "struct a { int32_t v[]; }",
                "t.lcm:1:22: expected an array size (a number, an integer constant, or an earlier integer member), found `]`",
            ),
            (
                "struct a { const double D = 2; int32_t v[D]; }",
                "t.lcm:1:42: array size `D` is a double constant",
            ),
            (
                "struct a { const int32_t N = -1; int32_t v[N]; }",
                "t.lcm:1:44: array size constant `N` = -1 is out of range",
            ),
            (
                "struct a { const int8_t A = 128; }",
                "t.lcm:1:29: `128` is out of range for int8_t (-128 to 127)",
            ),
            (
                "struct a { const int16_t A = 0x8000; }",
                "t.lcm:1:30: `0x8000` is out of range for int16_t",
            ),
            (
                "struct a { const int32_t A = 1.5; }",
                "t.lcm:1:30: expected an integer value for int32_t, found `1.5`",
            ),
            (
                "struct a { const int64_t A = 9223372036854775808; }",
                "t.lcm:1:30: `9223372036854775808` is out of range for int64_t",
            ),
            (
                "struct a { const float F = 1e39; }",
                "t.lcm:1:28: `1e39` is out of range for float",
            ),
            (
                "struct a { const double D = 1e+3; }",
                "t.lcm:1:29: expected a number for double, found `1e`",
            ),
            (
                "struct a { const double D = nan; }",
                "t.lcm:1:29: expected a number for double, found `nan`",
            ),
            (
                "struct a { const byte B = 1; }",
                "t.lcm:1:18: expected a constant type: int8_t, int16_t, int32_t, int64_t, float or double, found `byte`",
            ),
            (
                "struct a { const int32_t A 1; }",
                "t.lcm:1:28: expected `=`, found `1`",
            ),
            (
                "struct a { int32_t x$y; }",
                "t.lcm:1:20: expected a member name (a letter or `_`, then letters, digits or `_`), found `x$y`",
            ),
            (
                "struct a { 9x y; }",
                "t.lcm:1:12: expected a member type, a constant or `}`, found `9x`",
            ),
            (
                "struct a { struct b { } }",
                "t.lcm:1:12: a struct cannot be declared inside a struct",
            ),
            ("enum e { A = 1 }", "t.lcm:1:1: enums are not supported"),
            ("package 1a;", "t.lcm:1:9: expected a package name"),
            (
                "package a.b",
                "t.lcm:1:12: expected `;`, found the end of the file",
            ),
            (
                "struct int32_t { }",
                "t.lcm:1:8: `int32_t` is a primitive type, not a struct name",
            ),
            (
                "int32_t x;",
                "t.lcm:1:1: expected `package` or `struct`, found `int32_t`",
            ),
            (
                "struct a { int32_t x; } /* open",
                "t.lcm:1:25: comment `/*` is never closed",
            ),
            (
                "struct a { int32_t x; }\n\nstruct a { }",
                "t.lcm:3:8: struct `a` is declared twice; first at t.lcm:1:8",
            ),
            ("struct a { int32_t x /* c */ [ /* c */ 2 ] // c\n ; }", ""),
            (
                "struct a {\r\n\tint32_t x;\r\n\tb y;\r\n}",
                "t.lcm:3:2: unknown type `b` of member `y`",
            ),
            (
                "package p; struct a { int y; }",
                "t.lcm:1:23: unknown type `p.int` of member `y`; LCM's primitive types are",
            ),
            (
                "package p; struct a { b y; }",
                "t.lcm:1:23: unknown type `p.b` of member `y` (a name without a package is looked up in package `p`)",
            ),
            (
                "package p; struct a { q.a y; } struct b { a x; }",
                "t.lcm:1:23: unknown type `q.a` of member `y`; did you mean `p.a`?",
            ),
            (
                "struct a { int32_t é; }",
                "t.lcm:1:20: expected a member name",
            ),
            (
                "struct a { b x[2]; }\nstruct b { int32_t n; a y; }",
                "t.lcm:1:14: struct `a` contains itself through `b` with no variable-length array on the way",
            ),
            (
                "struct a { a x; }",
                "t.lcm:1:14: struct `a` contains itself through `a`",
            ),
        ];
        for (text, want) in cases {
            let got = resolve(&[("t.lcm", text)]);
            match (got, want) {
                (Ok(_), "") => {}
                (Ok(_), _) => panic!("{text:?} accepted, wanted {want:?}"),
                (Err(e), _) => {
                    let e = e.to_string();
                    assert!(
                        !want.is_empty() && e.starts_with(want),
                        "{text:?}: got {e:?}, wanted {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_struct_declared_again_identically_is_the_same_struct() {
        let text = "package p;\nstruct a { int32_t n; double v[n]; const int8_t K = 3; }\n\
                    struct b { a x[2]; }";
        let mut set = TypeSet::new();
        set.add_text("one.lcm", text)
            .unwrap_or_else(|e| panic!("{e}"));
        // a copy, laid out otherwise: accepted, kept once
        set.add_text(
            "copy.lcm",
            &format!("// a copy\n\n{}", text.replace("; ", ";\n  ")),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(set.len(), 2);
        let t = set.clone().resolve().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            t.get("p.a").map(|a| a.pos().file.to_string()),
            Some("one.lcm".into())
        );
        // the same name declared otherwise is an error: another member, a constant's value
        for other in [
            "package p; struct a { int32_t n; float v[n]; const int8_t K = 3; }",
            "package p; struct a { int32_t n; double v[n]; const int8_t K = 4; }",
            "package p; struct a { int32_t n; double v[n]; }",
        ] {
            let e = set.clone().add_text("other.lcm", other).unwrap_err();
            assert!(
                e.to_string()
                    .contains("struct `p.a` is declared twice; first at one.lcm:2:8"),
                "{other}: {e}"
            );
        }
        // and twice in one file, identically, too
        let mut set = TypeSet::new();
        set.add_text("t.lcm", "struct c { int8_t x; }\nstruct c { int8_t x; }")
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(set.len(), 1);
    }

    #[test]
    fn min_sizes_count_what_every_value_must_send() {
        let t = resolve(&[(
            "t.lcm",
            "struct e { }\n\
             struct z { e a[3]; int32_t n; }\n\
             struct s { string s; boolean b; e e; int16_t k[2][3]; z z[2]; }\n\
             struct node { int32_t n; node c[n]; int8_t m[n][4]; }\n\
             struct w { s x[2]; int32_t m; byte b[m]; }",
        )])
        .unwrap_or_else(|e| panic!("{e}"));
        let size = |n: &str| t.get(n).map(StructType::min_size);
        assert_eq!(size("e"), Some(0));
        assert_eq!(size("z"), Some(4));
        assert_eq!(size("s"), Some(5 + 1 + 12 + 8));
        assert_eq!(size("node"), Some(4));
        assert_eq!(size("w"), Some(2 * 26 + 4));
    }

    #[test]
    fn a_failed_file_adds_nothing() {
        let mut set = TypeSet::new();
        set.add_text("one.lcm", "struct a { int32_t x; }")
            .unwrap_or_else(|e| panic!("{e}"));
        let e = set
            .add_text("two.lcm", "struct b { int32_t x; }\nstruct a { }")
            .map(|_| ())
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "two.lcm:2:8: struct `a` is declared twice; first at one.lcm:1:8"
        );
        assert_eq!(set.len(), 1);
        let e = set
            .add_text("three.lcm", "struct c { int32_t x; } struct d {")
            .unwrap_err();
        assert_eq!(e.pos.line, 1);
        assert_eq!(set.len(), 1);
        let types = set.resolve().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(types.len(), 1);
    }

    #[test]
    fn reads_files_and_directories() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let write = |name: &str, text: &str| {
            std::fs::write(dir.path().join(name), text).expect("a written file");
        };
        write("b.lcm", "package p;\nstruct b { a x; }\n");
        write(
            "a.lcm",
            "package p;\nstruct a { int32_t foo; int16_t bar; }\n",
        );
        write("notes.txt", "not lcm");
        let types = ResolvedTypes::load(dir.path()).unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<_> = types.iter().map(|s| s.full_name()).collect();
        assert_eq!(names, ["p.a", "p.b"]);
        assert_eq!(
            types.get("p.a").map(|s| s.fingerprint()),
            Some(0x25d9ba38e29c7a14)
        );
        let mut set = TypeSet::new();
        set.add_path(&dir.path().join("a.lcm"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(set.len(), 1);
        write("c.lcm", "struct c {\n  int32_t x; x\n}\n");
        let e = ResolvedTypes::load(dir.path()).unwrap_err();
        let file = dir.path().join("c.lcm").display().to_string();
        assert_eq!(
            e.to_string(),
            format!(
                "{file}:3:1: expected a member name (a letter or `_`, then letters, digits or \
                 `_`), found `}}`"
            )
        );
        let e = ResolvedTypes::load(&dir.path().join("missing.lcm")).unwrap_err();
        assert!(e.message.starts_with("cannot read"), "{e}");
    }

    #[test]
    fn tangled_recursion_is_refused_not_endless() {
        // 12 structs, each holding variable arrays of all of them: 12! paths
        let n = 12;
        let mut text = String::new();
        for i in 0..n {
            text.push_str(&format!("struct s{i} {{ int32_t n;"));
            for j in 0..n {
                text.push_str(&format!(" s{j} m{j}[n];"));
            }
            text.push_str(" }\n");
        }
        let e = error(&text);
        assert!(e.contains("too many ways to fingerprint"), "{e}");
    }

    #[test]
    fn long_chains_do_not_overflow_the_stack() {
        let n = 20_000;
        let mut text = String::from("struct s0 { int32_t x; }\n");
        for i in 1..n {
            text.push_str(&format!("struct s{i} {{ s{} x; }}\n", i - 1));
        }
        let types = one(&text);
        assert_eq!(types.len(), n);
        // a chain of single members: H(s_i) = rotl(base_i + H(s_{i-1}))
        let mut h = types.get("s0").expect("s0").fingerprint();
        for i in 1..n {
            let s = types.get(&format!("s{i}")).expect("a struct");
            h = s.base_hash().wrapping_add(h).rotate_left(1);
            assert_eq!(s.fingerprint(), h);
        }
    }

    #[test]
    fn c_integer_literals() {
        assert_eq!(parse_c_int("0"), Some(0));
        assert_eq!(parse_c_int("010"), Some(8));
        assert_eq!(parse_c_int("0x1F"), Some(31));
        assert_eq!(parse_c_int("-0X10"), Some(-16));
        assert_eq!(parse_c_int("08"), None);
        assert_eq!(parse_c_int("0x"), None);
        assert_eq!(parse_c_int("-"), None);
        assert_eq!(parse_c_int("1_000"), None);
        assert_eq!(parse_c_float("-.5e2"), Some(-50.0));
        assert_eq!(parse_c_float("0x10"), Some(16.0));
        assert_eq!(parse_c_float("inf"), None);
        assert_eq!(parse_c_float("1.5f"), None);
    }
}
