//! The `nmea2000` driver sending PGNs, read by canboat's own JavaScript implementation:
//! `seabus run` claims address 40 on an slcan pseudo-terminal, every built-in PGN (fast-packet
//! ones included) is published on the bus as `n2k.out.ID` in seabus's units, and
//! `tests/peers/n2k_canboat_read.js` — canboatjs's parser on the frames the adapter passes —
//! decodes the same values, from address 40; asked for its claim (ISO Request), the driver
//! answers with the NAME the system file gives. A value a field
//! cannot hold is refused and counted, never sent.
//!
//! Needs Node with `@canboat/canboatjs` and `@canboat/pgns`, which `scripts/test` installs and
//! names in `SEABUS_CANBOATJS` (their `node_modules`).

mod common;
use common::*;
use seabus_medium::{DataMap, Node, Value as V};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;
use tokio::time::Instant;

/// Where canboatjs is: `SEABUS_CANBOATJS` (which must then hold it), else where `scripts/test`
/// installs it; `None` when neither holds it.
fn canboatjs() -> Option<PathBuf> {
    let modules = match std::env::var_os("SEABUS_CANBOATJS") {
        Some(m) => PathBuf::from(m),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/node-canboat/node_modules"),
    };
    let found = modules.join("@canboat/canboatjs/package.json").is_file();
    if std::env::var_os("SEABUS_CANBOATJS").is_some() {
        assert!(
            found,
            "SEABUS_CANBOATJS={} holds no canboatjs",
            modules.display()
        );
    }
    found.then_some(modules)
}

/// Every built-in PGN but the address claim (which the driver sends itself), with its fields in
/// canboat's units (radians, kelvin), as canboatjs gives them back.
fn messages() -> Vec<(u32, Value)> {
    vec![
        (
            127250,
            json!({"sid": 7, "heading": 1.2345, "deviation": -0.0123, "variation": 0.0456,
                   "reference": "Magnetic"}),
        ),
        (127251, json!({"sid": 1, "rate": 0.0123})),
        (
            127257,
            json!({"sid": 2, "yaw": 0.5, "pitch": 0.05, "roll": -0.1}),
        ),
        (
            127488,
            json!({"instance": "Dual Engine Starboard", "speed": 1500, "boostPressure": 120000,
                   "tiltTrim": -5}),
        ),
        (
            127489,
            json!({"instance": "Single Engine or Dual Engine Port", "oilPressure": 350000,
                   "oilTemperature": 363.2, "temperature": 353.15, "alternatorPotential": 14.2,
                   "fuelRate": 12.5, "totalEngineHours": 3600000, "coolantPressure": 150000,
                   "fuelPressure": 300000, "discreteStatus1": ["Check Engine", "Over Temperature"],
                   "discreteStatus2": ["Maintenance Needed"], "engineLoad": 50,
                   "engineTorque": 40}),
        ),
        (
            127506,
            json!({"sid": 3, "instance": 0, "dcType": "Battery", "stateOfCharge": 87,
                   "stateOfHealth": 95, "timeRemaining": 7200, "rippleVoltage": 0.025,
                   "remainingCapacity": 360000}),
        ),
        (
            127508,
            json!({"instance": 0, "voltage": 12.8, "current": -3.5, "temperature": 298.15,
                   "sid": 4}),
        ),
        (
            128267,
            json!({"sid": 5, "depth": 12.34, "offset": 0.5, "range": 100}),
        ),
        (129025, json!({"latitude": 43.5123456, "longitude": 16.44})),
        (
            129026,
            json!({"sid": 6, "cogReference": "True", "cog": 1.0, "sog": 5.14}),
        ),
        (
            129029,
            json!({"sid": 9, "date": 19000, "time": 36000.5, "latitude": 43.5,
                   "longitude": -16.25, "altitude": 12.5, "gnssType": "GPS+GLONASS",
                   "method": "RTK Fixed Integer", "integrity": "Safe", "numberOfSvs": 12,
                   "hdop": 0.8, "pdop": 1.5, "geoidalSeparation": 40.0, "referenceStations": 1,
                   "list": [{"referenceStationType": "GPS", "referenceStationId": 100,
                             "ageOfDgnssCorrections": 2.5}]}),
        ),
        (
            130306,
            json!({"sid": 8, "windSpeed": 7.5, "windAngle": 0.7, "reference": "Apparent"}),
        ),
        (
            130312,
            json!({"sid": 1, "instance": 2, "source": "Sea Temperature",
                   "actualTemperature": 288.15, "setTemperature": 290.0}),
        ),
        (
            130316,
            json!({"sid": 1, "instance": 0, "source": "Outside Temperature",
                   "temperature": 283.15, "setTemperature": 293.1}),
        ),
        (
            126992,
            json!({"sid": 0, "source": "GPS", "date": 19000, "time": 43200.5}),
        ),
    ]
}

