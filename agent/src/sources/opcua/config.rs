//! `[opcua]`: how the agent reaches its server, and as whom. The table as
//! written ([`RawOpcUa`]), the validated configuration ([`OpcUaConfig`])
//! and its check (`validate`).

use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::sources::opcua::node::TagNode;
use crate::table::Table;

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

/// `[opcua]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawOpcUa {
    pub(crate) endpoint: Spanned<String>,
    pub(crate) security_policy: Option<Spanned<String>>,
    pub(crate) security_mode: Option<Spanned<String>>,
    pub(crate) pki_dir: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) identity: Option<Spanned<RawIdentity>>,
    pub(crate) publishing_interval: Option<Spanned<String>>,
    pub(crate) sampling_interval: Option<Spanned<String>>,
    pub(crate) namespace_uri: Option<Spanned<String>>,
    pub(crate) queue_size: Option<Spanned<i64>>,
    pub(crate) max_notifications_per_publish: Option<Spanned<i64>>,
    pub(crate) overflow_clear_after: Option<Spanned<String>>,
    pub(crate) subscription_lifetime: Option<Spanned<String>>,
    pub(crate) verify_interval: Option<Spanned<String>>,
    pub(crate) reverse_listen: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) redundant: Vec<Spanned<String>>,
    #[serde(default)]
    pub(crate) events: Vec<Spanned<RawEvents>>,
}

/// `[[opcua.events]]`: the PLC's own alarms, read from a notifier.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawEvents {
    pub(crate) source: Option<Spanned<String>>,
    pub(crate) prefix: Option<Spanned<String>>,
    pub(crate) min_severity: Option<Spanned<i64>>,
}

/// `[opcua.identity]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawIdentity {
    pub(crate) kind: Spanned<String>,
    pub(crate) user: Option<String>,
    pub(crate) password_env: Option<String>,
    pub(crate) password_file: Option<Spanned<String>>,
    /// Never allowed: present only to say so clearly.
    pub(crate) password: Option<Spanned<toml::Value>>,
}

