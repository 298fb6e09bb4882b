//! Sending a medium's datagrams on its UDP socket: a message at once when the socket is quiet, in
//! sendmmsg(2) batches when messages come faster than one call each.
//!
//! Datagrams leave at once, from the sender's task, unless they come in a stream: [`STREAM`]
//! handovers in a row, each less than the medium's gap ([`QUIET`] unless its URL says
//! `send_gap=`, [`gap_from_url`]; `send_gap=0` sends every datagram at once) after the last one
//! ended. A message now and then, or a few at
//! once, costs no more than a plain send. Datagrams of a stream join a queue: the sender that fills a batch sends it itself, and what is left is sent by
//! the outbox's own task as soon as it runs (at once on another thread of a multi-threaded
//! runtime; on a single-threaded one, when the sender's task next waits). The queue holds at most
//! [`CAPACITY`] datagrams; a sender finding it full waits for room. Datagrams leave in the order
//! they were handed over. A failure sending one from the queue is counted in the medium's
//! `tx_errors` and logged (rate-limited), and the others still go; one sent at once is returned to
//! its sender.
//!
//! Used by the UDP and LCM media.

use crate::medium::Ingress;
use crate::url::{MediumUrl, UrlError};
use arc_swap::ArcSwapOption;
use bytes::Bytes;
use socket2::SockAddr;
use std::collections::VecDeque;
use std::io;
use std::net::SocketAddr;
use std::os::fd::AsRawFd;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::io::Interest;
use tokio::net::UdpSocket;
use tokio::sync::Notify;

/// Datagrams one sendmmsg(2) call sends at most.
pub const BATCH: usize = 32;
/// Datagrams waiting at most.
pub const CAPACITY: usize = 4 * BATCH;
/// Handovers less than this apart make a stream, by default.
pub const QUIET: Duration = Duration::from_micros(50);
/// The longest gap a URL may set.
pub const MAX_GAP: Duration = Duration::from_secs(1);

/// The gap a medium's URL sets with `send_gap=` (a duration: `50us`, `2ms`; `0` sends every
/// datagram at once), taking the option; `None` without it.
pub fn gap_from_url(url: &mut MediumUrl) -> Result<Option<Duration>, UrlError> {
    let Some(text) = url.take("send_gap") else {
        return Ok(None);
    };
    crate::parse::parse_duration(&text)
        .filter(|d| *d <= MAX_GAP)
        .map(Some)
        .ok_or_else(|| {
            url.error(format!(
                "option `send_gap={text}`: expected a duration up to 1s such as 50us or 2ms, or 0"
            ))
        })
}
/// Handovers in a row, each less than [`QUIET`] after the last, that make a stream.
pub const STREAM: u32 = 8;
/// Bytes of header a datagram keeps beside its body.
pub const MAX_HEAD: usize = 32;

/// One datagram: a short header, then a body shared with the frame it was cut from.
#[derive(Clone)]
pub struct Outgoing {
    head: [u8; MAX_HEAD],
    head_len: u8,
    body: Bytes,
    /// `None`: the peer a connected socket sends to
    to: Option<SocketAddr>,
}

impl Outgoing {
    /// `head` then `body`, to `to`. A head longer than [`MAX_HEAD`] is copied to the front of the
    /// body.
    pub fn new(head: &[u8], body: Bytes, to: SocketAddr) -> Outgoing {
        Outgoing::with(head, body, Some(to))
    }

    /// `head` then `body`, to the peer of a connected socket (whose route the kernel keeps, where
    /// it looks one up for every datagram given an address).
    pub fn connected(head: &[u8], body: Bytes) -> Outgoing {
        Outgoing::with(head, body, None)
    }

    fn with(head: &[u8], body: Bytes, to: Option<SocketAddr>) -> Outgoing {
        let mut out = Outgoing {
            head: [0; MAX_HEAD],
            head_len: 0,
            body,
            to,
        };
        if head.len() <= MAX_HEAD {
            out.head[..head.len()].copy_from_slice(head);
            out.head_len = head.len() as u8;
        } else {
            let mut joined = Vec::with_capacity(head.len() + out.body.len());
            joined.extend_from_slice(head);
            joined.extend_from_slice(&out.body);
            out.body = Bytes::from(joined);
        }
        out
    }

