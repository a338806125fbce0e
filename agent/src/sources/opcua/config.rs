//! OPC UA: how the agent reaches its server, and as whom.

use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

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
    /// How long without a lost change before the `opcua-overflow` alarm
    /// clears (`opcua.overflow_clear_after`).
    pub overflow_clear_after: Duration,
    /// How long the server keeps the subscription, and the changes it
    /// queues, while the agent is cut off (`opcua.subscription_lifetime`):
    /// a network cut shorter than this loses nothing.
    pub subscription_lifetime: Duration,
    /// How often every monitored item is checked against the server's
    /// nodes (`opcua.verify_interval`): a node deleted, or deleted and
    /// added again, by a server that said nothing is found and monitored
    /// again.
    pub verify_interval: Duration,
    /// Where the agent listens for the server to connect to it (OPC UA
    /// reverse connect, `opcua.reverse_listen`): the server dials out, the
    /// agent never dials `endpoint`, which then only names the server.
    pub reverse_listen: Option<std::net::SocketAddr>,
    /// The other servers of a redundant set (`opcua.redundant`,
    /// non-transparent redundancy): the agent reads from whichever of
    /// `endpoint` and these says the highest `ServiceLevel`, and moves to
    /// another when it drops or degrades.
    pub redundant: Vec<String>,
    /// Where the PLC's own alarms are read from (`[[opcua.events]]`): each
    /// condition the server reports there is an alarm of the cell.
    pub events: Vec<EventSource>,
}

/// A notifier whose Alarms & Conditions events are the cell's alarms
/// (`[[opcua.events]]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EventSource {
    /// The node whose events are read (`source`; the Server object,
    /// `i=2253`, by default: every event of the server).
    pub source: crate::sources::opcua::node::TagNode,
    /// The alarms' ids start with this and `-` (`prefix`, `plc` by
    /// default).
    pub prefix: String,
    /// Events of a lower severity (1–1000) are not alarms
    /// (`min_severity`, 1 by default).
    pub min_severity: u16,
}

impl EventSource {
    /// The Server object: every event the server reports.
    pub const SERVER: &'static str = "i=2253";
    /// `prefix` unless configured.
    pub const DEFAULT_PREFIX: &'static str = "plc";
}

impl OpcUaConfig {
    /// Every server the cell may be read from: `endpoint`, then
    /// `redundant`.
    pub fn servers(&self) -> Vec<&str> {
        std::iter::once(self.endpoint.as_str())
            .chain(self.redundant.iter().map(String::as_str))
            .collect()
    }

    /// The same configuration for server `endpoint` of the set.
    pub fn at(&self, endpoint: &str) -> OpcUaConfig {
        OpcUaConfig {
            endpoint: endpoint.to_string(),
            ..self.clone()
        }
    }

    /// The default of `opcua.max_notifications_per_publish`. A publishing
    /// cycle the server splits over several publishes is judged whole, so
    /// its alarms wait for its last publish; a publish past the first two
    /// of a cycle costs a round trip for the next publish request. 10,000
    /// sends the cycles of a 100,000-tag cell at 100,000 changes/s in one
    /// or two publishes (BENCHMARKS.md) and decodes within the client's
    /// limits, which are sized for it.
    pub const DEFAULT_MAX_NOTIFICATIONS: u32 = 10_000;

    /// `opcua.subscription_lifetime` unless configured.
    pub const DEFAULT_SUBSCRIPTION_LIFETIME: Duration = Duration::from_secs(60);

    /// `opcua.verify_interval` unless configured.
    pub const DEFAULT_VERIFY_INTERVAL: Duration = Duration::from_secs(30);

    /// `opcua.overflow_clear_after` unless configured.
    pub const DEFAULT_OVERFLOW_CLEAR_AFTER: Duration = Duration::from_secs(10);

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