pub(crate) fn validate(kit: &mut Table<'_>, raw: RawOpcUa) -> Option<OpcUaConfig> {
    let endpoint = raw.endpoint.get_ref().clone();
    if !endpoint.starts_with("opc.tcp://") {
        kit.problem(
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
            kit.problem(
                span,
                "opcua.security_policy",
                format!("'{p}' is deprecated and insecure; use Basic256Sha256"),
            );
            SecurityPolicy::Basic256Sha256
        }
        Some((p, span)) => {
            kit.problem(span, "opcua.security_policy", format!("unknown policy '{p}': use Basic256Sha256, Aes128_Sha256_RsaOaep, Aes256_Sha256_RsaPss or None"));
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
            kit.problem(
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
        kit.problem(
            span,
            "opcua.security_mode",
            "security_policy None goes with security_mode None, and only with it",
        );
    } else if policy == SecurityPolicy::None {
        kit.warn(format!(
            "OPC UA security is off for {endpoint}: traffic is neither signed nor encrypted"
        ));
    }
    let pki_dir = kit.path(raw.pki_dir.as_ref().map_or("pki", |p| p.get_ref().as_str()));
    let identity = match raw.identity {
        None => Identity::Anonymous,
        Some(id) => identity(kit, id.into_inner())?,
    };
    let publishing_interval = kit.duration(
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
        other => kit.duration(other, "opcua.sampling_interval", Duration::from_millis(50)),
    };
    let queue_size = match raw.queue_size {
        None => OpcUaConfig::default_queue_size(publishing_interval, sampling_interval),
        Some(q) => kit.count(q, "opcua.queue_size", 1..=10_000, 10),
    };
    let max_notifications_per_publish =
        raw.max_notifications_per_publish
            .map_or(OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS, |q| {
                kit.count(
                    q,
                    "opcua.max_notifications_per_publish",
                    100..=1_000_000,
                    OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS,
                )
            });
    let namespace_uri = match raw.namespace_uri {
        Some(uri) if uri.get_ref().trim().is_empty() => {
            kit.problem(uri.span(), "opcua.namespace_uri", "is empty");
            None
        }
        other => other.map(|u| (u.span(), u.into_inner())),
    };
    let overflow_clear_after = match raw.overflow_clear_after {
        None => OpcUaConfig::DEFAULT_OVERFLOW_CLEAR_AFTER,
        Some(v) if v.get_ref().trim() == "0" => Duration::ZERO,
        Some(v) => {
            let span = v.span();
            let d = kit.duration(
                Some(v),
                "opcua.overflow_clear_after",
                OpcUaConfig::DEFAULT_OVERFLOW_CLEAR_AFTER,
            );
            if d > Duration::from_secs(3600) {
                kit.problem(span, "opcua.overflow_clear_after", "at most 1h");
            }
            d
        }
    };
    // At least three keep-alive periods (OPC UA Part 4): the server
    // sends a keep-alive every 10 publishing intervals without data.
    let shortest = publishing_interval * 30;
    let subscription_lifetime = match raw.subscription_lifetime {
        None => OpcUaConfig::DEFAULT_SUBSCRIPTION_LIFETIME.max(shortest),
        Some(v) => {
            let span = v.span();
            let d = kit.duration(
                Some(v),
                "opcua.subscription_lifetime",
                OpcUaConfig::DEFAULT_SUBSCRIPTION_LIFETIME,
            );
            if d < shortest {
                kit.problem(
                    span,
                    "opcua.subscription_lifetime",
                    format!(
                        "at least three keep-alive periods (30 publishing intervals: {})",
                        humantime::format_duration(shortest)
                    ),
                );
            } else if d > Duration::from_secs(3600) {
                kit.problem(span, "opcua.subscription_lifetime", "at most 1h");
            }
            d
        }
    };
    let verify_interval = match raw.verify_interval {
        None => OpcUaConfig::DEFAULT_VERIFY_INTERVAL,
        Some(v) => {
            let span = v.span();
            let d = kit.duration(
                Some(v),
                "opcua.verify_interval",
                OpcUaConfig::DEFAULT_VERIFY_INTERVAL,
            );
            if d < Duration::from_secs(1) {
                kit.problem(span, "opcua.verify_interval", "at least 1s");
            } else if d > Duration::from_secs(3600) {
                kit.problem(span, "opcua.verify_interval", "at most 1h");
            }
            d
        }
    };
    let reverse_listen = raw.reverse_listen.and_then(|r| reverse_listen(kit, &r));
    let mut redundant: Vec<String> = Vec::new();
    for (i, r) in raw.redundant.iter().enumerate() {
        let key = format!("opcua.redundant[{i}]");
        let url = r.get_ref().trim().to_string();
        if !url.starts_with("opc.tcp://") {
            kit.problem(
                r.span(),
                &key,
                format!("'{url}' must start with opc.tcp://"),
            );
        } else if url == endpoint || redundant.contains(&url) {
            kit.problem(r.span(), &key, format!("'{url}' is named twice in the set"));
        } else if reverse_listen.is_some() {
            kit.problem(
                r.span(),
                &key,
                "a redundant set is dialled by the agent: not with opcua.reverse_listen",
            );
        } else {
            redundant.push(url);
        }
    }
    let events = events(
        kit,
        &raw.events,
        namespace_uri.as_ref().map(|(_, u)| u.as_str()),
    );
    Some(OpcUaConfig {
        events,
        redundant,
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
        overflow_clear_after,
        subscription_lifetime,
        verify_interval,
        reverse_listen,
    })
}

/// `[[opcua.events]]`: each notifier once, each prefix once and a key
/// chunk, severities within 1–1000.
fn events(
    kit: &mut Table<'_>,
    raw: &[Spanned<RawEvents>],
    namespace_uri: Option<&str>,
) -> Vec<EventSource> {
    let mut events: Vec<EventSource> = Vec::new();
    for (i, e) in raw.iter().enumerate() {
        let key = |k: &str| format!("opcua.events[{i}].{k}");
        let e_span = e.span();
        let e = e.get_ref();
        let (text, span) = match &e.source {
            Some(s) => (s.get_ref().trim().to_string(), s.span()),
            None => (EventSource::SERVER.to_string(), e_span.clone()),
        };
        let source = match TagNode::parse(&text, namespace_uri) {
            Ok(n) => n,
            Err(why) => {
                kit.problem(span, &key("source"), why);
                continue;
            }
        };
        let (prefix, prefix_span) = match &e.prefix {
            Some(p) => (p.get_ref().clone(), p.span()),
            None => (EventSource::DEFAULT_PREFIX.to_string(), e_span.clone()),
        };
        if !crate::tags::key_chunk(&prefix) {
            kit.problem(
                prefix_span,
                &key("prefix"),
                format!(
                    "'{prefix}' must be letters, digits, - and _ only (it begins the alarms' ids)"
                ),
            );
            continue;
        }
        let min_severity = match &e.min_severity {
            None => 1,
            Some(v) => match u16::try_from(*v.get_ref()) {
                Ok(s @ 1..=1000) => s,
                _ => {
                    kit.problem(
                        v.span(),
                        &key("min_severity"),
                        "an OPC UA severity: 1 to 1000",
                    );
                    continue;
                }
            },
        };
        if events.iter().any(|o| o.source == source) {
            kit.problem(span, &key("source"), format!("'{text}' is read twice"));
        } else if events.iter().any(|o| o.prefix == prefix) {
            kit.problem(
                prefix_span,
                &key("prefix"),
                format!("'{prefix}' is used twice"),
            );
        } else {
            events.push(EventSource {
                source,
                prefix,
                min_severity,
            });
        }
    }
    events
}

/// `opcua.reverse_listen`: `opc.tcp://ADDRESS:PORT` with an IP address
/// (`0.0.0.0` or `[::]` for every interface).
fn reverse_listen(kit: &mut Table<'_>, raw: &Spanned<String>) -> Option<std::net::SocketAddr> {
    let text = raw.get_ref().trim();
    let address = text
        .strip_prefix("opc.tcp://")
        .map(|a| a.trim_end_matches('/'));
    match address.map(str::parse::<std::net::SocketAddr>) {
        Some(Ok(a)) => Some(a),
        _ => {
            kit.problem(
                    raw.span(),
                    "opcua.reverse_listen",
                    format!(
                        "'{text}' is not opc.tcp://ADDRESS:PORT with an IP address: write e.g. opc.tcp://0.0.0.0:4843"
                    ),
                );
            None
        }
    }
}

fn identity(kit: &mut Table<'_>, id: RawIdentity) -> Option<Identity> {
    if let Some(p) = &id.password {
        kit.problem(
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
                kit.problem(
                    id.kind.span(),
                    "opcua.identity.user",
                    "a user identity needs a user name",
                );
            }
            let password = match (id.password_env, id.password_file) {
                (Some(env), None) => PasswordSource::Env(env),
                (None, Some(file)) => PasswordSource::File(kit.path(file.get_ref())),
                _ => {
                    kit.problem(
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
            kit.problem(
                id.kind.span(),
                "opcua.identity.kind",
                format!("unknown identity '{other}': use anonymous or user"),
            );
            None
        }
    }
}
