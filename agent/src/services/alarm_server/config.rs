//! `[alarm_server]`: the cell's alarms served to SCADA clients as OPC UA
//! Alarms & Conditions (the server itself is `services::alarm_server`).
//! The table as written ([`RawAlarmServer`], unknown keys rejected), the
//! validated configuration ([`AlarmServerConfig`]) and [`validate`], which
//! finds every problem and says where it is.

use std::net::SocketAddr;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

/// The server's PKI directory unless the configuration names one.
const DEFAULT_PKI_DIR: &str = "alarm-server-pki";

/// `[alarm_server]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAlarmServer {
    listen: Option<Spanned<String>>,
    pki_dir: Option<Spanned<String>>,
    users_file: Option<Spanned<String>>,
}

/// Serving the cell's alarms over OPC UA.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlarmServerConfig {
    /// Where the server listens (`opc.tcp://0.0.0.0:4855`; port 0: chosen
    /// by the system).
    pub listen: SocketAddr,
    /// The server's own key pair (`own/`, `private/`, made on first
    /// start), the clients' certificates it trusts (`trusted/`) and those
    /// it refused (`rejected/`).
    pub pki_dir: PathBuf,
    /// The OPC UA users: name, the operator each acts as, password hash.
    pub users_file: PathBuf,
}

/// Why `[alarm_server]` is not valid: one problem, placed by the
/// configuration's validator.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum AlarmServerConfigError {
    /// No `listen`.
    #[error("required: where the server listens, like \"opc.tcp://0.0.0.0:4855\"")]
    NoListen,
    /// No `users_file`.
    #[error("required: the file of the OPC UA users and the operators they act as")]
    NoUsersFile,
    /// Not an `opc.tcp://` address.
    #[error("'{0}' is not like opc.tcp://0.0.0.0:4855")]
    NotOpcTcp(String),
    /// An `opc.tcp://` address without an IP address and a port.
    #[error("'{0}': give an IP address and a port, like opc.tcp://0.0.0.0:4855")]
    NoIpAndPort(String),
}

/// What [`validate`] found.
pub(crate) type Checked = crate::table::Checked<AlarmServerConfig, AlarmServerConfigError>;

/// Validates `[alarm_server]` (its table at `raw`'s span), relative paths
/// from `base`.
pub(crate) fn validate(raw: Spanned<RawAlarmServer>, base: &Path) -> Checked {
    use AlarmServerConfigError as E;
    let table = raw.span();
    let raw = raw.into_inner();
    let mut out = Checked::default();
    let mut problem = |span: Range<usize>, key: &str, error| {
        out.problem(span, format!("alarm_server.{key}"), error)
    };
    let listen = match &raw.listen {
        None => {
            problem(table.clone(), "listen", E::NoListen);
            None
        }
        Some(l) => listen_address(l.get_ref())
            .map_err(|why| problem(l.span(), "listen", why))
            .ok(),
    };
    let users_file = match &raw.users_file {
        None => {
            problem(table, "users_file", E::NoUsersFile);
            None
        }
        Some(f) => Some(crate::table::path(base, f.get_ref())),
    };
    let pki_dir = crate::table::path(
        base,
        raw.pki_dir
            .as_ref()
            .map_or(DEFAULT_PKI_DIR, |p| p.get_ref().as_str()),
    );
    if let (Some(listen), Some(users_file)) = (listen, users_file) {
        out.config = Some(AlarmServerConfig {
            listen,
            pki_dir,
            users_file,
        });
    }
    out
}

/// The socket address of `opc.tcp://IP:PORT`, or why it is not one.
fn listen_address(text: &str) -> Result<SocketAddr, AlarmServerConfigError> {
    let rest = text
        .strip_prefix("opc.tcp://")
        .ok_or_else(|| AlarmServerConfigError::NotOpcTcp(text.into()))?;
    rest.trim_end_matches('/')
        .parse()
        .map_err(|_| AlarmServerConfigError::NoIpAndPort(text.into()))
}

#[cfg(test)]
mod tests {
    use super::listen_address;

    #[test]
    fn listen_is_an_opc_tcp_ip_and_port() {
        assert_eq!(
            listen_address("opc.tcp://127.0.0.1:4855/").unwrap(),
            "127.0.0.1:4855".parse().unwrap()
        );
        assert_eq!(
            listen_address("127.0.0.1:4855").unwrap_err().to_string(),
            "'127.0.0.1:4855' is not like opc.tcp://0.0.0.0:4855"
        );
        assert_eq!(
            listen_address("opc.tcp://scada:4855")
                .unwrap_err()
                .to_string(),
            "'opc.tcp://scada:4855': give an IP address and a port, like opc.tcp://0.0.0.0:4855"
        );
    }
}
