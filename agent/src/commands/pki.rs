//! `cellwatch pki`: a plant CA for the Zenoh bus, and certificates issued
//! from it for agents, routers and operators (X.509, ECDSA P-256), so that
//! mutual TLS needs no openssl recipe; and each agent's signing key.

use std::io::Write;

use crate::cli::{Failure, PkiAgentKeyArgs, PkiCaArgs, PkiIssueArgs};
use crate::sinks::zenoh::certs::{ca_files, issue, make_ca};
use crate::sinks::zenoh::envelope::AgentKey;

/// `cellwatch pki ca`.
pub(crate) fn ca(args: &PkiCaArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let made = make_ca(&args.dir, &args.name).map_err(Failure::Runtime)?;
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
    let (cert, key) = issue(&args.dir, &args.name, &hosts).map_err(Failure::Input)?;
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
