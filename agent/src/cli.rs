//! The command line: what each command takes, and how outcomes become exit
//! statuses (0 success, 1 runtime failure, 2 bad input).

use std::ffi::OsString;
use std::io::Write;
use std::path::PathBuf;

use cellwatch_models::explain::Polarity;
use cellwatch_models::il::Dialect;
use clap::{Parser, Subcommand};

use crate::commands;
use crate::operator::Action;

/// cellwatch — watches a PLC and names the step and the contact behind every fault.
///
/// Compiles PLC logic (instruction lists, FANUC PMC or IEC 61131-3) into the
/// switching function of each fault coil, splits it into step blocks, and at
/// fault time names the step and the contacts that caused it, with their
/// comments from the machine's I/O list.
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
    /// Explain a fault: the coil's value, every step's value, the fault step
    /// and the contacts that caused it.
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
    Demo(DemoArgs),
    /// Serve a simulated cell over OPC UA.
    #[command(subcommand)]
    Simulate(SimulateCommand),
    /// Show active alarms of running agents, or follow alarm events (Zenoh).
    Alarms(AlarmsArgs),
    /// Show a cell's machine-state, alarm and command history (Zenoh).
    History(HistoryArgs),
    /// Acknowledge an alarm: a signed command to the cell's agent (Zenoh).
    Ack(CommandArgs),
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
    /// Make an operator's key pair for signing commands (Ed25519).
    ///
    /// Writes the private key file, which stays with the operator (give it
    /// to `ack` and `reset` with --key-file), and prints the entry for the
    /// agents' operators file: the public key and the actions allowed. An
    /// agent holds public keys only.
    Keygen(KeygenArgs),
    /// Certificates for the Zenoh bus: a plant CA, and certificates issued
    /// from it for agents, routers and operators (mutual TLS; the access
    /// control matches their common names).
    #[command(subcommand)]
    Pki(PkiCommand),
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
    /// Check a journal: its command rows' hash chain (audit verify).
    Audit(commands::audit::Args),
}

#[derive(Debug, Subcommand)]
pub(crate) enum PkiCommand {
    /// Create the plant CA: DIR/ca.pem (public) and DIR/ca.key (private).
    Ca(PkiCaArgs),
    /// Issue a certificate from the CA in DIR: DIR/NAME.pem and DIR/NAME.key.
    /// NAME is its common name: `agent-<cell>` for an agent, `router-…` for
    /// a router, `operator-<name>` for an operator (as config/zenoh/ expects).
    Issue(PkiIssueArgs),
    /// Make a cell agent's Ed25519 signing key (`zenoh.signing_key`), or
    /// read an existing one, and print its entry for the plant trust file
    /// that clients check every alarm and answer against.
    AgentKey(PkiAgentKeyArgs),
}

