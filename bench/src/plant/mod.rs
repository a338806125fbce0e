//! The plant at scale: `cells` simulated cells on this host, each its own
//! OPC UA server (a load server in this process, Basic256Sha256 +
//! SignAndEncrypt) and its own agent (`cellwatch run`, its own process),
//! every file made by `cellwatch plant init` from one inventory; the plant's
//! routers (`cellwatch router`, their access control and archive as the
//! plant made them, each its own process); the console (`cellwatch
//! console`, plain HTTP on loopback, its bus session a client of the
//! routers); and Prometheus (Debian's, when installed) scraping every agent
//! from the plant's targets file.
//!
//! Measured, in order:
//! 1. one agent alone (the others not started) for a quiet minute: its CPU
//!    and resident memory, the baseline of each agent's share;
//! 2. the whole plant for `seconds`, a limit switch opening once every
//!    `fault_every` in each cell at its own phase: the agents' total CPU and
//!    memory, each router's, the console's and Prometheus's; each alarm's
//!    latency from the switch's source timestamp to the console's event
//!    stream, and (the baseline) to a bare subscriber on the last router;
//! 3. the first router killed (`SIGKILL`): how long until every agent's
//!    liveliness token is back at the last router, and until the console's
//!    plant says every agent is up again; faults go on through it, and
//!    every one must reach the console.

mod make;
mod parts;
mod watch;

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant, SystemTime};

use anyhow::{bail, Context};

use crate::alarms::{self, Generator, Seen};
use crate::cell::{self};
use crate::console_bounds::sign_in;
use crate::load::LoadServer;
use crate::measure;

use make::{as_on_host, console, inventory, prometheus, ready, router, spawn_agent};
pub use parts::Setup;
use parts::{Cell, Process, ALONE, BACK_WITHIN};
use watch::{console_alarms, console_back, targets_up, Bus, Pids};

