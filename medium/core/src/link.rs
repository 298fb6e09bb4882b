//! Keeping a link to a device or a server: one reconnect loop with back-off and link-state
//! reporting, for every medium whose wire can go away (a serial device unplugged, a CAN interface
//! down, a MOOSDB restarted, a router out of reach).
//!
//! A transport makes a [`link_queue`]: the [`LinkSender`] stays with the transport, which queues
//! encoded frames on it (refused at once while the link is down), and the [`LinkQueue`] goes to
//! [`spawn_link`], whose task connects, runs a session on the connection (reading the wire into
//! the medium, writing queued frames out) until it fails, and connects again after a back-off
//! ([`Backoff`]: `reopen` doubling up to `reopen_max`, back to `reopen` once a link has been up).
//! The medium's link state follows ([`crate::Medium::watch_link`]), logged on each change. A frame
//! sent while the link is first coming up (its first attempt under way, as at a system's start)
//! waits for that attempt, at most [`COMING_UP`]; once a link has been up, or its first attempt
//! failed, a frame sent while it is down is refused at once. Frames queued when the link was lost
//! are dropped with it, counted as transmit errors and logged: the medium's peer never had them.
//!
//! A medium whose wire is such a link implements only [`Encode`] (what a message becomes) and
//! opens as a [`Linked`] transport, which queues, flushes and closes through the link.

use crate::caps::Capabilities;
use crate::medium::{BoxFuture, Ingress, LinkState, SendError, Transport};
use crate::parse::parse_duration;
use crate::url::{MediumUrl, UrlError};
use crate::{Message, Payload, Topic};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::{Notify, mpsc};

/// How long to wait between attempts to reopen a lost link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    /// The wait after a link is lost, and after the first failed attempt.
    pub first: Duration,
    /// The longest wait: each further failed attempt doubles the wait up to this.
    pub max: Duration,
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff {
            first: Duration::from_millis(500),
            max: Duration::from_secs(5),
        }
    }
}

impl Backoff {
    /// The URL options a back-off takes.
    pub const OPTIONS: [&'static str; 2] = ["reopen", "reopen_max"];

    /// Takes `reopen` (the first wait, default 500ms) and `reopen_max` (the longest, default 5s or
    /// `reopen` when that is longer) from a URL.
    pub fn from_url(url: &mut MediumUrl) -> Result<Backoff, UrlError> {
        let mut take = |name: &str| -> Result<Option<Duration>, UrlError> {
            match url.take(name) {
                None => Ok(None),
                Some(v) => parse_duration(&v)
                    .filter(|d| !d.is_zero())
                    .map(Some)
                    .ok_or_else(|| {
                        url.error(format!(
                            "option `{name}={v}`: expected a duration such as 500ms"
                        ))
                    }),
            }
        };
        let first = take("reopen")?.unwrap_or(Backoff::default().first);
        let max = match take("reopen_max")? {
            Some(max) if max < first => {
                return Err(url.error(format!(
                    "option `reopen_max`: {max:?} is shorter than `reopen` ({first:?})"
                )));
            }
            Some(max) => max,
            None => Backoff::default().max.max(first),
        };
        Ok(Backoff { first, max })
    }

    /// The wait after one of `wait`.
    pub fn next(&self, wait: Duration) -> Duration {
        (wait * 2).min(self.max)
    }
}

/// How long a frame sent while a link is first coming up waits for it.
pub const COMING_UP: Duration = Duration::from_secs(10);

#[derive(Default)]
struct Shared {
    up: AtomicBool,
    /// the link's first attempt is over (up or failed), or the link is closed
    tried: AtomicBool,
    /// frames lost with the link since the link's task last looked
    lost: AtomicU64,
    /// frames handed to the queue, and those written or dropped since
    queued: AtomicU64,
    done: AtomicU64,
    progress: Notify,
}

impl Shared {
    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::AcqRel);
        self.progress.notify_waiters();
    }

    fn set_up(&self, up: bool) {
        self.up.store(up, Ordering::Release);
        self.progress.notify_waiters();
    }

    fn tried(&self) {
        self.tried.store(true, Ordering::Release);
        self.progress.notify_waiters();
    }

    /// Waits (at most [`COMING_UP`]) while the link's first attempt is under way.
    async fn coming_up(&self) {
        let deadline = tokio::time::Instant::now() + COMING_UP;
        loop {
            // made before the check: a wake-up between the check and the wait is not lost
            let progress = self.progress.notified();
            if self.up.load(Ordering::Acquire) || self.tried.load(Ordering::Acquire) {
                return;
            }
            if tokio::time::timeout_at(deadline, progress).await.is_err() {
                return;
            }
        }
    }
}