#[derive(Debug, clap::Args)]
pub(crate) struct PkiAgentKeyArgs {
    /// The cell whose agent signs with it.
    #[arg(long)]
    pub(crate) cell: String,
    /// The key file (owner-only); an existing one is read, never
    /// overwritten.
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct PkiCaArgs {
    /// Where the CA's files go.
    #[arg(long, default_value = "pki-bus")]
    pub(crate) dir: PathBuf,
    /// The CA's common name.
    #[arg(long, default_value = "cellwatch plant CA")]
    pub(crate) name: String,
}

#[derive(Debug, clap::Args)]
pub(crate) struct PkiIssueArgs {
    /// Where the CA is, and where the certificate goes.
    #[arg(long, default_value = "pki-bus")]
    pub(crate) dir: PathBuf,
    /// The common name.
    #[arg(long)]
    pub(crate) name: String,
    /// Host name or IP address the holder listens on (repeatable; default
    /// localhost and 127.0.0.1). Clients check it when they connect.
    #[arg(long)]
    pub(crate) host: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct KeygenArgs {
    /// The operator's name, as agents' operators files will know it.
    #[arg(long)]
    pub(crate) operator: String,
    /// Where to write the private key (never overwritten).
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,
    /// Actions to allow in the printed entry, comma-separated (ack, reset,
    /// write: writes to the PLC, only for those who may).
    #[arg(long, default_value = "ack", value_name = "LIST")]
    pub(crate) allow: String,
}

#[derive(Debug, clap::Args)]
pub(crate) struct LearnArgs {
    /// Run logs: CSV `time_ms,tag,value`, or the paper's `t,e` form with --map.
    #[arg(required = true)]
    pub(crate) runs: Vec<PathBuf>,
    /// Signal map `number,tag` for logs in the paper's numeric form.
    #[arg(long, value_name = "CSV")]
    pub(crate) map: Option<PathBuf>,
    /// Shortest Δt kept (shorter transitions are the program flipping its own signals).
    #[arg(long, default_value = "2s")]
    pub(crate) delta_min: String,
    /// Fixed tolerance τ (default 100ms).
    #[arg(long, conflicts_with = "tau_auto")]
    pub(crate) tau: Option<String>,
    /// τ per transition: max(2 × largest training deviation, 5 % of Δt, 100 ms).
    #[arg(long)]
    pub(crate) tau_auto: bool,
    /// Runs a transition must be seen in (default: every run).
    #[arg(long)]
    pub(crate) min_support: Option<usize>,
    /// Learning method: `common` (each event timed from its most consistent
    /// trigger; copes with stations running in parallel) or `full-state`
    /// (the paper's: timed from entering the full state).
    #[arg(long, default_value = "common")]
    pub(crate) method: String,
    /// Learn step supervision times for these charts (`.sfc.toml`) instead
    /// of transition timers: each step's longest duration in the runs plus
    /// max(half of it, twice the spread, 1 s). The file goes to a
    /// `[[checks.sfc]]` `steps` key; a supervision declared in the charts wins.
    #[arg(
        long,
        value_name = "CHARTS",
        conflicts_with_all = ["tau", "tau_auto", "table", "method", "delta_min"]
    )]
    pub(crate) sfc: Option<PathBuf>,
    /// Where to write the model (JSON; default timers.json, with --sfc
    /// steps.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Also print the paper's Fig. 12 view: transitions × signals (1, 0, or
    /// . when the signal is not in the start condition; E marks the event).
    #[arg(long)]
    pub(crate) table: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ExportStArgs {
    /// The timer model (JSON, from `cellwatch learn`).
    #[arg(long)]
    pub(crate) timers: PathBuf,
    /// Name of the function block.
    #[arg(long, default_value = "FB_CELLWATCH_TIMERS")]
    pub(crate) name: String,
    /// Write to this file instead of standard output.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ReplayArgs {
    /// The timer model (JSON, from `cellwatch learn`).
    #[arg(long)]
    pub(crate) timers: PathBuf,
    /// Run logs to replay.
    #[arg(required = true)]
    pub(crate) runs: Vec<PathBuf>,
    /// Signal map for logs in the paper's numeric form.
    #[arg(long, value_name = "CSV")]
    pub(crate) map: Option<PathBuf>,
    /// One JSON outcome per line: {outcome, transition, at_ms, observed_ms}.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ReportArgs {
    #[command(subcommand)]
    pub(crate) command: ReportCommand,
    /// The agent's SQLite journal.
    #[arg(long, global = true, default_value = "cellwatch.sqlite")]
    pub(crate) db: PathBuf,
    /// Stop-cause table (TOML, `[[cause]] code, name, fault_type | state`).
    #[arg(long, global = true, default_value = "config/stop-causes.toml")]
    pub(crate) causes: PathBuf,
    /// The plant's offset from UTC, for day boundaries (+09:00).
    #[arg(
        long,
        global = true,
        default_value = "+00:00",
        allow_hyphen_values = true
    )]
    pub(crate) utc_offset: String,
    /// CSV instead of a table.
    #[arg(long, global = true, conflicts_with = "json")]
    pub(crate) csv: bool,
    /// JSON instead of a table.
    #[arg(long, global = true)]
    pub(crate) json: bool,
}

impl ReportArgs {
    pub(crate) fn format(&self) -> crate::commands::report::Format {
        use crate::commands::report::Format;
        match (self.csv, self.json) {
            (true, _) => Format::Csv,
            (_, true) => Format::Json,
            _ => Format::Table,
        }
    }
}

