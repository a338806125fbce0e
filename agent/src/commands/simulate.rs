//! `cellwatch simulate cnc`: the simulated CNC as a standalone OPC UA server.

use std::path::PathBuf;

use std::io::Write;

use tokio::io::{AsyncBufReadExt, BufReader};

use super::signals::StopSignals;
use super::Failure;
use crate::sim::cnc::{Scenario, SimOptions, SimulatedCnc};
use crate::sim::moulding::{Event, MouldingBus};
use crate::sources::pki;

/// The simulated CNC's commands on its standard input.
const COMMANDS: &str = "set ADDRESS 0|1, temp CELSIUS, bad ADDRESS, quit";

/// Serves a simulated moulding bus until interrupted or `quit`.
pub(crate) async fn moulding(args: &MouldingArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let mut signals = StopSignals::listen()?;
    let bus = MouldingBus::new(args.units);
    let io = Failure::output;
    let _server = match args.tcp {
        Some(addr) => {
            let (local, task) = bus
                .listen_tcp(addr)
                .await
                .map_err(|e| Failure::Runtime(format!("cannot listen on {addr}: {e}")))?;
            writeln!(
                out,
                "simulated moulding bus, units 1-{}, on tcp {local}",
                args.units
            )
            .map_err(io)?;
            Some(task)
        }
        None => {
            let path = bus
                .pty()
                .map_err(|e| Failure::Runtime(format!("no pseudo-terminal: {e}")))?;
            writeln!(
                out,
                "simulated moulding bus, units 1-{}, on serial line {}",
                args.units,
                path.display()
            )
            .map_err(io)?;
            None
        }
    };
    writeln!(
        out,
        "commands: stop UNIT CAUSE (01-06), run UNIT, silent UNIT, answer UNIT, noise N, cycle, quit"
    )
    .map_err(io)?;
    out.flush().map_err(io)?;
    let player = {
        let bus = bus.clone();
        let (cycle, schedule) = (args.cycle, args.scenario == "demo");
        tokio::spawn(async move { bus.play(cycle, schedule, |n| tracing::info!("{n}")).await })
    };
    let mut lines = BufReader::new(tokio::io::stdin()).lines();
    loop {
        let line = tokio::select! {
            _ = signals.recv() => break,
            line = lines.next_line() => line,
        };
        let Ok(Some(line)) = line else {
            // No (more) input: keep serving until interrupted.
            signals.recv().await;
            break;
        };
        let words: Vec<&str> = line.split_whitespace().collect();
        let unit = |w: Option<&&str>| w.and_then(|u| u.parse::<u8>().ok());
        let done = match (words.first().copied(), unit(words.get(1))) {
            (Some("quit"), _) => break,
            (Some("cycle"), _) => {
                bus.cycle();
                true
            }
            (Some("noise"), _) => match words.get(1).and_then(|n| n.parse().ok()) {
                Some(n) => {
                    bus.apply(Event::Noise(n));
                    true
                }
                None => false,
            },
            (Some("run"), Some(u)) => {
                bus.apply(Event::Run(u));
                true
            }
            (Some("silent"), Some(u)) => {
                bus.apply(Event::Silent(u));
                true
            }
            (Some("answer"), Some(u)) => {
                bus.apply(Event::Answer(u));
                true
            }
            (Some("stop"), Some(u)) => {
                let bit = words.get(2).and_then(|c| {
                    cellwatch_models::at_bus::Status::NAMED
                        .iter()
                        .find(|(_, _, code)| code == &Some(*c))
                        .map(|(_, b, _)| *b)
                });
                match bit {
                    Some(b) => {
                        bus.apply(Event::Stop(u, b));
                        true
                    }
                    None => false,
                }
            }
            _ => false,
        };
        let reply = if done {
            format!("done {line}")
        } else {
            format!("? {line}: stop UNIT CAUSE (01-06), run UNIT, silent UNIT, answer UNIT, noise N, cycle, quit")
        };
        writeln!(out, "{reply}").map_err(io)?;
        out.flush().map_err(io)?;
    }
    player.abort();
    Ok(())
}

