//! What goes wrong on an `@` bus: its line ([`LineError`], after which
//! it is opened again), a write an operator asked for, and the buses
//! several cells share ([`AtBusError`]).

use std::sync::Arc;
use std::time::Duration;

use super::Item;

/// What goes wrong on an `@` bus: its line, a write, the buses cells
/// share.
#[derive(Debug, thiserror::Error)]
pub enum AtBusError {
    /// The serial device server does not take the connection in time.
    #[error("no answer from {addr} within {} s", within.as_secs())]
    ConnectTimeout {
        /// Its address.
        addr: String,
        /// How long it was given.
        within: Duration,
    },
    /// The serial device server refuses the connection.
    #[error("{addr}: {source}")]
    Connect {
        /// Its address.
        addr: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The serial port cannot be opened.
    #[error("{path}: {source}")]
    Serial {
        /// The port.
        path: String,
        /// Why.
        #[source]
        source: tokio_serial::Error,
    },
    /// A value that is not a quantity, for a target or production.
    #[error("'{value}' is not a quantity (0 to 999999)")]
    NotQuantity {
        /// The value given.
        value: String,
    },
    /// A value that is not an item code.
    #[error("'{value}' is not an item code (1 to 8 of A-Z, 0-9 and -)")]
    NotItemCode {
        /// The value given.
        value: String,
    },
    /// An item that is not written.
    #[error("{item:?} of a unit is not written: item code, target and production are")]
    NotWritable {
        /// The item.
        item: Item,
    },
    /// A write of no tag of the cell.
    #[error("no such tag")]
    NoSuchTag,
    /// A tag whose node id is not `@<unit>/<item>`.
    #[error(transparent)]
    NodeId(crate::sources::at_bus::config::NotABusNode),
    /// A switch pulse: an `@` unit has none.
    #[error("an @ unit takes item writes, not switch pulses")]
    NoPulses,
    /// An acknowledgement: an `@` unit has no alarms of its own.
    #[error("an @ unit has no alarms of its own to acknowledge")]
    NoAlarms,
    /// The unit did not take the write.
    #[error("{what}: not taken: {why}")]
    NotTaken {
        /// The write (`WT120 to unit 01`).
        what: String,
        /// What the unit did, last time.
        why: String,
    },
    /// The line failed during the write.
    #[error("{what}: the bus failed: {source}")]
    BusFailed {
        /// The write (`WT120 to unit 01`).
        what: String,
        /// Why.
        #[source]
        source: LineError,
    },
    /// Two cells poll one bus with different settings.
    #[error("{cell} and {other_cell} share {place} but poll it differently ({settings} / {other_settings}): give both the same [legacy] settings")]
    SharedDifferently {
        /// The first cell.
        cell: String,
        /// The other cell.
        other_cell: String,
        /// The bus (port or address).
        place: String,
        /// The first cell's settings.
        settings: String,
        /// The other cell's.
        other_settings: String,
    },
}

/// Why the line to the bus failed: it is opened again.
#[derive(Debug, Clone, thiserror::Error)]
pub enum LineError {
    /// A request cannot be written to the line.
    #[error("cannot write: {0}")]
    Write(#[source] Arc<std::io::Error>),
    /// The line cannot be read.
    #[error("cannot read: {0}")]
    Read(#[source] Arc<std::io::Error>),
    /// The line closed.
    #[error("the line closed")]
    Closed,
}
