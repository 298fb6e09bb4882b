//! The STARFISH paper's depth-control example as module types, each a DSAAV component on its own
//! node, configured and plumbed only through the configuration service:
//!
//! - `starfish-vehicle-sim` (media: the Elevators node, then the DepthSensor node): a simple depth
//!   model — the depth changes at `rate` m/s per degree of elevator, nose up rising — serving the
//!   Elevators actuator and the DepthSensor sensor (both on port 0 of their nodes);
//! - `depth-filter` (its node): reads depth from the server its configuration names for `Depth`
//!   (`DepthFilter` overrides it to the sensor), smooths it, and serves it as the `Depth` sentuator;
//! - `depth-controller` (its node; component `MyDepthController` by default): reads depth from its
//!   `Depth` server, sets the elevators to `ControlGain × (depth − target)` (at most 30°), and logs
//!   each step at DEBUG through the logging service.
//!
//! Changing only the configuration file re-plumbs the data: with `[Depth] Server = 4:0` the
//! controller reads the sensor itself.

use super::config_service::ConfigClient;
use super::health::ComponentState;
use super::health_service::{self, DataHealth, Reporter, health_reply};
use super::logging::{Level, Logger};
use super::rpc::{self, CallOptions};
use super::sentuator::{self, Device, Sentuator, SentuatorClient, quantity};
use async_trait::async_trait;
use seabus_medium::xml::FileError;
use seabus_medium::{DataMap, Medium};
use seabus_medium_dsaav::wire::Address;
use seabus_modules::datasets::Catalogue;
use seabus_modules::module::{Context, Declaration, Module, ModuleError, ModuleKind, TimerId};
use seabus_modules::registry::{Built, ModuleConfig, ModuleType};
use seabus_modules::runtime::AbortOnDrop;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The `starfish-vehicle-sim` module type.
pub const VEHICLE_SIM: ModuleType = ModuleType {
    name: "starfish-vehicle-sim",
    kind: ModuleKind::Driver,
    summary: "simulated Elevators and DepthSensor sentuators over a simple depth model (DSAAV)",
    build: build_sim,
};

/// The `depth-filter` module type.
pub const DEPTH_FILTER: ModuleType = ModuleType {
    name: "depth-filter",
    kind: ModuleKind::Supporting,
    summary: "smooths depth from its configured source and serves it as the Depth sentuator",
    build: build_filter,
};

/// The `depth-controller` module type.
pub const DEPTH_CONTROLLER: ModuleType = ModuleType {
    name: "depth-controller",
    kind: ModuleKind::Supporting,
    summary: "holds a depth with the elevators, plumbed and tuned by the configuration",
    build: build_controller,
};

const TICK: Duration = Duration::from_millis(100);
/// The port components send their health updates from.
const HEALTH_PORT: u16 = 10;
/// How long a component may go without depth before it is UNAVAILABLE.
const GRACE: Duration = Duration::from_secs(1);

/// Largest elevator angle, degrees.
const MAX_ELEVATOR: f64 = 30.0;

fn opts() -> CallOptions {
    CallOptions {
        timeout: Duration::from_secs(2),
        ..CallOptions::default()
    }
}

fn medium(ctx: &Context, i: usize) -> Result<Medium, ModuleError> {
    ctx.port(i)
        .map(|p| p.medium().clone())
        .ok_or_else(|| ModuleError::msg(format!("needs a DSAAV medium as its medium {}", i + 1)))
}

/// The simulated vehicle's depth and elevator.
#[derive(Debug, Clone, Copy)]
struct Physics {
    depth: f64,
    elevator: f64,
    rate: f64,
}

struct SharedDevice<F>(Arc<Mutex<Physics>>, F);

