//! Properties of the UDP medium's datagram codec that every input must keep.

use bytes::Bytes;
use seabus_medium::datagram as wire;

/// The UDP datagram decoder: any datagram decodes or is rejected without a panic, and every message
/// it accepts encodes back to a datagram that decodes to the same message. True when `data`
/// decodes.
pub fn udp_datagram(data: &[u8]) -> bool {
    let mut origins = wire::Origins::default();
    let Ok((sender, msg)) = wire::decode(&Bytes::copy_from_slice(data), &mut origins) else {
        return false;
    };
    let datagram = wire::encode(&msg, sender)
        .unwrap_or_else(|e| panic!("a decoded message does not encode: {e}"));
    let (sender2, back) = wire::decode(&datagram, &mut origins)
        .unwrap_or_else(|e| panic!("an encoded message does not decode: {e}"));
    assert_eq!(sender2, sender, "sender");
    assert_eq!(back.topic, msg.topic, "topic");
    assert_eq!(back.kind, msg.kind, "kind");
    assert_eq!(back.provenance, msg.provenance, "provenance");
    assert_eq!(back.stamp, msg.stamp, "stamp");
    assert_eq!(back.payload, msg.payload, "payload");
    true
}
