//! The command line: what each command takes, and how outcomes become exit
//! statuses (0 success, 1 runtime failure, 2 bad input).

use std::ffi::OsString;
use std::io::Write;

use clap::{Parser, Subcommand};

use crate::commands::agent::{RunArgs, ValidateArgs};
use crate::commands::bus::{
    AckArgs, AlarmsArgs, CommandArgs, ForceArgs, HistoryArgs, ReasonArgs, ReloadArgs, ShelveArgs,
    StopArgs, WriteArgs,
};
use crate::commands::console::ConsoleArgs;
#[cfg(feature = "simulators")]
use crate::commands::demo::DemoArgs;
use crate::commands::discover::DiscoverArgs;
use crate::commands::explain::ExplainArgs;
use crate::commands::hash_password::HashPasswordArgs;
use crate::commands::keygen::KeygenArgs;
use crate::commands::mad::MadCommand;
use crate::commands::pki::PkiCommand;
use crate::commands::plant::PlantCommand;
use crate::commands::report::ReportArgs;
use crate::commands::sf::SfArgs;
use crate::commands::sfc::SfcCommand;
#[cfg(feature = "simulators")]
use crate::commands::simulate::SimulateCommand;
use crate::commands::timers::{ExportStArgs, LearnArgs, ReplayArgs};
use crate::commands::{self, Failure};
use crate::operator::Action;

