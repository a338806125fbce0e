//! `[alertmanager]`: where the cell's alarms are pushed for people
//! (Prometheus Alertmanager's API v2).

use std::path::PathBuf;
use std::time::Duration;

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
