//! One module per command; each takes its parsed arguments and the output
//! streams, and returns [`crate::cli::Failure`] on error.

pub(crate) mod agent;
pub(crate) mod audit;
pub(crate) mod discover;
pub(crate) mod explain;
pub(crate) mod keygen;
pub(crate) mod pki;
pub(crate) mod report;
pub(crate) mod sf;
pub(crate) mod sfc;
pub(crate) mod simulate;
pub(crate) mod subscribers;
pub(crate) mod timers;
