//! `[journal]`: where the journal is and what each of its tables keeps.

use std::path::PathBuf;
use std::time::Duration;

/// The SQLite journal.
#[derive(Debug, Clone)]
pub struct JournalConfig {
    /// Database file.
    pub path: PathBuf,
    /// What each table keeps (`journal.retention`, `[journal.tables.*]`):
    /// one entry per table of rows, in [`JOURNAL_TABLES`] order.
    pub keep: Vec<Keep>,
}

/// The journal's tables of rows, as `[journal.tables.*]` names them.
pub const JOURNAL_TABLES: [&str; 7] = [
    "alarm_events",
    "state_history",
    "commands",
    "production",
    "orders",
    "recordings",
    "modes",
];

/// What one table of the journal keeps: rows younger than `age`, and at
/// most `max_rows` of them (the newest).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keep {
    /// The table (one of [`JOURNAL_TABLES`]).
    pub table: &'static str,
    /// Rows older than this are deleted.
    pub age: Duration,
    /// Beyond this many rows, the oldest are deleted.
    pub max_rows: Option<u64>,
}

impl Keep {
    /// Every table keeps rows younger than `age`, however many.
    pub fn all(age: Duration) -> Vec<Keep> {
        JOURNAL_TABLES
            .into_iter()
            .map(|table| Keep {
                table,
                age,
                max_rows: None,
            })
            .collect()
    }
}
