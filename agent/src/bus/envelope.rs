//! End-to-end authenticity on the bus: everything an agent puts or answers
//! is sealed in a signed envelope with the agent's own Ed25519 key, and
//! every client opens it against a plant trust file (cell → public key).
//!
//! TLS and access control decide who may reach whom; they cannot tell a
//! reader that an alarm on `cellwatch/m01ps0004/alarms/ese` was written by
//! m01ps0004's agent rather than relayed or answered by another session
//! (a router without access control, a peer relaying). The envelope can:
//! a router or peer in between can drop traffic, never forge it.
//!
//! The envelope (`cellwatch.signed.v1`, JSON):
//!
//! ```json
//! {"schema": "cellwatch.signed.v1", "kind": "put", "cell": "m01ps0004",
//!  "key": "cellwatch/m01ps0004/alarms/ese", "query": "", "at": 1764052850653,
//!  "body": "{\"schema\":\"cellwatch.alarm.v1\",…}", "signature": "<128 hex digits>"}
//! ```
//!
//! - `kind`: `put` (a publication), `reply` (an answer to a query) or
//!   `error` (an error answer: `body` is its text);
//! - `key`: the key expression it was put or answered on;
//! - `query`: for answers, the query's parameters exactly as received
//!   (clients add a fresh `nonce=…`, so an old answer cannot be replayed
//!   as a new one); empty for publications;
//! - `at`: when it was sealed, ms since the epoch;
//! - `body`: the payload itself (JSON text), as a string;
//! - `signature`: Ed25519 over [`signed_bytes`]: the bytes
//!   `cellwatch.signed.v1`, then for each of `kind`, `cell`, `key`,
//!   `query`, `at` (decimal) and `body` its UTF-8 length as a 4-byte
//!   big-endian number followed by its bytes. Length-prefixed, so no text
//!   in one field can pass for another.
//!
//! This module owns the agent's signing key file ([`AgentKey`]), the plant
//! trust file ([`Trust`]) and the envelope; [`crate::sinks::zenoh`] and
//! [`crate::services`] seal, the CLI opens.

use std::collections::BTreeMap;
use std::path::Path;

use ed25519_dalek::{Signature, Signer, SigningKey, VerifyingKey};
use serde::{Deserialize, Serialize};

/// Schema name of the envelope.
pub const SIGNED_SCHEMA: &str = "cellwatch.signed.v1";

/// What an envelope carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// A publication (alarm event, machine state).
    Put,
    /// An answer to a query.
    Reply,
    /// An error answer to a query; the body is its text.
    Error,
}

impl Kind {
    fn as_str(self) -> &'static str {
        match self {
            Kind::Put => "put",
            Kind::Reply => "reply",
            Kind::Error => "error",
        }
    }
}

/// A signed envelope as it travels (see the module's documentation).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Envelope {
    /// [`SIGNED_SCHEMA`].
    pub schema: String,
    /// Put, reply or error.
    pub kind: Kind,
    /// The cell whose agent sealed it.
    pub cell: String,
    /// The key expression it was put or answered on.
    pub key: String,
    /// The query's parameters (answers); empty for publications.
    #[serde(default)]
    pub query: String,
    /// When it was sealed, ms since the epoch.
    pub at: u64,
    /// The payload (JSON text), or an error's text.
    pub body: String,
    /// Hex Ed25519 signature of [`signed_bytes`].
    pub signature: String,
}

/// The bytes an envelope's signature covers: the schema name, then each
/// field as a 4-byte big-endian length and its UTF-8 bytes.
pub fn signed_bytes(
    kind: Kind,
    cell: &str,
    key: &str,
    query: &str,
    at: u64,
    body: &str,
) -> Vec<u8> {
    let at = at.to_string();
    let fields = [kind.as_str(), cell, key, query, at.as_str(), body];
    let mut out =
        Vec::with_capacity(SIGNED_SCHEMA.len() + fields.iter().map(|f| f.len() + 4).sum::<usize>());
    out.extend_from_slice(SIGNED_SCHEMA.as_bytes());
    for f in fields {
        let len = u32::try_from(f.len()).unwrap_or(u32::MAX);
        out.extend_from_slice(&len.to_be_bytes());
        out.extend_from_slice(f.as_bytes());
    }
    out
}

