//! The DSAAV RPC layer over an IComms medium (`dsaav+…://`): procedure calls identified by the
//! destination address and an operation id, with parameters in and out.
//!
//! - **Reliable calls** ([`RpcClient::call`]): the request (`dsaav.rpc-request`, `@id` chosen by
//!   the client) is sent again, with back-off, until its reply (`dsaav.rpc-reply`, `@ref` = the
//!   request's id) arrives; the reply is the acknowledgement. After the call's timeout the caller
//!   gets [`RpcError::Timeout`]. The server remembers the replies it sent by client address and
//!   request id, so a request that arrives twice (a retry, or a duplicate on the wire) is answered
//!   again from memory and the procedure runs exactly once.
//! - **Unreliable calls** ([`RpcClient::call_unreliable`], `dsaav.rpc-oneway`): sent once, no reply,
//!   run at most once.
//! - **Broadcast calls** ([`RpcClient::discover`]): a request to the RPC channel that every server
//!   offering the operation answers; the first reply names the service's address (how a component
//!   finds the configuration server).
//!
//! A reply's `status` is 0 when the procedure ran, else an error code with `error` saying why
//! ([`RpcError::Failed`]).

use seabus_medium::{DataMap, Interface, Medium, Payload, SendError, Topic, Value};
use seabus_medium_dsaav::wire::Address;
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;
use thiserror::Error;
use tokio::sync::oneshot;

/// The channel broadcast calls go to.
pub const RPC_CHANNEL: u16 = 1;
/// The status of a reply whose results could not be sent.
pub const UNSENDABLE: i64 = 7;

/// Replies a server remembers to answer repeated requests.
pub const REMEMBERED_REPLIES: usize = 65_536;

/// The topics of the three RPC messages, made once.
struct Topics {
    request: Topic,
    oneway: Topic,
    reply: Topic,
}

fn topics() -> &'static Topics {
    static TOPICS: OnceLock<Topics> = OnceLock::new();
    TOPICS.get_or_init(|| {
        let topic = |name| Topic::new(name).expect("the RPC topics are valid");
        Topics {
            request: topic("dsaav.rpc-request"),
            oneway: topic("dsaav.rpc-oneway"),
            reply: topic("dsaav.rpc-reply"),
        }
    })
}

/// The datamap of a payload, owned: taken as it is when nobody else holds it, else copied.
fn owned(map: Arc<DataMap>) -> DataMap {
    Arc::try_unwrap(map).unwrap_or_else(|shared| (*shared).clone())
}

/// How a reliable call waits and retries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CallOptions {
    /// Give up after this long.
    pub timeout: Duration,
    /// Wait this long for the reply before the first retry.
    pub first_retry: Duration,
    /// Longest wait between retries (each wait doubles up to it).
    pub max_retry: Duration,
}

impl Default for CallOptions {
    fn default() -> Self {
        CallOptions {
            timeout: Duration::from_secs(5),
            first_retry: Duration::from_millis(20),
            max_retry: Duration::from_millis(500),
        }
    }
}

/// Why a call did not return results.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RpcError {
    /// No reply within the timeout, after this many attempts.
    #[error("no reply from {to} to operation {op} within {timeout:?} ({attempts} attempts)")]
    Timeout {
        /// Who was called (`channel N` for a broadcast).
        to: String,
        /// The operation.
        op: i32,
        /// The timeout.
        timeout: Duration,
        /// Requests sent.
        attempts: u32,
    },
    /// The procedure ran and failed.
    #[error("operation {op} at {from} failed ({status}): {message}")]
    Failed {
        /// The server.
        from: String,
        /// The operation.
        op: i32,
        /// Its error code.
        status: i64,
        /// What it said.
        message: String,
    },
    /// The request could not be sent.
    #[error(transparent)]
    Send(#[from] SendError),
}

type Waiters = Arc<Mutex<HashMap<u32, oneshot::Sender<DataMap>>>>;

/// Makes calls from one port of a node.
pub struct RpcClient {
    port: u16,
    iface: Interface,
    next_id: AtomicU32,
    waiters: Waiters,
    reader: tokio::task::JoinHandle<()>,
}

