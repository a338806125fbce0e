//! `[alarm_server]`: the cell's alarms served to SCADA clients as OPC UA
//! Alarms & Conditions (the server itself is `services::alarm_server`).

use std::net::SocketAddr;
use std::path::PathBuf;

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
