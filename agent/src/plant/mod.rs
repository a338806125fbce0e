//! The plant: one inventory (`plant.toml`) and everything fifty cells
//! need made and kept from it (`cellwatch plant`): the plant CA, the
//! routers', agents' and console's certificates, the agents' signing keys,
//! the trust file, each cell's configuration and operators file for its
//! host, the routers' access control, Prometheus's targets, the console's
//! configuration, the Alertmanager routes and the systemd instances; and
//! the check of the running plant against it.
//!
//! - `inventory.rs`: the inventory, read and validated.
//! - `edit.rs`: cells and operators added to it, its comments kept.
//! - `layout.rs`: where each file goes, on its host and in the folder.
//! - `render.rs`: the derived files' text (pure).
//! - `files.rs`: writing them, never over a hand edit or a secret.
//! - `make.rs`: the whole run.
//! - `check.rs`: the running plant against the inventory.
//! - `judge.rs`: an agent's `about` against what was deployed to it
//!   (pure; the check's and the console's).

pub(crate) mod check;
pub(crate) mod edit;
pub(crate) mod files;
pub(crate) mod inventory;
pub(crate) mod judge;
pub(crate) mod layout;
pub(crate) mod make;
pub mod render;

use std::path::PathBuf;

pub use files::Made;
pub use inventory::Inventory;

/// Why a plant command cannot do what it was asked.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// The inventory has problems, each at its line and column.
    #[error("{}", .0.join("\n"))]
    Inventory(Vec<String>),
    /// A file cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file or folder cannot be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A derived file's content cannot be written out.
    #[error("{what}: cannot be encoded: {message}")]
    Encode {
        /// Which file.
        what: String,
        /// Why.
        message: String,
    },
    /// A certificate or key cannot be made.
    #[error("{name}: {message}")]
    Certificate {
        /// Whose.
        name: String,
        /// Why.
        message: String,
    },
    /// A cell's configuration cannot be made its host's.
    #[error("{path}: {message}")]
    CellConfig {
        /// The cell's configuration.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// Two parts of the plant ask for one file with different contents.
    #[error("{path}: two cells of one host need this file with different contents; give one of them another name")]
    Clash {
        /// The file.
        path: PathBuf,
    },
    /// An addition contradicts what the inventory holds.
    #[error("{path}: {message}")]
    Edit {
        /// The inventory.
        path: PathBuf,
        /// What and where.
        message: String,
    },
}
