//! `cellwatch-bench`: the agent measured against a peer, end to end.
//!
//! Run through `bench/run` (docs/README.md, BENCHMARKS.md), which builds the
//! release binaries and the Python baseline's virtual environment first.

// A binary: `pub` marks what its modules offer each other.
#![allow(unreachable_pub)]

mod alarms;
mod alertmanager;
mod cell;
mod console;
mod console_bounds;
mod console_browser;
mod fanout;
mod idle;
mod journal;
mod load;
mod measure;
mod peer;
mod plant;
mod replay;
mod table;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};

/// The agent under load, measured against a peer.
#[derive(Parser)]
#[command(name = "cellwatch-bench", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

// Parsed once per run: the peer benchmark's many options need no box.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Cmd {
    /// The peer benchmark: a load OPC UA server (async-opcua, this build)
    /// toggling Boolean tags and opening limit switches; the agent
    /// (`cellwatch run`, its own process) and the Python asyncua baseline
    /// each subscribe alone to a fresh server and must report every
    /// opened switch as the fault's cause; with `--reference c`, the bare
    /// open62541 client subscribes as the agent does and only counts.
    /// Prints a Markdown table: changes handled per second, CPU, the
    /// agent's CPU per change over the baseline's and the bare client's,
    /// peak RSS, fault → alarm latency, faults reported, notifications
    /// lost, and the ratios.
    Peer {
        /// A load as TAGS:CHANGES_PER_SECOND; repeat for several rows.
        #[arg(long = "load", required = true, value_name = "TAGS:RATE")]
        loads: Vec<cell::Load>,
        /// OPC UA security of the agent's rows; repeat for several.
        #[arg(long = "security", value_enum, default_values_t = [cell::Security::None])]
        security: Vec<cell::Security>,
        /// What stands where the agent's `[alertmanager]` points (`off`:
        /// no section); repeat for several rows.
        #[arg(long = "alertmanager", value_enum, default_values_t = [alertmanager::Alertmanager::Off])]
        alertmanagers: Vec<alertmanager::Alertmanager>,
        /// The agent's `opcua.verify_interval` (every monitored item read
        /// back that often); repeat for several rows. Default: the agent's.
        #[arg(long = "verify-interval", value_parser = humantime::parse_duration)]
        verify_intervals: Vec<Duration>,
        /// How long each load runs.
        #[arg(long, default_value = "20s", value_parser = humantime::parse_duration)]
        duration: Duration,
        /// How the agent is given its tags: `file` (a `tags_file`) or
        /// `toml` (`[[tags]]` tables in its configuration); repeat for
        /// several rows.
        #[arg(long = "tags-in", value_enum, default_values_t = [peer::TagsIn::File])]
        tags_in: Vec<peer::TagsIn>,
        /// Subscription publishing interval (agent and baseline).
        #[arg(long, default_value = "100ms", value_parser = humantime::parse_duration)]
        publishing: Duration,
        /// The agent's `opcua.max_notifications_per_publish` (smaller:
        /// smaller batches, more publishes); default: the agent's.
        #[arg(long, value_name = "N")]
        max_notifications: Option<u32>,
        /// A limit switch opens this often, held open for half of it
        /// (more faults: more alarms for the latency's quantiles).
        #[arg(long, default_value = "500ms", value_parser = humantime::parse_duration)]
        fault_every: Duration,
        /// Alarms each fault raises: the agent's cell gets this many checks
        /// on the one switch (an interlock chain one opened guard breaks:
        /// an alarm flood), the latency measured on the first.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=1000))]
        alarms_per_fault: u16,
        /// Run the load server this much lower in priority than the agent
        /// (niceness, 0–19): it stands in for a PLC on its own hardware,
        /// and with a positive value it does not take the agent's turn on
        /// the cores they share. 0: the same priority.
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(i32).range(0..=19))]
        server_nice: i32,
        /// Run the agent with `--realtime-priority N` (its threads under
        /// SCHED_FIFO at N; needs root or CAP_SYS_NICE).
        #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=99))]
        agent_priority: Option<u8>,
        /// The `cellwatch` binary under test.
        #[arg(long, default_value = "target/release/cellwatch")]
        agent: PathBuf,
        /// A Python with asyncua: run the baseline (security None) for each
        /// load. Without it, only the agent runs.
        #[arg(long)]
        python: Option<PathBuf>,
        /// The baseline script.
        #[arg(long, default_value = "bench/baseline.py")]
        script: PathBuf,
        /// A reference to run as well, for each load and security: `c`,
        /// the bare open62541 client (`--bare-client`).
        #[arg(long = "reference", value_enum)]
        references: Vec<peer::Reference>,
        /// The bare open62541 client (`bench/bare-client`, built by
        /// `bench/run peer --reference c`).
        #[arg(
            long,
            default_value = "target/bare-client/release/cellwatch-bare-client"
        )]
        bare_client: PathBuf,
        /// Where configurations, PKI directories, journals and logs go.
        #[arg(long, default_value = "target/bench-peer")]
        workdir: PathBuf,
        /// How long the baseline may take to catch up after the load stops.
        #[arg(long, default_value = "30s", value_parser = humantime::parse_duration)]
        drain: Duration,
    },
    /// The agent under load from the replay source (an OPC UA server that
    /// re-sends notification messages built once, patching sequence
    /// numbers, timestamps and values), measured as `peer` measures it,
    /// with the source's own CPU beside each row; with `--reference`, the
    /// same load from the load server (async-opcua) in the same run.
    Replay {
        /// A load as TAGS:CHANGES_PER_SECOND; repeat for several rows.
        #[arg(long = "load", required = true, value_name = "TAGS:RATE")]
        loads: Vec<cell::Load>,
        /// OPC UA security of the agent's session; repeat for several.
        #[arg(long = "security", value_enum, default_values_t = [replay::bench::ReplaySecurity::None])]
        security: Vec<replay::bench::ReplaySecurity>,
        /// Also the same load from the load server (security None).
        #[arg(long)]
        reference: bool,
        /// How long each load runs.
        #[arg(long, default_value = "20s", value_parser = humantime::parse_duration)]
        duration: Duration,
        /// Subscription publishing interval.
        #[arg(long, default_value = "100ms", value_parser = humantime::parse_duration)]
        publishing: Duration,
        /// The agent's `opcua.max_notifications_per_publish`.
        #[arg(long, value_name = "N")]
        max_notifications: Option<u32>,
        /// A limit switch opens this often, held open for half of it.
        #[arg(long, default_value = "500ms", value_parser = humantime::parse_duration)]
        fault_every: Duration,
        /// The `cellwatch` binary under test.
        #[arg(long, default_value = "target/release/cellwatch")]
        agent: PathBuf,
        /// Where configurations, PKI directories, journals and logs go.
        #[arg(long, default_value = "target/bench-replay")]
        workdir: PathBuf,
    },
    /// The scale-out recipe: `--agents` agents in client mode, each with
    /// its own simulated cell, through one Zenoh router (a router-mode
    /// session, the engine of zenohd, in its own process), and one agent in
    /// peer mode reached directly as the baseline; one subscriber for
    /// `cellwatch/*/alarms/**`. Prints the fault → alarm latency of both
    /// paths and the router's CPU and memory.
    Fanout {
        /// Agents through the router.
        #[arg(long, default_value_t = 20)]
        agents: usize,
        /// Each cell's load as TAGS:CHANGES_PER_SECOND.
        #[arg(long, default_value = "100:1000")]
        load: cell::Load,
        /// How long the load runs.
        #[arg(long, default_value = "30s", value_parser = humantime::parse_duration)]
        duration: Duration,
        /// A limit switch opens this often in each cell.
        #[arg(long, default_value = "1s", value_parser = humantime::parse_duration)]
        fault_every: Duration,
        /// The `cellwatch` binary.
        #[arg(long, default_value = "target/release/cellwatch")]
        agent: PathBuf,
        /// Where the agents' directories go.
        #[arg(long, default_value = "target/bench-fanout")]
        workdir: PathBuf,
    },
    /// Agents with nothing to do, side by side: CELLS cells of TAGS tags,
    /// none changing, each its own load server and agent. Prints each
    /// agent's CPU (from `/proc/PID/stat` and from its threads'
    /// `schedstat`), resident memory (median, max; anonymous and
    /// file-backed) and threads; several `--agent`s are measured in turn,
    /// the first the baseline of the ratios.
    Idle {
        /// Cells (agents) side by side.
        #[arg(long, default_value_t = 1)]
        cells: usize,
        /// Noise tags of each cell (the ten limit switches come on top).
        #[arg(long, default_value_t = 100)]
        tags: usize,
        /// How long the agents are measured, once settled.
        #[arg(long, default_value = "30s", value_parser = humantime::parse_duration)]
        duration: Duration,
        /// The agents' OPC UA security.
        #[arg(long, value_enum, default_value_t = cell::Security::None)]
        security: cell::Security,
        /// The agents' publishing interval.
        #[arg(long, default_value = "100ms", value_parser = humantime::parse_duration)]
        publishing: Duration,
        /// A `cellwatch` binary; repeat to measure several in turn.
        #[arg(long = "agent", default_values_t = [String::from("target/release/cellwatch")])]
        agents: Vec<String>,
        /// Times each binary is measured, alternating.
        #[arg(long, default_value_t = 1)]
        rounds: usize,
        /// Where the agents' directories go.
        #[arg(long, default_value = "target/bench-idle")]
        workdir: PathBuf,
    },
    /// The plant at scale: CELLS simulated cells on this host, each its
    /// own OPC UA server (in this process, Basic256Sha256 +
    /// SignAndEncrypt) and agent, every file made by `cellwatch plant
    /// init` from one inventory; ROUTERS `cellwatch router`s with the
    /// plant's access control and archive; the console; Prometheus
    /// scraping every agent when `--prometheus` names it. Measures one
    /// agent alone (the baseline), then the whole plant: CPU and memory
    /// of the agents, routers, console and Prometheus; each alarm's
    /// latency to the console's event stream and to a bare subscriber;
    /// then kills the first router and measures how long until every
    /// agent and the console are back, every fault still reaching the
    /// console.
    Plant {
        /// Simulated cells.
        #[arg(long, default_value_t = 50)]
        cells: usize,
        /// Routers (agents and the console are clients of every one).
        #[arg(long, default_value_t = 2)]
        routers: usize,
        /// Each cell's noise as TAGS:CHANGES_PER_SECOND.
        #[arg(long, default_value = "20:10")]
        load: cell::Load,
        /// How long the whole plant is measured before the kill.
        #[arg(long, default_value = "5m", value_parser = humantime::parse_duration)]
        duration: Duration,
        /// A limit switch opens this often in each cell (each cell at its
        /// own phase), held open for half of it.
        #[arg(long, default_value = "60s", value_parser = humantime::parse_duration)]
        fault_every: Duration,
        /// Prometheus's binary; without it none runs.
        #[arg(long)]
        prometheus: Option<PathBuf>,
        /// The `cellwatch` binary.
        #[arg(long, default_value = "target/release/cellwatch")]
        agent: PathBuf,
        /// The plant's folder (emptied first).
        #[arg(long, default_value = "target/bench-plant")]
        workdir: PathBuf,
    },
    /// What the journal costs on disk: ROWS rows each of alarm events
    /// (the demo's ESE raise, one or two culprits), machine states,
    /// commands (verified acknowledgements, hash-chained) and parts,
    /// written through the agent's journal writer; bytes per row per
    /// table, measured with SQLite's dbstat.
    Journal {
        /// Rows of each kind.
        #[arg(long, default_value_t = 100_000)]
        rows: u64,
        /// Where the journal goes.
        #[arg(long, default_value = "target/bench-journal")]
        workdir: PathBuf,
    },
    /// Serves as a Zenoh router on LISTEN until killed (used by `fanout`);
    /// prints `ready` once listening.
    Router {
        /// The endpoint, e.g. tcp/127.0.0.1:7447.
        #[arg(long)]
        listen: String,
    },
    /// The operators' console under a plant's alarms: a publisher seals
    /// alarm events with CELLS agents' keys; the console (`cellwatch
    /// console`, its own process) with its alarm table open in a headless
    /// Chromium, and a bare bus subscriber as the baseline, take them.
    /// Prints when each has all of them, the page's heap and the console's
    /// memory, over four rounds (then every alarm cleared and as many new
    /// raised, three times).
    Console {
        /// Simulated cells.
        #[arg(long, default_value_t = 200)]
        cells: usize,
        /// Alarms active at once.
        #[arg(long, default_value_t = 5000)]
        alarms: usize,
        /// The `cellwatch` binary under test.
        #[arg(long, default_value = "target/release/cellwatch")]
        agent: PathBuf,
        /// Where the configuration, trust file and log go.
        #[arg(long, default_value = "target/bench-console")]
        workdir: PathBuf,
        /// Chromium.
        #[arg(long, default_value = "/usr/bin/chromium")]
        chromium: PathBuf,
        /// Its WebDriver.
        #[arg(long, default_value = "/usr/bin/chromedriver")]
        chromedriver: PathBuf,
        /// A cell's alarms sealed together under one signature, as its
        /// agent seals what one step raises (1: each alone).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=1024))]
        alarms_per_step: u16,
    },
    /// One client's share of the console: an operator from 127.0.0.1
    /// asking the plant and a cell's history, alone and then while
    /// another signed-in operator from 127.0.0.2 opens as many
    /// connections and live streams as it can and floods requests
    /// (`/api/kpi?since=1970-01-01` among them). Stand-in agents answer
    /// each cell's history, sealed. Prints the operator's latencies, their
    /// ratio, and what the attacker got.
    ConsoleBounds {
        /// Cells the console reads.
        #[arg(long, default_value_t = 8)]
        cells: usize,
        /// How long each phase lasts.
        #[arg(long, default_value = "20s", value_parser = humantime::parse_duration)]
        phase: Duration,
        /// Connections the attacker tries to hold.
        #[arg(long, default_value_t = 200)]
        connections: usize,
        /// The `cellwatch` binary under test.
        #[arg(long, default_value = "target/release/cellwatch")]
        agent: PathBuf,
        /// Where the configuration, trust file and log go.
        #[arg(long, default_value = "target/bench-console-bounds")]
        workdir: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The load server's and the router's own warnings (dropped
    // notifications, refused sessions) go to stderr.
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("cellwatch-bench: cannot start the runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(run(cli)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("cellwatch-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}

async fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Cmd::Peer {
            loads,
            security,
            alertmanagers,
            verify_intervals,
            tags_in,
            duration: seconds,
            publishing,
            max_notifications,
            fault_every,
            alarms_per_fault,
            server_nice,
            agent_priority,
            agent,
            python,
            script,
            references,
            bare_client,
            workdir,
            drain,
        } => {
            let mut setup = peer::Setup {
                tags_in: peer::TagsIn::File,
                agent,
                python,
                script,
                workdir,
                seconds,
                publishing,
                max_notifications,
                fault_every,
                fault_hold: fault_every / 2,
                server_nice,
                agent_priority,
                drain,
                bare_client: references
                    .contains(&peer::Reference::C)
                    .then_some(bare_client),
                alarms_per_fault: usize::from(alarms_per_fault),
            };
            let mut rows = Vec::new();
            for &load in &loads {
                for &s in &security {
                    for &am in &alertmanagers {
                        let verify: Vec<Option<Duration>> = if verify_intervals.is_empty() {
                            vec![None]
                        } else {
                            verify_intervals.iter().copied().map(Some).collect()
                        };
                        for v in verify {
                            for &t in &tags_in {
                                setup.tags_in = t;
                                eprintln!(
                                    "cellwatch-bench: agent, {} tags, {}/s, {s:?}, Alertmanager {am:?}, verify {v:?}, tags in {t:?}",
                                    load.tags, load.rate
                                );
                                rows.push(peer::agent(&setup, load, s, am, v).await?);
                            }
                        }
                    }
                }
                if let Some(python) = &setup.python {
                    eprintln!(
                        "cellwatch-bench: baseline, {} tags, {}/s",
                        load.tags, load.rate
                    );
                    rows.push(peer::baseline(&setup, python, load).await?);
                }
                if let Some(client) = &setup.bare_client {
                    for &s in &security {
                        eprintln!(
                            "cellwatch-bench: bare open62541 client, {} tags, {}/s, {s:?}",
                            load.tags, load.rate
                        );
                        rows.push(peer::bare(&setup, client, load, s).await?);
                    }
                }
            }
            print!("{}", table::table(&rows));
            Ok(())
        }
        Cmd::Replay {
            loads,
            security,
            reference,
            duration: seconds,
            publishing,
            max_notifications,
            fault_every,
            agent,
            workdir,
        } => {
            let setup = peer::Setup {
                tags_in: peer::TagsIn::File,
                agent,
                python: None,
                script: PathBuf::new(),
                workdir,
                seconds,
                publishing,
                max_notifications,
                fault_every,
                fault_hold: fault_every / 2,
                server_nice: 0,
                agent_priority: None,
                drain: Duration::from_secs(30),
                bare_client: None,
                alarms_per_fault: 1,
            };
            print!(
                "{}",
                replay::bench::run(&setup, &loads, &security, reference).await?
            );
            Ok(())
        }
        Cmd::Fanout {
            agents,
            load,
            duration: seconds,
            fault_every,
            agent,
            workdir,
        } => {
            let setup = fanout::Setup {
                agent,
                bench: fanout::own_path()?,
                workdir,
                agents,
                load,
                seconds,
                fault_every,
            };
            print!("{}", fanout::run(&setup).await?);
            Ok(())
        }
        Cmd::Idle {
            cells,
            tags,
            duration: seconds,
            security,
            publishing,
            agents,
            rounds,
            workdir,
        } => {
            let setup = idle::Setup {
                agents: agents.into_iter().map(PathBuf::from).collect(),
                workdir,
                cells,
                tags,
                security,
                publishing,
                seconds,
                rounds,
            };
            print!("{}", idle::run(&setup).await?);
            Ok(())
        }
        Cmd::Router { listen } => fanout::router(&listen).await,
        Cmd::Plant {
            cells,
            routers,
            load,
            duration: seconds,
            fault_every,
            prometheus,
            agent,
            workdir,
        } => {
            anyhow::ensure!(routers >= 2, "--routers: at least 2, one to kill");
            let setup = plant::Setup {
                agent,
                workdir,
                cells,
                routers,
                load,
                seconds,
                fault_every,
                prometheus,
            };
            print!("{}", plant::run(&setup).await?);
            Ok(())
        }
        Cmd::Journal { rows, workdir } => {
            print!("{}", journal::run(&workdir, rows).await?);
            Ok(())
        }
        Cmd::Console {
            cells,
            alarms,
            agent,
            workdir,
            chromium,
            chromedriver,
            alarms_per_step,
        } => {
            let setup = console::Setup {
                agent,
                workdir,
                cells,
                alarms,
                chromium,
                chromedriver,
                alarms_per_step: usize::from(alarms_per_step),
            };
            print!("{}", console::run(&setup).await?);
            Ok(())
        }
        Cmd::ConsoleBounds {
            cells,
            phase,
            connections,
            agent,
            workdir,
        } => {
            let setup = console_bounds::Setup {
                agent,
                workdir,
                cells,
                phase,
                connections,
            };
            print!("{}", console_bounds::run(&setup).await?);
            Ok(())
        }
    }
}
