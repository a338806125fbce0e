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
        problem: crate::bus::config::ZenohFileError,
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
    /// The archive's section names what `cellwatch router` cannot keep.
    #[error("{path}: plugins.storage_manager.{key}: {problem}")]
    Archive {
        /// The file.
        path: PathBuf,
        /// The key under the storage manager's section.
        key: String,
        /// What is wrong.
        problem: String,
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
        let config =
            crate::bus::config::zenoh_file(path).map_err(|problem| RouterError::Config {
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
        if archives {
            let section = config
                .get_json(&format!("plugins/{STORAGE_MANAGER}"))
                .ok()
                .and_then(|v| serde_json::from_str::<serde_json::Value>(&v).ok())
                .unwrap_or_default();
            archive_problem(&section).map_err(|(key, problem)| RouterError::Archive {
                path: origin.to_path_buf(),
                key,
                problem,
            })?;
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

/// What in the storage manager's section `cellwatch router` cannot keep,
/// as the key under it and why: a volume other than the SQLite one (no
/// backend library is loaded) or one without its folder, a storage
/// without a key expression or naming a volume that is not there, a
/// retention that is not a duration. Zenoh's storage manager would log
/// these and run without the storage; a router that keeps nothing of
/// what it was told to keep must not start.
fn archive_problem(section: &serde_json::Value) -> Result<(), (String, String)> {
    use super::volume::VOLUME;
    let mut volumes = vec!["memory".to_string()];
    for (name, v) in section["volumes"].as_object().into_iter().flatten() {
        let backend = v["backend"].as_str().unwrap_or(name);
        if backend != VOLUME {
            return Err((
                format!("volumes.{name}"),
                format!("backend `{backend}`: cellwatch router has the `{VOLUME}` volume only (and Zenoh's `memory`)"),
            ));
        }
        if v["dir"].as_str().is_none_or(str::is_empty) {
            return Err((
                format!("volumes.{name}.dir"),
                "the folder of the archive's SQLite files is required".into(),
            ));
        }
        volumes.push(name.clone());
    }
    for (name, st) in section["storages"].as_object().into_iter().flatten() {
        if st["key_expr"].as_str().is_none() {
            return Err((format!("storages.{name}.key_expr"), "required".into()));
        }
        let volume = st["volume"].as_str().or(st["volume"]["id"].as_str());
        match volume {
            Some(v) if volumes.iter().any(|known| known == v) => {}
            Some(v) => {
                return Err((
                    format!("storages.{name}.volume"),
                    format!(
                        "`{v}` is no volume of this section (volumes: {})",
                        volumes.join(", ")
                    ),
                ))
            }
            None => return Err((format!("storages.{name}.volume"), "required".into())),
        }
        if let Some(r) = st["volume"].get("retention") {
            let fine = r
                .as_str()
                .and_then(|t| humantime::parse_duration(t).ok())
                .is_some_and(|d| !d.is_zero());
            if !fine {
                return Err((
                    format!("storages.{name}.volume.retention"),
                    format!("{r}: a duration such as \"90d\""),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::archive_problem;

    fn problem(section: &str) -> Option<(String, String)> {
        archive_problem(&serde_json::from_str(section).unwrap()).err()
    }

    #[test]
    fn an_archive_the_router_cannot_keep_is_refused_at_its_key() {
        let good = r#"{"volumes": {"sqlite": {"dir": "/var/lib/cellwatch/archive"}},
            "storages": {"alarms": {"key_expr": "cellwatch/*/alarms/**",
                                    "volume": {"id": "sqlite", "retention": "90d"}}}}"#;
        assert_eq!(problem(good), None);
        let key = |s: &str| problem(s).map(|(k, _)| k);
        assert_eq!(
            key(r#"{"volumes": {"sqlite": {}}}"#).as_deref(),
            Some("volumes.sqlite.dir")
        );
        assert_eq!(
            key(r#"{"volumes": {"fs": {"backend": "filesystem"}}}"#).as_deref(),
            Some("volumes.fs")
        );
        assert_eq!(
            key(r#"{"storages": {"a": {"key_expr": "x/**", "volume": "sqlite"}}}"#).as_deref(),
            Some("storages.a.volume")
        );
        assert_eq!(
            key(r#"{"storages": {"a": {"volume": "memory"}}}"#).as_deref(),
            Some("storages.a.key_expr")
        );
        assert_eq!(
            key(
                r#"{"volumes": {"sqlite": {"dir": "/a"}}, "storages": {"a": {"key_expr": "x/**",
                "volume": {"id": "sqlite", "retention": "soon"}}}}"#
            )
            .as_deref(),
            Some("storages.a.volume.retention")
        );
    }
}
