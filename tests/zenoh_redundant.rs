//! A vehicle reaching shore two ways at once — seabus UDP and Zenoh — and a shore station that
//! bridges both into its bus: every message of the vehicle is on the shore bus once, whichever way
//! came first. The shore bus is watched on the wire by a plain UDP socket, so that a duplicate
//! would be seen (a seabus receiver would drop it by itself).

mod common;
use common::*;
use seabus_medium::datagram;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

#[test]
fn a_vehicle_bridged_over_udp_and_zenoh_is_on_the_shore_bus_once() {
    let (link_group, link_port) = (group(), free_port());
    let (bus_group, bus_port) = (group(), free_port());
    let zport = free_tcp_port();
    let vehicle = format!(
        r#"<seabus node="auv1">
  <medium name="bus" url="inproc://"/>
  <medium name="radio" url="udp://{link_group}:{link_port}?ttl=0"/>
  <medium name="fleet" url="zenoh://?listen=tcp/127.0.0.1:{zport}&amp;prefix=fleet/auv1&amp;scout=false"/>
  <module name="vehicle" type="vehicle-sim" medium="bus" tick="20Hz"/>
  <bridge name="by-radio" media="bus radio" report="0">
    <route from="bus" to="radio" topics="nav.**"/>
  </bridge>
  <bridge name="by-zenoh" media="bus fleet" report="0">
    <route from="bus" to="fleet" topics="nav.**"/>
  </bridge>
</seabus>"#
    );
    let shore = format!(
        r#"<seabus node="shore">
  <medium name="bus" url="udp://{bus_group}:{bus_port}?ttl=0"/>
  <medium name="radio" url="udp://{link_group}:{link_port}?ttl=0"/>
  <medium name="fleet" url="zenoh://?connect=tcp/127.0.0.1:{zport}&amp;prefix=fleet/auv1&amp;scout=false"/>
  <bridge name="from-radio" media="radio bus" report="0">
    <route from="radio" to="bus" topics="nav.**"/>
  </bridge>
  <bridge name="from-zenoh" media="fleet bus" report="0">
    <route from="fleet" to="bus" topics="nav.**"/>
  </bridge>
</seabus>"#
    );
    // the shore bus's wire, read as it is (a socket sharing the group's port, as seabus's do)
    let mut url =
        seabus_medium::url::MediumUrl::parse(&format!("udp://{bus_group}:{bus_port}?ttl=0"))
            .unwrap();
    let endpoint = seabus_medium::net::UdpEndpoint::from_url(&mut url).unwrap();
    let (wire, _) = seabus_medium::net::socket(&endpoint).unwrap();
    wire.set_nonblocking(false).unwrap();
    wire.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let (_v, vpath) = system_file("auv1.xml", &vehicle);
    let (_s, spath) = system_file("shore.xml", &shore);
    let _shore = spawn_run(&spath, &[]);
    let _vehicle = spawn_run(&vpath, &[]);
    let mut seen: BTreeMap<(String, u64), u32> = BTreeMap::new();
    let mut origins = datagram::Origins::default();
    let mut buf = vec![0u8; 65_536];
    let start = Instant::now();
    // ten seconds of navigation at 20 Hz, five topics a tick
    while start.elapsed() < Duration::from_secs(10) {
        let Ok(n) = wire.recv(&mut buf) else { continue };
        let bytes = bytes::Bytes::copy_from_slice(&buf[..n]);
        let Ok((_, msg)) = datagram::decode(&bytes, &mut origins) else {
            continue;
        };
        let o = msg.origin();
        if &*o.node == "auv1" {
            *seen.entry((msg.topic.to_string(), msg.seq())).or_default() += 1;
        }
    }
    assert!(
        seen.len() > 300,
        "the vehicle's navigation reached the shore bus: {}",
        seen.len()
    );
    let twice: Vec<_> = seen.iter().filter(|(_, n)| **n > 1).collect();
    assert!(
        twice.is_empty(),
        "on the shore bus more than once: {twice:?}"
    );
}
