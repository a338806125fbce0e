//! `cellwatch journal backup JOURNAL DEST`: an online, consistent copy of a
//! journal while its agent runs ([`crate::journal::backup`]).

use std::io::Write;
use std::path::PathBuf;

use super::Failure;
use crate::journal::backup::{backup, backup_database, BackupError};
use crate::sinks::sparkplug::store::store_path;

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
    /// The Sparkplug B node's held changes beside it (`JOURNAL.sparkplug`),
    /// when there are, are copied the same way to `DEST.sparkplug`.
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
    let failure = |e: BackupError| match e {
        BackupError::Input(m) => Failure::Input(m),
        e @ BackupError::Failed { .. } => Failure::Runtime(e.to_string()),
    };
    // The held store's destination is checked before anything is copied.
    let store = store_path(journal);
    let store_dest = store_path(dest);
    if store.is_file() && store_dest.symlink_metadata().is_ok() {
        return Err(Failure::Input(format!(
            "{}: exists already (a backup never overwrites a file: name a new one)",
            store_dest.display()
        )));
    }
    let copied = backup(journal, dest).map_err(failure)?;
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
    .map_err(Failure::output)?;
    if store.is_file() {
        let bytes = backup_database(&store, &store_dest).map_err(|e| {
            Failure::Runtime(format!(
                "the journal is copied to {}, but not the Sparkplug B node's held changes: {e}",
                dest.display()
            ))
        })?;
        writeln!(
            out,
            "{} → {}: the Sparkplug B node's held changes, {bytes} bytes, integrity ok",
            store.display(),
            store_dest.display()
        )
        .map_err(Failure::output)?;
    }
    Ok(())
}
