//! `cellwatch audit verify JOURNAL`: checks the hash chain of a journal's
//! command rows ([`crate::journal::chain`]) and names the first row
//! edited, inserted or deleted. Reads the file only; never repairs it.

use std::io::Write;
use std::path::PathBuf;

use super::Failure;
use crate::journal::{self, chain};

/// `cellwatch audit`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    command: AuditCommand,
}

#[derive(Debug, clap::Subcommand)]
enum AuditCommand {
    /// Check that no command row of a journal was edited, inserted or
    /// deleted since it was written (the rows' hash chain). Exits 0 when
    /// every row holds, 1 at the first that does not (named by its seq).
    Verify {
        /// The agent's SQLite journal.
        journal: PathBuf,
    },
}

/// Runs `cellwatch audit`.
pub(crate) fn run(args: &Args, out: &mut dyn Write) -> Result<(), Failure> {
    let AuditCommand::Verify { journal: path } = &args.command;
    if !path.is_file() {
        return Err(Failure::Input(format!("{}: no such file", path.display())));
    }
    let conn = journal::open_read(path).map_err(Failure::input)?;
    let verdict = chain::verify(&conn).map_err(|e| {
        Failure::Input(format!(
            "{}: not a cellwatch journal with chained command rows: {e}",
            path.display()
        ))
    })?;
    match verdict {
        chain::Verdict::Intact { rows, before, from } => {
            let mut line = format!("{}: {rows} command rows intact", path.display());
            if from > 1 {
                line += &format!(" (the chain kept from position {from}: older rows purged)");
            }
            if before > 0 {
                let rows = if before == 1 { "row" } else { "rows" };
                line += &format!("; {before} {rows} before the chain (not checked)");
            }
            writeln!(out, "{line}").map_err(Failure::output)
        }
        chain::Verdict::Broken { seq, what, intact } => Err(Failure::Runtime(format!(
            "{}: seq {seq}: {what} ({intact} command rows intact before it)",
            path.display()
        ))),
    }
}
