//! The scale-out recipe measured: many agents in client mode through one
//! Zenoh router, one subscriber for `cellwatch/*/alarms/**`, and beside
//! them one agent in peer mode that the subscriber reaches directly — the
//! baseline for what the router adds.
//!
//! The router is `cellwatch-bench router`: a Zenoh session in router mode,
//! the engine `zenohd` runs (without its plugins), in its own process so
//! its CPU and memory are its own.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};

use crate::alarms::{self, Generator};
use crate::cell::{self, Load, Security};
use crate::load::LoadServer;
use crate::measure;

/// How a fan-out run is set up.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The `cellwatch` binary.
    pub agent: PathBuf,
    /// This binary (started again as the router).
    pub bench: PathBuf,
    /// Where the agents' directories go.
    pub workdir: PathBuf,
    /// Agents through the router.
    pub agents: usize,
    /// Each cell's load.
    pub load: Load,
    /// How long the load runs.
    pub seconds: Duration,
    /// A limit switch opens this often in each cell, for half as long.
    pub fault_every: Duration,
}

/// Serves as a Zenoh router on `listen` until killed.
pub async fn router(listen: &str) -> anyhow::Result<()> {
    let config = cell::zenoh_config("router", &[listen.to_string()], &[])?;
    let _session = zenoh::open(config).await.map_err(|e| anyhow!("{e}"))?;
    println!("ready");
    std::future::pending::<()>().await;
    Ok(())
}

/// One agent of the run and its simulated cell.
struct Cell {
    id: String,
    server: LoadServer,
    child: Child,
    metrics: std::net::SocketAddr,
    generator: Option<Generator>,
}

/// Runs the fan-out and prints its table.
pub async fn run(setup: &Setup) -> anyhow::Result<String> {
    let _ = std::fs::remove_dir_all(&setup.workdir);
    std::fs::create_dir_all(&setup.workdir)?;
    let router_port = cell::free_port()?;
    let router_endpoint = format!("tcp/127.0.0.1:{router_port}");
    let mut router = Command::new(&setup.bench)
        .arg("router")
        .arg("--listen")
        .arg(&router_endpoint)
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(setup.workdir.join("router.log"))?)
        .spawn()
        .with_context(|| format!("cannot start {} router", setup.bench.display()))?;
    {
        use std::io::BufRead;
        let out = router
            .stdout
            .take()
            .ok_or_else(|| anyhow!("the router has no stdout"))?;
        let mut line = String::new();
        std::io::BufReader::new(out).read_line(&mut line)?;
        if line.trim() != "ready" {
            anyhow::bail!("the router did not start (see router.log)");
        }
    }
    let result = measure_cells(setup, &router_endpoint, router.id()).await;
    let _ = router.kill();
    let _ = router.wait();
    result
}

async fn start_cell(setup: &Setup, id: String, zenoh: &str) -> anyhow::Result<Cell> {
    let dir = setup.workdir.join(&id);
    std::fs::create_dir_all(&dir)?;
    let server = LoadServer::start(
        "127.0.0.1:0".parse()?,
        &dir.join("server-pki"),
        setup.load.tags,
        1,
        0,
    )
    .await?;
    let metrics_port = cell::free_port()?;
    std::fs::write(dir.join("tags.csv"), cell::tags_csv(setup.load))?;
    std::fs::write(
        dir.join("cell.toml"),
        cell::agent_config(
            &id,
            &server.endpoint(),
            Security::None,
            cell::Subscription {
                publishing: Duration::from_millis(100),
                max_notifications: None,
                verify_interval: None,
            },
            zenoh,
            metrics_port,
        ),
    )?;
    let child = cell::spawn_agent(&setup.agent, &dir, None)?;
    Ok(Cell {
        id,
        server,
        child,
        metrics: format!("127.0.0.1:{metrics_port}").parse()?,
        generator: None,
    })
}

