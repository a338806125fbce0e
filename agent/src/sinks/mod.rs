//! Where the engine's events go: the SQLite journal, Zenoh, Prometheus.

pub mod journal;
pub mod zenoh;
