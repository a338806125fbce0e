//! The Zenoh session: mode, endpoints, TLS, keys, and which links are refused.

use std::path::PathBuf;

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

/// Why a Zenoh configuration file is not one: what a reader can act on.
#[derive(Debug, thiserror::Error)]
pub enum ZenohFileError {
    /// The file cannot be read (missing, not allowed).
    #[error(transparent)]
    Unreadable(std::io::Error),
    /// Zenoh refuses it: Zenoh's words, without the place in Zenoh's own
    /// source its errors end with.
    #[error("{0}")]
    Refused(String),
}

/// A Zenoh configuration file (JSON5, or YAML by its extension), read as
/// Zenoh reads it.
///
/// # Errors
/// The file cannot be read, or Zenoh refuses it.
pub fn zenoh_file(path: &std::path::Path) -> Result<zenoh::Config, ZenohFileError> {
    std::fs::metadata(path).map_err(ZenohFileError::Unreadable)?;
    zenoh::Config::from_file(path).map_err(|e| {
        let said = e.to_string();
        // `… at /…/zenoh-config-1.10.2/src/lib.rs:1507.`
        ZenohFileError::Refused(match said.rsplit_once(" at ") {
            Some((words, place)) if place.contains(".rs:") => words.to_string(),
            _ => said,
        })
    })
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

/// The root of every cell's keys unless `zenoh.key_prefix` says otherwise.
pub const DEFAULT_ROOT: &str = "cellwatch";

/// A cell's key prefix under a root: `<root>/<cell>`. The one place the
/// prefix is spelled; the keys under it are `crate::bus::keys`'.
pub fn cell_prefix(root: &str, cell: &str) -> String {
    format!("{}/{cell}", root.trim_end_matches('/'))
}

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

#[cfg(test)]
mod zenoh_file_tests {
    #[test]
    fn a_zenoh_file_that_does_not_read_is_said_without_zenoh_s_source_place() {
        let dir = tempfile::tempdir().unwrap();
        let missing = super::zenoh_file(&dir.path().join("router.json5"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("No such file"), "{missing}");
        let bad = dir.path().join("bad.json5");
        std::fs::write(&bad, "{ mode: ").unwrap();
        let said = super::zenoh_file(&bad).unwrap_err().to_string();
        assert!(!said.contains(".rs:"), "{said}");
        assert!(!said.is_empty());
    }
}
