//! `[sparkplug]`: the cell as a Sparkplug B edge node on an MQTT broker.
//! The table as written ([`RawSparkplug`], unknown keys rejected), the
//! validated configuration ([`SparkplugConfig`]) and [`validate`], which
//! finds every problem and says where it is. No I/O: the files named here
//! (CA, client certificate and key, password) are read when the sink
//! starts. The configuration's validator calls [`validate`] and places
//! each problem at its line and column; it imports nothing else of the
//! sink.

use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

/// How many changes are held at most while they cannot be published
/// unless `sparkplug.max_held` says.
pub const DEFAULT_MAX_HELD: usize = 10_000;

/// The most `sparkplug.max_held` may say: a change costs about a hundred
/// bytes held.
pub const MAX_HELD_LIMIT: usize = 1_000_000;

/// `[sparkplug]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSparkplug {
    broker: Option<Spanned<String>>,
    group_id: Option<Spanned<String>>,
    edge_node_id: Option<Spanned<String>>,
    device_id: Option<Spanned<String>>,
    primary_host: Option<Spanned<String>>,
    username: Option<Spanned<String>>,
    password_file: Option<Spanned<String>>,
    /// Never allowed: present only to say so clearly.
    password: Option<Spanned<toml::Value>>,
    max_held: Option<Spanned<i64>>,
    tls: Option<Spanned<RawSparkplugTls>>,
}

/// `[sparkplug.tls]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSparkplugTls {
    ca: Spanned<String>,
    cert: Option<Spanned<String>>,
    key: Option<Spanned<String>>,
}

/// The cell as a Sparkplug B edge node.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SparkplugConfig {
    /// The MQTT broker.
    pub broker: Broker,
    /// The Sparkplug group the edge node belongs to.
    pub group_id: String,
    /// The edge node's id within its group.
    pub edge_node_id: String,
    /// The device the cell is under its edge node (the cell's id unless
    /// `sparkplug.device_id` says).
    pub device_id: String,
    /// The primary host application whose `STATE` the node follows, if
    /// any.
    pub primary_host: Option<String>,
    /// The user name and the file holding its password, if the broker asks
    /// for one.
    pub credentials: Option<Credentials>,
    /// TLS to the broker (`mqtts://`).
    pub tls: Option<SparkplugTls>,
    /// How many changes are held at most while they cannot be published;
    /// past it the oldest are dropped (the next birth carries every
    /// current value).
    pub max_held: usize,
}

/// Where the broker is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broker {
    /// Its host name or address.
    pub host: String,
    /// Its port (8883 for `mqtts://`, 1883 for `mqtt://` unless written).
    pub port: u16,
    /// `mqtts://`: TLS.
    pub secure: bool,
}

/// A user name and where its password is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Credentials {
    /// The MQTT user name.
    pub username: String,
    /// The file whose first line is the password (owner-only).
    pub password_file: Option<PathBuf>,
}

/// TLS to the broker.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SparkplugTls {
    /// The CA that signed the broker's certificate.
    pub ca: PathBuf,
    /// The agent's client certificate and key, when the broker asks for
    /// one.
    pub client: Option<(PathBuf, PathBuf)>,
}

/// What is wrong with a key of `[sparkplug]`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SparkplugConfigError {
    /// A required key is missing.
    #[error("required: {0}")]
    Required(&'static str),
    /// The broker is not an MQTT address.
    #[error("'{0}' is not a broker address like mqtts://broker:8883 (or mqtt://host:1883, plain)")]
    NotABroker(String),
    /// An id cannot be a level of an MQTT topic.
    #[error("'{0}' must be a non-empty id without '/', '+', '#' or spaces (it is a level of MQTT topics)")]
    NotAnId(String),
    /// The password is written in the file.
    #[error("a password is never written in the configuration: put it in a file only the agent reads and name it with password_file")]
    InlinePassword,
    /// A password without a user.
    #[error("a password_file needs a username")]
    PasswordWithoutUser,
    /// Half a client certificate.
    #[error("give both cert and key (a client certificate), or neither")]
    HalfClientCertificate,
    /// `mqtts://` without the CA.
    #[error("an mqtts:// broker needs [sparkplug.tls] ca = the CA that signed its certificate")]
    NoCa,
    /// TLS files for a plain broker.
    #[error("[sparkplug.tls] is for an mqtts:// broker; this one is plain mqtt://")]
    TlsOnPlain,
    /// `max_held` out of range.
    #[error("{0} is not between 1 and {MAX_HELD_LIMIT}")]
    HeldOutOfRange(i64),
}