/// cellwatch — one agent per manufacturing cell: alarms that name the step and the contact behind every fault.
///
/// Reads the PLC's own program — instruction lists (FANUC PMC, IEC 61131-3
/// IL, Siemens STL), PLCopen XML, Rockwell Studio 5000 exports (.L5X) and
/// Siemens TIA Portal block exports (SimaticML) — and compiles each fault
/// coil into its switching function and step blocks; at fault time the
/// alarm names the step and the contacts that caused it, with their
/// comments from the machine's I/O list. Beside them: limit and discrete
/// alarms, transition timers learned from normal runs, and supervision of
/// sequential function charts with forcing of stuck steps.
///
/// An agent (`run`) watches one cell over OPC UA, or legacy units on the
/// `@` serial bus; it publishes alarms and machine state on Eclipse Zenoh
/// (mutual TLS, every payload signed), journals to SQLite, serves
/// Prometheus metrics, sends alarms to people through Prometheus
/// Alertmanager, serves the cell's alarms to SCADA as an OPC UA Alarms &
/// Conditions server, and takes operators' signed commands. The operators'
/// web console (`console`) shows the plant's cells live; `demo` runs
/// simulated cells with all of it on one machine.
#[derive(Debug, Parser)]
#[command(name = "cellwatch", version, max_term_width = 100)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Print the switching function (SF) and step blocks (SSF) of coils.
    ///
    /// Each coil's SF is written in observable signals: internal relays are
    /// replaced by the logic that writes them; self-holding coils and
    /// SET/RST latches stay as their own last value. The SF is printed in the
    /// paper's notation (`*` AND, `+` OR, `-` NOT) and in words, followed by
    /// its step blocks SSF1..SSFn, bottom-up.
    Sf(SfArgs),
    /// Sequential function charts (paper 004) in their TOML form: check a
    /// chart file and list its charts, steps and transitions, or print what
    /// the PLC program needs for forcing transitions.
    #[command(subcommand)]
    Sfc(SfcCommand),
    /// The cell's master alarm database (ISA-18.2): every alarm it can
    /// raise, drafted from its logic, for rationalisation.
    #[command(subcommand)]
    Mad(MadCommand),
    /// Explain a fault: the coil's value, every step's value, the fault step
    /// and the contacts that caused it; or a cell's consequence relation
    /// (--consequences), or an alarm's flight recording (--alarm).
    ///
    /// Culprits that changed between --before and --snapshot are the trigger
    /// and come first. Each culprit shows its value, the value that would
    /// clear the fault, and its comment.
    Explain(ExplainArgs),
    /// Run the agent for one cell: subscribe to the PLC over OPC UA, run the
    /// checks, publish alarms and machine state on Zenoh, journal to SQLite,
    /// serve Prometheus metrics.
    Run(RunArgs),
    /// Check a cell configuration (and the programs and I/O lists it names)
    /// without connecting to anything.
    Validate(ValidateArgs),
    /// Run a simulated CNC (paper 000's ESE and CSD machine) served over OPC
    /// UA and an agent watching it, in one process, printing alarms with
    /// their explanation as they happen.
    #[cfg(feature = "simulators")]
    Demo(DemoArgs),
    /// Serve a simulated cell over OPC UA.
    #[cfg(feature = "simulators")]
    #[command(subcommand)]
    Simulate(SimulateCommand),
    /// Serve the operators' web console for the plant: every cell's state
    /// and alarms live, each alarm's diagnosis, the cells' history, and
    /// operators' commands signed in the browser with their own key and
    /// forwarded to the cell's agent (the console holds no operator key).
    Console(ConsoleArgs),
    /// Show active alarms of running agents, or follow alarm events (Zenoh).
    Alarms(AlarmsArgs),
    /// Show a cell's machine-state, alarm and command history (Zenoh).
    History(HistoryArgs),
    /// Acknowledge an alarm: a signed command to the cell's agent (Zenoh).
    Ack(AckArgs),
    /// Reset a latched alarm whose condition has ended: a signed command (Zenoh).
    Reset(CommandArgs),
    /// Shelve an alarm (ISA-18.2): still evaluated and journaled, but not
    /// announced as active until the shelf ends — after --for (at most the
    /// cell's commands.max_shelve) or, with --once, when the alarm clears.
    /// A signed command; the operator needs permission `shelve`.
    Shelve(ShelveArgs),
    /// End an alarm's shelf now: a signed command (permission `unshelve`).
    Unshelve(CommandArgs),
    /// Take an alarm out of service (ISA-18.2: a broken instrument, a check
    /// under repair): not raised whatever its condition until it is back in
    /// service; an active occurrence ends now. Any alarm of the cell's
    /// checks, raised before or not. A signed command (permission
    /// `out-of-service`).
    OutOfService(ReasonArgs),
    /// Put an alarm back in service: raised at once if its condition holds.
    /// A signed command (permission `in-service`).
    InService(CommandArgs),
    /// Write a value to the PLC: a signed command (Zenoh) that the agent
    /// carries out only for an operator allowed `write`, and journals with
    /// the PLC's answer (a legacy unit's item code, target quantity or
    /// production correction).
    Write(WriteArgs),
    /// Force a stuck step's transition (paper 004): the agent pulses the
    /// chart's force switch only if you may `force`, the transition is
    /// declared forcible, a step it leaves has its stuck alarm active and
    /// its condition holds now; each check, the write and the result are
    /// journaled. Answers when the chart has arrived (or not, after the
    /// cell's force_timeout).
    Force(ForceArgs),
    /// Press a chart's remote stop switch (permission `stop`): a signed
    /// command, journaled with the PLC's answer.
    Stop(StopArgs),
    /// Have a cell's agent read its configuration file again (permission
    /// `configure`): checks, limits, delays and timers taken live with
    /// every alarm state kept, as on SIGHUP; answers what was taken, what
    /// only a restart changes, or why the file was refused.
    Reload(ReloadArgs),
    /// Make an operator's key pair for signing commands (Ed25519).
    ///
    /// Writes the private key file, which stays with the operator (give it
    /// to `ack` and `reset` with --key-file), and prints the entry for the
    /// agents' operators file: the public key and the actions allowed. An
    /// agent holds public keys only.
    Keygen(KeygenArgs),
    /// Hash a password for the alarm server's users file (Argon2id).
    ///
    /// Reads the password from standard input, one line, and prints the
    /// PHC string for a user's `password_hash`.
    HashPassword(HashPasswordArgs),
    /// Certificates for the Zenoh bus: a plant CA, and certificates issued
    /// from it for agents, routers and operators (mutual TLS; the access
    /// control matches their common names).
    #[command(subcommand)]
    Pki(PkiCommand),
    /// A plant of many cells from one inventory (plant.toml): certificates,
    /// keys, trust file, operators files, routers' access control,
    /// Prometheus targets, console and systemd instances made from it, and
    /// the running plant checked against it.
    #[command(subcommand)]
    Plant(PlantCommand),
    /// Run a plant router: Zenoh's router (as `zenohd -c` runs it) from
    /// its configuration, with Zenoh's storage manager keeping the plant
    /// archive (every cell's signed alarm events, states and recordings,
    /// read by `history --plant` when an agent is down or gone).
    Router(commands::router::Args),
    /// Learn transition timers δ(A, E | Δt) = B from logs of normal runs;
    /// with --sfc, the supervision time of every step of the charts instead.
    Learn(LearnArgs),
    /// Run the transition-timer monitor over run logs in virtual time.
    Replay(ReplayArgs),
    /// Write a timer model as IEC 61131-3 Structured Text: the paper's
    /// diagnosis functions (ERROR_ALARM_nnn, ERROR_RESET_nnn) for the PLC.
    ExportSt(ExportStArgs),
    /// Reports from a journal: production (per-hour run/idle/fault minutes,
    /// availability, stop causes and production, daily or per day monthly)
    /// and the alarm system's ISA-18.2 performance (alarms).
    Report(ReportArgs),
    /// Browse an OPC UA server and print its variables as a cell
    /// configuration (`[[tags]]` with node ids by namespace URI, address,
    /// data type and comment), or check a configuration's tags against it.
    ///
    /// Connects as `run` does: the security policy and mode given, the PKI
    /// directory's key pair, a server certificate trusted only from its
    /// `trusted/` folder.
    Discover(DiscoverArgs),
    /// Trust an OPC UA server's certificate in one go: shows it (subject,
    /// validity, SHA-256 fingerprint, thumbprint), trusts it on
    /// confirmation (or --yes), shows the agent's own certificate for the
    /// server's trusted clients and whether the server accepts it yet.
    TrustServer(commands::trust_server::TrustServerArgs),
    /// Check a journal: its command rows' hash chain (audit verify).
    Audit(commands::audit::Args),
    /// Look after a journal: an online, consistent backup while its agent
    /// runs (journal backup).
    Journal(commands::journal::Args),
    /// Write the manual pages (troff), one per command, into a folder:
    /// generated from the command line's own definitions, as the package
    /// installs them.
    Man(commands::man::Args),
}

