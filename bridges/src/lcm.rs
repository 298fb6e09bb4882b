//! LCM types on bridge routes: `<route … lcm="seabus.position_t"/>` between an LCM medium
//! (`udpm://`) and any other.
//!
//! A route leading to the LCM medium encodes each message's datamap (after field renames) as the
//! type; one leading from it decodes the LCM bytes as the type, after checking their fingerprint,
//! and hands on a datamap. The types are the built-in ones for the standard datasets
//! (`configs/lcm/seabus.lcm`, package `seabus`) and those of the `.lcm` files or directories the
//! bridge's `lcm_types` parameter lists (space-separated, relative to the system file). A type with
//! an `int64_t utime` member gets the message's stamp there (microseconds) when the map has none.

use crate::route::Problem;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{Capabilities, DataMap, Payload, Stamp, Value};
use seabus_medium_lcm::codec::{self, CodecError};
pub use seabus_medium_lcm::types::ResolvedTypes;
use seabus_medium_lcm::types::{MemberType, Primitive, StructType, TypeSet};
use seabus_modules::system::{BridgeSpec, RouteSpec};
use std::path::PathBuf;
use std::sync::Arc;

/// The LCM types of the standard datasets, built in.
pub const BUILT_IN: &str = include_str!("../../configs/lcm/seabus.lcm");
/// The name the built-in types' file is known by in messages.
pub const BUILT_IN_FILE: &str = "configs/lcm/seabus.lcm";

/// True when `ty` has an `int64_t utime` member holding a single value: the member filled with a
/// message's stamp (microseconds since the epoch) when the map has none.
pub fn has_utime(ty: &StructType) -> bool {
    ty.member("utime")
        .is_some_and(|(_, m)| m.dims.is_empty() && m.ty == MemberType::Primitive(Primitive::Int64))
}

/// The built-in LCM types and those of `paths` (`.lcm` files, or directories of them). A struct
/// declared again exactly as before, as in a copy of the built-in file, is the same struct.
pub fn types_with(paths: &[PathBuf]) -> Result<ResolvedTypes, FileError> {
    let mut set = TypeSet::new();
    set.add_text(BUILT_IN_FILE, BUILT_IN)?;
    for path in paths {
        set.add_path(path)?;
    }
    set.resolve()
}

/// The names of `types`, sorted, for a message listing what there is.
pub fn known_types(types: &ResolvedTypes) -> String {
    let mut known: Vec<&str> = types.iter().map(|t| t.full_name()).collect();
    known.sort_unstable();
    known.join(", ")
}

/// The LCM types a bridge can use: the built-in ones and those its `lcm_types` parameter names.
pub fn load(spec: &BridgeSpec) -> Result<Arc<ResolvedTypes>, FileError> {
    let mut paths = Vec::new();
    if let Some(p) = spec.params.get("lcm_types") {
        for item in p.value.split_whitespace() {
            let path = seabus_modules::system::beside(&spec.pos, item);
            if !path.exists() {
                return Err(p.pos.error(format!(
                    "parameter `lcm_types`: `{}` does not exist",
                    path.display()
                )));
            }
            paths.push(path);
        }
    }
    types_with(&paths).map(Arc::new)
}

/// Decodes a payload that is an LCM message of a type in `types` (found by its fingerprint):
/// the type and the datamap, or `None` when it is not one.
pub fn recognise<'t>(types: &'t ResolvedTypes, payload: &Payload) -> Option<(&'t str, DataMap)> {
    let bytes = payload.as_bytes()?;
    let fingerprint = u64::from_be_bytes(bytes.get(..8)?.try_into().ok()?);
    let ty = types.by_fingerprint(fingerprint)?;
    let (map, _) = codec::decode(types, ty, bytes).ok()?;
    Some((ty.full_name(), map))
}

/// What a route does with LCM: decode on the way in, encode on the way out, or both.
#[derive(Debug, Clone)]
pub struct Mapping {
    /// The type's full name.
    pub ty: String,
    /// Messages come from an LCM medium and are decoded.
    pub decode: bool,
    /// Messages go to an LCM medium and are encoded.
    pub encode: bool,
    /// The type has an `int64_t utime` member, filled from the stamp when missing.
    utime: bool,
}

impl Mapping {
    /// Compiles a route's `lcm` attribute for the leg from medium `from` to medium `to` (0 or 1).
    pub fn new(
        spec: &BridgeSpec,
        caps: &[Capabilities; 2],
        route: &RouteSpec,
        types: &ResolvedTypes,
        from: usize,
        to: usize,
    ) -> Result<Option<Mapping>, FileError> {
        let Some(name) = &route.lcm else {
            return Ok(None);
        };
        let Some(ty) = types.get(name) else {
            return Err(route.pos.error(format!(
                "unknown LCM type `{name}`; known types: {} (more with the bridge's `lcm_types`)",
                known_types(types)
            )));
        };
        let (decode, encode) = (caps[from].is_native("lcm"), caps[to].is_native("lcm"));
        if !decode && !encode {
            return Err(route.pos.error(format!(
                "`lcm=\"{name}\"` needs an LCM medium (udpm://) on one side of the bridge; \
                 `{}` and `{}` are not",
                spec.media[0], spec.media[1]
            )));
        }
        Ok(Some(Mapping {
            ty: name.clone(),
            decode,
            encode,
            utime: has_utime(ty),
        }))
    }

