//! `convert`: reads one topic, applies the unit and frame conversions declared in configuration,
//! publishes another topic.
//!
//! ```xml
//! <module name="depth-m" type="convert" medium="bus" input="sonar.raw" output="nav.depth"
//!         fields="depth_ft ft->m as depth; temp_f degF->degC as temperature; range*2+0.1"
//!         keep="false"/>
//! <module name="grid" type="convert" medium="bus" input="nav.position" output="nav.local"
//!         frames="geodetic->enu(43.5081, 16.4402): lat, lon -> x, y"/>
//! <module name="dvl-ned" type="convert" medium="bus" input="dvl.raw" output="nav.velocity.ned"
//!         fields="vx mm/s->m/s; vy mm/s->m/s; vz mm/s->m/s"
//!         frames="rotate(0, 0, 45): vx, vy, vz -> surge, sway, heave;
//!                 rotate(roll, pitch, yaw): surge, sway, heave -> vn, ve, vd"
//!         attitude="nav.attitude" keep="false"/>
//! ```
//!
//! `fields`: each conversion is `SOURCE`, then optionally a unit pair `FROM->TO` (see
//! [`crate::frames::UNITS`]; both of one quantity), then any number of `*N`, `/N`, `+N`, `-N`
//! applied left to right, then optionally `as NAME`.
//!
//! `frames`: each transform is `KIND(ARGS): IN, … -> OUT, …` (see [`Transform::parse`]), applied
//! in order after the field conversions, so a transform reads what the ones before it wrote. Angles
//! of `rotate`/`unrotate` are degrees, numbers (a sensor's mounting) or field names (the vehicle's
//! attitude); a field not in the message is taken from the latest message on the `attitude` topic
//! when that is at most `attitude_age` (default 1 s) older or newer than the message.
//!
//! With `keep="true"` (the default) the other fields pass through unchanged (a renamed source is
//! removed); with `keep="false"` only the converted fields and the transforms' outputs are
//! published. `dataset` names a standard dataset the output must satisfy (checked before
//! publishing). A message lacking a field it needs is not published, and counted by reason.

use crate::frames::{Fields, Transform, Unit};
use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Stamp, Topic, Value};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use seabus_modules::params::Params;
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::time::Duration;

/// The `convert` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "convert",
    kind: ModuleKind::Supporting,
    summary: "applies unit and frame conversions to fields of one topic and publishes another",
    build,
};

#[derive(Debug, Clone, PartialEq)]
enum Op {
    Mul(f64),
    Add(f64),
}

/// One conversion: `source` through `ops` into `target`.
#[derive(Debug, Clone, PartialEq)]
pub struct Conversion {
    source: String,
    ops: Vec<Op>,
    target: String,
    /// The unit converted to, if the conversion names one.
    unit: Option<&'static str>,
}

