//! The DSAAV RPC layer between two nodes on an IComms medium: ten thousand reliable calls through
//! a fault stage losing 30 %, duplicating 10 % and reordering 10 % of the frames each way all
//! complete, each run exactly once; timeouts, failures, unreliable calls and discovery.

use seabus_dsaav::rpc::{self, CallOptions, RpcClient, RpcError};
use seabus_medium::{DataMap, Medium, Node};
use seabus_medium_dsaav::wire::Address;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

fn backbone() -> String {
    format!("dsaav+inproc://rpc{}", fastrand::u32(..))
}

const SERVER: Address = Address { node: 2, port: 5 };

/// Serves operation 1 (adds one to `count`, recording each run) and 2 (always fails).
fn start_server(medium: &Medium, runs: Arc<Mutex<HashMap<(Address, i64), u32>>>) {
    let medium = medium.clone();
    tokio::spawn(async move {
        rpc::serve(&medium, SERVER.port, &[1], move |call| match call.op {
            1 => {
                let n = call.params.get_i64("count").unwrap_or(0);
                *runs.lock().unwrap().entry((call.from, n)).or_default() += 1;
                Ok(DataMap::new().with("count", n + 1))
            }
            _ => Err((3, format!("operation {} is not served here", call.op))),
        })
        .await
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ten_thousand_reliable_calls_through_a_lossy_link_each_run_exactly_once() {
    const CALLS: i64 = 10_000;
    let bus = backbone();
    let faults = "fault.loss=0.3&fault.dup=0.1&fault.reorder=0.1&fault.hold=3ms";
    let client_medium = open(&format!("{bus}?node=1&{faults}&fault.seed=7"));
    let server_medium = open(&format!("{bus}?node=2&{faults}&fault.seed=8"));
    let runs = Arc::new(Mutex::new(HashMap::new()));
    start_server(&server_medium, runs.clone());
    let client = Arc::new(RpcClient::new(&client_medium, 9));
    let opts = CallOptions {
        timeout: Duration::from_secs(30),
        first_retry: Duration::from_millis(15),
        max_retry: Duration::from_millis(200),
    };
    let start = Instant::now();
    let permits = Arc::new(tokio::sync::Semaphore::new(64));
    let mut tasks = Vec::new();
    for n in 0..CALLS {
        let client = client.clone();
        let permits = permits.clone();
        tasks.push(tokio::spawn(async move {
            let _permit = permits.acquire().await.unwrap();
            let reply = client
                .call(SERVER, 1, &DataMap::new().with("count", n), opts)
                .await;
            (n, reply.map(|r| r.get_i64("count")))
        }));
    }
    let mut failed = Vec::new();
    for t in tasks {
        let (n, reply) = t.await.unwrap();
        if reply != Ok(Some(n + 1)) {
            failed.push((n, reply));
        }
    }
    let elapsed = start.elapsed();
    assert!(
        failed.is_empty(),
        "{} calls failed: {:?}",
        failed.len(),
        &failed[..failed.len().min(5)]
    );
    let runs = runs.lock().unwrap();
    assert_eq!(runs.len(), CALLS as usize, "every call ran");
    assert!(
        runs.values().all(|&r| r == 1),
        "a call ran more than once: {:?}",
        runs.iter().find(|(_, r)| **r != 1)
    );
    let (c, s) = (client_medium.stats(), server_medium.stats());
    println!(
        "{CALLS} reliable calls, 30 % loss / 10 % duplication / 10 % reordering each way: all done in \
         {:.2} s ({:.0} calls/s); requests sent {} (lost {}, duplicated {}), replies sent {} (lost {}, \
         duplicated {}); every call ran exactly once",
        elapsed.as_secs_f64(),
        CALLS as f64 / elapsed.as_secs_f64(),
        c.published,
        c.fault_lost,
        c.fault_duplicated,
        s.published,
        s.fault_lost,
        s.fault_duplicated
    );
    assert!(
        c.fault_lost > 0 && s.fault_duplicated > 0,
        "the faults were there"
    );
}

#[tokio::test]
async fn timeouts_failures_unreliable_calls_and_discovery() {
    let bus = backbone();
    let client_medium = open(&format!("{bus}?node=1"));
    let server_medium = open(&format!("{bus}?node=2"));
    let runs = Arc::new(Mutex::new(HashMap::new()));
    start_server(&server_medium, runs.clone());
    let client = RpcClient::new(&client_medium, 9);
    let quick = CallOptions {
        timeout: Duration::from_millis(300),
        first_retry: Duration::from_millis(20),
        max_retry: Duration::from_millis(100),
    };
    // nobody on node 7
    let started = Instant::now();
    match client
        .call(Address { node: 7, port: 0 }, 1, &DataMap::new(), quick)
        .await
    {
        Err(RpcError::Timeout { attempts, .. }) => assert!(attempts >= 3, "{attempts}"),
        other => panic!("expected a timeout, got {other:?}"),
    }
    assert!(started.elapsed() < Duration::from_secs(2));
    // a procedure that fails says why
    match client.call(SERVER, 2, &DataMap::new(), quick).await {
        Err(RpcError::Failed {
            status, message, ..
        }) => assert_eq!(
            (status, message.as_str()),
            (3, "operation 2 is not served here")
        ),
        other => panic!("expected a failure, got {other:?}"),
    }
    // an unreliable call runs once, with no reply
    client
        .call_unreliable(SERVER, 1, &DataMap::new().with("count", 500i64))
        .await
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while runs.lock().unwrap().is_empty() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert_eq!(
        runs.lock()
            .unwrap()
            .get(&(Address { node: 1, port: 9 }, 500)),
        Some(&1)
    );
    // a broadcast call finds the server offering the operation
    let (at, reply) = client
        .discover(1, &DataMap::new().with("count", 41i64), quick)
        .await
        .unwrap();
    assert_eq!(at, SERVER);
    assert_eq!(reply.get_i64("count"), Some(42));
}

/// A reliable call from port 5 of node 1 to a server on port 0 of the same medium: answered, and
/// run once.
async fn call_within_one_node(url: &str) {
    let medium = open(url);
    let runs = Arc::new(Mutex::new(Vec::new()));
    let r = runs.clone();
    let server = medium.clone();
    tokio::spawn(async move {
        rpc::serve(&server, 0, &[1], move |call| {
            let n = call.params.get_i64("count").unwrap_or(0);
            r.lock().unwrap().push((call.from, n));
            Ok(DataMap::new().with("count", n + 1))
        })
        .await
    });
    let client = RpcClient::new(&medium, 5);
    let opts = CallOptions {
        timeout: Duration::from_secs(3),
        ..CallOptions::default()
    };
    let reply = client
        .call(
            Address { node: 1, port: 0 },
            1,
            &DataMap::new().with("count", 41i64),
            opts,
        )
        .await
        .expect("the call is answered");
    assert_eq!(reply.get_i64("count"), Some(42));
    assert_eq!(reply.get_str("@src"), Some("1:0"));
    assert_eq!(reply.get_str("@dst"), Some("1:5"));
    // retries, if any, were answered from memory
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(
        *runs.lock().unwrap(),
        [(Address { node: 1, port: 5 }, 41)],
        "the handler ran once, for the caller"
    );
    medium.close();
}

#[tokio::test]
async fn a_call_between_two_ports_of_one_node_is_answered_in_process() {
    call_within_one_node(&format!("{}?node=1", backbone())).await;
}

#[tokio::test]
async fn a_call_between_two_ports_of_one_node_is_answered_over_udp() {
    call_within_one_node(&format!(
        "dsaav+udp://239.255.{}.{}:{}?ttl=0&node=1",
        fastrand::u8(1..250),
        fastrand::u8(1..250),
        fastrand::u16(20_000..60_000)
    ))
    .await;
}
