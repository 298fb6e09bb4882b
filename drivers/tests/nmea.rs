//! NMEA sensor drivers over a real pseudo-terminal: a GPS, a compass and an echo sounder on one
//! line, their sentences turned into standard datasets; garbage on the line changes nothing.

use seabus_drivers::nmea::sentence::build;
use seabus_medium::framing::nmea_sentence;
use seabus_medium::{Message, Payload};
use seabus_modules::{Catalogue, Runtime, SystemSpec};
use std::collections::BTreeMap;
use std::time::Duration;
use tokio::time::{Instant, timeout};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sensor_sentences_become_standard_datasets() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sensors").display().to_string();
    let text = format!(
        r#"<seabus node="usv">
  <medium name="bus" url="inproc://"/>
  <medium name="far" url="pty://{path}?framing=lines"/>
  <medium name="line" url="serial://{path}?baud=4800&amp;reopen=50ms"/>
  <module name="gps" type="nmea-gps" media="line bus" talkers="GP"/>
  <module name="compass" type="nmea-heading" media="line bus"/>
  <module name="sounder" type="nmea-sounder" media="line bus" offset="0.4"/>
</seabus>"#
    );
    let spec = SystemSpec::parse("usv.xml", &text).unwrap();
    let mut reg = seabus_modules::Registry::new();
    reg.set_schemes(seabus_medium_serial::schemes());
    seabus_drivers::register(&mut reg);
    let rt = Runtime::start(&spec, &reg, Catalogue::built_in())
        .await
        .unwrap();
    let mut watch = rt
        .medium("bus")
        .unwrap()
        .attach("watch")
        .subscribed("nav.**")
        .unwrap();
    let device = rt.medium("far").unwrap().attach("device");
    let mut line = rt.medium("line").unwrap().watch_link();
    timeout(
        Duration::from_secs(5),
        line.wait_for(|s| *s == seabus_medium::LinkState::Up),
    )
    .await
    .expect("the line opens")
    .unwrap();
    let sentences = [
        "\u{1}\u{2}static on the line".to_string(),
        build::gga("GP", 45_000.0, 43.5081, 16.4402, true, 10),
        build::gga("GN", 45_000.0, 1.0, 1.0, true, 10),
        build::rmc("GP", 45_000.0, "211126", 43.5081, 16.4402, 2.0, 45.0),
        build::hdg("HC", 90.0, 1.0, 2.0),
        build::xdr_pitch_roll("HC", 3.0, -2.0),
        nmea_sentence(b'$', "HEHDT,93.5,T"),
        "$SDDBT,32.8,f,10.0,M,5.5,F*00".to_string(),
        build::dbt("SD", 12.0),
    ];
    let mut got: BTreeMap<String, Vec<Message>> = BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    // resend until every output has been seen (the far end may take a moment to be read)
    let wanted = [
        "nav.altitude",
        "nav.attitude",
        "nav.fix",
        "nav.heading",
        "nav.position",
        "nav.velocity",
    ];
    let heading_of = |m: &Message| format!("{:?}", m.payload.to_map().unwrap().get_f64("heading"));
    let done = |got: &BTreeMap<String, Vec<Message>>| {
        wanted.iter().all(|t| got.contains_key(*t))
            && got["nav.heading"]
                .iter()
                .any(|m| heading_of(m) == "Some(93.0)")
            && got["nav.heading"]
                .iter()
                .any(|m| heading_of(m) == "Some(93.5)")
    };
    while Instant::now() < deadline && !done(&got) {
        for s in &sentences {
            device
                .send("raw", Payload::from(s.as_bytes()))
                .await
                .unwrap();
        }
        while let Ok(Some(m)) = timeout(Duration::from_millis(300), watch.recv()).await {
            got.entry(m.topic.to_string()).or_default().push(m);
        }
    }
    let first = |t: &str| -> seabus_medium::DataMap {
        let m = got
            .get(t)
            .and_then(|v| v.first())
            .unwrap_or_else(|| panic!("nothing on {t}: {:?}", got.keys()));
        (*m.payload.to_map().unwrap()).clone()
    };
    let pos = first("nav.position");
    assert!((pos.get_f64("lat").unwrap() - 43.5081).abs() < 1e-5);
    assert!(
        got["nav.position"]
            .iter()
            .all(|m| m.payload.to_map().unwrap().get_f64("lat").unwrap() > 40.0),
        "GN is not listened to"
    );
    let vel = first("nav.velocity");
    assert!((vel.get_f64("speed").unwrap() - 2.0).abs() < 0.01);
    assert_eq!(vel.get_f64("course"), Some(45.0));
    // HDG (90 + 1 deviation + 2 variation) and HDT (93.5) each give a heading; the line may
    // drop the start of the first round, so which comes first is not fixed
    let headings: std::collections::BTreeSet<String> =
        got["nav.heading"].iter().map(heading_of).collect();
    assert_eq!(
        headings.into_iter().collect::<Vec<_>>(),
        ["Some(93.0)", "Some(93.5)"],
        "HDG corrected by deviation and variation, HDT as sent"
    );
    let att = first("nav.attitude");
    assert_eq!(
        (att.get_f64("pitch"), att.get_f64("roll")),
        (Some(3.0), Some(-2.0))
    );
    let alt = first("nav.altitude");
    assert_eq!(
        alt.get_f64("altitude"),
        Some(12.4),
        "the bad-checksum DBT is dropped, the good one read"
    );
    let line = rt.medium("line").unwrap().stats().rejected;
    assert!(line.get("garbage").copied().unwrap_or(0) >= 1, "{line:?}");
    assert!(
        line.get("bad-checksum").copied().unwrap_or(0) >= 1,
        "{line:?}"
    );
    rt.shutdown().await;
}
