//! The cell configuration: one TOML file per cell.
//!
//! [`load`] reads the file and the files it names (programs, comment
//! databases); [`parse`] does the rest from text, so tests feed literals.
//! Parsing has two stages, as in Vector and zenoh: serde into the raw
//! structs of `raw` (unknown keys rejected), then validation into
//! [`CellConfig`], collecting *every* problem, each reported as
//! `FILE:LINE:COL: key: message`. `cellwatch validate CONFIG` runs exactly
//! this and connects to nothing.
//!
//! Relative paths are relative to the configuration file's directory.
//! Secrets never live in the file: an OPC UA password comes from an
//! environment variable or a file, and an inline `password` is an error.

pub mod legacy;
pub mod node;
mod raw;

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;
use std::net::SocketAddr;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use cellwatch_models::alarm::Severity;
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{PartCounting, StateRules, SwitchingCheck, Tag};
use cellwatch_models::explain::Polarity;
use cellwatch_models::expr::Expr;
use cellwatch_models::il::Dialect;
use cellwatch_models::limit::{Level, LimitCheck, LimitLevel};
use cellwatch_models::program::Program;
use cellwatch_models::sfc::learn::StepModel;
use cellwatch_models::sfc::Sfc;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::value::{Comparison, Counter, Operand, ValueType};
use toml::Spanned;

use legacy::{BusNode, LegacyConfig, Parity, SerialLine, Transport};
use node::TagNode;

use raw::RawConfig;

/// OPC UA message security policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SecurityPolicy {
    /// No security: only when written explicitly, with a warning.
    None,
    /// RSA-SHA256 with AES-256-CBC (the default).
    Basic256Sha256,
    /// RSA-OAEP-SHA256 with AES-128-CBC.
    Aes128Sha256RsaOaep,
    /// RSA-PSS-SHA256 with AES-256-CBC.
    Aes256Sha256RsaPss,
}

impl SecurityPolicy {
    /// The name as OPC UA tools write it.
    pub fn as_str(self) -> &'static str {
        match self {
            SecurityPolicy::None => "None",
            SecurityPolicy::Basic256Sha256 => "Basic256Sha256",
            SecurityPolicy::Aes128Sha256RsaOaep => "Aes128_Sha256_RsaOaep",
            SecurityPolicy::Aes256Sha256RsaPss => "Aes256_Sha256_RsaPss",
        }
    }
}

/// OPC UA message security mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SecurityMode {
    /// Plain text.
    None,
    /// Signed.
    Sign,
    /// Signed and encrypted (the default).
    SignAndEncrypt,
}

impl SecurityMode {
    /// The name as OPC UA tools write it.
    pub fn as_str(self) -> &'static str {
        match self {
            SecurityMode::None => "None",
            SecurityMode::Sign => "Sign",
            SecurityMode::SignAndEncrypt => "SignAndEncrypt",
        }
    }
}

impl FromStr for SecurityMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        [
            SecurityMode::None,
            SecurityMode::Sign,
            SecurityMode::SignAndEncrypt,
        ]
        .into_iter()
        .find(|m| m.as_str() == s)
        .ok_or_else(|| format!("unknown mode '{s}': use SignAndEncrypt, Sign or None"))
    }
}

impl FromStr for SecurityPolicy {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        [
            SecurityPolicy::None,
            SecurityPolicy::Basic256Sha256,
            SecurityPolicy::Aes128Sha256RsaOaep,
            SecurityPolicy::Aes256Sha256RsaPss,
        ]
        .into_iter()
        .find(|p| p.as_str() == s)
        .ok_or_else(|| {
            format!("unknown policy '{s}': use Basic256Sha256, Aes128_Sha256_RsaOaep, Aes256_Sha256_RsaPss or None")
        })
    }
}

/// Where the OPC UA password comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PasswordSource {
    /// An environment variable.
    Env(String),
    /// A file (its first line).
    File(PathBuf),
}

/// How the agent identifies itself to the server.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Identity {
    /// No user.
    Anonymous,
    /// A user name and password.
    User {
        /// The user name.
        user: String,
        /// Where the password is.
        password: PasswordSource,
    },
}

/// The OPC UA connection.
#[derive(Debug, Clone)]
pub struct OpcUaConfig {
    /// `opc.tcp://host:port/path`.
    pub endpoint: String,
    /// Message security policy.
    pub policy: SecurityPolicy,
    /// Message security mode.
    pub mode: SecurityMode,
    /// PKI directory: `own/`, `private/`, `trusted/`, `rejected/`.
    pub pki_dir: PathBuf,
    /// Who the agent is.
    pub identity: Identity,
    /// How often the server publishes changes.
    pub publishing_interval: Duration,
    /// How often the server samples each tag.
    pub sampling_interval: Duration,
    /// What `ns=<index>` (index 1 and up) in the tags' node ids means: the
    /// namespace with this URI, looked up on the server at every connect.
    pub namespace_uri: Option<String>,
    /// Changes the server queues per tag between publishes.
    pub queue_size: u32,
    /// The most notifications the server may put in one publish; the
    /// client's decoding limits are sized from it.
    pub max_notifications_per_publish: u32,
}

impl OpcUaConfig {
    /// The default of `opcua.max_notifications_per_publish`. A publish is
    /// handled as one step, cut after each alarm; an alarm waits for the
    /// changes ahead of it in its publish and for the publish being
    /// handled when it arrives: about 0.2 ms each at 1,000 changes on a
    /// 100,000-tag cell (BENCHMARKS.md), against 2 ms at 10,000. More
    /// publishes cost the source a little more per change.
    pub const DEFAULT_MAX_NOTIFICATIONS: u32 = 1_000;

    /// The default queue size: room for every sample of four publishing
    /// intervals (sampling 0, exception-based, counts as 1 ms), at least 10
    /// and at most 1000.
    pub fn default_queue_size(publishing: Duration, sampling: Duration) -> u32 {
        let sampling = sampling.max(Duration::from_millis(1));
        let per_publish = publishing.as_micros().div_ceil(sampling.as_micros());
        u32::try_from(per_publish.saturating_mul(4))
            .unwrap_or(u32::MAX)
            .clamp(10, 1000)
    }
}

/// A tag: a node on the server and the PLC address the models use.
#[derive(Debug, Clone, PartialEq)]
pub struct TagConfig {
    /// Plant name.
    pub name: String,
    /// OPC UA node id (`nsu=urn:plc;s=X0.06` or `ns=2;s=X0.06`), as written.
    pub node_id: String,
    /// PLC address (`X0.06`).
    pub address: Signal,
    /// Comment.
    pub comment: Option<String>,
    /// The node's data type (`type`, default Boolean).
    pub value_type: ValueType,
    /// One bit of an integer word (`bit = 7`): the tag is that contact.
    pub bit: Option<u8>,
    /// Sampling interval for this tag, instead of `opcua.sampling_interval`.
    pub sampling_interval: Option<Duration>,
    /// Data-change filter deadband for this tag.
    pub deadband: Option<Deadband>,
    /// Export the value as the `cellwatch_tag_value` gauge.
    pub export: bool,
    /// The largest value of a counter before it wraps to 0 (default: the
    /// type's maximum).
    pub max: Option<u64>,
}

impl TagConfig {
    /// A Boolean tag with defaults for everything else.
    pub fn boolean(name: &str, node_id: &str, address: Signal) -> TagConfig {
        TagConfig {
            name: name.into(),
            node_id: node_id.into(),
            address,
            comment: None,
            value_type: ValueType::Boolean,
            bit: None,
            sampling_interval: None,
            deadband: None,
            export: false,
            max: None,
        }
    }

    /// Whether the tag is a contact (a Boolean, or one bit of a word).
    pub fn is_contact(&self) -> bool {
        self.value_type == ValueType::Boolean || self.bit.is_some()
    }

    /// How the tag is used, for messages: `Boolean`, `bit 7 of a UInt16`.
    pub fn usage(&self) -> String {
        match self.bit {
            Some(b) => format!("bit {b} of a {}", self.value_type),
            None => self.value_type.to_string(),
        }
    }
}

/// The OPC UA data-change filter's deadband: a change smaller than this is
/// not reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Deadband {
    /// In the tag's unit.
    Absolute(f64),
    /// In percent of the node's `EURange`.
    Percent(f64),
}

/// Zenoh session mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZenohMode {
    /// Peer (default; loopback).
    Peer,
    /// Client of a router.
    Client,
    /// Router.
    Router,
}

impl ZenohMode {
    /// The name zenoh's config uses.
    pub fn as_str(self) -> &'static str {
        match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        }
    }
}

/// Why `endpoint` cannot carry a secure bus, if it cannot. The bus runs
/// mutual TLS over QUIC (`quic/host:port`). Zenoh's TLS-over-TCP link
/// (`tls/`) is refused: it reads and writes one TLS stream from two
/// threads at once (eclipse-zenoh/zenoh#2557, open in Zenoh 1.10), which
/// under load breaks the connection (queries then end with no answer) and
/// is undefined behaviour.
pub fn link_problem(endpoint: &str) -> Option<String> {
    if endpoint.starts_with("quic/") {
        None
    } else if endpoint.starts_with("tls/") {
        Some(format!(
            "Zenoh's tls/ link breaks its connections under load (it reads and writes one TLS stream from two threads at once, eclipse-zenoh/zenoh#2557): write {} instead, with the same certificates (mutual TLS over QUIC, UDP)",
            endpoint.replacen("tls/", "quic/", 1)
        ))
    } else {
        Some(
            "not an encrypted endpoint: the bus takes quic/host:port (mutual TLS over QUIC)".into(),
        )
    }
}

