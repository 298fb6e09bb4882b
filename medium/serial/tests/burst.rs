//! Bursts of about 1 MB/s of NMEA sentences written into a real pseudo-terminal, read by a
//! `serial://` medium: every sentence written reaches each receiver or is counted as lost, and a
//! burst that loses sentences is warned of once, with the count, when it ends.

use seabus_medium::framing::nmea_sentence;
use seabus_medium::{Interface, LinkState, Medium, Node};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;
use tokio::time::timeout;
use tracing::span;

/// Bytes a second written in a burst.
const RATE: usize = 1_000_000;
/// Bytes written at a time: the burst is paced in steps of 10 ms.
const STEP: usize = RATE / 100;

/// The warnings logged anywhere in this test program, each with its fields (`medium=…`).
fn warnings() -> &'static Arc<Mutex<Vec<String>>> {
    static CAUGHT: OnceLock<Arc<Mutex<Vec<String>>>> = OnceLock::new();
    CAUGHT.get_or_init(|| {
        let caught = Arc::new(Mutex::new(Vec::new()));
        tracing::subscriber::set_global_default(Warnings(caught.clone()))
            .expect("the only subscriber of this program");
        caught
    })
}

struct Warnings(Arc<Mutex<Vec<String>>>);

impl tracing::Subscriber for Warnings {
    fn enabled(&self, m: &tracing::Metadata<'_>) -> bool {
        *m.level() <= tracing::Level::WARN
    }
    fn new_span(&self, _: &span::Attributes<'_>) -> span::Id {
        span::Id::from_u64(1)
    }
    fn record(&self, _: &span::Id, _: &span::Record<'_>) {}
    fn record_follows_from(&self, _: &span::Id, _: &span::Id) {}
    fn event(&self, e: &tracing::Event<'_>) {
        let mut line = String::new();
        e.record(&mut |f: &tracing::field::Field, v: &dyn std::fmt::Debug| {
            line += &format!("{f}={v:?} ");
        });
        self.0.lock().unwrap().push(line.trim_end().to_string());
    }
    fn enter(&self, _: &span::Id) {}
    fn exit(&self, _: &span::Id) {}
}

/// The warnings about medium `name` so far.
fn warnings_of(name: &str) -> Vec<String> {
    let tag = format!("medium={name}");
    let all = warnings().lock().unwrap();
    all.iter()
        .filter(|w| w.split(' ').any(|f| f == tag))
        .cloned()
        .collect()
}

/// A serial medium called `name` reading a new pseudo-terminal, and the terminal's other side,
/// where the test writes (and the file that holds the terminal open).
async fn line(
    name: &str,
) -> (
    Medium,
    tokio_serial::SerialStream,
    std::fs::File,
    tempfile::TempDir,
) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("gps").display().to_string();
    let (master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let far = tokio_serial::SerialPort::name(&slave).unwrap();
    let held = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&far)
        .unwrap();
    drop(slave);
    std::os::unix::fs::symlink(&far, &path).unwrap();
    let node = Node::new("n");
    let medium = seabus_medium_serial::schemes()
        .open(name, &format!("serial://{path}?baud=115200"), &node)
        .unwrap();
    let mut link = medium.watch_link();
    timeout(
        Duration::from_secs(5),
        link.wait_for(|s| *s == LinkState::Up),
    )
    .await
    .expect("the line opens")
    .unwrap();
    (medium, master, held, dir)
}

/// Sentence number `n` of a burst, with its line ending (61 bytes).
fn sentence(n: u64) -> String {
    format!(
        "{}\r\n",
        nmea_sentence(
            b'$',
            &format!("GPTXT,01,01,02,seabus burst sentence {n:08} at 1 MB/s")
        )
    )
}

/// The number of a sentence of a burst.
fn number(payload: &[u8]) -> u64 {
    let text = std::str::from_utf8(payload).unwrap();
    let at = text.find("sentence ").unwrap() + "sentence ".len();
    text[at..at + 8].parse().unwrap()
}

/// Writes sentences into `port` at [`RATE`] for `length`; returns how many and how long it took.
async fn burst(port: &mut tokio_serial::SerialStream, length: Duration) -> (u64, Duration) {
    let start = tokio::time::Instant::now();
    let per_step = (STEP / sentence(0).len()) as u64;
    let steps = (length.as_millis() / 10) as u64;
    let mut n = 0;
    for step in 1..=steps {
        let mut chunk = Vec::with_capacity(STEP);
        for _ in 0..per_step {
            chunk.extend_from_slice(sentence(n).as_bytes());
            n += 1;
        }
        port.write_all(&chunk).await.unwrap();
        tokio::time::sleep_until(start + Duration::from_millis(step * 10)).await;
    }
    port.flush().await.unwrap();
    (n, start.elapsed())
}

