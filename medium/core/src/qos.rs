//! Quality of service: how urgently a medium that carries priorities sends a message, and what it
//! does with it when the network is congested.
//!
//! A medium that has such a thing ([`crate::Capabilities::qos`], Zenoh's) gives each message the
//! defaults of its kind; a [`Qos`] declared for some topics ([`crate::Medium::set_qos`], as a
//! bridge route's `priority`, `congestion` and `express` attributes do) changes the attributes it
//! sets and leaves the others as they were. The names are those users write in system files.

use std::fmt;

/// How urgently a message goes, from the most urgent to the least.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Priority {
    /// `realtime`: ahead of everything else.
    Realtime,
    /// `interactive-high`: what an operator waits for (commands, by default).
    InteractiveHigh,
    /// `interactive-low`.
    InteractiveLow,
    /// `data-high`: data ahead of other data.
    DataHigh,
    /// `data`: data (by default).
    Data,
    /// `data-low`.
    DataLow,
    /// `background`: when nothing else is waiting.
    Background,
}

impl Priority {
    /// Every priority, the most urgent first.
    pub const ALL: [Priority; 7] = [
        Priority::Realtime,
        Priority::InteractiveHigh,
        Priority::InteractiveLow,
        Priority::DataHigh,
        Priority::Data,
        Priority::DataLow,
        Priority::Background,
    ];

    /// Its name in a system file (`interactive-high`).
    pub fn name(self) -> &'static str {
        match self {
            Priority::Realtime => "realtime",
            Priority::InteractiveHigh => "interactive-high",
            Priority::InteractiveLow => "interactive-low",
            Priority::DataHigh => "data-high",
            Priority::Data => "data",
            Priority::DataLow => "data-low",
            Priority::Background => "background",
        }
    }

    /// The priority called `name` (as [`Priority::name`] gives it; case and surrounding space do
    /// not matter).
    pub fn parse(name: &str) -> Option<Priority> {
        let name = name.trim();
        Priority::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(name))
    }

    /// The names a system file may use, for an error message: `realtime, …, data-low or
    /// background`.
    pub fn expected() -> String {
        or_list(&Priority::ALL.map(Priority::name))
    }
}

impl fmt::Display for Priority {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a medium does with a message when the network cannot take it yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Congestion {
    /// `block`: the sender waits for room (commands, by default).
    Block,
    /// `drop`: the message is dropped, so that newer ones go instead (data, by default).
    Drop,
}

impl Congestion {
    /// Both, `block` first.
    pub const ALL: [Congestion; 2] = [Congestion::Block, Congestion::Drop];

    /// Its name in a system file.
    pub fn name(self) -> &'static str {
        match self {
            Congestion::Block => "block",
            Congestion::Drop => "drop",
        }
    }

    /// The behaviour called `name` (case and surrounding space do not matter).
    pub fn parse(name: &str) -> Option<Congestion> {
        let name = name.trim();
        Congestion::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name))
    }

    /// The names a system file may use, for an error message: `block or drop`.
    pub fn expected() -> String {
        or_list(&Congestion::ALL.map(Congestion::name))
    }
}

impl fmt::Display for Congestion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A quality of service, attribute by attribute: each one set replaces what the medium would
/// otherwise give, each one left `None` keeps it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Qos {
    /// How urgently the message goes.
    pub priority: Option<Priority>,
    /// What happens to it when the network is congested.
    pub congestion: Option<Congestion>,
    /// Whether it goes at once, on its own, rather than batched with others (less delay, more
    /// overhead).
    pub express: Option<bool>,
}

impl Qos {
    /// Whether it sets nothing.
    pub fn is_empty(&self) -> bool {
        *self == Qos::default()
    }

    /// These attributes over `base`: each one set here, the others as `base` has them.
    pub fn over(self, base: Qos) -> Qos {
        Qos {
            priority: self.priority.or(base.priority),
            congestion: self.congestion.or(base.congestion),
            express: self.express.or(base.express),
        }
    }
}

impl fmt::Display for Qos {
    /// `priority=data-high congestion=block express=true`, the attributes that are set.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut parts = Vec::new();
        if let Some(p) = self.priority {
            parts.push(format!("priority={p}"));
        }
        if let Some(c) = self.congestion {
            parts.push(format!("congestion={c}"));
        }
        if let Some(e) = self.express {
            parts.push(format!("express={e}"));
        }
        f.write_str(&parts.join(" "))
    }
}

/// `a, b or c`.
fn or_list(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [one] => one.to_string(),
        [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_read_back_and_the_expected_lists_name_them_all() {
        for p in Priority::ALL {
            assert_eq!(Priority::parse(p.name()), Some(p));
        }
        assert_eq!(
            Priority::parse(" Interactive-High "),
            Some(Priority::InteractiveHigh)
        );
        assert_eq!(Priority::parse("urgent"), None);
        assert_eq!(Priority::parse("real-time"), None);
        assert_eq!(
            Priority::expected(),
            "realtime, interactive-high, interactive-low, data-high, data, data-low or background"
        );
        for c in Congestion::ALL {
            assert_eq!(Congestion::parse(c.name()), Some(c));
        }
        assert_eq!(Congestion::parse("wait"), None);
        assert_eq!(Congestion::expected(), "block or drop");
    }

    #[test]
    fn a_qos_changes_only_what_it_sets() {
        let base = Qos {
            priority: Some(Priority::Data),
            congestion: Some(Congestion::Drop),
            express: Some(false),
        };
        let only_priority = Qos {
            priority: Some(Priority::DataHigh),
            ..Qos::default()
        };
        assert_eq!(
            only_priority.over(base),
            Qos {
                priority: Some(Priority::DataHigh),
                ..base
            }
        );
        assert_eq!(Qos::default().over(base), base);
        assert!(Qos::default().is_empty() && !only_priority.is_empty());
        assert_eq!(only_priority.to_string(), "priority=data-high");
        assert_eq!(
            base.to_string(),
            "priority=data congestion=drop express=false"
        );
    }
}
