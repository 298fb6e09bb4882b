//! The bounded receive queue behind every interface.
//!
//! Each interface has two bounded queues. Data messages go to the data queue; when it is full the
//! oldest data message is dropped and counted, so a slow receiver sees the newest data and never
//! holds up the medium. Commands go to the command queue; when it is full the command is refused
//! (the medium then holds a local publisher back until there is room, or counts and logs a command
//! that was forwarded or read from the wire). Commands are taken before data.
//!
//! Duplicates are dropped as messages arrive, in arrival order, by the queue's per-origin window
//! ([`crate::dedup`]), so a duplicate never takes a slot. A message its medium has just numbered
//! cannot be one and skips the window; its medium drops any later sighting of it. The receiver
//! takes data in batches (one lock per batch); what it holds in hand counts against the capacity
//! like what still waits.
//!
//! Every data message a queue drops is counted in the queue and, under the receiver's name, in
//! its medium's [`Losses`], which warns of a burst of them when it ends.

use crate::dedup::{Dedup, Seen};
use crate::loss::Losses;
use crate::message::{Kind, Message};
use atomic_waker::AtomicWaker;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use tokio::sync::Notify;

/// Default capacity of an interface's data queue.
pub const DEFAULT_DATA_CAPACITY: usize = 1024;
/// Default capacity of an interface's command queue.
pub const DEFAULT_COMMAND_CAPACITY: usize = 64;

/// How a pushed message is checked for duplicates.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Check {
    /// Through the queue's per-origin window.
    Window,
    /// Not at all: its medium has just numbered it, so nobody can have seen it.
    Fresh,
    /// A later sighting of a message its medium numbered and delivered: a duplicate.
    Echo,
}

/// What happened to a pushed message.
pub(crate) enum Pushed {
    /// Queued.
    Queued,
    /// Queued, after dropping the oldest data message.
    DroppedOldest,
    /// Not queued: seen before (or older than the duplicate window).
    Duplicate,
    /// Not queued: the command queue is full. The message is handed back.
    Full(Message),
    /// Not queued: the receiver is gone.
    Closed,
}

struct State {
    data: VecDeque<Message>,
    commands: VecDeque<Message>,
    seen: Dedup,
    closed: bool,
    /// the receiver found nothing and waits to be woken: the push that finds it set wakes it
    /// (read and set under the lock both take anyway, so neither needs a fence)
    parked: bool,
}

/// Counters kept by a queue.
#[derive(Default)]
pub(crate) struct QueueCounters {
    pub dropped_oldest: AtomicU64,
    pub commands_refused: AtomicU64,
    pub duplicates: AtomicU64,
    pub late: AtomicU64,
}

pub(crate) struct Queue {
    state: Mutex<State>,
    /// commands waiting, readable without the lock
    commands: AtomicUsize,
    /// data messages waiting, readable without the lock
    data_len: AtomicUsize,
    waker: AtomicWaker,
    space: Notify,
    closed: AtomicBool,
    data_cap: usize,
    cmd_cap: usize,
    pub counters: QueueCounters,
    /// the medium's losses and the receiver's name there, for the data messages dropped
    losses: Option<(Arc<Losses>, Arc<str>)>,
}

impl Queue {
    pub fn new(data_cap: usize, cmd_cap: usize) -> Queue {
        Queue {
            state: Mutex::new(State {
                data: VecDeque::with_capacity(data_cap.min(64)),
                commands: VecDeque::new(),
                seen: Dedup::new(),
                closed: false,
                parked: false,
            }),
            commands: AtomicUsize::new(0),
            data_len: AtomicUsize::new(0),
            waker: AtomicWaker::new(),
            space: Notify::new(),
            closed: AtomicBool::new(false),
            data_cap: data_cap.max(1),
            cmd_cap: cmd_cap.max(1),
            counters: QueueCounters::default(),
            losses: None,
        }
    }

    /// The same queue, counting what it drops in `losses` as `receiver`'s.
    pub fn counted_in(mut self, losses: Arc<Losses>, receiver: Arc<str>) -> Queue {
        self.losses = Some((losses, receiver));
        self
    }

