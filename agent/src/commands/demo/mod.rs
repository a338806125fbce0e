//! `cellwatch demo`: simulated cells served over real OPC UA (paper 000's CNC, paper 004's
//! robot, paper 001's line, paper 002's moulding units on a simulated `@` bus), an agent
//! watching each, the bus with its own plant CA, alarms printed with their diagnosis.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use tokio::sync::mpsc;

use super::agent::{load, start_failure};
use super::signals::StopSignals;
use super::Failure;
use crate::agent;
use crate::bus::keys::{CellKeys, Service};
use crate::config::{CellConfig, OpcUaConfig};
use crate::sim::cnc::{Scenario, SimOptions, SimulatedCnc};
use crate::sim::line::SimulatedLine;
use crate::sinks::console::Notice;
use crate::sources::{opcua, pki};
use cellwatch_models::alarm::{AlarmKind, AlarmState, Transition};
use cellwatch_models::timer::line::{Fault, FaultKind};

mod bus;
mod scada;
mod shipped;

use bus::{bus_tls, DemoBus};

/// The demo's operator: a private key file (the operator's side, given to
/// `ack`/`reset` with --key-file) and the agents' operators file with only
/// its public key. Made once; kept across runs.
fn demo_operator(state: &Path) -> Result<(PathBuf, PathBuf), Failure> {
    let key_file = state.join("operator-demo.key");
    let operators = state.join("operators.toml");
    if !key_file.exists() || !operators.exists() {
        let key = crate::operator::OperatorKey::generate("demo");
        let _ = std::fs::remove_file(&key_file);
        super::keygen::write_private(&key_file, &key.to_file())?;
        let entry = key.operators_entry(&crate::operator::Action::ALL);
        std::fs::write(
            &operators,
            format!("# Operators' public keys and permissions (cellwatch keygen prints entries).\n{entry}"),
        )
        .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", operators.display())))?;
    }
    Ok((key_file, operators))
}

/// The agent of `cell` (its key pair made now) and the simulated PLC whose
/// PKI is `sim_pki` trust each other, certificate by certificate, as on a
/// real cell.
fn trust_each_other(cell: &str, ua: &OpcUaConfig, sim_pki: &Path) -> Result<(), Failure> {
    drop(opcua::client(cell, ua).map_err(|e| Failure::Runtime(e.to_string()))?);
    pki::trust(&pki::own_cert(&ua.pki_dir), sim_pki).map_err(Failure::runtime)?;
    pki::trust(&pki::own_cert(sim_pki), &ua.pki_dir).map_err(Failure::runtime)?;
    Ok(())
}

/// The OPC UA connection of a demo cell (its simulator is an OPC UA
/// server).
fn opcua_of<'a>(c: &'a mut CellConfig, file: &Path) -> Result<&'a mut OpcUaConfig, Failure> {
    c.opcua.as_mut().ok_or_else(|| {
        Failure::Input(format!(
            "{}: the demo serves this cell over OPC UA; its configuration needs an [opcua] section",
            file.display()
        ))
    })
}

/// The simulated cell's listen address, taken from the config's endpoint.
fn endpoint_addr(endpoint: &str) -> Result<std::net::SocketAddr, Failure> {
    let hostport = endpoint
        .trim_start_matches("opc.tcp://")
        .split('/')
        .next()
        .unwrap_or_default();
    hostport.parse().map_err(|_| {
        Failure::Input(format!(
            "opcua.endpoint '{endpoint}': the demo needs an IP:port endpoint on this machine"
        ))
    })
}