/// Field `id` of built-in PGN `pgn`.
fn field(pgn: u32, id: &str) -> seabus_drivers::n2k::pgn::Field {
    let db = seabus_drivers::n2k::builtin::database();
    db.definitions(pgn)[0]
        .fields
        .iter()
        .find(|f| f.id == id)
        .unwrap_or_else(|| panic!("PGN {pgn} has no field {id}"))
        .clone()
}

/// `fields` (canboat's units) as the datamap seabus is given (seabus's units).
fn to_seabus(pgn: u32, fields: &Value) -> DataMap {
    let mut m = DataMap::new();
    for (id, v) in fields.as_object().unwrap() {
        let value = match v {
            Value::Number(n) => {
                let f = field(pgn, id);
                let x = f.to_seabus(n.as_f64().unwrap());
                if n.is_i64() && f.seabus_unit() == f.unit {
                    V::Int(n.as_i64().unwrap())
                } else {
                    V::Float(x)
                }
            }
            Value::String(s) => V::from(s.clone()),
            Value::Array(items) if id == "list" => {
                V::List(items.iter().map(|i| V::Map(to_seabus(pgn, i))).collect())
            }
            Value::Array(items) => V::List(
                items
                    .iter()
                    .map(|i| V::from(i.as_str().unwrap().to_string()))
                    .collect(),
            ),
            other => panic!("{other}"),
        };
        m.insert(id.clone(), value);
    }
    m
}

/// The number canboatjs writes as text: a time or duration `H:MM:SS.s` in seconds, a date
/// `YYYY.MM.DD` in days since 1970-01-01.
fn canboat_text(kind: &seabus_drivers::n2k::pgn::Kind, text: &str) -> Option<f64> {
    use seabus_drivers::n2k::pgn::Kind;
    match kind {
        Kind::Time | Kind::Duration => {
            let parts: Vec<f64> = text
                .split(':')
                .map(|p| p.parse().ok())
                .collect::<Option<_>>()?;
            (parts.len() == 3).then(|| parts[0] * 3600.0 + parts[1] * 60.0 + parts[2])
        }
        Kind::Date => {
            let p: Vec<i64> = text
                .split('.')
                .map(|p| p.parse().ok())
                .collect::<Option<_>>()?;
            let (y, m, d) = (*p.first()?, *p.get(1)?, *p.get(2)?);
            // days from civil (Howard Hinnant's algorithm)
            let y = if m <= 2 { y - 1 } else { y };
            let era = y.div_euclid(400);
            let yoe = y - era * 400;
            let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + d - 1;
            let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
            Some((era * 146097 + doe - 719468) as f64)
        }
        _ => None,
    }
}

