//! The command line: what each command takes, and how outcomes become exit
//! statuses (0 success, 1 runtime failure, 2 bad input).

use std::ffi::OsString;
use std::io::Write;
use std::path::PathBuf;

use cellwatch_models::explain::Polarity;
use cellwatch_models::il::Dialect;
use clap::{Parser, Subcommand};

use crate::commands;

/// cellwatch — watches a PLC and names the step and the contact behind every fault.
///
/// Compiles PLC logic (instruction lists, FANUC PMC or IEC 61131-3) into the
/// switching function of each fault coil, splits it into step blocks, and at
/// fault time names the step and the contacts that caused it, with their
/// comments from the machine's I/O list.
#[derive(Debug, Parser)]
#[command(name = "cellwatch", version, max_term_width = 100)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Print the switching function (SF) and step blocks (SSF) of coils.
    ///
    /// Each coil's SF is written in observable signals: internal relays are
    /// replaced by the logic that writes them; self-holding coils and
    /// SET/RST latches stay as their own last value. The SF is printed in the
    /// paper's notation (`*` AND, `+` OR, `-` NOT) and in words, followed by
    /// its step blocks SSF1..SSFn, bottom-up.
    Sf(SfArgs),
    /// Explain a fault: the coil's value, every step's value, the fault step
    /// and the contacts that caused it.
    ///
    /// Culprits that changed between --before and --snapshot are the trigger
    /// and come first. Each culprit shows its value, the value that would
    /// clear the fault, and its comment.
    Explain(ExplainArgs),
}

/// Where the program comes from and how to read it.
#[derive(Debug, clap::Args)]
pub(crate) struct ProgramArgs {
    /// The PLC program: an instruction list file.
    #[arg(value_name = "PROGRAM")]
    pub(crate) program: PathBuf,
    /// The instruction-list dialect: `pmc` (RD, AND.NOT, WRT; X0.07) or
    /// `iec` (LD, ANDN, ST; %IX0.0.3). Detected from the mnemonics if not given.
    #[arg(long, value_name = "pmc|iec", value_parser = parse_dialect)]
    pub(crate) dialect: Option<Dialect>,
    /// Signals the SF may stop at, comma-separated: classes (`X,Y,F,G`;
    /// `%I,%Q`) or single signals (`R1024.00`). Default: X, Y, F, G for pmc;
    /// %I, %Q for iec.
    #[arg(long, value_name = "LIST")]
    pub(crate) observable: Option<String>,
    /// The I/O database: CSV `address,comment`, one row per address.
    #[arg(long, value_name = "CSV")]
    pub(crate) comments: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct SfArgs {
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// A coil to print; repeat for several. Default: every coil the program writes.
    #[arg(long, value_name = "NAME")]
    pub(crate) coil: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ExplainArgs {
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// The fault coil to explain.
    #[arg(long, value_name = "NAME")]
    pub(crate) coil: String,
    /// Signal values at the fault: inline `X0.06=0,X0.07=1`, or a file with
    /// one `ADDRESS=VALUE` (or CSV `ADDRESS,VALUE`) a line. Values: 0/1,
    /// true/false, on/off.
    #[arg(long, value_name = "VALUES")]
    pub(crate) snapshot: String,
    /// Signal values just before the fault, same forms; contacts that changed
    /// are marked as the trigger.
    #[arg(long, value_name = "VALUES")]
    pub(crate) before: Option<String>,
    /// Which coil value is the fault: `on` (an alarm coil) or `off` (an enable coil).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_polarity)]
    pub(crate) fault_when: Polarity,
}

fn parse_dialect(s: &str) -> Result<Dialect, String> {
    s.parse()
}

fn parse_polarity(s: &str) -> Result<Polarity, String> {
    s.parse()
}

/// Why a command failed.
#[derive(Debug)]
pub(crate) enum Failure {
    /// The user's input is wrong: exit status 2.
    Input(String),
    /// Something failed while running: exit status 1.
    #[allow(dead_code)]
    Runtime(String),
}

impl<E: std::error::Error> From<E> for Failure {
    fn from(e: E) -> Self {
        Failure::Input(e.to_string())
    }
}

/// Runs the command line `args` (program name first), writing output to
/// `out` and diagnostics to `err`; returns the exit status.
pub fn run(
    args: impl IntoIterator<Item = impl Into<OsString> + Clone>,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> u8 {
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let text = e.render().to_string();
            let _ = if e.use_stderr() {
                err.write_all(text.as_bytes())
            } else {
                out.write_all(text.as_bytes())
            };
            return code;
        }
    };
    let result = match cli.command {
        Command::Sf(args) => commands::sf::run(&args, out, err),
        Command::Explain(args) => commands::explain::run(&args, out, err),
    };
    match result {
        Ok(()) => 0,
        Err(Failure::Input(msg)) => {
            let _ = writeln!(err, "error: {msg}");
            2
        }
        Err(Failure::Runtime(msg)) => {
            let _ = writeln!(err, "error: {msg}");
            1
        }
    }
}
