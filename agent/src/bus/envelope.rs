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
//! state it changed, the alarms one cause raised together, the recordings
//! that end together) is sealed with **one** signature
//! (`cellwatch.signed.v2`): the [`signed_bytes`] of each payload are the
//! leaves of a Merkle tree (RFC 9162's, as Certificate Transparency's:
//! [`tree`]), and `signature` is Ed25519 over [`tree_bytes`]: the bytes
//! `cellwatch.signed.v2`, the number of leaves as a 4-byte big-endian
//! number and the 32-byte root. Each envelope carries its place in the
//! tree, `"tree": {"size", "index", "path"}` (its inclusion path, hex, at
//! most 16 hashes for the largest step), and opens on its own: a reader
//! hashes what it got, climbs the path to the root (RFC 9162 §2.1.3.2) and
//! verifies the one signature ([`Trust`] remembers a verified root for the
//! step's other envelopes). The signature, the one cost that counts in
//! sealing, is made once per step instead of once per payload; an envelope
//! grows by its path only.
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

/// The most payloads one signature covers; a step that puts more is
/// sealed in trees of this many.
pub const MAX_GROUP: usize = 65_536;

/// How many verified roots a [`Trust`] remembers.
const VERIFIED_ROOTS: usize = 256;

mod tree;

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
    /// [`GROUP_SCHEMA`] only: its place in the tree of the payloads sealed
    /// together.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tree: Option<InTree>,
    /// Hex Ed25519 signature of [`signed_bytes`] ([`SIGNED_SCHEMA`]) or of
    /// [`tree_bytes`] ([`GROUP_SCHEMA`]).
    pub signature: String,
}

/// An envelope's place in the Merkle tree of the payloads sealed with it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InTree {
    /// How many payloads were sealed together (2 to [`MAX_GROUP`]).
    pub size: u64,
    /// This one's number among them, from 0.
    pub index: u64,
    /// Its inclusion path (RFC 9162 §2.1.3.1): the sibling hashes from the
    /// leaf up, hex.
    pub path: Vec<String>,
}

/// An envelope as it is written: the fields borrowed.
#[derive(Serialize)]
struct Writing<'a> {
    schema: &'a str,
    kind: Kind,
    cell: &'a str,
    key: &'a str,
    query: &'a str,
    at: u64,
    body: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    tree: Option<InTree>,
    signature: &'a str,
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

/// The bytes the signature of payloads sealed together covers:
/// `cellwatch.signed.v2`, the number of payloads as a 4-byte big-endian
/// number, then the tree's 32-byte root.
pub fn tree_bytes(size: u64, root: &[u8; 32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(GROUP_SCHEMA.len() + 4 + 32);
    out.extend_from_slice(GROUP_SCHEMA.as_bytes());
    out.extend_from_slice(&u32::try_from(size).unwrap_or(u32::MAX).to_be_bytes());
    out.extend_from_slice(root);
    out
}

/// Payloads put together, sealed under one signature by
/// [`AgentKey::seal_puts`]: each envelope is written when it is put.
pub struct SealedPuts<'a> {
    key: &'a AgentKey,
    at: u64,
    size: usize,
    /// Hex; `None` for one payload alone, sealed on its own.
    signature: Option<String>,
    paths: Vec<Vec<tree::Hash>>,
}

impl SealedPuts<'_> {
    /// The envelope of payload `index`, put on `key` with `body` — the
    /// same as were sealed.
    pub fn envelope(&self, index: usize, key: &str, body: &str) -> String {
        let Some(signature) = &self.signature else {
            return self.key.seal(Kind::Put, key, "", self.at, body.to_string());
        };
        let envelope = Writing {
            schema: GROUP_SCHEMA,
            kind: Kind::Put,
            cell: &self.key.cell,
            key,
            query: "",
            at: self.at,
            body,
            tree: Some(InTree {
                size: self.size as u64,
                index: index as u64,
                path: self
                    .paths
                    .get(index)
                    .map_or_else(Vec::new, |p| p.iter().map(hex::encode).collect()),
            }),
            signature,
        };
        serde_json::to_string(&envelope).unwrap_or_default()
    }
}