/// `cellwatch demo`: a simulated CNC served over OPC UA and an agent
/// watching it, in one process; alarms printed as they happen.
pub(crate) async fn demo(args: &DemoArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let mut signals = StopSignals::listen()?;
    let state: PathBuf = args.state_dir.clone();
    std::fs::create_dir_all(&state)
        .map_err(|e| Failure::Runtime(format!("cannot create {}: {e}", state.display())))?;
    let shipped = shipped::write(&state)?;
    let files = ConfigFiles::of(args, &shipped.dir);
    let mut c = load(&files.cnc)?;
    if args.any_ports {
        any_ports(&mut c);
    }
    let sim_pki = state.join("sim-pki");
    opcua_of(&mut c, &files.cnc)?.pki_dir = state.join("agent-pki");
    c.journal.path = state.join(format!("{}.sqlite", c.cell));
    let (operator_key, secrets) = demo_operator(&state)?;
    let mut demo_bus = DemoBus::new(&state);
    demo_bus.join(&mut c)?;
    let (client_config, trust_file) = (state.join("client.json5"), state.join("trust.toml"));
    c.operators_file = Some(secrets.clone());
    c.warnings
        .retain(|w| !w.starts_with("no commands.operators_file"));
    let scada_password = if args.no_alarm_server {
        c.alarm_server = None;
        None
    } else {
        let mut listen = args.alarm_server;
        if args.any_ports {
            listen.set_port(0);
        }
        Some(scada::serve(&mut c, &state, listen)?)
    };
    let ua = opcua_of(&mut c, &files.cnc)?.clone();
    let listen = endpoint_addr(&ua.endpoint)?;
    let sim = SimulatedCnc::start(&SimOptions {
        listen,
        pki_dir: sim_pki.clone(),
        insecure: false,
        decoy: None,
    })
    .await
    .map_err(Failure::runtime)?;
    trust_each_other(&c.cell, &ua, &sim_pki)?;
    opcua_of(&mut c, &files.cnc)?.endpoint = sim.endpoint();
    let keys = CellKeys::new(&c.zenoh.prefix);
    let journal = c.journal.path.clone();
    let (tx, mut rx) = mpsc::unbounded_channel();
    let cnc_agent = agent::start(c.clone(), Some(tx.clone()))
        .await
        .map_err(start_failure)?;
    demo_bus.listening(&cnc_agent).await;
    let io = Failure::output;
    writeln!(
        out,
        "cellwatch demo: cell {} — paper 000's engraving machine (ESE, CSD)",
        c.cell
    )
    .map_err(io)?;
    writeln!(
        out,
        "  simulated PLC   {} (Basic256Sha256, SignAndEncrypt, mutual certificate trust)",
        sim.endpoint()
    )
    .map_err(io)?;
    writeln!(
        out,
        "  Zenoh           {}, {}, {}, {} (listening on {})",
        keys.alarms(),
        keys.state(),
        keys.service(Service::History),
        keys.service(Service::Snapshot),
        cnc_agent.zenoh_locators().await.join(", ")
    )
    .map_err(io)?;
    if let Some(m) = cnc_agent.metrics_addr() {
        writeln!(out, "  metrics         http://{m}/metrics").map_err(io)?;
    }
    writeln!(out, "  journal         {}", journal.display()).map_err(io)?;
    let kept = if shipped.kept.is_empty() {
        String::new()
    } else {
        format!("; kept as edited: {}", shipped.kept.join(", "))
    };
    writeln!(
        out,
        "  configuration   {} (the demo's own, written by this binary{kept})",
        shipped.dir.display()
    )
    .map_err(io)?;
    if let (Some(addr), Some(password)) = (cnc_agent.alarm_server_addr(), &scada_password) {
        let pki = state.join("alarm-server-pki");
        writeln!(
            out,
            "  SCADA           opc.tcp://{addr}/ serves the cell's alarms as OPC UA Alarms & Conditions (Basic256Sha256, SignAndEncrypt)\n                  \
             user demo, password in {}; the server's certificate {}; a client's is refused until moved from {}/ to trusted/",
            password.display(),
            pki.join("own").join("cert.der").display(),
            pki.join("rejected").display(),
        )
        .map_err(io)?;
    }
    writeln!(
        out,
        "  bus             mutual TLS, certificates from the CA in {}, everything signed by its cell's agent; clients: --zenoh-config {} --trust {}",
        state.join("pki-bus").display(),
        client_config.display(),
        trust_file.display()
    )
    .map_err(io)?;
    writeln!(
        out,
        "  operator        demo, private key {} (public key in {})",
        operator_key.display(),
        secrets.display()
    )
    .map_err(io)?;
    writeln!(out, "  faults injected every 24 s: Y over-travel limit switch (ESE), cycle start in JOG mode (CSD)").map_err(io)?;
    let (note_tx, mut note_rx) = mpsc::unbounded_channel::<String>();
    // The active alarms of every cell, for the robot's scenario to wait on.
    let (active_tx, active_rx) = tokio::sync::watch::channel(std::collections::HashSet::new());
    let line = if args.no_line {
        None
    } else {
        let mut l = load(&files.line)?;
        if args.any_ports {
            any_ports(&mut l);
        }
        opcua_of(&mut l, &files.line)?.pki_dir = state.join("line-agent-pki");
        let lua = opcua_of(&mut l, &files.line)?.clone();
        l.journal.path = state.join(format!("{}.sqlite", l.cell));
        l.operators_file = Some(secrets.clone());
        demo_bus.join(&mut l)?;
        l.warnings
            .retain(|w| !w.starts_with("no commands.operators_file"));
        let line_pki = state.join("line-sim-pki");
        let options = SimOptions {
            listen: endpoint_addr(&lua.endpoint)?,
            pki_dir: line_pki.clone(),
            insecure: false,
            decoy: None,
        };
        let line_sim = SimulatedLine::start(&options)
            .await
            .map_err(Failure::runtime)?;
        trust_each_other(&l.cell, &lua, &line_pki)?;
        opcua_of(&mut l, &files.line)?.endpoint = line_sim.endpoint();
        let timers: usize = l.timers.iter().map(|t| t.model.transitions.len()).sum();
        let cell = l.cell.clone();
        let line_agent = agent::start(l, Some(tx.clone()))
            .await
            .map_err(start_failure)?;
        demo_bus.listening(&line_agent).await;
        writeln!(
            out,
            "  cell {cell}: body-shop line on {}, {timers} transition timers; one motion made slow early on ({})",
            line_sim.endpoint(),
            listening(&line_agent).await
        )
        .map_err(io)?;
        let player_sim = line_sim.clone();
        let notes = note_tx.clone();
        let line_player = tokio::spawn(async move {
            player_sim
                .play(
                    1000,
                    Some(Fault {
                        kind: FaultKind::TooSlow,
                        step: 14,
                    }),
                    |n| {
                        let _ = notes.send(format!("line: {n}"));
                    },
                )
                .await;
        });
        Some((line_sim, line_agent, line_player))
    };
    let moulding = if args.no_moulding {
        None
    } else {
        let mut m = load(&files.moulding)?;
        if args.any_ports {
            any_ports(&mut m);
        }
        let addr = match m.legacy.as_ref().map(|l| &l.transport) {
            Some(crate::sources::at_bus::Transport::Tcp(a)) => a.parse::<std::net::SocketAddr>().map_err(|_| {
                Failure::Input(format!(
                    "{}: legacy.tcp '{a}': the demo needs an IP:port on this machine",
                    files.moulding.display()
                ))
            })?,
            _ => {
                return Err(Failure::Input(format!(
                    "{}: the demo serves the moulding units on TCP; its configuration needs [legacy] tcp = \"IP:port\"",
                    files.moulding.display()
                )))
            }
        };
        m.journal.path = state.join(format!("{}.sqlite", m.cell));
        m.operators_file = Some(secrets.clone());
        demo_bus.join(&mut m)?;
        m.warnings
            .retain(|w| !w.starts_with("no commands.operators_file"));
        let bus = crate::sim::moulding::MouldingBus::new(3);
        let (local, server) = bus.listen_tcp(addr).await.map_err(|e| {
            Failure::Runtime(format!("cannot serve the moulding bus on {addr}: {e}"))
        })?;
        if let Some(l) = &mut m.legacy {
            l.transport = crate::config::at_bus::Transport::Tcp(local.to_string());
        }
        let cell = m.cell.clone();
        let agent = agent::start(m, Some(tx.clone()))
            .await
            .map_err(start_failure)?;
        demo_bus.listening(&agent).await;
        writeln!(
            out,
            "  cell {cell}: injection-moulding units 1-3 on an @ bus at tcp {local}; a door, a mould change, a silent gateway every 40 s ({})",
            listening(&agent).await
        )
        .map_err(io)?;
        let notes = note_tx.clone();
        let player_bus = bus.clone();
        let player = tokio::spawn(async move {
            player_bus
                .play(Duration::from_secs(2), true, |n| {
                    let _ = notes.send(format!("moulding: {n}"));
                })
                .await;
        });
        Some((agent, server, player))
    };
    let robot = if args.no_robot {
        None
    } else {
        Some(
            demo_robot(
                (args, &files.robot),
                &mut demo_bus,
                (&operator_key, &secrets),
                tx.clone(),
                note_tx.clone(),
                active_rx,
                out,
            )
            .await?,
        )
    };
    demo_bus.write()?;
    let console = if args.no_console {
        None
    } else {
        let mut listen = args.console;
        if args.any_ports {
            listen.set_port(0);
        }
        let console = demo_bus.console(listen, &secrets).await?;
        writeln!(
            out,
            "  console         {} (sign in with {} in the page, as operator demo)",
            console.url(),
            operator_key.display()
        )
        .map_err(io)?;
        Some(console)
    };
    writeln!(out).map_err(io)?;
    out.flush().map_err(io)?;

    let agent = cnc_agent;
    drop(c);
    let scenario_sim = sim.clone();
    let player = tokio::spawn(async move {
        Scenario::demo()
            .play(&scenario_sim, |s| {
                let _ = note_tx.send(format!("{} ({} = {})", s.note, s.address, s.value));
            })
            .await;
    });
    let deadline = async {
        match args.duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(deadline);
    let mut last_state: std::collections::HashMap<String, String> =
        std::collections::HashMap::new();
    loop {
        tokio::select! {
            _ = &mut deadline => break,
            _ = signals.recv() => break,
            Some(note) = note_rx.recv() => writeln!(out, "{}  plc    {note}", clock()).map_err(io)?,
            Some(n) = rx.recv() => {
                if let Notice::Alarm(a) = &n {
                    let active = matches!(
                        a.state,
                        AlarmState::ActiveUnacknowledged | AlarmState::ActiveAcknowledged
                    );
                    active_tx.send_modify(|ids| {
                        if active {
                            ids.insert(a.id.clone());
                        } else {
                            ids.remove(&a.id);
                        }
                    });
                }
                print_notice(out, &n, &mut last_state).map_err(io)?
            }
        }
        out.flush().map_err(io)?;
    }
    player.abort();
    if let Some(console) = console {
        console.stop().await;
    }
    agent.stop().await;
    sim.stop();
    if let Some((robot, agent, scanning, player)) = robot {
        player.abort();
        agent.stop().await;
        scanning.abort();
        robot.stop();
    }
    if let Some((agent, server, player)) = moulding {
        player.abort();
        agent.stop().await;
        server.abort();
    }
    if let Some((line_sim, line_agent, line_player)) = line {
        line_player.abort();
        line_agent.stop().await;
        line_sim.stop();
    }
    Ok(())
}

/// The demo's robot cell (paper 004): the simulated robot on OPC UA, its
/// agent, the PLC's scan task and the scenario, which asks the agent to
/// force stuck steps on as operator `demo` (its key file and the agents'
/// operators file), over the bus, signed; it waits on `active`, the
/// alarms active in the demo, for a step to be stuck.
async fn demo_robot(
    (args, robot_config): (&DemoArgs, &Path),
    demo_bus: &mut DemoBus,
    (operator_key, secrets): (&Path, &Path),
    tx: mpsc::UnboundedSender<Notice>,
    notes: mpsc::UnboundedSender<String>,
    active: tokio::sync::watch::Receiver<std::collections::HashSet<String>>,
    out: &mut dyn Write,
) -> Result<
    (
        crate::sim::robot::SimulatedRobot,
        agent::Agent,
        tokio::task::JoinHandle<()>,
        tokio::task::JoinHandle<()>,
    ),
    Failure,
> {
    use crate::sim::robot::SimulatedRobot;
    let state = demo_bus.state.clone();
    let state = state.as_path();
    let mut r = load(robot_config)?;
    if args.any_ports {
        any_ports(&mut r);
    }
    opcua_of(&mut r, robot_config)?.pki_dir = state.join("robot-agent-pki");
    let rua = opcua_of(&mut r, robot_config)?.clone();
    r.journal.path = state.join(format!("{}.sqlite", r.cell));
    r.operators_file = Some(secrets.to_path_buf());
    demo_bus.join(&mut r)?;
    let trust = demo_bus.trust.clone();
    r.warnings
        .retain(|w| !w.starts_with("no commands.operators_file"));
    let robot_pki = state.join("robot-sim-pki");
    let robot = SimulatedRobot::start(
        &SimOptions {
            listen: endpoint_addr(&rua.endpoint)?,
            pki_dir: robot_pki.clone(),
            insecure: false,
            decoy: None,
        },
        Duration::from_secs(1),
    )
    .await
    .map_err(Failure::runtime)?;
    trust_each_other(&r.cell, &rua, &robot_pki)?;
    opcua_of(&mut r, robot_config)?.endpoint = robot.endpoint();
    let scanning = tokio::spawn({
        let robot = robot.clone();
        async move { robot.run().await }
    });
    // The stuck alarm of each step, by CHART.STEP.
    let alarm_of: std::collections::HashMap<String, String> = r
        .sfc
        .iter()
        .flat_map(|c| {
            c.sfc
                .steps()
                .map(|(s, _)| {
                    (
                        c.sfc.step_name(s),
                        cellwatch_models::sfc::supervise::alarm_id(&c.id, &c.sfc, s),
                    )
                })
                .collect::<Vec<_>>()
        })
        .collect();
    // The operator's side: its own key and certificate, a session to the
    // robot agent's endpoint.
    let key_text = std::fs::read_to_string(operator_key)
        .map_err(|e| Failure::Runtime(format!("cannot read {}: {e}", operator_key.display())))?;
    let key = crate::operator::OperatorKey::parse(&operator_key.display().to_string(), &key_text)
        .map_err(Failure::runtime)?;
    let cell_id = r.cell.clone();
    let agent = agent::start(r, Some(tx)).await.map_err(start_failure)?;
    demo_bus.listening(&agent).await;
    writeln!(
        out,
        "  cell {cell_id}: paper 004's LCD-glass robot on {}, charts F1 and F2 supervised; S2 then S15 stuck, forced on by operator demo ({})",
        robot.endpoint(),
        listening(&agent).await
    )
    .map_err(Failure::output)?;
    let connect: Vec<String> = agent
        .zenoh_locators()
        .await
        .iter()
        .map(|e| e.replace("0.0.0.0", "127.0.0.1"))
        .collect();
    // Connected once the agent listens.
    let bus = crate::bus::open(&crate::config::ZenohConfig {
        mode: crate::config::ZenohMode::Peer,
        connect,
        listen: Vec::new(),
        prefix: String::new(),
        multicast_scouting: false,
        tls: Some(bus_tls(state, "operator-demo")?),
        config_file: None,
        plain: false,
        signing_key: None,
    })
    .await
    .map_err(Failure::runtime)?;
    let bus = crate::client::BusClient::on(bus, trust, crate::config::DEFAULT_ROOT);
    let player_robot = robot.clone();
    let player = tokio::spawn(async move {
        let force = |transition: &'static str| {
            let mut cmd = crate::operator::Command {
                action: crate::operator::Action::Force,
                alarm: String::new(),
                tag: None,
                value: Some(transition.to_string()),
                reason: None,
                operator: key.operator.clone(),
                nonce: crate::operator::nonce(),
                issued_at: crate::clock::now_ms(),
                signature: String::new(),
            };
            cmd.sign(&cell_id, &key);
            let bus = &bus;
            let cell_id = &cell_id;
            async move {
                bus.command(cell_id, &cmd, Duration::from_secs(10))
                    .await
                    .map_err(|e| e.to_string())
            }
        };
        let stuck = |step: &'static str| {
            let mut active = active.clone();
            let alarm = alarm_of.get(step).cloned().unwrap_or_default();
            async move {
                let _ = active.wait_for(|ids| ids.contains(&alarm)).await;
            }
        };
        player_robot
            .play_demo(stuck, force, |n| {
                let _ = notes.send(format!("robot: {n}"));
            })
            .await;
    });
    Ok((robot, agent, scanning, player))
}

