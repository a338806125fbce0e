//! Agents with nothing to do, side by side: `cells` simulated cells of
//! `tags` Boolean tags each (plus the ten limit switches), none changing,
//! each its own load server (in this process) and its own agent (`cellwatch
//! run`, its own process, Zenoh in peer mode on its own port). Measured
//! once every agent is subscribed and a settling pause has passed: each
//! agent's CPU over the window (utime + stime from `/proc/PID/stat`, and the
//! scheduler's own nanoseconds summed over its threads from
//! `/proc/PID/task/*/schedstat`), its resident memory (anonymous and
//! file-backed) and its threads.
//!
//! Several agent binaries are measured in turn, in rounds (A B A B …), on
//! the same machine in the same run: the first is the baseline of the
//! ratios.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::cell::{self, Load, Security, Subscription};
use crate::load::LoadServer;
use crate::measure;

/// How an idle run is set up.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The `cellwatch` binaries, measured in turn; the first is the
    /// baseline.
    pub agents: Vec<PathBuf>,
    /// Where the agents' directories go.
    pub workdir: PathBuf,
    /// Cells (agents) side by side.
    pub cells: usize,
    /// Noise tags of each cell (none changes).
    pub tags: usize,
    /// The agents' OPC UA security.
    pub security: Security,
    /// The agents' publishing interval.
    pub publishing: Duration,
    /// How long the agents are measured, once settled.
    pub seconds: Duration,
    /// Times each binary is measured, alternating.
    pub rounds: usize,
}

/// After every agent is ready, before the window opens: the agents'
/// start-up work (reading the cell, subscribing, the first values
/// journaled) is over.
const SETTLE: Duration = Duration::from_secs(10);

/// One agent's figures over the window.
#[derive(Debug, Clone, Copy)]
struct Figures {
    /// CPU seconds per second, from `/proc/PID/stat` (10 ms ticks).
    cpu_ticks: f64,
    /// CPU seconds per second, from the threads' `schedstat` (ns).
    cpu_sched: f64,
    rss: u64,
    /// Proportional set size: shared pages split among their sharers.
    pss: u64,
    anon: u64,
    file: u64,
    threads: u64,
}

/// Runs every round and prints the table.
pub async fn run(setup: &Setup) -> anyhow::Result<String> {
    let _ = std::fs::remove_dir_all(&setup.workdir);
    std::fs::create_dir_all(&setup.workdir)?;
    let mut rows = Vec::new();
    for round in 1..=setup.rounds {
        for (a, agent) in setup.agents.iter().enumerate() {
            let dir = setup.workdir.join(format!("round{round}-agent{a}"));
            let figures = measure_agents(setup, agent, &dir).await?;
            let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
            rows.push((round, a, figures, load));
        }
    }
    Ok(table(setup, &rows))
}

/// Starts the cells and their agents, lets them settle, measures them.
async fn measure_agents(setup: &Setup, agent: &Path, dir: &Path) -> anyhow::Result<Vec<Figures>> {
    let load = Load {
        tags: setup.tags,
        rate: 0,
    };
    let mut cells = Vec::new();
    for i in 0..setup.cells {
        let cdir = dir.join(format!("c{i:02}"));
        std::fs::create_dir_all(&cdir)?;
        let server = LoadServer::start(
            "127.0.0.1:0".parse()?,
            &cdir.join("server-pki"),
            setup.tags,
            i as u64,
            0,
        )
        .await?;
        let (zenoh_port, metrics_port) = (cell::free_port()?, cell::free_port()?);
        std::fs::write(cdir.join("tags.csv"), cell::tags_csv(load))?;
        let config = cdir.join("cell.toml");
        std::fs::write(
            &config,
            cell::agent_config(
                &format!("c{i:02}"),
                &server.endpoint(),
                setup.security,
                Subscription {
                    publishing: setup.publishing,
                    max_notifications: None,
                    verify_interval: None,
                },
                &format!("mode = \"peer\"\nlisten = [\"tcp/127.0.0.1:{zenoh_port}\"]"),
                metrics_port,
            ),
        )?;
        if setup.security == Security::SignEncrypt {
            std::fs::write(cdir.join("fault.il"), cell::program())?;
            cell::trust(&config, &cdir.join("server-pki"))?;
        }
        let child = cell::spawn_agent(agent, &cdir, None)?;
        let metrics: SocketAddr = format!("127.0.0.1:{metrics_port}").parse()?;
        cells.push((server, child, metrics, cdir));
    }
    let result = async {
        for (_, child, metrics, cdir) in &mut cells {
            cell::wait_ready(child, *metrics, cdir).await?;
        }
        tokio::time::sleep(SETTLE).await;
        let pids: Vec<u32> = cells.iter().map(|c| c.1.id()).collect();
        let before: Vec<(f64, f64)> = pids
            .iter()
            .map(|&p| Ok((measure::cpu_seconds(p)?, sched_seconds(p)?)))
            .collect::<anyhow::Result<_>>()?;
        let t0 = Instant::now();
        tokio::time::sleep(setup.seconds).await;
        let mut figures = Vec::new();
        for (&pid, (ticks0, sched0)) in pids.iter().zip(before) {
            let (ticks, sched) = (measure::cpu_seconds(pid)?, sched_seconds(pid)?);
            let wall = t0.elapsed().as_secs_f64();
            let status = Status::of(pid)?;
            figures.push(Figures {
                cpu_ticks: (ticks - ticks0) / wall,
                cpu_sched: (sched - sched0) / wall,
                rss: status.kb("VmRSS:") * 1024,
                pss: Status::rollup(pid)?.kb("Pss:") * 1024,
                anon: status.kb("RssAnon:") * 1024,
                file: status.kb("RssFile:") * 1024 + status.kb("RssShmem:") * 1024,
                threads: status.kb("Threads:"),
            });
        }
        anyhow::Ok(figures)
    }
    .await;
    for (server, child, _, _) in cells {
        cell::stop_agent(child);
        server.stop();
    }
    result
}

