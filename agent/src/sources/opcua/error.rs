//! What goes wrong in the OPC UA source's own requests: reading the
//! namespace array, pulsing a chart switch, acknowledging a PLC alarm,
//! taking a subscription over.

use std::time::Duration;

use opcua::types::{StatusCode, Variant};

/// Why a request of the OPC UA source failed.
#[derive(Debug, thiserror::Error)]
pub enum OpcUaError {
    /// The service call failed (no connection, a timeout, a bad service
    /// result).
    #[error("{0}")]
    Service(#[source] opcua::types::Error),
    /// The server answered with a bad status.
    #[error("{0}")]
    Status(StatusCode),
    /// A read answered with no value.
    #[error("empty read result")]
    EmptyRead,
    /// A call answered with no result.
    #[error("the server answered nothing")]
    NoAnswer,
    /// The namespace array is not an array of strings.
    #[error("not an array of strings: {0:?}")]
    NotStrings(Option<Variant>),
    /// The namespace array cannot be read (switches written off).
    #[error("cannot read the namespace array: {0}")]
    Namespaces(#[source] Box<OpcUaError>),
    /// The namespace array cannot be read for switch `name`'s pulse.
    #[error("{name}: cannot read the namespace array: {source}")]
    SwitchNamespaces {
        /// The switch.
        name: String,
        /// Why.
        #[source]
        source: Box<OpcUaError>,
    },
    /// The switch's namespace is not on the server.
    #[error("{name}: its namespace is not on the server")]
    NoNamespace {
        /// The switch.
        name: String,
    },
    /// Writing the switch failed.
    #[error("{name}: write {} failed: {source}", u8::from(*on))]
    SwitchWrite {
        /// The switch.
        name: String,
        /// The value written.
        on: bool,
        /// Why.
        #[source]
        source: opcua::types::Error,
    },
    /// The server refused the switch's write.
    #[error("{name}: the server refused {}: {status}", u8::from(*on))]
    SwitchRefused {
        /// The switch.
        name: String,
        /// The value written.
        on: bool,
        /// The server's status.
        status: StatusCode,
    },
    /// The server answered the switch's write with nothing.
    #[error("{name}: the server answered nothing")]
    SwitchNoAnswer {
        /// The switch.
        name: String,
    },
    /// Reading the switch back failed.
    #[error("{name}: read back failed: {source}")]
    ReadBack {
        /// The switch.
        name: String,
        /// Why.
        #[source]
        source: opcua::types::Error,
    },
    /// The switch did not read back as written in time.
    #[error("{name}: written {} but read back {read:?} for {} s", u8::from(*on), within.as_secs())]
    ReadBackDiffers {
        /// The switch.
        name: String,
        /// The value written.
        on: bool,
        /// What it read last.
        read: Option<Variant>,
        /// How long it was given.
        within: Duration,
    },
    /// Switches not written off, each with why.
    #[error("{}", joined(.0))]
    Switches(Vec<OpcUaError>),
    /// The PLC refused to acknowledge its alarm.
    #[error("the PLC refused to acknowledge {id}: {status}")]
    AckRefused {
        /// The alarm.
        id: String,
        /// The server's status.
        status: StatusCode,
    },
    /// The acknowledgement's call failed.
    #[error("cannot acknowledge {id} at the PLC: {source}")]
    Ack {
        /// The alarm.
        id: String,
        /// Why.
        #[source]
        source: opcua::types::Error,
    },
    /// A write of a value: this source writes only switches.
    #[error("this OPC UA source writes only the charts' force and stop switches")]
    OnlySwitches,
    /// A pulse of a tag that is not one of the cell's switches.
    #[error("not a switch of this cell")]
    NotASwitch,
}

/// Errors one after another, `; ` between them.
fn joined(errors: &[OpcUaError]) -> String {
    errors
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}
