//! `cellwatch router`: a plant router. Zenoh's own router runtime (what
//! `zenohd` runs) from a `zenohd` configuration file, with Zenoh's storage
//! manager linked in and the [`SqliteVolume`] declared to it, so that the
//! configuration's `plugins.storage_manager` section keeps the plant
//! archive without a plugin library to load.

use std::path::{Path, PathBuf};

use zenoh::config::WhatAmI;
use zenoh::internal::plugins::PluginsManager;
use zenoh::internal::runtime::{Runtime, RuntimeBuilder};
use zenoh_plugin_storage_manager::StoragesPlugin;
use zenoh_plugin_trait::Plugin;

use super::volume::SqliteVolume;

/// The storage manager's name in the configuration's `plugins`.
pub const STORAGE_MANAGER: &str = "storage_manager";

/// What keeps a router from starting.
#[derive(Debug, thiserror::Error)]
pub enum RouterError {
    /// The configuration file does not read as Zenoh's.
    #[error("{path}: {problem}")]
    Config {
        /// The file.
        path: PathBuf,
        /// Zenoh's words.
        problem: String,
    },
    /// The configuration is Zenoh's but not a router's that can keep an
    /// archive.
    #[error("{path}: {problem}")]
    NotARouter {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: &'static str,
    },
    /// Zenoh could not start the router (a port taken, a certificate
    /// missing).
    #[error("the router did not start: {0}")]
    Start(String),
}

/// A running router; closed by [`PlantRouter::close`] (or when the process
/// ends).
pub struct PlantRouter {
    runtime: Runtime,
    archives: bool,
}

impl PlantRouter {
    /// Reads `path` (JSON5, as `zenohd -c` does) and starts the router.
    pub async fn start_from(path: &Path) -> Result<PlantRouter, RouterError> {
        let config = crate::config::zenoh_file(path).map_err(|problem| RouterError::Config {
            path: path.to_path_buf(),
            problem,
        })?;
        PlantRouter::start(config, path).await
    }

    /// Starts a router from `config`; `origin` names where it came from in
    /// errors. The storage manager starts when the configuration has a
    /// `plugins.storage_manager` section; it needs timestamps, which a
    /// router adds to what it routes unless its configuration says not.
    pub async fn start(config: zenoh::Config, origin: &Path) -> Result<PlantRouter, RouterError> {
        let not = |problem| RouterError::NotARouter {
            path: origin.to_path_buf(),
            problem,
        };
        if config.mode() != &Some(WhatAmI::Router) {
            return Err(not("`mode` must be \"router\""));
        }
        let archives = config
            .get_json(&format!("plugins/{STORAGE_MANAGER}"))
            .is_ok();
        if archives {
            // `true`, `false`, or per mode (`{ router: true, … }`; a
            // router's default is on).
            let timestamped = match config
                .get_json("timestamping/enabled")
                .ok()
                .and_then(|v| serde_json::from_str::<serde_json::Value>(&v).ok())
            {
                Some(serde_json::Value::Bool(on)) => on,
                Some(serde_json::Value::Object(modes)) => modes
                    .get("router")
                    .and_then(|v| v.as_bool())
                    .unwrap_or(true),
                _ => true,
            };
            if !timestamped {
                return Err(not(
                    "the storage manager needs `timestamping: { enabled: true }` on a router",
                ));
            }
        }
        let mut plugins = PluginsManager::static_plugins_only();
        if archives {
            zenoh_plugin_storage_manager::declare_static_backend::<SqliteVolume>();
            plugins
                .declare_static_plugin::<StoragesPlugin, &str>(StoragesPlugin::DEFAULT_NAME, true);
        }
        let mut runtime = RuntimeBuilder::new(config)
            .plugins_manager(plugins)
            .build()
            .await
            .map_err(|e| RouterError::Start(e.to_string()))?;
        runtime
            .start()
            .await
            .map_err(|e| RouterError::Start(e.to_string()))?;
        Ok(PlantRouter { runtime, archives })
    }

    /// Whether this router keeps an archive (its configuration has a
    /// storage manager).
    pub fn archives(&self) -> bool {
        self.archives
    }

    /// The router's Zenoh id.
    pub fn zid(&self) -> String {
        self.runtime.zid().to_string()
    }

    /// The endpoints it listens on (`quic/127.0.0.1:40123`), once started.
    pub fn locators(&self) -> Vec<String> {
        self.runtime
            .get_locators()
            .iter()
            .map(|l| l.to_string())
            .collect()
    }

    /// Stops the router: its links, its storages (their files are closed).
    pub async fn close(self) {
        if let Err(e) = self.runtime.close().await {
            tracing::warn!("the router did not close cleanly: {e}");
        }
    }
}
