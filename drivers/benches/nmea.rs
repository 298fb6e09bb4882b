//! NMEA throughput and latency.
//!
//! 1. In memory (`memory`): sentences per second through seabus's per-sentence work — framing a byte
//!    stream, the checksum, the serial medium's topic, parsing, and the GPS/heading drivers'
//!    conversion to datasets — against bare `nmea::parse_str` on the same sentences (already cut
//!    into strings). No tasks, no queues, no pseudo-terminal. Target: at least 1.0×. The same
//!    work without the drivers' readings, in the same rounds, says how the time divides.
//! 2. The whole path over a pseudo-terminal (`line`): mixed traffic as a multiplexer's line carries
//!    it (a GPS, a compass with pitch and roll, a sounder, a log, a wind sensor and an AIS receiver:
//!    19 sentences per second of traffic, 500 seconds of it, 9 500 sentences) written into the
//!    master side of a pty made here, read by a `serial://` medium; the `nmea-gps`, `nmea-heading`
//!    and `nmea-sounder` drivers run as modules on that line and an in-process bus, started by the
//!    module runtime from system XML as `seabus run` starts them, and a subscriber on the bus counts
//!    the datasets. Timed from the first byte written until the last dataset the traffic gives
//!    (counted beforehand by the same drivers in memory) has arrived. The device writes 200
//!    sentences at a time and never more than two such chunks ahead of the datasets counted: a
//!    driver's queue holds 1024 sentences and drops the oldest beyond, so a device that never waits
//!    measures how much is lost, not how fast the path goes (shown once at the end). The reference
//!    is bare `nmea::parse_str` over the same sentences already cut into strings, on one thread.
//!    Two ratios: wall-clock sentences per second, and CPU time per sentence (the process's user +
//!    system time over the run, less the device thread's) against `parse_str`'s time per sentence.
//!    Measured in the same rounds, what the path is built on: seabus's per-sentence work on one
//!    thread without the pty and without tasks; the pty alone, read raw by a plain thread (a pty
//!    moves some hundreds of MB/s here: the ceiling of any reader); and the pty read by the serial
//!    medium with one subscriber and no drivers. Target: a CPU ratio of at least 1.0× the bare
//!    parse.
//! 3. Serial → bus latency over a pseudo-terminal (`latency`): a sentence written on the far end of
//!    a pty, until it is taken from an interface on the serial medium; p50 and p99 at 200 sentences
//!    per second.
//!
//! Run: `cargo bench -p seabus-drivers --bench nmea` (all three), or name the parts to run:
//! `cargo bench -p seabus-drivers --bench nmea -- line`. The smoke run (`SEABUS_BENCH_SMOKE=1`)
//! takes fewer rounds and fewer sentences for the latency.

use seabus_bench::{Goals, scale};
use seabus_drivers::nmea::sensors::{Role, Sensor};
use seabus_drivers::nmea::sentence::{build, parse};
use seabus_medium::framing::{ChecksumPolicy, Framer, Framing, nmea_sentence};
use seabus_medium::url::MediumUrl;
use seabus_medium::{LinkState, Medium, Node, Payload};
use seabus_medium_serial::{FrameTopics, SerialConfig};
use seabus_modules::{Catalogue, Params};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn sentences() -> Vec<String> {
    let mut out = Vec::new();
    for i in 0..200 {
        let t = 40_000.0 + f64::from(i) * 0.2;
        let lat = 43.5 + f64::from(i) * 1e-5;
        out.push(build::gga("GP", t, lat, 16.44, true, 9));
        out.push(build::rmc("GP", t, "211126", lat, 16.44, 1.5, 90.0));
        out.push(nmea_sentence(
            b'$',
            &format!("GPVTG,{:.1},T,,M,2.9,N,5.4,K,A", f64::from(i % 360)),
        ));
        out.push(nmea_sentence(
            b'$',
            &format!("HEHDT,{:.1},T", f64::from(i % 360)),
        ));
    }
    out
}

/// Sentences per second of the fastest of `rounds` runs of each of `ways` ways of doing the same
/// work (`run(i)` does it the `i`-th way), taken in turns so that all see the same machine (clock
/// speed, other load).
fn best_rates(n: usize, rounds: usize, ways: usize, mut run: impl FnMut(usize)) -> Vec<f64> {
    let mut best = vec![0.0f64; ways];
    for _ in 0..rounds {
        for (i, b) in best.iter_mut().enumerate() {
            let start = Instant::now();
            run(i);
            *b = b.max(n as f64 / start.elapsed().as_secs_f64());
        }
    }
    best
}

