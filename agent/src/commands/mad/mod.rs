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

use super::Failure;

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
    /// Take a rationalised file back as the cell's master alarm database:
    /// each alarm's priority, class, consequence of inaction, corrective
    /// action and response time become the cell's (written to the file
    /// `alarms.database` names, taken at the agent's next start or
    /// `cellwatch reload`). The changes are shown first; every problem of
    /// the file is said at its line and column, and nothing is written
    /// then.
    Import(ImportArgs),
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

mod import;
mod rows;

pub(crate) use import::ImportArgs;
pub(crate) use rows::{merge, rows, MadRow};

pub(crate) fn run(command: &MadCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match command {
        MadCommand::Export(args) => export(args, out),
        MadCommand::Import(args) => import::run(args, out),
    }
}

fn export(args: &ExportArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let mut c = crate::config::load(&args.config).map_err(Failure::input)?;
    // The database is merged here, row by row: a row whose alarm is gone
    // is marked, not refused.
    let database = c.database.take().map(|(_, db)| db);
    let engine = crate::cell::compile::engine(&c)
        .map_err(|e| Failure::Input(format!("{}: {e}", args.config.display())))?;
    let mut rows = rows(&c, &engine.catalogue());
    if let Some(db) = &database {
        merge(&mut rows, db);
    }
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