    fn head(&self) -> &[u8] {
        &self.head[..usize::from(self.head_len)]
    }

    /// Where it goes, as an error names it.
    fn dest(&self) -> String {
        self.to
            .map_or_else(|| "the connected peer".to_string(), |to| to.to_string())
    }
}

struct State {
    queue: VecDeque<Outgoing>,
    /// an empty queue kept for the next batch taken whole, so that taking one allocates nothing
    spare: VecDeque<Outgoing>,
    /// somebody (the outbox's task, or a sender with a full batch) is sending from the queue
    sending: bool,
    /// when the last handover ended (when it began, for one that neither called the kernel nor
    /// waited: the same to within the lock)
    last: Option<Instant>,
    /// handovers in a row less than [`QUIET`] apart
    streak: u32,
    /// when the oldest datagram waiting was queued
    oldest: Option<Instant>,
    /// flushed while a send was under way: what waits goes, without waiting, as that send ends
    flushing: bool,
}

struct Shared {
    socket: Arc<UdpSocket>,
    /// handovers less than this apart make a stream ([`QUIET`])
    quiet: Duration,
    state: Mutex<State>,
    /// wakes the outbox's task: datagrams wait
    wake: Notify,
    /// wakes senders waiting for room
    room: Notify,
    ingress: Ingress,
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Takes every datagram waiting, to be sent by the caller ([`Shared::send_taken`]).
    fn take(st: &mut State) -> VecDeque<Outgoing> {
        st.sending = true;
        st.oldest = None;
        let spare = std::mem::take(&mut st.spare);
        std::mem::replace(&mut st.queue, spare)
    }

    /// Sends `batch`, taken with [`Shared::take`], waiting while the socket has no room; a
    /// datagram that fails is counted and logged, and the rest still go. Then marks the queue free,
    /// waking whoever waits for room and the outbox's task when more wait to go. A sender that
    /// stops waiting midway (its future dropped) puts what was not sent back at the queue's front.
    async fn send_taken(&self, batch: VecDeque<Outgoing>) {
        let mut taken = Taken {
            shared: self,
            batch,
            at: 0,
        };
        let batch = &*taken.batch.make_contiguous();
        let mut at = 0;
        while at < batch.len() {
            // tried at once; the runtime's word that the socket has room is awaited only once it
            // had none (the runtime learns of room only when it next looks, which a task that
            // keeps sending without waiting may put off)
            let sent = match send_now(&self.socket, &batch[at..]) {
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    self.socket
                        .async_io(Interest::WRITABLE, || send_now(&self.socket, &batch[at..]))
                        .await
                }
                sent => sent,
            };
            at += self.went(sent, &batch[at]);
            taken.at = at;
        }
    }
}

/// What became of a datagram handed to the queue.
enum Queued {
    /// It waits in the queue, for the outbox's task or the next batch.
    Waits,
    /// It filled a batch, taken for the caller to send.
    Batch(VecDeque<Outgoing>),
    /// The queue had no room: handed back.
    Full(Outgoing),
}

impl Shared {
    /// Puts `d` in the queue at `at` when it has room, taking the batch it fills when nobody
    /// sends from the queue, or waking the outbox's task for the first datagram waiting.
    fn queue_up(&self, d: Outgoing, at: Instant) -> Queued {
        let mut st = self.lock();
        if st.queue.len() >= CAPACITY {
            if st.sending {
                return Queued::Full(d);
            }
            // full, and nobody sends from it (the outbox's task has not run yet, or is gone with
            // its medium): this sender sends what waits, and `d` waits after it
            let batch = Shared::take(&mut st);
            st.queue.push_back(d);
            st.oldest = Some(at);
            return Queued::Batch(batch);
        }
        st.queue.push_back(d);
        if st.oldest.is_none() {
            st.oldest = Some(at);
        }
        if st.queue.len() >= BATCH && !st.sending {
            return Queued::Batch(Shared::take(&mut st));
        }
        if st.queue.len() == 1 && !st.sending {
            self.wake.notify_one();
        }
        Queued::Waits
    }

