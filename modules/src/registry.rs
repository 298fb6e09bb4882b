//! The registry of module, bridge and service types, by name, with the program's medium schemes.
//!
//! Each crate that provides modules registers its types (`seabus-modules` the supporting modules,
//! `seabus-drivers` the drivers and simulators, `seabus-bridges` the bridges, `seabus-ui` the
//! console); the program puts them all in one [`Registry`]. A type builds a fresh module from its
//! configuration, without side effects, so that `seabus check` can build every module to validate
//! it and the runtime can build a new instance after a failure.

use crate::datasets::Catalogue;
use crate::module::{Declaration, Module, ModuleKind};
use crate::params::Params;
use crate::system::{BridgeSpec, SystemSpec};
use seabus_medium::xml::{Element, FileError, Pos};
use seabus_medium::{BoxFuture, Capabilities, Medium, Node, Schemes};
use std::collections::BTreeMap;
use std::time::Duration;

/// A module as placed in a system file.
#[derive(Debug, Clone, PartialEq)]
pub struct ModuleConfig {
    /// Its name in the system.
    pub name: String,
    /// Its type's name.
    pub type_name: String,
    /// The media it is attached to, one port each, in order.
    pub media: Vec<String>,
    /// Timer [`crate::module::TICK`] period, from the `tick` attribute.
    pub tick: Option<Duration>,
    /// Its parameters.
    pub params: Params,
    /// Where it is written.
    pub pos: Pos,
}

/// A freshly built module and its declaration.
pub struct Built {
    /// What it produces, consumes and accepts.
    pub decl: Declaration,
    /// The module.
    pub module: Box<dyn Module>,
}

/// How a module type builds modules.
pub type BuildModule = fn(&ModuleConfig, &Catalogue) -> Result<Built, FileError>;

/// How a bridge type builds bridges: from the bridge's system-file form and what its two media can
/// do, in the order of [`BridgeSpec::media`].
pub type BuildBridge = fn(&BridgeSpec, &[Capabilities; 2], &Catalogue) -> Result<Built, FileError>;

/// A module type.
#[derive(Clone)]
pub struct ModuleType {
    /// Name used in `type="…"`.
    pub name: &'static str,
    /// Kind of the modules it builds.
    pub kind: ModuleKind,
    /// One-line description.
    pub summary: &'static str,
    /// Builder.
    pub build: BuildModule,
}

/// A bridge type.
#[derive(Clone)]
pub struct BridgeType {
    /// Name used in `<bridge type="…">`.
    pub name: &'static str,
    /// One-line description.
    pub summary: &'static str,
    /// Builder.
    pub build: BuildBridge,
}

/// How a service starts: from its element, on the system's opened media, as `node`.
pub type StartService =
    fn(&Element, &BTreeMap<String, Medium>, &Node) -> Result<Box<dyn Service>, FileError>;

/// A service a crate runs beside a system's modules, from a top-level element of the system file
/// it reads (the DSAAV crate's `<log>`).
#[derive(Clone, Copy)]
pub struct ServiceType {
    /// The element's name.
    pub tag: &'static str,
    /// Checks one such element against the system, without starting anything.
    pub check: fn(&Element, &SystemSpec, &Registry) -> Result<(), FileError>,
    /// Starts it on the system's opened media, before any module starts.
    pub start: StartService,
}

/// A running service: it is finished when the system shuts down, after the modules have stopped
/// and before the media close.
pub trait Service: Send + Sync {
    /// Finishes within `within` (what it still holds goes out).
    fn finish(self: Box<Self>, within: Duration) -> BoxFuture<'static, ()>;
}

/// Module, bridge and service types by name, and the medium schemes of the program.
#[derive(Clone, Default)]
pub struct Registry {
    modules: BTreeMap<&'static str, ModuleType>,
    bridges: BTreeMap<&'static str, BridgeType>,
    services: BTreeMap<&'static str, ServiceType>,
    sections: Vec<&'static str>,
    schemes: Schemes,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Registry {
        Registry::default()
    }

    /// The medium schemes systems may use.
    pub fn schemes(&self) -> &Schemes {
        &self.schemes
    }

    /// Sets the medium schemes systems may use (by default the in-process medium only).
    pub fn set_schemes(&mut self, schemes: Schemes) -> &mut Self {
        self.schemes = schemes;
        self
    }

