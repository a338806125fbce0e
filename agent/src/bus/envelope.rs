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
//! What one step of the cell loop puts (an alarm event and the machine
//! state it changed, several alarms raised together, the recordings that
//! end together) is sealed with **one** signature (`cellwatch.signed.v2`):
//! each envelope then also carries `group`, the hex SHA-256 digests of the
//! [`signed_bytes`] of every payload sealed with it (its own among them),
//! and `signature` is Ed25519 over [`group_bytes`]: the bytes
//! `cellwatch.signed.v2`, the number of digests as a 4-byte big-endian
//! number, then the 32-byte digests in order. Each envelope still opens on
//! its own: a reader hashes what it got, finds the digest in `group` and
//! verifies the one signature ([`Trust`] verifies a group's signature once
//! and remembers it for its other members). The signature, the one cost
//! that counts in sealing, is made once per step instead of once per
//! payload.
//!
//! This module owns the agent's signing key file ([`AgentKey`]), the plant
//! trust file ([`Trust`]) and the envelope; [`crate::sinks::zenoh`] and
//! [`crate::services`] seal, the CLI opens.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use ed25519_dalek::{Signature, Signer, SigningKey, VerifyingKey};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::clock::thread_cpu_ns;

/// Schema name of the envelope sealed alone.
pub const SIGNED_SCHEMA: &str = "cellwatch.signed.v1";

/// Schema name of an envelope sealed with others under one signature.
pub const GROUP_SCHEMA: &str = "cellwatch.signed.v2";

/// The most payloads one signature may cover; a longer `group` is refused
/// unread.
pub const MAX_GROUP: usize = 1024;

/// How many verified group signatures a [`Trust`] remembers.
const VERIFIED_GROUPS: usize = 256;

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
    /// [`GROUP_SCHEMA`] only: the hex SHA-256 of the [`signed_bytes`] of
    /// each payload sealed together, this one's among them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub group: Vec<String>,
    /// Hex Ed25519 signature of [`signed_bytes`] ([`SIGNED_SCHEMA`]) or of
    /// [`group_bytes`] ([`GROUP_SCHEMA`]).
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

