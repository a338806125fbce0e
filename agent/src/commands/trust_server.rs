//! `cellwatch trust-server`: the OPC UA certificate exchange in one
//! command. Shows the server's certificate (asked for without a session),
//! trusts it on confirmation, shows the agent's own and whether the server
//! accepts it yet.

use std::io::{BufRead, Write};
use std::path::PathBuf;

use super::Failure;
use crate::operator::escaped;
use crate::sources::opcua;
use crate::sources::pki::{self, CertificateFacts};

#[derive(Debug, clap::Args)]
pub(crate) struct TrustServerArgs {
    /// The server's endpoint (opc.tcp://host:port/path).
    pub(crate) endpoint: String,
    /// PKI directory: the agent's key pair (made if it has none) and the
    /// `trusted/` folder the server's certificate goes to.
    #[arg(long, default_value = "pki")]
    pub(crate) pki_dir: PathBuf,
    /// Trust the server's certificate without asking (check its
    /// fingerprint against the server's own tool first).
    #[arg(long)]
    pub(crate) yes: bool,
    /// Basic256Sha256 | Aes128_Sha256_RsaOaep | Aes256_Sha256_RsaPss.
    #[arg(long, default_value = "Basic256Sha256")]
    pub(crate) security_policy: crate::config::SecurityPolicy,
    /// SignAndEncrypt | Sign.
    #[arg(long, default_value = "SignAndEncrypt")]
    pub(crate) security_mode: crate::config::SecurityMode,
}

pub(crate) async fn run(args: &TrustServerArgs, out: &mut dyn Write) -> Result<(), Failure> {
    if args.security_policy == crate::config::SecurityPolicy::None {
        return Err(Failure::input(
            "--security-policy None: such a connection has no certificates to trust",
        ));
    }
    let config = super::discover::connection(
        &args.endpoint,
        &args.pki_dir,
        args.security_policy,
        args.security_mode,
        None,
    )?;
    let server = opcua::server_identity(&config)
        .await
        .map_err(Failure::runtime)?;
    let now = crate::clock::now_ms();
    let facts = CertificateFacts::of(&server.certificate, now).map_err(|e| {
        Failure::runtime(format!("{}: the server's certificate: {e}", args.endpoint))
    })?;
    let io = Failure::output;
    writeln!(out, "The server at {}", args.endpoint).map_err(io)?;
    // What the server says of itself is its own text: escaped, so that no
    // line of it can pass for one of ours (a fingerprint line drawn).
    writeln!(
        out,
        "  application  {} ({})",
        escaped(&server.application_name),
        escaped(&server.application_uri)
    )
    .map_err(io)?;
    facts_lines(&facts, out).map_err(io)?;
    if !facts.valid_now {
        writeln!(
            out,
            "  WARNING: not valid now: the connection will be refused until the server has a valid certificate"
        )
        .map_err(io)?;
    }
    if pki::is_trusted(&server.certificate, &args.pki_dir) {
        writeln!(
            out,
            "is trusted already ({}/trusted).",
            args.pki_dir.display()
        )
        .map_err(io)?;
    } else {
        let yes = args.yes
            || ask(
                out,
                "Trust it? Compare the fingerprint with the one the server's own tool shows. [y/N] ",
            )?;
        if !yes {
            return Err(Failure::Input(
                "not trusted: nothing changed (answer y, or pass --yes once the fingerprint is checked)".into(),
            ));
        }
        let path = pki::trust_der(&server.certificate, &args.pki_dir).map_err(Failure::runtime)?;
        writeln!(out, "Trusted: {}", path.display()).map_err(io)?;
    }
    let own = pki::own_cert(&args.pki_dir);
    let own_facts = std::fs::read(&own)
        .map_err(|e| e.to_string())
        .and_then(|der| CertificateFacts::of(&der, now).map_err(|e| e.to_string()))
        .map_err(|e| Failure::runtime(format!("{}: {e}", own.display())))?;
    writeln!(out, "\nThis agent's certificate, {}", own.display()).map_err(io)?;
    facts_lines(&own_facts, out).map_err(io)?;
    match opcua::connect_once("trust", &config).await {
        Ok((session, task)) => {
            let _ = session.disconnect().await;
            task.abort();
            writeln!(
                out,
                "\nConnected: the server accepts this agent. Next: cellwatch discover {} --pki-dir {}",
                args.endpoint,
                args.pki_dir.display()
            )
            .map_err(io)?;
        }
        Err(e) => {
            writeln!(
                out,
                "\nThe server does not accept this agent yet: {}\nAdd {} to the server's trusted clients (for `cellwatch simulate cnc`: --trust {}), then run this command again to check.",
                escaped(&e.to_string()),
                own.display(),
                own.display()
            )
            .map_err(io)?;
        }
    }
    Ok(())
}

fn facts_lines(f: &CertificateFacts, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(out, "  subject      {}", f.subject)?;
    writeln!(out, "  valid        {} to {}", f.not_before, f.not_after)?;
    writeln!(out, "  SHA-256      {}", f.sha256)?;
    writeln!(
        out,
        "  thumbprint   {} (SHA-1, as servers list certificates)",
        f.thumbprint
    )
}

/// Asks `question`: whether the answer on standard input is yes. No
/// answer (end of input): no.
fn ask(out: &mut dyn Write, question: &str) -> Result<bool, Failure> {
    write!(out, "{question}").map_err(Failure::output)?;
    out.flush().map_err(Failure::output)?;
    let mut line = String::new();
    std::io::stdin()
        .lock()
        .read_line(&mut line)
        .map_err(|e| Failure::runtime(format!("cannot read the answer: {e}")))?;
    Ok(matches!(
        line.trim().to_ascii_lowercase().as_str(),
        "y" | "yes"
    ))
}
