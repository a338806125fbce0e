//! Why one value of a configuration does not read ([`ValueError`]): a tag
//! reference, the alarm server's listening address, an Alertmanager's
//! URL. The validator reports it at the value's file, line and column.

use cellwatch_models::signal::{AddressError, Signal};

/// Why one value of a configuration does not read.
#[derive(Debug, thiserror::Error)]
pub(super) enum ValueError {
    /// The text names one tag and is the address of another.
    #[error(
        "'{text}' is the name of the tag at {named} and the address of another tag: write the address you mean"
    )]
    AmbiguousTag {
        /// The text.
        text: String,
        /// The address of the tag it names.
        named: Signal,
    },
    /// No tag is named so or has that address.
    #[error("no tag is named '{text}' or has the address {address}")]
    NoTag {
        /// The text.
        text: String,
        /// The address it reads as.
        address: Signal,
    },
    /// No tag is named so, and it is no address.
    #[error("no tag is named '{text}', and it is not an address: {source}")]
    NotATag {
        /// The text.
        text: String,
        /// Why it is no address.
        source: AddressError,
    },
    /// Not an `opc.tcp://` address.
    #[error("'{0}' is not like opc.tcp://0.0.0.0:4855")]
    NotOpcTcp(String),
    /// An `opc.tcp://` address without an IP address and a port.
    #[error("'{0}': give an IP address and a port, like opc.tcp://0.0.0.0:4855")]
    NoIpAndPort(String),
    /// Not a URL.
    #[error("'{text}' is not a URL like http://alertmanager:9093 ({source})")]
    NotAUrl {
        /// The text.
        text: String,
        /// Why.
        source: hyper::http::uri::InvalidUri,
    },
    /// A URL neither `http://` nor `https://`.
    #[error("'{0}': use http:// or https://")]
    NotHttp(String),
    /// A URL without a host.
    #[error("'{0}' names no host")]
    NoHost(String),
    /// A URL with a query.
    #[error("'{0}': no query (?…) is allowed")]
    Query(String),
}