/// The transport's side of a link: queues frames for the link's task to write.
pub struct LinkSender<F> {
    medium: Arc<str>,
    peer: Arc<str>,
    shared: Arc<Shared>,
    tx: mpsc::Sender<F>,
}

/// The link task's side: the frames to write.
pub struct LinkQueue<F> {
    shared: Arc<Shared>,
    rx: mpsc::Receiver<F>,
}

/// A queue of `capacity` frames between a transport of medium `medium` and its link's task;
/// `peer` names what the link reaches (`/dev/ttyUSB0`, `the MOOSDB at db:9000`) in errors. The
/// link starts down.
pub fn link_queue<F>(
    medium: &Arc<str>,
    peer: impl Into<String>,
    capacity: usize,
) -> (LinkSender<F>, LinkQueue<F>) {
    let shared = Arc::new(Shared::default());
    let (tx, rx) = mpsc::channel(capacity);
    (
        LinkSender {
            medium: medium.clone(),
            peer: Arc::from(peer.into()),
            shared: shared.clone(),
            tx,
        },
        LinkQueue { shared, rx },
    )
}

impl<F: Send> LinkSender<F> {
    /// Queues a frame, waiting while the link is this far behind, and while it is first coming up
    /// (at most [`COMING_UP`]); fails at once while the link is down after that
    /// ([`SendError::LinkDown`]).
    pub async fn send(&self, frame: F) -> Result<(), SendError> {
        if !self.is_up() {
            self.shared.coming_up().await;
        }
        if !self.is_up() {
            return Err(SendError::LinkDown {
                medium: self.medium.to_string(),
                reason: format!("{} is not open", self.peer),
            });
        }
        self.shared.queued.fetch_add(1, Ordering::AcqRel);
        if self.tx.send(frame).await.is_err() {
            self.shared.advance(1);
            return Err(SendError::Closed(self.medium.to_string()));
        }
        Ok(())
    }

    /// Returns once every frame queued so far has been written or dropped, or at once while the
    /// link is down.
    pub async fn flush(&self) {
        let target = self.shared.queued.load(Ordering::Acquire);
        loop {
            // made before the check: a wake-up between the check and the wait is not lost
            let progress = self.shared.progress.notified();
            if !self.is_up() || self.shared.done.load(Ordering::Acquire) >= target {
                return;
            }
            progress.await;
        }
    }

    /// Whether the link is up.
    pub fn is_up(&self) -> bool {
        self.shared.up.load(Ordering::Acquire)
    }

    /// Marks the link down (the medium is closing).
    pub fn close(&self) {
        self.shared.set_up(false);
        self.shared.tried();
    }

    /// An error of this medium's wire, for the sender.
    pub fn error(&self, reason: impl Into<String>) -> SendError {
        SendError::Io {
            medium: self.medium.to_string(),
            reason: reason.into(),
        }
    }

    /// The medium's name.
    pub fn medium(&self) -> &str {
        &self.medium
    }
}

impl<F> LinkQueue<F> {
    /// The next frame to write; `None` once the transport is gone.
    pub async fn recv(&mut self) -> Option<F> {
        self.rx.recv().await
    }

    /// The next frame if one waits.
    pub fn try_recv(&mut self) -> Option<F> {
        self.rx.try_recv().ok()
    }

    /// Notes that `n` frames taken from the queue were written (or given up).
    pub fn written(&self, n: u64) {
        self.shared.advance(n);
    }

    /// Marks the link up or down, for a link kept by other means than [`spawn_link`] (which also
    /// ends the wait of frames sent while the link was first coming up).
    pub fn set_up(&self, up: bool) {
        self.shared.set_up(up);
        self.shared.tried();
    }

    /// Notes that `n` frames taken from the queue were lost with the link (a write that failed):
    /// [`spawn_link`] counts them as transmit errors.
    pub fn lost(&self, n: u64) {
        self.shared.lost.fetch_add(n, Ordering::AcqRel);
    }

    /// Takes the count of frames lost since the last call.
    fn take_lost(&self) -> u64 {
        self.shared.lost.swap(0, Ordering::AcqRel)
    }

