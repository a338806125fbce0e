//! Why a check's reference to a tag (a tag's name or an address in the
//! cell's dialect) names no tag ([`TagRefError`]). The validator reports
//! it at the value's file, line and column.

use cellwatch_models::signal::{AddressError, Signal};

/// Why a reference to a tag names no tag.
#[derive(Debug, thiserror::Error)]
pub(super) enum TagRefError {
    /// The text names one tag and is the address of another.
    #[error(
        "'{text}' is the name of the tag at {named} and the address of another tag: write the address you mean"
    )]
    Ambiguous {
        /// The text.
        text: String,
        /// The address of the tag it names.
        named: Signal,
    },
    /// No tag is named so or has that address.
    #[error("no tag is named '{text}' or has the address {address}")]
    Missing {
        /// The text.
        text: String,
        /// The address it reads as.
        address: Signal,
    },
    /// No tag is named so, and it is no address.
    #[error("no tag is named '{text}', and it is not an address: {source}")]
    NotAnAddress {
        /// The text.
        text: String,
        /// Why it is no address.
        source: AddressError,
    },
}
