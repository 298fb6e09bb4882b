//! The configuration service over RPC with the paper's depth-control file: a component finds the
//! server by a broadcast call, reads its settings, is plumbed to the right servers, and keeps
//! application data that masks the file's value, survives a restart and is removed again.

use seabus_dsaav::config::Database;
use seabus_dsaav::config_service::{self, ConfigClient};
use seabus_dsaav::rpc::{CallOptions, RpcError};
use seabus_medium::{Medium, Node};
use seabus_medium_dsaav::wire::Address;
use std::path::Path;

fn open(url: &str) -> Medium {
    seabus_medium_dsaav::schemes()
        .open("dsaav", url, &Node::new("t"))
        .expect("dsaav medium opens")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn components_are_configured_and_plumbed_through_the_service() {
    let dir = tempfile::tempdir().unwrap();
    let ini = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/starfish.ini");
    let app = dir.path().join("appdata.ini");
    let bus = format!("dsaav+inproc://cfg{}", fastrand::u32(..));
    let server_medium = open(&format!("{bus}?node=1"));
    let db = Database::open(&ini, &app).expect("the example loads");
    let server = server_medium.clone();
    tokio::spawn(async move { config_service::serve(&server, 2, db).await });

    let component = open(&format!("{bus}?node=3"));
    let opts = CallOptions::default();
    let cfg = ConfigClient::discover(&component, 7, opts).await.unwrap();
    assert_eq!(cfg.server(), Address { node: 1, port: 2 });

    // the paper's plumbing
    let at = |node, port| Address { node, port };
    assert_eq!(
        cfg.server_of("DepthFilter", "Depth").await.unwrap(),
        at(4, 0)
    );
    assert_eq!(
        cfg.server_of("MyDepthController", "Depth").await.unwrap(),
        at(3, 0)
    );
    assert_eq!(
        cfg.server_of("MyDepthController", "Elevators")
            .await
            .unwrap(),
        at(2, 0)
    );
    assert_eq!(
        cfg.setting("MyDepthController", "Logging", "LogLevel")
            .await
            .unwrap(),
        "LOG_DEBUG"
    );
    assert_eq!(
        cfg.setting("DepthFilter", "Logging", "LogLevel")
            .await
            .unwrap(),
        "LOG_INFO"
    );
    assert_eq!(
        cfg.get_float("MyDepthController", "ControlGain")
            .await
            .unwrap(),
        2.3
    );
    match cfg.get_str("MyDepthController", "NoSuchKey").await {
        Err(RpcError::Failed {
            status: 4, message, ..
        }) => {
            assert!(message.contains("NoSuchKey"), "{message}")
        }
        other => panic!("expected a missing setting, got {other:?}"),
    }

    // application data masks the file, is written to its own file, and is removed again
    cfg.put("MyDepthController", "ControlGain", "2.5")
        .await
        .unwrap();
    assert_eq!(
        cfg.get_float("MyDepthController", "ControlGain")
            .await
            .unwrap(),
        2.5
    );
    let reopened = Database::open(&ini, &app).unwrap();
    assert_eq!(
        reopened.get_float("MyDepthController", "ControlGain"),
        Ok(2.5)
    );
    assert!(
        cfg.remove("MyDepthController", "ControlGain")
            .await
            .unwrap()
    );
    assert_eq!(
        cfg.get_float("MyDepthController", "ControlGain")
            .await
            .unwrap(),
        2.3
    );
    assert!(
        !cfg.remove("MyDepthController", "ControlGain")
            .await
            .unwrap()
    );
}
