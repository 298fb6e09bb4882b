//! `generator`: publishes `{counter, sine, time}` at its tick rate (1 Hz without a tick).
//!
//! Parameters: `topic` (default `test.counter`), `format` (`map`, `xml` or `bytes`: the payload
//! format it sends), `kind` (`data` or `command`), `amplitude` and `period` of the sine wave,
//! `count` (stop publishing after this many; default: never).

use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Format, Kind, Payload, Stamp, Topic};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::time::Duration;

/// The `generator` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "generator",
    kind: ModuleKind::Supporting,
    summary: "publishes a counter and a sine wave at its tick rate",
    build,
};

struct Generator {
    topic: Topic,
    format: Format,
    kind: Kind,
    amplitude: f64,
    period: Duration,
    count: Option<u64>,
    sent: u64,
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let topic = p.topic_or("topic", "test.counter")?;
    let format = match p.get("format") {
        None => Format::Map,
        Some(f) => {
            Format::parse(f.value.trim()).ok_or_else(|| f.error("expected map, xml or bytes"))?
        }
    };
    let kind = match p.get("kind") {
        None => Kind::Data,
        Some(k) => match k.value.trim() {
            "data" => Kind::Data,
            "command" => Kind::Command,
            _ => return Err(k.error("expected data or command")),
        },
    };
    let period = p.duration_or("period", Duration::from_secs(10))?;
    if period.is_zero() {
        return Err(p.get("period").map_or_else(
            || cfg.pos.error("period is zero"),
            |x| x.error("must be above zero"),
        ));
    }
    let decl = Declaration::new(ModuleKind::Supporting)
        .produces(
            TopicDecl::topic(topic.as_str())
                .field("counter", "")
                .field("sine", "")
                .field("time", "s"),
        )
        .default_tick(Duration::from_secs(1));
    Ok(Built {
        decl,
        module: Box::new(Generator {
            topic,
            format,
            kind,
            amplitude: p.float_or("amplitude", 1.0)?,
            period,
            count: p.parse("count", "a whole number")?,
            sent: 0,
        }),
    })
}

#[async_trait]
impl Module for Generator {
    async fn on_timer(&mut self, ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        if self.count.is_some_and(|c| self.sent >= c) {
            return Ok(());
        }
        let t = Stamp::now().as_secs_f64();
        let phase = t / self.period.as_secs_f64() * std::f64::consts::TAU;
        let map = DataMap::new()
            .with("counter", self.sent as i64)
            .with("sine", self.amplitude * phase.sin())
            .with("time", t);
        let payload = Payload::from(map).convert(self.format).map_err(|e| {
            ModuleError::msg(format!("cannot build a {} payload: {e}", self.format))
        })?;
        ctx.publish_on(0, self.kind, &self.topic, payload).await?;
        self.sent += 1;
        Ok(())
    }
}
