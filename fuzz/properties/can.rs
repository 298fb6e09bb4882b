//! Properties of the CAN medium's slcan lines and cannelloni packets that every input must keep.

/// slcan lines: any byte stream splits into lines the same whole and in pieces, every line parses
/// or is refused without a panic, a frame line's frame encodes to a line that parses to the same
/// frame and timestamp, and the frame's message form gives it back. True when some line held a
/// frame.
pub fn slcan_lines(data: &[u8]) -> bool {
    use seabus_medium::Payload;
    use seabus_medium_can::frame::CanFrame;
    use seabus_medium_can::slcan::{self, Line, Lines};
    let split = |pieces: &mut dyn Iterator<Item = &[u8]>| {
        let mut lines = Lines::new();
        let mut out: Vec<Result<Vec<u8>, u64>> = Vec::new();
        for p in pieces {
            lines.push(p, &mut |l| out.push(l.map(<[u8]>::to_vec)));
        }
        out
    };
    let whole = split(&mut std::iter::once(data));
    let bytewise = split(&mut data.chunks(3));
    assert_eq!(
        whole, bytewise,
        "lines differ when the bytes come in pieces"
    );
    let mut frames = false;
    for line in whole.into_iter().flatten() {
        assert!(line.len() <= slcan::MAX_LINE, "a line past the maximum");
        let Ok(Line::Frame(frame, time)) = slcan::parse_line(&line) else {
            continue;
        };
        frames = true;
        let encoded = slcan::encode_frame(&frame, time).expect("a parsed frame encodes");
        let again =
            slcan::parse_line(&encoded[..encoded.len() - 1]).expect("an encoded line parses");
        assert_eq!(
            again,
            Line::Frame(frame.clone(), time),
            "slcan round trip changed the frame"
        );
        let back = CanFrame::from_message(&frame.topic(), &Payload::from(frame.to_map(None)))
            .expect("a frame's message gives it back");
        assert_eq!(back, frame, "message round trip changed the frame");
    }
    frames
}

/// cannelloni packets: any bytes decode or are refused without a panic, naming an offset inside
/// them, and a packet that decodes encodes back to as many bytes, which decode to the same packet
/// (FD flag bits other than BRS and ESI are not kept). True when `data` decodes.
pub fn cannelloni_packets(data: &[u8]) -> bool {
    use seabus_medium_can::cannelloni;
    match cannelloni::decode(data) {
        Err(e) => {
            assert!(
                e.offset().is_some_and(|o| o <= data.len()),
                "error offset past the packet: {e}"
            );
            false
        }
        Ok(p) => {
            let again = cannelloni::encode(p.seq, &p.frames);
            assert_eq!(again.len(), data.len(), "re-encoded to another length");
            let back = cannelloni::decode(&again).expect("an encoded packet decodes");
            assert_eq!(back, p, "a decoded packet encodes to another packet");
            true
        }
    }
}