    /// Sends everything waiting at once, without waiting for room: what the socket does not take
    /// is counted as failed ([`Outbox::flush_now`]).
    fn send_all_now(&self) {
        let batch: Vec<Outgoing> = {
            let mut st = self.lock();
            st.oldest = None;
            st.queue.drain(..).collect()
        };
        let mut at = 0;
        while at < batch.len() {
            at += self.went(send_now(&self.socket, &batch[at..]), &batch[at]);
        }
    }

    /// How many datagrams of a batch starting with `first` a send call dealt with: those it sent,
    /// or the first, which failed (counted and logged).
    fn went(&self, sent: io::Result<usize>, first: &Outgoing) -> usize {
        match sent {
            Ok(n) => n.max(1),
            Err(e) => {
                self.ingress
                    .send_failed(format_args!("sending to {}: {e}", first.dest()));
                1
            }
        }
    }
}

/// A batch taken from the queue while it is being sent: when dropped, whether sent or given up
/// midway, the queue is free again and what was not sent is back at its front.
struct Taken<'a> {
    shared: &'a Shared,
    batch: VecDeque<Outgoing>,
    /// datagrams of the batch sent (or failed) so far
    at: usize,
}

impl Drop for Taken<'_> {
    fn drop(&mut self) {
        let mut batch = std::mem::take(&mut self.batch);
        let unsent = batch.split_off(self.at.min(batch.len()));
        batch.clear();
        let (waiting, flushing) = {
            let mut st = self.shared.lock();
            st.sending = false;
            if !unsent.is_empty() {
                for d in unsent.into_iter().rev() {
                    st.queue.push_front(d);
                }
                st.oldest = Some(Instant::now());
            }
            st.spare = batch;
            (!st.queue.is_empty(), st.flushing)
        };
        self.shared.room.notify_waiters();
        if flushing {
            self.shared.send_all_now();
        } else if waiting {
            self.shared.wake.notify_one();
        }
    }
}

/// A transport's outbox until its medium closes.
#[derive(Default)]
pub struct Held(ArcSwapOption<Outbox>);

impl Held {
    /// Holding `outbox`.
    pub fn new(outbox: Outbox) -> Held {
        Held(ArcSwapOption::from_pointee(outbox))
    }

    /// The outbox; `None` once closed.
    pub fn get(&self) -> Option<Arc<Outbox>> {
        self.0.load_full()
    }

    /// [`Outbox::flush`], at once once closed.
    pub async fn flush(&self) {
        let outbox = self.get();
        if let Some(outbox) = outbox {
            outbox.flush().await;
        }
    }

    /// Lets the outbox go: what waits is sent once the sends under way end ([`Outbox`]'s drop).
    pub fn close(&self) {
        self.0.store(None);
    }
}

/// Sends a medium's datagrams on its socket (see the module's documentation).
pub struct Outbox {
    shared: Arc<Shared>,
}

impl Outbox {
    /// An outbox for `socket`, handovers less than `gap` apart making a stream ([`QUIET`] by
    /// default; zero: none does). Its task stops when the medium `ingress` belongs to closes.
    pub fn new(socket: Arc<UdpSocket>, ingress: &Ingress, gap: Duration) -> Outbox {
        let shared = Arc::new(Shared {
            socket,
            quiet: gap,
            state: Mutex::new(State {
                queue: VecDeque::new(),
                spare: VecDeque::new(),
                sending: false,
                last: None,
                streak: 0,
                oldest: None,
                flushing: false,
            }),
            wake: Notify::new(),
            room: Notify::new(),
            ingress: ingress.clone(),
        });
        let task = tokio::spawn(run(shared.clone()));
        ingress.own_task(task.abort_handle());
        Outbox { shared }
    }