fn throughput(goals: &mut Goals) {
    let list = sentences();
    let stream: Vec<u8> = list
        .iter()
        .flat_map(|s| format!("{s}\r\n").into_bytes())
        .collect();
    let reps = 50;
    let n = list.len() * reps;
    let cat = Catalogue::built_in();
    let none = Params::from_pairs(&[]);
    let (mut gps, _) = Sensor::new(&none, &cat, Role::Gps).expect("a GPS driver");
    let (mut compass, _) = Sensor::new(&none, &cat, Role::Heading).expect("a heading driver");
    let cfg = SerialConfig::from_url(&mut MediumUrl::parse("serial:///dev/null").expect("url"))
        .expect("config");
    let mut topics = FrameTopics::new(&cfg);
    let now = tokio::time::Instant::now();
    let bare = || {
        for _ in 0..reps {
            for s in &list {
                let _ = black_box(nmea::parse_str(black_box(s)));
            }
        }
    };
    // seabus's per-sentence work; the drivers' readings only `with_drivers`
    let mut work = |with_drivers: bool| {
        let mut framer = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 256);
        let mut counted = 0usize;
        for _ in 0..reps {
            framer.push(black_box(&stream), &mut |out| {
                let Ok(frame) = out else { return };
                let topic = topics.topic_of(&frame);
                let payload = Payload::from(frame);
                let line = std::str::from_utf8(payload.as_bytes().expect("bytes")).unwrap_or("");
                if let Ok(p) = parse(line) {
                    counted += if with_drivers {
                        gps.read(&p, now).len() + compass.read(&p, now).len()
                    } else {
                        black_box(&p);
                        1
                    };
                }
                black_box(topic);
            });
        }
        black_box(counted);
    };
    let rounds = scale(9, 5);
    let rates = best_rates(n, rounds, 3, |i| match i {
        0 => bare(),
        1 => work(true),
        _ => work(false),
    });
    let (bare, ours, before_drivers) = (rates[0], rates[1], rates[2]);
    println!(
        "NMEA sentences (GGA, RMC, VTG, HDT), in memory, best of {rounds} x {n}, taken in turns:"
    );
    println!("  bare nmea::parse_str                              {bare:>9.0} sentences/s");
    println!("  seabus: frame, check, topic, parse, to datasets   {ours:>9.0} sentences/s");
    // where seabus's time goes: up to a parsed sentence (set beside the bare parse), then the
    // drivers' readings
    let ns = |rate: f64| 1e9 / rate;
    println!(
        "  of which framing, checksum, topic and parse {:.0} ns a sentence (bare parse_str {:.0} \
         ns), the drivers' readings {:.0} ns",
        ns(before_drivers),
        ns(bare),
        ns(ours) - ns(before_drivers),
    );
    goals.at_least("NMEA in memory, seabus / bare parse_str", ours / bare, 1.0);
}

/// The whole path over a pseudo-terminal, on 64-bit Linux (the process's CPU time and the
/// pseudo-terminals come from the C library).
#[cfg(all(target_os = "linux", target_pointer_width = "64"))]
mod line {
    use super::*;
    use seabus_drivers::nmea::line::Reader;
    use seabus_drivers::nmea::sentence::{lat_field, lon_field, time_field};
    use seabus_medium::Interface;
    use seabus_modules::{Declaration, Runtime, SystemSpec};
    use std::fs::File;
    use std::io::{Read, Write};
    use std::sync::Arc;
    use std::sync::mpsc;

    /// Seconds of traffic in the corpus (19 sentences each).
    const SECONDS: u32 = 500;
    /// Rounds of each measurement, after one to warm up.
    fn rounds() -> usize {
        scale(7, 3)
    }
    /// How long a count may stand still before a round is taken as over (something lost).
    const QUIET: Duration = Duration::from_secs(1);
    /// Sentences the device writes at a time, and how many such chunks it may be ahead of the
    /// datasets counted on the bus: at most 400 sentences wait for a driver (whose queue holds
    /// 1024 and drops the oldest beyond), so that the figure is that of a path that loses nothing.
    const CHUNK: usize = 200;
    const AHEAD: usize = 2;