/// Runs the plant and prints its tables.
pub async fn run(setup: &Setup) -> anyhow::Result<String> {
    let agent = std::fs::canonicalize(&setup.agent)
        .with_context(|| format!("the agent {}", setup.agent.display()))?;
    let setup = &Setup {
        agent,
        ..setup.clone()
    };
    let _ = std::fs::remove_dir_all(&setup.workdir);
    std::fs::create_dir_all(&setup.workdir)?;
    let dir = std::fs::canonicalize(&setup.workdir)?;
    let mut cells = Vec::new();
    for i in 0..setup.cells {
        let id = format!("c{i:02}");
        let server = LoadServer::start(
            "127.0.0.1:0".parse()?,
            &dir.join("servers").join(&id),
            setup.load.tags,
            i as u64,
            5,
        )
        .await?;
        cells.push(Cell {
            metrics: "127.0.0.1:0".parse()?,
            config: PathBuf::new(),
            id,
            server,
            agent: None,
            generator: None,
        });
    }
    // Every server listening first: a port one of them took after it was
    // picked for an agent's metrics would be nobody's to bind.
    let mut taken: HashSet<u16> = cells.iter().map(|c| c.server.port()).collect();
    for c in &mut cells {
        let port = loop {
            let p = cell::free_port()?;
            if taken.insert(p) {
                break p;
            }
        };
        c.metrics.set_port(port);
    }
    let ports: Vec<u16> = (0..setup.routers)
        .map(|_| cell::free_udp_port())
        .collect::<anyhow::Result<_>>()?;
    let operator = cellwatch::operator::OperatorKey::generate("bench");
    inventory(setup, &dir, &cells, &ports, &operator)?;
    let made = Command::new(&setup.agent)
        .args(["plant", "init"])
        .current_dir(&dir)
        .output()
        .context("cannot run cellwatch plant init")?;
    if !made.status.success() {
        bail!(
            "cellwatch plant init: {}{}",
            String::from_utf8_lossy(&made.stdout),
            String::from_utf8_lossy(&made.stderr)
        );
    }
    for c in &mut cells {
        c.config = as_on_host(&dir, &c.id)?;
        cell::trust(&c.config, &dir.join("servers").join(&c.id))?;
    }
    let mut routers = Vec::new();
    for r in 1..=setup.routers {
        routers.push(router(&setup.agent, &dir, r)?);
    }
    let (console, console_addr) = console(setup, &dir, &ports, &operator)?;
    let prometheus = match &setup.prometheus {
        Some(p) => Some(prometheus(p, &dir)?),
        None => None,
    };
    let last = format!("quic/127.0.0.1:{}", ports[ports.len() - 1]);
    let bus = Bus::open(&dir, &last).await?;
    let cookie = sign_in(console_addr, None, &operator).await?;
    let (at_console, known_to_console) = console_alarms(console_addr, cookie.clone()).await?;

    // 1. One agent alone.
    let lone = {
        let c = &mut cells[0];
        c.agent = Some(spawn_agent(&setup.agent, c)?);
        ready(c, &dir).await?;
        let pid = c.agent.as_ref().map(Process::pid).unwrap_or_default();
        let (cpu0, t0) = (measure::cpu_seconds(pid)?, Instant::now());
        tokio::time::sleep(ALONE).await;
        let cpu = (measure::cpu_seconds(pid)? - cpu0) / t0.elapsed().as_secs_f64();
        (cpu, measure::rss(pid)?.0)
    };

    // 2. The whole plant.
    for c in &mut cells[1..] {
        c.agent = Some(spawn_agent(&setup.agent, c)?);
    }
    for c in &mut cells {
        ready(c, &dir).await?;
    }
    bus.all_alive(setup.cells, BACK_WITHIN).await?;
    let n = cells.len() as u32;
    for (i, c) in cells.iter_mut().enumerate() {
        tokio::time::sleep(setup.fault_every / n).await;
        c.generator = Some(Generator::start(
            &c.server,
            setup.load.rate,
            setup.fault_every,
            setup.fault_every / 2,
            100 + i as u64,
        ));
    }
    let pids = Pids::of(
        &cells,
        &routers,
        &console,
        prometheus.as_ref().map(|p| &p.0),
    );
    let before = pids.cpu()?;
    let started = Instant::now();
    tokio::time::sleep(setup.seconds).await;
    let wall = started.elapsed().as_secs_f64();
    let steady = pids.cpu()?.since(&before, wall, &pids)?;
    let rss: Vec<u64> = pids
        .agents
        .iter()
        .map(|&p| measure::rss(p).map(|r| r.0))
        .collect::<anyhow::Result<_>>()?;
    let targets = match &prometheus {
        Some((_, port)) => Some(targets_up(*port).await),
        None => None,
    };
    let faults_before_kill: usize = cells.iter().map(|c| c.generator_faults()).sum();

    // 3. The first router killed.
    let mut first = routers.remove(0);
    let (killed, killed_at) = (Instant::now(), SystemTime::now());
    first.child.kill()?;
    let _ = first.child.wait();
    let console_view = tokio::spawn(console_back(
        console_addr,
        cookie.clone(),
        setup.cells,
        killed,
    ));
    let on_bus = bus.back_after_loss(setup.cells, BACK_WITHIN).await;
    let at_console_back = console_view.await?;
    // A full fault period after the kill, every cell has faulted again.
    tokio::time::sleep(setup.fault_every).await;

    // Every fault's alarm, matched.
    let mut faults = Vec::new();
    for c in &mut cells {
        if let Some(g) = c.generator.take() {
            faults.push((c.id.clone(), g.stop().1));
        }
    }
    // The last faults' alarms may still be on their way.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let matched = |seen: &Seen| {
        let seen = seen.lock().map(|m| m.clone()).unwrap_or_default();
        let (mut latencies, mut missed) = (Vec::new(), Vec::new());
        for (cell, fs) in &faults {
            let each = alarms::match_each(fs, seen.get(cell).map_or(&[][..], Vec::as_slice));
            for (f, l) in fs.iter().zip(each) {
                match l {
                    Some(l) => latencies.push(l),
                    // When, from the kill.
                    None => missed.push(format!(
                        "{cell} at {:+.1} s",
                        match f.at.duration_since(killed_at) {
                            Ok(d) => d.as_secs_f64(),
                            Err(e) => -e.duration().as_secs_f64(),
                        }
                    )),
                }
            }
        }
        (latencies, missed)
    };
    let total: usize = faults.iter().map(|(_, f)| f.len()).sum();
    let (console_l, console_missed) = matched(&at_console);
    let (_, console_unknown) = matched(&known_to_console);
    let (bus_l, bus_missed) = matched(&bus.seen);
    // What the last router's archive keeps of them.
    let (archived, archive_error) = match archived(setup, &dir, &last) {
        Ok(a) => (a, None),
        Err(e) => (HashMap::new(), Some(format!("{e:#}"))),
    };
    let archive_missed: Vec<String> = faults
        .iter()
        .filter_map(|(cell, fs)| {
            let kept = archived.get(cell).copied().unwrap_or(0);
            (kept < fs.len()).then(|| format!("{cell}: {kept} of {}", fs.len()))
        })
        .collect();

    for c in cells {
        if let Some(a) = c.agent {
            a.stop();
        }
        c.server.stop();
    }
    drop(console);
    drop(routers);

    let ms =
        |v: &[f64], q| measure::quantile(v, q).map_or("-".into(), |s| format!("{:.1}", s * 1e3));
    let mb = |b: u64| b as f64 / 1048576.0;
    let agents_rss: u64 = rss.iter().sum();
    let per_agent_cpu = steady.agents / setup.cells as f64;
    let per_agent_rss = agents_rss / setup.cells as u64;
    let mut out = format!(
        "| | cells | CPU (% of a core) | RSS (MB) |\n|---|---|---|---|\n\
         | one agent alone (baseline) | 1 | {:.2} | {:.1} |\n\
         | every agent | {} | {:.1} | {:.1} |\n\
         | per agent | | {:.2} (**{:.2}×** alone) | {:.1} (**{:.2}×** alone) |\n",
        lone.0 * 100.0,
        mb(lone.1),
        setup.cells,
        steady.agents * 100.0,
        mb(agents_rss),
        per_agent_cpu * 100.0,
        per_agent_cpu / lone.0.max(1e-9),
        mb(per_agent_rss),
        per_agent_rss as f64 / lone.1.max(1) as f64,
    );
    for (i, r) in steady.routers.iter().enumerate() {
        out.push_str(&format!(
            "| router-{} | | {:.1} | {:.1} |\n",
            i + 1,
            r.0 * 100.0,
            mb(r.1)
        ));
    }
    out.push_str(&format!(
        "| console | | {:.1} | {:.1} |\n",
        steady.console.0 * 100.0,
        mb(steady.console.1)
    ));
    if let Some((cpu, rss)) = steady.prometheus {
        out.push_str(&format!(
            "| Prometheus | | {:.1} | {:.1} |\n",
            cpu * 100.0,
            mb(rss)
        ));
    }
    out.push_str(&format!(
        "\n- measured over {wall:.0} s, {total} faults in all ({} before the kill)\n",
        faults_before_kill
    ));
    match targets {
        Some(Ok((up, all))) => out.push_str(&format!("- Prometheus: {up} of {all} targets up\n")),
        Some(Err(e)) => out.push_str(&format!("- Prometheus's targets not read: {e:#}\n")),
        None => {}
    }
    out.push_str(&format!(
        "\n| alarm latency, switch → | alarms / faults | p50 (ms) | p99 (ms) | max (ms) |\n|---|---|---|---|---|\n\
         | a bare subscriber on the last router (baseline) | {} / {total} | {} | {} | {} |\n\
         | the console's event stream | {} / {total} | {} | {} | {} |\n\
         \n- console p50 / bare subscriber p50: **{:.2}**\n",
        bus_l.len(),
        ms(&bus_l, 0.5),
        ms(&bus_l, 0.99),
        ms(&bus_l, 1.0),
        console_l.len(),
        ms(&console_l, 0.5),
        ms(&console_l, 0.99),
        ms(&console_l, 1.0),
        measure::quantile(&console_l, 0.5).unwrap_or(0.0)
            / measure::quantile(&bus_l, 0.5).unwrap_or(1.0).max(1e-9),
    ));
    let secs = |r: &anyhow::Result<Option<Duration>>, none: &str| match r {
        Ok(Some(d)) => format!("{:.1} s", d.as_secs_f64()),
        Ok(None) => none.to_string(),
        Err(e) => format!("not within {} s: {e}", BACK_WITHIN.as_secs()),
    };
    out.push_str(&format!(
        "- router-1 killed: every agent's token back at router-{}: {}; the console's plant whole again: {}\n",
        setup.routers,
        secs(&on_bus, "none was lost (no agent was on router-1)"),
        secs(&at_console_back, "it never showed one down"),
    ));
    out.push_str(&format!(
        "- raises of the faults in router-{}'s archive (`cellwatch history --plant`): {} of {total}\n",
        setup.routers,
        archived.values().sum::<usize>()
    ));
    if let Some(e) = archive_error {
        out.push_str(&format!("- the archive not read: {e}\n"));
    }
    if !archive_missed.is_empty() {
        out.push_str(&format!(
            "- cells whose raises the archive lacks: {}\n",
            archive_missed.join(", ")
        ));
    }
    out.push_str(&format!(
        "- faults the console showed active (its live raise, or the alarm in a snapshot it asked an agent that came back): {} of {total}\n",
        total - console_unknown.len()
    ));
    for (what, missed) in [
        ("console's live raises", &console_missed),
        ("console's table at all", &console_unknown),
        ("bare subscriber", &bus_missed),
    ] {
        if !missed.is_empty() {
            out.push_str(&format!(
                "- faults not at the {what} (when, from the kill): {}\n",
                missed.join(", ")
            ));
        }
    }
    Ok(out)
}

/// Per cell, how many raises of check `fault` the archive of the router at
/// `endpoint` keeps, read as an operator would (`cellwatch history --plant`,
/// every entry verified).
fn archived(
    setup: &Setup,
    dir: &std::path::Path,
    endpoint: &str,
) -> anyhow::Result<HashMap<String, usize>> {
    let out = Command::new(&setup.agent)
        .args([
            "history", "--plant", "--cell", "*", "--kind", "alarm", "--since", "2h", "--json",
        ])
        .args(["--mode", "client", "--connect", endpoint])
        .arg("--tls-ca")
        .arg(dir.join("ca/ca.pem"))
        .arg("--tls-cert")
        .arg(dir.join("admin/plant-admin.pem"))
        .arg("--tls-key")
        .arg(dir.join("admin/plant-admin.key"))
        .arg("--trust")
        .arg(dir.join("trust.toml"))
        .output()
        .context("cannot run cellwatch history --plant")?;
    anyhow::ensure!(
        out.status.success(),
        "cellwatch history --plant: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut kept = HashMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        if let Some((cell, _)) = alarms::fault_raised(&v) {
            *kept.entry(cell).or_insert(0) += 1;
        }
    }
    Ok(kept)
}
