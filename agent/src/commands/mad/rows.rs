//! The rows of a cell's master alarm database as `cellwatch mad` writes
//! them: the engine's alarms described, the agent's own and the PLC's
//! patterns, and the database's rationalisation merged in with each row's
//! status.

use cellwatch_models::alarm::{AlarmKind, Severity};
use cellwatch_models::engine::CatalogueEntry;
use serde::Serialize;

use crate::config::CellConfig;

/// One alarm of the master alarm database: a row of the CSV, an object of
/// the JSON. Lists are written `a; b` so that a row stays one cell each.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
pub(crate) struct MadRow {
    /// The alarm id.
    pub(crate) id: String,
    /// What raises it (`switching`, `limit`, `timer`, `step`, …).
    pub(crate) kind: String,
    /// `low`, `medium`, `high`, `critical`.
    pub(crate) priority: String,
    /// `fault` (puts the machine in fault: its state history and
    /// availability), `warning` or `system` (the link, the tags' quality,
    /// the agent itself).
    pub(crate) class: String,
    /// The condition in words.
    pub(crate) condition: String,
    /// The signals its check reads, each with its comment.
    pub(crate) culprits: String,
    /// The alarms it may follow from.
    pub(crate) causes: String,
    /// The alarms that may follow from it.
    pub(crate) effects: String,
    /// The machine modes that suppress it by design.
    pub(crate) suppressed_in_modes: String,
    /// How long its condition must hold to raise.
    pub(crate) on_delay: String,
    /// How long it must be gone to clear.
    pub(crate) off_delay: String,
    /// `yes`: stays active until an operator resets it.
    pub(crate) latched: String,
    /// The fault type in the machine-state history.
    pub(crate) fault_type: String,
    /// Rationalisation: what happens if nobody acts.
    pub(crate) consequence_of_inaction: String,
    /// Rationalisation: what the operator does.
    pub(crate) corrective_action: String,
    /// Rationalisation: how long the operator has (`5m`).
    pub(crate) response_time: String,
    /// Against the cell's database (`alarms.database`): `new` (no row
    /// yet), `changed` (its condition is not the one rationalised), `gone`
    /// (a row for an alarm the cell no longer raises); empty otherwise.
    pub(crate) status: String,
}

/// The database's rows: the engine's alarms, then the agent's own and the
/// PLC's, by id.
pub(crate) fn rows(c: &CellConfig, catalogue: &[CatalogueEntry]) -> Vec<MadRow> {
    let fault_severity = c.state.fault_severity;
    let mut rows: Vec<MadRow> = catalogue
        .iter()
        .map(|e| {
            let fault = matches!(
                e.kind,
                AlarmKind::Switching | AlarmKind::Timer | AlarmKind::Step
            ) && e.severity >= fault_severity;
            MadRow {
                id: e.id.clone(),
                kind: e.kind.as_str().into(),
                priority: e.severity.as_str().into(),
                class: class(e.kind, fault).into(),
                condition: e.condition.clone().unwrap_or_default(),
                culprits: e
                    .culprits
                    .iter()
                    .map(|(s, comment)| match comment {
                        Some(comment) => format!("{s} ({comment})"),
                        None => s.to_string(),
                    })
                    .collect::<Vec<_>>()
                    .join("; "),
                causes: e.causes.join("; "),
                effects: e.effects.join("; "),
                suppressed_in_modes: e.suppressed_in.join("; "),
                on_delay: duration(e.delays_ms.0),
                off_delay: duration(e.delays_ms.1),
                latched: if e.latched { "yes" } else { "no" }.into(),
                fault_type: e.fault_type.clone(),
                ..MadRow::default()
            }
        })
        .collect();
    rows.extend(own_alarms(c));
    rows.sort_by(|a, b| a.id.cmp(&b.id));
    rows
}

/// The database's rationalisation in `rows`, and each row's status
/// against it; its rows for alarms no longer raised added, `gone`.
pub(crate) fn merge(rows: &mut Vec<MadRow>, db: &cellwatch_models::madb::Database) {
    for row in rows.iter_mut() {
        let Some(r) = db.rows.get(&row.id) else {
            row.status = "new".into();
            continue;
        };
        if let Some(p) = r.priority {
            row.priority = p.as_str().into();
        }
        let g = &r.guidance;
        if !g.class.is_empty() {
            row.class.clone_from(&g.class);
        }
        row.consequence_of_inaction
            .clone_from(&g.consequence_of_inaction);
        row.corrective_action.clone_from(&g.corrective_action);
        row.response_time = g.response_time_ms.map(duration).unwrap_or_default();
        if r.condition.as_ref().is_some_and(|c| *c != row.condition) {
            row.status = "changed".into();
        }
    }
    for (id, r) in &db.rows {
        if !rows.iter().any(|row| row.id == *id) {
            rows.push(MadRow {
                id: id.clone(),
                priority: r
                    .priority
                    .map(|p| p.as_str().to_string())
                    .unwrap_or_default(),
                class: r.guidance.class.clone(),
                condition: r.condition.clone().unwrap_or_default(),
                consequence_of_inaction: r.guidance.consequence_of_inaction.clone(),
                corrective_action: r.guidance.corrective_action.clone(),
                response_time: r
                    .guidance
                    .response_time_ms
                    .map(duration)
                    .unwrap_or_default(),
                status: "gone".into(),
                ..MadRow::default()
            });
        }
    }
    rows.sort_by(|a, b| a.id.cmp(&b.id));
}

fn class(kind: AlarmKind, fault: bool) -> &'static str {
    match kind {
        AlarmKind::Communication | AlarmKind::TagQuality | AlarmKind::System => "system",
        _ if fault => "fault",
        _ => "warning",
    }
}

fn duration(ms: u64) -> String {
    humantime::format_duration(std::time::Duration::from_millis(ms)).to_string()
}

/// The agent's own alarms and the PLC's patterns, as rows.
fn own_alarms(c: &CellConfig) -> Vec<MadRow> {
    crate::cell::own_alarms::own_alarms(c)
        .into_iter()
        .map(|a| {
            if a.plc {
                MadRow {
                    id: a.id,
                    kind: AlarmKind::Plc.as_str().into(),
                    priority: "from the PLC".into(),
                    class: "warning".into(),
                    condition: a.condition,
                    ..MadRow::default()
                }
            } else {
                MadRow {
                    fault_type: a.id.to_uppercase(),
                    id: a.id,
                    kind: AlarmKind::System.as_str().into(),
                    priority: Severity::High.as_str().into(),
                    class: "system".into(),
                    condition: a.condition,
                    ..MadRow::default()
                }
            }
        })
        .collect()
}

impl Default for MadRow {
    fn default() -> Self {
        MadRow {
            id: String::new(),
            kind: String::new(),
            priority: String::new(),
            class: String::new(),
            condition: String::new(),
            culprits: String::new(),
            causes: String::new(),
            effects: String::new(),
            suppressed_in_modes: String::new(),
            on_delay: "0s".into(),
            off_delay: "0s".into(),
            latched: "no".into(),
            fault_type: String::new(),
            consequence_of_inaction: String::new(),
            corrective_action: String::new(),
            response_time: String::new(),
            status: String::new(),
        }
    }
}