/// What [`validate`] found (warnings: a plain broker off this machine).
pub type Checked = crate::table::Checked<SparkplugConfig, SparkplugConfigError>;

/// One problem of `[sparkplug]` and where it is.
pub type Problem = crate::table::Problem<SparkplugConfigError>;

/// Validates `[sparkplug]` (its table at `raw`'s span) for cell `cell`,
/// relative paths from `base`.
pub fn validate(raw: Spanned<RawSparkplug>, cell: &str, base: &Path) -> Checked {
    let table = raw.span();
    let raw = raw.into_inner();
    let mut out = Checked::default();
    let mut problem = |span: Range<usize>, key: &'static str, error| out.problem(span, key, error);
    let path = |p: &Spanned<String>| {
        let p = Path::new(p.get_ref());
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            base.join(p)
        }
    };
    let broker = match &raw.broker {
        None => {
            problem(
                table.clone(),
                "sparkplug.broker",
                SparkplugConfigError::Required("the MQTT broker, like \"mqtts://broker:8883\""),
            );
            None
        }
        Some(b) => match broker(b.get_ref()) {
            Some(broker) => Some(broker),
            None => {
                problem(
                    b.span(),
                    "sparkplug.broker",
                    SparkplugConfigError::NotABroker(b.get_ref().clone()),
                );
                None
            }
        },
    };
    let mut id = |value: Option<&Spanned<String>>, key: &'static str, default: Option<&str>| match (
        value, default,
    ) {
        (Some(v), _) if is_id(v.get_ref()) => Some(v.get_ref().clone()),
        (Some(v), _) => {
            problem(
                v.span(),
                key,
                SparkplugConfigError::NotAnId(v.get_ref().clone()),
            );
            None
        }
        (None, Some(d)) => Some(d.to_string()),
        (None, None) => {
            problem(table.clone(), key, SparkplugConfigError::Required("an id"));
            None
        }
    };
    let group_id = id(raw.group_id.as_ref(), "sparkplug.group_id", None);
    let edge_node_id = id(raw.edge_node_id.as_ref(), "sparkplug.edge_node_id", None);
    let device_id = id(raw.device_id.as_ref(), "sparkplug.device_id", Some(cell));
    let primary_host = raw
        .primary_host
        .as_ref()
        .and_then(|h| id(Some(h), "sparkplug.primary_host", None));
    if let Some(p) = &raw.password {
        problem(
            p.span(),
            "sparkplug.password",
            SparkplugConfigError::InlinePassword,
        );
    }
    let credentials = match (&raw.username, &raw.password_file) {
        (Some(u), file) => Some(Credentials {
            username: u.get_ref().clone(),
            password_file: file.as_ref().map(path),
        }),
        (None, Some(f)) => {
            problem(
                f.span(),
                "sparkplug.password_file",
                SparkplugConfigError::PasswordWithoutUser,
            );
            None
        }
        (None, None) => None,
    };
    let tls = raw.tls.as_ref().map(|t| {
        let span = t.span();
        let t = t.get_ref();
        let client = match (&t.cert, &t.key) {
            (Some(c), Some(k)) => Some((path(c), path(k))),
            (None, None) => None,
            _ => {
                problem(
                    span.clone(),
                    "sparkplug.tls",
                    SparkplugConfigError::HalfClientCertificate,
                );
                None
            }
        };
        (
            span,
            SparkplugTls {
                ca: path(&t.ca),
                client,
            },
        )
    });
    match (&broker, &tls) {
        (Some(b), None) if b.secure => problem(
            raw.broker.as_ref().map_or(table.clone(), Spanned::span),
            "sparkplug.tls",
            SparkplugConfigError::NoCa,
        ),
        (Some(b), Some((span, _))) if !b.secure => problem(
            span.clone(),
            "sparkplug.tls",
            SparkplugConfigError::TlsOnPlain,
        ),
        _ => {}
    }
    let max_held = match &raw.max_held {
        None => DEFAULT_MAX_HELD,
        Some(n) => match usize::try_from(*n.get_ref()) {
            Ok(v) if (1..=MAX_HELD_LIMIT).contains(&v) => v,
            _ => {
                problem(
                    n.span(),
                    "sparkplug.max_held",
                    SparkplugConfigError::HeldOutOfRange(*n.get_ref()),
                );
                DEFAULT_MAX_HELD
            }
        },
    };
    if let Some(b) = broker
        .as_ref()
        .filter(|b| !b.secure && !is_loopback(&b.host))
    {
        out.warnings.push(format!(
            "sparkplug.broker: mqtt://{}:{} is plain MQTT: the cell's data crosses the network unencrypted{}",
            b.host,
            b.port,
            if credentials.is_some() {
                ", its password too"
            } else {
                ""
            }
        ));
    }
    if !out.problems.is_empty() {
        return out;
    }
    if let (Some(broker), Some(group_id), Some(edge_node_id), Some(device_id)) =
        (broker, group_id, edge_node_id, device_id)
    {
        out.config = Some(SparkplugConfig {
            broker,
            group_id,
            edge_node_id,
            device_id,
            primary_host,
            credentials,
            tls: tls.map(|(_, t)| t),
            max_held,
        });
    }
    out
}