impl<F: Fn(&mut Physics, Option<&DataMap>) -> Result<DataMap, (i64, String)> + Send + 'static>
    Device for SharedDevice<F>
{
    fn get(&mut self) -> DataMap {
        let mut p = self.0.lock().unwrap_or_else(|e| e.into_inner());
        (self.1)(&mut p, None).unwrap_or_default()
    }
    fn set(&mut self, values: &DataMap) -> super::rpc::Outcome {
        let mut p = self.0.lock().unwrap_or_else(|e| e.into_inner());
        (self.1)(&mut p, Some(values))
    }
}

/// What a simulated sentuator does with a get (`None`) or a set.
type Handler = fn(&mut Physics, Option<&DataMap>) -> super::rpc::Outcome;

struct VehicleSim {
    physics: Arc<Mutex<Physics>>,
    elevators: Option<Sentuator<SharedDevice<Handler>>>,
    sensor: Option<Sentuator<SharedDevice<Handler>>>,
    /// Health updates of Elevators and DepthSensor, when the configuration names a monitor.
    reporters: Vec<Reporter>,
}

fn build_sim(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    let physics = Physics {
        depth: p.float_or("depth", 10.0)?,
        elevator: 0.0,
        rate: p.float_or("rate", 0.1)?,
    };
    Ok(Built {
        decl: Declaration::new(ModuleKind::Driver).default_tick(TICK),
        module: Box::new(VehicleSim {
            physics: Arc::new(Mutex::new(physics)),
            elevators: None,
            sensor: None,
            reporters: Vec::new(),
        }),
    })
}

#[async_trait]
impl Module for VehicleSim {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let elevators: Handler = |p: &mut Physics, set: Option<&DataMap>| {
            if let Some(v) = set {
                match v.get_f64("elevator") {
                    Some(a) if a.abs() <= MAX_ELEVATOR => p.elevator = a,
                    Some(a) => {
                        return Err((5, format!("elevator {a}° is past ±{MAX_ELEVATOR}°")));
                    }
                    None => return Err((5, "set needs `elevator`".to_string())),
                }
            }
            Ok(DataMap::new()
                .with("quantity", quantity::ELEVATOR)
                .with("elevator", p.elevator))
        };
        let sensor: Handler = |p: &mut Physics, set: Option<&DataMap>| {
            if set.is_some() {
                return Err((3, "a sensor cannot be set".to_string()));
            }
            Ok(DataMap::new()
                .with("quantity", quantity::DEPTH)
                .with("measurement", sentuator::measurement::RAW)
                .with("depth", p.depth))
        };
        let (a, b) = (medium(ctx, 0)?, medium(ctx, 1)?);
        // the sensor's listeners, when a configuration server names any
        let quick = CallOptions {
            timeout: Duration::from_millis(500),
            ..opts()
        };
        let mut listeners = Vec::new();
        self.reporters.clear();
        if let Ok(cfg) = ConfigClient::discover(&b, 7, quick).await {
            if let Ok(text) = cfg.get_str("DepthSensor", "Listeners").await {
                listeners =
                    sentuator::parse_listeners("DepthSensor", &text).map_err(ModuleError::msg)?;
            }
            for (m, component) in [(&a, "Elevators"), (&b, "DepthSensor")] {
                if let Ok(r) = Reporter::from_service(m, HEALTH_PORT, component, &cfg).await {
                    self.reporters.push(r);
                }
            }
        }
        let shared = |h: Handler| SharedDevice(self.physics.clone(), h);
        self.elevators = Some(Sentuator::start(
            &a,
            0,
            9,
            shared(elevators),
            &["Elevators"],
            vec![],
        ));
        self.sensor = Some(Sentuator::start(
            &b,
            0,
            9,
            shared(sensor),
            &["DepthSensor"],
            listeners,
        ));
        Ok(())
    }

    async fn on_timer(&mut self, _: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        {
            let mut p = self.physics.lock().unwrap_or_else(|e| e.into_inner());
            // nose up (positive elevator) rises
            p.depth = (p.depth - p.rate * p.elevator * TICK.as_secs_f64()).max(0.0);
        }
        if let Some(sensor) = &self.sensor {
            sensor.notify().await;
        }
        for r in &mut self.reporters {
            r.update(ComponentState::Healthy).await;
        }
        Ok(())
    }
}