/// A process's `/proc/PID/status`.
struct Status(String);

impl Status {
    fn of(pid: u32) -> anyhow::Result<Status> {
        Ok(Status(
            std::fs::read_to_string(format!("/proc/{pid}/status"))
                .with_context(|| format!("process {pid} is gone"))?,
        ))
    }

    /// The process's `/proc/PID/smaps_rollup` (its memory summed over
    /// its mappings), read as a status.
    fn rollup(pid: u32) -> anyhow::Result<Status> {
        Ok(Status(
            std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup"))
                .with_context(|| format!("process {pid} is gone"))?,
        ))
    }

    /// The first number after `key` (kB for sizes, a count for
    /// `Threads:`); 0 when absent.
    fn kb(&self, key: &str) -> u64 {
        self.0
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    }
}

/// CPU seconds a process's live threads have run, by the scheduler's own
/// count (`/proc/PID/task/TID/schedstat`, nanoseconds).
fn sched_seconds(pid: u32) -> anyhow::Result<f64> {
    let mut ns = 0u64;
    for task in std::fs::read_dir(format!("/proc/{pid}/task"))
        .with_context(|| format!("process {pid} is gone"))?
    {
        let path = task?.path().join("schedstat");
        // A thread may end between the listing and the read.
        if let Ok(s) = std::fs::read_to_string(path) {
            ns += s
                .split_whitespace()
                .next()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or(0);
        }
    }
    Ok(ns as f64 / 1e9)
}

/// The median and the maximum of `v`.
fn median_max(v: &[f64]) -> (f64, f64) {
    (
        measure::quantile(v, 0.5).unwrap_or(0.0),
        v.iter().copied().fold(0.0, f64::max),
    )
}

fn table(setup: &Setup, rows: &[(usize, usize, Vec<Figures>, String)]) -> String {
    let mut out = format!(
        "{} cell(s) of {} tags side by side, nothing changing, security {}, publishing {} ms, \
         measured {} s after {} s settled\n\n\
         | round | agent | CPU ms/s per agent, stat: mean | schedstat: median / max | ÷ baseline | \
         RSS MB median / max | PSS MB median / max | anon / file MB (median) | threads | \
         load average (1/5/15 min) |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
        setup.cells,
        setup.tags,
        setup.security.label(),
        setup.publishing.as_millis(),
        setup.seconds.as_secs(),
        SETTLE.as_secs(),
    );
    let mb = |b: f64| b / 1048576.0;
    let sched_median =
        |f: &[Figures]| median_max(&f.iter().map(|x| x.cpu_sched).collect::<Vec<_>>()).0;
    let baseline: Vec<f64> = rows
        .iter()
        .filter(|r| r.1 == 0)
        .map(|r| sched_median(&r.2))
        .collect();
    let baseline = baseline.iter().sum::<f64>() / baseline.len().max(1) as f64;
    for (round, a, f, load) in rows {
        let n = f.len().max(1) as f64;
        let ticks = f.iter().map(|x| x.cpu_ticks).sum::<f64>() / n;
        let (sm, sx) = median_max(&f.iter().map(|x| x.cpu_sched).collect::<Vec<_>>());
        let (rm, rx) = median_max(&f.iter().map(|x| x.rss as f64).collect::<Vec<_>>());
        let (pm, px) = median_max(&f.iter().map(|x| x.pss as f64).collect::<Vec<_>>());
        let anon = median_max(&f.iter().map(|x| x.anon as f64).collect::<Vec<_>>()).0;
        let file = median_max(&f.iter().map(|x| x.file as f64).collect::<Vec<_>>()).0;
        let threads = median_max(&f.iter().map(|x| x.threads as f64).collect::<Vec<_>>()).0;
        let load: Vec<&str> = load.split_whitespace().take(3).collect();
        out.push_str(&format!(
            "| {round} | {} | {:.2} | {:.2} / {:.2} | {:.2}× | {:.1} / {:.1} | {:.1} / {:.1} | {:.1} / {:.1} | \
             {threads:.0} | {} |\n",
            setup.agents[*a].display(),
            ticks * 1e3,
            sm * 1e3,
            sx * 1e3,
            sm / baseline.max(1e-12),
            mb(rm),
            mb(rx),
            mb(pm),
            mb(px),
            mb(anon),
            mb(file),
            load.join(" "),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_threads_are_counted_by_the_scheduler() {
        let pid = std::process::id();
        let t = sched_seconds(pid).unwrap();
        let mut x = 0u64;
        for i in 0..5_000_000u64 {
            x = x.wrapping_add(i * i);
        }
        assert!(x > 0);
        assert!(sched_seconds(pid).unwrap() > t);
        assert!(Status::of(pid).unwrap().kb("Threads:") >= 1);
        assert!(Status::rollup(pid).unwrap().kb("Pss:") > 0);
    }
}