/// The longest shelf unless the configuration says (`commands.max_shelve`).
pub const DEFAULT_MAX_SHELVE: Duration = Duration::from_secs(8 * 3600);

/// The longest `commands.max_shelve` accepted: one year.
pub const MAX_SHELVE_LIMIT: Duration = Duration::from_secs(365 * 24 * 3600);

/// The Zenoh session and keys.
#[derive(Debug, Clone)]
pub struct ZenohConfig {
    /// Session mode.
    pub mode: ZenohMode,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Key prefix, default `cellwatch/<cell>`.
    pub prefix: String,
    /// Multicast scouting (off by default: explicit endpoints on plant networks).
    pub multicast_scouting: bool,
    /// Mutual TLS with certificates from the plant CA; `None` only with
    /// plain TCP written explicitly (`plain = true`).
    pub tls: Option<ZenohTls>,
    /// A Zenoh configuration file (JSON5) for anything Zenoh offers;
    /// cellwatch's own settings are laid over it.
    pub config_file: Option<PathBuf>,
    /// A bus without TLS accepted (`zenoh.plain = true`): otherwise every
    /// endpoint must be TLS with the plant CA, whatever the Zenoh file says.
    pub plain: bool,
    /// The agent's Ed25519 signing key file (`zenoh.signing_key`): every
    /// alarm, state and answer it puts on the bus is sealed with it; made
    /// on first start if missing. `None` for clients.
    pub signing_key: Option<PathBuf>,
}

/// The files of mutual TLS on the bus (PEM): made by `cellwatch pki`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ZenohTls {
    /// The plant CA's certificate: peers are accepted only with a
    /// certificate it issued.
    pub ca: PathBuf,
    /// This node's certificate (listening and connecting).
    pub cert: PathBuf,
    /// Its private key.
    pub key: PathBuf,
}

/// The SQLite journal.
#[derive(Debug, Clone)]
pub struct JournalConfig {
    /// Database file.
    pub path: PathBuf,
    /// Rows older than this are deleted.
    pub retention: Duration,
}

/// A transition-timer check: a learned model whose signals are tags.
#[derive(Debug, Clone)]
pub struct TimerCheck {
    /// Alarm id prefix (`<id>-<nnn>`).
    pub id: String,
    /// The model, from `cellwatch learn`.
    pub model: cellwatch_models::timer::learn::TimerModel,
    /// Severity of its alarms.
    pub severity: Severity,
}

/// Step supervision of sequential function charts (paper 004).
#[derive(Debug, Clone)]
pub struct SfcCheck {
    /// Alarm id prefix (`<id>-<chart>-<step>`).
    pub id: String,
    /// The charts, their signals the cell's tag addresses.
    pub sfc: cellwatch_models::sfc::Sfc,
    /// Severity of its stuck-step alarms.
    pub severity: Severity,
    /// The remote module's force switch (a boolean tag the agent may
    /// pulse, index into the tags), if the charts may be forced.
    pub force_switch: Option<usize>,
    /// The remote module's stop switch (index into the tags).
    pub stop_switch: Option<usize>,
    /// The transitions the PLC program lets the force switch fire
    /// (chart, transition).
    pub forcible: Vec<(String, String)>,
    /// How long the force (and stop) switch is held on.
    pub force_pulse: Duration,
    /// How long the steps a forced transition leads to may take to become
    /// active before the force is called failed (an alarm).
    pub force_timeout: Duration,
}

/// How long the force switch is held on unless configured.
pub const DEFAULT_FORCE_PULSE: Duration = Duration::from_millis(500);
/// How long a forced transition may take unless configured.
pub const DEFAULT_FORCE_TIMEOUT: Duration = Duration::from_secs(10);
/// How long a forced transition may take at most.
pub const MAX_FORCE_TIMEOUT: Duration = Duration::from_secs(60);

/// A validated cell configuration.
#[derive(Clone)]
pub struct CellConfig {
    /// Cell id.
    pub cell: String,
    /// Free text.
    pub description: String,
    /// How the tags' addresses and the conditions over them are written
    /// (`cell.dialect`).
    pub addressing: Addressing,
    /// OPC UA connection.
    pub opcua: Option<OpcUaConfig>,
    /// The `@` bus of legacy units (paper 002), when the cell is read from
    /// one instead of an OPC UA server.
    pub legacy: Option<LegacyConfig>,
    /// Tags, in file order.
    pub tags: Vec<TagConfig>,
    /// Switching-function checks, compiled.
    pub switching: Vec<SwitchingCheck>,
    /// Transition-timer checks: id, model, severity.
    pub timers: Vec<TimerCheck>,
    /// Machine-state rules.
    pub state: StateRules,
    /// How often the state is published even without change.
    pub state_interval: Duration,
    /// Zenoh.
    pub zenoh: ZenohConfig,
    /// Journal.
    pub journal: JournalConfig,
    /// Prometheus `/metrics` address; `None` disables it.
    pub metrics: Option<SocketAddr>,
    /// The operators' public keys and permissions (`commands.operators_file`).
    pub operators_file: Option<PathBuf>,
    /// The longest an operator may shelve an alarm (`commands.max_shelve`).
    pub max_shelve: Duration,
    /// The tag whose rising edge is one part done (index into `tags`).
    pub part_done: Option<usize>,
    /// The integer tags counting parts (indices into `tags`).
    pub part_counters: Vec<usize>,
    /// The tag giving the item (mould, product) code being made.
    pub order_item: Option<usize>,
    /// The tag giving the target quantity.
    pub order_target: Option<usize>,
    /// Limit checks on numeric tags.
    pub limits: Vec<LimitCheck>,
    /// Step supervision of charts.
    pub sfc: Vec<SfcCheck>,
    /// Alarm delays: alarm id, on-delay and off-delay, ms.
    pub delays: Vec<(String, u64, u64)>,
    /// Things worth saying at start (security off, ...).
    pub warnings: Vec<String>,
}

impl fmt::Debug for CellConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CellConfig")
            .field("cell", &self.cell)
            .field("tags", &self.tags.len())
            .finish_non_exhaustive()
    }
}

impl CellConfig {
    /// The tags that are the flags of supervised steps: per tag index,
    /// (check, chart, step) of each step it flags. A step told by a
    /// step-number comparison (`D300 == 2`) has no flag tag and is not here.
    pub fn step_flags(&self) -> HashMap<usize, Vec<[String; 3]>> {
        let by_address: HashMap<&Signal, usize> = self
            .tags
            .iter()
            .enumerate()
            .map(|(i, t)| (&t.address, i))
            .collect();
        let mut out: HashMap<usize, Vec<[String; 3]>> = HashMap::new();
        for check in &self.sfc {
            for (r, step) in check.sfc.steps() {
                let Some(&tag) = by_address.get(&step.flag) else {
                    continue;
                };
                out.entry(tag).or_default().push([
                    check.id.clone(),
                    check.sfc.charts[r.chart].name.clone(),
                    step.name.clone(),
                ]);
            }
        }
        out
    }

    /// The engine's view of the tags.
    pub fn engine_tags(&self) -> Vec<Tag> {
        self.tags
            .iter()
            .map(|t| Tag {
                name: t.name.clone(),
                address: t.address.clone(),
            })
            .collect()
    }

    /// How the engine counts parts.
    pub fn part_counting(&self) -> PartCounting {
        match self.part_done {
            Some(t) => PartCounting::Edge(t),
            None if self.part_counters.is_empty() => PartCounting::None,
            None => PartCounting::Counters(
                self.part_counters
                    .iter()
                    .map(|&t| {
                        let max = self.tags[t].max.or(self.tags[t].value_type.max());
                        (t, Counter::new(max.unwrap_or(u64::MAX)))
                    })
                    .collect(),
            ),
        }
    }
}

/// Every problem found in a configuration, one per line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigErrors(pub Vec<String>);

impl fmt::Display for ConfigErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0.join("\n"))
    }
}

impl std::error::Error for ConfigErrors {}

/// Reads files a configuration names, relative to its directory.
pub trait Files {
    /// The bytes of `path`.
    ///
    /// # Errors
    /// The file cannot be read.
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>>;
}

/// [`Files`] on disk.
pub struct Disk;

impl Files for Disk {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        std::fs::read(path)
    }
}

/// Loads and validates the configuration at `path`.
///
/// # Errors
/// Every problem, each as `FILE:LINE:COL: key: message`.
pub fn load(path: &Path) -> Result<CellConfig, ConfigErrors> {
    let name = path.display().to_string();
    let bytes =
        std::fs::read(path).map_err(|e| ConfigErrors(vec![format!("{name}: cannot read: {e}")]))?;
    // TOML is UTF-8 by definition.
    let text = cellwatch_models::source::text(&name, &bytes, Some(cellwatch_models::source::UTF_8))
        .map_err(|e| ConfigErrors(vec![e.to_string()]))?;
    let base = path
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    parse(&name, &text, &base, &Disk)
}

/// Validates configuration `text` named `origin`; relative paths are
/// resolved against `base` and read through `files`.
///
/// # Errors
/// Every problem, each as `ORIGIN:LINE:COL: key: message`.
pub fn parse(
    origin: &str,
    text: &str,
    base: &Path,
    files: &dyn Files,
) -> Result<CellConfig, ConfigErrors> {
    let raw: RawConfig = toml::from_str(text).map_err(|e| {
        let at = e.span().map_or((1, 1), |s| line_col(text, s.start));
        ConfigErrors(vec![format!(
            "{origin}:{}:{}: {}",
            at.0,
            at.1,
            e.message().trim_end()
        )])
    })?;
    let mut v = Validator {
        origin,
        text,
        base,
        files,
        problems: Vec::new(),
        warnings: Vec::new(),
        namespace_uri: None,
        kinds: HashMap::new(),
        bus: false,
        tag_comments: HashMap::new(),
        tags_file: None,
        addressing: Addressing::PmcOrIec,
    };
    let config = v.config(raw);
    if v.problems.is_empty() {
        let mut config = config.expect("a configuration with no problems is complete");
        config.warnings = v.warnings;
        Ok(config)
    } else {
        Err(ConfigErrors(v.problems))
    }
}

