//! The standard datasets: what every driver of one device type publishes.
//!
//! The catalogue lives in `configs/datasets.xml` and is built into the program; a system may load
//! another file instead. [`Catalogue::validate`] checks a datamap against a dataset: required fields
//! present, every known field of the right type and inside its range. Fields the dataset does not
//! name are allowed (a device may publish more).

use seabus_medium::xml::{self, Element, FileError};
use seabus_medium::{DataMap, Value};
use std::collections::BTreeMap;
use std::fmt;
use std::sync::{Arc, OnceLock};

/// The catalogue shipped with seabus.
pub const BUILT_IN: &str = include_str!("../../configs/datasets.xml");

/// The type of a dataset field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldType {
    /// A float; integers are accepted.
    Float,
    /// An integer.
    Int,
    /// A boolean.
    Bool,
    /// A string.
    Str,
    /// A byte string.
    Bytes,
    /// A list.
    List,
    /// A nested datamap.
    Map,
}

impl FieldType {
    fn parse(s: &str) -> Option<FieldType> {
        Some(match s {
            "float" => FieldType::Float,
            "int" => FieldType::Int,
            "bool" => FieldType::Bool,
            "string" => FieldType::Str,
            "bytes" => FieldType::Bytes,
            "list" => FieldType::List,
            "map" => FieldType::Map,
            _ => return None,
        })
    }

    /// The name used in files.
    pub fn name(self) -> &'static str {
        match self {
            FieldType::Float => "float",
            FieldType::Int => "int",
            FieldType::Bool => "bool",
            FieldType::Str => "string",
            FieldType::Bytes => "bytes",
            FieldType::List => "list",
            FieldType::Map => "map",
        }
    }

    fn admits(self, v: &Value) -> bool {
        matches!(
            (self, v),
            (FieldType::Float, Value::Float(_) | Value::Int(_))
                | (FieldType::Int, Value::Int(_))
                | (FieldType::Bool, Value::Bool(_))
                | (FieldType::Str, Value::Str(_))
                | (FieldType::Bytes, Value::Bytes(_))
                | (FieldType::List, Value::List(_))
                | (FieldType::Map, Value::Map(_))
        )
    }
}

/// One field of a dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// Field name.
    pub name: String,
    /// Type.
    pub ty: FieldType,
    /// Unit, empty when none.
    pub unit: String,
    /// Whether every producer must send it.
    pub required: bool,
    /// Lowest valid value.
    pub min: Option<f64>,
    /// Highest valid value.
    pub max: Option<f64>,
    /// One-line description.
    pub summary: String,
}

/// A standard dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Its name (`attitude`).
    pub name: String,
    /// The topic it is published on by default (`nav.attitude`).
    pub topic: String,
    /// One-line description.
    pub summary: String,
    /// Fields, required ones first as written.
    pub fields: Vec<Field>,
}

impl Dataset {
    /// The field called `name`.
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.name == name)
    }

    /// The required fields.
    pub fn required(&self) -> impl Iterator<Item = &Field> {
        self.fields.iter().filter(|f| f.required)
    }
}

/// One way a datamap fails its dataset.
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// A required field is absent.
    Missing(String),
    /// A field has the wrong type.
    WrongType {
        /// Field.
        field: String,
        /// The type the dataset states.
        expected: FieldType,
        /// The type found.
        found: &'static str,
    },
    /// A numeric field outside its range.
    OutOfRange {
        /// Field.
        field: String,
        /// The value.
        value: f64,
        /// Lowest valid value.
        min: Option<f64>,
        /// Highest valid value.
        max: Option<f64>,
    },
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Missing(field) => write!(f, "required field `{field}` is missing"),
            Problem::WrongType {
                field,
                expected,
                found,
            } => {
                write!(
                    f,
                    "field `{field}` is {found}, expected {}",
                    expected.name()
                )
            }
            Problem::OutOfRange {
                field,
                value,
                min,
                max,
            } => {
                write!(f, "field `{field}` = {value} is outside [")?;
                match min {
                    Some(m) => write!(f, "{m}")?,
                    None => write!(f, "-inf")?,
                }
                write!(f, ", ")?;
                match max {
                    Some(m) => write!(f, "{m}")?,
                    None => write!(f, "inf")?,
                }
                write!(f, "]")
            }
        }
    }
}

