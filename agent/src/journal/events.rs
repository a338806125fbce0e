//! What the journal's writer says and counts: one type per event, whose
//! `emit` writes its log line and tells the [`CommitObserver`] together (in
//! the agent the metrics registry, `cellwatch_journal_*`).

use std::path::Path;
use std::time::Duration;

use super::observer::CommitObserver;

/// Something the writer did or met.
#[derive(Debug)]
pub(super) enum JournalEvent<'a> {
    /// A batch was committed.
    Committed {
        /// The journal's file.
        path: &'a Path,
        /// The rows it held.
        rows: usize,
        /// How long the commit took.
        took: Duration,
        /// The journal had been failing: it is writable again (said).
        again: bool,
    },
    /// A batch failed; its rows are kept and retried.
    Failed {
        /// The journal's file.
        path: &'a Path,
        /// Why.
        why: &'a str,
        /// Rows waiting to be written.
        rows: usize,
        /// Another reason than the last failure's: said (each reason is
        /// said once while it lasts, however often it is retried).
        new: bool,
    },
    /// The journal was unwritable and its queue full: the oldest rows
    /// were dropped.
    Dropped {
        /// The journal's file.
        path: &'a Path,
        /// How many.
        rows: usize,
    },
    /// Rows handed to the journal and not yet committed, now.
    Pending {
        /// How many.
        rows: usize,
    },
    /// The end of the command rows' hash chain could not be read: it
    /// starts again.
    ChainUnreadable {
        /// The journal's file.
        path: &'a Path,
        /// Why.
        error: &'a rusqlite::Error,
    },
    /// The journal closed with rows it could not write.
    ClosedUnwritten {
        /// The journal's file.
        path: &'a Path,
        /// How many.
        rows: usize,
    },
}

impl JournalEvent<'_> {
    /// Logs the event and tells `observer`.
    pub(super) fn emit(self, observer: &dyn CommitObserver) {
        match self {
            JournalEvent::Committed {
                path,
                rows,
                took,
                again,
            } => {
                observer.committed(rows, took);
                if again {
                    tracing::info!(path = %path.display(), "journal writable again");
                }
            }
            JournalEvent::Failed {
                path,
                why,
                rows,
                new,
            } => {
                observer.failed(why);
                if new {
                    tracing::error!(path = %path.display(), error = %why, rows, "journal write failed; rows kept and retried");
                }
            }
            JournalEvent::Dropped { path, rows } => {
                tracing::error!(path = %path.display(), rows, "journal unwritable and its queue full: oldest rows dropped");
                observer.dropped(rows);
            }
            JournalEvent::Pending { rows } => observer.pending(rows),
            JournalEvent::ChainUnreadable { path, error } => {
                tracing::error!(path = %path.display(), error = %error, "cannot read the end of the command rows' hash chain; it starts again");
            }
            JournalEvent::ClosedUnwritten { path, rows } => {
                tracing::error!(path = %path.display(), rows, "journal closed with rows it could not write");
            }
        }
    }
}