/// The 1-based line and column of byte `offset` in `text`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// The namespace index a node id is written with, when it is not 0 and not
/// given by URI.
fn written_index(node_id: &str) -> Option<u16> {
    if node_id.starts_with("nsu=") {
        return None;
    }
    opcua::types::NodeId::from_str(node_id)
        .ok()
        .map(|n| n.namespace)
        .filter(|&n| n > 0)
}

struct Validator<'a> {
    origin: &'a str,
    text: &'a str,
    base: &'a Path,
    files: &'a dyn Files,
    problems: Vec<String>,
    warnings: Vec<String>,
    /// `opcua.namespace_uri` and where it is written, for the tags.
    namespace_uri: Option<(Range<usize>, String)>,
    /// Every tag's type and whether it is a contact, by address.
    kinds: HashMap<Signal, (ValueType, bool)>,
    /// The tags' node ids are `@` bus nodes.
    bus: bool,
    /// The tags' comments, by address.
    tag_comments: HashMap<Signal, String>,
    /// While the tags of a `tags_file` are checked: its name and text,
    /// which their spans point into.
    tags_file: Option<(String, String)>,
    /// How the tags' addresses are written (`cell.dialect`).
    addressing: Addressing,
}

impl Validator<'_> {
    fn problem(&mut self, span: Range<usize>, key: &str, message: impl fmt::Display) {
        let (origin, text) = match &self.tags_file {
            Some((origin, text)) => (origin.as_str(), text.as_str()),
            None => (self.origin, self.text),
        };
        let (line, col) = line_col(text, span.start);
        self.problems
            .push(format!("{origin}:{line}:{col}: {key}: {message}"));
    }

    /// A problem unless `id` can be a chunk of a Zenoh key and part of a
    /// file name ([`key_chunk`]): a check's id, a chart's, step's or
    /// transition's name, which alarm ids (`alarms/<id>`) are made of.
    fn key_chunk(&mut self, span: Range<usize>, key: &str, what: &str, id: &str) {
        if !key_chunk(id) {
            self.problem(
                span,
                key,
                format!(
                    "{what}'{}' must be letters, digits, '-' or '_' (it is part of Zenoh keys)",
                    id.escape_debug()
                ),
            );
        }
    }

    fn path(&self, p: &str) -> PathBuf {
        let p = Path::new(p);
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base.join(p)
        }
    }

    /// A whole number in `range`, or a problem and `default`.
    fn count(
        &mut self,
        value: Spanned<i64>,
        key: &str,
        range: std::ops::RangeInclusive<u32>,
        default: u32,
    ) -> u32 {
        match u32::try_from(*value.get_ref()) {
            Ok(n) if range.contains(&n) => n,
            _ => {
                self.problem(
                    value.span(),
                    key,
                    format!(
                        "{} is not between {} and {}",
                        value.get_ref(),
                        range.start(),
                        range.end()
                    ),
                );
                default
            }
        }
    }

    fn duration(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        default: Duration,
    ) -> Duration {
        let Some(v) = value else { return default };
        match humantime::parse_duration(v.get_ref()) {
            Ok(d) if !d.is_zero() => d,
            Ok(_) => {
                self.problem(v.span(), key, "must be longer than zero");
                default
            }
            Err(e) => {
                self.problem(
                    v.span(),
                    key,
                    format!(
                        "'{}' is not a duration ({e}); write e.g. 100ms, 2s, 30d",
                        v.get_ref()
                    ),
                );
                default
            }
        }
    }

    /// A delay in ms: `0` or a duration.
    fn delay(&mut self, value: Option<Spanned<String>>, key: &str) -> u64 {
        match value {
            Some(v) if v.get_ref().trim() == "0" => 0,
            other => self.duration(other, key, Duration::ZERO).as_millis() as u64,
        }
    }

    fn deadband(
        &mut self,
        value: Spanned<f64>,
        key: &str,
        value_type: ValueType,
        range: std::ops::RangeInclusive<f64>,
    ) -> Option<f64> {
        if !value_type.is_numeric() {
            self.problem(
                value.span(),
                key,
                format!("a deadband needs a numeric type; this tag is {value_type}"),
            );
            return None;
        }
        let v = *value.get_ref();
        if range.contains(&v) {
            Some(v)
        } else {
            self.problem(
                value.span(),
                key,
                format!("{v} is not between {} and {}", range.start(), range.end()),
            );
            None
        }
    }

    fn parsed<T: FromStr<Err = String>>(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        default: T,
    ) -> T {
        let Some(v) = value else { return default };
        match v.get_ref().parse() {
            Ok(x) => x,
            Err(e) => {
                self.problem(v.span(), key, e);
                default
            }
        }
    }

    fn config(&mut self, raw: RawConfig) -> Option<CellConfig> {
        if let Some(d) = &raw.cell.dialect {
            match d.get_ref().parse::<Dialect>() {
                Ok(d) => self.addressing = Addressing::In(d),
                Err(e) => self.problem(d.span(), "cell.dialect", e),
            }
        }
        let cell = raw.cell.id.get_ref().clone();
        if cell.is_empty()
            || !cell
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            self.problem(
                raw.cell.id.span(),
                "cell.id",
                format!("'{cell}' must be letters, digits, '-' or '_' (it is part of Zenoh keys)"),
            );
        }
        let (opcua, legacy) = match (raw.opcua, raw.legacy) {
            (Some(o), None) => (self.opcua(o.into_inner()).map(Some), None),
            (None, Some(l)) => (Some(None), self.legacy(l.into_inner())),
            (Some(_), Some(l)) => {
                self.problem(
                    l.span(),
                    "legacy",
                    "a cell reads one source: [opcua] or [legacy], not both",
                );
                (None, None)
            }
            (None, None) => {
                self.problem(
                    0..0,
                    "opcua",
                    "a cell needs a source: an [opcua] server or a [legacy] bus",
                );
                (None, None)
            }
        };
        let tags = match raw.tags_file {
            None => self.tags(raw.tags.into_iter()),
            Some(file) => {
                if !raw.tags.is_empty() {
                    self.problem(
                        file.span(),
                        "tags_file",
                        "give the tags as [[tags]] tables or in tags_file, not both",
                    );
                }
                self.tags_in_file(file)
            }
        };
        let by_address: HashMap<Signal, usize> = tags
            .iter()
            .enumerate()
            .map(|(i, t)| (t.address.clone(), i))
            .collect();
        self.kinds = tags
            .iter()
            .map(|t| (t.address.clone(), (t.value_type, t.is_contact())))
            .collect();
        self.tag_comments = tags
            .iter()
            .filter_map(|t| Some((t.address.clone(), t.comment.clone()?)))
            .collect();
        let mut switching = Vec::new();
        let mut ids = HashSet::new();
        let mut delays = Vec::new();
        for (i, c) in raw.checks.switching.into_iter().enumerate() {
            let key = format!("checks.switching[{i}]");
            let on = self.delay(c.on_delay.clone(), &format!("{key}.on_delay"));
            let off = self.delay(c.off_delay.clone(), &format!("{key}.off_delay"));
            if on > 0 || off > 0 {
                delays.push((c.id.get_ref().clone(), on, off));
            }
            self.key_chunk(c.id.span(), &format!("{key}.id"), "", c.id.get_ref());
            if !ids.insert(c.id.get_ref().clone())
                || matches!(c.id.get_ref().as_str(), "communication" | "tag-quality")
            {
                self.problem(
                    c.id.span(),
                    &format!("{key}.id"),
                    format!("'{}' is used twice or reserved", c.id.get_ref()),
                );
            }
            if let Some(check) = self.switching(&key, c, &by_address) {
                switching.push(check);
            }
        }
        let mut timers = Vec::new();
        for (i, t) in raw.checks.timers.into_iter().enumerate() {
            let key = format!("checks.timers[{i}]");
            self.key_chunk(t.id.span(), &format!("{key}.id"), "", t.id.get_ref());
            if !ids.insert(t.id.get_ref().clone()) {
                self.problem(
                    t.id.span(),
                    &format!("{key}.id"),
                    format!("'{}' is used twice", t.id.get_ref()),
                );
            }
            let severity = self.parsed(
                t.severity.clone(),
                &format!("{key}.severity"),
                Severity::High,
            );
            let path = self.path(t.model.get_ref());
            let Some(text) = self.read_text(
                t.model.span(),
                &format!("{key}.model"),
                &path,
                "timer model",
            ) else {
                continue;
            };
            let model: cellwatch_models::timer::learn::TimerModel =
                match serde_json::from_str(&text) {
                    Ok(m) => m,
                    Err(e) => {
                        self.problem(
                            t.model.span(),
                            &format!("{key}.model"),
                            format!("{}: {e}", path.display()),
                        );
                        continue;
                    }
                };
            let unknown: Vec<&String> = model
                .signals
                .iter()
                .filter(|n| timer_signal(self.addressing, &tags, n).is_none())
                .collect();
            if !unknown.is_empty() {
                let list: Vec<&str> = unknown.iter().map(|s| s.as_str()).collect();
                self.problem(
                    t.model.span(),
                    &format!("{key}.model"),
                    format!(
                        "the model reads {}, which no tag has as name or address",
                        list.join(", ")
                    ),
                );
                continue;
            }
            timers.push(TimerCheck {
                id: t.id.into_inner(),
                model,
                severity,
            });
        }
        let sfc = self.sfc(raw.checks.sfc, &mut ids, &by_address);
        let mut limits = self.limits(raw.checks.limit, &mut ids);
        for l in &mut limits {
            if let Some(t) = by_address.get(&l.tag) {
                l.label = tags[*t].name.clone();
            }
        }
        let state = self.state(&raw.state, &by_address);
        let state_interval = self.duration(
            raw.state.publish_interval,
            "state.publish_interval",
            Duration::from_secs(10),
        );
        let zenoh = self.zenoh(raw.zenoh, &cell);
        let journal = JournalConfig {
            path: self.path(
                raw.journal
                    .path
                    .as_deref()
                    .unwrap_or(&format!("cellwatch-{cell}.sqlite")),
            ),
            retention: self.duration(
                raw.journal.retention,
                "journal.retention",
                Duration::from_secs(90 * 86_400),
            ),
        };
        let metrics = match raw.metrics.listen {
            None => Some(SocketAddr::from(([127, 0, 0, 1], 9464))),
            Some(v) if v.get_ref() == "off" => None,
            Some(v) => match v.get_ref().parse() {
                Ok(a) => Some(a),
                Err(_) => {
                    self.problem(
                        v.span(),
                        "metrics.listen",
                        format!(
                            "'{}' is not an address like 127.0.0.1:9464 (or \"off\")",
                            v.get_ref()
                        ),
                    );
                    None
                }
            },
        };
        if let Some(old) = &raw.commands.secrets_file {
            self.problem(
                old.span(),
                "commands.secrets_file",
                "shared operator secrets are no longer accepted: operators sign with their own keys (cellwatch keygen --operator NAME); name the file of their public keys with commands.operators_file",
            );
        }
        let operators_file = raw.commands.operators_file.map(|s| self.path(s.get_ref()));
        let max_shelve_span = raw.commands.max_shelve.as_ref().map(Spanned::span);
        let max_shelve = self.duration(
            raw.commands.max_shelve,
            "commands.max_shelve",
            DEFAULT_MAX_SHELVE,
        );
        // A shelf is temporary (ISA-18.2): out of service is for longer.
        if max_shelve > MAX_SHELVE_LIMIT {
            self.problem(
                max_shelve_span.unwrap_or(0..0),
                "commands.max_shelve",
                "at most 365d: an alarm to be kept quiet longer is taken out of service",
            );
        }
        #[derive(PartialEq)]
        enum Use {
            Contact,
            Counter,
            Item,
        }
        let addressing = self.addressing;
        let mut production = |p: Spanned<String>, key: &str, usage: Use| {
            let found = addressing
                .signal(p.get_ref())
                .ok()
                .and_then(|a| by_address.get(&a).copied());
            let Some(t) = found else {
                self.problem(
                    p.span(),
                    key,
                    format!("no tag has the address '{}'", p.get_ref()),
                );
                return None;
            };
            let tag = &tags[t];
            if usage == Use::Contact && !tag.is_contact() {
                self.problem(
                    p.span(),
                    key,
                    format!(
                        "{} is a {}: a part-done tag must be a contact (Boolean, or a bit)",
                        tag.address,
                        tag.usage()
                    ),
                );
                return None;
            }
            let what = match usage {
                Use::Contact => None,
                Use::Counter => Some("a counter"),
                Use::Item => Some("an item code"),
            };
            let fits = tag.bit.is_none()
                && (tag.value_type.is_integer()
                    || (usage == Use::Item && tag.value_type == ValueType::String));
            if let (Some(what), false) = (what, fits) {
                let kind = if usage == Use::Item {
                    "a string or integer tag"
                } else {
                    "an integer tag"
                };
                self.problem(
                    p.span(),
                    key,
                    format!(
                        "{} is a {}: {what} must be {kind} without a bit",
                        tag.address,
                        tag.usage()
                    ),
                );
                return None;
            }
            Some(t)
        };
        let part_done = raw
            .production
            .part_done
            .and_then(|p| production(p, "production.part_done", Use::Contact));
        let order_item = raw
            .production
            .item
            .and_then(|p| production(p, "production.item", Use::Item));
        let order_target = raw
            .production
            .target
            .and_then(|p| production(p, "production.target", Use::Counter));
        let both = raw
            .production
            .counter
            .as_ref()
            .filter(|_| part_done.is_some())
            .map(Spanned::span);
        let part_counters = match raw.production.counter {
            Some(_) if both.is_some() => Vec::new(),
            Some(c) => {
                let span = c.span();
                let list = match c.into_inner() {
                    raw::OneOrMany::One(a) => vec![a],
                    raw::OneOrMany::Many(list) => list,
                };
                list.into_iter()
                    .filter_map(|a| {
                        production(
                            Spanned::new(span.clone(), a),
                            "production.counter",
                            Use::Counter,
                        )
                    })
                    .collect()
            }
            None => Vec::new(),
        };
        if let Some(span) = both {
            self.problem(
                span,
                "production.counter",
                "give part_done or counter, not both",
            );
        }
        if operators_file.is_none() {
            self.warnings.push(
                "no commands.operators_file: every acknowledge and reset will be refused".into(),
            );
        }
        Some(CellConfig {
            cell,
            description: raw.cell.description,
            addressing: self.addressing,
            opcua: opcua?,
            legacy,
            tags,
            switching,
            timers,
            state,
            state_interval,
            zenoh,
            journal,
            metrics,
            operators_file,
            max_shelve,
            part_done,
            part_counters,
            order_item,
            order_target,
            limits,
            sfc,
            delays,
            warnings: Vec::new(),
        })
    }

    fn opcua(&mut self, raw: raw::RawOpcUa) -> Option<OpcUaConfig> {
        let endpoint = raw.endpoint.get_ref().clone();
        if !endpoint.starts_with("opc.tcp://") {
            self.problem(
                raw.endpoint.span(),
                "opcua.endpoint",
                format!("'{endpoint}' must start with opc.tcp://"),
            );
        }
        let policy = match raw
            .security_policy
            .as_ref()
            .map(|p| (p.get_ref().as_str(), p.span()))
        {
            None => SecurityPolicy::Basic256Sha256,
            Some(("None", _)) => SecurityPolicy::None,
            Some(("Basic256Sha256", _)) => SecurityPolicy::Basic256Sha256,
            Some(("Aes128_Sha256_RsaOaep" | "Aes128Sha256RsaOaep", _)) => {
                SecurityPolicy::Aes128Sha256RsaOaep
            }
            Some(("Aes256_Sha256_RsaPss" | "Aes256Sha256RsaPss", _)) => {
                SecurityPolicy::Aes256Sha256RsaPss
            }
            Some((p @ ("Basic128Rsa15" | "Basic256"), span)) => {
                self.problem(
                    span,
                    "opcua.security_policy",
                    format!("'{p}' is deprecated and insecure; use Basic256Sha256"),
                );
                SecurityPolicy::Basic256Sha256
            }
            Some((p, span)) => {
                self.problem(span, "opcua.security_policy", format!("unknown policy '{p}': use Basic256Sha256, Aes128_Sha256_RsaOaep, Aes256_Sha256_RsaPss or None"));
                SecurityPolicy::Basic256Sha256
            }
        };
        let mode = match raw
            .security_mode
            .as_ref()
            .map(|m| (m.get_ref().as_str(), m.span()))
        {
            None if policy == SecurityPolicy::None => SecurityMode::None,
            None => SecurityMode::SignAndEncrypt,
            Some(("None", _)) => SecurityMode::None,
            Some(("Sign", _)) => SecurityMode::Sign,
            Some(("SignAndEncrypt", _)) => SecurityMode::SignAndEncrypt,
            Some((m, span)) => {
                self.problem(
                    span,
                    "opcua.security_mode",
                    format!("unknown mode '{m}': use SignAndEncrypt, Sign or None"),
                );
                SecurityMode::SignAndEncrypt
            }
        };
        if (policy == SecurityPolicy::None) != (mode == SecurityMode::None) {
            let span = raw
                .security_mode
                .as_ref()
                .or(raw.security_policy.as_ref())
                .map_or(raw.endpoint.span(), Spanned::span);
            self.problem(
                span,
                "opcua.security_mode",
                "security_policy None goes with security_mode None, and only with it",
            );
        } else if policy == SecurityPolicy::None {
            self.warnings.push(format!(
                "OPC UA security is off for {endpoint}: traffic is neither signed nor encrypted"
            ));
        }
        let pki_dir = self.path(raw.pki_dir.as_ref().map_or("pki", |p| p.get_ref().as_str()));
        let identity = match raw.identity {
            None => Identity::Anonymous,
            Some(id) => self.identity(id.into_inner())?,
        };
        let publishing_interval = self.duration(
            raw.publishing_interval,
            "opcua.publishing_interval",
            Duration::from_millis(100),
        );
        // 0 is the OPC UA convention for exception-based reporting: every
        // change, as the server sees it.
        let sampling_interval = match raw.sampling_interval {
            Some(v)
                if v.get_ref().trim() == "0"
                    || humantime::parse_duration(v.get_ref()).is_ok_and(|d| d.is_zero()) =>
            {
                Duration::ZERO
            }
            other => self.duration(other, "opcua.sampling_interval", Duration::from_millis(50)),
        };
        let queue_size = match raw.queue_size {
            None => OpcUaConfig::default_queue_size(publishing_interval, sampling_interval),
            Some(q) => self.count(q, "opcua.queue_size", 1..=10_000, 10),
        };
        let max_notifications_per_publish =
            raw.max_notifications_per_publish
                .map_or(OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS, |q| {
                    self.count(
                        q,
                        "opcua.max_notifications_per_publish",
                        100..=1_000_000,
                        OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS,
                    )
                });
        let namespace_uri = match raw.namespace_uri {
            Some(uri) if uri.get_ref().trim().is_empty() => {
                self.problem(uri.span(), "opcua.namespace_uri", "is empty");
                None
            }
            other => other.map(|u| (u.span(), u.into_inner())),
        };
        self.namespace_uri = namespace_uri.clone();
        Some(OpcUaConfig {
            endpoint,
            policy,
            mode,
            pki_dir,
            identity,
            publishing_interval,
            sampling_interval,
            namespace_uri: namespace_uri.map(|(_, u)| u),
            queue_size,
            max_notifications_per_publish,
        })
    }

    fn legacy(&mut self, raw: raw::RawLegacy) -> Option<LegacyConfig> {
        self.bus = true;
        let transport = match (raw.tcp, raw.serial) {
            (Some(t), None) => {
                if t.get_ref()
                    .rsplit_once(':')
                    .and_then(|(_, p)| p.parse::<u16>().ok())
                    .is_none()
                {
                    self.problem(
                        t.span(),
                        "legacy.tcp",
                        format!(
                            "'{}' is not host:port (the serial device server's raw socket)",
                            t.get_ref()
                        ),
                    );
                }
                Transport::Tcp(t.into_inner())
            }
            (None, Some(path)) => {
                let baud = match raw.baud {
                    None => 9600,
                    Some(b) => self.count(b, "legacy.baud", 50..=4_000_000, 9600),
                };
                let data_bits = match raw.data_bits {
                    None => 7,
                    Some(b) => self.count(b, "legacy.data_bits", 5..=8, 7) as u8,
                };
                let stop_bits = match raw.stop_bits {
                    None => 2,
                    Some(b) => self.count(b, "legacy.stop_bits", 1..=2, 2) as u8,
                };
                let parity = match raw
                    .parity
                    .as_ref()
                    .map(|p| (p.get_ref().as_str(), p.span()))
                {
                    None | Some(("even", _)) => Parity::Even,
                    Some(("odd", _)) => Parity::Odd,
                    Some(("none", _)) => Parity::None,
                    Some((p, span)) => {
                        self.problem(
                            span,
                            "legacy.parity",
                            format!("unknown parity '{p}': use even, odd or none"),
                        );
                        Parity::Even
                    }
                };
                Transport::Serial(SerialLine {
                    path: path.into_inner(),
                    baud,
                    data_bits,
                    parity,
                    stop_bits,
                })
            }
            (Some(t), Some(_)) => {
                self.problem(t.span(), "legacy.tcp", "give tcp or serial, not both");
                return None;
            }
            (None, None) => {
                self.problem(
                    0..0,
                    "legacy",
                    "give the bus: tcp = \"host:port\" or serial = \"/dev/ttyUSB0\"",
                );
                return None;
            }
        };
        let poll_interval = self.duration(
            raw.poll_interval,
            "legacy.poll_interval",
            Duration::from_secs(1),
        );
        let response_timeout = self.duration(
            raw.response_timeout,
            "legacy.response_timeout",
            Duration::from_millis(300),
        );
        let retries = match raw.retries {
            None => 2,
            Some(r) => self.count(r, "legacy.retries", 0..=10, 2),
        };
        Some(LegacyConfig {
            transport,
            poll_interval,
            response_timeout,
            retries,
        })
    }

    fn identity(&mut self, id: raw::RawIdentity) -> Option<Identity> {
        if let Some(p) = &id.password {
            self.problem(
                p.span(),
                "opcua.identity.password",
                "passwords are never written in config files; use password_env (an environment variable) or password_file",
            );
            return None;
        }
        match id.kind.get_ref().as_str() {
            "anonymous" => Some(Identity::Anonymous),
            "user" => {
                let user = id.user.unwrap_or_default();
                if user.is_empty() {
                    self.problem(
                        id.kind.span(),
                        "opcua.identity.user",
                        "a user identity needs a user name",
                    );
                }
                let password = match (id.password_env, id.password_file) {
                    (Some(env), None) => PasswordSource::Env(env),
                    (None, Some(file)) => PasswordSource::File(self.path(file.get_ref())),
                    _ => {
                        self.problem(
                            id.kind.span(),
                            "opcua.identity",
                            "give exactly one of password_env and password_file",
                        );
                        return None;
                    }
                };
                Some(Identity::User { user, password })
            }
            other => {
                self.problem(
                    id.kind.span(),
                    "opcua.identity.kind",
                    format!("unknown identity '{other}': use anonymous or user"),
                );
                None
            }
        }
    }

    fn tags(&mut self, mut raw: impl raw::TagRows) -> Vec<TagConfig> {
        // Indices written with `opcua.namespace_uri` (each with its first
        // tag), and a tag whose index is trusted blindly.
        let mut indices: BTreeMap<u16, usize> = BTreeMap::new();
        let mut blind: Option<(u16, String)> = None;
        // Room for every tag at once (a tags file's rows are counted by
        // its lines), not grown by doubling.
        let (least, most) = raw.size_hint();
        let mut out = Vec::with_capacity(most.unwrap_or(least));
        let mut names = HashSet::new();
        let mut addresses = HashSet::new();
        for (i, t) in raw.by_ref().enumerate() {
            let key = format!("tags[{i}]");
            if !names.insert(t.name.get_ref().clone()) {
                self.problem(
                    t.name.span(),
                    &format!("{key}.name"),
                    format!("'{}' is used by another tag", t.name.get_ref()),
                );
            }
            let uri = self.namespace_uri.as_ref().map(|(_, u)| u.as_str());
            if self.bus {
                if let Err(e) = BusNode::parse(t.node_id.get_ref()) {
                    self.problem(t.node_id.span(), &format!("{key}.node_id"), e);
                }
            } else {
                match TagNode::parse(t.node_id.get_ref(), uri) {
                    Ok(node) => {
                        if let Some(index) = written_index(t.node_id.get_ref()) {
                            indices.entry(index).or_insert(i);
                        }
                        if let Some(index) = node.bare_index().filter(|&i| i > 0) {
                            blind.get_or_insert((index, t.name.get_ref().clone()));
                        }
                    }
                    Err(e) => self.problem(t.node_id.span(), &format!("{key}.node_id"), e),
                }
            }
            let address = match self.addressing.signal(t.address.get_ref()) {
                Ok(a) => a,
                Err(e) => {
                    self.problem(t.address.span(), &format!("{key}.address"), e);
                    continue;
                }
            };
            if !addresses.insert(address.clone()) {
                self.problem(
                    t.address.span(),
                    &format!("{key}.address"),
                    format!("{address} is used by another tag"),
                );
            }
            let value_type = self.parsed(
                t.value_type.clone(),
                &format!("{key}.type"),
                ValueType::Boolean,
            );
            let bit = t.bit.as_ref().and_then(|b| {
                let Some(width) = value_type.bits() else {
                    self.problem(
                        b.span(),
                        &format!("{key}.bit"),
                        format!("a bit needs an integer type; this tag is {value_type}: add type = \"Byte\" (or another integer type)"),
                    );
                    return None;
                };
                match u8::try_from(*b.get_ref()) {
                    Ok(n) if u32::from(n) < width => Some(n),
                    _ => {
                        self.problem(
                            b.span(),
                            &format!("{key}.bit"),
                            format!("{} is not a bit of a {value_type} (0..{})", b.get_ref(), width - 1),
                        );
                        None
                    }
                }
            });
            let sampling_interval = t.sampling_interval.map(|v| {
                if v.get_ref().trim() == "0" {
                    Duration::ZERO
                } else {
                    self.duration(Some(v), &format!("{key}.sampling_interval"), Duration::ZERO)
                }
            });
            let deadband = match (t.deadband, t.deadband_percent) {
                (Some(a), Some(_)) => {
                    self.problem(
                        a.span(),
                        &format!("{key}.deadband"),
                        "give deadband or deadband_percent, not both",
                    );
                    None
                }
                (Some(a), None) => self
                    .deadband(a, &format!("{key}.deadband"), value_type, 0.0..=f64::MAX)
                    .map(Deadband::Absolute),
                (None, Some(p)) => self
                    .deadband(
                        p,
                        &format!("{key}.deadband_percent"),
                        value_type,
                        0.0..=100.0,
                    )
                    .map(Deadband::Percent),
                (None, None) => None,
            };
            if t.export && !value_type.is_numeric() && value_type != ValueType::Boolean {
                self.problem(
                    t.name.span(),
                    &format!("{key}.export"),
                    format!("a {value_type} cannot be a gauge: export numbers and booleans only"),
                );
            }
            let max = t.max.and_then(|m| match value_type.max() {
                Some(top) if *m.get_ref() >= 1 && *m.get_ref() <= top => Some(*m.get_ref()),
                Some(top) => {
                    self.problem(
                        m.span(),
                        &format!("{key}.max"),
                        format!(
                            "{} is not between 1 and {top}, the largest {value_type}",
                            m.get_ref()
                        ),
                    );
                    None
                }
                None => {
                    self.problem(
                        m.span(),
                        &format!("{key}.max"),
                        format!(
                            "a counter's maximum needs an integer type; this tag is {value_type}"
                        ),
                    );
                    None
                }
            });
            out.push(TagConfig {
                name: t.name.into_inner(),
                node_id: t.node_id.into_inner(),
                address,
                comment: t.comment,
                value_type,
                bit,
                sampling_interval,
                deadband,
                export: t.export,
                max,
            });
        }
        for (offset, key, message) in raw.problems() {
            self.problem(offset..offset, &key, message);
        }
        // What follows is about the configuration file again.
        self.tags_file = None;
        if let Some((span, uri)) = self.namespace_uri.clone() {
            if indices.len() > 1 {
                let list: Vec<String> = indices.keys().map(|i| format!("ns={i}")).collect();
                self.problem(
                    span,
                    "opcua.namespace_uri",
                    format!(
                        "names one namespace ('{uri}') but the tags use {}: write their node ids as nsu=<namespace uri>;...",
                        list.join(" and ")
                    ),
                );
            } else if indices.is_empty() {
                self.warnings.push(format!(
                    "opcua.namespace_uri '{uri}' is not used: no tag is written ns=<index>;..."
                ));
            }
        }
        if let Some((index, name)) = blind {
            self.warnings.push(format!(
                "tag '{name}' (and maybe others) is written ns={index};... without opcua.namespace_uri: the index is trusted as is, and a server that renumbers its namespaces would be misread; write nsu=<namespace uri>;... or set opcua.namespace_uri"
            ));
        }
        out
    }

    /// The tags of `tags_file`: a CSV file with a header row naming its
    /// columns as the keys of a `[[tags]]` table (`name`, `node_id`,
    /// `address` required; `type`, `comment`, `bit`, `sampling_interval`,
    /// `deadband`, `deadband_percent`, `export`, `max`), one tag a row, an
    /// empty cell meaning the key is not given. Read row by row, without a
    /// document tree: a 100,000-tag cell is read in a fraction of what
    /// 100,000 TOML tables take. Problems name the file and the row's line.
    fn tags_in_file(&mut self, file: Spanned<String>) -> Vec<TagConfig> {
        let path = self.path(file.get_ref());
        let Some(text) = self.read_text(file.span(), "tags_file", &path, "the tags file") else {
            return Vec::new();
        };
        let origin = path.display().to_string();
        // The validator places problems in the file's text; the rows are
        // read from a copy of it as they are validated.
        self.tags_file = Some((origin, text.clone()));
        self.tags(raw::CsvTags::new(&text))
    }

    fn read_text(
        &mut self,
        span: Range<usize>,
        key: &str,
        path: &Path,
        what: &str,
    ) -> Option<String> {
        match self.files.read(path) {
            Ok(bytes) => {
                match cellwatch_models::source::text(&path.display().to_string(), &bytes, None) {
                    Ok(t) => Some(t.to_string()),
                    Err(e) => {
                        self.problems.push(e.to_string());
                        None
                    }
                }
            }
            Err(e) => {
                self.problem(
                    span,
                    key,
                    format!("cannot read {what} '{}': {e}", path.display()),
                );
                None
            }
        }
    }

    fn switching(
        &mut self,
        key: &str,
        c: raw::RawSwitching,
        tags: &HashMap<Signal, usize>,
    ) -> Option<SwitchingCheck> {
        let dialect: Option<Dialect> = match &c.dialect {
            None => None,
            Some(d) => match d.get_ref().parse() {
                Ok(d) => Some(d),
                Err(e) => {
                    self.problem(d.span(), &format!("{key}.dialect"), e);
                    None
                }
            },
        };
        let polarity = self.parsed(
            c.fault_when.clone(),
            &format!("{key}.fault_when"),
            Polarity::On,
        );
        let severity = self.parsed(
            c.severity.clone(),
            &format!("{key}.severity"),
            Severity::High,
        );
        let path = self.path(c.program.get_ref());
        let text = self.read_text(
            c.program.span(),
            &format!("{key}.program"),
            &path,
            "program",
        )?;
        let program = match Program::compile(&path.display().to_string(), &text, dialect) {
            Ok(p) => p,
            Err(e) => {
                self.problems.extend(e.lines());
                return None;
            }
        };
        let observable = match &c.observable {
            None => Observability::default_for(program.dialect()),
            Some(o) => match Observability::parse(program.dialect(), o.get_ref()) {
                Ok(o) => o,
                Err(e) => {
                    self.problem(o.span(), &format!("{key}.observable"), e);
                    return None;
                }
            },
        };
        let coil = match program.resolve(c.coil.get_ref()) {
            Ok(s) => s,
            Err(e) => {
                self.problem(c.coil.span(), &format!("{key}.coil"), e);
                return None;
            }
        };
        let sf = match SwitchingFunction::expand(&program, &coil, &observable) {
            Ok(sf) => sf,
            Err(e) => {
                self.problem(c.coil.span(), &format!("{key}.coil"), e);
                return None;
            }
        };
        // Tags read as another dialect's addresses than the program's
        // cannot match its signals: say which key fixes it.
        let hint = match self.addressing {
            Addressing::In(d) if d == program.dialect() => String::new(),
            Addressing::PmcOrIec if program.dialect() != Dialect::Stl => String::new(),
            _ => format!(
                " (the program is {}: set cell.dialect = \"{}\" to read the tags' addresses as it writes them)",
                program.dialect(),
                program.dialect()
            ),
        };
        for leaf in sf.leaves() {
            if !tags.contains_key(&leaf) {
                self.problem(
                    c.coil.span(),
                    &format!("{key}.coil"),
                    format!("{coil} reads {leaf}, but no tag has that address; add a [[tags]] entry for it{hint}"),
                );
            } else if let Some((t, false)) = self.kinds.get(&leaf) {
                self.problem(
                    c.coil.span(),
                    &format!("{key}.coil"),
                    format!("{coil} reads {leaf} as a contact, but its tag is a {t}: make it Boolean or give it a bit"),
                );
            }
        }
        // The program's own declarations, then the tags' comments, then the
        // I/O list: each overrides the one before.
        let tag_comments: CommentDb = sf
            .leaves()
            .into_iter()
            .filter_map(|s| Some((s.clone(), self.tag_comments.get(&s)?.clone())))
            .collect();
        let declared = program.documentation().clone().overridden_by(tag_comments);
        let comments = match &c.comments {
            None => declared,
            Some(p) => {
                let path = self.path(p.get_ref());
                let text = self.read_text(
                    p.span(),
                    &format!("{key}.comments"),
                    &path,
                    "comment database",
                )?;
                match CommentDb::parse(&path.display().to_string(), &text, |a| program.resolve(a)) {
                    Ok(db) => declared.overridden_by(db),
                    Err(e) => {
                        self.problems.push(e.to_string());
                        return None;
                    }
                }
            }
        };
        let armed_when = match &c.armed_when {
            None => None,
            Some(a) => {
                let expr = self.expression(a, &format!("{key}.armed_when"), tags)?;
                Some(SwitchingFunction::from_expr(
                    Signal::new(&format!("{}.armed", c.id.get_ref())),
                    &expr,
                ))
            }
        };
        Some(SwitchingCheck {
            armed_when,
            id: c.id.into_inner(),
            fault_type: c.fault_type.unwrap_or_else(|| coil.to_string()),
            sf,
            polarity,
            severity,
            comments,
        })
    }

    /// A condition over tag addresses in the paper's notation, every
    /// address a contact tag's; comparisons (`TEMP > 80.5`) read numeric
    /// tags.
    fn expression(
        &mut self,
        text: &Spanned<String>,
        key: &str,
        tags: &HashMap<Signal, usize>,
    ) -> Option<Expr> {
        let e = match Expr::parse(text.get_ref()) {
            Ok(e) => canonical_expr(self.addressing, e),
            Err(m) => {
                self.problem(text.span(), key, format!("'{}': {m}", text.get_ref()));
                return None;
            }
        };
        let mut problems = Vec::new();
        for s in e.signals() {
            match Comparison::of_signal(&s) {
                Some(c) => {
                    let operands = std::iter::once(&c.lhs).chain(match &c.rhs {
                        Operand::Tag(t) => Some(t),
                        Operand::Const(_) => None,
                    });
                    for a in operands {
                        match self.kinds.get(a) {
                            None => problems.push(format!("no tag has the address {a} (in '{s}')")),
                            Some((t, _)) if !t.is_numeric() && *t != ValueType::Boolean => problems
                                .push(format!(
                                    "{a} is a {t} and cannot be compared as a number (in '{s}')"
                                )),
                            Some(_) => {}
                        }
                    }
                }
                None if !tags.contains_key(&s) => {
                    problems.push(format!("no tag has the address {s}"));
                }
                None => {
                    if let Some((t, false)) = self.kinds.get(&s) {
                        problems.push(format!(
                            "{s} is a {t}, not a contact: compare it (`{s} > 0`) or give the tag a bit"
                        ));
                    }
                }
            }
        }
        if problems.is_empty() {
            Some(e)
        } else {
            self.problem(text.span(), key, problems.join("; "));
            None
        }
    }

    /// Step supervision times learned by `cellwatch learn --sfc`, given to
    /// the steps of `sfc` that declare none.
    fn learned_steps(&mut self, file: &Spanned<String>, key: &str, sfc: &mut Sfc) {
        let path = self.path(file.get_ref());
        let Some(text) = self.read_text(file.span(), key, &path, "step supervision") else {
            return;
        };
        let model: StepModel = match serde_json::from_str(&text) {
            Ok(m) => m,
            Err(e) => {
                self.problem(
                    file.span(),
                    key,
                    format!("{}:{}:{}: {e}", path.display(), e.line(), e.column()),
                );
                return;
            }
        };
        if let Err(errors) = model.apply(sfc) {
            for e in errors {
                self.problem(file.span(), key, format!("{}: {e}", path.display()));
            }
        }
    }

    /// The charts under supervision (`[[checks.sfc]]`).
    fn sfc(
        &mut self,
        raw: Vec<raw::RawSfc>,
        ids: &mut HashSet<String>,
        tags: &HashMap<Signal, usize>,
    ) -> Vec<SfcCheck> {
        let mut out = Vec::new();
        let mut charts = HashSet::new();
        for (i, c) in raw.into_iter().enumerate() {
            let key = format!("checks.sfc[{i}]");
            self.key_chunk(c.id.span(), &format!("{key}.id"), "", c.id.get_ref());
            if !ids.insert(c.id.get_ref().clone()) {
                self.problem(
                    c.id.span(),
                    &format!("{key}.id"),
                    format!("'{}' is used twice", c.id.get_ref()),
                );
            }
            let severity = self.parsed(
                c.severity.clone(),
                &format!("{key}.severity"),
                Severity::High,
            );
            let path = self.path(c.charts.get_ref());
            let Some(text) =
                self.read_text(c.charts.span(), &format!("{key}.charts"), &path, "charts")
            else {
                continue;
            };
            // A contact is known when it is a tag's bit or a comparison of
            // numeric tags, as in any other condition.
            let addressing = self.addressing;
            let kinds = &self.kinds;
            let known = |s: &Signal| {
                let canonical = canonical_expr(addressing, Expr::Lit(s.clone(), false));
                canonical
                    .signals()
                    .iter()
                    .all(|s| match Comparison::of_signal(s) {
                        Some(cmp) => std::iter::once(&cmp.lhs)
                            .chain(match &cmp.rhs {
                                Operand::Tag(t) => Some(t),
                                Operand::Const(_) => None,
                            })
                            .all(|a| kinds.get(a).is_some_and(|(t, _)| t.is_numeric())),
                        None => tags.contains_key(s) && !matches!(kinds.get(s), Some((_, false))),
                    })
            };
            match cellwatch_models::sfc::read(&path.display().to_string(), &text, &known) {
                Ok(mut sfc) => {
                    // The cell's own times first, then learned ones for
                    // the steps still without.
                    for (step, time) in &c.supervision {
                        let skey = format!("{key}.supervision.\"{step}\"");
                        let found = sfc
                            .steps()
                            .map(|(r, _)| r)
                            .find(|&r| sfc.step_name(r) == *step);
                        let ms = cellwatch_models::sfc::text::duration_ms(time.get_ref());
                        match (found, ms) {
                            (Some(r), Ok(ms)) => {
                                sfc.charts[r.chart].steps[r.step].supervision_ms = Some(ms)
                            }
                            (None, _) => self.problem(
                                time.span(),
                                &skey,
                                format!("no step {step} in {} (write CHART.STEP)", path.display()),
                            ),
                            (_, Err(why)) => self.problem(time.span(), &skey, why),
                        }
                    }
                    if let Some(steps) = &c.steps {
                        self.learned_steps(steps, &format!("{key}.steps"), &mut sfc);
                    }
                    // Alarm ids are made of them: `<id>-<chart>-<step>`,
                    // `force-<chart>-<transition>`.
                    let ckey = format!("{key}.charts");
                    for chart in &sfc.charts {
                        let span = c.charts.span();
                        self.key_chunk(span.clone(), &ckey, "chart ", &chart.name);
                        for step in &chart.steps {
                            let what = format!("chart {} step ", chart.name.escape_debug());
                            self.key_chunk(span.clone(), &ckey, &what, &step.name);
                        }
                        for t in &chart.transitions {
                            let what = format!("chart {} transition ", chart.name.escape_debug());
                            self.key_chunk(span.clone(), &ckey, &what, &t.id);
                        }
                    }
                    for chart in &sfc.charts {
                        if !charts.insert(chart.name.clone()) {
                            self.problem(
                                c.charts.span(),
                                &format!("{key}.charts"),
                                format!(
                                    "chart {} is supervised twice in this cell (a force or stop names a chart)",
                                    chart.name
                                ),
                            );
                        }
                    }
                    for chart in &mut sfc.charts {
                        for step in &mut chart.steps {
                            if let Expr::Lit(s, _) =
                                canonical_expr(addressing, Expr::Lit(step.flag.clone(), false))
                            {
                                step.flag = s;
                            }
                        }
                        for t in &mut chart.transitions {
                            t.condition = canonical_expr(addressing, t.condition.clone());
                        }
                    }
                    let mut switch = |v: Option<Spanned<String>>, name: &str| {
                        let v = v?;
                        let key = format!("{key}.{name}");
                        let found = addressing
                            .signal(v.get_ref())
                            .ok()
                            .and_then(|a| Some((tags.get(&a).copied()?, self.kinds.get(&a)?.0)));
                        match found {
                            _ if self.bus => {
                                self.problem(
                                    v.span(),
                                    &key,
                                    "the switches are written over OPC UA; this cell reads an @ bus",
                                );
                                None
                            }
                            Some((i, ValueType::Boolean)) => Some(i),
                            Some((_, t)) => {
                                self.problem(
                                    v.span(),
                                    &key,
                                    format!("'{}' is {t}; a switch is a Boolean tag", v.get_ref()),
                                );
                                None
                            }
                            None => {
                                self.problem(
                                    v.span(),
                                    &key,
                                    format!("'{}' is not a tag of this cell", v.get_ref()),
                                );
                                None
                            }
                        }
                    };
                    let force_switch = switch(c.force_switch.clone(), "force_switch");
                    let stop_switch = switch(c.stop_switch, "stop_switch");
                    let mut forcible = Vec::new();
                    for (j, f) in c.forcible.into_iter().enumerate() {
                        let fkey = format!("{key}.forcible[{j}]");
                        let Some((chart, t)) = f.get_ref().split_once('.') else {
                            self.problem(
                                f.span(),
                                &fkey,
                                format!("'{}' is not CHART.TRANSITION (F1.t3)", f.get_ref()),
                            );
                            continue;
                        };
                        if sfc.transition(chart, t).is_none() {
                            self.problem(
                                f.span(),
                                &fkey,
                                format!(
                                    "no transition {t} in a chart {chart} of {}",
                                    path.display()
                                ),
                            );
                        } else if c.force_switch.is_none() {
                            self.problem(
                                f.span(),
                                &fkey,
                                "forcing needs the force switch (force_switch)",
                            );
                        } else {
                            forcible.push((chart.to_string(), t.to_string()));
                        }
                    }
                    let force_pulse = self.duration(
                        c.force_pulse,
                        &format!("{key}.force_pulse"),
                        DEFAULT_FORCE_PULSE,
                    );
                    let timeout_span = c.force_timeout.as_ref().map(Spanned::span);
                    let mut force_timeout = self.duration(
                        c.force_timeout,
                        &format!("{key}.force_timeout"),
                        DEFAULT_FORCE_TIMEOUT,
                    );
                    if force_timeout > MAX_FORCE_TIMEOUT {
                        self.problem(
                            timeout_span.unwrap_or_default(),
                            &format!("{key}.force_timeout"),
                            "at most 1 minute (the operator waits for the answer)",
                        );
                        force_timeout = DEFAULT_FORCE_TIMEOUT;
                    }
                    out.push(SfcCheck {
                        id: c.id.into_inner(),
                        sfc,
                        severity,
                        force_switch,
                        stop_switch,
                        forcible,
                        force_pulse,
                        force_timeout,
                    });
                }
                // The chart file's own positions.
                Err(errors) => self.problems.extend(errors),
            }
        }
        out
    }

    /// The limit checks.
    fn limits(&mut self, raw: Vec<raw::RawLimit>, ids: &mut HashSet<String>) -> Vec<LimitCheck> {
        let mut out = Vec::new();
        for (i, c) in raw.into_iter().enumerate() {
            let key = format!("checks.limit[{i}]");
            self.key_chunk(c.id.span(), &format!("{key}.id"), "", c.id.get_ref());
            if !ids.insert(c.id.get_ref().clone()) {
                self.problem(
                    c.id.span(),
                    &format!("{key}.id"),
                    format!("'{}' is used twice", c.id.get_ref()),
                );
            }
            let tag = match self.addressing.signal(c.tag.get_ref()) {
                Ok(a) => a,
                Err(e) => {
                    self.problem(c.tag.span(), &format!("{key}.tag"), e);
                    continue;
                }
            };
            match self.kinds.get(&tag) {
                None => {
                    self.problem(
                        c.tag.span(),
                        &format!("{key}.tag"),
                        format!("no tag has the address {tag}"),
                    );
                    continue;
                }
                Some((t, _)) if !t.is_numeric() => {
                    self.problem(
                        c.tag.span(),
                        &format!("{key}.tag"),
                        format!("{tag} is a {t}: a limit check needs a numeric tag (type = \"Double\", \"Int16\", ...)"),
                    );
                    continue;
                }
                Some(_) => {}
            }
            let deadband = match c.deadband {
                None => 0.0,
                Some(d) if *d.get_ref() >= 0.0 && d.get_ref().is_finite() => *d.get_ref(),
                Some(d) => {
                    self.problem(
                        d.span(),
                        &format!("{key}.deadband"),
                        format!("{} must be zero or more", d.get_ref()),
                    );
                    0.0
                }
            };
            let on_delay = self.delay(c.on_delay, &format!("{key}.on_delay"));
            let off_delay = self.delay(c.off_delay, &format!("{key}.off_delay"));
            let mut levels = Vec::new();
            for (level, raw, default) in [
                (Level::HH, c.hh, Severity::Critical),
                (Level::H, c.h, Severity::High),
                (Level::L, c.l, Severity::High),
                (Level::LL, c.ll, Severity::Critical),
            ] {
                let Some(raw) = raw else { continue };
                let span = raw.span();
                let raw = raw.into_inner();
                let lkey = format!("{key}.{}", level.as_str().to_ascii_lowercase());
                if !raw.limit.is_finite() {
                    self.problem(
                        span.clone(),
                        &format!("{lkey}.limit"),
                        "must be a finite number",
                    );
                }
                let severity = self.parsed(raw.severity, &format!("{lkey}.severity"), default);
                levels.push(LimitLevel {
                    level,
                    limit: raw.limit,
                    severity,
                });
            }
            if levels.is_empty() {
                self.problem(
                    c.id.span(),
                    &key,
                    "give at least one level: hh, h, l or ll = { limit = ..., severity = ... }",
                );
            }
            let limit = |l: Level| levels.iter().find(|x| x.level == l).map(|x| x.limit);
            let ordered = [Level::HH, Level::H, Level::L, Level::LL]
                .iter()
                .filter_map(|&l| limit(l))
                .collect::<Vec<_>>()
                .windows(2)
                .all(|w| w[0] > w[1]);
            if !ordered {
                self.problem(
                    c.id.span(),
                    &key,
                    "the limits must fall in the order hh > h > l > ll",
                );
            }
            out.push(LimitCheck {
                id: c.id.into_inner(),
                label: String::new(),
                tag,
                unit: c.unit,
                deadband,
                on_delay,
                off_delay,
                levels,
            });
        }
        out
    }

    fn state(&mut self, raw: &raw::RawState, tags: &HashMap<Signal, usize>) -> StateRules {
        let fault_severity = self.parsed(
            raw.fault_severity.clone(),
            "state.fault_severity",
            Severity::High,
        );
        let running = raw
            .running
            .as_ref()
            .and_then(|r| self.expression(r, "state.running", tags));
        StateRules {
            running,
            fault_severity,
        }
    }

    fn zenoh(&mut self, raw: raw::RawZenoh, cell: &str) -> ZenohConfig {
        let mode = match raw.mode.as_ref().map(|m| (m.get_ref().as_str(), m.span())) {
            None | Some(("peer", _)) => ZenohMode::Peer,
            Some(("client", _)) => ZenohMode::Client,
            Some(("router", _)) => ZenohMode::Router,
            Some((m, span)) => {
                self.problem(
                    span,
                    "zenoh.mode",
                    format!("unknown mode '{m}': use peer, client or router"),
                );
                ZenohMode::Peer
            }
        };
        let plain = raw.plain.as_ref().is_some_and(|p| *p.get_ref());
        let tls = raw.tls.map(|t| {
            let t = t.into_inner();
            ZenohTls {
                ca: self.path(t.ca.get_ref()),
                cert: self.path(t.cert.get_ref()),
                key: self.path(t.key.get_ref()),
            }
        });
        let config_file = raw.config_file.map(|f| {
            let path = self.path(f.get_ref());
            if let Err(e) = zenoh::Config::from_file(&path) {
                self.problem(
                    f.span(),
                    "zenoh.config_file",
                    format!("{}: {e}", path.display()),
                );
            }
            path
        });
        // Where the [zenoh] table is, for problems of the table as a whole.
        let table = raw
            .listen
            .first()
            .or(raw.connect.first())
            .map_or(0..0, Spanned::span);
        let with_tls = tls.is_some();
        let mut endpoints = |list: Vec<Spanned<String>>, key: &str| -> Vec<String> {
            let mut out = Vec::new();
            for e in list {
                let text = e.get_ref();
                if !text.contains('/') {
                    self.problem(
                        e.span(),
                        key,
                        format!("'{text}' is not an endpoint like quic/127.0.0.1:7447"),
                    );
                } else if let Some(why) = with_tls.then(|| link_problem(text)).flatten() {
                    self.problem(e.span(), key, format!("'{text}': {why}"));
                }
                out.push(e.into_inner());
            }
            out
        };
        let connect = endpoints(raw.connect, "zenoh.connect");
        let listen = endpoints(raw.listen, "zenoh.listen");
        match (&tls, plain) {
            (Some(_), true) => self.problem(
                raw.plain.as_ref().map_or(table, Spanned::span),
                "zenoh.plain",
                "plain = true and [zenoh.tls] contradict each other: remove one",
            ),
            (None, true) => self.warnings.push(
                "zenoh.plain = true: the bus is neither encrypted nor authenticated; anyone on the network can publish alarms and answer queries as this agent".into(),
            ),
            (None, false) if config_file.is_none() => self.problem(
                table,
                "zenoh",
                "no [zenoh.tls]: the bus would be neither encrypted nor authenticated; give tls = { ca, cert, key } (made by `cellwatch pki`), or write plain = true to accept that",
            ),
            _ => {}
        }
        if mode == ZenohMode::Client && connect.is_empty() {
            self.warnings.push("zenoh.mode is client but zenoh.connect is empty: the agent relies on scouting to find a router".into());
        }
        let prefix = match raw.key_prefix {
            None => format!("cellwatch/{cell}"),
            Some(p) => {
                let s = p.get_ref().trim_end_matches('/').to_string();
                if s.is_empty() || s.contains(['*', '$', '?', '#']) {
                    self.problem(
                        p.span(),
                        "zenoh.key_prefix",
                        format!(
                            "'{}' must be a plain key expression without wildcards",
                            p.get_ref()
                        ),
                    );
                }
                s
            }
        };
        let signing_key = Some(
            self.path(
                raw.signing_key
                    .as_ref()
                    .map_or(&format!("{cell}.agent.key"), |k| k.get_ref()),
            ),
        );
        ZenohConfig {
            mode,
            connect,
            listen,
            prefix,
            multicast_scouting: raw.multicast_scouting.unwrap_or(false),
            tls,
            config_file,
            plain,
            signing_key,
        }
    }
}

