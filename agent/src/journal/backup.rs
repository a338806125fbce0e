//! An online, consistent copy of a journal (`cellwatch journal backup`):
//! SQLite's backup API copies the file as of one read transaction while
//! the agent goes on writing (WAL: a reader never holds up the writer),
//! into a file of its own (owner-only, a private name), then the copy is
//! checked (`PRAGMA integrity_check`) and counted, and only then given its
//! name, never over another file. A backup is a journal like any other.
//! [`backup_database`] copies another SQLite file the same way (the
//! Sparkplug B node's held changes beside the journal).

use std::path::{Path, PathBuf};

use rusqlite::{Connection, OpenFlags};

use super::schema::TABLES;

/// What a backup holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Copied {
    /// Rows per table, in [`TABLES`] order, and `alarm_current`.
    pub rows: Vec<(&'static str, u64)>,
    /// The copy's size, bytes.
    pub bytes: u64,
}

/// Why a backup failed.
#[derive(Debug, thiserror::Error)]
pub(crate) enum BackupError {
    /// The source is missing, or the destination exists already.
    #[error("{0}")]
    Input(String),
    /// SQLite or the file system failed.
    #[error("{path}: {message}")]
    Failed {
        /// The file at fault.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Copies the journal at `from` to `to` (which must not exist) and checks
/// the copy. The copy is made in a file of its own, created owner-only
/// (0600) under a private random name beside `to` (never through a
/// symbolic link, never over a file), and linked to `to` only once checked:
/// a file made at `to` meanwhile is never overwritten.
///
/// # Errors
/// See [`BackupError`]; a failed backup leaves nothing at `to`.
pub(crate) fn backup(from: &Path, to: &Path) -> Result<Copied, BackupError> {
    if !from.is_file() {
        return Err(BackupError::Input(format!(
            "{}: no such journal",
            from.display()
        )));
    }
    copy_to(from, to, true)
}

/// Copies the SQLite database at `from` to `to` as [`backup`] copies a
/// journal (one instant, checked, owner-only, never over a file), rows
/// not counted. The copy's size, bytes.
///
/// # Errors
/// See [`BackupError`]; a failed backup leaves nothing at `to`.
pub(crate) fn backup_database(from: &Path, to: &Path) -> Result<u64, BackupError> {
    if !from.is_file() {
        return Err(BackupError::Input(format!(
            "{}: no such file",
            from.display()
        )));
    }
    copy_to(from, to, false).map(|c| c.bytes)
}

/// [`backup`] and [`backup_database`]: `journal` says whether the rows of
/// the journal's tables are counted (and the file refused if it has none).
fn copy_to(from: &Path, to: &Path, journal: bool) -> Result<Copied, BackupError> {
    let exists = || {
        BackupError::Input(format!(
            "{}: exists already (a backup never overwrites a file: name a new one)",
            to.display()
        ))
    };
    // A symbolic link counts, whether or not it leads anywhere.
    if to.symlink_metadata().is_ok() {
        return Err(exists());
    }
    let partial = private_file(to)?;
    let result = copy(from, &partial, journal).and_then(|copied| {
        // link(2) never replaces a file: one made at `to` since the check
        // above is refused, not overwritten.
        std::fs::hard_link(&partial, to).map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => exists(),
            _ => BackupError::Failed {
                path: to.to_path_buf(),
                message: e.to_string(),
            },
        })?;
        Ok(copied)
    });
    let _ = std::fs::remove_file(&partial);
    result
}

/// Creates the file the copy is made in: beside `to` (same file system, so
/// it can be linked there), under a random name of its own, owner-only
/// from the start, refusing to follow or reuse anything at that name.
fn private_file(to: &Path) -> Result<PathBuf, BackupError> {
    let mut name = std::ffi::OsString::from(".");
    name.push(to.file_name().unwrap_or_default());
    name.push(format!(
        ".{}.partial",
        hex::encode(rand::random::<[u8; 8]>())
    ));
    let partial = to.with_file_name(name);
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600).custom_flags(nix::libc::O_NOFOLLOW);
    }
    options
        .open(&partial)
        .map(drop)
        .map_err(|e| BackupError::Failed {
            path: partial.clone(),
            message: format!("cannot create the copy: {e}"),
        })?;
    Ok(partial)
}

fn copy(from: &Path, partial: &Path, journal: bool) -> Result<Copied, BackupError> {
    let failed = |path: &Path| {
        let path = path.to_path_buf();
        move |e: rusqlite::Error| BackupError::Failed {
            path,
            message: e.to_string(),
        }
    };
    let source = Connection::open_with_flags(
        from,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(failed(from))?;
    source
        .busy_timeout(std::time::Duration::from_secs(10))
        .map_err(failed(from))?;
    // The file just made, not whatever may have taken its name since.
    let mut dest = Connection::open_with_flags(
        partial,
        OpenFlags::SQLITE_OPEN_READ_WRITE
            | OpenFlags::SQLITE_OPEN_NOFOLLOW
            | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(failed(partial))?;
    {
        let backup = rusqlite::backup::Backup::new(&source, &mut dest).map_err(failed(partial))?;
        // Every page in one step: one read transaction, so the copy is the
        // journal at one instant, whatever the agent writes meanwhile.
        // Busy or locked (a checkpoint under way): again, for up to 10 s.
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        loop {
            use rusqlite::backup::StepResult;
            match backup.step(-1).map_err(failed(partial))? {
                StepResult::Done => break,
                StepResult::More | StepResult::Busy | StepResult::Locked
                    if std::time::Instant::now() < deadline =>
                {
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
                other => {
                    return Err(BackupError::Failed {
                        path: from.to_path_buf(),
                        message: format!("the journal stayed busy for 10 s ({other:?})"),
                    })
                }
            }
        }
    }
    let verdict: String = dest
        .query_row("PRAGMA integrity_check", [], |r| r.get(0))
        .map_err(failed(partial))?;
    if verdict != "ok" {
        return Err(BackupError::Failed {
            path: partial.to_path_buf(),
            message: format!("the copy fails SQLite's integrity check: {verdict}"),
        });
    }
    let mut rows = Vec::new();
    let tables = if journal { TABLES.as_slice() } else { &[] };
    for &table in tables.iter().chain(if journal {
        ["alarm_current"].as_slice()
    } else {
        &[]
    }) {
        let n: i64 = dest
            .query_row(&format!("SELECT count(*) FROM {table}"), [], |r| r.get(0))
            .map_err(|e| {
                BackupError::Input(format!(
                    "{}: not a cellwatch journal (table {table}: {e})",
                    from.display()
                ))
            })?;
        rows.push((table, n as u64));
    }
    // The copy is a file of its own, not a WAL database waiting for a
    // checkpoint.
    dest.pragma_update(None, "journal_mode", "DELETE")
        .map_err(failed(partial))?;
    drop(dest);
    let bytes = std::fs::metadata(partial)
        .map_err(|e| BackupError::Failed {
            path: partial.to_path_buf(),
            message: e.to_string(),
        })?
        .len();
    Ok(Copied { rows, bytes })
}