#[derive(Debug, Subcommand)]
pub(crate) enum ReportCommand {
    /// One day: 24 hourly slots (paper 002, Table 3).
    Daily {
        /// The day, 2026-11-21.
        #[arg(long)]
        date: String,
    },
    /// One month, day by day (paper 002, Table 5).
    Monthly {
        /// The month, 2026-11.
        #[arg(long)]
        month: String,
    },
    /// The alarm system's performance (ISA-18.2 / IEC 62682) over a day or
    /// a month, each figure against its target: average and peak alarm
    /// rate per 10 minutes, 10-minute intervals in flood, the 10 most
    /// frequent alarms and their share, chattering and stale alarms,
    /// priority distribution, shelving and out-of-service use,
    /// acknowledgement times.
    #[command(group(clap::ArgGroup::new("period").required(true).args(["date", "month"])))]
    Alarms {
        /// One day, 2026-11-21.
        #[arg(long)]
        date: Option<String>,
        /// One month, 2026-11.
        #[arg(long)]
        month: Option<String>,
    },
}

#[derive(Debug, Subcommand)]
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
pub(crate) struct DiscoverArgs {
    /// The server's endpoint (opc.tcp://host:port/path); with --check, the
    /// configuration's endpoint unless given.
    #[arg(required_unless_present = "check")]
    pub(crate) endpoint: Option<String>,
    /// Where to start browsing (a node id: nsu=<uri>;s=Machine or
    /// ns=2;i=1000); the Objects folder by default.
    #[arg(long)]
    pub(crate) root: Option<String>,
    /// How many levels of folders and objects to descend.
    #[arg(long, default_value_t = 10)]
    pub(crate) depth: u32,
    /// Only variables whose browse name matches this glob (`X0.*`, `D1??`).
    #[arg(long)]
    pub(crate) filter: Option<String>,
    /// Write the tags found to this CSV file (the `tags_file` format: one
    /// row a tag, columns name, node_id, address, type, comment) instead
    /// of `[[tags]]` tables, and print a configuration that reads it: for
    /// servers of thousands of tags. Replaces the file if it exists.
    #[arg(long, value_name = "PATH", conflicts_with = "check")]
    pub(crate) tags_file: Option<PathBuf>,
    /// Check this cell configuration instead: report the tags the server
    /// lacks or types differently (exit status 1 if any); connects with
    /// the configuration's [opcua] settings.
    #[arg(long)]
    pub(crate) check: Option<PathBuf>,
    /// PKI directory (own key pair, trusted/ and rejected/ certificates).
    #[arg(long, default_value = "pki")]
    pub(crate) pki_dir: PathBuf,
    /// Basic256Sha256 | Aes128_Sha256_RsaOaep | Aes256_Sha256_RsaPss | None.
    #[arg(long, default_value = "Basic256Sha256")]
    pub(crate) security_policy: crate::config::SecurityPolicy,
    /// SignAndEncrypt | Sign | None.
    #[arg(long, default_value = "SignAndEncrypt")]
    pub(crate) security_mode: crate::config::SecurityMode,
    /// Log in as this user (the password from --password-env).
    #[arg(long, requires = "password_env")]
    pub(crate) user: Option<String>,
    /// The environment variable holding the user's password.
    #[arg(long)]
    pub(crate) password_env: Option<String>,
}

impl DiscoverArgs {
    /// The connection the flags describe.
    pub(crate) fn opcua(&self) -> Result<crate::config::OpcUaConfig, Failure> {
        use crate::config::{Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy};
        let endpoint = self.endpoint.clone().unwrap_or_default();
        if !endpoint.starts_with("opc.tcp://") {
            return Err(Failure::input(format!(
                "'{endpoint}' must start with opc.tcp://"
            )));
        }
        if (self.security_policy == SecurityPolicy::None)
            != (self.security_mode == SecurityMode::None)
        {
            return Err(Failure::input(
                "--security-policy None goes with --security-mode None, and only with it",
            ));
        }
        let publishing = std::time::Duration::from_millis(100);
        let sampling = std::time::Duration::from_millis(50);
        Ok(OpcUaConfig {
            endpoint,
            policy: self.security_policy,
            mode: self.security_mode,
            pki_dir: self.pki_dir.clone(),
            identity: match (&self.user, &self.password_env) {
                (Some(user), Some(var)) => Identity::User {
                    user: user.clone(),
                    password: PasswordSource::Env(var.clone()),
                },
                _ => Identity::Anonymous,
            },
            publishing_interval: publishing,
            sampling_interval: sampling,
            namespace_uri: None,
            queue_size: OpcUaConfig::default_queue_size(publishing, sampling),
            max_notifications_per_publish: OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS,
        })
    }
}