    /// `seconds` seconds of what a multiplexer puts on one line, 19 sentences a second: a GPS
    /// (RMC, VTG, GGA, GSA, three GSV, GLL, ZDA, TXT), a compass with pitch and roll (XDR before
    /// HDT and HDG), a sounder (DPT, DBT, MTW), a log (VHW), a wind sensor (MWV) and an AIS
    /// receiver (`!AIVDM`), every sentence with its checksum.
    fn traffic(seconds: u32) -> Vec<String> {
        const AIS: [&str; 4] = [
            "AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0",
            "AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0",
            "AIVDM,1,1,,B,16S`2cPP00a3UF6EKT@2:?vOr0S2,0",
            "AIVDM,1,1,,A,15RTgt0PAso;90TKcjM8h6g208CQ,0",
        ];
        let s = |body: String| nmea_sentence(b'$', &body);
        let mut out = Vec::with_capacity(seconds as usize * 19);
        for i in 0..seconds {
            let x = f64::from(i);
            let t = 36_000.0 + x;
            let (lat, lon) = (43.5081 + x * 2e-5, 16.4402 + x * 1e-5);
            let course = (45.0 + x * 0.3) % 360.0;
            let heading = (40.0 + x * 0.3) % 360.0;
            let depth = 12.0 + (x * 0.05).sin() * 3.0;
            let snr = 30 + i % 15;
            out.extend([
                build::rmc("GP", t, "261126", lat, lon, 2.6, course),
                s(format!(
                    "GPVTG,{course:.1},T,{:.1},M,5.1,N,9.4,K,A",
                    (course - 3.5).rem_euclid(360.0)
                )),
                build::gga("GP", t, lat, lon, true, 9),
                s("GPGSA,A,3,04,05,09,12,24,25,29,31,,,,,1.8,1.0,1.5".into()),
                s(format!(
                    "GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,{snr},13,06,292,00"
                )),
                s(format!(
                    "GPGSV,3,2,11,14,25,170,00,16,57,208,39,18,67,296,{snr},19,40,246,00"
                )),
                s(format!(
                    "GPGSV,3,3,11,22,42,067,42,24,14,311,43,27,05,244,{snr}"
                )),
                s(format!(
                    "GPGLL,{},{},{},A,A",
                    lat_field(lat),
                    lon_field(lon),
                    time_field(t)
                )),
                s(format!("GPZDA,{},26,11,2026,00,00", time_field(t))),
                s("GPTXT,01,01,02,ANTENNA OK".into()),
                build::xdr_pitch_roll("HC", 2.0 + (x * 0.1).sin(), -1.5 + (x * 0.07).cos()),
                build::hdt("HE", heading),
                build::hdg("HC", (heading - 4.0).rem_euclid(360.0), 1.5, 2.5),
                s(format!("SDDPT,{depth:.2},0.4,100")),
                build::dbt("SD", depth + 0.4),
                s(format!("YXMTW,{:.1},C", 17.0 + (x * 0.01).sin())),
                s(format!(
                    "VWVHW,{heading:.1},T,{:.1},M,5.0,N,9.3,K",
                    (heading - 3.5).rem_euclid(360.0)
                )),
                s(format!(
                    "WIMWV,{:.1},R,{:.1},N,A",
                    (30.0 + x * 0.7) % 360.0,
                    8.0 + (x * 0.2).sin()
                )),
                nmea_sentence(b'!', AIS[i as usize % AIS.len()]),
            ]);
        }
        out
    }

    /// The GPS, heading and sounder drivers with their default parameters, with what each
    /// declares it publishes.
    fn drivers() -> [(Sensor, Declaration); 3] {
        let cat = Catalogue::built_in();
        let none = Params::from_pairs(&[]);
        [Role::Gps, Role::Heading, Role::Sounder]
            .map(|r| Sensor::new(&none, &cat, r).expect("a driver"))
    }

    /// The datasets the three drivers publish of each of `lines`, read in memory in turn: their
    /// readings that are valid for their dataset (the others their modules do not publish).
    fn datasets_of(lines: &[String]) -> Vec<usize> {
        let cat = Catalogue::built_in();
        let mut drivers = drivers();
        let now = tokio::time::Instant::now();
        lines
            .iter()
            .map(|l| {
                let Ok(p) = parse(l) else { return 0 };
                let mut n = 0;
                for (d, decl) in &mut drivers {
                    for (i, map) in d.read(&p, now) {
                        let dataset = decl.produces.get(i).and_then(|t| t.dataset.as_deref());
                        n += usize::from(dataset.is_some_and(|ds| cat.validate(ds, &map).is_ok()));
                    }
                }
                n
            })
            .collect()
    }

    /// The process's (or a thread's) CPU time, and pseudo-terminals.
    mod sys {
        use std::ffi::{CStr, c_char, c_int};
        use std::fs::{File, OpenOptions};
        use std::io;
        use std::os::fd::AsRawFd;
        use std::os::unix::fs::OpenOptionsExt;
        use std::time::Duration;