    /// Counts `n` data messages dropped.
    fn dropped(&self, n: u64) {
        self.counters.dropped_oldest.fetch_add(n, Ordering::Relaxed);
        if let Some((losses, receiver)) = &self.losses {
            losses.queue_full(receiver, n);
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // a panic while holding this lock cannot leave the queues inconsistent: keep going
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn count_seen(&self, seen: Seen) {
        match seen {
            Seen::Duplicate => self.counters.duplicates.fetch_add(1, Ordering::Relaxed),
            Seen::Late => self.counters.late.fetch_add(1, Ordering::Relaxed),
            Seen::New => 0,
        };
    }

    pub fn push(&self, msg: Message, check: Check) -> Pushed {
        if check == Check::Echo {
            self.count_seen(Seen::Duplicate);
            return Pushed::Duplicate;
        }
        let fresh = check == Check::Fresh;
        let (origin, seq) = (msg.provenance.origin.id, msg.provenance.seq);
        let (result, wake) = {
            let mut st = self.lock();
            if st.closed {
                return Pushed::Closed;
            }
            let result = match msg.kind {
                Kind::Data => {
                    let seen = if fresh {
                        Seen::New
                    } else {
                        st.seen.check_raw(origin, seq)
                    };
                    if seen != Seen::New {
                        drop(st);
                        self.count_seen(seen);
                        return Pushed::Duplicate;
                    }
                    let dropped = if st.data.len() >= self.data_cap {
                        st.data.pop_front();
                        true
                    } else {
                        false
                    };
                    st.data.push_back(msg);
                    self.data_len.store(st.data.len(), Ordering::Relaxed);
                    if dropped {
                        Pushed::DroppedOldest
                    } else {
                        Pushed::Queued
                    }
                }
                Kind::Command => {
                    if st.commands.len() >= self.cmd_cap {
                        // a duplicate is dropped even when there is no room; anything else waits
                        let seen = if fresh {
                            Seen::New
                        } else {
                            st.seen.peek_raw(origin, seq)
                        };
                        drop(st);
                        if seen != Seen::New {
                            self.count_seen(seen);
                            return Pushed::Duplicate;
                        }
                        return Pushed::Full(msg);
                    }
                    let seen = if fresh {
                        Seen::New
                    } else {
                        st.seen.check_raw(origin, seq)
                    };
                    if seen != Seen::New {
                        drop(st);
                        self.count_seen(seen);
                        return Pushed::Duplicate;
                    }
                    st.commands.push_back(msg);
                    self.commands.store(st.commands.len(), Ordering::Release);
                    Pushed::Queued
                }
            };
            (result, std::mem::take(&mut st.parked))
        };
        if let Pushed::DroppedOldest = result {
            self.dropped(1);
        }
        if wake {
            self.waker.wake();
        }
        result
    }

    /// Pushes a command, waiting for room in the command queue.
    pub async fn push_wait(&self, mut msg: Message, check: Check) -> Pushed {
        loop {
            let space = self.space.notified();
            tokio::pin!(space);
            space.as_mut().enable();
            match self.push(msg, check) {
                Pushed::Full(back) => {
                    msg = back;
                    space.await;
                }
                other => return other,
            }
        }
    }

    /// Takes the oldest waiting command, if any (cheap when there is none).
    fn pop_command(&self) -> Option<Message> {
        if self.commands.load(Ordering::Acquire) == 0 {
            return None;
        }
        let c = {
            let mut st = self.lock();
            let c = st.commands.pop_front();
            self.commands.store(st.commands.len(), Ordering::Release);
            c
        };
        if c.is_some() {
            self.space.notify_waiters();
        }
        c
    }

    /// Moves every waiting data message into `out` (which must be empty); true when any was moved.
    fn drain_data(&self, out: &mut VecDeque<Message>) -> bool {
        let mut st = self.lock();
        std::mem::swap(&mut st.data, out);
        self.data_len.store(0, Ordering::Relaxed);
        !out.is_empty()
    }

    /// The next message without waiting: a command first, then `batch` (data already taken from
    /// the queue), then a fresh batch of data. Data in hand and data waiting together stay within
    /// the capacity: the oldest in hand are dropped (and counted) first.
    pub fn next(&self, batch: &mut VecDeque<Message>) -> Option<Message> {
        if let Some(c) = self.pop_command() {
            return Some(c);
        }
        if batch.is_empty() && !self.drain_data(batch) {
            return None;
        }
        let waiting = self.data_len.load(Ordering::Relaxed);
        let excess = (batch.len() + waiting).saturating_sub(self.data_cap);
        let excess = excess.min(batch.len().saturating_sub(1));
        if excess > 0 {
            batch.drain(..excess);
            self.dropped(excess as u64);
        }
        batch.pop_front()
    }

    /// Like [`Queue::next`], registering the receiver's waker when nothing is waiting.
    /// `Ready(None)` means the queue is closed and empty.
    pub fn poll_next(
        &self,
        cx: &mut Context<'_>,
        batch: &mut VecDeque<Message>,
    ) -> Poll<Option<Message>> {
        if let Some(m) = self.next(batch) {
            return Poll::Ready(Some(m));
        }
        if self.closed.load(Ordering::Acquire) {
            // a push that began before the close has finished by now (it held the lock)
            return Poll::Ready(self.next(batch));
        }
        self.waker.register(cx.waker());
        // a push that lands from here on finds `parked` set and wakes the waker just registered;
        // one that landed before is found now
        let found = {
            let mut st = self.lock();
            let empty = st.data.is_empty() && st.commands.is_empty();
            if empty && !st.closed {
                st.parked = true;
            }
            !empty || st.closed
        };
        if found {
            // (none when closed with nothing left)
            Poll::Ready(self.next(batch))
        } else {
            Poll::Pending
        }
    }

    /// Messages waiting (not counting what the receiver holds in hand).
    pub fn len(&self) -> usize {
        let st = self.lock();
        st.data.len() + st.commands.len()
    }

    /// Marks the queue closed: pushes are refused, the receiver drains what is left then sees the end.
    pub fn close(&self) {
        self.lock().closed = true;
        self.closed.store(true, Ordering::Release);
        self.waker.wake();
        self.space.notify_waiters();
    }

    pub fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }
}