/// Why a datamap is not a valid instance of a dataset.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ValidationError {
    /// No dataset has this name.
    #[error("no standard dataset `{0}`")]
    Unknown(String),
    /// The datamap breaks the dataset's rules.
    #[error("not a valid `{dataset}`: {}", problems.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
    Invalid {
        /// The dataset.
        dataset: String,
        /// Every problem found.
        problems: Vec<Problem>,
    },
}

/// The set of standard datasets.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Catalogue {
    datasets: BTreeMap<String, Dataset>,
}

impl Catalogue {
    /// The catalogue built into seabus (`configs/datasets.xml`), parsed once.
    pub fn built_in() -> Arc<Catalogue> {
        static CAT: OnceLock<Arc<Catalogue>> = OnceLock::new();
        CAT.get_or_init(|| {
            Arc::new(
                Catalogue::parse("configs/datasets.xml", BUILT_IN)
                    .expect("the built-in catalogue is valid"),
            )
        })
        .clone()
    }

    /// Parses a catalogue file's text.
    pub fn parse(file: &str, text: &str) -> Result<Catalogue, FileError> {
        let root = xml::parse(file, text)?;
        Catalogue::from_element(&root)
    }

    fn from_element(root: &Element) -> Result<Catalogue, FileError> {
        if root.name != "datasets" {
            return Err(root.error(format!(
                "root element is <{}>, expected <datasets>",
                root.name
            )));
        }
        root.only_attrs(&[])?;
        root.only_children(&["dataset"])?;
        let mut datasets = BTreeMap::new();
        for d in &root.children {
            d.only_attrs(&["name", "topic", "summary"])?;
            d.only_children(&["field"])?;
            let name = d.required("name")?.value.clone();
            let topic = d.required("topic")?;
            seabus_medium::Topic::new(&topic.value).map_err(|e| topic.error(e))?;
            let mut fields: Vec<Field> = Vec::new();
            for f in &d.children {
                f.only_attrs(&["name", "type", "unit", "required", "min", "max", "summary"])?;
                let fname = f.required("name")?.value.clone();
                if fields.iter().any(|x| x.name == fname) {
                    return Err(f.error(format!(
                        "field `{fname}` is listed twice in dataset `{name}`"
                    )));
                }
                let ty_attr = f.required("type")?;
                let ty = FieldType::parse(&ty_attr.value).ok_or_else(|| {
                    ty_attr.error(format!(
                        "`{}` is not one of float, int, bool, string, bytes, list, map",
                        ty_attr.value
                    ))
                })?;
                fields.push(Field {
                    name: fname,
                    ty,
                    unit: f.get("unit").unwrap_or("").to_string(),
                    required: f.flag("required")?.unwrap_or(false),
                    min: f.parsed("min", "a number")?,
                    max: f.parsed("max", "a number")?,
                    summary: f.get("summary").unwrap_or("").to_string(),
                });
            }
            if !fields.iter().any(|f| f.required) {
                return Err(d.error(format!("dataset `{name}` has no required field")));
            }
            let ds = Dataset {
                name: name.clone(),
                topic: topic.value.clone(),
                summary: d.get("summary").unwrap_or("").to_string(),
                fields,
            };
            if datasets.insert(name.clone(), ds).is_some() {
                return Err(d.error(format!("dataset `{name}` is defined twice")));
            }
        }
        Ok(Catalogue { datasets })
    }

    /// The dataset called `name`.
    pub fn get(&self, name: &str) -> Option<&Dataset> {
        self.datasets.get(name)
    }

    /// The topic dataset `name` is published on by default, or `fallback` when the catalogue
    /// has no such dataset.
    pub fn topic_of(&self, name: &str, fallback: &str) -> String {
        self.get(name)
            .map_or_else(|| fallback.to_string(), |d| d.topic.clone())
    }

    /// Every dataset, by name.
    pub fn iter(&self) -> impl Iterator<Item = &Dataset> {
        self.datasets.values()
    }

    /// The names of all datasets.
    pub fn names(&self) -> Vec<&str> {
        self.datasets.keys().map(String::as_str).collect()
    }

