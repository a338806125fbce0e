//! `cellwatch mad export`: the first draft of a cell's master alarm
//! database (ISA-18.2 / IEC 62682 rationalisation), written from what the
//! agent knows of every alarm the cell can raise: its checks' alarms (each
//! with its condition in words, its possible culprits with their
//! comments, the alarms it may follow from and cause, the modes that
//! suppress it by design, its delays) and the agent's own. The
//! rationalisation columns (consequence of inaction, corrective action,
//! response time) are left for the plant's engineers to fill in.

use std::io::Write;
use std::path::PathBuf;

use cellwatch_models::alarm::{AlarmKind, Severity};
use cellwatch_models::engine::CatalogueEntry;
use serde::Serialize;

use super::Failure;
use crate::config::CellConfig;

/// `cellwatch mad`.
#[derive(Debug, clap::Subcommand)]
pub(crate) enum MadCommand {
    /// Write every alarm the cell can raise as the first draft of its
    /// master alarm database: id, kind, priority, class, the condition in
    /// words, the possible culprits with their comments, the alarms it may
    /// follow from and cause, the modes that suppress it by design, its
    /// delays, and empty columns for the rationalisation (consequence of
    /// inaction, corrective action, response time). CSV opens in a
    /// spreadsheet; JSON is the same rows.
    Export(ExportArgs),
}

/// `cellwatch mad export`.
#[derive(Debug, clap::Args)]
pub(crate) struct ExportArgs {
    /// The cell's configuration.
    config: PathBuf,
    /// `csv` (one row per alarm, a header row first) or `json` (an array
    /// of the same rows).
    #[arg(long, default_value = "csv", value_parser = ["csv", "json"])]
    format: String,
    /// Write to this file instead of standard output.
    #[arg(long, short, value_name = "FILE")]
    out: Option<PathBuf>,
}

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
}

pub(crate) fn run(command: &MadCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match command {
        MadCommand::Export(args) => export(args, out),
    }
}

fn export(args: &ExportArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let c = crate::config::load(&args.config).map_err(Failure::input)?;
    let engine = crate::cell::compile::engine(&c)
        .map_err(|e| Failure::Input(format!("{}: {e}", args.config.display())))?;
    let rows = rows(&c, &engine.catalogue());
    let text = match args.format.as_str() {
        "json" => serde_json::to_string_pretty(&rows).map_err(Failure::runtime)? + "\n",
        _ => csv_text(&rows).map_err(Failure::runtime)?,
    };
    match &args.out {
        Some(path) => std::fs::write(path, text)
            .map_err(|e| Failure::Runtime(format!("{}: {e}", path.display()))),
        None => out.write_all(text.as_bytes()).map_err(Failure::output),
    }
}

/// The rows as CSV, a header first.
fn csv_text(rows: &[MadRow]) -> Result<String, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r)?;
    }
    let bytes = w.into_inner().map_err(|e| e.into_error())?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
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

/// The agent's system alarms this cell can raise, and a row per prefix of
/// the PLC's own alarms it follows.
fn own_alarms(c: &CellConfig) -> Vec<MadRow> {
    let system = |id: String, condition: String| MadRow {
        fault_type: id.to_uppercase(),
        id,
        kind: AlarmKind::System.as_str().into(),
        priority: Severity::High.as_str().into(),
        class: "system".into(),
        condition,
        ..MadRow::default()
    };
    let mut out = vec![system(
        crate::cell::JOURNAL_ALARM.into(),
        "the journal cannot write (rows kept in memory and retried)".into(),
    )];
    if let Some(ua) = &c.opcua {
        out.push(system(
            crate::sources::opcua::NAMESPACE_ALARM.into(),
            "a tag's namespace is not on the OPC UA server".into(),
        ));
        out.push(system(
            crate::sources::opcua::OVERFLOW_ALARM.into(),
            "changes were lost in the OPC UA server's queues".into(),
        ));
        if !ua.events.is_empty() {
            out.push(system(
                crate::sources::opcua::EVENTS_ALARM.into(),
                "the PLC's own alarms cannot be followed".into(),
            ));
        }
        for e in &ua.events {
            out.push(MadRow {
                id: format!("{}-*", e.prefix),
                kind: AlarmKind::Plc.as_str().into(),
                priority: "from the PLC".into(),
                class: "warning".into(),
                condition: "the PLC's own alarm (OPC UA Alarms & Conditions), its text as message"
                    .into(),
                ..MadRow::default()
            });
        }
    }
    for s in &c.sfc {
        for (chart, transition) in &s.forcible {
            out.push(system(
                format!("force-{chart}-{transition}"),
                format!("a forced transition {chart}.{transition} did not arrive in time"),
            ));
        }
    }
    if c.legacy.is_some() {
        let mut units: Vec<u8> = c
            .tags
            .iter()
            .filter_map(|t| crate::config::legacy::BusNode::parse(&t.node_id).ok())
            .map(|n| n.unit)
            .collect();
        units.sort_unstable();
        units.dedup();
        for unit in units {
            out.push(system(
                crate::sources::legacy::unit_problem(unit),
                format!("unit @{unit:02X} on the bus does not answer"),
            ));
        }
    }
    out
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
        }
    }
}