#[derive(Debug, clap::Args)]
pub(crate) struct ValidateArgs {
    /// The cell configuration (TOML).
    pub(crate) config: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct DemoArgs {
    /// The cell configuration to run (its OPC UA endpoint is where the
    /// simulator listens).
    #[arg(long, default_value = "config/demo.toml")]
    pub(crate) config: PathBuf,
    /// The body-shop line's cell configuration, run beside the CNC.
    #[arg(long, default_value = "config/line.toml")]
    pub(crate) line_config: PathBuf,
    /// Run the CNC only (no line).
    #[arg(long)]
    pub(crate) no_line: bool,
    /// The moulding units' cell configuration (paper 002), run beside the
    /// CNC: three units on one simulated `@` bus.
    #[arg(long, default_value = "config/moulding.toml")]
    pub(crate) moulding_config: PathBuf,
    /// No moulding units.
    #[arg(long)]
    pub(crate) no_moulding: bool,
    /// The robot's cell configuration (paper 004), run beside the CNC: the
    /// LCD-glass robot's charts supervised, stuck steps forced on.
    #[arg(long, default_value = "config/robot.toml")]
    pub(crate) robot_config: PathBuf,
    /// No robot.
    #[arg(long)]
    pub(crate) no_robot: bool,
    /// Where the demo keeps certificates, the journal and operator keys.
    #[arg(long, default_value = "cellwatch-demo")]
    pub(crate) state_dir: PathBuf,
    /// Stop after this long (e.g. 60s); default: until Ctrl-C.
    #[arg(long, value_parser = crate::commands::agent::parse_duration)]
    pub(crate) duration: Option<std::time::Duration>,
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

/// How the Zenoh clients reach agents.
#[derive(Debug, clap::Args)]
pub(crate) struct ZenohArgs {
    /// Zenoh endpoint of an agent or router; repeatable (default
    /// quic/127.0.0.1:7447, or tcp/127.0.0.1:7447 with --plain).
    #[arg(long)]
    pub(crate) connect: Vec<String>,
    /// The plant CA's certificate (PEM): only agents and routers with a
    /// certificate it issued are accepted. Needs --tls-cert and --tls-key.
    #[arg(long, value_name = "PEM", requires_all = ["tls_cert", "tls_key"])]
    pub(crate) tls_ca: Option<PathBuf>,
    /// Your certificate from the plant CA (`cellwatch pki issue`).
    #[arg(long, value_name = "PEM", requires = "tls_ca")]
    pub(crate) tls_cert: Option<PathBuf>,
    /// Your certificate's private key.
    #[arg(long, value_name = "PEM", requires = "tls_ca")]
    pub(crate) tls_key: Option<PathBuf>,
    /// A Zenoh configuration file (JSON5) for anything else Zenoh offers;
    /// the flags above are laid over it. This client listens on nothing
    /// and scouts nothing, whatever the file says, and every endpoint must
    /// be TLS with the plant CA unless --plain.
    #[arg(long, value_name = "JSON5")]
    pub(crate) zenoh_config: Option<PathBuf>,
    /// The plant trust file: each cell's agent's public key. Every alarm
    /// and answer is believed only if the cell's own agent signed it.
    #[arg(long, value_name = "TOML", env = "CELLWATCH_TRUST")]
    pub(crate) trust: Option<PathBuf>,
    /// Accept a bus without TLS (plain TCP): neither encrypted nor
    /// authenticated. Signatures are still checked.
    #[arg(long)]
    pub(crate) plain: bool,
    /// Zenoh mode of this client: peer or client (of a router).
    #[arg(long, default_value = "peer")]
    pub(crate) mode: String,
    /// Root of the agents' key prefixes (`<root>/<cell>/...`).
    #[arg(long, default_value = "cellwatch")]
    pub(crate) root: String,
    /// Seconds to wait for answers.
    #[arg(long = "timeout", default_value_t = 5)]
    pub(crate) timeout_secs: u64,
}

#[derive(Debug, clap::Args)]
pub(crate) struct AlarmsArgs {
    /// Only this cell (default: every cell).
    #[arg(long)]
    pub(crate) cell: Option<String>,
    /// Follow alarm events as they happen (recovering any missed) until Ctrl-C.
    #[arg(long)]
    pub(crate) follow: bool,
    /// With --follow: first the cell's alarm events since then, from its
    /// journal (a duration back from now such as 1h, or an RFC 3339 time),
    /// even those from before the agent last restarted. Needs --cell.
    #[arg(long, requires = "follow")]
    pub(crate) since: Option<String>,
    /// One JSON alarm event per line.
    #[arg(long)]
    pub(crate) json: bool,
    #[command(flatten)]
    pub(crate) zenoh: ZenohArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct HistoryArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// From: a duration back from now (1h, 30m) or an RFC 3339 time.
    #[arg(long, default_value = "24h")]
    pub(crate) since: String,
    /// Until: same forms; default now.
    #[arg(long)]
    pub(crate) until: Option<String>,
    /// Only `state`, `alarm` or `command` rows.
    #[arg(long)]
    pub(crate) kind: Option<String>,
    /// At most this many rows (the newest); one reply also holds at most
    /// 1 MiB of rows.
    #[arg(long, default_value_t = 1000)]
    pub(crate) limit: usize,
    /// Every row of the range, oldest first, fetched in pages of `--limit`
    /// rows.
    #[arg(long)]
    pub(crate) all: bool,
    /// The pages as the agent sends them (one JSON object per line:
    /// `rows`, `more`, `next`).
    #[arg(long)]
    pub(crate) json: bool,
    #[command(flatten)]
    pub(crate) zenoh: ZenohArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct CommandArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The alarm id.
    #[arg(long)]
    pub(crate) alarm: String,
    #[command(flatten)]
    pub(crate) signer: SignerArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ShelveArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The alarm id.
    #[arg(long)]
    pub(crate) alarm: String,
    /// How long (`30m`, `2h`).
    #[arg(long = "for", conflicts_with = "once")]
    pub(crate) duration: Option<String>,
    /// One-shot: until the alarm clears.
    #[arg(long)]
    pub(crate) once: bool,
    /// Why (journaled and published with the shelf).
    #[arg(long)]
    pub(crate) reason: String,
    #[command(flatten)]
    pub(crate) signer: SignerArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ReasonArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The alarm id.
    #[arg(long)]
    pub(crate) alarm: String,
    /// Why (journaled and published with the alarm).
    #[arg(long)]
    pub(crate) reason: String,
    #[command(flatten)]
    pub(crate) signer: SignerArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct WriteArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The tag written, by address (a legacy unit's item code `J2`, target
    /// `T2` or production `P2`, as the cell's configuration names them).
    #[arg(long)]
    pub(crate) tag: String,
    /// The value: a quantity (0-999999) or an item code (up to 8 of A-Z,
    /// 0-9, -).
    #[arg(long, allow_hyphen_values = true)]
    pub(crate) value: String,
    #[command(flatten)]
    pub(crate) signer: SignerArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ForceArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The chart (`F1`).
    #[arg(long)]
    pub(crate) chart: String,
    /// The transition of that chart to fire (`t3`).
    #[arg(long)]
    pub(crate) transition: String,
    #[command(flatten)]
    pub(crate) signer: SignerArgs,
}

#[derive(Debug, clap::Args)]
pub(crate) struct StopArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The chart whose stop switch is pressed (`F1`).
    #[arg(long)]
    pub(crate) chart: String,
    #[command(flatten)]
    pub(crate) signer: SignerArgs,
}

/// Who signs a command, and how it reaches the agent.
#[derive(Debug, clap::Args)]
pub(crate) struct SignerArgs {
    /// Who you are (default: the operator the key file names).
    #[arg(long)]
    pub(crate) operator: Option<String>,
    /// Your private key file, made by `cellwatch keygen --operator NAME`;
    /// or set CELLWATCH_OPERATOR_KEY to the key's 64 hex digits (then give
    /// --operator).
    #[arg(long, value_name = "FILE")]
    pub(crate) key_file: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) zenoh: ZenohArgs,
}

/// Where the program comes from and how to read it.
#[derive(Debug, clap::Args)]
pub(crate) struct ProgramArgs {
    /// The PLC program: an instruction list file.
    #[arg(value_name = "PROGRAM")]
    pub(crate) program: PathBuf,
    /// The instruction-list dialect: `pmc` (RD, AND.NOT, WRT; X0.07),
    /// `iec` (LD, ANDN, ST; %IX0.0.3) or `stl` (Siemens STL/AWL: U, UN, =;
    /// E 0.0, or A, AN; I 0.0). Detected from the mnemonics if not given.
    #[arg(long, value_name = "pmc|iec|stl", value_parser = parse_dialect)]
    pub(crate) dialect: Option<Dialect>,
    /// Signals the SF may stop at, comma-separated: classes (`X,Y,F,G`;
    /// `%I,%Q`; `E,A`) or single signals (`R1024.00`). Default: X, Y, F, G
    /// for pmc; %I, %Q for iec; E, A, I, Q for stl.
    #[arg(long, value_name = "LIST")]
    pub(crate) observable: Option<String>,
    /// The I/O database: CSV `address,comment`, one row per address.
    #[arg(long, value_name = "CSV")]
    pub(crate) comments: Option<PathBuf>,
    /// The program file's encoding: `utf-8`, `utf-16le`, `utf-16be`,
    /// `latin1` (Windows-1252)... Default: a byte-order mark decides, then
    /// UTF-8 if the bytes are UTF-8, else Latin-1 (Windows-1252).
    #[arg(long, value_name = "NAME", value_parser = parse_encoding)]
    pub(crate) encoding: Option<&'static cellwatch_models::source::Encoding>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub(crate) json: bool,
}

fn parse_encoding(s: &str) -> Result<&'static cellwatch_models::source::Encoding, String> {
    cellwatch_models::source::encoding(s)
}

