//! What a restarted agent takes back from its journal: the alarms not back
//! to normal (with their `raised_at`, acknowledgement and culprits), the
//! machine state, and the nonces of recent verified commands.

use std::path::Path;

use cellwatch_models::alarm::Alarm;
use cellwatch_models::engine::{HistoryKind, MachineState};

use crate::config::CellConfig;
use crate::journal::{self, JournalError, SavedState};
use crate::operator::Gate;
use crate::payload::AlarmPayload;

/// What the journal kept for this start.
#[derive(Debug, Default)]
pub(crate) struct Restored {
    /// Alarms not back to normal, oldest change first.
    pub alarms: Vec<Alarm>,
    /// The machine state, when it was entered and by which change.
    pub state: Option<(MachineState, u64, HistoryKind)>,
    /// Nonces of verified commands recent enough to be replayed, with
    /// their times.
    pub nonces: Vec<(u64, String)>,
    /// Those commands' outcomes, for a client that sends one again.
    pub outcomes: Vec<journal::SavedOutcome>,
}

/// Reads what `config`'s journal kept, at `now`. Alarms that `can_raise`
/// refuses (of checks no longer configured) are left out, with a warning.
///
/// # Errors
/// The journal cannot be read.
pub(crate) fn load(
    config: &CellConfig,
    now: u64,
    can_raise: impl Fn(&str) -> bool,
) -> Result<Restored, JournalError> {
    let path: &Path = &config.journal.path;
    let err = |source| JournalError::Sqlite {
        path: path.to_path_buf(),
        source,
    };
    let conn = journal::open_read(path)?;
    let saved = journal::saved(&conn, now.saturating_sub(Gate::NONCE_WINDOW_MS)).map_err(err)?;
    let mut alarms = Vec::new();
    for json in &saved.alarms {
        let alarm = serde_json::from_str::<AlarmPayload>(json)
            .ok()
            .and_then(|p| p.to_alarm());
        match alarm {
            Some(a) if can_raise(&a.id) => alarms.push(a),
            Some(a) => tracing::warn!(
                alarm = %a.id,
                "the journal holds an open alarm of a check no longer configured; not restored"
            ),
            None => tracing::warn!(
                path = %path.display(),
                "an open alarm in the journal does not read as an alarm payload; not restored"
            ),
        }
    }
    Ok(Restored {
        alarms,
        state: saved.state.and_then(machine_state),
        nonces: saved.nonces,
        outcomes: saved.outcomes,
    })
}

fn machine_state(row: SavedState) -> Option<(MachineState, u64, HistoryKind)> {
    let state = match row.state.as_str() {
        "running" => MachineState::Running,
        "idle" => MachineState::Idle,
        "offline" => MachineState::Offline,
        "fault" => MachineState::Fault {
            fault_type: row.fault_type?,
            element: row.element,
        },
        _ => return None,
    };
    let kind = serde_json::from_value(serde_json::Value::String(row.kind)).ok()?;
    Some((state, row.at, kind))
}