fn clock() -> String {
    let t = crate::clock::rfc3339(crate::clock::now_ms());
    t.get(11..23).unwrap_or(&t).to_string()
}

fn print_notice(
    out: &mut dyn Write,
    n: &Notice,
    last_state: &mut std::collections::HashMap<String, String>,
) -> std::io::Result<()> {
    match n {
        Notice::Connection(true, ep) => writeln!(out, "{}  opcua  connected to {ep}", clock()),
        Notice::Connection(false, why) => writeln!(out, "{}  opcua  {why}", clock()),
        Notice::State(s) => {
            let text = match (&s.fault_type, &s.element) {
                (Some(t), Some(e)) => format!("{} ({t}, element {e})", s.state),
                (Some(t), None) => format!("{} ({t})", s.state),
                _ => s.state.to_string(),
            };
            if last_state.get(&s.cell) != Some(&text) {
                writeln!(out, "{}  state  {} {text}", clock(), s.cell)?;
                last_state.insert(s.cell.clone(), text);
            }
            Ok(())
        }
        Notice::Alarm(a) => match a.transition {
            Transition::Raised => {
                let step = a.fault_step.map(|s| format!(" at step {s}"));
                let of = a.consequence.as_ref().map(|c| format!(" ({c})"));
                let step = step.unwrap_or_default() + &of.unwrap_or_default();
                writeln!(
                    out,
                    "{}  ALARM  {} [{}] {}{step}",
                    clock(),
                    a.id,
                    a.severity,
                    a.fault_type
                )?;
                if a.culprits.is_empty() || matches!(a.kind, AlarmKind::Timer | AlarmKind::Step) {
                    writeln!(out, "                      {}", a.message)?;
                }
                for c in &a.culprits {
                    writeln!(out, "                      {}", c.line())?;
                }
                Ok(())
            }
            other => writeln!(out, "{}  alarm  {} {other} ({})", clock(), a.id, a.state),
        },
    }
}

