//! `[alertmanager]`: where the cell's alarms are pushed for people
//! (Prometheus Alertmanager's API v2). The table as written
//! ([`RawAlertmanager`], unknown keys rejected), the validated
//! configuration ([`AlertmanagerConfig`]) and [`validate`], which finds
//! every problem and says where it is. No I/O: the CA and client
//! certificate are read when the sink starts.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::table::DurationError;

/// The most Alertmanagers one cell sends to (each is owed every ended
/// alert until it has taken it).
const MAX_URLS: usize = 16;

/// The most steps of `alertmanager.escalation`.
const MAX_STEPS: usize = 8;

/// The longest `alertmanager.resend_interval`: an alert says it ends four
/// intervals after it was sent, and an hour's silence hides a dead agent.
const MAX_RESEND: Duration = Duration::from_secs(3600);

/// `[alertmanager]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAlertmanager {
    #[serde(default)]
    urls: Vec<Spanned<String>>,
    area: Option<String>,
    console: Option<Spanned<String>>,
    resend_interval: Option<Spanned<String>>,
    escalation: Option<Vec<Spanned<String>>>,
    tls: Option<Spanned<RawAlertmanagerTls>>,
}

/// `[alertmanager.tls]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAlertmanagerTls {
    ca: Spanned<String>,
    cert: Option<Spanned<String>>,
    key: Option<Spanned<String>>,
}

/// How often active alerts are sent again unless the configuration says.
pub const DEFAULT_RESEND: Duration = Duration::from_secs(60);

/// Pushing the cell's alarms to Alertmanager.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlertmanagerConfig {
    /// Every instance of the Alertmanager cluster (`http://am:9093`, or
    /// with the path prefix it is served under); each is sent every alert,
    /// as Alertmanager's clustering expects.
    pub urls: Vec<String>,
    /// The `area` label (`alertmanager.area`), for routing by area.
    pub area: Option<String>,
    /// The operators' console (`https://console:8470`): each alert links
    /// to its alarm's page there.
    pub console: Option<String>,
    /// How often active alerts are sent again; each send says they end
    /// four intervals later unless sent again.
    pub resend: Duration,
    /// For `https://` Alertmanagers.
    pub tls: Option<AlertmanagerTls>,
    /// The steps of the `unacknowledged_for` label (`alertmanager.escalation`):
    /// its value as written, and how long after its raise an alarm nobody
    /// acknowledged reaches it. Empty: no such label.
    pub escalation: Vec<(String, Duration)>,
}

/// The steps of escalation unless the configuration says: 5 minutes,
/// 15 minutes, an hour.
pub fn default_escalation() -> Vec<(String, Duration)> {
    [("5m", 5), ("15m", 15), ("1h", 60)]
        .into_iter()
        .map(|(name, minutes)| (name.to_string(), Duration::from_secs(60 * minutes)))
        .collect()
}

/// TLS to Alertmanager (its `web.config.file`'s `tls_server_config`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlertmanagerTls {
    /// The CA that signed the Alertmanagers' certificates.
    pub ca: PathBuf,
    /// The agent's client certificate and key, when Alertmanager asks for
    /// one (`client_auth_type`).
    pub client: Option<(PathBuf, PathBuf)>,
}

/// Why `[alertmanager]` is not valid: one problem, placed by the
/// configuration's validator.
#[derive(Debug, thiserror::Error)]
pub(crate) enum AlertmanagerConfigError {
    /// No URL.
    #[error("name at least one Alertmanager, like [\"http://alertmanager:9093\"]")]
    NoUrl,
    /// More URLs than [`MAX_URLS`].
    #[error("at most {MAX_URLS} Alertmanagers (a cluster's instances)")]
    TooManyUrls,
    /// Not a URL.
    #[error("'{text}' is not a URL like http://alertmanager:9093 ({source})")]
    NotAUrl {
        /// The text.
        text: String,
        /// Why.
        source: hyper::http::uri::InvalidUri,
    },
    /// A URL neither `http://` nor `https://`.
    #[error("'{0}': use http:// or https://")]
    NotHttp(String),
    /// A URL without a host.
    #[error("'{0}' names no host")]
    NoHost(String),
    /// A URL with a query.
    #[error("'{0}': no query (?…) is allowed")]
    Query(String),
    /// `resend_interval` does not read.
    #[error(transparent)]
    Resend(DurationError),
    /// `resend_interval` over an hour.
    #[error("at most 1h: active alerts end four intervals after they were last sent")]
    ResendTooLong,
    /// A client certificate without its key, or the other way round.
    #[error("give both cert and key (a client certificate), or neither")]
    HalfClientCertificate,
    /// An `https://` URL without `[alertmanager.tls]`.
    #[error(
        "an https:// Alertmanager needs [alertmanager.tls] ca = the CA that signed its certificate"
    )]
    NoCa,
    /// An empty `area`.
    #[error("must not be empty")]
    EmptyArea,
    /// More steps than [`MAX_STEPS`].
    #[error("at most {MAX_STEPS} steps")]
    TooManySteps,
    /// A step of zero.
    #[error("'{0}': a step is a time after the raise, more than 0")]
    ZeroStep(String),
    /// A step not longer than the one before it.
    #[error("'{0}': each step must be longer than the one before it")]
    StepNotLonger(String),
    /// A step that is not a duration.
    #[error("'{text}' is not a duration like 5m or 1h ({reason})")]
    StepNotADuration {
        /// The text.
        text: String,
        /// Why not.
        reason: String,
    },
}

/// What [`validate`] found (warnings: a plain-HTTP Alertmanager off this
/// machine).
pub(crate) type Checked = crate::table::Checked<AlertmanagerConfig, AlertmanagerConfigError>;

