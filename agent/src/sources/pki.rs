//! OPC UA certificates on disk: creating an application's own key pair and
//! trusting another application's certificate.
//!
//! The layout is async-opcua's: `own/cert.der`, `private/private.pem`,
//! `trusted/`, `rejected/`. Trusting a peer means copying its certificate
//! into `trusted/` under the name the certificate store looks for.

use std::path::{Path, PathBuf};

use opcua::crypto::{CertificateStore, X509};

/// Why an OPC UA key pair or certificate cannot be made, read or trusted.
#[derive(Debug, thiserror::Error)]
pub enum PkiError {
    /// One file of the key pair is there without the other.
    #[error("{} is there without {}: restore it, or remove both to make a new pair", there.display(), missing.display())]
    HalfPair {
        /// The file that is there.
        there: PathBuf,
        /// The file that is missing.
        missing: PathBuf,
    },
    /// The OPC UA stack cannot make the key pair.
    #[error("cannot make the key pair: {0}")]
    Generate(String),
    /// The private key cannot be encoded.
    #[error("cannot encode the private key: {0}")]
    EncodeKey(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// The certificate cannot be encoded.
    #[error("cannot encode the certificate: {0}")]
    EncodeCert(#[source] opcua::crypto::X509Error),
    /// A directory or file cannot be created.
    #[error("cannot create {}: {source}", path.display())]
    Create {
        /// The directory or file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file cannot be written.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file cannot be removed.
    #[error("cannot remove {}: {source}", path.display())]
    Remove {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The private key cannot be written owner-only.
    #[error(transparent)]
    PrivateKey(#[from] crate::bus::certs::CertError),
    /// An existing private key is exposed or cannot be looked at.
    #[error(transparent)]
    Exposed(#[from] crate::bus::envelope::KeyFileError),
    /// The permissions of the private key cannot be set.
    #[error("cannot make {} the owner's only: {source}", path.display())]
    Protect {
        /// The key file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A certificate file cannot be read.
    #[error("cannot read certificate {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The bytes are no DER certificate.
    #[error("not a DER certificate: {0}")]
    NotDer(#[source] opcua::crypto::X509Error),
    /// The certificate file named cannot be trusted.
    #[error("{}: {source}", path.display())]
    Certificate {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: Box<PkiError>,
    },
}

/// The application's own certificate in a PKI directory.
pub fn own_cert(pki_dir: &Path) -> PathBuf {
    pki_dir.join("own").join("cert.der")
}

/// The application's own private key in a PKI directory.
pub fn own_key(pki_dir: &Path) -> PathBuf {
    pki_dir.join("private").join("private.pem")
}

/// An OPC UA server's security as every server of this project has it:
/// its key pair in `pki_dir` (made now if it has none, the private key
/// owner-only from the start: [`own_key_pair`]), client certificates
/// trusted only from `trusted/`, listening on `addr` with its endpoints at
/// `/`.
pub fn served_from(
    builder: opcua::server::ServerBuilder,
    pki_dir: &Path,
    addr: std::net::SocketAddr,
) -> opcua::server::ServerBuilder {
    let (name, uri) = (
        builder.config().application_name.clone(),
        builder.config().application_uri.clone(),
    );
    // Not made: the stack makes none either (it would write through a
    // link planted at the key's name); the server says it has no key.
    let made = own_key_pair(pki_dir, &name, &uri)
        .inspect_err(|e| tracing::error!(pki = %pki_dir.display(), error = %e, "cannot make the server's key pair"))
        .is_ok();
    builder
        .create_sample_keypair(made)
        .pki_dir(pki_dir)
        .certificate_path("own/cert.der")
        .private_key_path("private/private.pem")
        .trust_client_certs(false)
        .host(addr.ip().to_string())
        .port(addr.port())
        .discovery_urls(vec!["/".to_owned()])
}

/// Makes the application's key pair in `pki_dir` when it has neither
/// certificate nor key, as the OPC UA stack would (RSA 2048, the
/// certificate named and addressed after `name` and `uri`), but with the
/// private key created owner-only (0600, never through a symbolic link or
/// over a file) and in a `private/` directory only its owner may enter:
/// the stack writes it with the process's umask. Returns whether it made
/// them.
///
/// # Errors
/// The files cannot be written, or one of the two is there without the
/// other.
pub fn own_key_pair(pki_dir: &Path, name: &str, uri: &str) -> Result<bool, PkiError> {
    let (cert, key) = (own_cert(pki_dir), own_key(pki_dir));
    match (
        cert.symlink_metadata().is_ok(),
        key.symlink_metadata().is_ok(),
    ) {
        (true, true) => return Ok(false),
        (false, false) => {}
        (has_cert, _) => {
            let (there, missing) = if has_cert {
                (&cert, &key)
            } else {
                (&key, &cert)
            };
            return Err(PkiError::HalfPair {
                there: there.clone(),
                missing: missing.clone(),
            });
        }
    }
    let description = opcua::types::ApplicationDescription {
        application_name: opcua::types::LocalizedText::new("", name),
        application_uri: uri.into(),
        ..Default::default()
    };
    let (x509, pkey) = X509::cert_and_pkey(&opcua::crypto::X509Data::from(description))
        .map_err(PkiError::Generate)?;
    let der = pkey.to_der().map_err(|e| PkiError::EncodeKey(e.into()))?;
    let private = key.parent().unwrap_or(pki_dir);
    let mut dirs = std::fs::DirBuilder::new();
    dirs.recursive(true);
    #[cfg(unix)]
    std::os::unix::fs::DirBuilderExt::mode(&mut dirs, 0o700);
    dirs.create(private).map_err(|source| PkiError::Create {
        path: private.to_path_buf(),
        source,
    })?;
    crate::bus::certs::write_private(&key, &pem("PRIVATE KEY", der.as_bytes()))?;
    let cert_der = x509.to_der().map_err(PkiError::EncodeCert)?;
    let own = cert.parent().unwrap_or(pki_dir);
    std::fs::create_dir_all(own).map_err(|source| PkiError::Create {
        path: own.to_path_buf(),
        source,
    })?;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    std::io::Write::write_all(
        &mut options.open(&cert).map_err(|source| PkiError::Create {
            path: cert.clone(),
            source,
        })?,
        &cert_der,
    )
    .map_err(|source| PkiError::Write {
        path: cert.clone(),
        source,
    })?;
    Ok(true)
}

/// `der` in PEM under `label` (RFC 7468: base64, 64 characters a line).
fn pem(label: &str, der: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut text = String::with_capacity(der.len() * 4 / 3 + 4);
    for chunk in der.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                text.push(ALPHABET[(n >> (18 - 6 * i)) as usize & 63] as char);
            } else {
                text.push('=');
            }
        }
    }
    let mut out = format!("-----BEGIN {label}-----\n");
    for line in text.as_bytes().chunks(64) {
        out.push_str(std::str::from_utf8(line).unwrap_or_default());
        out.push('\n');
    }
    out.push_str(&format!("-----END {label}-----\n"));
    out
}

/// Makes the private key that the OPC UA stack has just created in
/// `pki_dir` (it writes it with the process's umask, often readable by
/// everyone, unless [`own_key_pair`] made it first) readable by its owner
/// only, and refuses an existing one that others may read. `existed`: whether the key was there before the stack
/// ran.
///
/// # Errors
/// An existing key readable by others (the message names the file), or
/// the permissions cannot be set.
pub fn protect_own_key(pki_dir: &Path, existed: bool) -> Result<(), PkiError> {
    let key = own_key(pki_dir);
    if existed {
        return Ok(crate::bus::envelope::check_private(&key)?);
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if key.exists() {
            std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).map_err(
                |source| PkiError::Protect {
                    path: key.clone(),
                    source,
                },
            )?;
        }
    }
    Ok(())
}

/// Copies the certificate at `cert` into `pki_dir/trusted/`, and takes it
/// out of `pki_dir/rejected/` if an earlier refused connection left it
/// there (the certificate store takes a certificate found in `rejected/`
/// as untrusted, whatever `trusted/` holds).
///
/// # Errors
/// The certificate cannot be read or parsed, or the copy fails.
pub fn trust(cert: &Path, pki_dir: &Path) -> Result<PathBuf, PkiError> {
    let bytes = std::fs::read(cert).map_err(|source| PkiError::Read {
        path: cert.to_path_buf(),
        source,
    })?;
    trust_der(&bytes, pki_dir).map_err(|e| PkiError::Certificate {
        path: cert.to_path_buf(),
        source: Box::new(e),
    })
}

/// [`trust`] for a certificate in hand (DER).
///
/// # Errors
/// The bytes are no certificate, or the copy fails.
pub fn trust_der(bytes: &[u8], pki_dir: &Path) -> Result<PathBuf, PkiError> {
    let x509 = X509::from_der(bytes).map_err(PkiError::NotDer)?;
    let dir = pki_dir.join("trusted");
    std::fs::create_dir_all(&dir).map_err(|source| PkiError::Create {
        path: dir.clone(),
        source,
    })?;
    let target = dir.join(CertificateStore::cert_file_name(&x509));
    std::fs::write(&target, bytes).map_err(|source| PkiError::Write {
        path: target.clone(),
        source,
    })?;
    let rejected = pki_dir
        .join("rejected")
        .join(CertificateStore::cert_file_name(&x509));
    match std::fs::remove_file(&rejected) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(source) => {
            return Err(PkiError::Remove {
                path: rejected,
                source,
            })
        }
    }
    Ok(target)
}

/// What a person checks before trusting a certificate.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertificateFacts {
    /// `CN=…/O=…`, escaped ([`crate::operator::escaped`]).
    pub subject: String,
    /// Valid from, RFC 3339.
    pub not_before: String,
    /// Valid until, RFC 3339.
    pub not_after: String,
    /// Whether it is valid now.
    pub valid_now: bool,
    /// SHA-256 of the DER, `AB:CD:…`.
    pub sha256: String,
    /// SHA-1 of the DER, as OPC UA servers list certificates (thumbprint).
    pub thumbprint: String,
}

impl CertificateFacts {
    /// The facts of the DER certificate `bytes`, validity judged at `now`
    /// (ms since the epoch).
    ///
    /// # Errors
    /// The bytes are no certificate.
    pub fn of(bytes: &[u8], now: u64) -> Result<CertificateFacts, PkiError> {
        use sha2::Digest;
        let x509 = X509::from_der(bytes).map_err(PkiError::NotDer)?;
        let colons = |b: &[u8]| {
            b.iter()
                .map(|x| format!("{x:02X}"))
                .collect::<Vec<_>>()
                .join(":")
        };
        let from = x509.not_before().ok();
        let until = x509.not_after().ok();
        let now = chrono::DateTime::from_timestamp_millis(now as i64).unwrap_or_default();
        let when = |t: Option<chrono::DateTime<chrono::Utc>>| {
            t.map_or_else(
                || "unreadable".into(),
                |t| t.to_rfc3339_opts(chrono::SecondsFormat::Secs, true),
            )
        };
        Ok(CertificateFacts {
            // Whoever made the certificate wrote it: escaped, so that it
            // prints on one line of its own (no line drawn after it).
            subject: crate::operator::escaped(&x509.subject_name()).into_owned(),
            not_before: when(from),
            not_after: when(until),
            valid_now: from.is_some_and(|f| f <= now) && until.is_some_and(|u| now <= u),
            sha256: colons(&sha2::Sha256::digest(bytes)),
            thumbprint: x509.thumbprint().as_hex_string().to_ascii_uppercase(),
        })
    }
}

/// Whether `pki_dir/trusted/` holds exactly the DER certificate `bytes`
/// (under the name the certificate store looks for), and `rejected/` does
/// not (the store takes a rejected certificate as untrusted).
pub fn is_trusted(bytes: &[u8], pki_dir: &Path) -> bool {
    let Ok(x509) = X509::from_der(bytes) else {
        return false;
    };
    let name = CertificateStore::cert_file_name(&x509);
    let trusted = std::fs::read(pki_dir.join("trusted").join(&name)).is_ok_and(|b| b == bytes);
    trusted && !pki_dir.join("rejected").join(&name).exists()
}

/// Leaves the DER certificate `bytes` in `pki_dir/rejected/` for an engineer
/// to review, as the certificate store does with one it refuses. Best
/// effort: a failure is logged.
pub fn reject(bytes: &[u8], pki_dir: &Path) {
    let Ok(x509) = X509::from_der(bytes) else {
        return;
    };
    if let Err(e) = CertificateStore::new(pki_dir).store_rejected_cert(&x509) {
        tracing::warn!(pki = %pki_dir.display(), error = %e, "cannot keep the refused server certificate for review");
    }
}

/// Why the server certificate of `endpoint` is not trusted, with its
/// fingerprint and the command that trusts it; `None` when it is (or the
/// connection has no security).
pub fn untrusted(
    config: &crate::sources::opcua::config::OpcUaConfig,
    endpoint: &opcua::types::EndpointDescription,
) -> Option<String> {
    if config.policy == crate::sources::opcua::config::SecurityPolicy::None {
        return None;
    }
    let der = endpoint.server_certificate.as_ref();
    if is_trusted(der, &config.pki_dir) {
        return None;
    }
    let facts = CertificateFacts::of(der, crate::clock::now_ms()).map_or_else(
        |e| format!("its certificate is unreadable: {e}"),
        |f| format!("{}, SHA-256 {}", f.subject, f.sha256),
    );
    Some(format!(
        "the server's certificate is not trusted ({facts}): check it and trust it with `cellwatch trust-server {} --pki-dir {}`",
        config.endpoint,
        config.pki_dir.display()
    ))
}

#[cfg(test)]
mod tests {
    #[test]
    fn pem_is_base64_in_lines_of_64() {
        assert_eq!(
            super::pem("X", b"Man"),
            "-----BEGIN X-----\nTWFu\n-----END X-----\n"
        );
        assert_eq!(
            super::pem("X", b"Ma"),
            "-----BEGIN X-----\nTWE=\n-----END X-----\n"
        );
        assert_eq!(
            super::pem("X", b"M"),
            "-----BEGIN X-----\nTQ==\n-----END X-----\n"
        );
        let long = super::pem("X", &[0u8; 60]);
        assert_eq!(long.lines().nth(1).unwrap().len(), 64);
        assert_eq!(long.lines().nth(2).unwrap(), "AAAAAAAAAAAAAAAA");
    }
}
