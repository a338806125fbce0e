//! The demo's own configuration, carried in the binary: its four cells'
//! configurations and every file they name (paper 000's instruction lists
//! and I/O lists, the line's timer model, the moulding units' program, the
//! robot's charts), written under the state directory's `config/` so that
//! `cellwatch demo` runs from any directory, installed or in a checkout.
//! Loading a configuration is `config::load`'s, not this file's.
//!
//! A file is written when it is missing, and replaced by this binary's
//! version only while it is still what an earlier run wrote (its SHA-256
//! in `config/shipped.sha256`): a file someone edited is theirs and kept.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::commands::Failure;

/// Every file the demo reads, by its path under `config/`.
pub(super) const FILES: &[(&str, &str)] = &[
    ("demo.toml", include_str!("../../../../config/demo.toml")),
    ("cnc/ese.il", include_str!("../../../../config/cnc/ese.il")),
    (
        "cnc/ese-comments.csv",
        include_str!("../../../../config/cnc/ese-comments.csv"),
    ),
    ("cnc/csd.il", include_str!("../../../../config/cnc/csd.il")),
    (
        "cnc/csd-comments.csv",
        include_str!("../../../../config/cnc/csd-comments.csv"),
    ),
    ("line.toml", include_str!("../../../../config/line.toml")),
    (
        "line/timers.json",
        include_str!("../../../../config/line/timers.json"),
    ),
    (
        "moulding.toml",
        include_str!("../../../../config/moulding.toml"),
    ),
    (
        "moulding/causes.il",
        include_str!("../../../../config/moulding/causes.il"),
    ),
    ("robot.toml", include_str!("../../../../config/robot.toml")),
    (
        "robot/robot.sfc.toml",
        include_str!("../../../../config/robot/robot.sfc.toml"),
    ),
];

/// The record of what was written: `<sha256>  <path>` a line.
const RECORD: &str = "shipped.sha256";

/// The demo's configuration as written under a state directory.
#[derive(Debug)]
pub(super) struct ShippedConfig {
    /// The directory holding `demo.toml` and the files it names.
    pub(super) dir: PathBuf,
    /// Files kept as someone edited them, by their path under `dir`.
    pub(super) kept: Vec<String>,
}

fn sha256(text: &[u8]) -> String {
    hex::encode(Sha256::digest(text))
}

/// Writes the demo's files under `state/config/`: missing ones, and those
/// an earlier run wrote and nobody changed since; edited ones are kept.
///
/// # Errors
/// A file or directory that cannot be read or written.
pub(super) fn write(state: &Path) -> Result<ShippedConfig, Failure> {
    let dir = state.join("config");
    let record_file = dir.join(RECORD);
    let cannot = |what: &str, p: &Path, e: std::io::Error| {
        Failure::Runtime(format!("cannot {what} {}: {e}", p.display()))
    };
    let record: HashMap<String, String> = match std::fs::read_to_string(&record_file) {
        Ok(text) => text
            .lines()
            .filter_map(|l| l.split_once("  "))
            .map(|(hash, path)| (path.to_string(), hash.to_string()))
            .collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => HashMap::new(),
        Err(e) => return Err(cannot("read", &record_file, e)),
    };
    let mut written = String::new();
    let mut kept = Vec::new();
    for (name, text) in FILES {
        let path = dir.join(name);
        let shipped = sha256(text.as_bytes());
        let on_disk = match std::fs::read(&path) {
            Ok(bytes) => Some(sha256(&bytes)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(cannot("read", &path, e)),
        };
        let ours = match &on_disk {
            None => true,
            Some(h) => *h == shipped || record.get(*name) == Some(h),
        };
        if !ours {
            kept.push((*name).to_string());
            continue;
        }
        if on_disk.as_ref() != Some(&shipped) {
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| cannot("create", parent, e))?;
            }
            std::fs::write(&path, text).map_err(|e| cannot("write", &path, e))?;
        }
        written.push_str(&format!("{shipped}  {name}\n"));
    }
    std::fs::create_dir_all(&dir).map_err(|e| cannot("create", &dir, e))?;
    std::fs::write(&record_file, written).map_err(|e| cannot("write", &record_file, e))?;
    Ok(ShippedConfig { dir, kept })
}

#[cfg(test)]
mod tests {
    use super::{write, FILES};

    #[test]
    fn every_file_is_written_and_the_demo_configs_load_from_there() {
        let state = tempfile::tempdir().unwrap();
        let shipped = write(state.path()).unwrap();
        assert!(shipped.kept.is_empty(), "{:?}", shipped.kept);
        for (name, text) in FILES {
            let on_disk = std::fs::read_to_string(shipped.dir.join(name)).unwrap();
            assert_eq!(on_disk, *text, "{name}");
        }
        for cell in ["demo.toml", "line.toml", "moulding.toml", "robot.toml"] {
            let path = shipped.dir.join(cell);
            if let Err(e) = crate::config::load(&path) {
                panic!("{cell}: {e}");
            }
        }
    }

    #[test]
    fn an_edited_file_is_kept_and_an_unedited_old_one_replaced() {
        let state = tempfile::tempdir().unwrap();
        let dir = write(state.path()).unwrap().dir;
        // Someone edits the CNC's I/O list.
        let edited = "X0.06,my own comment\n";
        std::fs::write(dir.join("cnc/ese-comments.csv"), edited).unwrap();
        // An earlier version wrote another line.toml, unedited since.
        let old = "# an earlier version's line\n";
        std::fs::write(dir.join("line.toml"), old).unwrap();
        let record = std::fs::read_to_string(dir.join("shipped.sha256")).unwrap();
        let record = record
            .lines()
            .map(|l| match l.split_once("  ") {
                Some((_, "line.toml")) => format!("{}  line.toml", super::sha256(old.as_bytes())),
                _ => l.to_string(),
            })
            .collect::<Vec<_>>()
            .join("\n");
        std::fs::write(dir.join("shipped.sha256"), record).unwrap();

        let again = write(state.path()).unwrap();
        assert_eq!(again.kept, ["cnc/ese-comments.csv"]);
        let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap();
        assert_eq!(read("cnc/ese-comments.csv"), edited);
        assert_eq!(
            read("line.toml"),
            include_str!("../../../../config/line.toml")
        );
        // Still kept on the next run: the record never takes an edit for ours.
        assert_eq!(write(state.path()).unwrap().kept, ["cnc/ese-comments.csv"]);
        // Removed, it comes back as shipped.
        std::fs::remove_file(dir.join("cnc/ese-comments.csv")).unwrap();
        assert!(write(state.path()).unwrap().kept.is_empty());
        assert_eq!(
            read("cnc/ese-comments.csv"),
            include_str!("../../../../config/cnc/ese-comments.csv")
        );
    }
}
