//! The DSAAV logging service with the paper's configuration: components log through RPC at the
//! level their configuration gives them (MyDepthController at DEBUG, the others at INFO), into one
//! chronological central log that rotates by size.

use seabus_dsaav::config::Database;
use seabus_dsaav::logging::{self, Level, LogFile, Logger};
use seabus_dsaav::rpc::CallOptions;
use seabus_medium::{Medium, Node};
use std::time::{Duration, Instant};

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn components_log_centrally_at_their_configured_levels() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = Database::parse(
        "starfish.ini",
        "[Logging]\nServer = 1:0\nLogLevel = LOG_INFO\n\
         [DepthFilter]\nServer = 3:0\n\
         [MyDepthController]\nLogging.LogLevel = LOG_DEBUG\n",
    )
    .unwrap();
    let bus = format!("dsaav+inproc://log{}", fastrand::u32(..));
    let server_medium = open(&format!("{bus}?node=1"));
    let path = dir.path().join("vehicle.log");
    let log = LogFile::open(path.clone(), 1 << 20, 3).unwrap();
    let sm = server_medium.clone();
    let (_drain, draining) = tokio::sync::watch::channel(false);
    tokio::spawn(async move { logging::serve(&sm, 0, log, draining).await });

    let opts = CallOptions::default();
    let controller_medium = open(&format!("{bus}?node=5"));
    let controller = Logger::new(&controller_medium, 4, "MyDepthController", &cfg, opts).unwrap();
    let filter_medium = open(&format!("{bus}?node=3"));
    let mut filter = Logger::new(&filter_medium, 4, "DepthFilter", &cfg, opts).unwrap();
    assert_eq!(
        (controller.level(), filter.level()),
        (Level::Debug, Level::Info)
    );

    assert!(
        controller
            .log(Level::Info, "controller started")
            .await
            .unwrap()
    );
    assert!(
        filter
            .log(Level::Warning, "depth jumped 3 m")
            .await
            .unwrap()
    );
    assert!(
        !filter
            .log(Level::Debug, "not logged at INFO")
            .await
            .unwrap()
    );
    assert!(controller.log(Level::Debug, "gain 2.3").await.unwrap());
    filter.set_level(Level::Debug);
    assert!(filter.log(Level::Debug, "now logged").await.unwrap());
    assert!(controller.log(Level::Data, "depth=12.5").await.unwrap());

    // DATA goes unreliably: wait for it to be written
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut text = String::new();
    while Instant::now() < deadline {
        text = std::fs::read_to_string(&path).unwrap_or_default();
        if text.lines().count() >= 5 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 5, "{text}");
    let expect = [
        ("INFO", "MyDepthController", "controller started"),
        ("WARNING", "DepthFilter", "depth jumped 3 m"),
        ("DEBUG", "MyDepthController", "gain 2.3"),
        ("DEBUG", "DepthFilter", "now logged"),
        ("DATA", "MyDepthController", "depth=12.5"),
    ];
    for (line, (level, component, msg)) in lines.iter().zip(expect) {
        let fields: Vec<&str> = line.split_whitespace().collect();
        assert!(
            fields[0].ends_with('Z') && fields[0].contains('T'),
            "{line}"
        );
        assert_eq!((fields[1], fields[2]), (level, component), "{line}");
        assert!(line.ends_with(msg), "{line}");
    }
    // chronological
    let times: Vec<&str> = lines.iter().map(|l| l.split(' ').next().unwrap()).collect();
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "{times:?}");
}

#[test]
fn the_central_log_rotates_by_size_keeping_the_newest_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v.log");
    let mut log = LogFile::open(path.clone(), 100, 2).unwrap();
    for i in 0..12 {
        log.write(&format!("record {i:02} {}", "x".repeat(20)))
            .unwrap();
    }
    let read = |p: &std::path::Path| std::fs::read_to_string(p).unwrap_or_default();
    let numbered = |n: u32| dir.path().join(format!("v.log.{n}"));
    // 31 bytes a line: three to a file; the newest in v.log, then v.log.1, v.log.2; older gone
    assert!(read(&path).starts_with("record 09"), "{}", read(&path));
    assert!(read(&numbered(1)).starts_with("record 06"));
    assert!(read(&numbered(2)).starts_with("record 03"));
    assert!(!numbered(3).exists());
    assert!(std::fs::metadata(&path).unwrap().len() <= 100);
    assert_eq!(Level::parse("LOG_DEBUG"), Some(Level::Debug));
    assert_eq!(Level::parse("warning"), Some(Level::Warning));
    assert_eq!(Level::parse("LOUD"), None);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn records_arriving_out_of_order_are_written_in_time_order() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = Database::parse("v.ini", "[Logging]\nServer = 1:0\n").unwrap();
    let bus = format!("dsaav+inproc://order{}", fastrand::u32(..));
    let server_medium = open(&format!("{bus}?node=1"));
    let path = dir.path().join("v.log");
    let log = LogFile::open(path.clone(), 1 << 20, 1).unwrap();
    let (drain, draining) = tokio::sync::watch::channel(false);
    let sm = server_medium.clone();
    let server = tokio::spawn(async move { logging::serve(&sm, 0, log, draining).await });

    let opts = CallOptions::default();
    let a_medium = open(&format!("{bus}?node=2"));
    let a = Logger::new(&a_medium, 4, "A", &cfg, opts).unwrap();
    let now = seabus_medium::Stamp::now().as_secs_f64();
    // the record made first is sent second
    a.log_at(now + 0.010, Level::Info, "second").await.unwrap();
    a.log_at(now, Level::Info, "first").await.unwrap();
    // a record from a clock ahead of the server's is not held for ever
    a.log_at(now + 3600.0, Level::Info, "ahead").await.unwrap();
    let lines = |p: &std::path::Path| -> Vec<String> {
        std::fs::read_to_string(p)
            .unwrap_or_default()
            .lines()
            .map(|l| l.rsplit(' ').next().unwrap_or("").to_string())
            .collect()
    };
    let deadline = Instant::now() + Duration::from_secs(5);
    while lines(&path).len() < 3 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(lines(&path), ["first", "second", "ahead"]);

    // draining: written at once; the medium closing writes what is held
    drain.send(true).unwrap();
    tokio::time::sleep(Duration::from_millis(50)).await;
    a.log_at(
        seabus_medium::Stamp::now().as_secs_f64(),
        Level::Warning,
        "late",
    )
    .await
    .unwrap();
    assert_eq!(lines(&path).last().map(String::as_str), Some("late"));
    server_medium.close();
    tokio::time::timeout(Duration::from_secs(5), server)
        .await
        .expect("the server stops when its medium closes")
        .unwrap();
}