impl Conversion {
    /// Parses `SOURCE [FROM->TO] [*N|/N|+N|-N]… [as NAME]`.
    pub fn parse(text: &str) -> Result<Conversion, String> {
        let text = text.trim();
        let (expr, target) = match text.rsplit_once(" as ") {
            Some((e, t)) => (e.trim(), Some(t.trim())),
            None => (text, None),
        };
        let source: String = expr
            .chars()
            .take_while(|c| crate::frames::is_field_name(c.encode_utf8(&mut [0; 4])))
            .collect();
        if source.is_empty() {
            return Err(format!("`{text}` does not start with a field name"));
        }
        let mut ops = Vec::new();
        let mut rest = expr[source.len()..].trim_start();
        let mut unit = None;
        if rest.starts_with(|c: char| c.is_alphabetic()) {
            let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
            let (from, to) = rest[..end].split_once("->").ok_or_else(|| {
                format!(
                    "`{}` in `{text}`: expected a unit pair FROM->TO",
                    &rest[..end]
                )
            })?;
            let (from, to) = (Unit::named(from)?, Unit::named(to)?);
            let (k, c) = from.linear_to(&to)?;
            ops.push(Op::Mul(k));
            if c != 0.0 {
                ops.push(Op::Add(c));
            }
            unit = Some(to.name);
            rest = &rest[end..];
        }
        let mut rest = rest.chars().peekable();
        loop {
            while rest.next_if(|c| c.is_whitespace()).is_some() {}
            let Some(op) = rest.next() else { break };
            if !matches!(op, '*' | '/' | '+' | '-') {
                return Err(format!("`{op}` in `{text}`: expected *, /, + or -"));
            }
            while rest.next_if(|c| c.is_whitespace()).is_some() {}
            // a number: digits, a point, an exponent whose sign belongs to it (1e-3)
            let mut num = String::new();
            while let Some(c) = rest.next_if(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E'))
            {
                num.push(c);
                if matches!(c, 'e' | 'E')
                    && let Some(sign) = rest.next_if(|c| matches!(c, '+' | '-'))
                {
                    num.push(sign);
                }
            }
            let n: f64 = num
                .parse()
                .ok()
                .filter(|n: &f64| n.is_finite())
                .ok_or_else(|| format!("`{num}` after `{op}` in `{text}` is not a number"))?;
            ops.push(match op {
                '*' => Op::Mul(n),
                '/' if n == 0.0 => return Err(format!("division by zero in `{text}`")),
                '/' => Op::Mul(1.0 / n),
                '+' => Op::Add(n),
                _ => Op::Add(-n),
            });
        }
        let target = target.unwrap_or(&source);
        if !crate::frames::is_field_name(target) {
            return Err(format!("`{target}` is not a field name"));
        }
        Ok(Conversion {
            source: source.clone(),
            ops,
            target: target.to_string(),
            unit,
        })
    }

    /// Applies the conversion to a number.
    pub fn apply(&self, x: f64) -> f64 {
        self.ops.iter().fold(x, |v, op| match op {
            Op::Mul(k) => v * k,
            Op::Add(k) => v + k,
        })
    }
}

struct Convert {
    output: Topic,
    conversions: Vec<Conversion>,
    transforms: Vec<Transform>,
    keep: bool,
    dataset: Option<String>,
    /// Where angles missing from a message are read, and how far apart in time they may be.
    attitude: Option<(Topic, Duration)>,
    latest_attitude: Option<(Stamp, DataMap)>,
    skipped: Tally,
}

fn build(cfg: &ModuleConfig, catalogue: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let input = p.required("input")?;
    seabus_medium::Pattern::new(input.value.trim()).map_err(|e| input.error(e))?;
    let output = p.topic_or("output", "")?;
    let conversions = list(p, "fields", Conversion::parse)?;
    let transforms = list(p, "frames", Transform::parse)?;
    if conversions.is_empty() && transforms.is_empty() {
        return Err(p.error("`convert` needs conversions in `fields` or transforms in `frames`"));
    }
    let dataset = match p.get("dataset") {
        None => None,
        Some(d) => {
            if catalogue.get(&d.value).is_none() {
                return Err(d.error(format!(
                    "no standard dataset `{}`; datasets: {}",
                    d.value,
                    catalogue.names().join(", ")
                )));
            }
            Some(d.value.clone())
        }
    };
    let attitude = match p.get("attitude") {
        None => None,
        Some(_) => Some((
            p.topic_or("attitude", "")?,
            p.duration_or("attitude_age", Duration::from_secs(1))?,
        )),
    };
    let mut produced = match &dataset {
        Some(d) => TopicDecl::dataset(output.as_str(), d),
        None => TopicDecl::topic(output.as_str()),
    };
    for c in &conversions {
        produced = produced.field(&c.target, c.unit.unwrap_or(""));
    }
    for t in &transforms {
        for o in &t.outputs {
            produced = produced.field(o, "");
        }
    }
    let mut decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::topic(input.value.trim()))
        .produces(produced);
    if let Some((topic, _)) = &attitude {
        let mut att = TopicDecl::topic(topic.as_str());
        for t in &transforms {
            for f in t.angle_fields() {
                att = att.field(f, "deg");
            }
        }
        decl = decl.consumes(att);
    }
    Ok(Built {
        decl,
        module: Box::new(Convert {
            output,
            conversions,
            transforms,
            keep: p.flag_or("keep", true)?,
            dataset,
            attitude,
            latest_attitude: None,
            skipped: Tally::new(),
        }),
    })
}

/// The `;`-separated items of parameter `name`, each parsed, or the first one's error at its place.
fn list<T>(
    p: &Params,
    name: &str,
    parse: fn(&str) -> Result<T, String>,
) -> Result<Vec<T>, FileError> {
    let Some(param) = p.get(name) else {
        return Ok(Vec::new());
    };
    param
        .value
        .split(';')
        .filter(|s| !s.trim().is_empty())
        .map(parse)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| param.error(e))
}

/// A message's fields, then the latest attitude's.
struct Lookup<'a> {
    work: &'a DataMap,
    attitude: Option<&'a DataMap>,
}

impl Fields for Lookup<'_> {
    fn number(&self, name: &str) -> Option<f64> {
        self.work
            .get(name)
            .or_else(|| self.attitude.and_then(|a| a.get(name)))
            .and_then(Value::as_f64)
    }
}

