//! The key layout of the bus, spelled once. Under a cell's prefix
//! ([`CellKeys`]; by default `cellwatch/<cell>`, see
//! [`crate::bus::config::cell_prefix`]):
//!
//! | key | what | who |
//! |---|---|---|
//! | `alarms/<alarm-id>` | alarm events (`cellwatch.alarm.v1`) | the agent puts |
//! | `state` | the machine state (`cellwatch.state.v1`) | the agent puts |
//! | `history` | journal pages | the agent answers |
//! | `snapshot` | values, active alarms, values at the last fault | the agent answers |
//! | `command` | signed operator commands | the agent answers |
//! | `about` | its version, configuration hash, keys | the agent answers |
//! | `operators` | the plant operators list it holds | the agent answers |
//!
//! Under the root, `_plant/operators` is the plant's own key: the signed
//! plant operators list, put by `cellwatch plant publish`
//! ([`plant_operators`]). No cell is named `_plant`.
//! | `agent/<zenoh id>` | a liveliness token while the agent runs | the agent declares |
//!
//! The agent uses the prefix its configuration gives (`zenoh.key_prefix`);
//! clients build it from a root and a cell ([`CellKeys::of`]).

use std::fmt::Display;

/// A query service an agent answers under its prefix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Service {
    /// `history`: pages of the journal.
    History,
    /// `snapshot`: the cell's values and alarms now.
    Snapshot,
    /// `command`: a signed operator command.
    Command,
    /// `about`: what the agent is and runs.
    About,
}

impl Service {
    /// The service's key under the prefix.
    pub fn name(self) -> &'static str {
        match self {
            Service::History => "history",
            Service::Snapshot => "snapshot",
            Service::Command => "command",
            Service::About => "about",
        }
    }
}

/// Every key of one cell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CellKeys {
    prefix: String,
}

impl CellKeys {
    /// The keys under an agent's configured prefix (`zenoh.key_prefix`).
    pub fn new(prefix: impl Into<String>) -> CellKeys {
        CellKeys {
            prefix: prefix.into(),
        }
    }

    /// The keys of `cell` under `root` (`<root>/<cell>`), as clients name
    /// a cell. `cell` may be `*` to mean every cell under the root.
    pub fn of(root: &str, cell: &str) -> CellKeys {
        CellKeys::new(crate::bus::config::cell_prefix(root, cell))
    }

    /// The prefix itself.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// `alarms/<id>`: one alarm's events.
    pub fn alarm(&self, id: &str) -> String {
        format!("{}/alarms/{id}", self.prefix)
    }

    /// `alarms/**`: every alarm's events, to subscribe to.
    pub fn alarms(&self) -> String {
        format!("{}/alarms/**", self.prefix)
    }

    /// `recordings/<id>`: one alarm's flight recordings.
    pub fn recording(&self, id: &str) -> String {
        format!("{}/recordings/{id}", self.prefix)
    }

    /// `recordings/**`: every alarm's flight recordings, to subscribe to.
    pub fn recordings(&self) -> String {
        format!("{}/recordings/**", self.prefix)
    }

    /// `state`: the machine state.
    pub fn state(&self) -> String {
        format!("{}/state", self.prefix)
    }

    /// A query service's key.
    pub fn service(&self, service: Service) -> String {
        format!("{}/{}", self.prefix, service.name())
    }

    /// `operators`: the plant operators list the agent holds, answered.
    pub fn operators(&self) -> String {
        format!("{}/operators", self.prefix)
    }

    /// `agent/<zenoh id>`: the running agent's liveliness token.
    pub fn agent_token(&self, zid: impl Display) -> String {
        format!("{}/agent/{zid}", self.prefix)
    }
}

/// `<root>/_plant/operators`: where the plant operators list is put.
pub(crate) fn plant_operators(root: &str) -> String {
    format!("{}/_plant/operators", root.trim_end_matches('/'))
}

/// `<root>/*/operators`: every agent's held plant operators list, to ask.
pub(crate) fn every_cells_operators(root: &str) -> String {
    format!("{}/*/operators", root.trim_end_matches('/'))
}

/// The root of an agent's prefix (`cellwatch` of `cellwatch/m01`).
pub(crate) fn root_of(prefix: &str) -> &str {
    prefix.rsplit_once('/').map_or("", |(root, _)| root)
}

/// The cell a key under `root` belongs to (`<root>/<cell>/…`), if it is
/// under `root` and names one.
pub(crate) fn cell_of<'k>(root: &str, key: &'k str) -> Option<&'k str> {
    let rest = key
        .strip_prefix(root.trim_end_matches('/'))?
        .strip_prefix('/')?;
    let cell = rest.split('/').next()?;
    (!cell.is_empty() && rest.len() > cell.len()).then_some(cell)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cell_of_a_key() {
        assert_eq!(cell_of("cellwatch", "cellwatch/m01/agent/ab"), Some("m01"));
        assert_eq!(cell_of("plant/a", "plant/a/m01/state"), Some("m01"));
        assert_eq!(cell_of("cellwatch", "cellwatchx/m01/state"), None);
        assert_eq!(cell_of("cellwatch", "cellwatch/m01"), None);
    }

    #[test]
    fn the_layout_under_a_prefix() {
        let k = CellKeys::of("cellwatch", "m01");
        assert_eq!(k.prefix(), "cellwatch/m01");
        assert_eq!(k.alarm("ese"), "cellwatch/m01/alarms/ese");
        assert_eq!(k.alarms(), "cellwatch/m01/alarms/**");
        assert_eq!(k.state(), "cellwatch/m01/state");
        assert_eq!(k.service(Service::History), "cellwatch/m01/history");
        assert_eq!(k.service(Service::Snapshot), "cellwatch/m01/snapshot");
        assert_eq!(k.service(Service::Command), "cellwatch/m01/command");
        assert_eq!(k.agent_token("ab12"), "cellwatch/m01/agent/ab12");
        assert_eq!(CellKeys::new("plant/a/m02").state(), "plant/a/m02/state");
    }
}