/// Why a key or trust file is refused.
#[derive(Debug, thiserror::Error)]
pub enum KeyFileError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file cannot be made.
    #[error(transparent)]
    Write(#[from] super::certs::CertError),
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
    let meta = std::fs::metadata(path).map_err(|source| KeyFileError::Io {
        path: path.display().to_string(),
        source,
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

/// [`check_private`] for each private key file a process reads (a
/// console's HTTPS and bus TLS keys, an agent's): every one refused, in
/// order, so that a configuration's check can say them all at once.
///
/// # Errors
/// Each file that cannot be looked at or that others may read.
pub fn check_private_keys<'a>(
    paths: impl IntoIterator<Item = &'a Path>,
) -> Result<(), Vec<KeyFileError>> {
    let refused: Vec<KeyFileError> = paths
        .into_iter()
        .filter_map(|p| check_private(p).err())
        .collect();
    if refused.is_empty() {
        Ok(())
    } else {
        Err(refused)
    }
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
        if !path.exists() {
            let key = AgentKey::generate(cell);
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(|source| KeyFileError::Io {
                    path: dir.display().to_string(),
                    source,
                })?;
            }
            match super::certs::write_private(path, &key.to_file()) {
                Ok(()) => return Ok((key, true)),
                // Made meanwhile by another agent of the same cell starting:
                // read below.
                Err(_) if path.exists() => {}
                Err(e) => return Err(e.into()),
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
        let text = std::fs::read_to_string(path).map_err(|source| KeyFileError::Io {
            path: path.display().to_string(),
            source,
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
            tree: None,
            signature: hex::encode(signature.to_bytes()),
        };
        serde_json::to_string(&envelope).unwrap_or_default()
    }

    /// Seals publications put together, `(key, body)` each, at `at` (ms):
    /// one signature over them all ([`GROUP_SCHEMA`]); one alone is sealed
    /// as [`AgentKey::seal`] does, and so is each of a list longer than
    /// [`MAX_GROUP`] (which no reader would take as one tree: the caller
    /// splits it). Each envelope is then written by [`SealedPuts::envelope`]
    /// with the same key and body.
    pub fn seal_puts(&self, at: u64, puts: &[(&str, &str)]) -> SealedPuts<'_> {
        let size = puts.len();
        if !(2..=MAX_GROUP).contains(&size) {
            return SealedPuts {
                key: self,
                at,
                size,
                signature: None,
                paths: Vec::new(),
            };
        }
        let leaves: Vec<tree::Hash> = puts
            .iter()
            .map(|(key, body)| tree::leaf(&signed_bytes(Kind::Put, &self.cell, key, "", at, body)))
            .collect();
        let (root, paths) = tree::root_and_paths(&leaves);
        let signature = self.sign(&tree_bytes(size as u64, &root));
        SealedPuts {
            key: self,
            at,
            size,
            signature: Some(hex::encode(signature.to_bytes())),
            paths,
        }
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
    /// Each cell's keys: its current one first, then those it is being
    /// rotated from (`previous_keys`), each believed.
    cells: BTreeMap<String, Vec<VerifyingKey>>,
    /// Roots verified lately: the SHA-256 of the public key, the
    /// [`tree_bytes`] and the signature, the newest last.
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
    /// Keys the agent is being rotated from, believed until removed.
    #[serde(default)]
    previous_keys: Vec<String>,
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
            let mut keys = Vec::new();
            let texts = std::iter::once(("public_key", &entry.public_key))
                .chain(entry.previous_keys.iter().map(|k| ("previous_keys", k)));
            for (name, text) in texts {
                let key = hex::decode(text.trim())
                    .ok()
                    .and_then(|b| <[u8; 32]>::try_from(b).ok())
                    .and_then(|b| VerifyingKey::from_bytes(&b).ok())
                    .ok_or_else(|| {
                        invalid(format!(
                            "cells.{cell}.{name}: not an Ed25519 public key (64 hex digits)"
                        ))
                    })?;
                keys.push(key);
            }
            cells.insert(cell, keys);
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
        let text = std::fs::read_to_string(path).map_err(|source| KeyFileError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Trust::parse(&path.display().to_string(), &text)
    }

    /// Adds (or replaces) `cell`'s public key.
    pub fn insert(&mut self, cell: &str, public: VerifyingKey) {
        self.cells.insert(cell.into(), vec![public]);
    }

    /// Cell `cell`'s current public key (hex), if it knows the cell.
    pub fn public_hex(&self, cell: &str) -> Option<String> {
        self.cells
            .get(cell)
            .and_then(|k| k.first())
            .map(|k| hex::encode(k.as_bytes()))
    }

    /// The keys cell `cell` is being rotated from (hex).
    pub fn previous_hex(&self, cell: &str) -> Vec<String> {
        self.cells.get(cell).map_or_else(Vec::new, |k| {
            k.iter()
                .skip(1)
                .map(|k| hex::encode(k.as_bytes()))
                .collect()
        })
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
        let placed = match (env.schema.as_str(), &env.tree) {
            (SIGNED_SCHEMA, None) => None,
            (GROUP_SCHEMA, Some(t))
                if (2..=MAX_GROUP as u64).contains(&t.size) && t.path.len() <= tree::MAX_PATH =>
            {
                Some(t)
            }
            (SIGNED_SCHEMA, Some(_)) => {
                return Err(Distrust::NotAnEnvelope(format!(
                    "{SIGNED_SCHEMA} with a tree"
                )))
            }
            (GROUP_SCHEMA, _) => {
                return Err(Distrust::NotAnEnvelope(format!(
                    "{GROUP_SCHEMA} without a tree of 2 to {MAX_GROUP} payloads"
                )))
            }
            (other, _) => return Err(Distrust::NotAnEnvelope(format!("schema '{other}'"))),
        };
        let keys = self
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
        let verified = keys.iter().any(|public| match placed {
            Some(place) => self
                .verify_in_tree(public, &signed, place, &signature)
                .is_some(),
            None => public.verify_strict(&signed, &signature).is_ok(),
        });
        if !verified {
            return Err(bad());
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

    /// Whether `signed`, at `place` in its tree, reaches a root that
    /// `signature` of `public` covers: each root verified once, remembered
    /// for the tree's other envelopes.
    fn verify_in_tree(
        &self,
        public: &VerifyingKey,
        signed: &[u8],
        place: &InTree,
        signature: &Signature,
    ) -> Option<()> {
        let mut path = Vec::with_capacity(place.path.len());
        for h in &place.path {
            let mut hash = [0u8; 32];
            hex::decode_to_slice(h, &mut hash).ok()?;
            path.push(hash);
        }
        let root = tree::root_from(place.index, place.size, tree::leaf(signed), &path)?;
        let bytes = tree_bytes(place.size, &root);
        let mut seen = Sha256::new();
        seen.update(public.as_bytes());
        seen.update(&bytes);
        seen.update(signature.to_bytes());
        let seen: [u8; 32] = seen.finalize().into();
        if self.verified.lock().is_ok_and(|v| v.contains(&seen)) {
            return Some(());
        }
        public.verify_strict(&bytes, signature).ok()?;
        if let Ok(mut v) = self.verified.lock() {
            if v.len() == VERIFIED_ROOTS {
                v.pop_front();
            }
            v.push_back(seen);
        }
        Some(())
    }
}

#[cfg(test)]
mod tests;
