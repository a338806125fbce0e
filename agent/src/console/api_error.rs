//! Why the console's API could not read what it shows ([`ApiError`]): the
//! file of what the plant deployed, an agent's answer, a query's value.
//! Said to the page as it reads.

use std::path::PathBuf;

use crate::client::ClientError;

/// Why the console's API could not read what it shows.
#[derive(Debug, thiserror::Error)]
pub(super) enum ApiError {
    /// The file of what the plant deployed cannot be read.
    #[error("{path}: {source}")]
    DeployedRead {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// That file is larger than the console reads.
    #[error("{path}: larger than {max} bytes")]
    DeployedTooLarge {
        /// The file.
        path: PathBuf,
        /// The most the console reads.
        max: u64,
    },
    /// That file is not what the plant deployed.
    #[error("{path}: {source}")]
    DeployedJson {
        /// The file.
        path: PathBuf,
        /// Why.
        source: serde_json::Error,
    },
    /// That file is of another schema (its schema, escaped).
    #[error("{path}: schema '{schema}', not {expected}")]
    DeployedSchema {
        /// The file.
        path: PathBuf,
        /// Its schema.
        schema: String,
        /// The one the console reads.
        expected: &'static str,
    },
    /// An agent did not answer about itself.
    #[error("its agent does not answer about itself: {0}")]
    NoAbout(#[source] ClientError),
    /// An agent's `about` does not read.
    #[error("its agent's about does not read: {0}")]
    AboutUnreadable(#[source] serde_json::Error),
    /// An agent did not answer.
    #[error(transparent)]
    Ask(#[from] ClientError),
    /// An agent's answer is not JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A query parameter's value that is not plain (its name, and the
    /// value escaped).
    #[error("{name}: '{value}' is not a time, duration, kind or number")]
    NotPlain {
        /// The parameter.
        name: String,
        /// Its value, escaped.
        value: String,
    },
}
