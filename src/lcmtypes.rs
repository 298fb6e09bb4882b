//! LCM types for `seabus spy` (messages of a known type shown decoded), `seabus pub --lcm` (an
//! LCM message made from fields, stamped as it is sent), and `seabus convert` and `replay` (an
//! MCAP message decoded from an LCM type encoded with it again). Without the `lcm` feature no type is
//! known: spy shows bytes, and `--lcm` or `--lcm-types` is refused with the reason.

use seabus_medium::{DataMap, Payload, Stamp};
use std::path::PathBuf;

#[cfg(feature = "lcm")]
mod imp {
    use super::*;
    use seabus_medium::Value;
    use seabus_medium_lcm::codec::RAW_SUFFIX;
    use seabus_medium_lcm::types::{MemberType, ResolvedTypes, Size, StructType};

    /// The LCM types known: the built-in ones and those of `--lcm-types`.
    pub struct Types(pub ResolvedTypes);

    /// The built-in types and those of the `.lcm` files or directories `paths`.
    pub fn load(paths: &[PathBuf]) -> Result<Types, String> {
        seabus_bridges::lcm::types_with(paths)
            .map(Types)
            .map_err(|e| format!("--lcm-types: {e}"))
    }

    impl Types {
        /// The type's name and the decoded message, when `payload` is an LCM message of a known
        /// type.
        pub fn recognise<'t>(&'t self, payload: &Payload) -> Option<(&'t str, DataMap)> {
            seabus_bridges::lcm::recognise(&self.0, payload)
        }

        /// `map` (a message decoded from type `name`) encoded as an LCM message of that type
        /// again.
        pub fn encode(&self, name: &str, map: &DataMap) -> Result<Payload, String> {
            let Some(ty) = self.0.get(name) else {
                return Err(format!(
                    "LCM type {name} is not known (--lcm-types names the .lcm file that has it)"
                ));
            };
            seabus_medium_lcm::codec::encode(&self.0, ty, map)
                .map(Payload::from)
                .map_err(|e| format!("LCM type {name}: {e}"))
        }
    }

    /// Checks the fields of `map` against struct `ty` (found at `path`, empty at the top), and
    /// those of the maps in it against the structs of its members.
    fn check_fields(
        types: &ResolvedTypes,
        ty: &StructType,
        map: &DataMap,
        path: &str,
        allow_missing: bool,
    ) -> Result<(), String> {
        let members = ty.members();
        let listed = || {
            let names: Vec<&str> = members.iter().map(|m| m.name.as_str()).collect();
            format!("{} has {}", ty.full_name(), names.join(", "))
        };
        let at = |key: &str| {
            if path.is_empty() {
                key.to_string()
            } else {
                format!("{path}.{key}")
            }
        };
        for (key, _) in map.iter() {
            let member = key.strip_suffix(RAW_SUFFIX).unwrap_or(key);
            if !members.iter().any(|m| m.name == member) {
                return Err(format!("no field `{}`: {}", at(key), listed()));
            }
        }
        // members that size arrays, and the one stamped as sent
        let sizes: Vec<usize> = members
            .iter()
            .flat_map(|m| m.dims.iter())
            .filter_map(|d| match d.size {
                Size::Member(j) => Some(j),
                Size::Fixed(_) => None,
            })
            .collect();
        let stamped = path.is_empty() && seabus_bridges::lcm::has_utime(ty);
        for (j, m) in members.iter().enumerate() {
            let value = map.get(&m.name);
            if value.is_none() {
                if allow_missing || sizes.contains(&j) || (stamped && m.name == "utime") {
                    continue;
                }
                return Err(format!(
                    "field `{}` missing (--allow-missing sends defaults): {}",
                    at(&m.name),
                    listed()
                ));
            }
            let MemberType::Struct(inner) = &m.ty else {
                continue;
            };
            let Some(inner) = types.get(inner) else {
                continue;
            };
            // the struct's maps, inside as many lists as the member has dimensions
            let mut level = vec![(at(&m.name), value)];
            for _ in &m.dims {
                level = level
                    .into_iter()
                    .flat_map(|(p, v)| match v.and_then(Value::as_list) {
                        Some(items) => items
                            .iter()
                            .enumerate()
                            .map(|(i, item)| (format!("{p}[{i}]"), Some(item)))
                            .collect(),
                        None => Vec::new(),
                    })
                    .collect();
            }
            for (p, v) in level {
                if let Some(Value::Map(inner_map)) = v {
                    check_fields(types, inner, inner_map, &p, allow_missing)?;
                }
            }
        }
        Ok(())
    }

    /// An LCM message of one type, made anew from the same fields each time it is sent.
    pub struct LcmMessage {
        types: ResolvedTypes,
        name: String,
        map: DataMap,
    }

    impl LcmMessage {
        /// The message of type `name` made from `map`, with the types of `paths` besides the
        /// built-in ones; checked by making it once. Every field must be a member of the type
        /// (of its nested structs, in nested maps), and every member must be given but for
        /// `utime` (stamped as sent) and the sizes of arrays (their lengths), unless
        /// `allow_missing` (then they take their defaults).
        pub fn new(
            name: &str,
            paths: &[PathBuf],
            map: &DataMap,
            allow_missing: bool,
        ) -> Result<LcmMessage, String> {
            let Types(types) = load(paths)?;
            let Some(ty) = types.get(name) else {
                return Err(format!(
                    "--lcm {name}: no such LCM type; known types: {}",
                    seabus_bridges::lcm::known_types(&types)
                ));
            };
            check_fields(&types, ty, map, "", allow_missing)
                .map_err(|e| format!("--lcm {name}: {e}"))?;
            LcmMessage::of(types, name, map)
        }

        /// The message of type `name` (one of `types`) made from `map`.
        pub fn of(types: ResolvedTypes, name: &str, map: &DataMap) -> Result<LcmMessage, String> {
            let m = LcmMessage {
                types,
                name: name.to_string(),
                map: map.clone(),
            };
            m.payload(Stamp::now())?;
            Ok(m)
        }

        /// The message sent at `stamp`: the type's single `int64_t utime`, when the fields do not
        /// give it, is `stamp` in microseconds.
        pub fn payload(&self, stamp: Stamp) -> Result<Payload, String> {
            let (types, name, map) = (&self.types, &self.name, &self.map);
            let Some(ty) = types.get(name) else {
                return Err(format!("--lcm {name}: no such LCM type"));
            };
            let bytes = if seabus_bridges::lcm::has_utime(ty) && map.get("utime").is_none() {
                let mut map = map.clone();
                map.insert("utime", Value::Int(stamp.0 / 1_000));
                seabus_medium_lcm::codec::encode(types, ty, &map)
            } else {
                seabus_medium_lcm::codec::encode(types, ty, map)
            };
            bytes
                .map(Payload::from)
                .map_err(|e| format!("--lcm {name}: {e}"))
        }
    }
}

