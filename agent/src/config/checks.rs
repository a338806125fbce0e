//! The cell's transition-timer and SFC checks as configured.

use std::time::Duration;

use cellwatch_models::alarm::Severity;

/// A transition-timer check: a learned model whose signals are tags.
#[derive(Debug, Clone)]
pub struct TimerCheck {
    /// Alarm id prefix (`<id>-<nnn>`).
    pub id: String,
    /// The model, from `cellwatch learn`.
    pub model: cellwatch_models::timer::learn::TimerModel,
    /// Severity of its alarms.
    pub severity: Severity,
    /// Drift warnings before a transition times out (`drift`, `drift_*`):
    /// `None` when off.
    pub drift: Option<cellwatch_models::timer::drift::DriftRules>,
}

/// `[alarms.consequences]`: how the cell treats alarms that follow from
/// others ([`cellwatch_models::consequence`]).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Consequences {
    /// A consequence is not annunciated: journaled and shown as suppressed.
    pub suppress: bool,
    /// Edges added to the derived relation: `(key, cause, effect)`.
    pub add: Vec<(String, String, String)>,
    /// Edges removed from it: `(key, cause, effect)`.
    pub remove: Vec<(String, String, String)>,
}

/// Step supervision of sequential function charts (paper 004).
#[derive(Debug, Clone)]
pub struct SfcCheck {
    /// Alarm id prefix (`<id>-<chart>-<step>`).
    pub id: String,
    /// The charts, their signals the cell's tag addresses.
    pub sfc: cellwatch_models::sfc::Sfc,
    /// Severity of its stuck-step alarms.
    pub severity: Severity,
    /// The remote module's force switch (a boolean tag the agent may
    /// pulse, index into the tags), if the charts may be forced.
    pub force_switch: Option<usize>,
    /// The remote module's stop switch (index into the tags).
    pub stop_switch: Option<usize>,
    /// The transitions the PLC program lets the force switch fire
    /// (chart, transition).
    pub forcible: Vec<(String, String)>,
    /// How long the force (and stop) switch is held on.
    pub force_pulse: Duration,
    /// How long the steps a forced transition leads to may take to become
    /// active before the force is called failed (an alarm).
    pub force_timeout: Duration,
    /// The PLC program that drives outputs from the supervised steps'
    /// flags (`program`), with what it leaves observable: a fault that
    /// holds such an output (the clamp valve a hydraulic fault drops)
    /// explains the step stuck.
    pub program: Option<(
        cellwatch_models::program::Program,
        cellwatch_models::signal::Observability,
    )>,
}

/// How long the force switch is held on unless configured.
pub const DEFAULT_FORCE_PULSE: Duration = Duration::from_millis(500);

/// How long a forced transition may take unless configured.
pub const DEFAULT_FORCE_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a forced transition may take at most.
pub const MAX_FORCE_TIMEOUT: Duration = Duration::from_secs(60);
