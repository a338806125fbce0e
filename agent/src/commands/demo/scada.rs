//! The demo's SCADA side: the engraving machine's alarms served as OPC UA
//! Alarms & Conditions ([SCADA over OPC UA](../../../../docs/how-to/scada.md)),
//! with one user, `demo`, acting as operator `demo`, whose password is made
//! on the first run and kept in the state directory.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use super::super::Failure;
use crate::config::{AlarmServerConfig, CellConfig};
use crate::services::alarm_server::users::hash_password;

/// The file holding user `demo`'s password, readable by its owner only.
pub(super) const PASSWORD_FILE: &str = "opcua-demo-password";

/// Serves `c`'s alarms on `listen`: the server's PKI in
/// `state/alarm-server-pki`, its users in `state/opcua-users.toml` (made
/// once, with the password file, and kept across runs). Returns the
/// password file's path.
pub(super) fn serve(
    c: &mut CellConfig,
    state: &Path,
    listen: SocketAddr,
) -> Result<PathBuf, Failure> {
    let password_file = state.join(PASSWORD_FILE);
    let users_file = state.join("opcua-users.toml");
    if !password_file.exists() || !users_file.exists() {
        let password = hex::encode(rand::random::<[u8; 12]>());
        let _ = std::fs::remove_file(&password_file);
        super::super::keygen::write_private(&password_file, &format!("{password}\n"))?;
        let text = format!(
            "# The demo's OPC UA users (cellwatch hash-password makes a hash); the password is in {PASSWORD_FILE}.\n\
             [users.demo]\noperator = \"demo\"\npassword_hash = \"{}\"\n",
            hash_password(&password)
        );
        std::fs::write(&users_file, text)
            .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", users_file.display())))?;
    }
    c.alarm_server = Some(AlarmServerConfig {
        listen,
        pki_dir: state.join("alarm-server-pki"),
        users_file,
    });
    Ok(password_file)
}

#[cfg(test)]
mod tests {
    use super::serve;
    use crate::services::alarm_server::users::Users;

    #[test]
    fn the_demo_user_is_made_once_and_its_password_is_its_hash() {
        let state = tempfile::tempdir().unwrap();
        let demo = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/demo.toml");
        let mut c = crate::config::load(std::path::Path::new(demo)).unwrap();
        let listen = "127.0.0.1:0".parse().unwrap();
        let file = serve(&mut c, state.path(), listen).unwrap();
        let password = std::fs::read_to_string(&file).unwrap();
        let server = c.alarm_server.clone().unwrap();
        assert_eq!(server.listen, listen);
        let users = Users::load(&server.users_file).unwrap();
        assert_eq!(users.operator("demo").as_deref(), Some("demo"));
        assert!(users.verify("demo", password.trim()));
        assert!(!users.verify("demo", "not-the-password"));
        // A second run keeps both.
        serve(&mut c, state.path(), listen).unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), password);
        assert!(Users::load(&server.users_file)
            .unwrap()
            .verify("demo", password.trim()));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&file).unwrap().permissions().mode();
            assert_eq!(mode & 0o077, 0, "{mode:o}");
        }
    }
}
