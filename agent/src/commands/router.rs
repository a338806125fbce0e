//! `cellwatch router`: a plant router that keeps the plant archive.

use std::io::Write;
use std::path::PathBuf;

use super::signals::StopSignals;
use super::Failure;
use crate::archive::router::{PlantRouter, RouterError};

/// Runs the router until Ctrl-C or SIGTERM.
pub(crate) async fn run(args: &Args, out: &mut dyn Write) -> Result<(), Failure> {
    let mut signals = StopSignals::listen()?;
    let router = PlantRouter::start_from(&args.config)
        .await
        .map_err(|e| match e {
            e @ (RouterError::Config { .. }
            | RouterError::NotARouter { .. }
            | RouterError::Archive { .. }) => Failure::Input(e.to_string()),
            e @ RouterError::Start(_) => Failure::Runtime(e.to_string()),
        })?;
    writeln!(
        out,
        "cellwatch router {}: listening on {}{}",
        router.zid(),
        router.locators().join(", "),
        if router.archives() {
            "; keeping the plant archive (plugins.storage_manager)"
        } else {
            ""
        }
    )
    .map_err(Failure::output)?;
    out.flush().map_err(Failure::output)?;
    let signal = signals.recv().await;
    tracing::info!(signal, "router stopping");
    router.close().await;
    Ok(())
}

#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// The router's Zenoh configuration (JSON5, as `zenohd -c` reads it;
    /// `cellwatch plant` makes one per router of the inventory). With a
    /// `plugins.storage_manager` section the router keeps the plant
    /// archive in the SQLite volume `sqlite` (docs/reference/archive.md).
    #[arg(long, short, value_name = "JSON5")]
    pub(crate) config: PathBuf,
}