#[derive(Debug, clap::Args)]
pub(crate) struct DemoArgs {
    /// The cell configuration to run (its OPC UA endpoint is where the
    /// simulator listens). Default: the demo's own, which the binary
    /// carries and writes to STATE_DIR/config/demo.toml.
    #[arg(long, value_name = "FILE")]
    pub(crate) config: Option<PathBuf>,
    /// The body-shop line's cell configuration, run beside the CNC.
    /// Default: STATE_DIR/config/line.toml, the demo's own.
    #[arg(long, value_name = "FILE")]
    pub(crate) line_config: Option<PathBuf>,
    /// Run the CNC only (no line).
    #[arg(long)]
    pub(crate) no_line: bool,
    /// The moulding units' cell configuration (paper 002), run beside the
    /// CNC: three units on one simulated `@` bus. Default:
    /// STATE_DIR/config/moulding.toml, the demo's own.
    #[arg(long, value_name = "FILE")]
    pub(crate) moulding_config: Option<PathBuf>,
    /// No moulding units.
    #[arg(long)]
    pub(crate) no_moulding: bool,
    /// The robot's cell configuration (paper 004), run beside the CNC: the
    /// LCD-glass robot's charts supervised, stuck steps forced on.
    /// Default: STATE_DIR/config/robot.toml, the demo's own.
    #[arg(long, value_name = "FILE")]
    pub(crate) robot_config: Option<PathBuf>,
    /// No robot.
    #[arg(long)]
    pub(crate) no_robot: bool,
    /// Where the demo keeps certificates, the journal, operator keys and
    /// its own configuration (config/: written when missing, never over a
    /// file someone edited).
    #[arg(long, default_value = "cellwatch-demo")]
    pub(crate) state_dir: PathBuf,
    /// Stop after this long (e.g. 60s); default: until Ctrl-C.
    #[arg(long, value_parser = parse_duration)]
    pub(crate) duration: Option<std::time::Duration>,
    /// Serve every simulated PLC, bus endpoint and metrics port on a port
    /// the system picks instead of the configurations' (printed as they
    /// start; the client file in the state directory says where the agents
    /// listen): a second demo beside a first on one machine.
    #[arg(long)]
    pub(crate) any_ports: bool,
    /// Where the operators' web console serves (plain HTTP, loopback
    /// only; port 0 with --any-ports).
    #[arg(long, default_value = "127.0.0.1:8470", value_name = "IP:PORT")]
    pub(crate) console: std::net::SocketAddr,
    /// No web console.
    #[arg(long)]
    pub(crate) no_console: bool,
    /// Where the engraving machine's alarms are served to SCADA clients as
    /// OPC UA Alarms & Conditions (user `demo`, its password in the state
    /// directory; port 0 with --any-ports).
    #[arg(long, default_value = "127.0.0.1:4855", value_name = "IP:PORT")]
    pub(crate) alarm_server: std::net::SocketAddr,
    /// No OPC UA alarm server.
    #[arg(long)]
    pub(crate) no_alarm_server: bool,
}

