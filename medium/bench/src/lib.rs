//! seabus-bench: what seabus's benchmark programs share — the goals their figures are held to.
//!
//! Each benchmark measures seabus and its reference side by side in one run and reports every
//! ratio through a [`Goals`]: [`Goals::at_least`] for a rate (seabus / reference, higher is
//! better), [`Goals::at_most`] for a cost (seabus / reference, lower is better). Each prints one
//! line, `goal NAME: RATIO (target: at least GOAL)`.
//!
//! A goal a path does not reach yet is an **aim** ([`Goals::aim_at_least`],
//! [`Goals::aim_at_most`], with the reason it is not reached): printed the same way, marked, and
//! not checked by the smoke run until the work that reaches it turns it into a goal.
//!
//! A full run (`cargo bench`) is for the figures in `BENCHMARKS.md`: it never fails on a missed
//! goal. The **smoke run** (`SEABUS_BENCH_SMOKE=1`, what `scripts/test` runs) is short
//! ([`scale`] picks its smaller sizes) and fails when a ratio is worse than half its goal (a rate
//! below half, a cost above twice) or a program reported a failure of its own ([`Goals::fail`]).
//! A program that fails so is run once more, whole, and fails the tests only when it fails
//! again: a change that halves a path's speed fails twice, while a moment of a shared machine's
//! noise (another process taking a core for part of a short round) passes the second time.
//!
//! Who may depend on it: the benchmark programs of every crate (as a dev-dependency), nothing else.

use std::fmt::Write as _;

/// Set in the environment of the smoke run's second attempt of a program.
const AGAIN: &str = "SEABUS_BENCH_SMOKE_AGAIN";

/// True in the smoke run (`SEABUS_BENCH_SMOKE` set to anything but `0`).
pub fn smoke() -> bool {
    std::env::var_os("SEABUS_BENCH_SMOKE").is_some_and(|v| v != "0")
}

/// `full` in a full run, `short` in the smoke run.
pub fn scale<T>(full: T, short: T) -> T {
    if smoke() { short } else { full }
}

/// Which way a ratio is good.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Way {
    AtLeast,
    AtMost,
}

/// One ratio and its goal.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// What was measured.
    pub name: String,
    /// seabus / the reference.
    pub ratio: f64,
    /// The goal it is held to.
    pub goal: f64,
    way: Way,
    /// Why it is only aimed at, not yet checked.
    pub aim: Option<String>,
}

impl Outcome {
    /// True when the ratio meets its goal.
    pub fn met(&self) -> bool {
        match self.way {
            Way::AtLeast => self.ratio >= self.goal,
            Way::AtMost => self.ratio <= self.goal,
        }
    }

    /// True when the ratio is worse than half its goal: a rate below half of it, a cost above
    /// twice it (or no figure at all). An aim never collapses.
    pub fn collapsed(&self) -> bool {
        if self.aim.is_some() {
            return false;
        }
        !self.ratio.is_finite()
            || match self.way {
                Way::AtLeast => self.ratio < self.goal / 2.0,
                Way::AtMost => self.ratio > self.goal * 2.0,
            }
    }
}

/// The goals of one benchmark program: reports each ratio, and in the smoke run fails the program
/// at [`Goals::finish`] when one collapsed.
#[derive(Debug, Default)]
pub struct Goals {
    outcomes: Vec<Outcome>,
    failures: Vec<String>,
}

impl Goals {
    /// No ratio yet.
    pub fn new() -> Goals {
        Goals::default()
    }

    /// A rate-like ratio (seabus / reference) that should be at least `goal`.
    pub fn at_least(&mut self, name: &str, ratio: f64, goal: f64) -> &Outcome {
        self.add(name, ratio, goal, Way::AtLeast)
    }

    /// A cost-like ratio (seabus / reference) that should be at most `goal`.
    pub fn at_most(&mut self, name: &str, ratio: f64, goal: f64) -> &Outcome {
        self.add(name, ratio, goal, Way::AtMost)
    }

    /// A rate-like ratio aimed at `goal` but not reached yet, for the reason `why`: reported,
    /// never failing the smoke run.
    pub fn aim_at_least(&mut self, name: &str, ratio: f64, goal: f64, why: &str) -> &Outcome {
        self.add_aim(name, ratio, goal, Way::AtLeast, why)
    }

    /// A cost-like ratio aimed at `goal` but not reached yet, for the reason `why`.
    pub fn aim_at_most(&mut self, name: &str, ratio: f64, goal: f64, why: &str) -> &Outcome {
        self.add_aim(name, ratio, goal, Way::AtMost, why)
    }

    fn add(&mut self, name: &str, ratio: f64, goal: f64, way: Way) -> &Outcome {
        self.push(Outcome {
            name: name.to_string(),
            ratio,
            goal,
            way,
            aim: None,
        })
    }

    fn add_aim(&mut self, name: &str, ratio: f64, goal: f64, way: Way, why: &str) -> &Outcome {
        self.push(Outcome {
            name: name.to_string(),
            ratio,
            goal,
            way,
            aim: Some(why.to_string()),
        })
    }

