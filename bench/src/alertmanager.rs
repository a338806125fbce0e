//! The agent beside an Alertmanager that cannot take its alerts: does a
//! dead one slow the alarms on the bus? (`bench/run peer --alertmanager
//! off --alertmanager refusing --alertmanager silent`.)

use std::path::Path;

/// What stands where the agent's `[alertmanager]` points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Alertmanager {
    /// No `[alertmanager]` section: the baseline.
    Off,
    /// A port nothing listens on: every send is refused at once.
    Refusing,
    /// A listener that accepts and never answers: every send waits for
    /// the agent's 10 s timeout, the worst a dead host behind a live
    /// network does.
    Silent,
}

impl Alertmanager {
    /// For the table.
    pub fn label(self) -> &'static str {
        match self {
            Alertmanager::Off => "",
            Alertmanager::Refusing => ", Alertmanager refusing",
            Alertmanager::Silent => ", Alertmanager silent",
        }
    }

    /// Adds the `[alertmanager]` section to the configuration at
    /// `config`, and starts what stands there; it lasts as long as the
    /// returned guard.
    pub async fn stand_in(
        self,
        config: &Path,
    ) -> anyhow::Result<Option<tokio::task::JoinHandle<()>>> {
        let (port, task) = match self {
            Alertmanager::Off => return Ok(None),
            // A port the system had free a moment ago, left unbound.
            Alertmanager::Refusing => (
                std::net::TcpListener::bind("127.0.0.1:0")?
                    .local_addr()?
                    .port(),
                None,
            ),
            Alertmanager::Silent => {
                let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
                let port = listener.local_addr()?.port();
                let task = tokio::spawn(async move {
                    let mut held = Vec::new();
                    while let Ok((stream, _)) = listener.accept().await {
                        // Taken, read by nobody, answered never.
                        held.push(stream);
                    }
                });
                (port, Some(task))
            }
        };
        let mut text = std::fs::read_to_string(config)?;
        text.push_str(&format!(
            "\n[alertmanager]\nurls = [\"http://127.0.0.1:{port}\"]\nresend_interval = \"1s\"\n"
        ));
        std::fs::write(config, text)?;
        Ok(task)
    }
}
