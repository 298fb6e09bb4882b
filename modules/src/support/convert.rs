//! `convert`: reads one topic, applies linear conversions to its fields, publishes another topic.
//!
//! ```xml
//! <module name="depth-m" type="convert" medium="bus" input="sonar.raw" output="nav.depth"
//!         fields="depth_ft*0.3048 as depth; temp_f-32*0.5555556 as temperature" keep="false"/>
//! ```
//! Each conversion is `SOURCE`, then any number of `*N`, `/N`, `+N`, `-N` applied left to right,
//! then optionally `as NAME`. With `keep="true"` (the default) the other fields pass through
//! unchanged; with `keep="false"` only the converted fields are published. `dataset` names a
//! standard dataset the output must satisfy (checked before publishing).

use crate::datasets::Catalogue;
use crate::module::{Context, Declaration, Module, ModuleError, ModuleKind, TopicDecl};
use crate::registry::{Built, ModuleConfig, ModuleType};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Message, Topic, Value};

/// The `convert` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "convert",
    kind: ModuleKind::Supporting,
    summary: "applies linear conversions to fields of one topic and publishes another",
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
}

impl Conversion {
    /// Parses `SOURCE[*N|/N|+N|-N]… [as NAME]`.
    pub fn parse(text: &str) -> Result<Conversion, String> {
        let text = text.trim();
        let (expr, target) = match text.rsplit_once(" as ") {
            Some((e, t)) => (e.trim(), Some(t.trim())),
            None => (text, None),
        };
        let is_name = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '.';
        let source: String = expr.chars().take_while(|c| is_name(*c)).collect();
        if source.is_empty() {
            return Err(format!("`{text}` does not start with a field name"));
        }
        let mut ops = Vec::new();
        let mut rest = expr[source.len()..].chars().peekable();
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
        if target.is_empty() || target.contains(char::is_whitespace) {
            return Err(format!("`{target}` is not a field name"));
        }
        Ok(Conversion {
            source: source.clone(),
            ops,
            target: target.to_string(),
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
    keep: bool,
    dataset: Option<String>,
}

fn build(cfg: &ModuleConfig, catalogue: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let input = p.required("input")?;
    seabus_medium::Pattern::new(input.value.trim()).map_err(|e| input.error(e))?;
    let output = p.topic_or("output", "")?;
    let fields = p.required("fields")?;
    let conversions = fields
        .value
        .split(';')
        .filter(|s| !s.trim().is_empty())
        .map(Conversion::parse)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| fields.error(e))?;
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
    let mut produced = match &dataset {
        Some(d) => TopicDecl::dataset(output.as_str(), d),
        None => TopicDecl::topic(output.as_str()),
    };
    for c in &conversions {
        produced = produced.field(&c.target, "");
    }
    let decl = Declaration::new(ModuleKind::Supporting)
        .consumes(TopicDecl::topic(input.value.trim()))
        .produces(produced);
    Ok(Built {
        decl,
        module: Box::new(Convert {
            output,
            conversions,
            keep: p.flag_or("keep", true)?,
            dataset,
        }),
    })
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
        let mut out = if self.keep {
            input.clone()
        } else {
            DataMap::new()
        };
        for c in &self.conversions {
            match input.get(&c.source).and_then(Value::as_f64) {
                Some(x) => {
                    if self.keep && c.target != c.source {
                        out.remove(&c.source);
                    }
                    out.insert(c.target.clone(), c.apply(x));
                }
                None => {
                    tracing::debug!(module = ctx.name(), topic = %msg.topic, "no numeric field `{}`", c.source);
                    return Ok(());
                }
            }
        }
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
