//! How the commands that send (`seabus pub`, `seabus replay`) keep to the medium's link.
//!
//! A command waits for the link to come up before its first message, at most its link wait (a
//! medium with a connection, a MOOSDB or a serial port, takes a moment). When the link is lost on
//! the way, the command logs it with the medium's reason, waits for the link to come back (the
//! medium keeps trying) at most the same time, logs its return and goes on with the message it
//! was sending: nothing the user asked for is skipped. What the link took with it (messages the
//! medium had taken and not yet written, or written into a connection that then failed: a MOOSDB
//! does not acknowledge, so those are lost for all the sender can tell) is counted and reported
//! at the end. A link that does not come back within the wait ends the command.
//!
//! Exit code [`LINK_LOST`] (4) says the link failed the command: it did not come up, did not come
//! back, or took messages with it.

use std::time::Duration;

use seabus_medium::{Interface, Kind, LinkState, Medium, Payload, SendError, Topic};

/// The exit code of a command whose medium's link failed it.
pub const LINK_LOST: u8 = 4;

/// Why a message could not be sent.
#[derive(Debug)]
pub enum NotSent {
    /// The link did not come up, or back, within the wait; the medium's reason.
    LinkLost(String),
    /// The medium refused the message (too long, a payload it cannot carry).
    Refused(SendError),
    /// The medium was closed.
    Closed,
}

/// What a command's end found still unsent.
#[derive(Debug, PartialEq, Eq)]
pub enum Unfinished {
    /// Messages taken by the medium and lost with its link (its peer never confirmed them).
    Lost(u64),
    /// What the medium held did not go out within the wait.
    Late(Duration),
}

impl std::fmt::Display for Unfinished {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unfinished::Lost(n) => write!(
                f,
                "{n} message(s) lost with the link (taken by the medium, never confirmed by its peer)"
            ),
            Unfinished::Late(wait) => write!(f, "not all sent within {}", secs(*wait)),
        }
    }
}

/// A command's sending side: the medium, its port, and what the link did.
pub struct Sending {
    /// The command's name, as its messages begin (`seabus pub`).
    command: &'static str,
    medium: Medium,
    port: Interface,
    wait: Duration,
}

impl Sending {
    /// Attaches the command to `medium` and waits, at most `wait`, for its link to come up.
    pub async fn open(
        command: &'static str,
        medium: Medium,
        wait: Duration,
    ) -> Result<Self, NotSent> {
        let port = medium.attach(command.trim_start_matches("seabus "));
        let sending = Sending {
            command,
            medium,
            port,
            wait,
        };
        if !sending.wait_up().await {
            return Err(NotSent::LinkLost(format!(
                "the link did not come up within {}: {}",
                secs(wait),
                sending.reason()
            )));
        }
        Ok(sending)
    }

    /// Sends one message; when the link is down (before the message, or refusing it), logs it,
    /// waits for it to come back and sends the message then. `Ok(true)` says the link was lost
    /// and came back on the way (a paced command starts its pacing again).
    pub async fn send(
        &mut self,
        kind: Kind,
        topic: &Topic,
        payload: Payload,
    ) -> Result<bool, NotSent> {
        let mut resumed = false;
        // refusals as down while the medium says up are a moment's (its sender learns first):
        // they end in the link wait like any other
        let deadline = tokio::time::Instant::now() + self.wait;
        loop {
            if self.medium.link_state() != LinkState::Up {
                self.come_back().await?;
                resumed = true;
            }
            match self
                .port
                .publish(kind, topic.clone(), payload.clone())
                .await
            {
                Ok(()) => return Ok(resumed),
                // lost between the look and the send: waited for above, on the next round
                Err(SendError::LinkDown { reason, .. }) => {
                    if self.medium.link_state() == LinkState::Up {
                        if tokio::time::Instant::now() >= deadline {
                            return Err(NotSent::LinkLost(format!(
                                "the link refused sends for {}: {reason}",
                                secs(self.wait)
                            )));
                        }
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                }
                Err(SendError::Closed(_)) => return Err(NotSent::Closed),
                Err(e) => return Err(NotSent::Refused(e)),
            }
        }
    }

    /// Waits for what the medium still holds to go out (at most the link wait); says what the
    /// link took, or that not all went out in time.
    pub async fn finish(&self) -> Result<(), Unfinished> {
        let flushed = tokio::time::timeout(self.wait, self.medium.flush())
            .await
            .is_ok();
        match self.medium.stats().tx_errors {
            0 if flushed => Ok(()),
            0 => Err(Unfinished::Late(self.wait)),
            lost => Err(Unfinished::Lost(lost)),
        }
    }

    /// The link is down: logs it, waits for its return (at most the wait) and logs that.
    async fn come_back(&mut self) -> Result<(), NotSent> {
        let command = self.command;
        tracing::warn!(
            "{command}: link lost: {}; waiting up to {} for it to come back",
            self.reason(),
            secs(self.wait)
        );
        if !self.wait_up().await {
            let lost = match self.medium.stats().tx_errors {
                0 => String::new(),
                n => format!(" ({n} message(s) lost with it)"),
            };
            return Err(NotSent::LinkLost(format!(
                "the link did not come back within {}: {}{lost}",
                secs(self.wait),
                self.reason()
            )));
        }
        tracing::info!("{command}: link back; sending again");
        Ok(())
    }

    /// Waits, at most the wait, for the link to be up; false when it is not.
    async fn wait_up(&self) -> bool {
        self.medium
            .link_within(self.wait, |s| *s == LinkState::Up)
            .await
            .is_some()
    }

    /// Why the link is down, as the medium says.
    fn reason(&self) -> String {
        match self.medium.link_state() {
            LinkState::Down(r) => r,
            LinkState::Up => "it is up again".into(),
        }
    }
}

/// `5 s`, `0.5 s`.
pub fn secs(d: Duration) -> String {
    format!("{} s", d.as_secs_f64())
}

/// Parses `--link-wait SECS`.
pub fn link_wait(value: f64) -> Option<Duration> {
    seabus_medium::parse::secs(value)
}
