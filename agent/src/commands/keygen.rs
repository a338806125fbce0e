//! `cellwatch keygen`: an operator's Ed25519 key pair.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::Failure;
use crate::operator::{valid_operator_name, Action, OperatorKey, OPERATOR_NAME};

/// Writes the private key file and prints the operators-file entry.
pub(crate) fn run(args: &KeygenArgs, out: &mut dyn Write) -> Result<(), Failure> {
    if !valid_operator_name(&args.operator) {
        return Err(Failure::Input(format!(
            "--operator {:?}: an operator's name is {OPERATOR_NAME}",
            args.operator
        )));
    }
    let mut allow = Vec::new();
    for name in args
        .allow
        .split(',')
        .map(str::trim)
        .filter(|n| !n.is_empty())
    {
        let action = Action::parse(name).ok_or_else(|| {
            let known: Vec<&str> = Action::ALL.iter().map(|a| a.as_str()).collect();
            Failure::Input(format!(
                "--allow: unknown action '{name}': use {}",
                known.join(", ")
            ))
        })?;
        if !allow.contains(&action) {
            allow.push(action);
        }
    }
    let key = OperatorKey::generate(&args.operator);
    write_private(&args.out, &key.to_file())?;
    let io = Failure::output;
    writeln!(
        out,
        "# private key of '{}' written to {} (keep it; agents never need it)",
        args.operator,
        args.out.display()
    )
    .map_err(io)?;
    writeln!(out, "# add to each agent's operators file:").map_err(io)?;
    write!(out, "{}", key.operators_entry(&allow)).map_err(io)?;
    Ok(())
}

/// Creates `path` readable by its owner only; an existing file is kept.
pub(crate) fn write_private(path: &Path, text: &str) -> Result<(), Failure> {
    crate::bus::certs::write_private(path, text).map_err(|e| match e {
        crate::bus::certs::CertError::Exists { .. } => Failure::input(e),
        _ => Failure::runtime(e),
    })
}

#[derive(Debug, clap::Args)]
pub(crate) struct KeygenArgs {
    /// The operator's name, as agents' operators files will know it.
    #[arg(long)]
    pub(crate) operator: String,
    /// Where to write the private key (never overwritten).
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,
    /// Actions to allow in the printed entry, comma-separated (ack, reset,
    /// write: writes to the PLC, only for those who may).
    #[arg(long, default_value = "ack", value_name = "LIST")]
    pub(crate) allow: String,
}