/// Checks that canboatjs's `got` holds `sent` (canboat's units), within one raw step.
fn check(what: &str, pgn: u32, sent: &Value, got: &Value) {
    for (id, want) in sent.as_object().unwrap() {
        let have = &got[id];
        match want {
            Value::Number(n) => {
                let f = field(pgn, id);
                let want = n.as_f64().unwrap();
                let have = have
                    .as_f64()
                    .or_else(|| have.as_str().and_then(|t| canboat_text(&f.kind, t)))
                    .unwrap_or_else(|| panic!("{what}.{id}: no number in {got}"));
                let tol = f.resolution * 0.51 + 1e-9;
                assert!(
                    (have - want).abs() <= tol,
                    "{what}.{id}: {have}, not {want} (±{tol}): {got}"
                );
            }
            Value::Array(items) if id == "list" => {
                let have = have
                    .as_array()
                    .unwrap_or_else(|| panic!("{what}: no list in {got}"));
                assert_eq!(have.len(), items.len(), "{what}.list: {got}");
                for (i, (s, g)) in items.iter().zip(have).enumerate() {
                    check(&format!("{what}.list[{i}]"), pgn, s, g);
                }
            }
            other => assert_eq!(have, other, "{what}.{id}: {got}"),
        }
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn canboatjs_reads_every_built_in_pgn_seabus_sends_from_its_claimed_address() {
    let Some(modules) = canboatjs() else {
        eprintln!(
            "SKIPPED canboatjs_reads_every_built_in_pgn_seabus_sends_from_its_claimed_address: \
             canboatjs is not installed (scripts/test installs it and sets SEABUS_CANBOATJS)"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pty = dir.path().join("can");
    let bus = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="n2k-sender">
  <medium name="bus" url="{}"/>
  <medium name="n2k" url="slcan+pty://{}"/>
  <module name="nmea2000" type="nmea2000" media="n2k bus" address="40" unique_number="4242"
          device_function="130" device_class="25"/>
</seabus>"#,
        bus.replace('&', "&amp;"),
        pty.display()
    );
    let path = dir.path().join("system.xml");
    std::fs::write(&path, system).unwrap();
    let checked = common::check(&path);
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
    let watcher = schemes().open("bus", &bus, &Node::new("n2k-test")).unwrap();
    let mut rx = watcher.attach("watch");
    rx.subscribe("n2k.status").unwrap();
    let tx = watcher.attach("send");
    let _run = spawn_run(&path, &[]);
    assert!(
        wait_for_path(&pty, Duration::from_secs(10)),
        "the pseudo-terminal {} appeared",
        pty.display()
    );
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/peers/n2k_canboat_read.js"
    );
    let mut node = Running(
        Command::new("node")
            .arg(script)
            .arg(&pty)
            .arg("40")
            .arg("request")
            .env("NODE_PATH", &modules)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("node runs"),
    );
    let out = node.0.stdout.take().unwrap();
    let (ntx, nrx) = std::sync::mpsc::channel::<Value>();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str(&line)
                && ntx.send(v).is_err()
            {
                return;
            }
        }
    });

    // the claim: 250 ms after it, the driver says it holds 40
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut status = None;
    while let Ok(Some(m)) = tokio::time::timeout_at(deadline, rx.recv()).await {
        let map = m.payload.as_map().unwrap().clone();
        if map.get_str("state") == Some("claimed") {
            status = Some(map);
            break;
        }
    }
    let status = status.expect("n2k.status says claimed within 15 s");
    assert_eq!(status.get_i64("address"), Some(40), "{status}");

    // every PGN, published until canboatjs has decoded each (at most 20 rounds)
    let mut decoded: HashMap<u32, Value> = HashMap::new();
    let mut claims = Vec::new();
    let mut errors = Vec::new();
    for _round in 0..20 {
        for (pgn, fields) in messages() {
            let id = seabus_drivers::n2k::builtin::database().definitions(pgn)[0]
                .id
                .to_string();
            tx.publish(
                seabus_medium::Kind::Data,
                format!("n2k.out.{id}").as_str(),
                to_seabus(pgn, &fields),
            )
            .await
            .unwrap();
        }
        // a heading of 400° is refused, not sent
        tx.publish(
            seabus_medium::Kind::Data,
            "n2k.out.vesselHeading",
            DataMap::new()
                .and("sid", V::Int(99))
                .and("heading", V::Float(400.0)),
        )
        .await
        .unwrap();
        let until = std::time::Instant::now() + Duration::from_millis(500);
        while let Ok(v) =
            nrx.recv_timeout(until.saturating_duration_since(std::time::Instant::now()))
        {
            match v["event"].as_str() {
                Some("pgn") if v["pgn"] == 60928 => claims.push(v),
                Some("pgn") => {
                    decoded.insert(v["pgn"].as_u64().unwrap() as u32, v);
                }
                Some("error") => errors.push(v),
                _ => {}
            }
        }
        if messages().iter().all(|(p, _)| decoded.contains_key(p)) {
            break;
        }
    }
    let missing: Vec<u32> = messages()
        .iter()
        .map(|(p, _)| *p)
        .filter(|p| !decoded.contains_key(p))
        .collect();
    assert!(
        missing.is_empty(),
        "canboatjs decoded nothing of {missing:?}; errors {errors:?}"
    );
    for (pgn, fields) in messages() {
        let got = &decoded[&pgn];
        assert_eq!(got["src"], 40, "{got}");
        check(&format!("PGN {pgn}"), pgn, &fields, &got["fields"]);
        // what was not given went as "not available": canboatjs shows nothing more
        let extra: Vec<&String> = got["fields"]
            .as_object()
            .unwrap()
            .keys()
            .filter(|k| fields.get(k.as_str()).is_none())
            .collect();
        assert!(extra.is_empty(), "PGN {pgn}: {extra:?} in {got}");
    }
    // the heading of 400° never went out
    assert_eq!(decoded[&127250]["fields"]["sid"], 7);

    // the driver's own claim, with the NAME of the system file
    let claim = claims.first().expect("canboatjs heard the address claim");
    assert_eq!(claim["src"], 40, "{claim}");
    let f = &claim["fields"];
    assert_eq!(
        (
            &f["uniqueNumber"],
            &f["manufacturerCode"],
            &f["deviceClass"],
            &f["industryGroup"]
        ),
        (
            &json!(4242),
            &json!(2046),
            &json!("Internetwork device"),
            &json!("Marine Industry")
        ),
        "{claim}"
    );

    // the refusals are counted on the status topic
    let deadline = Instant::now() + Duration::from_secs(8);
    let mut refused = None;
    while let Ok(Some(m)) = tokio::time::timeout_at(deadline, rx.recv()).await {
        let map = m.payload.as_map().unwrap().clone();
        if let Some(n) = map
            .get("refused")
            .and_then(V::as_map)
            .and_then(|r| r.get_i64("n2k-send-out-of-range"))
        {
            refused = Some((n, map));
            break;
        }
    }
    let (n, map) = refused.expect("n2k.status counts the refused heading");
    assert!(n >= 1, "{map}");
    assert!(
        map.get_i64("sent").unwrap() >= messages().len() as i64,
        "{map}"
    );
}
