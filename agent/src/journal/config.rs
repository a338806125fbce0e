//! `[journal]`: where the journal is and what each of its tables keeps.
//! The table as written ([`RawJournal`]), the validated configuration
//! ([`JournalConfig`]) and its check (`validate`).

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use crate::table::Table;

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

/// `journal.retention` unless the configuration says.
const DEFAULT_AGE: Duration = Duration::from_secs(90 * 86_400);

/// The least any table may keep: a restart reads back the last two
/// minutes' command nonces (a command is a replay after a restart too),
/// and an hour is the least a person looking back needs.
const LEAST_AGE: Duration = Duration::from_secs(3600);

/// The fewest rows `max_rows` may keep.
const LEAST_ROWS: i64 = 1000;

/// `[journal]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawJournal {
    pub(crate) path: Option<String>,
    pub(crate) retention: Option<Spanned<String>>,
    #[serde(default)]
    pub(crate) tables: RawJournalTables,
}

/// `[journal.tables.<table>]`, one per table of rows.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawJournalTables {
    pub(crate) alarm_events: Option<Spanned<RawKeep>>,
    pub(crate) state_history: Option<Spanned<RawKeep>>,
    pub(crate) commands: Option<Spanned<RawKeep>>,
    pub(crate) production: Option<Spanned<RawKeep>>,
    pub(crate) orders: Option<Spanned<RawKeep>>,
    pub(crate) recordings: Option<Spanned<RawKeep>>,
    pub(crate) modes: Option<Spanned<RawKeep>>,
}

/// `[journal.tables.<table>]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawKeep {
    pub(crate) retention: Option<Spanned<String>>,
    pub(crate) max_rows: Option<Spanned<i64>>,
}

fn keep(
    kit: &mut Table<'_>,
    retention: Option<Spanned<String>>,
    tables: RawJournalTables,
) -> Vec<Keep> {
    let span = retention.as_ref().map(Spanned::span);
    let default = kit.duration(retention, "journal.retention", DEFAULT_AGE);
    if let (Some(span), true) = (span, default < LEAST_AGE) {
        kit.problem(span, "journal.retention", "at least 1h");
    }
    let RawJournalTables {
        alarm_events,
        state_history,
        commands,
        production,
        orders,
        recordings,
        modes,
    } = tables;
    let raws = [
        alarm_events,
        state_history,
        commands,
        production,
        orders,
        recordings,
        modes,
    ];
    JOURNAL_TABLES
        .into_iter()
        .zip(raws)
        .map(|(table, raw)| match raw {
            None => Keep {
                table,
                age: default,
                max_rows: None,
            },
            Some(raw) => table_keep(kit, table, raw.into_inner(), default),
        })
        .collect()
}

fn table_keep(kit: &mut Table<'_>, table: &'static str, raw: RawKeep, default: Duration) -> Keep {
    let key = format!("journal.tables.{table}.retention");
    let span = raw.retention.as_ref().map(Spanned::span);
    let age = kit.duration(raw.retention, &key, default);
    if let (Some(span), true) = (span, age < LEAST_AGE) {
        kit.problem(span, &key, "at least 1h");
    }
    let max_rows = raw.max_rows.and_then(|n| {
        if *n.get_ref() < LEAST_ROWS {
            kit.problem(
                n.span(),
                &format!("journal.tables.{table}.max_rows"),
                format!("at least {LEAST_ROWS}"),
            );
            None
        } else {
            u64::try_from(*n.get_ref()).ok()
        }
    });
    Keep {
        table,
        age,
        max_rows,
    }
}

/// Validates `[journal]` for cell `cell`: its file (`cellwatch-<cell>.sqlite`
/// beside the configuration unless `path` says) and what each table keeps.
pub(crate) fn validate(kit: &mut Table<'_>, raw: RawJournal, cell: &str) -> JournalConfig {
    JournalConfig {
        path: kit.path(
            raw.path
                .as_deref()
                .unwrap_or(&format!("cellwatch-{cell}.sqlite")),
        ),
        keep: keep(kit, raw.retention, raw.tables),
    }
}
