//! The files the edge node reads to reach its broker: the password file
//! (owner-only) and the TLS CA, client certificate and key. Read when the
//! session is made and by `cellwatch validate`, which says what is wrong
//! with them before the agent runs.

use std::path::Path;
use std::sync::Arc;

use super::config::{SparkplugConfig, SparkplugTls};
use super::shared::SparkplugError;

/// Reads every file `config` names, as the session will.
///
/// # Errors
/// A file cannot be read, is readable by others (a key, the password) or
/// is not what it should be.
pub fn check(config: &SparkplugConfig) -> Result<(), SparkplugError> {
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
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let bad = |path: &Path, why: String| SparkplugError::Tls {
        path: path.display().to_string(),
        why,
    };
    let mut roots = rustls::RootCertStore::empty();
    let mut identity = None;
    if let Some(t) = tls {
        let cas: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&t.ca)
            .and_then(Iterator::collect)
            .map_err(|e| bad(&t.ca, e.to_string()))?;
        if cas.is_empty() {
            return Err(bad(&t.ca, "no certificate in the file".into()));
        }
        for ca in cas {
            roots.add(ca).map_err(|e| bad(&t.ca, e.to_string()))?;
        }
        if let Some((cert, key)) = &t.client {
            crate::bus::envelope::check_private(key)?;
            let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
                .and_then(Iterator::collect)
                .map_err(|e| bad(cert, e.to_string()))?;
            let key = PrivateKeyDer::from_pem_file(key).map_err(|e| bad(key, e.to_string()))?;
            identity = Some((chain, key));
        }
    }
    let builder = rustls::ClientConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .map_err(|e| SparkplugError::TlsConfig(e.to_string()))?
    .with_root_certificates(roots);
    match identity {
        Some((chain, key)) => builder
            .with_client_auth_cert(chain, key)
            .map_err(|e| SparkplugError::TlsConfig(e.to_string())),
        None => Ok(builder.with_no_client_auth()),
    }
}
