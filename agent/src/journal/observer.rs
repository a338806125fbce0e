//! What the journal tells whoever watches it (the metrics registry, in the
//! agent): each batch committed or failed, rows dropped, and the count of
//! rows not yet committed. Told only through the journal's events
//! (`events.rs`); what the observer does with it is its own business.

use std::time::Duration;

/// What the writer thread reports after each batch, and the count of rows
/// not yet committed as it changes (from the writer and the cell loop).
pub trait CommitObserver: Send + Sync + 'static {
    /// A batch of `rows` rows was committed in `took`.
    fn committed(&self, rows: usize, took: Duration);
    /// A write failed; its rows are kept and retried.
    fn failed(&self, error: &str);
    /// `rows` rows are not yet committed (staged, queued, or in the
    /// writer's batch).
    fn pending(&self, _rows: usize) {}
    /// The queue of unwritten rows was full: the `rows` oldest were dropped.
    fn dropped(&self, _rows: usize) {}
}