/// The broker `text` names: `mqtts://host[:port]` (TLS), `mqtt://host[:port]`
/// (plain, only when written so), or `host[:port]` (TLS).
fn broker(text: &str) -> Option<Broker> {
    let text = text.trim();
    let (secure, rest) = match text.split_once("://") {
        Some(("mqtts" | "ssl", rest)) => (true, rest),
        Some(("mqtt" | "tcp", rest)) => (false, rest),
        Some(_) => return None,
        None => (true, text),
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.is_empty() || rest.contains(['/', '?', '@', ' ']) {
        return None;
    }
    let default_port = if secure { 8883 } else { 1883 };
    let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
        let (host, after) = v6.split_once(']')?;
        let port = match after.strip_prefix(':') {
            Some(p) => p.parse().ok()?,
            None if after.is_empty() => default_port,
            None => return None,
        };
        (host.to_string(), port)
    } else {
        match rest.rsplit_once(':') {
            Some((host, port)) => (host.to_string(), port.parse().ok()?),
            None => (rest.to_string(), default_port),
        }
    };
    if host.is_empty() || port == 0 {
        return None;
    }
    Some(Broker { host, port, secure })
}

/// Whether `text` can be a level of a Sparkplug topic: not empty, no `/`,
/// `+`, `#`, no space or control character.
fn is_id(text: &str) -> bool {
    !text.is_empty()
        && !text
            .chars()
            .any(|c| matches!(c, '/' | '+' | '#') || c.is_whitespace() || c.is_control())
}