/// Puts the calling thread under SCHED_FIFO at `priority`; on Linux every
/// thread it starts afterwards inherits the policy.
pub(crate) fn realtime(priority: u8) -> Result<(), Failure> {
    use thread_priority::{
        set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy,
        ThreadPriority, ThreadSchedulePolicy,
    };
    let refused = |why: String| {
        Failure::Runtime(format!(
            "--realtime-priority {priority}: the system refused SCHED_FIFO ({why}); run as root, or give the agent CAP_SYS_NICE or an RLIMIT_RTPRIO of at least {priority} (systemd: LimitRTPRIO={priority})"
        ))
    };
    let value = priority
        .try_into()
        .map_err(|_| Failure::Input(format!("--realtime-priority {priority}: not in 1–99")))?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| match e {
        thread_priority::Error::OS(code) => {
            refused(std::io::Error::from_raw_os_error(code).to_string())
        }
        e => refused(e.to_string()),
    })
}

/// Runs a command that needs the tokio runtime.
fn asynchronous(command: Command, out: &mut dyn Write) -> Result<(), Failure> {
    let quiet = matches!(
        command,
        Command::Alarms(_)
            | Command::History(_)
            | Command::Ack(_)
            | Command::Reset(_)
            | Command::Write(_)
            | Command::Force(_)
            | Command::Stop(_)
            | Command::Reload(_)
            | Command::Shelve(_)
            | Command::Unshelve(_)
            | Command::OutOfService(_)
            | Command::InService(_)
            | Command::Discover(_)
            | Command::TrustServer(_)
    );
    #[cfg(feature = "simulators")]
    let quiet = quiet || matches!(command, Command::Demo(_));
    let filter = std::env::var("RUST_LOG").unwrap_or_else(|_| {
        if quiet {
            // The OPC UA stack's own errors of a refused connection are
            // said once, with what to do, by the command.
            "error,opcua_client=off,opcua_types=off,opcua_core=off".into()
        } else {
            "warn,cellwatch=info".into()
        }
    });
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::new(filter))
        .with_writer(std::io::stderr)
        // Colours only for a terminal: log files and pipes get plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
    if let Command::Run(RunArgs {
        realtime_priority: Some(priority),
        ..
    }) = &command
    {
        // Before the runtime: its threads, and every thread they start,
        // inherit the policy.
        realtime(*priority)?;
        tracing::info!(priority, "the agent's threads run under SCHED_FIFO");
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::Runtime(format!("cannot start the runtime: {e}")))?;
    runtime.block_on(async {
        match command {
            Command::Run(args) => commands::agent::run(&args).await,
            #[cfg(feature = "simulators")]
            Command::Demo(args) => commands::demo::demo(&args, out).await,
            #[cfg(feature = "simulators")]
            Command::Simulate(SimulateCommand::Line(args)) => commands::simulate::line(&args, out),
            #[cfg(feature = "simulators")]
            Command::Simulate(SimulateCommand::RobotRuns(args)) => {
                commands::simulate::robot_runs(&args, out)
            }
            #[cfg(feature = "simulators")]
            Command::Simulate(SimulateCommand::Cnc(args)) => {
                commands::simulate::cnc(&args, out).await
            }
            #[cfg(feature = "simulators")]
            Command::Simulate(SimulateCommand::Moulding(args)) => {
                commands::simulate::moulding(&args, out).await
            }
            Command::Console(args) => commands::console::run(&args, out).await,
            Command::Router(args) => commands::router::run(&args, out).await,
            Command::Alarms(args) => commands::bus::alarms(&args, out).await,
            Command::History(args) if args.plant => commands::archive::history(&args, out).await,
            Command::History(args) => commands::bus::history(&args, out).await,
            Command::Audit(args) => commands::audit::run(&args, out).await,
            Command::Ack(args) => commands::bus::ack(&args, out).await,
            Command::Reset(args) => commands::bus::command(Action::Reset, &args, out).await,
            Command::Write(args) => commands::bus::write(&args, out).await,
            Command::Force(args) => commands::bus::force(&args, out).await,
            Command::Stop(args) => commands::bus::stop(&args, out).await,
            Command::Reload(args) => commands::bus::reload(&args, out).await,
            Command::Shelve(args) => commands::bus::shelve(&args, out).await,
            Command::Unshelve(args) => commands::bus::command(Action::Unshelve, &args, out).await,
            Command::OutOfService(args) => commands::bus::out_of_service(&args, out).await,
            Command::InService(args) => commands::bus::command(Action::InService, &args, out).await,
            Command::Discover(args) => commands::discover::run(&args, out).await,
            Command::TrustServer(args) => commands::trust_server::run(&args, out).await,
            Command::Plant(PlantCommand::Check(args)) => {
                commands::plant::run_check(&args, out).await
            }
            Command::Plant(PlantCommand::Publish(args)) => {
                commands::plant::publish(&args, out).await
            }
            // Dispatched synchronously by `run`; never sent here.
            Command::Sf(_)
            | Command::Sfc(_)
            | Command::Mad(_)
            | Command::Explain(_)
            | Command::Validate(_)
            | Command::Report(_)
            | Command::Learn(_)
            | Command::Keygen(_)
            | Command::HashPassword(_)
            | Command::Pki(_)
            | Command::Plant(_)
            | Command::Replay(_)
            | Command::ExportSt(_)
            | Command::Journal(_)
            | Command::Man(_) => Ok(()),
        }
    })
}

