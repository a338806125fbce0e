//! Certificates for the Zenoh bus: a plant CA and certificates issued from
//! it (X.509, ECDSA P-256) for agents, routers and operators. Zenoh's own
//! TLS uses them for mutual authentication; its access control matches
//! their common names.

use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};

/// Why a certificate or key file of the bus cannot be made or read.
#[derive(Debug, thiserror::Error)]
pub enum CertError {
    /// A directory cannot be created.
    #[error("cannot create {}: {source}", path.display())]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A file cannot be created.
    #[error("cannot create {}: {source}", path.display())]
    Create {
        /// The file.
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
    /// A file that is never overwritten is there already.
    #[error("{} exists; not overwritten", path.display())]
    Exists {
        /// The file.
        path: PathBuf,
    },
    /// The CA's certificate or key cannot be read.
    #[error("cannot read {}: {source} (make the CA first: cellwatch pki ca --dir {})", path.display(), dir.display())]
    NoCa {
        /// The file.
        path: PathBuf,
        /// The CA's directory.
        dir: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The CA's certificate or key does not parse.
    #[error("{}: {source}", path.display())]
    BadCa {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: rcgen::Error,
    },
    /// Host names a certificate cannot carry.
    #[error("host names {hosts:?}: {source}")]
    Hosts {
        /// The names.
        hosts: Vec<String>,
        /// Why.
        #[source]
        source: rcgen::Error,
    },
    /// The key or certificate cannot be made.
    #[error("certificate: {0}")]
    Make(#[source] rcgen::Error),
    /// No PEM certificate in the text.
    #[error("no PEM certificate: {0}")]
    Pem(#[source] x509_parser::nom::Err<x509_parser::error::PEMError>),
    /// The PEM block is no X.509 certificate.
    #[error("not an X.509 certificate: {0}")]
    X509(#[source] x509_parser::nom::Err<x509_parser::error::X509Error>),
}

/// The CA's files in `dir`.
pub fn ca_files(dir: &Path) -> (PathBuf, PathBuf) {
    (dir.join("ca.pem"), dir.join("ca.key"))
}

/// A certificate's files in `dir`.
pub fn cert_files(dir: &Path, name: &str) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("{name}.pem")),
        dir.join(format!("{name}.key")),
    )
}

/// Creates a CA in `dir` (ca.pem, ca.key); an existing one is kept.
///
/// # Errors
/// The files cannot be written or the certificate made.
pub fn make_ca(dir: &Path, name: &str) -> Result<bool, CertError> {
    let (cert_path, key_path) = ca_files(dir);
    if cert_path.exists() && key_path.exists() {
        return Ok(false);
    }
    std::fs::create_dir_all(dir).map_err(|source| CertError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut params = CertificateParams::new(Vec::<String>::new()).map_err(CertError::Make)?;
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.distinguished_name = dn(name);
    params.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    params.not_before = rcgen::date_time_ymd(2024, 1, 1);
    params.not_after = rcgen::date_time_ymd(2044, 1, 1);
    let key = KeyPair::generate().map_err(CertError::Make)?;
    let cert = params.self_signed(&key).map_err(CertError::Make)?;
    write_private(&key_path, &key.serialize_pem())?;
    write_public(&cert_path, &cert.pem())?;
    Ok(true)
}

/// Issues `name` (its common name, which the bus's access control
/// matches) from the CA in `dir`, valid for `hosts` as server names.
///
/// # Errors
/// No CA in `dir`, an existing certificate of that name, or a bad host.
pub fn issue(dir: &Path, name: &str, hosts: &[String]) -> Result<(PathBuf, PathBuf), CertError> {
    let (cert_path, key_path) = cert_files(dir, name);
    issue_to(dir, name, hosts, (&cert_path, &key_path))?;
    Ok((cert_path, key_path))
}

/// Issues `name` from the CA in `dir` as [`issue`] does, the certificate
/// and its key written to `to` (the key owner-only).
///
/// # Errors
/// No CA in `dir`, an existing certificate or key there, or a bad host.
pub fn issue_to(
    dir: &Path,
    name: &str,
    hosts: &[String],
    to: (&Path, &Path),
) -> Result<(), CertError> {
    let (ca_cert, ca_key) = ca_files(dir);
    let read = |p: &Path| {
        std::fs::read_to_string(p).map_err(|source| CertError::NoCa {
            path: p.to_path_buf(),
            dir: dir.to_path_buf(),
            source,
        })
    };
    let bad = |path: &Path| {
        let path = path.to_path_buf();
        move |source| CertError::BadCa { path, source }
    };
    let ca_key = KeyPair::from_pem(&read(&ca_key)?).map_err(bad(&ca_key))?;
    let issuer = Issuer::from_ca_cert_pem(&read(&ca_cert)?, ca_key).map_err(bad(&ca_cert))?;
    let (cert_path, key_path) = to;
    if cert_path.exists() || key_path.exists() {
        return Err(CertError::Exists {
            path: cert_path.to_path_buf(),
        });
    }
    let mut params = CertificateParams::new(hosts.to_vec()).map_err(|source| CertError::Hosts {
        hosts: hosts.to_vec(),
        source,
    })?;
    params.distinguished_name = dn(name);
    params.is_ca = IsCa::ExplicitNoCa;
    params.key_usages = vec![
        KeyUsagePurpose::DigitalSignature,
        KeyUsagePurpose::KeyEncipherment,
    ];
    // One certificate both listens and connects (a peer does both).
    params.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    params.not_before = rcgen::date_time_ymd(2024, 1, 1);
    params.not_after = rcgen::date_time_ymd(2036, 1, 1);
    let key = KeyPair::generate().map_err(CertError::Make)?;
    let cert = params.signed_by(&key, &issuer).map_err(CertError::Make)?;
    write_private(key_path, &key.serialize_pem())?;
    write_public(cert_path, &cert.pem())?;
    Ok(())
}

fn dn(name: &str) -> DistinguishedName {
    let mut dn = DistinguishedName::new();
    dn.push(DnType::CommonName, name);
    dn.push(DnType::OrganizationName, "cellwatch");
    dn
}

fn write_public(path: &Path, text: &str) -> Result<(), CertError> {
    std::fs::write(path, text).map_err(|source| CertError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Creates `path` readable by its owner only; an existing file is kept.
///
/// # Errors
/// The file exists or cannot be written.
pub fn write_private(path: &Path, text: &str) -> Result<(), CertError> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let path_buf = || path.to_path_buf();
    let mut file = options.open(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::AlreadyExists {
            CertError::Exists { path: path_buf() }
        } else {
            CertError::Create {
                path: path_buf(),
                source,
            }
        }
    })?;
    file.write_all(text.as_bytes())
        .map_err(|source| CertError::Write {
            path: path_buf(),
            source,
        })
}

/// What a certificate says of itself: whose, until when, which.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertFacts {
    /// Its subject's common name.
    pub name: String,
    /// The end of its validity, ms since the Unix epoch.
    pub not_after_ms: u64,
    /// SHA-256 (hex) of its DER bytes.
    pub sha256: String,
}

/// The facts of the first certificate in PEM text `pem`.
///
/// # Errors
/// No certificate in it, or one that does not parse.
pub fn facts(pem: &str) -> Result<CertFacts, CertError> {
    use sha2::{Digest, Sha256};
    let (_, block) = x509_parser::pem::parse_x509_pem(pem.as_bytes()).map_err(CertError::Pem)?;
    let cert = block.parse_x509().map_err(CertError::X509)?;
    let name = cert
        .subject()
        .iter_common_name()
        .next()
        .and_then(|n| n.as_str().ok())
        .unwrap_or_default()
        .to_string();
    let seconds = cert.validity().not_after.timestamp();
    Ok(CertFacts {
        name,
        not_after_ms: u64::try_from(seconds).unwrap_or(0).saturating_mul(1000),
        sha256: hex::encode(Sha256::digest(&block.contents)),
    })
}
