//! Where tag values come from.
//!
//! A [`Source`] runs until its shutdown future completes and sends
//! [`SourceEvent`]s on a bounded channel: when the cell loop falls behind,
//! the channel fills and the source waits (for OPC UA, the server's queues
//! then hold the changes), so overload never becomes memory.
//!
//! - [`opcua`]: the production source, an OPC UA client.
//! - [`at_bus`]: the `@` bus poller of paper 002's moulding units (serial
//!   port or a serial device server's TCP socket).
//! - [`scripted::ScriptedSource`]: events handed in by a test or a replay,
//!   the smallest example of a source.
//! - [`pki`]: certificate-trust helpers for OPC UA.
//!
//! To add a source: a folder here with a type implementing [`Source`], and
//! one arm in the agent's `source_for` (`crate::agent`).

pub mod at_bus;
pub mod opcua;
pub mod pki;
#[cfg(any(test, feature = "test-kit"))]
pub mod scripted;
mod source;

pub use source::{
    Batch, Source, SourceError, SourceEvent, SourceSender, Write, WriteError, WriteRequest,
    WriteSender, QUEUE_CAPACITY, WRITE_CAPACITY,
};