/// Finds the configuration server and the address `component` is to use for `service`.
async fn plumb(
    medium: &Medium,
    component: &str,
    service: &str,
) -> Result<(ConfigClient, Address), ModuleError> {
    let cfg = ConfigClient::discover(medium, 7, opts())
        .await
        .map_err(|e| ModuleError::msg(format!("no configuration server: {e}")))?;
    let at = cfg
        .server_of(component, service)
        .await
        .map_err(|e| ModuleError::msg(format!("{component}: {service}: {e}")))?;
    Ok((cfg, at))
}

struct DepthFilter {
    component: String,
    smoothing: f64,
    filtered: Arc<Mutex<Option<f64>>>,
    source: Option<(SentuatorClient, Address)>,
    server: Option<Box<dyn std::any::Any + Send>>,
    reporter: Option<Reporter>,
    health: DataHealth,
}

fn build_filter(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    Ok(Built {
        decl: Declaration::new(ModuleKind::Supporting).default_tick(TICK),
        module: Box::new(DepthFilter {
            component: p.str("component").unwrap_or("DepthFilter").to_string(),
            smoothing: p.float_or("smoothing", 0.5)?,
            filtered: Arc::default(),
            source: None,
            server: None,
            reporter: None,
            health: DataHealth::new(GRACE),
        }),
    })
}

#[async_trait]
impl Module for DepthFilter {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let m = medium(ctx, 0)?;
        let (cfg, at) = plumb(&m, &self.component, "Depth").await?;
        tracing::info!(component = %self.component, "depth from {at}");
        self.reporter = Reporter::from_service(&m, HEALTH_PORT, &self.component, &cfg)
            .await
            .ok();
        self.source = Some((SentuatorClient::new(&m, 8, opts()), at));
        let filtered = self.filtered.clone();
        let device = SharedDevice(
            Arc::new(Mutex::new(Physics {
                depth: 0.0,
                elevator: 0.0,
                rate: 0.0,
            })),
            move |_: &mut Physics, set: Option<&DataMap>| {
                if set.is_some() {
                    return Err((3, "filtered depth cannot be set".to_string()));
                }
                match *filtered.lock().unwrap_or_else(|e| e.into_inner()) {
                    Some(d) => Ok(DataMap::new()
                        .with("quantity", quantity::DEPTH)
                        .with("measurement", sentuator::measurement::FILTERED)
                        .with("depth", d)),
                    None => Err((4, "no depth yet".to_string())),
                }
            },
        );
        self.server = Some(Box::new(Sentuator::start(
            &m,
            0,
            9,
            device,
            &["Depth"],
            vec![],
        )));
        Ok(())
    }

    async fn on_timer(&mut self, _: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        let Some((client, at)) = &self.source else {
            return Ok(());
        };
        let got = match client.get(*at).await {
            Ok(r) => r.get_f64("depth").map(|d| {
                let mut f = self.filtered.lock().unwrap_or_else(|e| e.into_inner());
                let a = self.smoothing;
                *f = Some(f.map_or(d, |old| a * old + (1.0 - a) * d));
            }),
            Err(e) => {
                tracing::warn!(component = %self.component, "depth: {e}");
                None
            }
        };
        let state = self.health.update(got.is_some());
        if let Some(r) = &mut self.reporter {
            r.update(state).await;
        }
        Ok(())
    }
}

struct DepthController {
    component: String,
    target: f64,
    state: Option<Controller>,
}

struct Controller {
    /// Its health as it answers health calls: HEALTHY while it reads depth, else UNAVAILABLE.
    health: Arc<AtomicU8>,
    depth_health: DataHealth,
    /// Its health server, stopped with the module.
    _server: Option<AbortOnDrop>,
    sentuators: SentuatorClient,
    depth_at: Address,
    elevators_at: Address,
    gain: f64,
    log: Logger,
}

