//! Replays the NMEA sentence and Remote Helm seeds of the fuzz corpus (`fuzz/corpus/`) through the
//! same property checks as the fuzz targets, so that every seed runs with the ordinary tests,
//! without libFuzzer.

#[path = "../../fuzz/properties/drivers.rs"]
mod properties;
#[macro_use]
#[path = "../../fuzz/properties/replay.rs"]
mod replay;

seed_tests! {
    /// NMEA sentences parse or are refused without a panic, as they are and as the body of a
    /// sentence; a built sentence carries a correct checksum.
    nmea_sentence_seeds => nmea_sentence,
    /// Proprietary attitude tables read or are refused with a placed error, and a table reads any
    /// fields to finite angles.
    nmea_attitude_table_seeds => nmea_attitude_table,
    /// Remote Helm sentences read as frontseat sentences and as commands without a panic, as they
    /// are and as the body of a sentence, and what reads survives a write/read round trip.
    remote_helm_seeds => remote_helm,
    /// CAN signals made from the seed decode without a panic, their raw bits read back, and their
    /// values encode back to the same raw bits.
    dbc_signals_seeds => dbc_signals,
    /// NMEA 2000 frames go through the driver without a panic, to bounded messages, finite values
    /// and valid datasets; reassembled fast packets frame again to themselves.
    n2k_frames_seeds => n2k_frames,
    /// Datamaps encode into PGNs or are refused without a panic, and what encodes decodes back;
    /// an address claimer keeps to the addresses a device may hold.
    n2k_send_seeds => n2k_send,
}