        #[repr(C)]
        struct Timeval {
            sec: i64,
            usec: i64,
        }

        #[repr(C)]
        struct Rusage {
            user: Timeval,
            system: Timeval,
            rest: [i64; 14],
        }

        /// Room for the C library's `struct termios` (60 bytes in glibc), only handed back and
        /// forth.
        #[repr(C, align(8))]
        struct Termios([u8; 256]);

        unsafe extern "C" {
            fn getrusage(who: c_int, usage: *mut Rusage) -> c_int;
            fn grantpt(fd: c_int) -> c_int;
            fn unlockpt(fd: c_int) -> c_int;
            fn ptsname_r(fd: c_int, buf: *mut c_char, len: usize) -> c_int;
            fn tcgetattr(fd: c_int, t: *mut Termios) -> c_int;
            fn cfmakeraw(t: *mut Termios);
            fn tcsetattr(fd: c_int, when: c_int, t: *const Termios) -> c_int;
        }

        /// `RUSAGE_SELF`: every thread of the process.
        pub const PROCESS: c_int = 0;
        /// `RUSAGE_THREAD`: the calling thread.
        pub const THREAD: c_int = 1;
        const O_NOCTTY: i32 = 0o400;

        /// User + system CPU time of `who` so far.
        pub fn cpu(who: c_int) -> Duration {
            let mut u = Rusage {
                user: Timeval { sec: 0, usec: 0 },
                system: Timeval { sec: 0, usec: 0 },
                rest: [0; 14],
            };
            // SAFETY: `u` is a `struct rusage` of 64-bit Linux, which the call only writes.
            if unsafe { getrusage(who, &mut u) } != 0 {
                return Duration::ZERO;
            }
            let t = |v: &Timeval| Duration::new(v.sec as u64, v.usec as u32 * 1000);
            t(&u.user) + t(&u.system)
        }

        fn open(path: &str) -> io::Result<File> {
            OpenOptions::new()
                .read(true)
                .write(true)
                .custom_flags(O_NOCTTY)
                .open(path)
        }

        /// A new pseudo-terminal: its master side, and the path of its other end.
        pub fn pty() -> io::Result<(File, String)> {
            let master = open("/dev/ptmx")?;
            let fd = master.as_raw_fd();
            let mut name = [0 as c_char; 128];
            // SAFETY: `fd` is an open master; `name` has the room the call is told of.
            let failed = unsafe {
                grantpt(fd) != 0
                    || unlockpt(fd) != 0
                    || ptsname_r(fd, name.as_mut_ptr(), name.len()) != 0
            };
            if failed {
                return Err(io::Error::last_os_error());
            }
            // SAFETY: on success the name ends with a NUL within `name`.
            let path = unsafe { CStr::from_ptr(name.as_ptr()) };
            Ok((master, path.to_string_lossy().into_owned()))
        }

        /// Opens the terminal at `path` in raw mode (bytes passed on as they come).
        pub fn open_raw(path: &str) -> io::Result<File> {
            let f = open(path)?;
            let mut t = Termios([0; 256]);
            // SAFETY: `f` is an open terminal; `t` has room for its settings.
            let failed = unsafe {
                tcgetattr(f.as_raw_fd(), &mut t) != 0 || {
                    cfmakeraw(&mut t);
                    tcsetattr(f.as_raw_fd(), 0, &t) != 0
                }
            };
            if failed {
                return Err(io::Error::last_os_error());
            }
            Ok(f)
        }
    }

    /// The bytes a device writes, cut into the chunks it writes at a time (their ends).
    struct Traffic {
        bytes: Arc<Vec<u8>>,
        ends: Arc<Vec<usize>>,
    }

    impl Traffic {
        /// `lines` with their line endings, in chunks of `chunk` sentences.
        fn new(lines: &[String], chunk: usize) -> Traffic {
            let (mut bytes, mut ends) = (Vec::new(), Vec::new());
            for (i, s) in lines.iter().enumerate() {
                bytes.extend_from_slice(s.as_bytes());
                bytes.extend_from_slice(b"\r\n");
                if (i + 1) % chunk == 0 || i + 1 == lines.len() {
                    ends.push(bytes.len());
                }
            }
            Traffic {
                bytes: Arc::new(bytes),
                ends: Arc::new(ends),
            }
        }

        /// The same bytes in one piece.
        fn whole(&self) -> Traffic {
            Traffic {
                bytes: self.bytes.clone(),
                ends: Arc::new(vec![self.bytes.len()]),
            }
        }
    }

