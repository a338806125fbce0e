//! `<prefix>/about`: what the agent is and runs (its version, the hash of
//! the configuration it runs, its signing key, its bus certificate), for
//! `cellwatch plant check`. Kept current by the agent: a reload taken
//! changes the configuration's hash.

use crate::bus::certs::facts;
use crate::bus::envelope::AgentKey;
use crate::clock::{now_ms, rfc3339};
use crate::config::CellConfig;
use crate::payload::{AboutPayload, CertificateAbout, ABOUT_SCHEMA};

/// What the agent of `config`, signing with `key`, says of itself.
pub fn about(config: &CellConfig, key: &AgentKey) -> AboutPayload {
    let bus_certificate = config.zenoh.tls.as_ref().and_then(|tls| {
        let pem = std::fs::read_to_string(&tls.cert).ok()?;
        let f = facts(&pem)
            .map_err(|e| tracing::warn!(file = %tls.cert.display(), "bus certificate: {e}"))
            .ok()?;
        Some(CertificateAbout {
            name: f.name,
            not_after: rfc3339(f.not_after_ms),
            sha256: f.sha256,
        })
    });
    AboutPayload {
        schema: ABOUT_SCHEMA.into(),
        cell: config.cell.clone(),
        version: env!("CARGO_PKG_VERSION").into(),
        config_sha256: config.source_sha256.clone(),
        signing_key: key.public_hex(),
        bus_certificate,
        started: rfc3339(now_ms()),
        operators_version: None,
    }
}
