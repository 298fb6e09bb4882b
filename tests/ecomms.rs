//! DSAAV external communications from a system file: a component on the backbone sends messages
//! out through a link (they reach the link's driver topic, the expired one never does) and hears
//! what comes in through it.

mod common;
use common::*;
use seabus_dsaav::ecomms::ops;
use seabus_dsaav::rpc::{self, CallOptions, RpcClient};
use seabus_medium::{DataMap, Node};
use seabus_medium_dsaav::wire::Address;
use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn messages_go_out_through_links_and_come_in_to_listeners() {
    let backbone = format!("dsaav+udp://{}:{}?ttl=0", group(), free_port());
    let net = format!("udp://{}:{}?ttl=0", group(), free_port());
    let system = format!(
        r#"<seabus node="vehicle">
  <medium name="bus" url="inproc://"/>
  <medium name="net" url="{net}"/>
  <medium name="n1" url="{backbone}&amp;node=1"/>
  <module name="ecomms" type="dsaav-ecomms" media="bus n1" port="3"/>
  <bridge name="links" media="bus net" report="0">
    <route from="bus" to="net" topics="ecomms.*.out"/>
    <route from="net" to="bus" topics="ecomms.*.in"/>
  </bridge>
</seabus>"#
    );
    let (_dir, path) = system_file("vehicle.xml", &system);
    let _run = spawn_run(&path, &[]);
    let spy = seabus()
        .args(["spy", &net, "--json", "--topics", "ecomms.**", "--for", "6"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();

    let me = schemes()
        .open("dsaav", &format!("{backbone}&node=9"), &Node::new("t"))
        .unwrap();
    let heard: Arc<Mutex<Vec<DataMap>>> = Arc::default();
    let h = heard.clone();
    let m = me.clone();
    tokio::spawn(async move {
        rpc::serve(&m, 5, &[], move |call| {
            if call.op == ops::RECEIVE {
                h.lock().unwrap().push(call.params);
            }
            Ok(DataMap::new())
        })
        .await
    });
    let client = RpcClient::new(&me, 5);
    let service = Address { node: 1, port: 3 };
    let opts = CallOptions::default();
    client
        .call(service, ops::LISTEN, &DataMap::new(), opts)
        .await
        .expect("the service answers");
    for (text, priority, lifetime) in [("low", 1i64, 30.0f64), ("high", 9, 30.0), ("stale", 5, 0.0)]
    {
        let msg = DataMap::new()
            .with("interface", "modem")
            .with("destination", "ship")
            .with("class", 2i64)
            .with("priority", priority)
            .with("lifetime", lifetime)
            .with("text", text);
        client.call(service, ops::SEND, &msg, opts).await.unwrap();
    }
    // something comes in over the link
    let sent = seabus()
        .args([
            "pub",
            &net,
            "ecomms.modem.in",
            "source=\"ship\"",
            "class=2",
            "text=\"hello\"",
        ])
        .status()
        .unwrap();
    assert!(sent.success());
    let deadline = Instant::now() + Duration::from_secs(5);
    while heard.lock().unwrap().is_empty() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let heard = heard.lock().unwrap().clone();
    assert_eq!(heard.len(), 1, "{heard:?}");
    assert_eq!(heard[0].get_str("interface"), Some("modem"));
    assert_eq!(heard[0].get_str("source"), Some("ship"));
    assert_eq!(heard[0].get_str("text"), Some("hello"));

    let out = spy.wait_with_output().unwrap();
    let texts: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["topic"] == "ecomms.modem.out")
        .filter_map(|v| v["payload"]["text"].as_str().map(str::to_string))
        .collect();
    let mut sorted = texts.clone();
    sorted.sort();
    assert_eq!(
        sorted,
        ["high", "low"],
        "sent once each, the expired one never: {texts:?}"
    );
}