    /// When a device thread started writing, the process's CPU time then, and the thread's own
    /// CPU time while it wrote.
    struct Written {
        start: Instant,
        process_cpu: Duration,
        own_cpu: Duration,
    }

    /// A thread that plays the device: writes `traffic` into the master side of a pty as fast as
    /// the terminal takes it, a chunk at a time; with `counted` (how many chunks have been counted
    /// at the far end), never more than [`AHEAD`] chunks ahead of it.
    fn device(
        master: &File,
        traffic: &Traffic,
        counted: Option<mpsc::Receiver<usize>>,
    ) -> std::thread::JoinHandle<Written> {
        let mut out = master.try_clone().expect("the pty's master");
        let (bytes, ends) = (traffic.bytes.clone(), traffic.ends.clone());
        std::thread::spawn(move || {
            let own = sys::cpu(sys::THREAD);
            let process_cpu = sys::cpu(sys::PROCESS);
            let start = Instant::now();
            let (mut from, mut done, mut counted) = (0, 0, counted);
            for (k, &end) in ends.iter().enumerate() {
                while let Some(rx) = &counted
                    && k >= AHEAD + done
                {
                    match rx.recv_timeout(QUIET) {
                        Ok(n) => done = n,
                        // something was lost: the rest goes out unwatched
                        Err(_) => counted = None,
                    }
                }
                out.write_all(&bytes[from..end])
                    .expect("writing into the pty");
                from = end;
            }
            Written {
                start,
                process_cpu,
                own_cpu: sys::cpu(sys::THREAD) - own,
            }
        })
    }

    /// One timed run of a stage: from the first byte written to the last item counted, the CPU
    /// time spent meanwhile (less the device's), and how many items were counted.
    #[derive(Clone, Copy)]
    struct Round {
        took: Duration,
        cpu: Duration,
        got: usize,
    }

    /// The best of a stage's rounds: the shortest time and the least CPU of those that counted
    /// everything (a round that lost some ends early), and the fewest items counted.
    #[derive(Default)]
    struct Best {
        took: Option<Duration>,
        cpu: Option<Duration>,
        fewest: Option<usize>,
    }

    impl Best {
        /// Adds a round that should have counted `all` items.
        fn add(&mut self, r: Round, all: usize) {
            self.fewest = Some(self.fewest.map_or(r.got, |g| g.min(r.got)));
            if r.got < all {
                return;
            }
            self.took = Some(self.took.map_or(r.took, |t| t.min(r.took)));
            self.cpu = Some(self.cpu.map_or(r.cpu, |t| t.min(r.cpu)));
        }

        fn rate(&self, n: usize) -> f64 {
            n as f64 / self.took.unwrap_or(Duration::MAX).as_secs_f64()
        }

        fn ns(&self, n: usize) -> f64 {
            self.cpu.unwrap_or_default().as_secs_f64() * 1e9 / n as f64
        }
    }

    /// Writes `traffic` into `master` and counts what arrives on `watch` until `marks.last()`
    /// items have (or the count has stood still for twice [`QUIET`], longer than the device
    /// waits). `marks` is the count expected after each chunk; with `window`, the device waits for
    /// it.
    async fn counted_round(
        master: &File,
        traffic: &Traffic,
        mut watch: Interface,
        marks: &Arc<Vec<usize>>,
        window: bool,
    ) -> (Interface, Round) {
        while watch.try_recv().is_ok() {}
        let (tell, counted) = mpsc::channel();
        let marks = marks.clone();
        let counter = tokio::spawn(async move {
            let expected = marks.last().copied().unwrap_or(0);
            let (mut got, mut last, mut chunks) = (0, Instant::now(), 0);
            let passed = |got: usize, chunks: &mut usize| {
                let before = *chunks;
                while marks.get(*chunks).is_some_and(|m| *m <= got) {
                    *chunks += 1;
                }
                if *chunks > before {
                    let _ = tell.send(*chunks);
                }
            };
            passed(0, &mut chunks);
            while got < expected
                && let Ok(Some(m)) = tokio::time::timeout(2 * QUIET, watch.recv()).await
            {
                black_box(m);
                got += 1;
                last = Instant::now();
                passed(got, &mut chunks);
            }
            (watch, got, last, sys::cpu(sys::PROCESS))
        });
        let device = device(master, traffic, window.then_some(counted));
        let (watch, got, last, cpu) = counter.await.expect("the counter");
        let w = device.join().expect("the device");
        let round = Round {
            took: last.saturating_duration_since(w.start),
            cpu: cpu.saturating_sub(w.process_cpu).saturating_sub(w.own_cpu),
            got,
        };
        // the next round starts on a quiet line
        tokio::time::sleep(Duration::from_millis(50)).await;
        (watch, round)
    }

