//! Where tag values come from.
//!
//! A [`Source`] runs until its shutdown future completes and sends
//! [`SourceEvent`]s on a bounded channel: when the cell loop falls behind,
//! the channel fills and the source waits (for OPC UA, the server's queues
//! then hold the changes), so overload never becomes memory.
//!
//! - [`opcua`]: the production source, an OPC UA client.
//! - [`legacy`]: the `@` bus poller of paper 002's moulding units (serial
//!   port or a serial device server's TCP socket).
//! - [`scripted::ScriptedSource`]: events handed in by a test or a replay,
//!   the smallest example of a source.
//! - [`pki`]: certificate-trust helpers for OPC UA.
//!
//! To add a source: a folder here with a type implementing [`Source`], and
//! one arm in [`for_config`].

pub mod legacy;
pub mod opcua;
pub mod pki;
pub mod scripted;
mod source;

pub use source::{
    Batch, Source, SourceError, SourceEvent, SourceSender, Write, WriteError, WriteRequest,
    WriteSender, QUEUE_CAPACITY, WRITE_CAPACITY,
};

use crate::config::{CellConfig, TagConfig};

/// The source a cell configuration asks for; `tags` are the
/// configuration's, handed over, not copied (on a 100,000-tag cell a copy
/// is 14 MB plus three strings a tag): the `@` source keeps them, the OPC UA
/// source only what it reads of them.
pub fn for_config(config: &CellConfig, tags: Vec<TagConfig>) -> Box<dyn Source> {
    match (&config.opcua, &config.legacy) {
        (_, Some(bus)) => Box::new(legacy::LegacySource::new(bus.clone(), tags)),
        (Some(ua), None) => Box::new(opcua::OpcUaSource::new(
            &config.cell,
            ua.clone(),
            tags,
            config
                .sfc
                .iter()
                .flat_map(|s| s.force_switch.into_iter().chain(s.stop_switch)),
        )),
        // A validated configuration has one; one built by hand without
        // either reads nothing.
        (None, None) => Box::new(scripted::ScriptedSource::new().0),
    }
}
