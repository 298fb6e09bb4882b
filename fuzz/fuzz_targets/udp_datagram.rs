//! Fuzzes the UDP datagram decoder: any datagram decodes or is rejected without a panic, and every
//! message it accepts encodes back to a datagram that decodes to the same message.

#![no_main]

use bytes::Bytes;
use libfuzzer_sys::fuzz_target;
use seabus_medium::udp::wire;

fuzz_target!(|data: &[u8]| {
    let mut origins = wire::Origins::default();
    let Ok((sender, msg)) = wire::decode(&Bytes::copy_from_slice(data), &mut origins) else {
        return;
    };
    let datagram = wire::encode(&msg, sender).expect("a decoded message encodes");
    let (sender2, back) =
        wire::decode(&datagram, &mut origins).expect("an encoded message decodes");
    assert_eq!(sender2, sender);
    assert_eq!(back.topic, msg.topic);
    assert_eq!(back.kind, msg.kind);
    assert_eq!(back.provenance, msg.provenance);
    assert_eq!(back.stamp, msg.stamp);
    assert_eq!(back.payload, msg.payload);
});