    /// Writes `traffic` into `master` while a plain thread reads it raw from the other end.
    fn raw_round(master: &File, slave: &File, traffic: &Traffic) -> Round {
        let mut input = slave.try_clone().expect("the pty's other end");
        let n = traffic.bytes.len();
        let reader = std::thread::spawn(move || {
            let own = sys::cpu(sys::THREAD);
            let (mut buf, mut got) = (vec![0u8; 4096], 0);
            while got < n {
                match input.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(k) => got += k,
                }
            }
            (Instant::now(), sys::cpu(sys::THREAD) - own, got)
        });
        let w = device(master, traffic, None).join().expect("the device");
        let (end, cpu, got) = reader.join().expect("the reader");
        Round {
            took: end.saturating_duration_since(w.start),
            cpu,
            got,
        }
    }

    /// seabus's per-sentence work on one thread, without the pty and without tasks: framing,
    /// the checksum, the topic, the message on a medium, the shared parse as each of the three
    /// drivers asks `reader` for it (the one the running drivers have told what they read), and
    /// the drivers' readings (not published).
    fn in_memory(
        bytes: &[u8],
        reader: &Reader,
        drivers: &mut [(Sensor, Declaration); 3],
        node: &Node,
    ) -> usize {
        let cfg = SerialConfig::from_url(&mut MediumUrl::parse("serial:///dev/null").expect("url"))
            .expect("config");
        let mut topics = FrameTopics::new(&cfg);
        let mut framer = Framer::new(Framing::Nmea, ChecksumPolicy::Require, 256);
        let medium = Medium::in_process("memory", node);
        let mut rx = medium
            .attach_with("drivers", 1 << 16, 64)
            .subscribed("nmea.**")
            .expect("pattern");
        let ingress = medium.ingress();
        let now = tokio::time::Instant::now();
        let mut datasets = 0;
        framer.push(black_box(bytes), &mut |out| {
            let Ok(frame) = out else { return };
            let Some(topic) = topics.topic_of(&frame) else {
                return;
            };
            ingress.originate(topic, Payload::from(frame));
            let Ok(msg) = rx.try_recv() else { return };
            let Some(Ok(line)) = msg.payload.as_bytes().map(|b| std::str::from_utf8(b)) else {
                return;
            };
            for (d, _) in drivers.iter_mut() {
                if let Some(read) = reader.read(&msg, line, &ingress)
                    && let Ok(p) = &*read
                {
                    datasets += d.read(p, now).len();
                }
            }
        });
        datasets
    }

    pub fn whole_path(goals: &mut Goals) {
        let lines = traffic(SECONDS);
        let n = lines.len();
        let traffic = Traffic::new(&lines, CHUNK);
        let per_line = datasets_of(&lines);
        // datasets counted once each chunk of the whole path has been read
        let marks: Arc<Vec<usize>> = Arc::new(
            per_line
                .chunks(CHUNK)
                .scan(0, |sum, c| {
                    *sum += c.iter().sum::<usize>();
                    Some(*sum)
                })
                .collect(),
        );
        let expected = marks.last().copied().unwrap_or(0);
        // the frames the medium without drivers hands its subscriber
        let frame_marks: Arc<Vec<usize>> = Arc::new(vec![n]);
        let parsed_ok = lines.iter().filter(|s| nmea::parse_str(s).is_ok()).count();
        let rt = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()
            .expect("runtime");
        let [mut ours, mut bare, mut memory, mut raw, mut medium_only] =
            std::array::from_fn(|_| Best::default());
        let mut burst = None;
        rt.block_on(async {
            let (whole_master, whole_slave) = sys::pty().expect("a pty");
            let (raw_master, raw_slave) = sys::pty().expect("a pty");
            let raw_slave = sys::open_raw(&raw_slave).expect("the pty's other end");
            let (line_master, line_slave) = sys::pty().expect("a pty");
            let text = format!(
                r#"<seabus node="bench">
  <medium name="bus" url="inproc://"/>
  <medium name="line" url="serial://{whole_slave}?baud=115200&amp;reopen=20ms"/>
  <module name="gps" type="nmea-gps" media="line bus"/>
  <module name="compass" type="nmea-heading" media="line bus"/>
  <module name="sounder" type="nmea-sounder" media="line bus"/>
</seabus>"#
            );
            let spec = SystemSpec::parse("bench.xml", &text).expect("the system");
            let mut reg = seabus_modules::Registry::new();
            reg.set_schemes(seabus_medium_serial::schemes());
            seabus_drivers::register(&mut reg);
            let system = Runtime::start(&spec, &reg, Catalogue::built_in())
                .await
                .expect("the system starts");
            // the subscriber takes what the drivers publish, nothing else
            let mut datasets = system
                .medium("bus")
                .expect("bus")
                .attach_with("count", 1 << 16, 64);
            for (_, decl) in &drivers() {
                for t in &decl.produces {
                    datasets.subscribe(&t.topic).expect("topic");
                }
            }
            let line_medium = system.medium("line").expect("line");
            link_up(line_medium).await;
            // the drivers have their ports once they run
            let deadline = Instant::now() + Duration::from_secs(5);
            while Instant::now() < deadline
                && !system
                    .status()
                    .iter()
                    .all(|u| u.state == seabus_modules::runtime::State::Running)
            {
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            let reader = line_medium.shared::<Reader>();
            let node = Node::new("bench");
            let line = seabus_medium_serial::schemes()
                .open(
                    "line",
                    &format!("serial://{line_slave}?baud=115200&reopen=20ms"),
                    &node,
                )
                .expect("serial");
            link_up(&line).await;
            let mut frames = line
                .attach_with("count", 1 << 16, 64)
                .subscribed("nmea.**")
                .expect("pattern");
            let mut drivers = drivers();
            // round 0 warms up, untimed
            for round in 0..=rounds() {
                let timed = |best: &mut Best, r: Round, all: usize| {
                    if round > 0 {
                        best.add(r, all);
                    }
                };
                let r;
                (datasets, r) =
                    counted_round(&whole_master, &traffic, datasets, &marks, true).await;
                timed(&mut ours, r, expected);
                let start = Instant::now();
                for s in &lines {
                    let _ = black_box(nmea::parse_str(black_box(s)));
                }
                let took = start.elapsed();
                timed(
                    &mut bare,
                    Round {
                        took,
                        cpu: took,
                        got: n,
                    },
                    n,
                );
                let start = Instant::now();
                let got = in_memory(&traffic.bytes, &reader, &mut drivers, &node);
                let took = start.elapsed();
                timed(
                    &mut memory,
                    Round {
                        took,
                        cpu: took,
                        got,
                    },
                    got,
                );
                let r = raw_round(&raw_master, &raw_slave, &traffic.whole());
                timed(&mut raw, r, traffic.bytes.len());
                let r;
                (frames, r) =
                    counted_round(&line_master, &traffic.whole(), frames, &frame_marks, false)
                        .await;
                timed(&mut medium_only, r, n);
            }
            // and the whole path given all of it at once
            let r;
            (datasets, r) = counted_round(
                &whole_master,
                &traffic.whole(),
                datasets,
                &Arc::new(vec![expected]),
                false,
            )
            .await;
            burst = Some(r);
            drop((datasets, frames));
            line.close();
            system.shutdown().await;
        });
        let bytes = traffic.bytes.len();
        println!(
            "NMEA whole path over a pty: {n} sentences of mixed traffic ({SECONDS} s of 19 a second, \
             {} kB), {expected} datasets; best of {} rounds, taken in turns:",
            bytes / 1000,
            rounds()
        );
        let row = |what: &str, b: &Best, cpu: &str, more: String| {
            println!(
                "  {what:<46} {:>9.0} sentences/s {:>6.0} ns/sentence{cpu}{more}",
                b.rate(n),
                b.ns(n)
            );
        };
        row(
            "bare nmea::parse_str, one thread",
            &bare,
            "",
            format!(" ({parsed_ok} of {n} read)"),
        );
        row(
            "seabus's work in memory, one thread, no tasks",
            &memory,
            "",
            format!(" ({} datasets)", memory.fewest.unwrap_or(0)),
        );
        row(
            "pty alone, a plain reader of raw bytes",
            &raw,
            " reader CPU",
            format!(" ({:.0} MB/s)", raw.rate(n) * bytes as f64 / n as f64 / 1e6),
        );
        row(
            "pty -> serial medium -> one subscriber",
            &medium_only,
            " CPU",
            format!(
                " (fewest frames counted {} of {n})",
                medium_only.fewest.unwrap_or(0)
            ),
        );
        row(
            "whole path: pty -> medium -> 3 drivers -> bus",
            &ours,
            " CPU",
            format!(
                " (fewest datasets counted {} of {expected})",
                ours.fewest.unwrap_or(0)
            ),
        );
        println!(
            "  wall-clock ratio, whole path / bare parse_str: {:.2}",
            ours.rate(n) / bare.rate(n)
        );
        if let Some(b) = burst {
            println!(
                "  the whole path written at once (the device never waiting): {} of {expected} \
                 datasets in {:.1} ms",
                b.got,
                b.took.as_secs_f64() * 1e3
            );
        }
        goals.aim_at_least(
            "NMEA whole path CPU, parse_str ns / whole path ns per sentence",
            bare.ns(n) / ours.ns(n),
            1.0,
            "each sentence also crosses a pseudo-terminal, the serial medium and the drivers' tasks, \
             which the bare parse does not",
        );
    }
}