async fn measure_cells(
    setup: &Setup,
    router_endpoint: &str,
    router_pid: u32,
) -> anyhow::Result<String> {
    let direct_port = cell::free_port()?;
    let mut cells = Vec::new();
    let result = async {
        for i in 0..setup.agents {
            let zenoh = format!("mode = \"client\"\nconnect = [\"{router_endpoint}\"]");
            cells.push(start_cell(setup, format!("cell{i:02}"), &zenoh).await?);
        }
        let direct = format!("mode = \"peer\"\nlisten = [\"tcp/127.0.0.1:{direct_port}\"]");
        cells.push(start_cell(setup, "direct".into(), &direct).await?);
        let (seen, transits) = alarms::subscribe_alarms(
            &[
                router_endpoint.to_string(),
                format!("tcp/127.0.0.1:{direct_port}"),
            ],
            "*",
        )
        .await?;
        for c in &mut cells {
            let dir = setup.workdir.join(&c.id);
            cell::wait_ready(&mut c.child, c.metrics, &dir).await?;
        }
        let cpu0 = measure::cpu_seconds(router_pid)?;
        let started = Instant::now();
        let n = cells.len() as u64;
        for (i, c) in cells.iter_mut().enumerate() {
            // Each cell's faults at its own phase of the period.
            tokio::time::sleep(setup.fault_every / n as u32).await;
            c.generator = Some(Generator::start(
                &c.server,
                setup.load.rate,
                setup.fault_every,
                setup.fault_every / 2,
                10 + i as u64,
            ));
        }
        tokio::time::sleep(setup.seconds).await;
        let (mut routed, mut direct) = (Vec::new(), Vec::new());
        let (mut routed_bus, mut direct_bus) = (Vec::new(), Vec::new());
        let (mut routed_faults, mut direct_faults) = (0, 0);
        for c in &mut cells {
            let Some(g) = c.generator.take() else { continue };
            let (_, faults, _, _) = g.stop();
            // The last fault's alarm may still be on its way.
            tokio::time::sleep(Duration::from_millis(300)).await;
            let s = seen
                .lock()
                .ok()
                .and_then(|m| m.get(&c.id).cloned())
                .unwrap_or_default();
            let l = alarms::match_faults(&faults, &s);
            let bus = transits
                .lock()
                .ok()
                .and_then(|m| m.get(&c.id).cloned())
                .unwrap_or_default();
            if c.id == "direct" {
                direct_faults += faults.len();
                direct.extend(l);
                direct_bus.extend(bus);
            } else {
                routed_faults += faults.len();
                routed.extend(l);
                routed_bus.extend(bus);
            }
        }
        let wall = started.elapsed().as_secs_f64();
        let cpu = measure::cpu_seconds(router_pid)? - cpu0;
        let (_, rss_peak) = measure::rss(router_pid)?;
        let ms = |v: &[f64], q| measure::quantile(v, q).map_or("-".into(), |s| format!("{:.1}", s * 1e3));
        let us = |v: &[f64], q| measure::quantile(v, q).map_or("-".into(), |s| format!("{:.0}", s * 1e6));
        Ok(format!(
            "| path | agents | alarms reported / faults | latency p50 (ms) | p99 (ms) | max (ms) | bus only p50 / p99 / max (µs) |\n\
             |---|---|---|---|---|---|---|\n\
             | through the router (client mode) | {} | {} / {routed_faults} | {} | {} | {} | {} / {} / {} |\n\
             | direct (peer mode, baseline) | 1 | {} / {direct_faults} | {} | {} | {} | {} / {} / {} |\n\n\
             - router: {:.1} % of a core over {wall:.0} s, peak RSS {:.1} MB\n\
             - the router's share of the bus time, median routed minus median direct: {:.0} µs\n",
            setup.agents,
            routed.len(),
            ms(&routed, 0.5),
            ms(&routed, 0.99),
            ms(&routed, 1.0),
            us(&routed_bus, 0.5),
            us(&routed_bus, 0.99),
            us(&routed_bus, 1.0),
            direct.len(),
            ms(&direct, 0.5),
            ms(&direct, 0.99),
            ms(&direct, 1.0),
            us(&direct_bus, 0.5),
            us(&direct_bus, 0.99),
            us(&direct_bus, 1.0),
            cpu / wall * 100.0,
            rss_peak as f64 / 1048576.0,
            share(&routed_bus, &direct_bus, 0.5) * 1e6,
        ))
    }
    .await;
    for c in cells {
        if let Some(g) = c.generator {
            let _ = g.stop();
        }
        cell::stop_agent(c.child);
        c.server.stop();
    }
    result
}

/// Quantile `q` of the routed path's bus time minus the direct path's
/// (0 when either has none).
fn share(routed: &[f64], direct: &[f64], q: f64) -> f64 {
    match (measure::quantile(routed, q), measure::quantile(direct, q)) {
        (Some(r), Some(d)) => r - d,
        _ => 0.0,
    }
}

/// This program's own path (to start it again as the router).
pub fn own_path() -> anyhow::Result<PathBuf> {
    std::env::current_exe().context("cannot tell this program's path")
}
