//! The designer's saves: a layout edited on the page replaces its file when it reads, when the
//! user may see it, and (for changes to its commands or roles) when they may take control. The
//! file it replaces is kept as `.bak`.

use super::{Hub, error_json};
use crate::auth::Session;
use crate::layout::Layout;
use seabus_medium::xml::FileError;
use serde_json::{Value as Json, json};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Why a layout is not saved; the text is what the page shows.
#[derive(Debug, thiserror::Error)]
pub enum SaveError {
    /// The user lacks the designer role.
    #[error("saving layouts needs role {0}")]
    RoleNeeded(String),
    /// No layout of that name the user may see.
    #[error("no layout `{0}` for you")]
    NoLayout(String),
    /// The layout does not read (`FILE:LINE:COL: message`).
    #[error("{0}")]
    Layout(FileError),
    /// A change to commands or roles by a user without the lease role.
    #[error("changing a layout's commands or roles needs role {0}")]
    RulesNeedRole(String),
    /// The layout saved under another layout's name.
    #[error("the layout is called `{found}`, not `{name}`")]
    Renamed {
        /// The name in the text saved.
        found: String,
        /// The layout being saved.
        name: String,
    },
    /// The file could not be written.
    #[error("{file}: {error}")]
    Io {
        /// The layout file.
        file: String,
        /// What went wrong.
        #[source]
        error: std::io::Error,
    },
}

impl SaveError {
    /// The error for the page: a layout that does not read with its place ([`error_json`]),
    /// anything else as `{message}`.
    pub fn json(&self) -> Json {
        match self {
            SaveError::Layout(e) => error_json(e),
            other => json!({"message": other.to_string()}),
        }
    }
}

impl Hub {
    /// Saves a layout edited in the designer: it must read; the old file is kept as `.bak`.
    pub fn save(&self, session: &Session, name: &str, xml: &str) -> Result<(), SaveError> {
        if !session.has(&self.settings.designer_role) {
            return Err(SaveError::RoleNeeded(self.settings.designer_role.clone()));
        }
        let (path, old) = self
            .settings
            .layouts
            .iter()
            .find_map(|p| {
                self.load(p, &BTreeMap::new())
                    .ok()
                    .filter(|l| l.name == name && l.visible_to(&session.roles))
                    .map(|l| (p, l))
            })
            .ok_or_else(|| SaveError::NoLayout(name.to_string()))?;
        let file = path.display().to_string();
        let layout = Layout::parse(&file, xml, &BTreeMap::new()).map_err(SaveError::Layout)?;
        // what may be sent and by whom is for those who may take control, not for designers alone
        let rules_changed = old.to_json()["commands"] != layout.to_json()["commands"]
            || old.roles != layout.roles
            || old.vehicle != layout.vehicle;
        if rules_changed && !session.has(&self.settings.lease_role) {
            return Err(SaveError::RulesNeedRole(self.settings.lease_role.clone()));
        }
        if layout.name != name {
            return Err(SaveError::Renamed {
                found: layout.name,
                name: name.to_string(),
            });
        }
        let io = |error| SaveError::Io {
            file: file.clone(),
            error,
        };
        std::fs::copy(path, PathBuf::from(format!("{file}.bak"))).map_err(io)?;
        seabus_medium::fs::atomic_write(path, xml.as_bytes()).map_err(io)?;
        tracing::info!(component = "console", user = %session.user, "saved layout {name} to {file}");
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::{Fixture, PILOT};
    use super::*;

    #[test]
    fn saving_needs_the_designer_role_and_a_layout_the_user_sees() {
        let f = Fixture::new();
        let refused = f.hub.save(&f.session("bo"), "pilot", PILOT).unwrap_err();
        assert_eq!(refused.to_string(), "saving layouts needs role designer");
        assert_eq!(
            refused.json(),
            json!({"message": "saving layouts needs role designer"})
        );
        let refused = f.hub.save(&f.session("ana"), "nope", PILOT).unwrap_err();
        assert_eq!(refused.to_string(), "no layout `nope` for you");
    }

    #[test]
    fn a_layout_that_does_not_read_is_refused_with_its_place() {
        let f = Fixture::new();
        let bad = "<layout name=\"pilot\">\n  <dial/>\n</layout>";
        let refused = f.hub.save(&f.session("ana"), "pilot", bad).unwrap_err();
        let file = f.dir.join("pilot.xml").display().to_string();
        let message = "unexpected element <dial> inside <layout>; expected <var>, <command>, <template>, <use>, <keys>, <gamepad>, <row>, <column>, <tabs>, <grid>, <readout>, <gauge>, <plot>, <track>, <fleet>, <health>, <log>, <history>, <button>, <slider>, <number>, <text>, <toggle>";
        let text = format!("{file}:2:3: {message}");
        assert_eq!(refused.to_string(), text);
        assert_eq!(
            refused.json(),
            json!({"file": file, "line": 2, "col": 3, "message": message, "text": text})
        );
        let kept = std::fs::read_to_string(f.dir.join("pilot.xml")).unwrap();
        assert_eq!(kept, PILOT);
    }

    #[test]
    fn a_designer_without_control_rights_changes_looks_but_not_commands() {
        let f = Fixture::new();
        let dee = f.session("dee");
        let faster = PILOT.replace("max.speed=\"3\"", "max.speed=\"9\"");
        let refused = f.hub.save(&dee, "pilot", &faster).unwrap_err();
        assert_eq!(
            refused.to_string(),
            "changing a layout's commands or roles needs role pilot"
        );
        let relabelled = PILOT.replace(
            "<button command=\"stop\"/>",
            "<button command=\"stop\" label=\"Stop!\"/>",
        );
        f.hub.save(&dee, "pilot", &relabelled).unwrap();
        let path = f.dir.join("pilot.xml");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), relabelled);
        let bak = f.dir.join("pilot.xml.bak");
        assert_eq!(std::fs::read_to_string(bak).unwrap(), PILOT);
    }

    #[test]
    fn a_layout_is_saved_under_its_own_name() {
        let f = Fixture::new();
        let renamed = PILOT.replace("name=\"pilot\"", "name=\"other\"");
        let refused = f
            .hub
            .save(&f.session("ana"), "pilot", &renamed)
            .unwrap_err();
        assert_eq!(
            refused.to_string(),
            "the layout is called `other`, not `pilot`"
        );
    }
}
