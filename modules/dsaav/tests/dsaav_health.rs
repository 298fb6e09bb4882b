//! The health service over RPC: components' reports reach the monitor, a bad report is refused
//! with the reason, the status call answers the severity and the states, the health call answers
//! for the monitor itself, and polling a component that is gone gives nothing. A server whose
//! results the wire cannot carry says so instead of leaving the caller to time out.

use seabus_dsaav::health::{ComponentState, Severity};
use seabus_dsaav::health_service::{self, Status, ops};
use seabus_dsaav::rpc::{CallOptions, RpcClient, RpcError};
use seabus_medium::{DataMap, Medium, Node};
use seabus_medium_dsaav::wire::Address;
use std::time::Duration;

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn components_report_and_stations_ask_for_the_severity() {
    let bus = format!("dsaav+inproc://health{}", fastrand::u32(..));
    let monitor = open(&format!("{bus}?node=1"));
    let (tx, mut updates) = tokio::sync::mpsc::channel(16);
    let status: Status = Default::default();
    *status.lock().unwrap() = health_service::status(
        Severity::Warn,
        [
            ("DepthSensor", ComponentState::Healthy),
            ("GPS", ComponentState::Unavailable),
        ]
        .into_iter(),
    );
    {
        let (m, st) = (monitor.clone(), status.clone());
        tokio::spawn(async move { health_service::serve(&m, 1, tx, st).await });
    }
    let at = Address { node: 1, port: 1 };
    let sensor = open(&format!("{bus}?node=4"));
    let rpc = RpcClient::new(&sensor, 10);
    let opts = CallOptions::default();

    // the server is up once it answers
    assert_eq!(
        health_service::poll(&rpc, at, opts).await,
        Some(ComponentState::Healthy)
    );
    // a report, sent unreliably, arrives as an update
    health_service::report(&rpc, at, "DepthSensor", ComponentState::Malfunction)
        .await
        .unwrap();
    let got = tokio::time::timeout(Duration::from_secs(5), updates.recv())
        .await
        .expect("the report arrives");
    assert_eq!(
        got,
        Some(("DepthSensor".to_string(), ComponentState::Malfunction))
    );

    // a report without a state, or with one out of range, is refused with the reason
    for bad in [
        DataMap::new().with("component", "GPS"),
        DataMap::new().with("component", "GPS").with("state", 9i64),
        DataMap::new().with("state", 0i64),
    ] {
        match rpc.call(at, ops::REPORT, &bad, opts).await {
            Err(RpcError::Failed {
                status, message, ..
            }) => {
                assert_eq!(status, 5);
                assert!(message.contains("`component` and `state`"), "{message}");
            }
            other => panic!("{bad:?}: expected a refusal, got {other:?}"),
        }
    }

    // a control station finds the monitor by broadcast and reads the severity
    let station = open(&format!("{bus}?node=7"));
    let srpc = RpcClient::new(&station, 3);
    let (found, reply) = srpc
        .discover(ops::STATUS, &DataMap::new(), opts)
        .await
        .unwrap();
    assert_eq!(found, at);
    assert_eq!(reply.get_i64("severity"), Some(1));
    assert_eq!(
        reply.get_str("components"),
        Some("DepthSensor=HEALTHY,GPS=UNAVAILABLE")
    );

    // the monitor answers the health call itself; a node nobody runs answers nothing
    assert_eq!(
        health_service::poll(&srpc, at, opts).await,
        Some(ComponentState::Healthy)
    );
    let quick = CallOptions {
        timeout: Duration::from_millis(200),
        ..opts
    };
    assert_eq!(
        health_service::poll(&srpc, Address { node: 5, port: 0 }, quick).await,
        None
    );
}

#[tokio::test]
async fn results_the_wire_cannot_carry_are_refused_with_the_reason() {
    let bus = format!("dsaav+inproc://unsendable{}", fastrand::u32(..));
    let server = open(&format!("{bus}?node=1"));
    {
        let m = server.clone();
        tokio::spawn(async move {
            seabus_dsaav::rpc::serve(&m, 0, &[], |_| Ok(DataMap::new().with("no-such-key", 1i64)))
                .await
        });
    }
    let client = open(&format!("{bus}?node=2"));
    let rpc = RpcClient::new(&client, 4);
    let opts = CallOptions {
        timeout: Duration::from_secs(2),
        ..CallOptions::default()
    };
    match rpc
        .call(Address { node: 1, port: 0 }, 42, &DataMap::new(), opts)
        .await
    {
        Err(RpcError::Failed {
            status, message, ..
        }) => {
            assert_eq!(status, seabus_dsaav::rpc::UNSENDABLE);
            assert!(message.contains("no-such-key"), "{message}");
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
}