#[cfg(not(feature = "lcm"))]
mod imp {
    use super::*;

    const LEFT_OUT: &str = "LCM is not compiled into this seabus (feature `lcm`)";

    /// No LCM types in this build.
    pub struct Types;

    /// Without LCM no type can be read: `--lcm-types` is refused.
    pub fn load(paths: &[PathBuf]) -> Result<Types, String> {
        match paths.first() {
            None => Ok(Types),
            Some(_) => Err(format!("--lcm-types: {LEFT_OUT}")),
        }
    }

    impl Types {
        /// Nothing is recognised without types.
        pub fn recognise<'t>(&'t self, _: &Payload) -> Option<(&'t str, DataMap)> {
            None
        }

        /// Refused: encoding an LCM message needs LCM.
        pub fn encode(&self, name: &str, _: &DataMap) -> Result<Payload, String> {
            Err(format!("LCM type {name}: {LEFT_OUT}"))
        }
    }

    /// No LCM message can be made in this build.
    pub enum LcmMessage {}

    impl LcmMessage {
        /// Refused: `--lcm` needs LCM.
        pub fn new(name: &str, _: &[PathBuf], _: &DataMap, _: bool) -> Result<LcmMessage, String> {
            Err(format!("--lcm {name}: {LEFT_OUT}"))
        }

        /// Never called: there is no message.
        pub fn payload(&self, _: Stamp) -> Result<Payload, String> {
            match *self {}
        }
    }
}

pub use imp::*;

#[cfg(all(test, feature = "lcm"))]
mod tests {
    use super::*;
    use seabus_medium::Value;

    #[test]
    fn lcm_messages_are_stamped_as_sent_in_a_single_int64_utime_only() {
        let mut set = seabus_medium_lcm::types::TypeSet::new();
        set.add_text(
            "t.lcm",
            "package t;\n\
             struct s_t { int64_t utime; double x; }\n\
             struct d_t { double utime; }\n\
             struct a_t { int64_t utime[2]; }\n\
             struct str_t { string utime; }",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let types = set.resolve().unwrap_or_else(|e| panic!("{e}"));
        let map = DataMap::new().and("x", 1.5);
        let decoded = |out: &LcmMessage, name: &str, stamp: i64| {
            let p = out.payload(Stamp(stamp)).unwrap_or_else(|e| panic!("{e}"));
            let bytes = p.as_bytes().expect("bytes");
            let ty = types.get(name).expect("type");
            seabus_medium_lcm::codec::decode(&types, ty, bytes)
                .unwrap_or_else(|e| panic!("{e}"))
                .0
        };
        // each message sent gets its own time
        let out = LcmMessage::of(types.clone(), "t.s_t", &map).unwrap_or_else(|e| panic!("{e}"));
        for stamp in [1_000_000_000, 2_000_000_000] {
            let m = decoded(&out, "t.s_t", stamp);
            assert_eq!(m.get("utime"), Some(&Value::Int(stamp / 1_000)));
            assert_eq!(m.get("x"), Some(&Value::Float(1.5)));
        }
        // one given in the fields stays
        let given = DataMap::new().and("utime", 7);
        let out = LcmMessage::of(types.clone(), "t.s_t", &given).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            decoded(&out, "t.s_t", 5_000).get("utime"),
            Some(&Value::Int(7))
        );
        // a `utime` of another type is left to its default
        let empty = DataMap::new();
        let out = LcmMessage::of(types.clone(), "t.d_t", &empty).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            decoded(&out, "t.d_t", 5_000)
                .get("utime")
                .and_then(Value::as_f64)
                .is_some_and(f64::is_nan)
        );
        for name in ["t.a_t", "t.str_t"] {
            let out = LcmMessage::of(types.clone(), name, &empty).unwrap_or_else(|e| panic!("{e}"));
            let m = decoded(&out, name, 5_000);
            assert_ne!(m.get("utime"), Some(&Value::Int(5)), "{name}");
        }
    }
}