/// Validates `[alertmanager]` (its table at `raw`'s span), relative paths
/// from `base`.
pub(crate) fn validate(raw: Spanned<RawAlertmanager>, base: &Path) -> Checked {
    use AlertmanagerConfigError as E;
    let table = raw.span();
    let raw = raw.into_inner();
    let mut out = Checked::default();
    let mut problem = |span: Range<usize>, key: &str, error| {
        out.problem(span, format!("alertmanager.{key}"), error)
    };
    if raw.urls.is_empty() {
        problem(table.clone(), "urls", E::NoUrl);
    }
    if raw.urls.len() > MAX_URLS {
        problem(table.clone(), "urls", E::TooManyUrls);
    }
    let mut urls = Vec::new();
    let mut https = None;
    let mut warnings = Vec::new();
    for u in raw.urls.iter().take(MAX_URLS) {
        match web_url(u.get_ref()) {
            Ok(secure) => {
                if secure && https.is_none() {
                    https = Some(u.span());
                }
                if !secure && !is_loopback(u.get_ref()) {
                    warnings.push(format!(
                        "alertmanager.urls: {} is plain HTTP: alerts cross the network unencrypted and unauthenticated",
                        u.get_ref()
                    ));
                }
                urls.push(u.get_ref().trim_end_matches('/').to_string());
            }
            Err(why) => problem(u.span(), "urls", why),
        }
    }
    let console = raw.console.and_then(|c| match web_url(c.get_ref()) {
        Ok(_) => Some(c.get_ref().trim_end_matches('/').to_string()),
        Err(why) => {
            problem(c.span(), "console", why);
            None
        }
    });
    let resend = match &raw.resend_interval {
        None => DEFAULT_RESEND,
        Some(r) => match crate::table::duration(r.get_ref()) {
            Ok(d) if d > MAX_RESEND => {
                problem(r.span(), "resend_interval", E::ResendTooLong);
                DEFAULT_RESEND
            }
            Ok(d) => d,
            Err(e) => {
                problem(r.span(), "resend_interval", E::Resend(e));
                DEFAULT_RESEND
            }
        },
    };
    let tls = raw.tls.map(|t| {
        let span = t.span();
        let t = t.into_inner();
        let path = |p: &Spanned<String>| crate::table::path(base, p.get_ref());
        let client = match (&t.cert, &t.key) {
            (Some(c), Some(k)) => Some((path(c), path(k))),
            (None, None) => None,
            _ => {
                problem(span, "tls", E::HalfClientCertificate);
                None
            }
        };
        AlertmanagerTls {
            ca: path(&t.ca),
            client,
        }
    });
    if let (Some(span), None) = (https, &tls) {
        problem(span, "tls", E::NoCa);
    }
    if raw.area.as_ref().is_some_and(|a| a.trim().is_empty()) {
        problem(table.clone(), "area", E::EmptyArea);
    }
    let escalation = match raw.escalation {
        None => default_escalation(),
        Some(steps) => escalation(steps, &table, &mut problem),
    };
    out.warnings = warnings;
    if out.problems.is_empty() {
        out.config = Some(AlertmanagerConfig {
            urls,
            area: raw.area,
            console,
            resend,
            tls,
            escalation,
        });
    }
    out
}

/// `alertmanager.escalation`: durations, each longer than the one before
/// it, at most [`MAX_STEPS`].
fn escalation(
    steps: Vec<Spanned<String>>,
    table: &Range<usize>,
    problem: &mut impl FnMut(Range<usize>, &str, AlertmanagerConfigError),
) -> Vec<(String, Duration)> {
    use AlertmanagerConfigError as E;
    if steps.len() > MAX_STEPS {
        problem(table.clone(), "escalation", E::TooManySteps);
    }
    let mut out: Vec<(String, Duration)> = Vec::new();
    for step in steps.into_iter().take(MAX_STEPS) {
        let span = step.span();
        let text = step.get_ref().trim().to_string();
        match humantime::parse_duration(&text) {
            Ok(d) if d.is_zero() => problem(span, "escalation", E::ZeroStep(text)),
            Ok(d) if out.last().is_some_and(|(_, before)| d <= *before) => {
                problem(span, "escalation", E::StepNotLonger(text));
            }
            Ok(d) => out.push((text, d)),
            Err(e) => problem(
                span,
                "escalation",
                E::StepNotADuration {
                    text,
                    reason: e.to_string(),
                },
            ),
        }
    }
    out
}

/// Whether `text` is an `http://` (false) or `https://` (true) address
/// with a host and no query; why not otherwise.
fn web_url(text: &str) -> Result<bool, AlertmanagerConfigError> {
    use AlertmanagerConfigError as E;
    let uri: hyper::Uri = text.parse().map_err(|source| E::NotAUrl {
        text: text.into(),
        source,
    })?;
    let secure = match uri.scheme_str() {
        Some("http") => false,
        Some("https") => true,
        _ => return Err(E::NotHttp(text.into())),
    };
    if uri.host().is_none_or(str::is_empty) {
        return Err(E::NoHost(text.into()));
    }
    if uri.query().is_some() {
        return Err(E::Query(text.into()));
    }
    Ok(secure)
}

/// Whether the URL's host is this machine.
fn is_loopback(text: &str) -> bool {
    let Ok(uri) = text.parse::<hyper::Uri>() else {
        return false;
    };
    match uri.host() {
        Some("localhost") => true,
        Some(h) => h
            .trim_matches(['[', ']'])
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback()),
        None => false,
    }
}