/// The tag a timer model's signal names: by tag name, else by address.
pub fn timer_signal(addressing: Addressing, tags: &[TagConfig], name: &str) -> Option<Signal> {
    tags.iter()
        .find(|t| t.name == name)
        .or_else(|| {
            addressing
                .signal(name)
                .ok()
                .and_then(|a| tags.iter().find(|t| t.address == a))
        })
        .map(|t| t.address.clone())
}

/// Whether `id` can be a chunk of a Zenoh key and part of a file name as
/// it is: not empty, letters and digits (of any script), `-` and `_` only
/// (no `/`, no wildcard, no `.` that `CHART.STEP` would split, no space or
/// control character).
pub fn key_chunk(id: &str) -> bool {
    !id.is_empty()
        && id
            .chars()
            .all(|c| c.is_alphanumeric() || c == '-' || c == '_')
}

/// A tag's PLC address: a PMC address (`X0.06`), an IEC direct address
/// (`%IX0.0.3`) or an IEC symbol (`Start`).
pub fn tag_address(text: &str) -> Result<Signal, String> {
    if text.starts_with('%') {
        return Dialect::Iec.signal(text);
    }
    Dialect::Pmc
        .signal(text)
        .or_else(|_| Dialect::Iec.signal(text))
}

/// How a cell's tag addresses, and the conditions over them, are written:
/// in its PLC's dialect (`cell.dialect`), or by default a PMC address or an
/// IEC address or name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addressing {
    /// A PMC address (`X0.07`, `D100`), else an IEC direct address or name.
    PmcOrIec,
    /// The PLC's own dialect only: `pmc` (or a plain name), `iec`, `stl`
    /// (`E 0.0`, `MW 10`, `"Start"`, `Band.#Reset`, or a plain name).
    In(Dialect),
}

