//! The `command-status` dataset: what became of a command a driver or simulator was given,
//! published on its `cmd.status` topic.
//!
//! Its fields: `command` (the command's name), `state` (`pending`, `acknowledged`, `refused`,
//! `timed-out`, or `sent` for a command without acknowledgements), `id` (the driver's number for
//! the command, where it counts them), `error` (why, where there is a why), and `origin` and
//! `request_seq`: the sender and sequence number of the command message it answers.

use seabus_medium::{DataMap, Message};

/// The dataset's name.
pub const DATASET: &str = "command-status";

/// The command message a status answers: its origin, as text, and its sequence number.
pub fn request(msg: &Message) -> (String, u64) {
    (msg.origin().to_string(), msg.seq())
}

/// The status of `command`, now `state`: with `id` and `error` where given, and `origin` and
/// `request_seq` of the command message it answers where there was one.
pub fn command_status(
    command: &str,
    state: &str,
    id: Option<i64>,
    error: Option<&str>,
    request: Option<&(String, u64)>,
) -> DataMap {
    let mut m = DataMap::with_capacity(6);
    m.push("command", command);
    m.push("state", state);
    if let Some(id) = id {
        m.push("id", id);
    }
    if let Some(error) = error {
        m.push("error", error);
    }
    if let Some((origin, seq)) = request {
        m.push("origin", origin.as_str());
        m.push("request_seq", *seq as i64);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_in_order_and_only_those_given() {
        let full = command_status(
            "ARM",
            "refused",
            Some(3),
            Some("DENIED"),
            Some(&("console".to_string(), 7)),
        );
        let names: Vec<&str> = full.iter().map(|(k, _)| k).collect();
        assert_eq!(
            names,
            ["command", "state", "id", "error", "origin", "request_seq"]
        );
        assert_eq!(full.get_str("command"), Some("ARM"));
        assert_eq!(full.get_str("state"), Some("refused"));
        assert_eq!(full.get_i64("id"), Some(3));
        assert_eq!(full.get_str("error"), Some("DENIED"));
        assert_eq!(full.get_str("origin"), Some("console"));
        assert_eq!(full.get_i64("request_seq"), Some(7));

        let bare = command_status("Thrust", "sent", None, None, None);
        assert_eq!(bare.len(), 2);
        assert_eq!(bare.get_str("state"), Some("sent"));
    }
}
