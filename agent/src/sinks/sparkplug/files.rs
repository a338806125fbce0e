//! The files the edge node reads to reach its broker: the password file
//! (owner-only) and the TLS CA, client certificate and key. Read when the
//! session is made and by `cellwatch validate`, which says what is wrong
//! with them before the agent runs.

use std::path::Path;

use super::config::{SparkplugConfig, SparkplugTls};
use super::shared::SparkplugError;

/// Reads every file `config` names, as the session will.
///
/// # Errors
/// A file cannot be read, is readable by others (a key, the password) or
/// is not what it should be.
pub(crate) fn check(config: &SparkplugConfig) -> Result<(), SparkplugError> {
    if let Some(f) = config
        .credentials
        .as_ref()
        .and_then(|c| c.password_file.as_ref())
    {
        password(f)?;
    }
    if config.broker.secure {
        tls(config.tls.as_ref())?;
    }
    Ok(())
}

/// The first line of the password file (owner-only).
pub(super) fn password(path: &Path) -> Result<String, SparkplugError> {
    crate::bus::envelope::check_private(path)?;
    let text = std::fs::read_to_string(path).map_err(|source| SparkplugError::Password {
        path: path.display().to_string(),
        source,
    })?;
    Ok(text.lines().next().unwrap_or_default().to_string())
}

/// TLS trusting `tls`'s CA, presenting its client certificate if any.
pub(super) fn tls(
    tls: Option<&SparkplugTls>,
) -> Result<tokio_rustls::rustls::ClientConfig, SparkplugError> {
    let client = tls.and_then(|t| t.client.as_ref());
    Ok(crate::bus::client_tls::client_config(
        tls.map(|t| t.ca.as_path()),
        client.map(|(cert, key)| (cert.as_path(), key.as_path())),
    )?)
}