/// Why a key or trust file is refused.
#[derive(Debug, thiserror::Error)]
pub enum KeyFileError {
    /// The file cannot be read or written.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        reason: String,
    },
    /// The file's text is not what it should be.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong, with the key or line.
        reason: String,
    },
    /// A private key that others than its owner may read.
    #[error("{path}: a private key readable by others (mode {mode:o}); make it the owner's only: chmod 600 {path}")]
    Exposed {
        /// The file.
        path: String,
        /// Its permission bits.
        mode: u32,
    },
}

/// Refuses a private key file that its group or others may read or write,
/// as ssh does.
///
/// # Errors
/// The file cannot be looked at, or is exposed.
pub fn check_private(path: &Path) -> Result<(), KeyFileError> {
    let meta = std::fs::metadata(path).map_err(|e| KeyFileError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(KeyFileError::Exposed {
                path: path.display().to_string(),
                mode,
            });
        }
    }
    #[cfg(not(unix))]
    drop(meta);
    Ok(())
}

/// An agent's signing key: Ed25519, one per cell, kept on the agent's
/// machine only (`zenoh.signing_key`). Its public half goes into the plant
/// trust file.
pub struct AgentKey {
    cell: String,
    key: SigningKey,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct AgentKeyFile {
    cell: String,
    private_key: String,
}

impl AgentKey {
    /// A new random key for `cell`'s agent.
    pub fn generate(cell: &str) -> AgentKey {
        AgentKey {
            cell: cell.into(),
            key: SigningKey::from_bytes(&rand::random::<[u8; 32]>()),
        }
    }

    /// Reads a key file (`cell = "…"`, `private_key = "<64 hex digits>"`).
    ///
    /// # Errors
    /// Not a key file; the message names the file and key.
    pub fn parse(origin: &str, text: &str) -> Result<AgentKey, KeyFileError> {
        let invalid = |reason: String| KeyFileError::Invalid {
            path: origin.into(),
            reason,
        };
        let f: AgentKeyFile = toml::from_str(text).map_err(|e| invalid(e.message().into()))?;
        let bytes: [u8; 32] = hex::decode(f.private_key.trim())
            .ok()
            .and_then(|b| b.try_into().ok())
            .ok_or_else(|| invalid("private_key: a private key is 64 hex digits".into()))?;
        Ok(AgentKey {
            cell: f.cell,
            key: SigningKey::from_bytes(&bytes),
        })
    }

    /// The key file's text.
    pub fn to_file(&self) -> String {
        format!(
            "# cellwatch agent signing key of cell '{}'. PRIVATE: only on this cell's agent\n\
             # (chmod 600). Its public key goes into the plant trust file:\n\
             # {}\ncell = \"{}\"\nprivate_key = \"{}\"\n",
            self.cell,
            self.trust_entry().trim_end().replace('\n', "\n# "),
            self.cell,
            hex::encode(self.key.to_bytes())
        )
    }

    /// Reads `path` for `cell`'s agent, or makes it (owner-only) when it
    /// does not exist. Returns the key and whether it was made now.
    ///
    /// # Errors
    /// The file is exposed, not a key file, another cell's key, or cannot
    /// be written.
    pub fn load_or_create(path: &Path, cell: &str) -> Result<(AgentKey, bool), KeyFileError> {
        let io = |e: String| KeyFileError::Io {
            path: path.display().to_string(),
            reason: e,
        };
        if !path.exists() {
            let key = AgentKey::generate(cell);
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(|e| io(e.to_string()))?;
            }
            match super::certs::write_private(path, &key.to_file()) {
                Ok(()) => return Ok((key, true)),
                // Made meanwhile by another agent of the same cell starting:
                // read below.
                Err(_) if path.exists() => {}
                Err(e) => return Err(io(e)),
            }
        }
        let key = AgentKey::load(path)?;
        if key.cell != cell {
            return Err(KeyFileError::Invalid {
                path: path.display().to_string(),
                reason: format!(
                    "the signing key of cell '{}', not of '{cell}': each cell's agent has its own",
                    key.cell
                ),
            });
        }
        Ok((key, false))
    }

