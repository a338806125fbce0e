//! Why a key does not read ([`KeyError`]): an operator's private key (its
//! key file, or its hex seed) or the plant administrator's public key.

/// Why a key does not read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// A private key that is not 64 hex digits.
    #[error("a private key is 64 hex digits")]
    NotHex,
    /// A key file that is not TOML of a key file's shape.
    #[error("{origin}: {message}")]
    Syntax {
        /// The file.
        origin: String,
        /// TOML's message.
        message: String,
    },
    /// A key file whose `private_key` is not 64 hex digits.
    #[error("{origin}: private_key: {source}")]
    PrivateKey {
        /// The file.
        origin: String,
        /// Why.
        source: Box<KeyError>,
    },
    /// A public key that is not an Ed25519 public key.
    #[error("not an Ed25519 public key (64 hex digits)")]
    NotAPublicKey,
}