    /// Sends `ds` in order: at once unless they are part of a stream (returning the first error,
    /// which names the datagram's destination unless the socket is connected, the datagrams after
    /// it not sent), else through the queue (waiting for room when it is full). Datagrams that
    /// have waited a gap or longer go now, before these.
    pub async fn send(&self, ds: &[Outgoing]) -> io::Result<()> {
        let now = Instant::now();
        let free = |st: &State| st.queue.is_empty() && !st.sending;
        let (stream, overdue, free_now) = {
            let mut st = self.shared.lock();
            let soon = st
                .last
                .is_some_and(|l| now.saturating_duration_since(l) < self.shared.quiet);
            st.streak = if soon { st.streak.saturating_add(1) } else { 0 };
            // a handover that neither calls the kernel nor waits ends now
            st.last = Some(now);
            let overdue = !st.sending
                && st
                    .oldest
                    .is_some_and(|o| now.saturating_duration_since(o) >= self.shared.quiet);
            let overdue = overdue.then(|| Shared::take(&mut st));
            (st.streak >= STREAM, overdue, free(&st))
        };
        let mut called = overdue.is_some();
        let free_now = match overdue {
            // the sender's task may not have let the outbox's run since: they go now
            Some(batch) => {
                self.shared.send_taken(batch).await;
                free(&self.shared.lock())
            }
            None => free_now,
        };
        let quiet = !stream && free_now;
        let mut at = 0;
        if quiet {
            while at < ds.len() {
                match send_now(&self.shared.socket, &ds[at..]) {
                    Ok(n) => at += n.max(1),
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                    Err(e) => {
                        return Err(match ds[at].to {
                            Some(to) => io::Error::new(e.kind(), format!("to {to}: {e}")),
                            None => e,
                        });
                    }
                }
            }
        }
        // a send tried, even one the socket had no room for, took the kernel's time
        called |= quiet;
        for d in &ds[at..] {
            called |= self.enqueue(d.clone(), now).await;
        }
        // the gap to the next handover is the sender's own time, not that of its sends or waits
        if called {
            self.shared.lock().last = Some(Instant::now());
        }
        Ok(())
    }

    /// Puts `d` in the queue at `now`, waiting for room; a sender that fills a batch sends it.
    /// True when it waited or sent one (`now` is then past).
    async fn enqueue(&self, mut d: Outgoing, now: Instant) -> bool {
        let mut at = now;
        let mut waited = false;
        loop {
            match self.shared.queue_up(d, at) {
                Queued::Waits => return waited,
                Queued::Batch(batch) => {
                    self.shared.send_taken(batch).await;
                    return true;
                }
                Queued::Full(back) => {
                    d = back;
                    let room = self.shared.room.notified();
                    tokio::pin!(room);
                    room.as_mut().enable();
                    // room made between the look and the registration is not waited for
                    if self.shared.lock().queue.len() < CAPACITY {
                        continue;
                    }
                    room.await;
                    waited = true;
                    at = Instant::now();
                }
            }
        }
    }

    /// Returns once every datagram handed over so far has been given to the socket (a program
    /// about to end, [`Transport::flush`]), sending what waits from this task.
    ///
    /// [`Transport::flush`]: crate::medium::Transport::flush
    pub async fn flush(&self) {
        loop {
            let room = self.shared.room.notified();
            tokio::pin!(room);
            room.as_mut().enable();
            let batch = {
                let mut st = self.shared.lock();
                if st.queue.is_empty() && !st.sending {
                    return;
                }
                (!st.sending).then(|| Shared::take(&mut st))
            };
            match batch {
                Some(batch) => self.shared.send_taken(batch).await,
                // another sends a batch: it wakes those waiting for room when done
                None => room.await,
            }
        }
    }

    /// Datagrams waiting in the queue.
    pub fn waiting(&self) -> usize {
        self.shared.lock().queue.len()
    }

    /// Sends what waits without waiting for room (the outbox dropped: its medium closing); what
    /// the socket does not take is counted as failed. While a send from the queue is under way
    /// (the outbox's task on another thread), what waits goes as that send ends, after it:
    /// datagrams leave in the order they were handed over.
    fn flush_now(&self) {
        {
            let mut st = self.shared.lock();
            if st.sending {
                st.flushing = true;
                return;
            }
        }
        self.shared.send_all_now();
    }
}

