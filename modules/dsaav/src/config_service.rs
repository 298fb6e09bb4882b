//! The configuration service over RPC: a server holding the configuration [`Database`], found by a
//! broadcast call, and the client components use to read settings, keep application data and
//! resolve the addresses of the services they use (the "data plumbing").
//!
//! Operations ([`ops`]) carry text in the dictionary keys `section`, `key`, `value`, `component`
//! and `service`; a failure's status is 4 for a missing setting, 5 for a value or name that is
//! not valid, 6 when the application data could not be written.

use super::config::{Database, StoreError, ValueError};
use super::rpc::{self, CallOptions, Outcome, RpcClient, RpcError};
use seabus_medium::{DataMap, Medium};
use seabus_medium_dsaav::wire::Address;

/// The configuration service's operation ids.
pub mod ops {
    /// Answers, so that a broadcast finds the server.
    pub const HELLO: i32 = 100;
    /// The value of `section`.`key` (application data first).
    pub const GET: i32 = 101;
    /// Puts `value` at `section`.`key` in the application data.
    pub const PUT: i32 = 102;
    /// Removes `section`.`key` (or the whole `section`) from the application data.
    pub const REMOVE: i32 = 103;
    /// The address of `service` for `component`.
    pub const SERVER_OF: i32 = 104;
    /// `key` of `service` as `component` sees it.
    pub const SETTING: i32 = 105;
}

/// Every operation the server offers.
pub const OPERATIONS: [i32; 6] = [
    ops::HELLO,
    ops::GET,
    ops::PUT,
    ops::REMOVE,
    ops::SERVER_OF,
    ops::SETTING,
];

fn value_error(e: ValueError) -> (i64, String) {
    let code = match e {
        ValueError::Missing { .. } | ValueError::NoSetting { .. } => 4,
        _ => 5,
    };
    (code, e.to_string())
}

fn store_error(e: StoreError) -> (i64, String) {
    let code = match e {
        StoreError::Write { .. } => 6,
        _ => 5,
    };
    (code, e.to_string())
}

fn text<'a>(p: &'a DataMap, key: &str) -> Result<&'a str, (i64, String)> {
    p.get_str(key)
        .ok_or_else(|| (5, format!("the call needs `{key}` (text)")))
}

fn answer(value: &str) -> DataMap {
    DataMap::new().with("value", value)
}

/// Answers one call on the database.
fn handle(db: &mut Database, op: i32, p: &DataMap) -> Outcome {
    match op {
        ops::HELLO => Ok(DataMap::new()),
        ops::GET => {
            let v = db.get_str(text(p, "section")?, text(p, "key")?);
            v.map(answer).map_err(value_error)
        }
        ops::PUT => db
            .put_str(text(p, "section")?, text(p, "key")?, text(p, "value")?)
            .map(|()| DataMap::new())
            .map_err(store_error),
        ops::REMOVE => {
            let section = text(p, "section")?;
            let removed = match p.get_str("key") {
                Some(key) => db.remove(section, key),
                None => db.remove_section(section),
            };
            removed
                .map(|found| DataMap::new().with("count", i64::from(found)))
                .map_err(store_error)
        }
        ops::SERVER_OF => db
            .server_of(text(p, "component")?, text(p, "service")?)
            .map(|a| answer(&a.to_string()))
            .map_err(value_error),
        ops::SETTING => db
            .setting(text(p, "component")?, text(p, "service")?, text(p, "key")?)
            .map(|v| answer(v.as_str()))
            .map_err(value_error),
        super::health_service::ops::HEALTH => Ok(super::health_service::health_reply(
            super::health::ComponentState::Healthy,
            "Configuration",
        )),
        op => Err((
            3,
            format!("operation {op} is not a configuration operation"),
        )),
    }
}

/// Serves the configuration database on `port` of the medium's node until the medium closes.
pub async fn serve(medium: &Medium, port: u16, mut db: Database) {
    rpc::serve(medium, port, &OPERATIONS, move |call| {
        handle(&mut db, call.op, &call.params)
    })
    .await
}

/// A component's way to the configuration service.
pub struct ConfigClient {
    rpc: RpcClient,
    server: Address,
    opts: CallOptions,
}

impl ConfigClient {
    /// Finds the configuration server by a broadcast call from `port` of the medium's node.
    pub async fn discover(
        medium: &Medium,
        port: u16,
        opts: CallOptions,
    ) -> Result<ConfigClient, RpcError> {
        let rpc = RpcClient::new(medium, port);
        let (server, _) = rpc.discover(ops::HELLO, &DataMap::new(), opts).await?;
        Ok(ConfigClient { rpc, server, opts })
    }

    /// The server's address.
    pub fn server(&self) -> Address {
        self.server
    }

    async fn call(&self, op: i32, params: DataMap) -> Result<DataMap, RpcError> {
        self.rpc.call(self.server, op, &params, self.opts).await
    }

    async fn value(&self, op: i32, params: DataMap) -> Result<String, RpcError> {
        let reply = self.call(op, params).await?;
        Ok(reply.get_str("value").unwrap_or("").to_string())
    }

    /// The text of `section`.`key` (application data masking configuration data).
    pub async fn get_str(&self, section: &str, key: &str) -> Result<String, RpcError> {
        let p = DataMap::new().with("section", section).with("key", key);
        self.value(ops::GET, p).await
    }

    /// `section`.`key` as a number; text that is not one is reported as a failed call.
    pub async fn get_float(&self, section: &str, key: &str) -> Result<f64, RpcError> {
        let text = self.get_str(section, key).await?;
        text.trim().parse().map_err(|_| RpcError::Failed {
            from: self.server.to_string(),
            op: ops::GET,
            status: 5,
            message: format!("[{section}] {key} = `{text}` is not a number"),
        })
    }

    /// Puts `value` at `section`.`key` in the application data (kept across restarts).
    pub async fn put(&self, section: &str, key: &str, value: &str) -> Result<(), RpcError> {
        let p = DataMap::new()
            .with("section", section)
            .with("key", key)
            .with("value", value);
        self.call(ops::PUT, p).await.map(|_| ())
    }

    /// Removes `section`.`key` from the application data, unmasking the configuration value;
    /// true when there was one.
    pub async fn remove(&self, section: &str, key: &str) -> Result<bool, RpcError> {
        let p = DataMap::new().with("section", section).with("key", key);
        let reply = self.call(ops::REMOVE, p).await?;
        Ok(reply.get_i64("count") == Some(1))
    }

    /// The address of `service` as `component` is to use it.
    pub async fn server_of(&self, component: &str, service: &str) -> Result<Address, RpcError> {
        let p = DataMap::new()
            .with("component", component)
            .with("service", service);
        let text = self.value(ops::SERVER_OF, p).await?;
        text.parse().map_err(
            |e: seabus_medium_dsaav::wire::AddressError| RpcError::Failed {
                from: self.server.to_string(),
                op: ops::SERVER_OF,
                status: 5,
                message: e.to_string(),
            },
        )
    }

    /// `key` of `service` as `component` sees it (its own `Service.Key` first).
    pub async fn setting(
        &self,
        component: &str,
        service: &str,
        key: &str,
    ) -> Result<String, RpcError> {
        let p = DataMap::new()
            .with("component", component)
            .with("service", service)
            .with("key", key);
        self.value(ops::SETTING, p).await
    }
}