    fn push(&mut self, o: Outcome) -> &Outcome {
        println!("{}", line(&o));
        self.outcomes.push(o);
        self.outcomes.last().expect("just pushed")
    }

    /// The ratios reported so far.
    pub fn outcomes(&self) -> &[Outcome] {
        &self.outcomes
    }

    /// A failure the program found besides its ratios (a message lost where none may be): it
    /// fails the smoke run as a collapsed ratio does.
    pub fn fail(&mut self, what: String) {
        eprintln!("{what}");
        self.failures.push(what);
    }

    /// A run where nothing may be lost: `got` of `sent` arrived. A loss is a failure
    /// ([`Goals::fail`]) named by `what`; true when nothing was lost.
    pub fn none_lost(&mut self, what: &str, sent: usize, got: usize) -> bool {
        if got >= sent {
            return true;
        }
        self.fail(format!("{what}: {} of {sent} lost", sent - got));
        false
    }

    /// What fails the smoke run: every collapsed ratio and every failure, one line each.
    fn failed(&self) -> Vec<String> {
        let collapsed = self.outcomes.iter().filter(|o| o.collapsed()).map(line);
        collapsed.chain(self.failures.iter().cloned()).collect()
    }

    /// Ends the program's report. In the smoke run, when something failed, it names it and runs
    /// the program once more; the program exits with that run's status (1 when it failed again).
    pub fn finish(self) {
        let failed = self.failed();
        if !smoke() || failed.is_empty() {
            return;
        }
        let mut said = String::from("smoke run: ratios worse than half their goal, or failures:");
        for f in &failed {
            let _ = write!(said, "\n  {f}");
        }
        eprintln!("{said}");
        if std::env::var_os(AGAIN).is_some() {
            eprintln!("smoke run: failed twice in a row");
            std::process::exit(1);
        }
        eprintln!("smoke run: measuring the whole program again, once");
        let status = std::env::current_exe().and_then(|exe| {
            std::process::Command::new(exe)
                .args(std::env::args_os().skip(1))
                .env(AGAIN, "1")
                .status()
        });
        match status {
            Ok(s) => std::process::exit(s.code().unwrap_or(1)),
            Err(e) => {
                eprintln!("smoke run: could not run the program again: {e}");
                std::process::exit(1);
            }
        }
    }
}

fn line(o: &Outcome) -> String {
    let way = match o.way {
        Way::AtLeast => "at least",
        Way::AtMost => "at most",
    };
    let mark = match (&o.aim, o.met()) {
        (_, true) => String::new(),
        (None, false) => "   (missed)".to_string(),
        (Some(why), false) => format!("   (missed; an aim, not checked yet: {why})"),
    };
    format!(
        "goal {}: {:.2} (target: {way} {}){mark}",
        o.name, o.ratio, o.goal
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ratio_collapses_when_worse_than_half_its_goal() {
        let mut g = Goals::new();
        assert!(!g.at_least("rate", 0.45, 0.8).collapsed());
        assert!(g.at_least("rate", 0.39, 0.8).collapsed());
        assert!(!g.at_least("rate", 0.39, 0.8).met());
        assert!(g.at_least("rate", 0.9, 0.8).met());
        assert!(!g.at_most("cost", 2.3, 1.2).collapsed());
        assert!(g.at_most("cost", 2.5, 1.2).collapsed());
        assert!(g.at_most("cost", f64::NAN, 1.2).collapsed());
        assert_eq!(
            line(&g.outcomes()[0]),
            "goal rate: 0.45 (target: at least 0.8)   (missed)"
        );
        let aim = g.aim_at_least("parse", 0.2, 0.8, "the crate's typed decode");
        assert!(!aim.collapsed() && !aim.met());
        assert_eq!(
            line(aim),
            "goal parse: 0.20 (target: at least 0.8)   (missed; an aim, not checked yet: the crate's typed decode)"
        );
        assert_eq!(g.outcomes().len(), 8);
    }

    #[test]
    fn what_fails_the_smoke_run_is_every_collapsed_ratio_and_every_failure() {
        let mut g = Goals::new();
        g.at_least("rate", 0.9, 0.8);
        g.aim_at_least("aimed", 0.1, 0.8, "not reached yet");
        assert!(g.failed().is_empty());
        g.at_most("cost", 3.0, 1.2);
        g.fail("run 2: 3 of 100 lost".to_string());
        assert_eq!(
            g.failed(),
            [
                "goal cost: 3.00 (target: at most 1.2)   (missed)",
                "run 2: 3 of 100 lost"
            ]
        );
    }

    #[test]
    fn a_loss_is_a_failure_named_with_how_many_of_how_many() {
        let mut g = Goals::new();
        assert!(g.none_lost("paced run", 100, 100));
        assert!(g.failed().is_empty());
        assert!(!g.none_lost("paced run", 100, 97));
        assert_eq!(g.failed(), ["paced run: 3 of 100 lost"]);
    }
}