/// Runs the simulator until interrupted. Commands on standard input:
/// `set ADDRESS 0|1`, `temp CELSIUS` (the spindle, D100), `bad ADDRESS`,
/// `quit` ([`COMMANDS`]).
pub(crate) async fn cnc(args: &SimulateArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let mut signals = StopSignals::listen()?;
    let sim = SimulatedCnc::start(&SimOptions {
        listen: args.listen,
        pki_dir: args.pki_dir.clone(),
        insecure: args.insecure,
        decoy: None,
    })
    .await
    .map_err(Failure::runtime)?;
    for cert in &args.trust {
        pki::trust(cert, &args.pki_dir).map_err(Failure::input)?;
    }
    let io = Failure::output;
    writeln!(
        out,
        "simulated CNC on {} (tags as nsu={};s=<address>, now ns={})",
        sim.endpoint(),
        crate::sim::cnc::NAMESPACE,
        sim.namespace()
    )
    .map_err(io)?;
    writeln!(
        out,
        "server certificate: {} (trust it in the agent's pki/trusted/)",
        pki::own_cert(&args.pki_dir).display()
    )
    .map_err(io)?;
    writeln!(out, "commands: {COMMANDS}").map_err(io)?;
    out.flush().map_err(io)?;
    let player = if args.scenario == "demo" {
        let s = sim.clone();
        Some(tokio::spawn(async move {
            Scenario::demo()
                .play(&s, |step| tracing::info!("{}", step.note))
                .await
        }))
    } else {
        None
    };
    let mut lines = BufReader::new(tokio::io::stdin()).lines();
    loop {
        tokio::select! {
            _ = signals.recv() => break,
            line = lines.next_line() => {
                let Ok(Some(line)) = line else {
                    // No (more) input: keep serving until interrupted.
                    signals.recv().await;
                    break;
                };
                let words: Vec<&str> = line.split_whitespace().collect();
                let said = |r: Result<(), crate::sim::SimError>| r.map_err(|e| e.to_string());
                let result = match words.as_slice() {
                    ["set", addr, v] => said(sim.set(addr, matches!(*v, "1" | "true" | "on"))),
                    ["temp", celsius] => match celsius.parse::<f64>() {
                        Ok(c) => said(sim.set_temperature(c)),
                        Err(_) => Err(format!("temp {celsius}: not a number")),
                    },
                    ["bad", addr] => said(sim.set_bad(addr)),
                    ["quit"] => break,
                    [] => Ok(()),
                    _ => Err(format!("unknown command '{line}': {COMMANDS}")),
                };
                match result {
                    Ok(()) => writeln!(out, "ok").map_err(io)?,
                    Err(e) => writeln!(out, "error: {e}").map_err(io)?,
                }
                out.flush().map_err(io)?;
            }
        }
    }
    if let Some(p) = player {
        p.abort();
    }
    sim.stop();
    Ok(())
}

/// Writes `run` as a CSV run log (`time_ms,tag,value`, initial values at 0).
fn write_run(
    path: &std::path::Path,
    run: &cellwatch_models::timer::log::RunLog,
) -> Result<(), Failure> {
    let mut csv = String::from("time_ms,tag,value\n");
    for (s, v) in run.signals.iter().zip(&run.initial) {
        csv.push_str(&format!("0,{s},{}\n", u8::from(*v)));
    }
    for c in &run.changes {
        csv.push_str(&format!(
            "{},{},{}\n",
            c.at,
            run.signals[c.signal],
            u8::from(c.value)
        ));
    }
    std::fs::write(path, csv)
        .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", path.display())))
}

/// Writes the labels of the runs (what was injected, when) to `path` and
/// says so.
fn write_labels(
    path: &std::path::Path,
    labels: &str,
    what: &str,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    std::fs::write(path, labels)
        .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", path.display())))?;
    writeln!(out, "{} ({what})", path.display()).map_err(Failure::output)
}

