//! The scheme registry: which URL schemes open which media.
//!
//! Every medium family is a crate of its own that exports `register(&mut Schemes)`, adding its
//! schemes, each with the check of its URL (which also says what a medium opened from it can do)
//! and its opener. The program builds one [`Schemes`] from the families compiled into it and
//! names the families it left out ([`Schemes::left_out`]), so that a URL of one of those gets
//! "medium `can` is not compiled into this seabus (feature `can`)" rather than "unknown scheme".
//!
//! ```
//! use seabus_medium::{Capabilities, Node, Schemes};
//! let mut schemes = Schemes::new(); // knows `inproc://`
//! schemes.left_out("can", "can", &["slcan", "cannelloni"]);
//! assert_eq!(schemes.check("inproc://").unwrap(), Capabilities::IN_PROCESS);
//! let e = schemes.check("slcan:///dev/ttyACM0").unwrap_err();
//! assert!(e.to_string().contains("medium `can` is not compiled into this seabus (feature `can`)"));
//! ```

use crate::caps::Capabilities;
use crate::fault::FaultConfig;
use crate::medium::{Builder, Medium, Node, OpenError, Opening, Transport, Wire};
use crate::url::{MediumUrl, UrlError};
use std::sync::Arc;

/// A transport a scheme opened, its frame type hidden.
pub struct Opened(pub(crate) Option<Arc<dyn Wire>>);

impl Opened {
    /// A medium without a wire (in-process).
    pub fn none() -> Opened {
        Opened(None)
    }
}

impl<T: Transport> From<Arc<T>> for Opened {
    fn from(t: Arc<T>) -> Opened {
        Opened(Some(t as Arc<dyn Wire>))
    }
}

/// Checks a URL of a scheme: takes and checks every option, opens nothing, and says what a medium
/// opened from it can do.
pub type CheckUrl = fn(&mut MediumUrl) -> Result<Capabilities, UrlError>;

/// Takes and checks every option of the URL as the check does, and opens the transport.
pub type OpenTransport = fn(Opening) -> Result<Opened, OpenError>;

/// One URL scheme.
#[derive(Clone, Copy)]
pub struct Scheme {
    /// The scheme (`udp`, `slcan+pty`).
    pub name: &'static str,
    /// The medium family it belongs to (`udp`, `can`): its crate and its cargo feature.
    pub family: &'static str,
    /// One line on what it opens, for `seabus schemes`.
    pub summary: &'static str,
    /// Its URL check.
    pub check: CheckUrl,
    /// Its opener.
    pub open: OpenTransport,
}

#[derive(Clone)]
struct LeftOut {
    family: &'static str,
    feature: &'static str,
    schemes: &'static [&'static str],
}

/// The schemes a program knows, and the families left out of it.
#[derive(Clone)]
pub struct Schemes {
    schemes: Vec<Scheme>,
    left_out: Vec<LeftOut>,
}

impl Default for Schemes {
    fn default() -> Self {
        Schemes::new()
    }
}

/// The in-process medium: the default bus.
const INPROC: Scheme = Scheme {
    name: "inproc",
    family: "inproc",
    summary: "the in-process bus: messages shared between modules, never copied",
    check: |url| {
        url.finish(&[])?;
        Ok(Capabilities::IN_PROCESS)
    },
    open: |o| {
        o.url.finish(&[])?;
        Ok(Opened::none())
    },
};

impl Schemes {
    /// A registry that knows the in-process medium only.
    pub fn new() -> Schemes {
        Schemes {
            schemes: vec![INPROC],
            left_out: Vec::new(),
        }
    }

    /// A registry with the in-process medium and the families `register` functions add: for a
    /// program or a test that uses a few media.
    pub fn with(register: &[fn(&mut Schemes)]) -> Schemes {
        let mut s = Schemes::new();
        for r in register {
            r(&mut s);
        }
        s
    }

    /// Adds a scheme (replacing one of the same name).
    pub fn add(&mut self, scheme: Scheme) -> &mut Self {
        self.schemes.retain(|s| s.name != scheme.name);
        self.schemes.push(scheme);
        self
    }

