//! Certificates for the Zenoh bus: a plant CA and certificates issued from
//! it (X.509, ECDSA P-256) for agents, routers and operators. Zenoh's own
//! TLS uses them for mutual authentication; its access control matches
//! their common names.

use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};

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
pub fn make_ca(dir: &Path, name: &str) -> Result<bool, String> {
    let (cert_path, key_path) = ca_files(dir);
    if cert_path.exists() && key_path.exists() {
        return Ok(false);
    }
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let mut params = CertificateParams::new(Vec::<String>::new()).map_err(runtime)?;
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.distinguished_name = dn(name);
    params.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    params.not_before = rcgen::date_time_ymd(2024, 1, 1);
    params.not_after = rcgen::date_time_ymd(2044, 1, 1);
    let key = KeyPair::generate().map_err(runtime)?;
    let cert = params.self_signed(&key).map_err(runtime)?;
    write_private(&key_path, &key.serialize_pem())?;
    write_public(&cert_path, &cert.pem())?;
    Ok(true)
}

/// Issues `name` (its common name, which the bus's access control
/// matches) from the CA in `dir`, valid for `hosts` as server names.
///
/// # Errors
/// No CA in `dir`, an existing certificate of that name, or a bad host.
pub fn issue(dir: &Path, name: &str, hosts: &[String]) -> Result<(PathBuf, PathBuf), String> {
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
) -> Result<(), String> {
    let (ca_cert, ca_key) = ca_files(dir);
    let read = |p: &Path| {
        std::fs::read_to_string(p).map_err(|e| {
            format!(
                "cannot read {}: {e} (make the CA first: cellwatch pki ca --dir {})",
                p.display(),
                dir.display()
            )
        })
    };
    let ca_key = KeyPair::from_pem(&read(&ca_key)?)
        .map_err(|e| format!("{}: {e}", ca_files(dir).1.display()))?;
    let issuer = Issuer::from_ca_cert_pem(&read(&ca_cert)?, ca_key)
        .map_err(|e| format!("{}: {e}", ca_files(dir).0.display()))?;
    let (cert_path, key_path) = to;
    if cert_path.exists() || key_path.exists() {
        return Err(format!("{} exists; not overwritten", cert_path.display()));
    }
    let mut params =
        CertificateParams::new(hosts.to_vec()).map_err(|e| format!("host names {hosts:?}: {e}"))?;
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
    let key = KeyPair::generate().map_err(runtime)?;
    let cert = params.signed_by(&key, &issuer).map_err(runtime)?;
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

fn runtime(e: rcgen::Error) -> String {
    format!("certificate: {e}")
}

fn write_public(path: &Path, text: &str) -> Result<(), String> {
    std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Creates `path` readable by its owner only; an existing file is kept.
///
/// # Errors
/// The file exists or cannot be written.
pub fn write_private(path: &Path, text: &str) -> Result<(), String> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let mut file = options.open(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            format!("{} exists; not overwritten", path.display())
        } else {
            format!("cannot create {}: {e}", path.display())
        }
    })?;
    file.write_all(text.as_bytes())
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
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
pub fn facts(pem: &str) -> Result<CertFacts, String> {
    use sha2::{Digest, Sha256};
    let (_, block) = x509_parser::pem::parse_x509_pem(pem.as_bytes())
        .map_err(|e| format!("no PEM certificate: {e}"))?;
    let cert = block
        .parse_x509()
        .map_err(|e| format!("not an X.509 certificate: {e}"))?;
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
