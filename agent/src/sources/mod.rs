//! Where tag values come from. The OPC UA client is the production source;
//! each source sends [`SourceEvent`]s to the engine task.

pub mod opcua;
pub mod pki;

use cellwatch_models::engine::Reading;

/// What a source tells the engine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceEvent {
    /// The connection is up and the subscription is in place.
    Connected,
    /// The connection is lost; why.
    Disconnected(String),
    /// A value (or bad quality) for tag `tag`, with its source timestamp.
    Reading {
        /// Index into the configured tags.
        tag: usize,
        /// The value, or bad quality.
        reading: Reading,
        /// Source timestamp, ms since the epoch.
        source_time: u64,
    },
}
