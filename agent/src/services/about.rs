//! `<prefix>/about`: what the agent is and runs (its version, the hash of
//! the configuration it runs, its signing key, its bus certificate), for
//! `cellwatch plant check`. Kept current by the agent: a reload taken
//! changes the configuration's hash.

use std::path::Path;

use crate::bus::certs::facts;
use crate::bus::envelope::AgentKey;
use crate::clock::{now_ms, rfc3339};
use crate::payload::{AboutPayload, CertificateAbout, ABOUT_SCHEMA};

/// What the agent of cell `cell` says of itself: it runs a configuration
/// hashing to `config_sha256`, is on the bus with the certificate at
/// `bus_certificate` (if TLS), and signs with `key`.
pub(crate) fn about(
    cell: &str,
    config_sha256: &str,
    bus_certificate: Option<&Path>,
    key: &AgentKey,
) -> AboutPayload {
    let bus_certificate = bus_certificate.and_then(|cert| {
        let pem = std::fs::read_to_string(cert).ok()?;
        let f = facts(&pem)
            .map_err(|e| tracing::warn!(file = %cert.display(), "bus certificate: {e}"))
            .ok()?;
        Some(CertificateAbout {
            name: f.name,
            not_after: rfc3339(f.not_after_ms),
            sha256: f.sha256,
        })
    });
    AboutPayload {
        schema: ABOUT_SCHEMA.into(),
        cell: cell.to_string(),
        version: env!("CARGO_PKG_VERSION").into(),
        config_sha256: config_sha256.to_string(),
        signing_key: key.public_hex(),
        bus_certificate,
        started: rfc3339(now_ms()),
        operators_version: None,
    }
}
