//! A TLS client's configuration from PEM files, as the agent's HTTPS and
//! MQTT clients make it (Alertmanager, the Sparkplug broker): the CA it
//! trusts and, if given, the certificate it presents with its owner-only
//! key; TLS 1.2 and 1.3 with ring's algorithms.

use std::path::Path;
use std::sync::Arc;

use tokio_rustls::rustls;
use tokio_rustls::rustls::pki_types::pem::PemObject;
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};

use super::envelope::{check_private, KeyFileError};

/// Why a TLS client cannot be made from the files.
#[derive(Debug, thiserror::Error)]
pub enum ClientTlsError {
    /// A file cannot be read or holds no usable certificate or key.
    #[error("{path}: {why}")]
    File {
        /// The file.
        path: String,
        /// Why.
        why: String,
    },
    /// The key file is readable by others, or cannot be looked at.
    #[error(transparent)]
    Private(#[from] KeyFileError),
    /// rustls refused the certificate and key together.
    #[error(transparent)]
    Rustls(#[from] rustls::Error),
}

/// A client trusting the certificates in `ca` (none: it trusts nothing, so
/// only a caller that never dials TLS passes none), presenting `client`'s
/// certificate chain and key if given.
///
/// # Errors
/// A file cannot be read, holds no certificate, or the key is readable by
/// others or does not go with the certificate.
pub(crate) fn client_config(
    ca: Option<&Path>,
    client: Option<(&Path, &Path)>,
) -> Result<rustls::ClientConfig, ClientTlsError> {
    let bad = |path: &Path, why: String| ClientTlsError::File {
        path: path.display().to_string(),
        why,
    };
    let mut roots = rustls::RootCertStore::empty();
    if let Some(ca) = ca {
        let cas: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(ca)
            .and_then(Iterator::collect)
            .map_err(|e| bad(ca, e.to_string()))?;
        if cas.is_empty() {
            return Err(bad(ca, "no certificate in the file".into()));
        }
        for cert in cas {
            roots.add(cert).map_err(|e| bad(ca, e.to_string()))?;
        }
    }
    let builder = rustls::ClientConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()?
    .with_root_certificates(roots);
    Ok(match client {
        Some((cert, key)) => {
            check_private(key)?;
            let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
                .and_then(Iterator::collect)
                .map_err(|e| bad(cert, e.to_string()))?;
            let key = PrivateKeyDer::from_pem_file(key).map_err(|e| bad(key, e.to_string()))?;
            builder.with_client_auth_cert(chain, key)?
        }
        None => builder.with_no_client_auth(),
    })
}