    /// Writes a frame taken from the queue with `write` and notes it written; on failure, the reason
    /// the link is lost, naming `what` (the device or server).
    pub async fn write<E: std::fmt::Display>(
        &self,
        what: impl std::fmt::Display,
        write: impl std::future::Future<Output = Result<(), E>>,
    ) -> Result<(), String> {
        let written = write.await;
        self.written(1);
        if written.is_err() {
            self.lost(1);
        }
        written.map_err(|e| format!("{what}: {e}"))
    }

    /// Drops every frame waiting (the link was lost with them).
    pub fn drop_waiting(&mut self) {
        let mut n = 0;
        while self.rx.try_recv().is_ok() {
            n += 1;
        }
        self.written(n);
        self.lost(n);
    }
}

/// What a medium on a kept link does with messages: the rest of its [`Transport`], which
/// [`Linked`] completes.
pub trait Encode: Send + Sync + 'static {
    /// What one message becomes on the wire.
    type Frame: Clone + Send + Sync + 'static;
    /// What the medium can do.
    fn capabilities(&self) -> Capabilities;
    /// Encodes `msg` for the wire; `link` makes this medium's errors.
    fn encode(
        &self,
        msg: &Message,
        link: &LinkSender<Self::Frame>,
    ) -> Result<Self::Frame, SendError>;
    /// See [`Transport::fingerprint`].
    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64> {
        let _ = (topic, payload);
        None
    }
    /// The medium is closing (remove what the medium made, such as a pseudo-terminal's link).
    fn close(&self) {}
}

/// A transport whose frames go out through a kept link.
pub struct Linked<E: Encode> {
    encoder: E,
    link: LinkSender<E::Frame>,
}

impl<E: Encode> Linked<E> {
    /// A transport encoding with `encoder` and sending on `link`.
    pub fn new(encoder: E, link: LinkSender<E::Frame>) -> Linked<E> {
        Linked { encoder, link }
    }
}

impl<E: Encode> Transport for Linked<E> {
    type Frame = E::Frame;

    fn capabilities(&self) -> Capabilities {
        self.encoder.capabilities()
    }

    fn encode(&self, msg: &Message) -> Result<E::Frame, SendError> {
        self.encoder.encode(msg, &self.link)
    }

    fn transmit(&self, frame: E::Frame) -> BoxFuture<'_, Result<(), SendError>> {
        Box::pin(self.link.send(frame))
    }

    fn flush(&self) -> BoxFuture<'_, ()> {
        Box::pin(self.link.flush())
    }

    fn close(&self) {
        self.link.close();
        self.encoder.close();
    }

    fn fingerprint(&self, topic: &Topic, payload: &Payload) -> Option<u64> {
        self.encoder.fingerprint(topic, payload)
    }
}

/// Runs a link on a task the medium owns: connects with `connect`, runs `session` on the
/// connection while it lasts (the link up), and when it fails (or a connection cannot be made)
/// reports the link down with the reason and connects again after the back-off, until the medium
/// closes. Both return the reason a link is down, in words naming the device or server.
pub fn spawn_link<C, F>(
    ingress: &Ingress,
    backoff: Backoff,
    queue: LinkQueue<F>,
    connect: impl FnMut() -> BoxFuture<'static, Result<C, String>> + Send + 'static,
    session: impl for<'q> FnMut(C, &'q mut LinkQueue<F>) -> BoxFuture<'q, String> + Send + 'static,
) where
    C: Send + 'static,
    F: Send + 'static,
{
    let task = tokio::spawn(keep_linked(
        ingress.clone(),
        backoff,
        queue,
        connect,
        session,
    ));
    ingress.own_task(task.abort_handle());
}