/// The four cells' configuration files: those given, else the demo's own.
struct ConfigFiles {
    cnc: PathBuf,
    line: PathBuf,
    moulding: PathBuf,
    robot: PathBuf,
}

impl ConfigFiles {
    fn of(args: &DemoArgs, shipped: &Path) -> Self {
        let or_shipped = |given: &Option<PathBuf>, name: &str| {
            given.clone().unwrap_or_else(|| shipped.join(name))
        };
        ConfigFiles {
            cnc: or_shipped(&args.config, "demo.toml"),
            line: or_shipped(&args.line_config, "line.toml"),
            moulding: or_shipped(&args.moulding_config, "moulding.toml"),
            robot: or_shipped(&args.robot_config, "robot.toml"),
        }
    }
}

/// With `--any-ports`: every address `c` listens or serves on, on port 0.
fn any_ports(c: &mut CellConfig) {
    let port_zero = |endpoint: &str| match endpoint.rsplit_once(':') {
        Some((host, port)) => {
            let rest = port.find('/').map_or("", |i| &port[i..]);
            format!("{host}:0{rest}")
        }
        None => endpoint.to_string(),
    };
    c.zenoh.listen = c.zenoh.listen.iter().map(|e| port_zero(e)).collect();
    if let Some(m) = &mut c.metrics {
        m.set_port(0);
    }
    if let Some(ua) = &mut c.opcua {
        ua.endpoint = port_zero(&ua.endpoint);
    }
    if let Some(l) = &mut c.legacy {
        if let crate::config::at_bus::Transport::Tcp(a) = &mut l.transport {
            *a = port_zero(a);
        }
    }
}

/// Where a started agent listens, as the demo prints it.
async fn listening(agent: &agent::Agent) -> String {
    format!(
        "Zenoh {}, metrics {}",
        agent.zenoh_locators().await.join(", "),
        agent
            .metrics_addr()
            .map_or_else(|| "off".to_string(), |m| format!("http://{m}/metrics"))
    )
}

/// `--duration`: a duration as written (`60s`, `10m`).
fn parse_duration(s: &str) -> Result<std::time::Duration, String> {
    humantime::parse_duration(s).map_err(|e| format!("'{s}' is not a duration ({e})"))
}
