//! Properties of the DSAAV medium's frames that every input must keep.

use seabus_medium_dsaav::wire::Frame as DsaavFrame;

/// DSAAV IComms frames: any bytes decode or are refused without a panic, naming an offset inside
/// them, and a frame that decodes encodes back to the same bytes (up to its stated length). True
/// when `data` decodes.
pub fn dsaav_frame(data: &[u8]) -> bool {
    match DsaavFrame::decode(data) {
        Err(e) => {
            assert!(
                e.offset().is_some_and(|o| o <= data.len().max(2)),
                "error offset past the input: {e}"
            );
            false
        }
        Ok(frame) => {
            let again = frame.encode().expect("a decoded frame encodes");
            assert!(again.len() <= data.len(), "encoded longer than read");
            // float values keep their bits both ways, NaNs included
            assert!(
                data.get(..again.len()) == Some(again.as_slice()),
                "decoded frame encodes to other bytes"
            );
            true
        }
    }
}