    /// Whether messages come from an LCM medium and are decoded.
    pub fn decodes(&self) -> bool {
        self.decode
    }

    /// Whether messages go to an LCM medium and are encoded.
    pub fn encodes(&self) -> bool {
        self.encode
    }

    /// Decodes LCM bytes read on `channel` into a datamap. What liblcm reads leniently
    /// ([`codec::Leniency`]) is read too, and counted in `tally` by case (logged as `source`).
    pub fn decode(
        &self,
        types: &ResolvedTypes,
        channel: &str,
        payload: &Payload,
        tally: &Tally,
        source: &str,
    ) -> Result<DataMap, Problem> {
        let Some(ty) = types.get(&self.ty) else {
            return Err(Problem::new("lcm-type", format!("no LCM type {}", self.ty)));
        };
        let Some(bytes) = payload.as_bytes() else {
            return Err(Problem::new(
                "lcm-decode",
                format!(
                    "channel `{channel}`: a {} payload is not an LCM message",
                    payload.format().name()
                ),
            ));
        };
        let (map, lenient) =
            codec::decode(types, ty, bytes).map_err(|e| codec_problem(channel, e))?;
        for (reason, what) in lenient.cases() {
            tally.record(source, reason, format_args!("channel `{channel}`: {what}"));
        }
        Ok(map)
    }

    /// Encodes a datamap as this type, for `channel`; `stamp` fills a missing `utime`.
    pub fn encode(
        &self,
        types: &ResolvedTypes,
        channel: &str,
        map: &DataMap,
        stamp: Stamp,
    ) -> Result<Payload, Problem> {
        let Some(ty) = types.get(&self.ty) else {
            return Err(Problem::new("lcm-type", format!("no LCM type {}", self.ty)));
        };
        let bytes = if self.utime && map.get("utime").is_none() {
            let mut with = map.clone();
            with.insert("utime", Value::Int(stamp.0 / 1_000));
            codec::encode(types, ty, &with)
        } else {
            codec::encode(types, ty, map)
        }
        .map_err(|e| codec_problem(channel, e))?;
        Ok(Payload::from(bytes))
    }
}

/// A codec error on `channel` as a problem, counted by reason.
fn codec_problem(channel: &str, e: CodecError) -> Problem {
    let reason = match e {
        CodecError::Fingerprint { .. } => "lcm-type-mismatch",
        _ => "lcm-codec",
    };
    Problem::new(reason, format!("channel `{channel}`: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A directory of its own under the system's temporary directory, removed when dropped.
    struct Dir(PathBuf);

    impl Dir {
        fn new(name: &str) -> Dir {
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos());
            let path =
                std::env::temp_dir().join(format!("seabus-{name}-{}-{nanos}", std::process::id()));
            std::fs::create_dir_all(&path).unwrap();
            Dir(path)
        }
    }

    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn a_copy_of_the_built_in_types_among_ones_own_is_accepted() {
        let dir = Dir::new("lcm-types");
        std::fs::write(dir.0.join("seabus.lcm"), BUILT_IN).unwrap();
        std::fs::write(
            dir.0.join("lab.lcm"),
            "package lab; struct probe_t { int64_t utime; seabus.depth_t depth; }",
        )
        .unwrap();
        let types = types_with(std::slice::from_ref(&dir.0)).unwrap_or_else(|e| panic!("{e}"));
        let built_in = types_with(&[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(types.len(), built_in.len() + 1);
        assert!(types.get("lab.probe_t").is_some());
        // the same name declared otherwise is still an error
        std::fs::write(
            dir.0.join("seabus.lcm"),
            BUILT_IN.replacen("double depth;", "float depth;", 1),
        )
        .unwrap();
        let e = types_with(std::slice::from_ref(&dir.0))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "struct `seabus.depth_t` is declared twice; first at configs/lcm/seabus.lcm"
            ),
            "{e}"
        );
    }

    #[test]
    fn only_a_single_int64_utime_is_stamped() {
        let mut set = TypeSet::new();
        set.add_text(
            "t.lcm",
            "struct s_t { int64_t utime; }\n\
             struct d_t { double utime; }\n\
             struct a_t { int64_t utime[2]; }\n\
             struct n_t { int64_t time; }",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let types = set.resolve().unwrap_or_else(|e| panic!("{e}"));
        let stamped: Vec<bool> = ["s_t", "d_t", "a_t", "n_t"]
            .iter()
            .map(|n| types.get(n).is_some_and(has_utime))
            .collect();
        assert_eq!(stamped, [true, false, false, false]);
    }
}
