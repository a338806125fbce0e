//! What the sink and the session share: the book, the store and the
//! signals between them, and why the edge node cannot start.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use tokio::sync::Notify;

use super::book::MetricBook;
use super::store::{HeldStore, StoreError};

/// Why the edge node cannot start.
#[derive(Debug, thiserror::Error)]
pub enum SparkplugError {
    /// A TLS file cannot be read or used.
    #[error("sparkplug.tls: {0}")]
    Tls(#[from] crate::bus::client_tls::ClientTlsError),
    /// The password file cannot be read.
    #[error("sparkplug.password_file: {path}: {source}")]
    Password {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A private file (key, password) is readable by others.
    #[error(transparent)]
    Private(#[from] crate::bus::envelope::KeyFileError),
    /// The store of held changes cannot be opened or read.
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// What the sink and the session share.
#[derive(Debug)]
pub(super) struct Shared {
    /// The metrics and the held changes; held only to write or read them,
    /// never across an await.
    pub(super) book: Mutex<MetricBook>,
    /// The changes held on disk and the bdSeq; held only on a blocking
    /// thread (or before the session runs).
    pub(super) store: Mutex<HeldStore>,
    /// How many changes the store holds, for the held gauge.
    pub(super) stored: AtomicUsize,
    /// Wakes the session: changes wait, or the sink closed.
    pub(super) wake: Notify,
    /// The cell loop is stopping: the session says NDEATH and ends.
    pub(super) closed: AtomicBool,
}

impl Shared {
    pub(super) fn book(&self) -> MutexGuard<'_, MetricBook> {
        self.book
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    pub(super) fn store(&self) -> MutexGuard<'_, HeldStore> {
        self.store
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// How many changes wait, in memory and in the store.
    pub(super) fn held(&self) -> usize {
        self.book().held() + self.stored.load(Ordering::Acquire)
    }
}