    /// Checks `map` against dataset `name`.
    pub fn validate(&self, name: &str, map: &DataMap) -> Result<(), ValidationError> {
        let ds = self
            .get(name)
            .ok_or_else(|| ValidationError::Unknown(name.to_string()))?;
        let mut problems = Vec::new();
        for field in &ds.fields {
            let Some(v) = map.get(&field.name) else {
                if field.required {
                    problems.push(Problem::Missing(field.name.clone()));
                }
                continue;
            };
            if !field.ty.admits(v) {
                problems.push(Problem::WrongType {
                    field: field.name.clone(),
                    expected: field.ty,
                    found: v.type_name(),
                });
                continue;
            }
            if let Some(x) = v.as_f64() {
                let below = field.min.is_some_and(|m| x < m);
                let above = field.max.is_some_and(|m| x > m);
                if below || above || x.is_nan() {
                    problems.push(Problem::OutOfRange {
                        field: field.name.clone(),
                        value: x,
                        min: field.min,
                        max: field.max,
                    });
                }
            }
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(ValidationError::Invalid {
                dataset: name.to_string(),
                problems,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_catalogue_has_the_standard_datasets() {
        let c = Catalogue::built_in();
        for name in [
            "attitude",
            "position",
            "velocity",
            "depth",
            "altitude",
            "battery",
            "vehicle-state",
            "vehicle-info",
            "course-command",
            "actuator-command",
            "mission-command",
        ] {
            let d = c
                .get(name)
                .unwrap_or_else(|| panic!("{name} is in the catalogue"));
            assert!(d.required().count() > 0);
        }
        let att = c.get("attitude").unwrap();
        let req: Vec<_> = att.required().map(|f| f.name.as_str()).collect();
        assert_eq!(req, ["yaw", "pitch", "roll"]);
        assert_eq!(att.field("yaw").unwrap().unit, "deg");
        let course: Vec<_> = c
            .get("course-command")
            .unwrap()
            .required()
            .map(|f| f.name.as_str())
            .collect();
        assert_eq!(course, ["heading", "depth", "speed"]);
    }

    #[test]
    fn validation_lists_every_problem() {
        let c = Catalogue::built_in();
        let ok = DataMap::new()
            .with("yaw", 10.0)
            .with("pitch", 1i64)
            .with("roll", -2.0)
            .with("vendor_x", "extra");
        assert_eq!(c.validate("attitude", &ok), Ok(()));
        let bad = DataMap::new()
            .with("yaw", 400.0)
            .with("pitch", "up")
            .with("temperature", true);
        let err = c.validate("attitude", &bad).unwrap_err();
        let ValidationError::Invalid { problems, .. } = &err else {
            panic!("{err}")
        };
        assert_eq!(problems.len(), 4, "{err}");
        assert_eq!(
            err.to_string(),
            "not a valid `attitude`: field `yaw` = 400 is outside [0, 360]; field `pitch` is string, expected float; \
             required field `roll` is missing; field `temperature` is bool, expected float"
        );
        assert_eq!(
            c.validate("nope", &ok),
            Err(ValidationError::Unknown("nope".into()))
        );
    }

    #[test]
    fn map_fields_admit_nested_maps_only() {
        let c = Catalogue::parse(
            "d.xml",
            "<datasets><dataset name=\"pose\" topic=\"nav.pose\">\
             <field name=\"position\" type=\"map\" required=\"true\"/></dataset></datasets>",
        )
        .unwrap();
        assert_eq!(c.get("pose").unwrap().fields[0].ty, FieldType::Map);
        let ok = DataMap::new().with("position", DataMap::new().with("x", 1.0));
        assert_eq!(c.validate("pose", &ok), Ok(()));
        let flat = DataMap::new().with("position", Value::List(vec![]));
        let err = c.validate("pose", &flat).unwrap_err();
        assert_eq!(
            err.to_string(),
            "not a valid `pose`: field `position` is list, expected map"
        );
    }

    #[test]
    fn catalogue_file_errors_are_placed() {
        let e = Catalogue::parse("d.xml", "<datasets>\n <dataset name=\"x\" topic=\"a.b\">\n  <field name=\"f\" type=\"real\"/>\n </dataset>\n</datasets>").unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.xml:3:19: attribute `type`: `real` is not one of float, int, bool, string, bytes, list, map"
        );
        let e = Catalogue::parse("d.xml", "<datasets><dataset name=\"x\" topic=\"a.b\"><field name=\"f\" type=\"int\"/></dataset></datasets>").unwrap_err();
        assert!(e.message.contains("no required field"), "{e}");
    }
}
