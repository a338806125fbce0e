//! `cellwatch console`: the operators' web console for the plant.

use std::io::Write;
use std::path::PathBuf;

use super::signals::StopSignals;
use super::Failure;
use crate::console::{Console, ConsoleError};

/// Serves the console until Ctrl-C or SIGTERM.
pub(crate) async fn run(args: &ConsoleArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let mut signals = StopSignals::listen()?;
    let mut cfg = crate::console::config::load(&args.config).map_err(Failure::input)?;
    if let Some(listen) = args.listen {
        if !listen.ip().is_loopback() && cfg.tls.is_none() {
            return Err(Failure::Input(format!(
                "--listen {listen}: reachable from the network without http.tls in {}",
                args.config.display()
            )));
        }
        cfg.listen = listen;
    }
    let console = Console::start(&cfg).await.map_err(|e| match e {
        ConsoleError::Input(e) => Failure::Input(e),
        ConsoleError::Runtime(e) => Failure::Runtime(e),
    })?;
    writeln!(out, "cellwatch console: {}", console.url()).map_err(Failure::output)?;
    out.flush().map_err(Failure::output)?;
    let signal = signals.recv().await;
    tracing::info!(signal, "console stopping");
    console.stop().await;
    Ok(())
}

#[derive(Debug, clap::Args)]
pub(crate) struct ConsoleArgs {
    /// The console's configuration (TOML): where it serves (http), how it
    /// joins the bus with its own certificate (bus), the operators file
    /// whose permissions it offers, and the plant's areas. See
    /// docs/reference/console.md.
    #[arg(long, value_name = "TOML")]
    pub(crate) config: PathBuf,
    /// Serve on this address instead of the file's http.listen (port 0:
    /// one the system picks; the URL is printed).
    #[arg(long, value_name = "IP:PORT")]
    pub(crate) listen: Option<std::net::SocketAddr>,
}
