//! The DSAAV core servers as module types, for system files: `dsaav-config` serves the
//! configuration database and `dsaav-log` the central log, each on a DSAAV medium (its node is the
//! medium's) at a port.
//!
//! ```xml
//! <medium name="n1" url="dsaav+eth://eth0?node=1"/>
//! <module name="config" type="dsaav-config" medium="n1" config="starfish.ini" appdata="starfish-app.ini" port="2"/>
//! <module name="log" type="dsaav-log" medium="n1" file="vehicle.log" port="0" max_size="10000000" keep="5"/>
//! ```
//! Paths are relative to the system file. The servers run until the system stops.

use super::config::Database;
use super::logging::LogFile;
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use std::path::PathBuf;

/// The `dsaav-config` module type.
pub const CONFIG: ModuleType = ModuleType {
    name: "dsaav-config",
    kind: ModuleKind::Service,
    summary: "the DSAAV configuration server (sectioned file, application data, plumbing)",
    build: build_config,
};

/// The `dsaav-log` module type.
pub const LOG: ModuleType = ModuleType {
    name: "dsaav-log",
    kind: ModuleKind::Service,
    summary: "the DSAAV logging server: one central log, rotated by size",
    build: build_log,
};

/// A path parameter, relative to the system file.
fn path_param(cfg: &ModuleConfig, name: &str) -> Result<PathBuf, FileError> {
    let Some(p) = cfg.params.get(name) else {
        return Err(cfg.pos.error(format!("a {} needs `{name}`", cfg.type_name)));
    };
    Ok(seabus_modules::system::beside(&cfg.pos, &p.value))
}

/// What a server module starts on its medium.
enum Server {
    Config(Option<Database>),
    /// The log file, its size limit and the old files kept: opened at start, so that checking a
    /// system creates nothing.
    Log(PathBuf, u64, u32),
}

struct ServerModule {
    port: u16,
    server: Server,
    /// Tells the logging server the system is stopping (it then writes at once).
    drain: Option<tokio::sync::watch::Sender<bool>>,
}

fn build_config(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let config = path_param(cfg, "config")?;
    let appdata = path_param(cfg, "appdata")?;
    let db = Database::open(&config, &appdata)?;
    let port = cfg.params.parse("port", "a port 0–65535")?.unwrap_or(0);
    Ok(Built {
        decl: Declaration::new(ModuleKind::Service),
        module: Box::new(ServerModule {
            port,
            server: Server::Config(Some(db)),
            drain: None,
        }),
    })
}

fn build_log(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let file = path_param(cfg, "file")?;
    let p = &cfg.params;
    let max_size: u64 = p
        .parse("max_size", "a size in bytes")?
        .unwrap_or(10_000_000);
    let keep: u32 = p.parse("keep", "a number of files")?.unwrap_or(5);
    let port = p.parse("port", "a port 0–65535")?.unwrap_or(0);
    Ok(Built {
        decl: Declaration::new(ModuleKind::Service),
        module: Box::new(ServerModule {
            port,
            server: Server::Log(file, max_size, keep),
            drain: None,
        }),
    })
}

#[async_trait]
impl Module for ServerModule {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let Some(medium) = ctx.port(0).map(|p| p.medium().clone()) else {
            return Err(ModuleError::msg("a DSAAV server needs a DSAAV medium"));
        };
        let port = self.port;
        // the server owns what it serves; it runs until the medium closes
        match &mut self.server {
            Server::Config(db) => {
                let Some(db) = db.take() else {
                    return Err(ModuleError::msg(
                        "the configuration server cannot start twice",
                    ));
                };
                tokio::spawn(async move { super::config_service::serve(&medium, port, db).await });
            }
            Server::Log(file, max_size, keep) => {
                let log = LogFile::open(file.clone(), *max_size, *keep).map_err(|e| {
                    ModuleError::msg(format!("cannot open the log {}: {e}", file.display()))
                })?;
                let (drain, draining) = tokio::sync::watch::channel(false);
                self.drain = Some(drain);
                tokio::spawn(
                    async move { super::logging::serve(&medium, port, log, draining).await },
                );
            }
        }
        Ok(())
    }

    async fn stop(&mut self, _: &mut Context) {
        // the records of the other modules' last moments are written as they come
        if let Some(d) = &self.drain {
            let _ = d.send(true);
        }
    }
}
