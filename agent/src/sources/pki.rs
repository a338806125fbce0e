//! OPC UA certificates on disk: creating an application's own key pair and
//! trusting another application's certificate.
//!
//! The layout is async-opcua's: `own/cert.der`, `private/private.pem`,
//! `trusted/`, `rejected/`. Trusting a peer means copying its certificate
//! into `trusted/` under the name the certificate store looks for.

use std::path::{Path, PathBuf};

use opcua::crypto::{CertificateStore, X509};

/// The application's own certificate in a PKI directory.
pub fn own_cert(pki_dir: &Path) -> PathBuf {
    pki_dir.join("own").join("cert.der")
}

/// The application's own private key in a PKI directory.
pub fn own_key(pki_dir: &Path) -> PathBuf {
    pki_dir.join("private").join("private.pem")
}

/// Makes the private key that the OPC UA stack has just created in
/// `pki_dir` (it writes it with the process's umask, often readable by
/// everyone) readable by its owner only, and refuses an existing one that
/// others may read. `existed`: whether the key was there before the stack
/// ran.
///
/// # Errors
/// An existing key readable by others (the message names the file), or
/// the permissions cannot be set.
pub fn protect_own_key(pki_dir: &Path, existed: bool) -> Result<(), String> {
    let key = own_key(pki_dir);
    if existed {
        return crate::bus::envelope::check_private(&key).map_err(|e| e.to_string());
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if key.exists() {
            std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600))
                .map_err(|e| format!("cannot make {} the owner's only: {e}", key.display()))?;
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
pub fn trust(cert: &Path, pki_dir: &Path) -> Result<PathBuf, String> {
    let bytes = std::fs::read(cert)
        .map_err(|e| format!("cannot read certificate {}: {e}", cert.display()))?;
    let x509 = X509::from_der(&bytes)
        .map_err(|e| format!("{} is not a DER certificate: {e}", cert.display()))?;
    let dir = pki_dir.join("trusted");
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let target = dir.join(CertificateStore::cert_file_name(&x509));
    std::fs::write(&target, &bytes)
        .map_err(|e| format!("cannot write {}: {e}", target.display()))?;
    let rejected = pki_dir
        .join("rejected")
        .join(CertificateStore::cert_file_name(&x509));
    match std::fs::remove_file(&rejected) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(format!("cannot remove {}: {e}", rejected.display())),
    }
    Ok(target)
}
