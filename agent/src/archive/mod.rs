//! The plant archive: every cell's signed alarm events, machine states
//! and flight recordings kept by the plant's routers, so that a cell's
//! last days can be read when its agent is down or its host is gone.
//!
//! No store of our own: the routers run Zenoh's storage manager (the
//! engine `zenohd` loads as a plugin), linked into `cellwatch router`
//! ([`router`]), with a SQLite volume that keeps every sample
//! ([`volume`]). Readers ([`read`]) query the storages with a time range
//! and believe only what each cell's agent signed.

pub(crate) mod read;
pub mod router;
pub(crate) mod volume;
