//! The bus commands' arguments: where the bus is, as whom, and what to ask.

use std::path::PathBuf;

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
    #[arg(long, default_value = crate::config::DEFAULT_ROOT)]
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
    /// Only `state`, `alarm` or `command` rows, or `recording`: the
    /// alarms' flight recordings, drawn as timing charts (asked for by name
    /// only: they are large); or, instead of rows, the
    /// agent's figures from its journal (JSON): `kpi`, the ISA-18.2 alarm
    /// figures of --since to --until (`cellwatch report alarms`), or
    /// `production`, the production day from --since (`cellwatch report
    /// daily`).
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
    /// `rows`, `more`, `next`); with --plant, each believed entry as its
    /// payload (one JSON object per line).
    #[arg(long)]
    pub(crate) json: bool,
    /// Read the plant archive the routers keep (`cellwatch router`), not
    /// the agent's journal: the cell's alarm events and machine states
    /// (and, with --kind recording, its flight recordings) even when its
    /// agent is down or its host is gone, each believed only if the cell's
    /// agent signed it. --cell '*' reads every cell. Commands are not in
    /// the archive (they are answered, not put).
    #[arg(long, conflicts_with_all = ["all", "limit"])]
    pub(crate) plant: bool,
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
pub(crate) struct AckArgs {
    /// The cell.
    #[arg(long)]
    pub(crate) cell: String,
    /// The alarm id.
    #[arg(long)]
    pub(crate) alarm: String,
    /// What you found or did, journaled after the acknowledgement (`ack
    /// ese by kim: tool changed`; its first 256 bytes).
    #[arg(long)]
    pub(crate) comment: Option<String>,
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

#[derive(Debug, clap::Args)]
pub(crate) struct ReloadArgs {
    /// The cell whose agent reads its configuration file again.
    #[arg(long)]
    pub(crate) cell: String,
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