impl Drop for Outbox {
    fn drop(&mut self) {
        self.flush_now();
    }
}

/// The outbox's task: sends what waits whenever nobody else is.
async fn run(shared: Arc<Shared>) {
    loop {
        shared.wake.notified().await;
        loop {
            let batch = {
                let mut st = shared.lock();
                if st.queue.is_empty() || st.sending {
                    break;
                }
                Shared::take(&mut st)
            };
            shared.send_taken(batch).await;
        }
    }
}

/// Sends as many of `ds` (up to [`BATCH`]) as the socket takes now in one sendmmsg(2) call: how
/// many went, or the error of the first (`WouldBlock` when the socket has no room).
fn send_now(socket: &UdpSocket, ds: &[Outgoing]) -> io::Result<usize> {
    let n = ds.len().min(BATCH);
    let ds = &ds[..n];
    let addrs: [Option<SockAddr>; BATCH] =
        std::array::from_fn(|i| ds.get(i).and_then(|d| d.to).map(SockAddr::from));
    let mut iovs: [libc::iovec; 2 * BATCH] = std::array::from_fn(|j| {
        let part = ds
            .get(j / 2)
            .map_or(&[][..], |d| if j % 2 == 0 { d.head() } else { &d.body[..] });
        libc::iovec {
            iov_base: part.as_ptr() as *mut libc::c_void,
            iov_len: part.len(),
        }
    });
    // SAFETY: mmsghdr is plain data; zeroed means no address, no control data and no flags
    let mut msgs: [libc::mmsghdr; BATCH] = unsafe { std::mem::zeroed() };
    for (i, (m, a)) in msgs.iter_mut().zip(&addrs).take(n).enumerate() {
        if let Some(a) = a {
            m.msg_hdr.msg_name = a.as_ptr() as *mut libc::c_void;
            m.msg_hdr.msg_namelen = a.len();
        }
        // SAFETY: `iovs` holds two entries per datagram: 2i and 2i + 1 lie inside it
        m.msg_hdr.msg_iov = unsafe { iovs.as_mut_ptr().add(2 * i) };
        m.msg_hdr.msg_iovlen = 2;
    }
    // SAFETY: every header points at an address and two iovecs that outlive the call, each with
    // its true length, and the iovecs at the datagram's parts, which the kernel only reads
    let sent = unsafe {
        libc::sendmmsg(
            socket.as_raw_fd(),
            msgs.as_mut_ptr(),
            n as libc::c_uint,
            libc::MSG_DONTWAIT,
        )
    };
    if sent < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(sent as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::medium::{Medium, Node};

    /// Long enough that a test's sends in a row make a stream on a busy machine.
    const TEST_QUIET: Duration = Duration::from_millis(20);

    /// A medium (for its counters), a sending socket and a receiving one on loopback.
    fn pair() -> (Medium, Arc<UdpSocket>, std::net::UdpSocket) {
        let medium = Medium::in_process("net", &Node::new("n"));
        let rx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        rx.set_nonblocking(true).unwrap();
        let tx = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        tx.set_nonblocking(true).unwrap();
        let tx = Arc::new(UdpSocket::from_std(tx).unwrap());
        (medium, tx, rx)
    }

    /// [`pair`] with an outbox on the sending socket, and where the receiving one listens.
    fn opened() -> (Medium, Outbox, std::net::UdpSocket, SocketAddr) {
        let (medium, tx, rx) = pair();
        let to = rx.local_addr().unwrap();
        let outbox = Outbox::new(tx, &medium.ingress(), TEST_QUIET);
        (medium, outbox, rx, to)
    }

    /// Everything waiting on `rx` now.
    fn waiting(rx: &std::net::UdpSocket) -> Vec<Vec<u8>> {
        let mut got = Vec::new();
        let mut buf = [0u8; 2048];
        while let Ok(n) = rx.recv(&mut buf) {
            got.push(buf[..n].to_vec());
        }
        got
    }

    fn datagram(i: u32, to: SocketAddr) -> Outgoing {
        Outgoing::new(&i.to_be_bytes(), Bytes::from_static(b"body"), to)
    }

    fn numbers(got: &[Vec<u8>]) -> Vec<u32> {
        got.iter()
            .map(|d| {
                assert_eq!(&d[4..], b"body");
                u32::from_be_bytes(d[..4].try_into().unwrap())
            })
            .collect()
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_lone_datagram_leaves_before_send_returns() {
        let (_medium, outbox, rx, to) = opened();
        for i in 0..3 {
            outbox.send(&[datagram(i, to)]).await.unwrap();
            // no task has run in between: the sender's own call sent it
            assert_eq!(numbers(&waiting(&rx)), [i]);
            std::thread::sleep(TEST_QUIET * 2);
        }
        // a head and body together, fragments of one message in one call
        let long_head = [7u8; MAX_HEAD + 3];
        outbox
            .send(&[
                Outgoing::new(&long_head, Bytes::from_static(b"x"), to),
                Outgoing::new(b"ab", Bytes::from_static(b"cd"), to),
            ])
            .await
            .unwrap();
        let got = waiting(&rx);
        assert_eq!(got.len(), 2);
        assert_eq!(got[0][..MAX_HEAD + 3], long_head);
        assert_eq!(got[0][MAX_HEAD + 3..], *b"x");
        assert_eq!(got[1], b"abcd");
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_stream_goes_in_batches_in_order_and_its_tail_when_the_sender_waits() {
        let (medium, outbox, rx, to) = opened();
        let n = 3 * BATCH as u32 + 5;
        for i in 0..n {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        // the first of the stream went one by one, then whole batches; the tail waits
        let first = numbers(&waiting(&rx));
        let sent = first.len() as u32;
        assert_eq!(first, (0..sent).collect::<Vec<_>>());
        assert!(sent < n, "the tail of a stream waits for the outbox's task");
        assert_eq!(outbox.waiting() as u32, n - sent);
        // the sender waits for something: the outbox's task sends the rest
        tokio::time::sleep(Duration::from_millis(5)).await;
        assert_eq!(numbers(&waiting(&rx)), (sent..n).collect::<Vec<_>>());
        assert_eq!(outbox.waiting(), 0);
        assert_eq!(medium.stats().tx_errors, 0);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_sender_finding_the_queue_full_waits_for_room_and_nothing_is_lost() {
        let (medium, outbox, rx, to) = opened();
        let outbox = Arc::new(outbox);
        // somebody is sending from the queue (a sender whose batch met a full socket): nothing
        // leaves at once, and the queue fills
        outbox.shared.lock().sending = true;
        let n = CAPACITY as u32 + 5;
        let sender = {
            let outbox = outbox.clone();
            tokio::spawn(async move {
                for i in 0..n {
                    outbox.send(&[datagram(i, to)]).await.unwrap();
                }
            })
        };
        for _ in 0..100 {
            tokio::task::yield_now().await;
        }
        assert!(
            !sender.is_finished(),
            "a sender waits while the queue is full"
        );
        assert_eq!(outbox.waiting(), CAPACITY);
        assert!(waiting(&rx).is_empty());
        // the batch under way ends: the queue is taken and sent, and the sender goes on
        let batch = Shared::take(&mut outbox.shared.lock());
        outbox.shared.send_taken(batch).await;
        tokio::time::timeout(Duration::from_secs(5), sender)
            .await
            .expect("the sender goes on once there is room")
            .unwrap();
        outbox.flush().await;
        let mut got = Vec::new();
        for _ in 0..100 {
            got.extend(numbers(&waiting(&rx)));
            if got.len() >= n as usize {
                break;
            }
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        assert_eq!(got, (0..n).collect::<Vec<_>>());
        assert_eq!(medium.stats().tx_errors, 0);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_full_queue_nobody_sends_from_is_sent_by_the_next_sender() {
        let (medium, outbox, rx, to) = opened();
        // the medium closes: the outbox's task is gone, and a send under way leaves the queue full
        medium.close();
        tokio::task::yield_now().await;
        outbox.shared.lock().sending = true;
        let n = CAPACITY as u32;
        for i in 0..n {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        outbox.shared.lock().sending = false;
        assert_eq!(outbox.waiting(), CAPACITY);
        // the next sender does not wait for room nobody would make: it sends what waits first
        tokio::time::timeout(Duration::from_secs(5), outbox.send(&[datagram(n, to)]))
            .await
            .expect("a sender never waits on a full queue nobody sends from")
            .unwrap();
        outbox.flush().await;
        assert_eq!(numbers(&waiting(&rx)), (0..=n).collect::<Vec<_>>());
    }

    #[tokio::test(flavor = "current_thread")]
    async fn what_waits_when_the_outbox_is_dropped_goes_after_the_send_under_way() {
        let (medium, outbox, rx, to) = opened();
        // the outbox's task (on another thread) is sending datagrams 0 to 9, taken from the
        // queue; 10 to 14 came after them and wait
        outbox.shared.lock().sending = true;
        for i in 10..15 {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        assert_eq!(outbox.waiting(), 5);
        let shared = outbox.shared.clone();
        drop(outbox);
        assert!(
            waiting(&rx).is_empty(),
            "nothing overtakes the send under way"
        );
        // that send ends: its datagrams, then those that waited
        let under_way: VecDeque<Outgoing> = (0..10).map(|i| datagram(i, to)).collect();
        shared.send_taken(under_way).await;
        assert_eq!(numbers(&waiting(&rx)), (0..15).collect::<Vec<_>>());
        assert!(shared.lock().queue.is_empty());
        assert_eq!(medium.stats().tx_errors, 0);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn what_waited_goes_before_the_next_datagram_and_all_goes_when_the_outbox_is_dropped() {
        let (_medium, outbox, rx, to) = opened();
        let stream = STREAM + 3;
        for i in 0..stream {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        let before = numbers(&waiting(&rx)).len() as u32;
        assert!(before < stream);
        // the sender went on without waiting on anything, then sends again after a pause: the
        // overdue ones go first, then this one, at once
        std::thread::sleep(TEST_QUIET * 2);
        outbox.send(&[datagram(stream, to)]).await.unwrap();
        assert_eq!(
            numbers(&waiting(&rx)),
            (before..=stream).collect::<Vec<_>>()
        );
        // a stream's tail goes when the outbox is dropped (its medium closing)
        for i in 0..stream {
            outbox.send(&[datagram(100 + i, to)]).await.unwrap();
        }
        let sent = waiting(&rx).len() as u32;
        drop(outbox);
        assert_eq!(
            numbers(&waiting(&rx)),
            (100 + sent..100 + stream).collect::<Vec<_>>()
        );
    }

    #[tokio::test(flavor = "current_thread")]
    async fn flush_returns_once_a_streams_tail_is_sent() {
        let (_medium, outbox, rx, to) = opened();
        let n = BATCH as u32 + 3;
        for i in 0..n {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        assert!(outbox.waiting() > 0);
        outbox.flush().await;
        assert_eq!(outbox.waiting(), 0);
        assert_eq!(numbers(&waiting(&rx)), (0..n).collect::<Vec<_>>());
        // nothing waiting: at once
        outbox.flush().await;
    }

    #[tokio::test(flavor = "current_thread")]
    async fn failures_are_returned_when_sent_at_once_and_counted_when_sent_from_the_queue() {
        let (medium, outbox, rx, to) = opened();
        // larger than any UDP datagram
        let huge = Outgoing::new(&[], Bytes::from(vec![0u8; 70_000]), to);
        let e = outbox.send(std::slice::from_ref(&huge)).await.unwrap_err();
        assert!(e.to_string().starts_with(&format!("to {to}: ")), "{e}");
        assert_eq!(medium.stats().tx_errors, 0, "returned, not counted");
        // in a stream, it waits in the queue: counted, and those after it still go
        for i in 0..STREAM {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        outbox.send(&[huge, datagram(50, to)]).await.unwrap();
        tokio::time::sleep(Duration::from_millis(5)).await;
        let got = numbers(&waiting(&rx));
        assert_eq!(got.last(), Some(&50));
        assert_eq!(got.len() as u32, STREAM + 1);
        assert_eq!(medium.stats().tx_errors, 1);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_batch_given_up_midway_goes_back_to_the_front_and_the_outbox_goes_on() {
        // a sender whose future is dropped while it waits for room in the socket (a timeout
        // around its send) leaves the rest of the batch it took to whoever sends next
        let (_medium, outbox, rx, to) = opened();
        for i in 0..STREAM + 4 {
            outbox.send(&[datagram(i, to)]).await.unwrap();
        }
        assert_eq!(numbers(&waiting(&rx)), (0..STREAM).collect::<Vec<_>>());
        let batch = Shared::take(&mut outbox.shared.lock());
        assert_eq!(batch.len(), 4);
        outbox.send(&[datagram(99, to)]).await.unwrap();
        // the first of the batch went, then its sender stopped waiting
        send_now(&outbox.shared.socket, &batch.as_slices().0[..1]).unwrap();
        drop(Taken {
            shared: &outbox.shared,
            batch,
            at: 1,
        });
        assert!(!outbox.shared.lock().sending);
        assert_eq!(outbox.waiting(), 4);
        outbox.flush().await;
        assert_eq!(
            numbers(&waiting(&rx)),
            [STREAM, STREAM + 1, STREAM + 2, STREAM + 3, 99]
        );
    }

    #[tokio::test(flavor = "current_thread")]
    async fn what_waited_a_gap_goes_with_the_next_datagram_of_a_stream() {
        // a stream whose sends come within the gap, while the oldest waiting passes it
        let (_medium, outbox, rx, to) = opened();
        let n = STREAM + 8;
        for i in 0..n {
            outbox.send(&[datagram(i, to)]).await.unwrap();
            if i >= STREAM {
                std::thread::sleep(TEST_QUIET / 4);
            }
        }
        let early = numbers(&waiting(&rx));
        assert!(early.len() > STREAM as usize, "{early:?}");
        assert_eq!(early, (0..early.len() as u32).collect::<Vec<_>>());
        tokio::time::timeout(Duration::from_secs(5), outbox.flush())
            .await
            .expect("the outbox is free again");
        let rest = numbers(&waiting(&rx));
        assert_eq!(rest, (early.len() as u32..n).collect::<Vec<_>>());
    }

    #[tokio::test(flavor = "current_thread")]
    async fn no_gap_sends_every_datagram_at_once() {
        let (medium, tx, rx) = pair();
        let to = rx.local_addr().unwrap();
        let outbox = Outbox::new(tx, &medium.ingress(), Duration::ZERO);
        for i in 0..3 * STREAM {
            outbox.send(&[datagram(i, to)]).await.unwrap();
            assert_eq!(outbox.waiting(), 0);
        }
        assert_eq!(numbers(&waiting(&rx)), (0..3 * STREAM).collect::<Vec<_>>());
    }

    #[test]
    fn a_urls_gap_is_a_duration_up_to_a_second() {
        let gap = |text: &str| gap_from_url(&mut MediumUrl::parse(text).unwrap());
        assert_eq!(gap("udp://127.0.0.1:1").unwrap(), None);
        assert_eq!(
            gap("udp://127.0.0.1:1?send_gap=2ms").unwrap(),
            Some(Duration::from_millis(2))
        );
        assert_eq!(
            gap("udp://127.0.0.1:1?send_gap=0").unwrap(),
            Some(Duration::ZERO)
        );
        for bad in ["2s", "soon", "-1"] {
            let e = gap(&format!("udp://127.0.0.1:1?send_gap={bad}")).unwrap_err();
            assert!(
                e.reason
                    .starts_with(&format!("option `send_gap={bad}`: expected a duration")),
                "{e}"
            );
        }
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_connected_socket_sends_without_an_address() {
        let (medium, tx, rx) = pair();
        tx.connect(rx.local_addr().unwrap()).await.unwrap();
        let outbox = Outbox::new(tx, &medium.ingress(), QUIET);
        outbox
            .send(&[Outgoing::connected(b"he", Bytes::from_static(b"llo"))])
            .await
            .unwrap();
        assert_eq!(waiting(&rx), [b"hello".to_vec()]);
    }
}