#[derive(Debug, Subcommand)]
pub(crate) enum SfcCommand {
    /// Check a chart file (every problem with file, line and column) and
    /// list its charts: steps with flag, supervision and comment, and
    /// transitions with source, target and condition.
    Check {
        /// The chart file (TOML).
        charts: PathBuf,
    },
    /// For each transition named, the term paper 004's eq. (3)/(4) adds so
    /// that the force switch can fire it while its condition holds —
    /// `(S14 · t15) + (ForceSW · t15)` — as IEC 61131-3 ST and IL, for the
    /// engineer to add to the PLC program.
    Patch {
        /// The chart file (TOML).
        charts: PathBuf,
        /// The force switch's address in the PLC (`%IX0.3.1`).
        #[arg(long, value_name = "ADDRESS")]
        force_switch: String,
        /// A transition to make forcible, `CHART.ID` (`F1.t3`); repeat for
        /// several.
        #[arg(long = "transition", value_name = "CHART.ID", required = true)]
        transitions: Vec<String>,
    },
}

#[derive(Debug, clap::Args)]
pub(crate) struct SfArgs {
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// A coil to print; repeat for several. Default: every coil the program writes.
    #[arg(long, value_name = "NAME")]
    pub(crate) coil: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ExplainArgs {
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// The fault coil to explain.
    #[arg(long, value_name = "NAME")]
    pub(crate) coil: String,
    /// Signal values at the fault: inline `X0.06=0,X0.07=1`, or a file with
    /// one `ADDRESS=VALUE` (or CSV `ADDRESS,VALUE`) a line. Values: 0/1,
    /// true/false, on/off.
    #[arg(long, value_name = "VALUES")]
    pub(crate) snapshot: String,
    /// Signal values just before the fault, same forms; contacts that changed
    /// are marked as the trigger.
    #[arg(long, value_name = "VALUES")]
    pub(crate) before: Option<String>,
    /// Which coil value is the fault: `on` (an alarm coil) or `off` (an enable coil).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_polarity)]
    pub(crate) fault_when: Polarity,
}

fn parse_dialect(s: &str) -> Result<Dialect, String> {
    s.parse()
}

fn parse_polarity(s: &str) -> Result<Polarity, String> {
    s.parse()
}

/// Why a command failed. Each error is sorted into one of the two by the
/// code that knows what failed; there is no blanket conversion.
#[derive(Debug)]
pub(crate) enum Failure {
    /// The user's input is wrong: exit status 2.
    Input(String),
    /// Something failed while running: exit status 1.
    Runtime(String),
}

impl Failure {
    /// Bad input: a file, flag or value the user gave.
    pub(crate) fn input(e: impl std::fmt::Display) -> Failure {
        Failure::Input(e.to_string())
    }