    /// What the medium at `url` can do, or the URL's error placed at `pos`.
    pub fn capabilities(&self, url: &str, pos: &Pos) -> Result<Capabilities, FileError> {
        self.schemes
            .check(url)
            .map_err(|e| pos.error(e.to_string()))
    }

    /// Adds a module type (replacing one of the same name).
    pub fn add_module(&mut self, t: ModuleType) -> &mut Self {
        self.modules.insert(t.name, t);
        self
    }

    /// Adds a bridge type (replacing one of the same name).
    pub fn add_bridge(&mut self, t: BridgeType) -> &mut Self {
        self.bridges.insert(t.name, t);
        self
    }

    /// Adds a service type; its element becomes a known section.
    pub fn add_service(&mut self, t: ServiceType) -> &mut Self {
        self.add_section(t.tag);
        self.services.insert(t.tag, t);
        self
    }

    /// The service that reads top-level elements called `tag`.
    pub fn service(&self, tag: &str) -> Option<&ServiceType> {
        self.services.get(tag)
    }

    /// Declares a top-level system-file element (such as `console`) that a registered crate reads.
    pub fn add_section(&mut self, tag: &'static str) -> &mut Self {
        if !self.sections.contains(&tag) {
            self.sections.push(tag);
        }
        self
    }

    /// The top-level elements registered crates read.
    pub fn sections(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.sections.iter().copied()
    }

    /// The module type called `name`.
    pub fn module(&self, name: &str) -> Option<&ModuleType> {
        self.modules.get(name)
    }

    /// The bridge type called `name`.
    pub fn bridge(&self, name: &str) -> Option<&BridgeType> {
        self.bridges.get(name)
    }

    /// Every module type.
    pub fn module_types(&self) -> impl Iterator<Item = &ModuleType> {
        self.modules.values()
    }

    /// Every bridge type.
    pub fn bridge_types(&self) -> impl Iterator<Item = &BridgeType> {
        self.bridges.values()
    }

    /// The module type `name` of `cfg`, or an error listing the known ones.
    pub fn module_for(&self, cfg: &ModuleConfig) -> Result<&ModuleType, FileError> {
        self.module(&cfg.type_name).ok_or_else(|| {
            cfg.pos.error(format!(
                "unknown module type `{}`; known types: {}",
                cfg.type_name,
                self.modules.keys().copied().collect::<Vec<_>>().join(", ")
            ))
        })
    }

    /// The bridge type of `spec`, or an error listing the known ones.
    pub fn bridge_for(&self, spec: &BridgeSpec) -> Result<&BridgeType, FileError> {
        self.bridge(&spec.type_name).ok_or_else(|| {
            spec.pos.error(format!(
                "unknown bridge type `{}`; known types: {}",
                spec.type_name,
                self.bridges.keys().copied().collect::<Vec<_>>().join(", ")
            ))
        })
    }

    /// Builds the module `cfg` describes, checking that its parameters were all used and that its
    /// declaration fits the media it is placed on.
    pub fn build_module(
        &self,
        cfg: &ModuleConfig,
        catalogue: &Catalogue,
    ) -> Result<Built, FileError> {
        let t = self.module_for(cfg)?;
        let built = (t.build)(cfg, catalogue)?;
        cfg.params.finish(t.name)?;
        check_ports(&built.decl, cfg.media.len(), &cfg.pos, &cfg.name)?;
        Ok(built)
    }

    /// Builds the bridge `spec` describes.
    pub fn build_bridge(
        &self,
        spec: &BridgeSpec,
        catalogue: &Catalogue,
    ) -> Result<Built, FileError> {
        let t = self.bridge_for(spec)?;
        let caps = [
            self.capabilities(&spec.urls[0], &spec.pos)?,
            self.capabilities(&spec.urls[1], &spec.pos)?,
        ];
        let built = (t.build)(spec, &caps, catalogue)?;
        spec.params.finish(t.name)?;
        Ok(built)
    }
}

fn check_ports(decl: &Declaration, ports: usize, pos: &Pos, name: &str) -> Result<(), FileError> {
    let wanted = decl
        .produces
        .iter()
        .chain(&decl.consumes)
        .chain(&decl.accepts)
        .map(|t| t.port + 1)
        .max()
        .unwrap_or(0)
        .max(decl.formats.len());
    if wanted > ports {
        return Err(pos.error(format!(
            "module `{name}` needs {wanted} media (attribute `media`, in order), it is placed on {ports}"
        )));
    }
    Ok(())
}