    /// Reads the key file at `path`, refusing one others may read.
    ///
    /// # Errors
    /// The file is exposed, unreadable or not a key file.
    pub fn load(path: &Path) -> Result<AgentKey, KeyFileError> {
        check_private(path)?;
        let text = std::fs::read_to_string(path).map_err(|e| KeyFileError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        AgentKey::parse(&path.display().to_string(), &text)
    }

    /// The cell this key signs for.
    pub fn cell(&self) -> &str {
        &self.cell
    }

    /// The public key, hex.
    pub fn public_hex(&self) -> String {
        hex::encode(self.key.verifying_key().to_bytes())
    }

    /// The entry the plant trust file needs for this agent.
    pub fn trust_entry(&self) -> String {
        format!(
            "[cells.{}]\npublic_key = \"{}\"\n",
            self.cell,
            self.public_hex()
        )
    }

    /// Seals `body`, put or answered on `key` (an answer: to a query with
    /// `query` as parameters), at `at` (ms).
    pub fn seal(&self, kind: Kind, key: &str, query: &str, at: u64, body: String) -> String {
        let signature = self
            .key
            .sign(&signed_bytes(kind, &self.cell, key, query, at, &body));
        let envelope = Envelope {
            schema: SIGNED_SCHEMA.into(),
            kind,
            cell: self.cell.clone(),
            key: key.into(),
            query: query.into(),
            at,
            body,
            signature: hex::encode(signature.to_bytes()),
        };
        serde_json::to_string(&envelope).unwrap_or_default()
    }
}

/// The plant trust file: each cell's agent's public key.
///
/// ```toml
/// [cells.m01ps0004]
/// public_key = "<64 hex digits>"
/// ```
#[derive(Debug, Clone, Default)]
pub struct Trust {
    cells: BTreeMap<String, VerifyingKey>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TrustFile {
    #[serde(default)]
    cells: BTreeMap<String, TrustEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TrustEntry {
    public_key: String,
}

/// Why an envelope is not believed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Distrust {
    /// Not a signed envelope at all.
    #[error("not a signed envelope ({0})")]
    NotAnEnvelope(String),
    /// A cell the trust file does not know.
    #[error("cell '{0}' is not in the trust file")]
    UnknownCell(String),
    /// The signature does not verify with the cell's key.
    #[error("the signature is not cell {0}'s agent's")]
    BadSignature(String),
    /// Sealed for another key, kind or query than it arrived on.
    #[error("sealed as {sealed}, arrived as {arrived}")]
    Misplaced {
        /// What the envelope says.
        sealed: String,
        /// What the transport says.
        arrived: String,
    },
}

/// What a verified envelope says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Opened {
    /// The cell whose agent sealed it.
    pub cell: String,
    /// Put, reply or error.
    pub kind: Kind,
    /// When it was sealed, ms.
    pub at: u64,
    /// The payload.
    pub body: String,
}

impl Trust {
    /// Reads a trust file's text.
    ///
    /// # Errors
    /// Not a trust file; the message names the file and the cell.
    pub fn parse(origin: &str, text: &str) -> Result<Trust, KeyFileError> {
        let invalid = |reason: String| KeyFileError::Invalid {
            path: origin.into(),
            reason,
        };
        let f: TrustFile = toml::from_str(text).map_err(|e| invalid(e.message().into()))?;
        let mut cells = BTreeMap::new();
        for (cell, entry) in f.cells {
            let key = hex::decode(entry.public_key.trim())
                .ok()
                .and_then(|b| <[u8; 32]>::try_from(b).ok())
                .and_then(|b| VerifyingKey::from_bytes(&b).ok())
                .ok_or_else(|| {
                    invalid(format!(
                        "cells.{cell}.public_key: not an Ed25519 public key (64 hex digits)"
                    ))
                })?;
            cells.insert(cell, key);
        }
        Ok(Trust { cells })
    }