impl Addressing {
    /// The canonical signal for a tag address written in the cell's
    /// configuration.
    ///
    /// # Errors
    /// A message quoting the malformed address.
    pub fn signal(self, text: &str) -> Result<Signal, String> {
        match self {
            Addressing::PmcOrIec => tag_address(text),
            Addressing::In(Dialect::Iec) => Dialect::Iec.tag_signal(text),
            // A plain name (`Temperatur`) is a symbol in any dialect.
            Addressing::In(d) => d.tag_signal(text).or_else(|e| {
                if text.starts_with('%') {
                    return Err(e);
                }
                Dialect::Iec.tag_signal(text).map_err(|_| e)
            }),
        }
    }
}

/// The expression with its addresses in canonical form (`x0.6` → `X0.06`).
fn canonical_expr(addressing: Addressing, e: Expr) -> Expr {
    let canonical = |s: &Signal| addressing.signal(s.name()).unwrap_or_else(|_| s.clone());
    match e {
        Expr::Lit(s, n) => match Comparison::of_signal(&s) {
            Some(mut c) => {
                c.lhs = canonical(&c.lhs);
                if let Operand::Tag(t) = &c.rhs {
                    c.rhs = Operand::Tag(canonical(t));
                }
                Expr::Lit(c.signal(), n)
            }
            None => Expr::Lit(canonical(&s), n),
        },
        Expr::Not(inner) => Expr::Not(Box::new(canonical_expr(addressing, *inner))),
        Expr::And(es) => Expr::And(
            es.into_iter()
                .map(|e| canonical_expr(addressing, e))
                .collect(),
        ),
        Expr::Or(es) => Expr::Or(
            es.into_iter()
                .map(|e| canonical_expr(addressing, e))
                .collect(),
        ),
        c @ Expr::Const(_) => c,
    }
}

#[cfg(test)]
mod tests;
