//! The cell configuration: one TOML file per cell.
//!
//! [`load`] reads the file and the files it names (programs, comment
//! databases); [`parse`] does the rest from text, so tests feed literals.
//! Parsing has two stages, as in Vector and zenoh: serde into the raw
//! structs of `raw` (unknown keys rejected), then validation into
//! [`CellConfig`], collecting *every* problem, each reported as
//! `FILE:LINE:COL: key: message`. `cellwatch validate CONFIG` runs exactly
//! this and connects to nothing.
//!
//! The document stands above the components it configures: a component
//! owns its table in its own `config.rs` (the raw table, the validated
//! types, re-exported here for the command line, and the check, which the
//! validator calls and whose problems it places: `crate::table`). The
//! cell's own parts (checks, alarms, state, recorder, commands, KPI rules)
//! are the document's.
//!
//! Relative paths are relative to the configuration file's directory.
//! Secrets never live in the file: an OPC UA password comes from an
//! environment variable or a file, and an inline `password` is an error.

mod cell;
mod checks;
mod document;
mod files;
mod problems;
mod raw;
mod validate;

pub use crate::bus::config::{
    cell_prefix, link_problem, zenoh_file, ZenohConfig, ZenohFileError, ZenohMode, ZenohTls,
    DEFAULT_ROOT,
};
pub use crate::journal::config::{JournalConfig, Keep, JOURNAL_TABLES};
pub use crate::services::alarm_server::config::AlarmServerConfig;
pub use crate::services::plant_operators::PlantOperatorsConfig;
pub use crate::sinks::alertmanager::config::{
    default_escalation, AlertmanagerConfig, AlertmanagerTls, DEFAULT_RESEND,
};
pub use crate::sinks::oee::config as oee;
pub use crate::sinks::sparkplug::config as sparkplug;
pub use crate::sources::at_bus::config as at_bus;
pub use crate::sources::opcua::config::{
    EventSource, Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy,
};
pub use crate::sources::opcua::node;
pub use crate::tags::{key_chunk, tag_address, timer_signal, Addressing, Deadband, TagConfig};
pub use cell::{CellConfig, DEFAULT_MAX_SHELVE, FIXED_PARTS, MAX_SHELVE_LIMIT};
pub use checks::{
    Consequences, SfcCheck, TimerCheck, DEFAULT_FORCE_PULSE, DEFAULT_FORCE_TIMEOUT,
    MAX_FORCE_TIMEOUT,
};
pub use files::{tag_tables_beside, Disk, Files};
pub use problems::ConfigErrors;

use std::path::{Path, PathBuf};

/// Loads and validates the configuration at `path`.
///
/// # Errors
/// Every problem, each as `FILE:LINE:COL: key: message`.
pub fn load(path: &Path) -> Result<CellConfig, ConfigErrors> {
    let name = path.display().to_string();
    let bytes =
        std::fs::read(path).map_err(|e| ConfigErrors(vec![format!("{name}: cannot read: {e}")]))?;
    // TOML is UTF-8 by definition.
    let text = cellwatch_models::source::text(&name, &bytes, Some(cellwatch_models::source::UTF_8))
        .map_err(|e| ConfigErrors(vec![e.to_string()]))?;
    let base = path
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    parse(&name, &text, &base, &Disk)
}

/// Validates configuration `text` named `origin`; relative paths are
/// resolved against `base` and read through `files`.
///
/// # Errors
/// Every problem, each as `ORIGIN:LINE:COL: key: message`.
pub fn parse(
    origin: &str,
    text: &str,
    base: &Path,
    files: &dyn Files,
) -> Result<CellConfig, ConfigErrors> {
    let (raw, tags) = document::read(text).map_err(|e| {
        let at = e.at.map_or((1, 1), |s| crate::table::line_col(text, s));
        ConfigErrors(vec![format!("{origin}:{}:{}: {}", at.0, at.1, e.message)])
    })?;
    validate::validate(origin, text, base, files, raw, tags)
}

#[cfg(test)]
mod tests;