/// `cellwatch simulate robot-runs`.
pub(crate) fn robot_runs(args: &RobotRunsArgs, out: &mut dyn Write) -> Result<(), Failure> {
    use cellwatch_models::sfc::plant::{record, Stuck};
    use cellwatch_models::sfc::StepRef;
    let sfc =
        cellwatch_models::sfc::text::parse("robot.sfc.toml", crate::sim::robot::CHARTS, &|_| true)
            .map_err(|e| Failure::Runtime(e.join("\n")))?;
    let ms = super::timers::millis;
    let length = ms("--length", &args.length)?;
    let dwell = [
        ms("--dwell-min", &args.dwell_min)?,
        ms("--dwell-max", &args.dwell_max)?,
    ];
    if dwell[0] == 0 || dwell[0] > dwell[1] {
        return Err(Failure::Input(format!(
            "--dwell-min {} must be above 0 and at most --dwell-max {}",
            args.dwell_min, args.dwell_max
        )));
    }
    let stuck = match &args.stuck {
        None => None,
        Some(spec) => {
            let bad = |why: &str| Failure::Input(format!("--stuck '{spec}': {why}"));
            let (step, at) = spec
                .split_once('@')
                .ok_or_else(|| bad("write STEP@TIME, as in F1.S2@10s"))?;
            let r = sfc
                .steps()
                .map(|(r, _)| r)
                .find(|&r: &StepRef| sfc.step_name(r) == step)
                .ok_or_else(|| bad("no such step in the robot's charts"))?;
            Some(Stuck {
                step: r,
                after_ms: ms("--stuck", at)?,
            })
        }
    };
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Runtime(format!("cannot create {}: {e}", args.out.display())))?;
    let io = Failure::output;
    let mut labels = String::from("run,step,stuck_at_ms\n");
    let scan = crate::sim::robot::SCAN.as_millis() as u64;
    for i in 0..args.runs {
        let (run, at) = record(&sfc, dwell, args.seed + i, scan, length, stuck);
        let name = format!("run-{:03}.csv", i + 1);
        let path = args.out.join(&name);
        write_run(&path, &run)?;
        if let (Some(s), Some(at)) = (stuck, at) {
            labels.push_str(&format!("{name},{},{at}\n", sfc.step_name(s.step)));
        }
        writeln!(out, "{} ({} changes)", path.display(), run.changes.len()).map_err(io)?;
    }
    if stuck.is_some() {
        write_labels(
            &args.out.join("stuck.csv"),
            &labels,
            "when each step stuck",
            out,
        )?;
    }
    Ok(())
}

/// `cellwatch simulate line`: writes run logs of the simulated body-shop line.
pub(crate) fn line(args: &LineArgs, out: &mut dyn Write) -> Result<(), Failure> {
    use cellwatch_models::timer::line::{self, Fault};
    let fault = match &args.inject {
        None => None,
        Some(spec) => {
            let (kind, step) = spec.split_once('@').ok_or_else(|| {
                Failure::Input(format!("--inject '{spec}': write KIND@STEP, as in slow@12"))
            })?;
            let kind = kind
                .parse()
                .map_err(|e: cellwatch_models::timer::line::UnknownFault| {
                    Failure::Input(format!("--inject '{spec}': {e}"))
                })?;
            let step = step
                .parse()
                .map_err(|_| Failure::Input(format!("--inject '{spec}': STEP must be a number")))?;
            Some(Fault { kind, step })
        }
    };
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Runtime(format!("cannot create {}: {e}", args.out.display())))?;
    let io = Failure::output;
    let mut labels = String::from("run,kind,sensor,command_at_ms\n");
    for i in 0..args.runs {
        let (run, injected) = line::run(args.seed + i, args.cycles, fault);
        let name = format!("run-{:03}.csv", i + 1);
        let path = args.out.join(&name);
        write_run(&path, &run)?;
        if let Some(f) = injected {
            labels.push_str(&format!(
                "{name},{:?},{},{}\n",
                f.kind, f.sensor, f.command_at
            ));
        }
        writeln!(out, "{} ({} changes)", path.display(), run.changes.len()).map_err(io)?;
    }
    if fault.is_some() {
        write_labels(
            &args.out.join("faults.csv"),
            &labels,
            "the injected faults",
            out,
        )?;
    }
    Ok(())
}

