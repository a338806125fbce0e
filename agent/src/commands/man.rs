//! `cellwatch man DIR`: the manual pages, generated from the command
//! line's own definitions (clap), one per command and subcommand
//! (`cellwatch.1`, `cellwatch-run.1`, `cellwatch-journal-backup.1`, …):
//! what the package installs, never out of step with `--help`.

use std::io::Write;
use std::path::PathBuf;

use super::Failure;

/// `cellwatch man`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The folder the pages are written to (made if missing).
    dir: PathBuf,
}

/// Writes the pages of `cli` (the whole command line) into `args.dir`.
pub(crate) fn run(args: &Args, cli: clap::Command, out: &mut dyn Write) -> Result<(), Failure> {
    std::fs::create_dir_all(&args.dir)
        .map_err(|e| Failure::Runtime(format!("{}: {e}", args.dir.display())))?;
    clap_mangen::generate_to(cli, &args.dir)
        .map_err(|e| Failure::Runtime(format!("{}: {e}", args.dir.display())))?;
    let mut pages: Vec<_> = std::fs::read_dir(&args.dir)
        .map_err(|e| Failure::Runtime(format!("{}: {e}", args.dir.display())))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".1"))
        .collect();
    pages.sort();
    writeln!(
        out,
        "{}: {} manual pages ({})",
        args.dir.display(),
        pages.len(),
        pages.join(", ")
    )
    .map_err(Failure::output)
}