/// Whether the broker's host is this machine.
fn is_loopback(host: &str) -> bool {
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> Checked {
        #[derive(Deserialize)]
        struct Doc {
            sparkplug: Spanned<RawSparkplug>,
        }
        let doc: Doc = toml::from_str(text).unwrap();
        validate(doc.sparkplug, "m01", Path::new("/etc/cellwatch"))
    }

    fn errors(text: &str) -> Vec<(String, String)> {
        check(text)
            .problems
            .into_iter()
            .map(|p| (p.key, p.error.to_string()))
            .collect()
    }

    #[test]
    fn a_broker_over_tls_by_default_and_the_device_is_the_cell() {
        let c = check(
            "[sparkplug]\nbroker = \"broker.plant\"\ngroup_id = \"press-shop\"\nedge_node_id = \"m01-agent\"\n[sparkplug.tls]\nca = \"mqtt-ca.pem\"\n",
        );
        let c = c.config.unwrap();
        assert_eq!(
            c.broker,
            Broker {
                host: "broker.plant".into(),
                port: 8883,
                secure: true
            }
        );
        assert_eq!(c.device_id, "m01");
        assert_eq!(c.max_held, DEFAULT_MAX_HELD);
        assert_eq!(c.tls.unwrap().ca, Path::new("/etc/cellwatch/mqtt-ca.pem"));
        assert_eq!(
            broker("mqtt://[::1]:1884"),
            Some(Broker {
                host: "::1".into(),
                port: 1884,
                secure: false
            })
        );
        assert_eq!(broker("http://x"), None);
        assert_eq!(broker("mqtt://x:0"), None);
    }

    #[test]
    fn every_problem_is_found_and_named() {
        let expected = [
            ("sparkplug.group_id", "'a/b' must be a non-empty id without '/', '+', '#' or spaces (it is a level of MQTT topics)"),
            ("sparkplug.edge_node_id", "required: an id"),
            ("sparkplug.password", "a password is never written in the configuration: put it in a file only the agent reads and name it with password_file"),
            ("sparkplug.password_file", "a password_file needs a username"),
            ("sparkplug.tls", "an mqtts:// broker needs [sparkplug.tls] ca = the CA that signed its certificate"),
            ("sparkplug.max_held", "0 is not between 1 and 1000000"),
        ];
        assert_eq!(
            errors("[sparkplug]\nbroker = \"mqtts://b\"\ngroup_id = \"a/b\"\npassword = \"x\"\npassword_file = \"p\"\nmax_held = 0\n"),
            expected.map(|(k, m)| (k.to_string(), m.to_string()))
        );
        assert!(check("[sparkplug]\nbroker = \"mqtts://b\"\n")
            .config
            .is_none());
    }

    #[test]
    fn plain_mqtt_is_written_and_warned_of_off_this_machine() {
        let c = check(
            "[sparkplug]\nbroker = \"mqtt://10.0.0.5\"\ngroup_id = \"g\"\nedge_node_id = \"n\"\n",
        );
        assert_eq!(c.config.unwrap().broker.port, 1883);
        assert_eq!(
            c.warnings,
            ["sparkplug.broker: mqtt://10.0.0.5:1883 is plain MQTT: the cell's data crosses the network unencrypted"]
        );
        let c = check(
            "[sparkplug]\nbroker = \"mqtt://127.0.0.1:1884\"\ngroup_id = \"g\"\nedge_node_id = \"n\"\n[sparkplug.tls]\nca = \"x\"\n",
        );
        assert_eq!(
            c.problems
                .iter()
                .map(|p| p.key.as_str())
                .collect::<Vec<_>>(),
            ["sparkplug.tls"]
        );
    }

    /// The commented `[sparkplug]` of the demo configuration, uncommented,
    /// is a valid section (the example is documentation).
    #[test]
    fn the_demo_configurations_example_is_valid() {
        let demo = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/demo.toml"),
        )
        .unwrap();
        let example: String = demo
            .lines()
            .skip_while(|l| *l != "# [sparkplug]")
            .take_while(|l| l.starts_with("# ") && !l.starts_with("# The"))
            .map(|l| format!("{}\n", &l[2..]))
            .collect();
        assert!(example.contains("[sparkplug.tls]"), "{example}");
        let c = check(&example);
        assert!(c.problems.is_empty(), "{:?}", c.problems);
        let c = c.config.unwrap();
        assert_eq!(c.primary_host.as_deref(), Some("scada"));
        assert!(c.tls.unwrap().client.is_some());
    }
}
