//! Validating the configuration: what the journal's tables keep.

use std::time::Duration;

use toml::Spanned;

use super::Validator;
use crate::config::raw::{RawJournalTables, RawKeep};
use crate::config::{Keep, JOURNAL_TABLES};

/// `journal.retention` unless the configuration says.
const DEFAULT_AGE: Duration = Duration::from_secs(90 * 86_400);

/// The least any table may keep: a restart reads back the last two
/// minutes' command nonces (a command is a replay after a restart too),
/// and an hour is the least a person looking back needs.
const LEAST_AGE: Duration = Duration::from_secs(3600);

/// The fewest rows `max_rows` may keep.
const LEAST_ROWS: i64 = 1000;

impl Validator<'_> {
    pub(super) fn keep(
        &mut self,
        retention: Option<Spanned<String>>,
        tables: RawJournalTables,
    ) -> Vec<Keep> {
        let span = retention.as_ref().map(Spanned::span);
        let default = self.duration(retention, "journal.retention", DEFAULT_AGE);
        if let (Some(span), true) = (span, default < LEAST_AGE) {
            self.problem(span, "journal.retention", "at least 1h");
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
                Some(raw) => self.table_keep(table, raw.into_inner(), default),
            })
            .collect()
    }

    fn table_keep(&mut self, table: &'static str, raw: RawKeep, default: Duration) -> Keep {
        let key = format!("journal.tables.{table}.retention");
        let span = raw.retention.as_ref().map(Spanned::span);
        let age = self.duration(raw.retention, &key, default);
        if let (Some(span), true) = (span, age < LEAST_AGE) {
            self.problem(span, &key, "at least 1h");
        }
        let max_rows = raw.max_rows.and_then(|n| {
            if *n.get_ref() < LEAST_ROWS {
                self.problem(
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
}
