//! `cellwatch journal backup JOURNAL DEST`: an online, consistent copy of a
//! journal while its agent runs ([`crate::journal::backup`]).

use std::io::Write;
use std::path::PathBuf;

use super::Failure;
use crate::journal::backup::{backup, BackupError};

/// `cellwatch journal`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: JournalCommand,
}

#[derive(Debug, clap::Subcommand)]
enum JournalCommand {
    /// Copy a journal while its agent runs, consistent and checked.
    ///
    /// SQLite's backup API takes the journal as of one instant (the agent
    /// goes on writing meanwhile); the copy is checked (integrity, the
    /// tables counted) and only then given its name. Copying the file with
    /// `cp` instead misses the rows still in its `-wal` file. The copy is a
    /// journal like any other: `report --db` and `audit verify` read it.
    Backup {
        /// The agent's SQLite journal (`journal.path`).
        journal: PathBuf,
        /// The copy; must not exist (a backup never overwrites).
        dest: PathBuf,
    },
}

/// Runs `cellwatch journal`.
pub(crate) fn run(args: &Args, out: &mut dyn Write) -> Result<(), Failure> {
    let JournalCommand::Backup { journal, dest } = &args.command;
    let copied = backup(journal, dest).map_err(|e| match e {
        BackupError::Input(m) => Failure::Input(m),
        e @ BackupError::Failed { .. } => Failure::Runtime(e.to_string()),
    })?;
    let rows: u64 = copied
        .rows
        .iter()
        .filter(|(t, _)| *t != "alarm_current")
        .map(|(_, n)| n)
        .sum();
    let each: Vec<String> = copied
        .rows
        .iter()
        .map(|(t, n)| format!("{t} {n}"))
        .collect();
    writeln!(
        out,
        "{} → {}: {rows} rows ({}), {} bytes, integrity ok",
        journal.display(),
        dest.display(),
        each.join(", "),
        copied.bytes
    )
    .map_err(Failure::output)
}
