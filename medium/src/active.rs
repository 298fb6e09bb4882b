//! Active mode: the interface drives the module.
//!
//! The module registers a [`Handler`]. The interface hands every incoming message to
//! [`Handler::on_receive`] and, whenever it is ready to transmit, asks [`Handler::on_transmit`] for
//! outgoing data until the handler has none. It is ready to transmit when it starts, after each
//! received message, when the module wakes it through a [`TxWaker`], at an optional polling period,
//! and as soon as the previous send has gone out (a slow wire paces the module).

use crate::medium::{Interface, SendError};
use crate::message::{Kind, Message};
use crate::payload::Payload;
use crate::topic::Topic;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::Notify;
use tokio::task::JoinHandle;

/// Outgoing data an active handler hands to its interface.
#[derive(Debug, Clone)]
pub struct Outgoing {
    /// Topic to publish on.
    pub topic: Topic,
    /// Data or command.
    pub kind: Kind,
    /// The payload, in any format.
    pub payload: Payload,
}

impl Outgoing {
    /// Outgoing data.
    pub fn data(topic: Topic, payload: impl Into<Payload>) -> Outgoing {
        Outgoing {
            topic,
            kind: Kind::Data,
            payload: payload.into(),
        }
    }

    /// An outgoing command.
    pub fn command(topic: Topic, payload: impl Into<Payload>) -> Outgoing {
        Outgoing {
            topic,
            kind: Kind::Command,
            payload: payload.into(),
        }
    }
}

/// The event handlers a module registers with an active interface.
pub trait Handler: Send + 'static {
    /// Called with each incoming message, in the interface's accepted format.
    fn on_receive(&mut self, msg: Message);
    /// Called when the interface is ready to transmit; `None` when there is nothing to send.
    fn on_transmit(&mut self) -> Option<Outgoing>;
    /// Called when a send fails; the default logs it.
    fn on_send_error(&mut self, err: SendError) {
        tracing::warn!("active interface send failed: {err}");
    }
}

/// Handlers made of two closures.
pub struct FnHandler<R, T> {
    receive: R,
    transmit: T,
}

impl<R, T> Handler for FnHandler<R, T>
where
    R: FnMut(Message) + Send + 'static,
    T: FnMut() -> Option<Outgoing> + Send + 'static,
{
    fn on_receive(&mut self, msg: Message) {
        (self.receive)(msg)
    }
    fn on_transmit(&mut self) -> Option<Outgoing> {
        (self.transmit)()
    }
}

/// Builds a handler from a receive closure and a transmit closure.
pub fn handler<R, T>(receive: R, transmit: T) -> FnHandler<R, T>
where
    R: FnMut(Message) + Send + 'static,
    T: FnMut() -> Option<Outgoing> + Send + 'static,
{
    FnHandler { receive, transmit }
}

/// Tells an active interface that its module has data to send.
#[derive(Clone)]
pub struct TxWaker {
    notify: Arc<Notify>,
}

impl TxWaker {
    /// Asks the interface to call [`Handler::on_transmit`] soon.
    pub fn wake(&self) {
        self.notify.notify_one();
    }
}

/// An interface in active mode, running its handler on a task. Dropping it stops the task.
pub struct ActiveInterface<H: Handler> {
    task: Option<JoinHandle<(Interface, H)>>,
    notify: Arc<Notify>,
    stop: Arc<Notify>,
    sent: Arc<AtomicU64>,
}

impl<H: Handler> ActiveInterface<H> {
    /// Starts driving `handler` from `iface`; `poll` adds a periodic transmit opportunity.
    /// Must be called inside a tokio runtime.
    pub fn spawn(iface: Interface, handler: H, poll: Option<Duration>) -> ActiveInterface<H> {
        let notify = Arc::new(Notify::new());
        let stop = Arc::new(Notify::new());
        let sent = Arc::new(AtomicU64::new(0));
        let task = tokio::spawn(drive(
            iface,
            handler,
            poll,
            notify.clone(),
            stop.clone(),
            sent.clone(),
        ));
        ActiveInterface {
            task: Some(task),
            notify,
            stop,
            sent,
        }
    }

    /// A handle the module uses to say it has data to send.
    pub fn waker(&self) -> TxWaker {
        TxWaker {
            notify: self.notify.clone(),
        }
    }

    /// Messages sent so far on the handler's behalf.
    pub fn sent(&self) -> u64 {
        self.sent.load(Ordering::Relaxed)
    }

    /// Stops driving and gives back the interface and the handler.
    pub async fn stop(mut self) -> Option<(Interface, H)> {
        self.stop.notify_one();
        self.task.take()?.await.ok()
    }
}

impl<H: Handler> Drop for ActiveInterface<H> {
    fn drop(&mut self) {
        if let Some(task) = self.task.take() {
            task.abort();
        }
    }
}

async fn drive<H: Handler>(
    mut iface: Interface,
    mut handler: H,
    poll: Option<Duration>,
    notify: Arc<Notify>,
    stop: Arc<Notify>,
    sent: Arc<AtomicU64>,
) -> (Interface, H) {
    let mut ticker = poll.map(|p| {
        let mut t = tokio::time::interval(p);
        t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        t
    });
    loop {
        while let Some(out) = handler.on_transmit() {
            match iface.publish(out.kind, out.topic, out.payload).await {
                Ok(()) => {
                    sent.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => handler.on_send_error(e),
            }
            // a handler that always has more to send must not starve the other tasks
            tokio::task::consume_budget().await;
        }
        tokio::select! {
            biased;
            _ = stop.notified() => return (iface, handler),
            m = iface.recv() => match m {
                Some(m) => handler.on_receive(m),
                None => return (iface, handler),
            },
            _ = notify.notified() => {}
            _ = async {
                match ticker.as_mut() {
                    Some(t) => { t.tick().await; }
                    None => std::future::pending().await,
                }
            } => {}
        }
    }
}
