//! `cellwatch audit verify JOURNAL`: checks the hash chain of a journal's
//! command rows ([`crate::journal::chain`]) and names the first row
//! edited, inserted or deleted; with `--against-bus`, also compares its end
//! with the head the cell's agent signs on the bus, finding rows cut off
//! the end. Reads the file only; never repairs it.

use std::io::Write;
use std::path::PathBuf;

use super::bus::ZenohArgs;
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
        /// Also ask the cell's agent on the bus for the end of the chain it
        /// signs (its snapshot) and find rows cut off the journal's end.
        /// Needs --cell and the bus flags.
        #[arg(long, requires = "cell")]
        against_bus: bool,
        /// Also hold the journal to every end of the chain the cell's
        /// agent ever signed in a state the plant archive keeps (`cellwatch
        /// router`): rows cut off or rewritten while the agent was stopped
        /// are found even after it signed the new end. Needs --cell and the
        /// bus flags.
        #[arg(long, requires = "cell")]
        against_archive: bool,
        /// The cell whose journal it is (with --against-bus or
        /// --against-archive).
        #[arg(long)]
        cell: Option<String>,
        #[command(flatten)]
        zenoh: ZenohArgs,
    },
}

/// Runs `cellwatch audit`.
pub(crate) async fn run(args: &Args, out: &mut dyn Write) -> Result<(), Failure> {
    let AuditCommand::Verify {
        journal: path,
        against_bus,
        against_archive,
        cell,
        zenoh,
    } = &args.command;
    if !path.is_file() {
        return Err(Failure::Input(format!("{}: no such file", path.display())));
    }
    if cell.is_some() && !against_bus && !against_archive {
        return Err(Failure::Input(
            "--cell is for --against-bus or --against-archive".into(),
        ));
    }
    // Asked before the file is read: every row the agent's head names was
    // committed by then.
    let head = match cell.as_deref().filter(|_| *against_bus) {
        Some(cell) => Some((cell, super::bus::command_chain(zenoh, cell).await?)),
        None => None,
    };
    let archived = match cell.as_deref().filter(|_| *against_archive) {
        Some(cell) => Some((
            cell,
            super::archive::archived_chain_heads(zenoh, cell).await?,
        )),
        None => None,
    };
    let conn = journal::open_read(path).map_err(Failure::input)?;
    let verdict = chain::verify(&conn).map_err(|e| {
        Failure::Input(format!(
            "{}: not a cellwatch journal with chained command rows: {e}",
            path.display()
        ))
    })?;
    let line = match verdict {
        chain::Verdict::Intact { rows, before, from } => {
            let mut line = format!("{}: {rows} command rows intact", path.display());
            if from > 1 {
                line += &format!(" (the chain kept from position {from}: older rows purged)");
            }
            if before > 0 {
                let rows = if before == 1 { "row" } else { "rows" };
                line += &format!("; {before} {rows} before the chain (not checked)");
            }
            line
        }
        chain::Verdict::Broken { seq, what, intact } => {
            return Err(Failure::Runtime(format!(
                "{}: seq {seq}: {what} ({intact} command rows intact before it)",
                path.display()
            )))
        }
    };
    let line = match archived {
        Some((cell, heads)) => format!(
            "{line}; {}",
            against_archive_heads(&conn, path, cell, &heads)?
        ),
        None => line,
    };
    let Some((cell, head)) = head else {
        return writeln!(out, "{line}").map_err(Failure::output);
    };
    let announced = chain::Link::from_announced(&head);
    let against = chain::against(&conn, &announced)
        .map_err(|e| Failure::Runtime(format!("{}: cannot read the chain: {e}", path.display())))?;
    let said = format!(
        "cell {cell}'s agent signs the chain's end at position {} (seq {})",
        head.position, head.seq
    );
    match against {
        chain::Against::Holds { .. } => {
            writeln!(out, "{line}; {said}: it is there").map_err(Failure::output)
        }
        chain::Against::Purged => writeln!(
            out,
            "{line}; {said}: older than the oldest row kept, not compared"
        )
        .map_err(Failure::output),
        chain::Against::CutOff { missing, ends } => {
            let rows = if missing == 1 { "row" } else { "rows" };
            Err(Failure::Runtime(format!(
                "{}: {missing} command {rows} cut off the end: {said}; the journal's chain ends at position {} (seq {}): positions {} to {} are missing",
                path.display(),
                ends.index,
                ends.seq,
                ends.index + 1,
                head.position
            )))
        }
        chain::Against::Rewritten { seq } => Err(Failure::Runtime(format!(
            "{}: seq {seq}: not the row the agent signed at position {}: {said}, with another hash (the chain rewritten from there)",
            path.display(),
            head.position
        ))),
    }
}

/// The journal held to every chain end the plant archive keeps for `cell`:
/// what holds, or the first end it contradicts.
fn against_archive_heads(
    conn: &rusqlite::Connection,
    path: &std::path::Path,
    cell: &str,
    heads: &[crate::payload::CommandChain],
) -> Result<String, Failure> {
    let (mut there, mut purged) = (0, 0);
    for head in heads {
        let announced = chain::Link::from_announced(head);
        let against = chain::against(conn, &announced).map_err(|e| {
            Failure::Runtime(format!("{}: cannot read the chain: {e}", path.display()))
        })?;
        match against {
            chain::Against::Holds { .. } => there += 1,
            chain::Against::Purged => purged += 1,
            chain::Against::CutOff { missing, ends } => {
                let rows = if missing == 1 { "row" } else { "rows" };
                return Err(Failure::Runtime(format!(
                    "{}: {missing} command {rows} cut off: the plant archive keeps cell {cell}'s agent's signed chain end at position {} (seq {}); the journal's chain ends at position {} (seq {})",
                    path.display(),
                    head.position,
                    head.seq,
                    ends.index,
                    ends.seq
                )));
            }
            chain::Against::Rewritten { seq } => {
                return Err(Failure::Runtime(format!(
                    "{}: seq {seq}: not the row cell {cell}'s agent signed at position {} (kept in the plant archive): the chain rewritten from there",
                    path.display(),
                    head.position
                )));
            }
        }
    }
    if heads.is_empty() {
        return Ok(format!(
            "the plant archive keeps no chain end of cell {cell}'s (no state of its archived)"
        ));
    }
    let mut said = format!(
        "every chain end cell {cell}'s agent signed in the plant archive is there ({there})"
    );
    if purged > 0 {
        said += &format!("; {purged} older than the oldest row kept, not compared");
    }
    Ok(said)
}
