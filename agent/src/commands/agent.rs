//! `cellwatch run` and `validate`: the agent itself (`demo.rs` runs it on
//! simulated cells).
//!
//! `run` and `demo` stop cleanly on Ctrl-C (SIGINT) and on SIGTERM, what
//! systemd, Docker and Kubernetes send ([`StopSignals`]): every agent is
//! stopped (its journal rows committed, its chart switches written off,
//! its liveliness token undeclared) and the process exits 0. An agent that
//! cannot go on by itself (its source failed, its cell loop panicked) stops
//! the process with status 1 after the same, the log naming the cell and
//! why, so that its supervisor starts it again.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::signals::{Hangups, StopSignals};
use super::Failure;
use crate::agent;
use crate::config::{self, CellConfig};

pub(super) fn load(path: &Path) -> Result<CellConfig, Failure> {
    config::load(path).map_err(|e| Failure::Input(e.to_string()))
}

/// A start failure: bad input if the configuration is at fault.
pub(super) fn start_failure(e: agent::StartError) -> Failure {
    if e.is_input() {
        Failure::input(e)
    } else {
        Failure::runtime(e)
    }
}

/// `cellwatch validate CONFIG`: everything `run` compiles, nothing it
/// connects to.
pub(crate) fn validate(args: &ValidateArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let c = load(&args.config)?;
    crate::cell::compile::engine(&c)
        .map_err(|e| Failure::Input(format!("{}: {e}", args.config.display())))?;
    let keys = match &c.operators_file {
        Some(path) => crate::operator::OperatorKeys::load(path).map_err(Failure::input)?,
        None => crate::operator::OperatorKeys::default(),
    };
    let mut warnings = c.warnings.clone();
    if let Some(server) = &c.alarm_server {
        let users = crate::services::alarm_server::users::Users::load(&server.users_file)
            .map_err(Failure::input)?;
        let gate = crate::operator::Gate::new(&c.cell, keys);
        warnings.extend(
            users
                .cannot_acknowledge(&gate)
                .into_iter()
                .map(|w| format!("{}: {w}", server.users_file.display())),
        );
    }
    crate::bus::session_config(&c.zenoh)
        .map_err(|e| Failure::Input(format!("{}: {e}", args.config.display())))?;
    if let Some(am) = &c.alertmanager {
        crate::sinks::alertmanager::check(am)
            .map_err(|e| Failure::Input(format!("{}: {e}", args.config.display())))?;
    }
    if let Some(sp) = &c.sparkplug {
        crate::sinks::sparkplug::check(sp)
            .map_err(|e| Failure::Input(format!("{}: {e}", args.config.display())))?;
    }
    let io = Failure::output;
    let discrete = c.switching.iter().filter(|s| s.text.is_some()).count();
    let checks: Vec<String> = [
        (c.switching.len() - discrete, "switching-function"),
        (discrete, "discrete"),
        (c.limits.len(), "limit"),
        (c.timers.len(), "timer"),
        (c.sfc.len(), "SFC"),
    ]
    .iter()
    .filter(|(n, _)| *n > 0)
    .map(|(n, what)| format!("{n} {what}"))
    .collect();
    writeln!(
        out,
        "{}: cell {}, {} tags, checks: {}, {}, Zenoh {} {}",
        args.config.display(),
        c.cell,
        c.tags.len(),
        if checks.is_empty() {
            "none".to_string()
        } else {
            checks.join(", ")
        },
        match (&c.opcua, &c.legacy) {
            (Some(o), _) => format!("OPC UA {} ({} {:?})", o.endpoint, o.policy.as_str(), o.mode),
            (None, Some(l)) => l.describe(),
            (None, None) => "no source".into(),
        },
        c.zenoh.mode.as_str(),
        c.zenoh.prefix
    )
    .map_err(io)?;
    for w in &warnings {
        writeln!(out, "warning: {w}").map_err(io)?;
    }
    writeln!(out, "ok").map_err(io)
}