/// Runs the command line `args` (program name first), writing output to
/// `out` and diagnostics to `err`; returns the exit status.
pub fn run(
    args: impl IntoIterator<Item = impl Into<OsString> + Clone>,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> u8 {
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let text = e.render().to_string();
            let _ = if e.use_stderr() {
                err.write_all(text.as_bytes())
            } else {
                out.write_all(text.as_bytes())
            };
            return code;
        }
    };
    let result = match cli.command {
        Command::Sf(args) => commands::sf::run(&args, out, err),
        Command::Sfc(command) => commands::sfc::run(&command, out),
        Command::Mad(command) => commands::mad::run(&command, out),
        Command::Explain(args) => commands::explain::run(&args, out, err),
        Command::Validate(args) => commands::agent::validate(&args, out),
        Command::Report(args) => commands::report::run(&args, out),
        Command::Learn(args) => commands::timers::learn(&args, out),
        Command::Keygen(args) => commands::keygen::run(&args, out),
        Command::HashPassword(_) => commands::hash_password::run(&mut std::io::stdin().lock(), out),
        Command::Pki(PkiCommand::Ca(args)) => commands::pki::ca(&args, out),
        Command::Pki(PkiCommand::Issue(args)) => commands::pki::issue_command(&args, out),
        Command::Pki(PkiCommand::AgentKey(args)) => commands::pki::agent_key(&args, out),
        Command::Plant(PlantCommand::Init(args)) => commands::plant::init(&args, out),
        Command::Plant(PlantCommand::AddCell(args)) => commands::plant::add_cell(&args, out),
        Command::Plant(PlantCommand::RotateKey(args)) => commands::plant::rotate_key(&args, out),
        Command::Plant(PlantCommand::Renew(args)) => commands::plant::renew(&args, out),
        Command::Plant(PlantCommand::AddOperator(args)) => {
            commands::plant::add_operator(&args, out)
        }
        Command::Replay(args) => commands::timers::replay(&args, out),
        Command::ExportSt(args) => commands::timers::export_st(&args, out),
        Command::Journal(args) => commands::journal::run(&args, out),
        Command::Man(args) => {
            commands::man::run(&args, <Cli as clap::CommandFactory>::command(), out)
        }
        other => asynchronous(other, out),
    };
    match result {
        Ok(()) => 0,
        Err(Failure::Input(msg)) => {
            let _ = writeln!(err, "error: {msg}");
            2
        }
        Err(Failure::Runtime(msg)) => {
            let _ = writeln!(err, "error: {msg}");
            1
        }
    }
}