#[derive(Debug, clap::Subcommand)]
pub(crate) enum SimulateCommand {
    /// The CNC of paper 000: ESE and CSD logic, faults on a schedule or on
    /// command (standard input: `set X0.06 0`, `bad X0.04`, `quit`).
    Cnc(SimulateArgs),
    /// Paper 001's body-shop line: writes run logs (CSV), normal or with an
    /// injected fault, deterministic per seed.
    Line(LineArgs),
    /// Paper 002's injection-moulding units on one `@` bus, answering the
    /// control computer by unit number over TCP (a serial device server's
    /// raw socket) or a pseudo-terminal (a serial port). Standard input:
    /// `stop UNIT CAUSE` (01-06), `run UNIT`, `silent UNIT`, `answer UNIT`,
    /// `noise N`, `cycle`, `quit`.
    Moulding(MouldingArgs),
    /// Paper 004's LCD-glass robot, in virtual time: writes run logs (CSV)
    /// of its step flags and inputs, normal or with a step stuck, as
    /// `cellwatch learn --sfc` reads them; deterministic per seed.
    RobotRuns(RobotRunsArgs),
}

#[derive(Debug, clap::Args)]
pub(crate) struct RobotRunsArgs {
    /// How many runs.
    #[arg(long, default_value_t = 4)]
    pub(crate) runs: u64,
    /// Length of each run.
    #[arg(long, default_value = "60s")]
    pub(crate) length: String,
    /// Shortest time a step takes.
    #[arg(long, default_value = "1s")]
    pub(crate) dwell_min: String,
    /// Longest time a step takes (each activation draws between the two).
    #[arg(long, default_value = "1400ms")]
    pub(crate) dwell_max: String,
    /// Put a step in error in every run: STEP@TIME, the step stuck at its
    /// first activation after TIME (F1.S2@10s).
    #[arg(long, value_name = "STEP@TIME")]
    pub(crate) stuck: Option<String>,
    /// Seed of the first run (run i uses seed + i).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Directory for run-NNN.csv (and stuck.csv with when each step stuck).
    #[arg(long)]
    pub(crate) out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct MouldingArgs {
    /// How many units (numbered from 1).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(1..=255))]
    pub(crate) units: u8,
    /// Serve on this TCP address.
    #[arg(long, conflicts_with = "pty", required_unless_present = "pty")]
    pub(crate) tcp: Option<std::net::SocketAddr>,
    /// Serve on a new pseudo-terminal (its path is printed).
    #[arg(long)]
    pub(crate) pty: bool,
    /// A machine cycle (production up) every this long; 0 for none.
    #[arg(long, default_value = "2s", value_parser = humantime::parse_duration)]
    pub(crate) cycle: std::time::Duration,
    /// Stop schedule: `demo` (unit 2's front door, unit 3's mould change,
    /// unit 1 silent, line noise, every 40 s) or `none`.
    #[arg(long, default_value = "demo", value_parser = ["demo", "none"])]
    pub(crate) scenario: String,
}

#[derive(Debug, clap::Args)]
pub(crate) struct LineArgs {
    /// How many runs.
    #[arg(long, default_value_t = 4)]
    pub(crate) runs: u64,
    /// Cycles per station per run.
    #[arg(long, default_value_t = 6)]
    pub(crate) cycles: usize,
    /// Inject a fault in every run: KIND@STEP, KIND one of missing, fast,
    /// slow, stuck; STEP the motion number (in command order).
    #[arg(long, value_name = "KIND@STEP")]
    pub(crate) inject: Option<String>,
    /// Seed of the first run (run i uses seed + i).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Directory for run-NNN.csv (and faults.csv with the labels).
    #[arg(long)]
    pub(crate) out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct SimulateArgs {
    /// Address to serve OPC UA on.
    #[arg(long, default_value = "127.0.0.1:4845")]
    pub(crate) listen: std::net::SocketAddr,
    /// The server's PKI directory (own certificate, trusted clients).
    #[arg(long, default_value = "sim-pki")]
    pub(crate) pki_dir: PathBuf,
    /// A client certificate to trust (the agent's pki/own/cert.der); repeatable.
    #[arg(long, value_name = "CERT")]
    pub(crate) trust: Vec<PathBuf>,
    /// Fault schedule: `demo` (ESE and CSD every 24 s) or `none`.
    #[arg(long, default_value = "demo", value_parser = ["demo", "none"])]
    pub(crate) scenario: String,
    /// Also offer an endpoint without security (for tools that cannot do better).
    #[arg(long)]
    pub(crate) insecure: bool,
}