    /// A failure while running.
    pub(crate) fn runtime(e: impl std::fmt::Display) -> Failure {
        Failure::Runtime(e.to_string())
    }

    /// Writing the command's output failed (a closed pipe, a full disk).
    pub(crate) fn output(e: std::io::Error) -> Failure {
        Failure::Runtime(format!("cannot write output: {e}"))
    }
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
        Command::Demo(_)
            | Command::Alarms(_)
            | Command::History(_)
            | Command::Ack(_)
            | Command::Reset(_)
            | Command::Write(_)
            | Command::Force(_)
            | Command::Stop(_)
            | Command::Shelve(_)
            | Command::Unshelve(_)
            | Command::OutOfService(_)
            | Command::InService(_)
            | Command::Discover(_)
    );
    let filter = std::env::var("RUST_LOG").unwrap_or_else(|_| {
        if quiet {
            "error".into()
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
            Command::Demo(args) => commands::agent::demo(&args, out).await,
            Command::Simulate(SimulateCommand::Line(args)) => commands::simulate::line(&args, out),
            Command::Simulate(SimulateCommand::RobotRuns(args)) => {
                commands::simulate::robot_runs(&args, out)
            }
            Command::Simulate(SimulateCommand::Cnc(args)) => {
                commands::simulate::cnc(&args, out).await
            }
            Command::Simulate(SimulateCommand::Moulding(args)) => {
                commands::simulate::moulding(&args, out).await
            }
            Command::Alarms(args) => commands::subscribers::alarms(&args, out).await,
            Command::History(args) => commands::subscribers::history(&args, out).await,
            Command::Ack(args) => commands::subscribers::command(Action::Ack, &args, out).await,
            Command::Reset(args) => commands::subscribers::command(Action::Reset, &args, out).await,
            Command::Write(args) => commands::subscribers::write(&args, out).await,
            Command::Force(args) => commands::subscribers::force(&args, out).await,
            Command::Stop(args) => commands::subscribers::stop(&args, out).await,
            Command::Shelve(args) => commands::subscribers::shelve(&args, out).await,
            Command::Unshelve(args) => {
                commands::subscribers::command(Action::Unshelve, &args, out).await
            }
            Command::OutOfService(args) => commands::subscribers::out_of_service(&args, out).await,
            Command::InService(args) => {
                commands::subscribers::command(Action::InService, &args, out).await
            }
            Command::Discover(args) => commands::discover::run(&args, out).await,
            // Dispatched synchronously by `run`; never sent here.
            Command::Sf(_)
            | Command::Sfc(_)
            | Command::Explain(_)
            | Command::Validate(_)
            | Command::Report(_)
            | Command::Learn(_)
            | Command::Keygen(_)
            | Command::Pki(_)
            | Command::Replay(_)
            | Command::ExportSt(_)
            | Command::Audit(_) => Ok(()),
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
        Command::Explain(args) => commands::explain::run(&args, out, err),
        Command::Validate(args) => commands::agent::validate(&args, out),
        Command::Report(args) => commands::report::run(&args, out),
        Command::Learn(args) => commands::timers::learn(&args, out),
        Command::Keygen(args) => commands::keygen::run(&args, out),
        Command::Pki(PkiCommand::Ca(args)) => commands::pki::ca(&args, out),
        Command::Pki(PkiCommand::Issue(args)) => commands::pki::issue_command(&args, out),
        Command::Pki(PkiCommand::AgentKey(args)) => commands::pki::agent_key(&args, out),
        Command::Replay(args) => commands::timers::replay(&args, out),
        Command::ExportSt(args) => commands::timers::export_st(&args, out),
        Command::Audit(args) => commands::audit::run(&args, out),
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