#[async_trait]
impl Module for Convert {
    async fn on_message(
        &mut self,
        ctx: &mut Context,
        _: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(input) = msg.payload.as_map() else {
            return Ok(());
        };
        if let Some((topic, _)) = &self.attitude
            && msg.topic == *topic
        {
            self.latest_attitude = Some((msg.stamp, input.clone()));
            return Ok(());
        }
        let mut work = input.clone();
        let mut out = DataMap::new();
        for c in &self.conversions {
            let Some(x) = input.get(&c.source).and_then(Value::as_f64) else {
                self.skipped.record(
                    ctx.name(),
                    "missing field",
                    format_args!("{}: no numeric field `{}`", msg.topic, c.source),
                );
                return Ok(());
            };
            if c.target != c.source {
                work.remove(&c.source);
            }
            let y = c.apply(x);
            work.insert(c.target.clone(), y);
            if !self.keep {
                out.insert(c.target.clone(), y);
            }
        }
        let attitude = match (&self.attitude, &self.latest_attitude) {
            (Some((_, age)), Some((stamp, map)))
                if msg.stamp.since(*stamp).max(stamp.since(msg.stamp)) <= *age =>
            {
                Some(map)
            }
            _ => None,
        };
        for t in &self.transforms {
            let values = t.apply(&Lookup {
                work: &work,
                attitude,
            });
            let values = match values {
                Ok(v) => v,
                Err(field) => {
                    let reason = if t.angle_fields().any(|f| f == field) && self.attitude.is_some()
                    {
                        "no fresh attitude"
                    } else {
                        "missing field"
                    };
                    self.skipped.record(
                        ctx.name(),
                        reason,
                        format_args!("{}: no numeric field `{field}`", msg.topic),
                    );
                    return Ok(());
                }
            };
            for (name, v) in t.outputs.iter().zip(values) {
                work.insert(name.clone(), v);
                if !self.keep {
                    out.insert(name.clone(), v);
                }
            }
        }
        let out = if self.keep { work } else { out };
        match &self.dataset {
            Some(d) => ctx.publish_dataset(d, &self.output, out).await,
            None => ctx.publish(&self.output, out).await,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_parse_and_apply_left_to_right() {
        let c = Conversion::parse("depth_ft*0.3048 as depth").unwrap();
        assert_eq!(
            (c.source.as_str(), c.target.as_str()),
            ("depth_ft", "depth")
        );
        assert!((c.apply(10.0) - 3.048).abs() < 1e-12);
        let c = Conversion::parse("temp_f - 32 * 0.5 as temp_c").unwrap();
        assert_eq!(c.apply(50.0), 9.0);
        let c = Conversion::parse("x/4+1e-3").unwrap();
        assert_eq!(c.target, "x");
        assert!((c.apply(2.0) - 0.501).abs() < 1e-12);
        let c = Conversion::parse("counter*2").unwrap();
        assert_eq!(c.apply(21.0), 42.0);
    }

    #[test]
    fn unit_pairs_convert_first_and_name_the_unit() {
        let c = Conversion::parse("depth_ft ft->m as depth").unwrap();
        assert!((c.apply(10.0) - 3.048).abs() < 1e-12);
        assert_eq!((c.target.as_str(), c.unit), ("depth", Some("m")));
        let c = Conversion::parse("t degF->degC").unwrap();
        assert!((c.apply(212.0) - 100.0).abs() < 1e-9);
        let c = Conversion::parse("s kn->m/s *2 +1").unwrap();
        assert!((c.apply(1.0) - (1.0 + 2.0 * 1852.0 / 3600.0)).abs() < 1e-12);
        assert!(
            Conversion::parse("d ft->kn")
                .unwrap_err()
                .contains("do not convert")
        );
        assert!(
            Conversion::parse("d ftm")
                .unwrap_err()
                .contains("unit pair")
        );
        assert!(
            Conversion::parse("s kn->m/s*2")
                .unwrap_err()
                .contains("unknown unit `m/s*2`")
        );
    }

    #[test]
    fn bad_conversions_say_why() {
        assert!(Conversion::parse("*2").unwrap_err().contains("field name"));
        assert!(
            Conversion::parse("x*two")
                .unwrap_err()
                .contains("is not a number")
        );
        // found in review: these used to slice past the end or inside a character
        assert!(Conversion::parse("x*1e").is_err());
        assert!(Conversion::parse("x*2e").is_err());
        assert!(Conversion::parse("x×2").unwrap_err().contains("expected *"));
        assert!(
            Conversion::parse("x/0")
                .unwrap_err()
                .contains("division by zero")
        );
        assert!(Conversion::parse("x^2").unwrap_err().contains("expected *"));
    }
}
