//! Properties of the MOOS medium's packets that every input must keep.

/// MOOS packets: any bytes read as a packet, as incomplete, or are refused without a panic, naming
/// an offset inside them; a packet read encodes back to the same bytes (but its compression flag,
/// which readers ignore), also when the stream is read a few bytes at a time. True when `data`
/// starts with a packet.
pub fn moos_packets(data: &[u8]) -> bool {
    use seabus_medium_moos::wire::{Read, read_packet};
    match read_packet(data) {
        Err(e) => {
            assert!(
                e.offset().is_some_and(|o| o <= data.len()),
                "error offset past the input: {e}"
            );
            false
        }
        Ok(Read::Incomplete(n)) => {
            assert!(n > data.len(), "incomplete, yet {n} bytes are there");
            false
        }
        Ok(Read::Packet(p, n)) => {
            let mut again = p.encode();
            assert_eq!(again.len(), n, "re-encoded to another length");
            again[8] = data[8];
            assert_eq!(
                &again[..],
                &data[..n],
                "a packet read encodes to other bytes"
            );
            // every shorter prefix is incomplete, never malformed
            for cut in [0, 8, n / 2, n - 1] {
                assert!(
                    matches!(read_packet(&data[..cut]), Ok(Read::Incomplete(_))),
                    "a prefix of {cut} bytes is not incomplete"
                );
            }
            true
        }
    }
}
