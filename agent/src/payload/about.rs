//! `<prefix>/about`: what an agent is and runs, for `cellwatch plant check`.

use serde::{Deserialize, Serialize};

/// The schema of an agent's answer to `about`.
pub const ABOUT_SCHEMA: &str = "cellwatch.about.v1";

/// What an agent is and runs: its version, the configuration it runs (by
/// hash), its signing key and its bus certificate.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AboutPayload {
    /// [`ABOUT_SCHEMA`].
    pub schema: String,
    /// Cell id.
    pub cell: String,
    /// The agent's version (`cellwatch --version`).
    pub version: String,
    /// SHA-256 (hex) of the configuration file it runs, as read at start
    /// or at the last reload taken.
    pub config_sha256: String,
    /// Its signing key's public half (hex), as in the plant trust file.
    pub signing_key: String,
    /// The certificate it shows on the bus, when it has one.
    pub bus_certificate: Option<CertificateAbout>,
    /// When it started (RFC 3339).
    pub started: String,
    /// The version of the plant operators list it judges commands by
    /// (`null`: its operators file).
    #[serde(default)]
    pub operators_version: Option<u64>,
}

/// A certificate as `about` tells it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CertificateAbout {
    /// Its subject's common name (`agent-m01ps0004`).
    pub name: String,
    /// The end of its validity (RFC 3339).
    pub not_after: String,
    /// SHA-256 (hex) of its DER bytes.
    pub sha256: String,
}