impl Drop for RpcClient {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

impl RpcClient {
    /// A client on `port` of the medium's node; replies to it are read by a task of its own.
    pub fn new(medium: &Medium, port: u16) -> RpcClient {
        let mut replies = medium.attach(&format!("rpc-client-{port}"));
        let _ = replies.subscribe("dsaav.rpc-reply");
        let waiters: Waiters = Arc::default();
        let w = waiters.clone();
        let reader = tokio::spawn(async move {
            while let Some(m) = replies.recv().await {
                let Payload::Map(map) = m.payload else {
                    continue;
                };
                // replies to other ports of this node are theirs
                let to_me = map
                    .get_str("@dst")
                    .and_then(|d| d.parse::<Address>().ok())
                    .is_some_and(|a| a.port == port);
                let reference = map.get_i64("@ref").and_then(|r| u32::try_from(r).ok());
                if let (true, Some(r)) = (to_me, reference) {
                    let waiter = w.lock().unwrap_or_else(|p| p.into_inner()).remove(&r);
                    if let Some(tx) = waiter {
                        let _ = tx.send(owned(map));
                    }
                }
            }
        });
        RpcClient {
            port,
            iface: medium.attach(&format!("rpc-out-{port}")),
            next_id: AtomicU32::new(fastrand::u32(1..u32::MAX / 2)),
            waiters,
            reader,
        }
    }

    fn request(&self, id: u32, to: Option<Address>, op: i32, params: &DataMap) -> DataMap {
        let mut map = DataMap::with_capacity(params.len() + 4);
        match to {
            Some(a) => map.push("@dst", a.to_string()),
            None => map.push("@channel", i64::from(RPC_CHANNEL)),
        }
        map.push("@port", i64::from(self.port));
        map.push("@id", i64::from(id));
        map.push("op", i64::from(op));
        for (k, v) in params.entries() {
            map.push(k.clone(), v.clone());
        }
        map
    }

    /// Calls `op` at `to` and waits for its results, retrying as `opts` says.
    pub async fn call(
        &self,
        to: Address,
        op: i32,
        params: &DataMap,
        opts: CallOptions,
    ) -> Result<DataMap, RpcError> {
        self.reliable(Some(to), op, params, opts).await
    }

    /// Calls `op` on whichever server on the RPC channel offers it; returns its address and the
    /// results.
    pub async fn discover(
        &self,
        op: i32,
        params: &DataMap,
        opts: CallOptions,
    ) -> Result<(Address, DataMap), RpcError> {
        let reply = self.reliable(None, op, params, opts).await?;
        let from = reply
            .get_str("@src")
            .and_then(|s| s.parse().ok())
            .unwrap_or(Address { node: 0, port: 0 });
        Ok((from, reply))
    }

    async fn reliable(
        &self,
        to: Option<Address>,
        op: i32,
        params: &DataMap,
        opts: CallOptions,
    ) -> Result<DataMap, RpcError> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let (tx, mut rx) = oneshot::channel();
        self.waiters
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(id, tx);
        // made once, shared by every attempt
        let request = Payload::from(self.request(id, to, op, params));
        let deadline = tokio::time::Instant::now() + opts.timeout;
        let mut wait = opts.first_retry;
        let mut attempts = 0;
        let result = loop {
            if let Err(e) = self.iface.send(&topics().request, request.clone()).await {
                break Err(RpcError::Send(e));
            }
            attempts += 1;
            let until = (tokio::time::Instant::now() + wait).min(deadline);
            match tokio::time::timeout_at(until, &mut rx).await {
                Ok(Ok(reply)) => break Ok(reply),
                Ok(Err(_)) | Err(_) if tokio::time::Instant::now() >= deadline => {
                    break Err(RpcError::Timeout {
                        to: to.map_or_else(|| format!("channel {RPC_CHANNEL}"), |a| a.to_string()),
                        op,
                        timeout: opts.timeout,
                        attempts,
                    });
                }
                _ => wait = (wait * 2).min(opts.max_retry),
            }
        };
        self.waiters
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&id);
        let reply = result?;
        match reply.get_i64("status").unwrap_or(0) {
            0 => Ok(reply),
            status => Err(RpcError::Failed {
                from: reply.get_str("@src").unwrap_or("?").to_string(),
                op,
                status,
                message: reply.get_str("error").unwrap_or("").to_string(),
            }),
        }
    }

    /// Sends `op` to `to` once, without waiting for anything.
    pub async fn call_unreliable(
        &self,
        to: Address,
        op: i32,
        params: &DataMap,
    ) -> Result<(), SendError> {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        self.iface
            .send(&topics().oneway, self.request(id, Some(to), op, params))
            .await
    }
}