/// The bytes a group's signature covers: `cellwatch.signed.v2`, the number
/// of digests as a 4-byte big-endian number, then each 32-byte digest.
pub fn group_bytes(digests: &[[u8; 32]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(GROUP_SCHEMA.len() + 4 + 32 * digests.len());
    out.extend_from_slice(GROUP_SCHEMA.as_bytes());
    let n = u32::try_from(digests.len()).unwrap_or(u32::MAX);
    out.extend_from_slice(&n.to_be_bytes());
    for d in digests {
        out.extend_from_slice(d);
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
    /// Signatures made, and the thread CPU time they took (ns).
    signatures: AtomicU64,
    signing_ns: AtomicU64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct AgentKeyFile {
    cell: String,
    private_key: String,
}

impl AgentKey {
    fn new(cell: String, key: SigningKey) -> AgentKey {
        AgentKey {
            cell,
            key,
            signatures: AtomicU64::new(0),
            signing_ns: AtomicU64::new(0),
        }
    }

    /// Signs `bytes`, counting the signature and the CPU time it took.
    fn sign(&self, bytes: &[u8]) -> Signature {
        let start = thread_cpu_ns();
        let signature = self.key.sign(bytes);
        let took = thread_cpu_ns().saturating_sub(start);
        self.signatures.fetch_add(1, Ordering::Relaxed);
        self.signing_ns.fetch_add(took, Ordering::Relaxed);
        signature
    }

    /// Signatures made so far, and the CPU seconds they took (the signing
    /// thread's own time, not the wall clock's).
    pub fn signing(&self) -> (u64, f64) {
        (
            self.signatures.load(Ordering::Relaxed),
            self.signing_ns.load(Ordering::Relaxed) as f64 / 1e9,
        )
    }

    /// A new random key for `cell`'s agent.
    pub fn generate(cell: &str) -> AgentKey {
        AgentKey::new(
            cell.into(),
            SigningKey::from_bytes(&rand::random::<[u8; 32]>()),
        )
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
        Ok(AgentKey::new(f.cell, SigningKey::from_bytes(&bytes)))
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
        let signature = self.sign(&signed_bytes(kind, &self.cell, key, query, at, &body));
        let envelope = Envelope {
            schema: SIGNED_SCHEMA.into(),
            kind,
            cell: self.cell.clone(),
            key: key.into(),
            query: query.into(),
            at,
            body,
            group: Vec::new(),
            signature: hex::encode(signature.to_bytes()),
        };
        serde_json::to_string(&envelope).unwrap_or_default()
    }

    /// Seals publications put together, `(key, body)` each, at `at` (ms):
    /// one signature over them all ([`GROUP_SCHEMA`]); one alone is sealed
    /// as [`AgentKey::seal`] does. The envelopes come back in `puts`'
    /// order.
    pub fn seal_puts(&self, at: u64, puts: Vec<(String, String)>) -> Vec<String> {
        if puts.len() < 2 || puts.len() > MAX_GROUP {
            return puts
                .into_iter()
                .map(|(key, body)| self.seal(Kind::Put, &key, "", at, body))
                .collect();
        }
        let digests: Vec<[u8; 32]> = puts
            .iter()
            .map(|(key, body)| {
                Sha256::digest(signed_bytes(Kind::Put, &self.cell, key, "", at, body)).into()
            })
            .collect();
        let signature = hex::encode(self.sign(&group_bytes(&digests)).to_bytes());
        let group: Vec<String> = digests.iter().map(hex::encode).collect();
        puts.into_iter()
            .map(|(key, body)| {
                let envelope = Envelope {
                    schema: GROUP_SCHEMA.into(),
                    kind: Kind::Put,
                    cell: self.cell.clone(),
                    key,
                    query: String::new(),
                    at,
                    body,
                    group: group.clone(),
                    signature: signature.clone(),
                };
                serde_json::to_string(&envelope).unwrap_or_default()
            })
            .collect()
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
    /// Group signatures verified lately: the SHA-256 of the public key,
    /// the [`group_bytes`] and the signature, the newest last.
    verified: Arc<Mutex<VecDeque<[u8; 32]>>>,
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
        Ok(Trust {
            cells,
            verified: Arc::default(),
        })
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
        let grouped = match env.schema.as_str() {
            SIGNED_SCHEMA if env.group.is_empty() => false,
            GROUP_SCHEMA if (2..=MAX_GROUP).contains(&env.group.len()) => true,
            SIGNED_SCHEMA | GROUP_SCHEMA => {
                return Err(Distrust::NotAnEnvelope(format!(
                    "{} with a group of {}",
                    env.schema,
                    env.group.len()
                )))
            }
            other => return Err(Distrust::NotAnEnvelope(format!("schema '{other}'"))),
        };
        let public = self
            .cells
            .get(&env.cell)
            .ok_or_else(|| Distrust::UnknownCell(env.cell.clone()))?;
        let bad = || Distrust::BadSignature(env.cell.clone());
        let signature = hex::decode(&env.signature)
            .ok()
            .and_then(|b| <[u8; 64]>::try_from(b).ok())
            .map(|b| Signature::from_bytes(&b))
            .ok_or_else(bad)?;
        let signed = signed_bytes(env.kind, &env.cell, &env.key, &env.query, env.at, &env.body);
        if grouped {
            self.verify_group(public, &signed, &env.group, &signature)
                .ok_or_else(bad)?;
        } else {
            public
                .verify_strict(&signed, &signature)
                .map_err(|_| bad())?;
        }
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

    /// Whether `group`'s `signature` is `public`'s and covers `signed`:
    /// verified once per group, remembered for its other members.
    fn verify_group(
        &self,
        public: &VerifyingKey,
        signed: &[u8],
        group: &[String],
        signature: &Signature,
    ) -> Option<()> {
        let own: [u8; 32] = Sha256::digest(signed).into();
        let mut digests = Vec::with_capacity(group.len());
        for d in group {
            let mut digest = [0u8; 32];
            hex::decode_to_slice(d, &mut digest).ok()?;
            digests.push(digest);
        }
        if !digests.contains(&own) {
            return None;
        }
        let bytes = group_bytes(&digests);
        let mut seen = Sha256::new();
        seen.update(public.as_bytes());
        seen.update(&bytes);
        seen.update(signature.to_bytes());
        let seen: [u8; 32] = seen.finalize().into();
        let verified = |v: &VecDeque<[u8; 32]>| v.contains(&seen);
        if self.verified.lock().is_ok_and(|v| verified(&v)) {
            return Some(());
        }
        public.verify_strict(&bytes, signature).ok()?;
        if let Ok(mut v) = self.verified.lock() {
            if v.len() == VERIFIED_GROUPS {
                v.pop_front();
            }
            v.push_back(seen);
        }
        Some(())
    }
}

#[cfg(test)]
mod tests;
