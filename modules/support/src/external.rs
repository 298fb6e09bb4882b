//! `external`: a module whose logic is another program — Python, MATLAB, a shell script, anything
//! that reads and writes lines.
//!
//! ```xml
//! <module name="doubler" type="external" medium="bus" command="python3 doubler.py"
//!         inputs="test.value" outputs="test.doubled"/>
//! ```
//!
//! The program is started in the system file's directory. Each message on an `inputs` topic (topic
//! patterns, comma-separated) is written to its standard input as one JSON line:
//!
//! ```json
//! {"topic":"test.value","kind":"data","stamp":1795256837.19,"payload":{"value":21}}
//! ```
//!
//! and each line it writes on its standard output is a message to publish, `{"topic": …,
//! "payload": {…}}` with `"kind": "command"` for a command; a topic outside its declared `outputs`
//! (patterns), or a line that is not such JSON, is counted and logged, never published. What it
//! writes on its standard error goes to the log, line by line, under the module's name (and so to
//! the DSAAV central log when the system has one). When the program exits or dies the module
//! fails, and the runtime starts it again with back-off.
//!
//! Parameters: `command` (the program and its arguments; double quotes keep blanks), `inputs`,
//! `outputs`, `accepts` (command topics passed to it as inputs too).

use async_trait::async_trait;
use seabus_medium::tally::Tally;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Interface, Kind, Message, Pattern, Value, json};
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{
    Context, Declaration, Module, ModuleError, ModuleKind, TimerId, TopicDecl,
};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::process::{Child, ChildStdin, Command};
use tokio::sync::watch;

/// The `external` module type.
pub const TYPE: ModuleType = ModuleType {
    name: "external",
    kind: ModuleKind::Supporting,
    summary: "a module whose logic is another program, speaking JSON lines on stdin/stdout",
    build,
};

/// How often the module looks whether its program is still running.
const WATCH: TimerId = 1;

struct External {
    program: String,
    args: Vec<String>,
    dir: PathBuf,
    outputs: Arc<Vec<Pattern>>,
    running: Option<Running>,
}

/// The running program.
struct Running {
    child: Child,
    stdin: ChildStdin,
    /// Set with the reason when the program's output ends.
    ended: watch::Receiver<Option<String>>,
    tasks: Vec<tokio::task::AbortHandle>,
}

impl Drop for Running {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
        // a program left behind would keep running after its module
        let _ = self.child.start_kill();
    }
}

fn patterns(cfg: &ModuleConfig, name: &str) -> Result<Vec<Pattern>, FileError> {
    let Some(p) = cfg.params.get(name) else {
        return Ok(Vec::new());
    };
    p.value
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| Pattern::new(s).map_err(|e| p.error(format!("`{s}`: {e}"))))
        .collect()
}

fn build(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let Some(command) = cfg.params.get("command") else {
        return Err(cfg
            .pos
            .error("an external module needs `command`, the program to run"));
    };
    let words = seabus_medium::parse::split_words(&command.value).map_err(|e| command.error(e))?;
    let mut words = words.into_iter().map(|w| w.trim_matches('"').to_string());
    let Some(program) = words.next() else {
        return Err(command.error("names no program"));
    };
    let inputs = patterns(cfg, "inputs")?;
    let outputs = patterns(cfg, "outputs")?;
    let accepts = patterns(cfg, "accepts")?;
    let mut decl =
        Declaration::new(ModuleKind::Supporting).default_tick(Duration::from_millis(100));
    for p in &inputs {
        decl = decl.consumes(TopicDecl::topic(p.as_str()));
    }
    for p in &accepts {
        decl = decl.accepts(TopicDecl::topic(p.as_str()));
    }
    for p in &outputs {
        decl = decl.produces(TopicDecl::topic(p.as_str()));
    }
    Ok(Built {
        decl,
        module: Box::new(External {
            program,
            args: words.collect(),
            dir: seabus_modules::system::beside(&cfg.pos, "."),
            outputs: Arc::new(outputs),
            running: None,
        }),
    })
}