    /// Notes a medium family left out of this build, with its cargo feature and its schemes.
    pub fn left_out(
        &mut self,
        family: &'static str,
        feature: &'static str,
        schemes: &'static [&'static str],
    ) -> &mut Self {
        self.left_out.push(LeftOut {
            family,
            feature,
            schemes,
        });
        self
    }

    /// The schemes known, in the order they were added.
    pub fn names(&self) -> Vec<&'static str> {
        self.schemes.iter().map(|s| s.name).collect()
    }

    /// Every scheme known.
    pub fn iter(&self) -> impl Iterator<Item = &Scheme> {
        self.schemes.iter()
    }

    /// The families compiled in, each with its schemes, in the order they were added.
    pub fn families(&self) -> Vec<(&'static str, Vec<&'static str>)> {
        let mut out: Vec<(&'static str, Vec<&'static str>)> = Vec::new();
        for s in &self.schemes {
            match out.iter_mut().find(|(f, _)| *f == s.family) {
                Some((_, names)) => names.push(s.name),
                None => out.push((s.family, vec![s.name])),
            }
        }
        out
    }

    /// The families left out of this build, with their features.
    pub fn families_left_out(&self) -> Vec<(&'static str, &'static str)> {
        self.left_out
            .iter()
            .map(|l| (l.family, l.feature))
            .collect()
    }

    /// Checks a medium URL without opening anything (scheme, options and their values, the fault
    /// stage's options) and says what a medium opened from it could do.
    pub fn check(&self, url: &str) -> Result<Capabilities, OpenError> {
        let (scheme, mut parsed, _) = self.parse(url)?;
        Ok((scheme.check)(&mut parsed)?)
    }

    /// Opens the medium a URL names, as `name` of `node`. `fault.*` options add the fault stage to
    /// any medium. Must be called inside a tokio runtime.
    pub fn open(&self, name: &str, url: &str, node: &Node) -> Result<Medium, OpenError> {
        let (scheme, parsed, common) = self.parse(url)?;
        Builder {
            name: Arc::from(name),
            url: url.to_string(),
            node: node.clone(),
            faults: common.faults,
            quiet_rejects: common.quiet_rejects,
        }
        .build(|ingress| {
            (scheme.open)(Opening {
                name: Arc::from(name),
                node: node.clone(),
                url: parsed,
                ingress,
            })
            .map(|o| o.0)
        })
    }

    /// The scheme of `url`, the URL with the options every medium takes removed, and those
    /// options: the fault stage (`fault.*`) and how rejected input is logged (`rejects`).
    fn parse(&self, url: &str) -> Result<(&Scheme, MediumUrl, Common), OpenError> {
        let mut parsed = MediumUrl::parse(url)?;
        let faults = FaultConfig::from_url(&mut parsed)?;
        let quiet_rejects = match parsed.take("rejects").as_deref() {
            None | Some("warn") => false,
            Some("debug") => true,
            Some(other) => {
                return Err(parsed
                    .error(format!(
                        "option `rejects={other}`: expected `warn` (the default) or `debug` (for a \
                         line known to carry noise, such as a simulator injecting faults)"
                    ))
                    .into());
            }
        };
        let common = Common {
            faults,
            quiet_rejects,
        };
        if let Some(scheme) = self.schemes.iter().find(|s| s.name == parsed.scheme) {
            return Ok((scheme, parsed, common));
        }
        if let Some(l) = self
            .left_out
            .iter()
            .find(|l| l.schemes.contains(&parsed.scheme.as_str()))
        {
            return Err(OpenError::NotCompiled {
                family: l.family.to_string(),
                feature: l.feature.to_string(),
                url: url.to_string(),
            });
        }
        Err(OpenError::UnknownScheme {
            scheme: parsed.scheme.clone(),
            url: url.to_string(),
            known: self.names().join(", "),
        })
    }
}

/// The options every medium's URL takes, whatever its scheme.
struct Common {
    faults: Option<FaultConfig>,
    quiet_rejects: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn register_loop(s: &mut Schemes) {
        s.add(Scheme {
            name: "loop",
            family: "test",
            summary: "a test scheme",
            check: |url| {
                url.finish(&[])?;
                Ok(Capabilities {
                    provenance: false,
                    ..Capabilities::IN_PROCESS
                })
            },
            open: |o| {
                o.url.finish(&[])?;
                Ok(Opened::none())
            },
        });
    }

    #[test]
    fn registered_schemes_check_and_the_rest_say_why_not() {
        let mut s = Schemes::with(&[register_loop]);
        s.left_out("can", "can", &["slcan", "socketcan"]);
        assert_eq!(s.names(), vec!["inproc", "loop"]);
        assert_eq!(
            s.families(),
            vec![("inproc", vec!["inproc"]), ("test", vec!["loop"])]
        );
        assert!(!s.check("loop://").unwrap().provenance);
        assert!(
            s.check("loop://?x=1")
                .unwrap_err()
                .to_string()
                .contains("x")
        );
        assert_eq!(
            s.check("socketcan://can0").unwrap_err().to_string(),
            "medium `can` is not compiled into this seabus (feature `can`): `socketcan://can0`"
        );
        let e = s.check("nosuch://x").unwrap_err().to_string();
        assert!(
            e.contains("unknown medium scheme `nosuch://`") && e.contains("inproc, loop"),
            "{e}"
        );
        assert!(
            s.check("inproc://?fault.loss=2").is_err(),
            "fault options are checked too"
        );
    }

    #[tokio::test]
    async fn an_opened_medium_reports_its_scheme_capabilities() {
        let s = Schemes::with(&[register_loop]);
        let m = s.open("bus", "inproc://", &Node::new("n")).unwrap();
        assert_eq!(m.capabilities(), Capabilities::IN_PROCESS);
        assert_eq!(m.url(), "inproc://");
    }

    #[tokio::test]
    async fn every_medium_takes_rejects_and_refuses_a_level_it_does_not_know() {
        let mut s = Schemes::new();
        register_loop(&mut s);
        assert!(s.check("loop://x?rejects=debug").is_ok());
        assert!(s.check("loop://x?rejects=warn").is_ok());
        let wrong = s.check("loop://x?rejects=loud").unwrap_err().to_string();
        assert!(
            wrong.contains("option `rejects=loud`: expected `warn` (the default) or `debug`"),
            "{wrong}"
        );
        let node = crate::Node::new("n");
        assert!(s.open("m", "loop://x?rejects=debug", &node).is_ok());
    }
}