/// What a procedure returns: its results, or an error code and message.
pub type Outcome = Result<DataMap, (i64, String)>;

/// A call as a server sees it.
#[derive(Debug, Clone)]
pub struct Call {
    /// Who called.
    pub from: Address,
    /// The operation.
    pub op: i32,
    /// The parameters (without the header and `op`).
    pub params: DataMap,
    /// Whether the caller waits for a reply.
    pub reliable: bool,
}

/// Serves calls on one port of a node: runs `handler` once per distinct request, whatever the
/// wire repeats, and replies. Returns when the medium closes.
pub async fn serve(
    medium: &Medium,
    port: u16,
    ops: &[i32],
    mut handler: impl FnMut(Call) -> Outcome,
) {
    let mut iface = medium.attach(&format!("rpc-server-{port}"));
    let _ = iface.subscribe("dsaav.rpc-request");
    let _ = iface.subscribe("dsaav.rpc-oneway");
    let mut replies: HashMap<(Address, u32), Payload> = HashMap::new();
    let mut order: VecDeque<(Address, u32)> = VecDeque::new();
    while let Some(m) = iface.recv().await {
        let reliable = m.topic == topics().request;
        let Payload::Map(map) = m.payload else {
            continue;
        };
        let header = |k: &str| map.get_str(k).and_then(|s| s.parse::<Address>().ok());
        let (Some(from), Some(id), Some(op)) = (
            header("@src"),
            map.get_i64("@id").and_then(|i| u32::try_from(i).ok()),
            map.get_i64("op").and_then(|o| i32::try_from(o).ok()),
        ) else {
            continue;
        };
        let broadcast = map.get("@channel").is_some();
        let for_me = match header("@dst") {
            Some(dst) => dst.port == port,
            None => broadcast && ops.contains(&op),
        };
        if !for_me {
            continue;
        }
        let key = (from, id);
        if let Some(reply) = replies.get(&key) {
            // a repeated request: answered again, not run again
            if reliable {
                let _ = iface.send(&topics().reply, reply.clone()).await;
            }
            continue;
        }
        let mut params = owned(map).into_entries();
        params.retain(|(k, _)| !k.starts_with('@') && k != "op");
        let params = DataMap::from_entries(params);
        let outcome = handler(Call {
            from,
            op,
            params,
            reliable,
        });
        let mut reply = DataMap::new()
            .with("@dst", from.to_string())
            .with("@port", i64::from(port))
            .with("@ref", i64::from(id));
        match outcome {
            Ok(results) => {
                reply.push("status", 0i64);
                for (k, v) in results.into_entries() {
                    reply.push(k, v);
                }
            }
            Err((status, message)) => {
                reply.push("status", Value::Int(status.max(1)));
                reply.push("error", message);
            }
        }
        if order.len() >= REMEMBERED_REPLIES
            && let Some(old) = order.pop_front()
        {
            replies.remove(&old);
        }
        order.push_back(key);
        // kept for repeated requests and sent, shared
        let mut reply = Payload::from(reply);
        if reliable && let Err(e) = iface.send(&topics().reply, reply.clone()).await {
            // results the wire cannot carry (a key not in the dictionary, too large): the caller
            // hears why instead of waiting for its timeout
            reply = Payload::from(
                DataMap::new()
                    .with("@dst", from.to_string())
                    .with("@port", i64::from(port))
                    .with("@ref", i64::from(id))
                    .with("status", UNSENDABLE)
                    .with("error", format!("the results cannot be sent: {e}")),
            );
            let _ = iface.send(&topics().reply, reply.clone()).await;
        }
        replies.insert(key, reply);
    }
}