fn build_controller(cfg: &ModuleConfig, _: &Catalogue) -> Result<Built, FileError> {
    let p = &cfg.params;
    Ok(Built {
        decl: Declaration::new(ModuleKind::Supporting).default_tick(TICK),
        module: Box::new(DepthController {
            component: p
                .str("component")
                .unwrap_or("MyDepthController")
                .to_string(),
            target: p.float_or("target", 5.0)?,
            state: None,
        }),
    })
}

#[async_trait]
impl Module for DepthController {
    async fn start(&mut self, ctx: &mut Context) -> Result<(), ModuleError> {
        let m = medium(ctx, 0)?;
        let c = self.component.as_str();
        let (cfg, depth_at) = plumb(&m, c, "Depth").await?;
        let elevators_at = cfg
            .server_of(c, "Elevators")
            .await
            .map_err(|e| ModuleError::msg(format!("{c}: Elevators: {e}")))?;
        let gain = cfg
            .get_float(c, "ControlGain")
            .await
            .map_err(|e| ModuleError::msg(format!("{c}: ControlGain: {e}")))?;
        let log = Logger::from_service(&m, 6, c, &cfg, opts())
            .await
            .map_err(|e| ModuleError::msg(format!("{c}: logging: {e}")))?;
        let _ = log
            .log(
                Level::Info,
                &format!("depth from {depth_at}, elevators at {elevators_at}, gain {gain}"),
            )
            .await;
        // polled by the health monitor where its configuration says it is served
        let health = Arc::new(AtomicU8::new(ComponentState::Healthy.code()));
        let server = match cfg.server_of(c, c).await {
            Ok(at) => {
                let (m, h) = (m.clone(), health.clone());
                let task = tokio::spawn(async move {
                    rpc::serve(&m, at.port, &[], move |call| match call.op {
                        health_service::ops::HEALTH => {
                            let state = ComponentState::from_code(h.load(Ordering::Relaxed).into())
                                .unwrap_or(ComponentState::Malfunction);
                            Ok(health_reply(state, ""))
                        }
                        op => Err((3, format!("operation {op} is not served here"))),
                    })
                    .await
                });
                Some(AbortOnDrop(task.abort_handle()))
            }
            Err(_) => None,
        };
        self.state = Some(Controller {
            health,
            depth_health: DataHealth::new(GRACE),
            _server: server,
            sentuators: SentuatorClient::new(&m, 8, opts()),
            depth_at,
            elevators_at,
            gain,
            log,
        });
        Ok(())
    }

    async fn on_timer(&mut self, _: &mut Context, _: TimerId) -> Result<(), ModuleError> {
        let Some(c) = &mut self.state else {
            return Ok(());
        };
        let depth = match c.sentuators.get(c.depth_at).await {
            Ok(r) => r.get_f64("depth"),
            Err(e) => {
                let _ = c.log.log(Level::Warning, &format!("no depth: {e}")).await;
                None
            }
        };
        let state = c.depth_health.update(depth.is_some());
        c.health.store(state.code(), Ordering::Relaxed);
        let Some(depth) = depth else {
            return Ok(());
        };
        let elevator = (c.gain * (depth - self.target)).clamp(-MAX_ELEVATOR, MAX_ELEVATOR);
        let set = DataMap::new().with("elevator", elevator);
        if let Err(e) = c.sentuators.set(c.elevators_at, &set).await {
            let _ = c.log.log(Level::Warning, &format!("elevators: {e}")).await;
        }
        let _ = c
            .log
            .log(
                Level::Debug,
                &format!(
                    "depth={depth:.3} target={:.3} elevator={elevator:.3}",
                    self.target
                ),
            )
            .await;
        Ok(())
    }
}
