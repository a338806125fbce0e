//! `cellwatch pki`: a plant CA for the Zenoh bus, and certificates issued
//! from it for agents, routers and operators (X.509, ECDSA P-256), so that
//! mutual TLS needs no openssl recipe; and each agent's signing key.

use std::path::PathBuf;

use std::io::Write;

use super::Failure;
use crate::bus::certs::{ca_files, issue, make_ca};
use crate::bus::envelope::AgentKey;

/// `cellwatch pki ca`.
pub(crate) fn ca(args: &PkiCaArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let made = make_ca(&args.dir, &args.name).map_err(Failure::runtime)?;
    let (cert, key) = ca_files(&args.dir);
    let io = Failure::output;
    if made {
        writeln!(out, "CA '{}': {} (give to every agent, router and client), {} (private: keep it off the network)", args.name, cert.display(), key.display()).map_err(io)
    } else {
        Err(Failure::Input(format!(
            "{} already holds a CA; not overwritten",
            args.dir.display()
        )))
    }
}

/// `cellwatch pki issue`.
pub(crate) fn issue_command(args: &PkiIssueArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let mut hosts = args.host.clone();
    if hosts.is_empty() {
        hosts = vec!["localhost".into(), "127.0.0.1".into()];
    }
    let (cert, key) = issue(&args.dir, &args.name, &hosts).map_err(Failure::input)?;
    writeln!(
        out,
        "issued '{}' for {}: {} and {} (private)",
        args.name,
        hosts.join(", "),
        cert.display(),
        key.display()
    )
    .map_err(Failure::output)
}

/// `cellwatch pki agent-key`.
pub(crate) fn agent_key(args: &PkiAgentKeyArgs, out: &mut dyn Write) -> Result<(), Failure> {
    if args.cell.is_empty()
        || !args
            .cell
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(Failure::Input(format!(
            "--cell '{}': a cell id is letters, digits, '-' and '_'",
            args.cell
        )));
    }
    let (key, made) = AgentKey::load_or_create(&args.out, &args.cell)
        .map_err(|e| Failure::Input(e.to_string()))?;
    let io = Failure::output;
    let what = if made { "written to" } else { "read from" };
    writeln!(
        out,
        "# signing key of cell {}'s agent {what} {} (keep it on that agent only: zenoh.signing_key)",
        args.cell,
        args.out.display()
    )
    .map_err(io)?;
    writeln!(
        out,
        "# add to the plant trust file (cellwatch --trust FILE):"
    )
    .map_err(io)?;
    write!(out, "{}", key.trust_entry()).map_err(io)
}

#[derive(Debug, clap::Subcommand)]
pub(crate) enum PkiCommand {
    /// Create the plant CA: DIR/ca.pem (public) and DIR/ca.key (private).
    Ca(PkiCaArgs),
    /// Issue a certificate from the CA in DIR: DIR/NAME.pem and DIR/NAME.key.
    /// NAME is its common name: `agent-<cell>` for an agent, `router-…` for
    /// a router, `operator-<name>` for an operator (as config/zenoh/ expects).
    Issue(PkiIssueArgs),
    /// Make a cell agent's Ed25519 signing key (`zenoh.signing_key`), or
    /// read an existing one, and print its entry for the plant trust file
    /// that clients check every alarm and answer against.
    AgentKey(PkiAgentKeyArgs),
}

#[derive(Debug, clap::Args)]
pub(crate) struct PkiAgentKeyArgs {
    /// The cell whose agent signs with it.
    #[arg(long)]
    pub(crate) cell: String,
    /// The key file (owner-only); an existing one is read, never
    /// overwritten.
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct PkiCaArgs {
    /// Where the CA's files go.
    #[arg(long, default_value = "pki-bus")]
    pub(crate) dir: PathBuf,
    /// The CA's common name.
    #[arg(long, default_value = "cellwatch plant CA")]
    pub(crate) name: String,
}

#[derive(Debug, clap::Args)]
pub(crate) struct PkiIssueArgs {
    /// Where the CA is, and where the certificate goes.
    #[arg(long, default_value = "pki-bus")]
    pub(crate) dir: PathBuf,
    /// The common name.
    #[arg(long)]
    pub(crate) name: String,
    /// Host name or IP address the holder listens on (repeatable; default
    /// localhost and 127.0.0.1). Clients check it when they connect.
    #[arg(long)]
    pub(crate) host: Vec<String>,
}