/// `cellwatch run CONFIG...`: one agent per configuration, in this
/// process, until a stop signal or one cannot go on. Cells reading the
/// same `@` bus share one poller on it.
pub(crate) async fn run(args: &RunArgs) -> Result<(), Failure> {
    let mut signals = StopSignals::listen()?;
    let mut hangups = Hangups::listen()?;
    let mut configs = Vec::new();
    for path in &args.config {
        configs.push((path.clone(), load(path)?));
    }
    distinct(&configs)?;
    // Only cells on an `@` bus need their tags here (a 100,000-tag OPC UA
    // cell's would be a copy held for nothing).
    let cells: Vec<_> = configs
        .iter()
        .map(|(p, c)| {
            let tags = c
                .legacy
                .as_ref()
                .map(|_| c.tags.clone())
                .unwrap_or_default();
            (p.display().to_string(), c.legacy.clone(), tags)
        })
        .collect();
    let (shares, buses) = crate::sources::at_bus::share_buses(&cells).map_err(Failure::input)?;
    drop(cells);
    let mut agents = Vec::new();
    let mut started = Vec::new();
    let mut paths = Vec::new();
    // One health for every cell of the process: each metrics port's
    // `/healthz` and systemd's watchdog cover them all.
    let health = crate::health::Health::default();
    for ((path, c), share) in configs.into_iter().zip(shares) {
        let cell = c.cell.clone();
        let options = agent::Options {
            source: share.map(|s| Box::new(s) as Box<dyn crate::sources::Source>),
            health: Some(health.clone()),
            reads_its_file: true,
            ..agent::Options::default()
        };
        match agent::start_with(c, options).await {
            Ok(agent) => {
                let zenoh = agent.zenoh_locators().await.join(",");
                let metrics = agent
                    .metrics_addr()
                    .map_or_else(|| "off".to_string(), |a| a.to_string());
                // Tests and scripts read the ports from this line (port 0
                // in the configuration: the ones the system chose).
                tracing::info!(cell, %zenoh, %metrics, "agent running");
                agents.push(agent);
                started.push(cell);
                paths.push(path);
            }
            Err(e) => {
                for agent in agents {
                    agent.stop().await;
                }
                let e = start_failure(e);
                return Err(match e {
                    Failure::Input(m) => Failure::Input(format!("{}: {m}", path.display())),
                    Failure::Runtime(m) => Failure::Runtime(format!("{}: {m}", path.display())),
                });
            }
        }
    }
    let (stop_buses, stopped) = tokio::sync::watch::channel(false);
    let mut pollers = Vec::new();
    for bus in buses {
        let mut stopped = stopped.clone();
        pollers.push(tokio::spawn(bus.run(async move {
            let _ = stopped.wait_for(|s| *s).await;
        })));
    }
    super::systemd::ready(&started);
    let watchdog = super::systemd::watchdog(health);
    enum Event {
        Stop(&'static str),
        Reload,
        Agent(usize, agent::AgentEvent),
    }
    let failed = loop {
        let event = {
            let events = agents.iter_mut().map(|a| Box::pin(a.next_event()));
            tokio::select! {
                signal = signals.recv() => Event::Stop(signal),
                () = hangups.recv() => Event::Reload,
                (event, i, _) = futures_util::future::select_all(events) => Event::Agent(i, event),
            }
        };
        match event {
            Event::Stop(signal) => {
                tracing::info!(signal, "stopping");
                break None;
            }
            Event::Reload => {
                super::systemd::reloading();
                for (agent, path) in agents.iter_mut().zip(&paths) {
                    let _ = reload(agent, path).await;
                }
                super::systemd::ready(&started);
            }
            Event::Agent(i, agent::AgentEvent::ReloadAsked(ask)) => {
                super::systemd::reloading();
                let answer = reload(&mut agents[i], &paths[i]).await;
                let _ = ask
                    .reply
                    .send(answer.map_err(crate::cell::swap::NotReloaded));
                super::systemd::ready(&started);
            }
            Event::Agent(i, agent::AgentEvent::Ended(ended)) => {
                tracing::error!(cell = %started[i], why = %ended, "the agent cannot go on; stopping every cell");
                break Some((i, ended));
            }
        }
    };
    // A second stop signal while the cells stop: asked twice, the process
    // ends at once (what the journal committed is kept).
    tokio::spawn(async move {
        let signal = signals.recv().await;
        tracing::warn!(signal, "stopped again while stopping: exiting now");
        std::process::exit(1);
    });
    super::systemd::stopping();
    if let Some(w) = watchdog {
        w.abort();
    }
    let _ = stop_buses.send(true);
    for agent in agents {
        agent.stop().await;
    }
    for p in pollers {
        let _ = p.await;
    }
    match failed {
        None => Ok(()),
        Some((i, ended)) => Err(Failure::Runtime(format!("cell {}: {ended}", started[i]))),
    }
}

/// Reads `path` again and hands it to its running `agent` (SIGHUP, or an
/// operator's `configure reload`): taken live, or refused with why, the
/// running configuration going on. Logged, and said for the operator.
async fn reload(agent: &mut agent::Agent, path: &Path) -> Result<String, String> {
    let file = path.display().to_string();
    let refused = |why: String| {
        tracing::error!(%file, "the configuration read again is refused, the running one goes on:\n{why}");
        Err(format!(
            "{file}: refused, the running configuration goes on: {why}"
        ))
    };
    let config = match config::load(path) {
        Ok(c) => c,
        Err(e) => return refused(e.to_string()),
    };
    for w in &config.warnings {
        tracing::warn!(%file, "{w}");
    }
    let cell = config.cell.clone();
    match agent.reload(&config).await {
        Ok(r) => {
            tracing::info!(%cell, %file, carried = r.carried, "configuration read again and taken");
            let mut said = format!(
                "{file}: read again and taken ({} alarms carried over)",
                r.carried
            );
            if !r.needs_restart.is_empty() {
                let parts = r.needs_restart.join(", ");
                tracing::warn!(
                    %cell,
                    %file,
                    "changed, but taken only by a restart (the running values go on): {parts}"
                );
                said += &format!("; taken only by a restart: {parts}");
            }
            Ok(said)
        }
        Err(e) => refused(e.to_string()),
    }
}

/// Cells run together must not write to the same journal or answer under
/// the same Zenoh prefix.
fn distinct(configs: &[(PathBuf, CellConfig)]) -> Result<(), Failure> {
    for (i, (a, ca)) in configs.iter().enumerate() {
        for (b, cb) in &configs[..i] {
            let clash = if ca.cell == cb.cell {
                Some(format!("the same cell id '{}'", ca.cell))
            } else if ca.journal.path == cb.journal.path {
                Some(format!("the same journal {}", ca.journal.path.display()))
            } else if ca.zenoh.prefix == cb.zenoh.prefix {
                Some(format!("the same Zenoh prefix '{}'", ca.zenoh.prefix))
            } else {
                None
            };
            if let Some(clash) = clash {
                return Err(Failure::Input(format!(
                    "{} and {} have {clash}",
                    b.display(),
                    a.display()
                )));
            }
        }
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
pub(crate) struct RunArgs {
    /// The cell configurations (TOML), one agent each in this process.
    /// Cells whose `[legacy]` sections name the same bus (serial port or
    /// TCP address) share one poller on it: each injection-moulding unit a
    /// cell of its own, one line. Their poll settings must agree.
    #[arg(required = true, num_args = 1..)]
    pub(crate) config: Vec<PathBuf>,
    /// Run the agent's threads (the cell loops, the OPC UA and `@`
    /// sources, the Zenoh session, the journal writer) under the real-time
    /// policy SCHED_FIFO at this priority, 1–99, instead of sharing the
    /// cores in turn with every other process: an alarm then waits for no
    /// ordinary process on a busy machine (BENCHMARKS.md: the agent's own
    /// latency). Needs root, CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least
    /// PRIORITY (systemd: LimitRTPRIO=); refused otherwise, before any
    /// cell starts. Keep it below the kernel's own real-time threads
    /// (50 on PREEMPT_RT kernels); 10 suits most machines.
    #[arg(long, value_name = "PRIORITY", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub(crate) realtime_priority: Option<u8>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ValidateArgs {
    /// The cell configuration (TOML).
    pub(crate) config: PathBuf,
}
