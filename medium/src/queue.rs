//! The bounded receive queue behind every interface.
//!
//! Each interface has two bounded queues. Data messages go to the data queue; when it is full the
//! oldest data message is dropped and counted, so a slow receiver sees the newest data and never
//! holds up the medium. Commands go to the command queue; when it is full the command is refused
//! (the medium then holds a local sender back until there is room, or counts and logs a command that
//! arrived from the wire). Commands are taken before data.

use crate::message::{Kind, Message};
use atomic_waker::AtomicWaker;
use std::collections::VecDeque;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::task::{Context, Poll};
use tokio::sync::Notify;

/// Default capacity of an interface's data queue.
pub const DEFAULT_DATA_CAPACITY: usize = 1024;
/// Default capacity of an interface's command queue.
pub const DEFAULT_COMMAND_CAPACITY: usize = 64;

/// What happened to a pushed message.
pub(crate) enum Pushed {
    /// Queued.
    Queued,
    /// Queued, after dropping the oldest data message.
    DroppedOldest,
    /// Not queued: the command queue is full. The message is handed back.
    Full(Message),
    /// Not queued: the receiver is gone.
    Closed,
}

struct State {
    data: VecDeque<Message>,
    commands: VecDeque<Message>,
}

/// Counters kept by a queue.
#[derive(Default)]
pub(crate) struct QueueCounters {
    pub queued: AtomicU64,
    pub dropped_oldest: AtomicU64,
    pub commands_refused: AtomicU64,
}

pub(crate) struct Queue {
    state: Mutex<State>,
    waker: AtomicWaker,
    space: Notify,
    closed: AtomicBool,
    data_cap: usize,
    cmd_cap: usize,
    pub counters: QueueCounters,
}

impl Queue {
    pub fn new(data_cap: usize, cmd_cap: usize) -> Queue {
        Queue {
            state: Mutex::new(State {
                data: VecDeque::with_capacity(data_cap.min(64)),
                commands: VecDeque::new(),
            }),
            waker: AtomicWaker::new(),
            space: Notify::new(),
            closed: AtomicBool::new(false),
            data_cap: data_cap.max(1),
            cmd_cap: cmd_cap.max(1),
            counters: QueueCounters::default(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // a panic while holding this lock cannot leave the queues inconsistent: keep going
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn push(&self, msg: Message) -> Pushed {
        if self.closed.load(Ordering::Relaxed) {
            return Pushed::Closed;
        }
        let result = {
            let mut st = self.lock();
            match msg.kind {
                Kind::Data => {
                    let dropped = if st.data.len() >= self.data_cap {
                        st.data.pop_front();
                        true
                    } else {
                        false
                    };
                    st.data.push_back(msg);
                    if dropped {
                        Pushed::DroppedOldest
                    } else {
                        Pushed::Queued
                    }
                }
                Kind::Command => {
                    if st.commands.len() >= self.cmd_cap {
                        return Pushed::Full(msg);
                    }
                    st.commands.push_back(msg);
                    Pushed::Queued
                }
            }
        };
        self.counters.queued.fetch_add(1, Ordering::Relaxed);
        if let Pushed::DroppedOldest = result {
            self.counters.dropped_oldest.fetch_add(1, Ordering::Relaxed);
        }
        self.waker.wake();
        result
    }

    /// Pushes a command, waiting for room in the command queue.
    pub async fn push_wait(&self, mut msg: Message) -> Pushed {
        loop {
            let space = self.space.notified();
            tokio::pin!(space);
            space.as_mut().enable();
            match self.push(msg) {
                Pushed::Full(back) => {
                    msg = back;
                    space.await;
                }
                other => return other,
            }
        }
    }

    pub fn pop(&self) -> Option<Message> {
        let mut st = self.lock();
        if let Some(c) = st.commands.pop_front() {
            drop(st);
            self.space.notify_waiters();
            return Some(c);
        }
        st.data.pop_front()
    }

    pub fn poll_pop(&self, cx: &mut Context<'_>) -> Poll<Option<Message>> {
        if let Some(m) = self.pop() {
            return Poll::Ready(Some(m));
        }
        if self.closed.load(Ordering::Acquire) {
            return Poll::Ready(None);
        }
        self.waker.register(cx.waker());
        // a push may have landed between the first look and the registration
        match self.pop() {
            Some(m) => Poll::Ready(Some(m)),
            None if self.closed.load(Ordering::Acquire) => Poll::Ready(None),
            None => Poll::Pending,
        }
    }

    pub fn len(&self) -> usize {
        let st = self.lock();
        st.data.len() + st.commands.len()
    }

    /// Marks the queue closed: pushes are refused, the receiver drains what is left then sees the end.
    pub fn close(&self) {
        self.closed.store(true, Ordering::Release);
        self.waker.wake();
        self.space.notify_waiters();
    }

    pub fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }
}