async fn keep_linked<C, F>(
    ingress: Ingress,
    backoff: Backoff,
    mut queue: LinkQueue<F>,
    mut connect: impl FnMut() -> BoxFuture<'static, Result<C, String>>,
    mut session: impl for<'q> FnMut(C, &'q mut LinkQueue<F>) -> BoxFuture<'q, String>,
) {
    let mut wait = backoff.first;
    loop {
        let reason = match connect().await {
            Ok(conn) => {
                // the sender first: a send on seeing the link up is taken
                queue.set_up(true);
                ingress.set_link(LinkState::Up);
                wait = backoff.first;
                let reason = session(conn, &mut queue).await;
                queue.shared.set_up(false);
                reason
            }
            Err(e) => {
                queue.shared.tried();
                e
            }
        };
        if !ingress.is_open() {
            return;
        }
        ingress.set_link(LinkState::Down(reason));
        queue.drop_waiting();
        let lost = queue.take_lost();
        if lost > 0 {
            ingress.lost_with_link(lost);
        }
        tokio::time::sleep(wait).await;
        wait = backoff.next(wait);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Node;
    use std::sync::Mutex;
    use tokio::time::Instant;

    #[test]
    fn backoff_options_are_read_and_checked() {
        let b = |u: &str| Backoff::from_url(&mut MediumUrl::parse(u).unwrap());
        assert_eq!(b("x://h").unwrap(), Backoff::default());
        let got = b("x://h?reopen=2s").unwrap();
        assert_eq!(
            (got.first, got.max),
            (Duration::from_secs(2), Duration::from_secs(5))
        );
        let got = b("x://h?reopen=10s").unwrap();
        assert_eq!(
            got.max,
            Duration::from_secs(10),
            "never shorter than the first wait"
        );
        assert!(b("x://h?reopen=0s").is_err());
        assert!(b("x://h?reopen=1s&reopen_max=100ms").is_err());
        let d = Backoff::default();
        assert_eq!(d.next(Duration::from_millis(500)), Duration::from_secs(1));
        assert_eq!(d.next(Duration::from_secs(4)), Duration::from_secs(5));
    }

    #[tokio::test(start_paused = true)]
    async fn a_lost_link_is_reported_and_reopened_with_backoff() {
        let medium = crate::Schemes::new()
            .open("dev", "inproc://", &Node::new("n"))
            .unwrap();
        let ingress = medium.ingress();
        let (tx, queue) = link_queue::<u32>(&Arc::from("dev"), "/dev/thing", 4);
        let attempts = Arc::new(Mutex::new(Vec::new()));
        let start = Instant::now();
        let log = attempts.clone();
        // the device: there for the first attempt (the session fails after 1 s), then gone for
        // three attempts, then back
        spawn_link(
            &ingress,
            Backoff::default(),
            queue,
            move || {
                let mut log = log.lock().unwrap();
                log.push(start.elapsed());
                let n = log.len();
                Box::pin(async move {
                    if n == 1 || n == 5 {
                        Ok(n)
                    } else {
                        Err(format!("/dev/thing: gone ({n})"))
                    }
                })
            },
            |n, q| {
                Box::pin(async move {
                    if n == 1 {
                        tokio::time::sleep(Duration::from_secs(1)).await;
                        return "/dev/thing: unplugged".to_string();
                    }
                    while let Some(_frame) = q.recv().await {
                        q.written(1);
                    }
                    "closed".to_string()
                })
            },
        );
        let mut link = medium.watch_link();
        tokio::time::sleep(Duration::from_millis(10)).await;
        assert!(tx.is_up());
        tx.send(7).await.unwrap();
        tx.flush().await;
        link.changed().await.unwrap();
        assert_eq!(
            *link.borrow(),
            LinkState::Down("/dev/thing: unplugged".into())
        );
        let e = tx.send(8).await.unwrap_err();
        assert!(matches!(e, SendError::LinkDown { .. }), "{e}");
        // down with the latest reason until the fifth attempt succeeds
        tokio::time::sleep(Duration::from_secs(10)).await;
        assert_eq!(*medium.watch_link().borrow(), LinkState::Up);
        let at: Vec<u64> = attempts
            .lock()
            .unwrap()
            .iter()
            .map(|d| d.as_millis() as u64)
            .collect();
        // lost at 1 s; waits 0.5, 1, 2, 4 s between the attempts
        assert_eq!(at, vec![0, 1500, 2500, 4500, 8500]);
        tx.send(9).await.unwrap();
        tx.flush().await;
        medium.close();
    }

    fn inproc() -> crate::Medium {
        crate::Schemes::new()
            .open("dev", "inproc://", &Node::new("n"))
            .unwrap()
    }

    #[tokio::test(start_paused = true)]
    async fn a_frame_sent_while_the_link_first_comes_up_waits_for_it() {
        let medium = inproc();
        let (tx, queue) = link_queue::<u32>(&Arc::from("dev"), "/dev/thing", 4);
        let got = Arc::new(Mutex::new(Vec::new()));
        let seen = got.clone();
        let start = Instant::now();
        // the device answers its first attempt after 2 s
        spawn_link(
            &medium.ingress(),
            Backoff::default(),
            queue,
            || {
                Box::pin(async {
                    tokio::time::sleep(Duration::from_secs(2)).await;
                    Ok(())
                })
            },
            move |(), q| {
                let seen = seen.clone();
                Box::pin(async move {
                    while let Some(frame) = q.recv().await {
                        seen.lock().unwrap().push((frame, start.elapsed()));
                        q.written(1);
                    }
                    "closed".to_string()
                })
            },
        );
        tx.send(1).await.unwrap();
        assert_eq!(
            start.elapsed(),
            Duration::from_secs(2),
            "waited for the link"
        );
        tx.flush().await;
        assert_eq!(*got.lock().unwrap(), vec![(1, Duration::from_secs(2))]);
        assert_eq!(medium.stats().tx_errors, 0);
        medium.close();
    }

    #[tokio::test(start_paused = true)]
    async fn a_frame_is_refused_at_once_once_the_first_attempt_failed() {
        let medium = inproc();
        let (tx, queue) = link_queue::<u32>(&Arc::from("dev"), "/dev/thing", 4);
        let start = Instant::now();
        spawn_link(
            &medium.ingress(),
            Backoff::default(),
            queue,
            || {
                Box::pin(async {
                    tokio::time::sleep(Duration::from_millis(300)).await;
                    Err::<(), _>("/dev/thing: no such device".to_string())
                })
            },
            |(), _q| Box::pin(async { "closed".to_string() }),
        );
        // the first attempt's failure ends the wait: no waiting out COMING_UP
        let e = tx.send(1).await.unwrap_err();
        assert!(matches!(e, SendError::LinkDown { .. }), "{e}");
        assert_eq!(start.elapsed(), Duration::from_millis(300));
        // and later sends are refused without waiting
        tokio::time::sleep(Duration::from_millis(100)).await;
        let before = Instant::now();
        assert!(tx.send(2).await.is_err());
        assert_eq!(before.elapsed(), Duration::ZERO);
        medium.close();
    }

    #[tokio::test(start_paused = true)]
    async fn a_link_that_never_answers_holds_a_frame_at_most_coming_up() {
        let medium = inproc();
        let (tx, queue) = link_queue::<u32>(&Arc::from("dev"), "/dev/thing", 4);
        let start = Instant::now();
        spawn_link(
            &medium.ingress(),
            Backoff::default(),
            queue,
            || Box::pin(std::future::pending::<Result<(), String>>()),
            |(), _q| Box::pin(async { "closed".to_string() }),
        );
        assert!(tx.send(1).await.is_err());
        assert_eq!(start.elapsed(), COMING_UP);
        medium.close();
    }

    #[tokio::test(start_paused = true)]
    async fn frames_lost_with_the_link_are_transmit_errors() {
        let medium = inproc();
        let (tx, queue) = link_queue::<u32>(&Arc::from("dev"), "/dev/thing", 8);
        let sessions = Arc::new(std::sync::atomic::AtomicU32::new(0));
        let n = sessions.clone();
        spawn_link(
            &medium.ingress(),
            Backoff::default(),
            queue,
            || Box::pin(async { Ok(()) }),
            move |(), q| {
                let first = n.fetch_add(1, Ordering::AcqRel) == 0;
                Box::pin(async move {
                    if !first {
                        std::future::pending::<()>().await;
                    }
                    // the first session: one frame's write fails, the connection goes with the
                    // two frames waiting behind it
                    let frame = q.recv().await.unwrap();
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    let failed = q
                        .write("/dev/thing", async move {
                            let _ = frame;
                            Err::<(), _>("broken pipe")
                        })
                        .await;
                    failed.unwrap_err()
                })
            },
        );
        for f in 1..=3 {
            tx.send(f).await.unwrap();
        }
        let mut link = medium.watch_link();
        let down = link
            .wait_for(|s| *s != LinkState::Up)
            .await
            .unwrap()
            .clone();
        assert_eq!(down, LinkState::Down("/dev/thing: broken pipe".into()));
        // counted once the link's task has dropped what waited
        tokio::time::sleep(Duration::from_millis(10)).await;
        assert_eq!(medium.stats().tx_errors, 3);
        tx.flush().await;
        medium.close();
    }
}