    /// Reads the trust file at `path`.
    ///
    /// # Errors
    /// Unreadable, or not a trust file.
    pub fn load(path: &Path) -> Result<Trust, KeyFileError> {
        let text = std::fs::read_to_string(path).map_err(|e| KeyFileError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Trust::parse(&path.display().to_string(), &text)
    }

    /// Adds (or replaces) `cell`'s public key.
    pub fn insert(&mut self, cell: &str, public: VerifyingKey) {
        self.cells.insert(cell.into(), public);
    }

    /// The cells it knows.
    pub fn cells(&self) -> impl Iterator<Item = &str> {
        self.cells.keys().map(String::as_str)
    }

    /// Opens `payload`, which arrived as `kind` on `key` (an answer: to a
    /// query sent with `query` as parameters): believed only if a known
    /// cell's agent sealed exactly that.
    ///
    /// # Errors
    /// Why it is not believed.
    pub fn open(
        &self,
        payload: &[u8],
        kind: Kind,
        key: &str,
        query: &str,
    ) -> Result<Opened, Distrust> {
        let env: Envelope =
            serde_json::from_slice(payload).map_err(|e| Distrust::NotAnEnvelope(e.to_string()))?;
        if env.schema != SIGNED_SCHEMA {
            return Err(Distrust::NotAnEnvelope(format!("schema '{}'", env.schema)));
        }
        let public = self
            .cells
            .get(&env.cell)
            .ok_or_else(|| Distrust::UnknownCell(env.cell.clone()))?;
        let signature = hex::decode(&env.signature)
            .ok()
            .and_then(|b| <[u8; 64]>::try_from(b).ok())
            .map(|b| Signature::from_bytes(&b))
            .ok_or_else(|| Distrust::BadSignature(env.cell.clone()))?;
        public
            .verify_strict(
                &signed_bytes(env.kind, &env.cell, &env.key, &env.query, env.at, &env.body),
                &signature,
            )
            .map_err(|_| Distrust::BadSignature(env.cell.clone()))?;
        let kind_ok = env.kind == kind || (kind == Kind::Reply && env.kind == Kind::Error);
        if !kind_ok || env.key != key || env.query != query {
            return Err(Distrust::Misplaced {
                sealed: format!("{} on {}?{}", env.kind.as_str(), env.key, env.query),
                arrived: format!("{} on {key}?{query}", kind.as_str()),
            });
        }
        Ok(Opened {
            cell: env.cell,
            kind: env.kind,
            at: env.at,
            body: env.body,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trust_of(key: &AgentKey) -> Trust {
        Trust::parse("trust.toml", &key.trust_entry()).unwrap()
    }

    #[test]
    fn a_sealed_put_opens_with_the_cells_key_only() {
        let m01 = AgentKey::generate("m01");
        let m02 = AgentKey::generate("m02");
        let sealed = m01.seal(Kind::Put, "cellwatch/m01/state", "", 7, "{\"a\":1}".into());
        let opened = trust_of(&m01)
            .open(sealed.as_bytes(), Kind::Put, "cellwatch/m01/state", "")
            .unwrap();
        assert_eq!((opened.cell.as_str(), opened.at), ("m01", 7));
        assert_eq!(opened.body, "{\"a\":1}");
        // Another cell's trust file does not know m01.
        assert_eq!(
            trust_of(&m02).open(sealed.as_bytes(), Kind::Put, "cellwatch/m01/state", ""),
            Err(Distrust::UnknownCell("m01".into()))
        );
        // m02's agent claiming to be m01: its signature is not m01's.
        let mut forged: Envelope =
            serde_json::from_str(&m02.seal(Kind::Put, "cellwatch/m01/state", "", 7, "{}".into()))
                .unwrap();
        forged.cell = "m01".into();
        assert_eq!(
            trust_of(&m01).open(
                serde_json::to_string(&forged).unwrap().as_bytes(),
                Kind::Put,
                "cellwatch/m01/state",
                ""
            ),
            Err(Distrust::BadSignature("m01".into()))
        );
    }

    #[test]
    fn an_envelope_moved_to_another_key_kind_or_query_is_refused() {
        let m01 = AgentKey::generate("m01");
        let trust = trust_of(&m01);
        let put = m01.seal(Kind::Put, "cellwatch/m01/alarms/ese", "", 7, "{}".into());
        assert!(matches!(
            trust.open(put.as_bytes(), Kind::Put, "cellwatch/m01/alarms/csd", ""),
            Err(Distrust::Misplaced { .. })
        ));
        assert!(matches!(
            trust.open(put.as_bytes(), Kind::Reply, "cellwatch/m01/alarms/ese", ""),
            Err(Distrust::Misplaced { .. })
        ));
        let reply = m01.seal(
            Kind::Reply,
            "cellwatch/m01/snapshot",
            "nonce=aa",
            7,
            "{}".into(),
        );
        assert!(trust
            .open(
                reply.as_bytes(),
                Kind::Reply,
                "cellwatch/m01/snapshot",
                "nonce=aa"
            )
            .is_ok());
        // An old answer replayed to a new query.
        assert!(matches!(
            trust.open(
                reply.as_bytes(),
                Kind::Reply,
                "cellwatch/m01/snapshot",
                "nonce=bb"
            ),
            Err(Distrust::Misplaced { .. })
        ));
        // A body edited after sealing.
        let mut edited: Envelope = serde_json::from_str(&reply).unwrap();
        edited.body = "{\"x\":1}".into();
        assert_eq!(
            trust.open(
                serde_json::to_string(&edited).unwrap().as_bytes(),
                Kind::Reply,
                "cellwatch/m01/snapshot",
                "nonce=aa"
            ),
            Err(Distrust::BadSignature("m01".into()))
        );
    }

    #[test]
    fn the_signed_bytes_are_length_prefixed() {
        // A field boundary moved by text inside a field changes the bytes.
        let a = signed_bytes(Kind::Put, "m01", "k", "a\u{0}", 1, "b");
        let b = signed_bytes(Kind::Put, "m01", "k", "a", 1, "\u{0}b");
        assert_ne!(a, b);
        let mut expected = b"cellwatch.signed.v1".to_vec();
        for f in ["put", "m01", "k", "", "12", "{}"] {
            expected.extend_from_slice(&(f.len() as u32).to_be_bytes());
            expected.extend_from_slice(f.as_bytes());
        }
        assert_eq!(signed_bytes(Kind::Put, "m01", "k", "", 12, "{}"), expected);
    }

    #[test]
    fn key_files_round_trip_and_trust_files_name_their_errors() {
        let key = AgentKey::generate("m01");
        let back = AgentKey::parse("m01.key", &key.to_file()).unwrap();
        assert_eq!((back.cell(), back.public_hex()), ("m01", key.public_hex()));
        assert_eq!(
            Trust::parse("trust.toml", "[cells.m01]\npublic_key = \"abc\"\n")
                .unwrap_err()
                .to_string(),
            "trust.toml: cells.m01.public_key: not an Ed25519 public key (64 hex digits)"
        );
        assert!(Trust::parse("trust.toml", "[cells.m01]\nkey = \"abc\"\n").is_err());
    }

    #[cfg(unix)]
    #[test]
    fn a_private_key_others_may_read_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m01.key");
        let (_, made) = AgentKey::load_or_create(&path, "m01").unwrap();
        assert!(made);
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert!(!AgentKey::load_or_create(&path, "m01").unwrap().1);
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let err = AgentKey::load(&path).err().unwrap().to_string();
        assert_eq!(
            err,
            format!(
                "{0}: a private key readable by others (mode 644); make it the owner's only: chmod 600 {0}",
                path.display()
            )
        );
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let err = AgentKey::load_or_create(&path, "m02")
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.ends_with(
                "the signing key of cell 'm01', not of 'm02': each cell's agent has its own"
            ),
            "{err}"
        );
    }
}