/// Publishes what the program writes, until its output ends.
async fn read_outputs(
    out: tokio::process::ChildStdout,
    port: Interface,
    outputs: Arc<Vec<Pattern>>,
    name: String,
    ended: watch::Sender<Option<String>>,
) {
    let tally = Tally::new();
    let mut lines = BufReader::new(out).lines();
    let mut n = 0u64;
    loop {
        let line = match lines.next_line().await {
            Ok(Some(l)) => l,
            Ok(None) => break,
            Err(e) => {
                let _ = ended.send(Some(format!("reading its output: {e}")));
                return;
            }
        };
        n += 1;
        let parsed = json::from_json(&line)
            .map_err(|e| format!("line {n} is not JSON ({e})"))
            .and_then(|m| {
                let topic = m
                    .get_str("topic")
                    .ok_or_else(|| format!("line {n} has no \"topic\""))?
                    .to_string();
                let payload = match m.get("payload") {
                    Some(Value::Map(p)) => p.clone(),
                    None => DataMap::new(),
                    Some(v) => return Err(format!("line {n}: \"payload\" is {v}, not an object")),
                };
                let kind = match m.get_str("kind") {
                    None | Some("data") => Kind::Data,
                    Some("command") => Kind::Command,
                    Some(k) => return Err(format!("line {n}: kind `{k}` is not data or command")),
                };
                Ok((topic, payload, kind))
            });
        let (topic, payload, kind) = match parsed {
            Ok(x) => x,
            Err(e) => {
                tally.record(&name, "bad-output", e);
                continue;
            }
        };
        let Ok(t) = seabus_medium::Topic::new(&topic) else {
            tally.record(
                &name,
                "bad-output",
                format_args!("line {n}: `{topic}` is not a topic"),
            );
            continue;
        };
        if !outputs.iter().any(|p| p.matches(&t)) {
            tally.record(
                &name,
                "undeclared-output",
                format_args!("line {n}: `{topic}` is not among its outputs"),
            );
            continue;
        }
        let sent = match kind {
            Kind::Data => port.send(t, payload).await,
            Kind::Command => port.command(t, payload).await,
        };
        if let Err(e) = sent {
            tally.record(&name, "not-sent", e);
        }
    }
    let _ = ended.send(Some("its output ended".into()));
}

#[async_trait]
impl Module for External {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let Some(medium) = ctx.port(0).map(|p| p.medium().clone()) else {
            return Err(ModuleError::msg("an external module needs a medium"));
        };
        let mut child = Command::new(&self.program)
            .args(&self.args)
            .current_dir(&self.dir)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .map_err(|e| ModuleError::msg(format!("cannot start `{}`: {e}", self.program)))?;
        let (Some(stdin), Some(stdout), Some(stderr)) =
            (child.stdin.take(), child.stdout.take(), child.stderr.take())
        else {
            return Err(ModuleError::msg("the program's streams were not piped"));
        };
        let (ended_tx, ended) = watch::channel(None);
        let name = ctx.name().to_string();
        let out = tokio::spawn(read_outputs(
            stdout,
            medium.attach(&format!("{name}-out")),
            self.outputs.clone(),
            name.clone(),
            ended_tx,
        ));
        let err = tokio::spawn({
            let name = name.clone();
            async move {
                let mut lines = BufReader::new(stderr).lines();
                while let Ok(Some(l)) = lines.next_line().await {
                    tracing::warn!(module = %name, "{l}");
                }
            }
        });
        tracing::info!(module = %name, "started `{}` (pid {})", self.program, child.id().unwrap_or(0));
        self.running = Some(Running {
            child,
            stdin,
            ended,
            tasks: vec![out.abort_handle(), err.abort_handle()],
        });
        ctx.every(WATCH, Duration::from_millis(100));
        Ok(())
    }

    async fn on_message(
        &mut self,
        _ctx: &mut Context,
        _port: usize,
        msg: Message,
    ) -> Result<(), ModuleError> {
        let Some(r) = &mut self.running else {
            return Ok(());
        };
        let Ok(payload) = msg.payload.to_map() else {
            return Ok(());
        };
        let line = DataMap::new()
            .with("topic", msg.topic.as_str())
            .with(
                "kind",
                match msg.kind {
                    Kind::Data => "data",
                    Kind::Command => "command",
                },
            )
            .with("stamp", msg.stamp.as_secs_f64())
            .with("payload", Value::Map(Arc::unwrap_or_clone(payload)));
        let mut text = json::to_json(&line).map_err(|e| ModuleError::msg(e.to_string()))?;
        text.push('\n');
        if let Err(e) = r.stdin.write_all(text.as_bytes()).await {
            return Err(ModuleError::msg(format!(
                "the program stopped reading: {e}"
            )));
        }
        Ok(())
    }

    async fn on_timer(&mut self, _ctx: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        let Some(r) = &mut self.running else {
            return Ok(());
        };
        let exited = r.child.try_wait().ok().flatten();
        let ended = r.ended.borrow().clone();
        match (exited, ended) {
            (Some(status), _) => Err(ModuleError::msg(format!("the program exited ({status})"))),
            (None, Some(why)) => Err(ModuleError::msg(format!("the program is lost: {why}"))),
            (None, None) => Ok(()),
        }
    }

    async fn stop(&mut self, _ctx: &mut Context) {
        if let Some(mut r) = self.running.take() {
            // closing its input asks it to finish; it is killed if it has not within a second
            let _ = r.stdin.shutdown().await;
            let _ = tokio::time::timeout(Duration::from_secs(1), r.child.wait()).await;
        }
    }
}
