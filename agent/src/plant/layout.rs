//! Where every file of the plant goes: on its host (absolute paths, as
//! the configurations name them) and in the plant's folder, where each
//! host's files are kept under `hosts/<host>/` as they are to be copied
//! (`hosts/cnc-4/etc/cellwatch/m01ps0004.toml` is
//! `/etc/cellwatch/m01ps0004.toml` on `cnc-4`).

use std::path::{Path, PathBuf};

use super::inventory::Inventory;

/// The paths of one plant.
pub struct Layout {
    dir: PathBuf,
    etc: String,
    state: String,
}

/// `path` (absolute on a host) under `base`.
fn under(base: &Path, path: &str) -> PathBuf {
    base.join(path.trim_start_matches('/'))
}

impl Layout {
    /// The layout of `inventory`'s plant.
    pub fn of(inventory: &Inventory) -> Layout {
        Layout {
            dir: inventory.dir.clone(),
            etc: inventory.etc.clone(),
            state: inventory.state.clone(),
        }
    }

    /// The plant's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The plant CA's folder (its private key never leaves it).
    pub fn ca_dir(&self) -> PathBuf {
        self.dir.join("ca")
    }

    /// The plant administrator's bus certificate and key: `plant check`
    /// and `plant publish` join the bus with it.
    pub fn admin_cert(&self) -> (PathBuf, PathBuf) {
        let dir = self.dir.join("admin");
        (dir.join("plant-admin.pem"), dir.join("plant-admin.key"))
    }

    /// The plant administrator's signing key (the operators list's), and
    /// its public half as the agents' configurations name it.
    pub fn admin_signing(&self) -> (PathBuf, PathBuf) {
        let dir = self.dir.join("admin");
        (
            dir.join("plant-admin.signing.key"),
            dir.join("plant-admin.pub"),
        )
    }

    /// The signed plant operators list, as `plant publish` puts it.
    pub fn operators_list(&self) -> PathBuf {
        self.dir.join("operators.signed.json")
    }

    /// The public key cell `id`'s agent is being rotated from, while the
    /// rotation is under way.
    pub fn rotating(&self, id: &str) -> PathBuf {
        self.dir.join("rotating").join(format!("{id}.pub"))
    }

    /// The plant's own copy of the trust file.
    pub fn trust(&self) -> PathBuf {
        self.dir.join("trust.toml")
    }

    /// What the plant last wrote, by file: `<sha256>  <path>` lines.
    pub fn manifest(&self) -> PathBuf {
        self.dir.join(".plant-written")
    }

    /// Host `host`'s root in the plant's folder.
    pub fn host(&self, host: &str) -> PathBuf {
        self.dir.join("hosts").join(host)
    }

    /// `path` on `host`, in the plant's folder.
    pub fn on_host(&self, host: &str, path: &str) -> PathBuf {
        under(&self.host(host), path)
    }

    /// Configuration on the hosts (`/etc/cellwatch`).
    pub fn etc(&self) -> &str {
        &self.etc
    }

    /// Cell `id`'s agent's signing key on its host.
    pub fn signing_key(&self, id: &str) -> String {
        format!("{}/{id}/signing.key", self.state)
    }

    /// Cell `id`'s agent's bus (TLS) key on its host.
    pub fn bus_key(&self, id: &str) -> String {
        format!("{}/{id}/agent-{id}.key", self.state)
    }

    /// The plant archive's folder on a router's host (its SQLite files).
    pub fn archive_dir(&self) -> String {
        format!("{}/archive", self.state)
    }

    /// Cell `id`'s state folder on its host (the agent's own, 0700).
    pub fn cell_state(&self, id: &str) -> String {
        format!("{}/{id}", self.state)
    }

    /// A router's root in the plant's folder.
    pub fn router(&self, name: &str) -> PathBuf {
        self.dir.join("routers").join(name)
    }

    /// Where a router's configuration and certificate are on its host.
    pub fn router_etc(&self) -> String {
        format!("{}/router", self.etc)
    }

    /// The console's root in the plant's folder.
    pub fn console(&self) -> PathBuf {
        self.dir.join("console")
    }

    /// The console's TLS key on its host.
    pub fn console_key(&self) -> String {
        format!("{}/console/console.key", self.state)
    }

    /// Prometheus's scrape targets.
    pub fn scrape_targets(&self) -> PathBuf {
        self.dir.join("prometheus").join("cellwatch.yml")
    }

    /// The Alertmanager routes skeleton.
    pub fn alertmanager_routes(&self) -> PathBuf {
        self.dir.join("alertmanager").join("routes.yml")
    }

    /// Cell `id`'s systemd instance on `host`: the link `systemctl enable
    /// cellwatch@<id>` makes.
    pub fn systemd_instance(&self, host: &str, id: &str) -> PathBuf {
        self.on_host(
            host,
            &format!("/etc/systemd/system/multi-user.target.wants/cellwatch@{id}.service"),
        )
    }

    /// `path` shown relative to the plant's folder.
    pub fn shown(&self, path: &Path) -> String {
        path.strip_prefix(&self.dir)
            .unwrap_or(path)
            .display()
            .to_string()
    }
}