fn whole_path(goals: &mut Goals) {
    #[cfg(all(target_os = "linux", target_pointer_width = "64"))]
    line::whole_path(goals);
    #[cfg(not(all(target_os = "linux", target_pointer_width = "64")))]
    {
        let _ = goals;
        println!("NMEA whole path over a pty: measured on 64-bit Linux only");
    }
}

/// Waits until `medium`'s link is up.
async fn link_up(medium: &Medium) {
    let mut link = medium.watch_link();
    tokio::time::timeout(
        Duration::from_secs(5),
        link.wait_for(|s| *s == LinkState::Up),
    )
    .await
    .expect("the serial line opens")
    .expect("the link state");
}

fn latency() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let dir = std::env::temp_dir().join(format!("seabus-bench-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join("line").display().to_string();
        let node = Node::new("bench");
        let far = seabus_medium_serial::schemes()
            .open("far", &format!("pty://{path}"), &node)
            .expect("pty");
        let line = seabus_medium_serial::schemes()
            .open(
                "line",
                &format!("serial://{path}?baud=115200&reopen=20ms"),
                &node,
            )
            .expect("serial");
        link_up(&line).await;
        let mut rx = line
            .attach_with("rx", 1 << 14, 16)
            .subscribed("nmea.**")
            .expect("pattern");
        let tx = far.attach("tx");
        let n = scale(2000, 400);
        // the receiver notes when each sentence arrives, on its own task
        let receiver = tokio::spawn(async move {
            let mut arrived = Vec::with_capacity(n);
            while let Ok(Some(m)) =
                tokio::time::timeout(Duration::from_millis(500), rx.recv()).await
            {
                let at = Instant::now();
                if let Some(i) = index(&m) {
                    arrived.push((i, at));
                }
                if arrived.len() == n {
                    break;
                }
            }
            arrived
        });
        let mut sent_at = vec![None; n];
        let start = Instant::now();
        for (i, slot) in sent_at.iter_mut().enumerate() {
            let due = start + Duration::from_micros(5_000 * i as u64);
            tokio::time::sleep_until(due.into()).await;
            let s = nmea_sentence(b'$', &format!("GPHDT,{i},T"));
            *slot = Some(Instant::now());
            let _ = tx.send("out", Payload::from(s.into_bytes())).await;
        }
        let arrived = receiver.await.expect("receiver");
        let mut lat: Vec<Duration> = arrived
            .iter()
            .filter_map(|(i, at)| {
                sent_at
                    .get(*i)
                    .copied()
                    .flatten()
                    .map(|s| at.duration_since(s))
            })
            .collect();
        lat.sort();
        let q = |p: f64| lat[((lat.len() - 1) as f64 * p) as usize].as_secs_f64() * 1e6;
        println!(
            "serial -> bus over a pty, {} of {n} sentences at 200/s:",
            lat.len()
        );
        println!("  latency p50 {:.0} us, p99 {:.0} us", q(0.5), q(0.99));
        far.close();
        let _ = std::fs::remove_dir_all(&dir);
    });
}

/// The sentence number carried in a `$GPHDT,<i>,T` sentence.
fn index(m: &seabus_medium::Message) -> Option<usize> {
    let b = m.payload.as_bytes()?;
    String::from_utf8_lossy(b).split(',').nth(1)?.parse().ok()
}

fn main() {
    // the parts named on the command line (cargo's own `--bench` aside), or all of them
    let named: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let run = |part: &str| named.is_empty() || named.iter().any(|a| a == part);
    let mut goals = Goals::new();
    if run("memory") {
        throughput(&mut goals);
    }
    if run("line") {
        whole_path(&mut goals);
    }
    if run("latency") {
        latency();
    }
    goals.finish();
}