/// Takes what `rx` gets until it gets nothing for a second, spending `work` on each sentence (a
/// receiver slower than the line); returns the numbers of the sentences, in order.
async fn drain(rx: &mut Interface, work: Duration) -> Vec<u64> {
    let mut got = Vec::new();
    while let Ok(Some(m)) = timeout(Duration::from_secs(1), rx.recv()).await {
        got.push(number(m.payload.as_bytes().unwrap()));
        let t = Instant::now();
        while t.elapsed() < work {
            std::hint::spin_loop();
        }
    }
    got
}

/// Whether `got` is strictly increasing: sentences are lost (oldest first), never reordered or
/// repeated.
fn in_order(got: &[u64]) -> bool {
    got.windows(2).all(|w| w[0] < w[1])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_1_mb_s_burst_loses_nothing_that_is_not_counted() {
    warnings();
    let (medium, mut port, _held, _dir) = line("gps-line").await;
    // a receiver that keeps up, and one that needs 100 µs a sentence (10 000 a second for the
    // 16 300 of the burst)
    let receiver = |name: &str, work: Duration| {
        let mut rx = medium.attach(name).subscribed("nmea.**").unwrap();
        tokio::spawn(async move { (drain(&mut rx, work).await, rx) })
    };
    let fast = receiver("fast", Duration::ZERO);
    let slow = receiver("slow", Duration::from_micros(100));
    let (written, took) = burst(&mut port, Duration::from_millis(1500)).await;
    let (fast_got, _) = fast.await.unwrap();
    let (slow_got, slow) = slow.await.unwrap();
    let st = medium.stats();
    eprintln!(
        "{written} sentences ({} kB) in {took:?}: the fast receiver got {}, the slow one {} \
         ({} lost, {:.1} %); {st:?}",
        written * sentence(0).len() as u64 / 1000,
        fast_got.len(),
        slow_got.len(),
        written - slow_got.len() as u64,
        100.0 * (written - slow_got.len() as u64) as f64 / written as f64,
    );
    assert!(took < Duration::from_secs(5), "the line took {took:?}");
    // the line itself loses nothing: every sentence was read, none rejected or dropped
    assert_eq!(st.received, written, "{st:?}");
    assert_eq!(
        (st.rejected_total(), st.dropped_bytes, st.overruns),
        (0, 0, 0),
        "{st:?}"
    );
    assert_eq!(fast_got.len() as u64, written);
    assert!(in_order(&fast_got) && in_order(&slow_got));
    // what the slow receiver missed is exactly what its queue counted as dropped
    let missing = written - slow_got.len() as u64;
    let counted = st.queue_dropped.get("slow").copied().unwrap_or(0);
    assert_eq!(counted, missing, "{st:?}");
    assert_eq!(slow.stats().dropped_oldest, missing);
    assert_eq!(st.queue_dropped.get("fast"), None, "{st:?}");
    assert_eq!(st.queue_dropped_total(), missing);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_that_drops_sentences_is_warned_of_once_with_the_count() {
    warnings();
    let (medium, mut port, _held, _dir) = line("compass-line").await;
    // a receiver with room for 64 sentences that reads none while the burst lasts
    let mut stalled = medium.attach_with("stalled", 64, 8);
    stalled.subscribe("nmea.**").unwrap();
    let (written, _) = burst(&mut port, Duration::from_millis(1000)).await;
    // the burst's end is said a second after its last loss
    let got = drain(&mut stalled, Duration::ZERO).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let lost = medium.stats().queue_dropped["stalled"];
    assert_eq!(lost, written - got.len() as u64);
    assert!(got.len() >= 64 && lost > 0, "lost {lost} of {written}");
    let said = warnings_of("compass-line");
    assert_eq!(said.len(), 1, "{said:?}");
    let text = &said[0];
    assert!(
        text.contains(&format!("message={lost} messages lost in a burst over "))
            && text.contains(" s (queue of stalled full)"),
        "{text}"
    );
    // and nothing more while nothing more is lost
    tokio::time::sleep(Duration::from_millis(1500)).await;
    assert_eq!(warnings_of("compass-line").len(), 1);
}
