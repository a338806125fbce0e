//! Machine state (paper 000's remote service): running, idle, fault,
//! offline, and the kind of each history row.

use crate::alarm::Severity;
use crate::expr::Expr;

/// The state of the machine, as paper 000's remote service reports it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "state", rename_all = "lowercase")]
pub enum MachineState {
    /// Producing: the running rule holds.
    Running,
    /// Connected, no fault, not running.
    Idle,
    /// A fault alarm is active.
    Fault {
        /// Its fault type (`ESE`).
        fault_type: String,
        /// The faulty element, if known (`X0.06`).
        element: Option<String>,
    },
    /// No connection to the PLC.
    Offline,
}

impl MachineState {
    /// The state's name: `running`, `idle`, `fault`, `offline`.
    pub fn name(&self) -> &'static str {
        match self {
            MachineState::Running => "running",
            MachineState::Idle => "idle",
            MachineState::Fault { .. } => "fault",
            MachineState::Offline => "offline",
        }
    }

    /// The state's name as an enum.
    pub fn state_name(&self) -> StateName {
        match self {
            MachineState::Running => StateName::Running,
            MachineState::Idle => StateName::Idle,
            MachineState::Fault { .. } => StateName::Fault,
            MachineState::Offline => StateName::Offline,
        }
    }

    /// All state names.
    pub const NAMES: [&'static str; 4] = ["running", "idle", "fault", "offline"];
}

/// The name of a machine state, as payloads carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StateName {
    /// Producing.
    Running,
    /// Connected, no fault, not running.
    Idle,
    /// A fault alarm is active.
    Fault,
    /// No connection to the PLC.
    Offline,
}

impl StateName {
    /// The lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            StateName::Running => "running",
            StateName::Idle => "idle",
            StateName::Fault => "fault",
            StateName::Offline => "offline",
        }
    }
}

impl std::fmt::Display for StateName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The kind of a machine-state history row (paper 000, Fig. 13).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HistoryKind {
    /// Running or idle, coming from running or idle.
    Normal,
    /// A fault, with its type and element.
    Fault,
    /// Back to running or idle after a fault or an outage.
    Recovery,
    /// The connection to the PLC is lost.
    Offline,
}

impl HistoryKind {
    /// The kind of the history row for a change from `from` to `to`.
    pub fn between(from: &MachineState, to: &MachineState) -> HistoryKind {
        match (from, to) {
            (_, MachineState::Offline) => HistoryKind::Offline,
            (_, MachineState::Fault { .. }) => HistoryKind::Fault,
            (MachineState::Fault { .. } | MachineState::Offline, _) => HistoryKind::Recovery,
            _ => HistoryKind::Normal,
        }
    }

    /// The lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            HistoryKind::Normal => "normal",
            HistoryKind::Fault => "fault",
            HistoryKind::Recovery => "recovery",
            HistoryKind::Offline => "offline",
        }
    }
}

/// How the machine state is derived.
#[derive(Debug, Clone)]
pub struct StateRules {
    /// The machine is running when this holds (over tag addresses); idle
    /// otherwise. `None`: never running, only idle or fault.
    pub running: Option<Expr>,
    /// Alarms at or above this severity put the machine in `fault`.
    pub fault_severity: Severity,
    /// Machine modes and the alarms each suppresses by design.
    pub modes: Vec<super::modes::Mode>,
}

impl Default for StateRules {
    fn default() -> Self {
        StateRules {
            running: None,
            fault_severity: Severity::High,
            modes: Vec::new(),
        }
    }
}
