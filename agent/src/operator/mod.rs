//! Operator commands and their authorisation.
//!
//! Every operator has an Ed25519 key pair of their own (`cellwatch keygen
//! --operator NAME`): the private key stays with the operator, the agent's
//! operators file holds only public keys and, per operator, the actions
//! allowed. A command names its operator and carries a signature over a
//! canonical text of the request ([`Command::canonical`]: every field
//! length-prefixed, so no two commands sign the same text). The agent
//! refuses a command with a control character in a field or a nonce out of
//! format, one that is unsigned, badly signed, from an unknown operator,
//! for an action the operator may not take, issued more than [`MAX_SKEW`]
//! away from its clock, or whose nonce it has seen (a replay). A stolen
//! agent disk signs nothing. The caller journals what the gate says:
//! refusals before a known operator's signature is verified are counted
//! and summarised ([`refusals`]), everything after it in full.
//!
//! Also here: [`escaped`], how every printer shows text an operator or a
//! journal supplies.

mod key_error;
pub(crate) mod plant;
pub(crate) mod refusals;

pub use key_error::KeyError;

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::path::Path;

use ed25519_dalek::{Signature, Signer, SigningKey, VerifyingKey};
use serde::{Deserialize, Serialize};
use sha2::Sha256;

/// How far a command's time may be from the agent's clock.
pub const MAX_SKEW_MS: u64 = 60_000;
/// Same, as a name for documentation.
pub const MAX_SKEW: &str = "60 s";

/// What an operator asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Action {
    /// Acknowledge an alarm.
    Ack,
    /// Reset a latched alarm whose condition has ended.
    Reset,
    /// Write a value to the PLC (a legacy unit's item code, target or
    /// production correction).
    Write,
    /// Shelve an alarm for a while, or until it clears (one-shot).
    Shelve,
    /// End an alarm's shelf.
    Unshelve,
    /// Take an alarm out of service (not raised whatever its condition).
    #[serde(rename = "out-of-service")]
    OutOfService,
    /// Put an alarm back in service.
    #[serde(rename = "in-service")]
    InService,
    /// Fire a stuck step's transition by the force switch (paper 004),
    /// only while its condition holds.
    Force,
    /// Press the remote stop switch.
    Stop,
    /// Change the agent's configuration: `value` `reload`, the file read
    /// again and taken live (as on SIGHUP).
    Configure,
}

impl Action {
    /// Every action.
    pub const ALL: [Action; 10] = [
        Action::Ack,
        Action::Reset,
        Action::Write,
        Action::Shelve,
        Action::Unshelve,
        Action::OutOfService,
        Action::InService,
        Action::Force,
        Action::Stop,
        Action::Configure,
    ];

    /// The name on the wire, in the journal and in operators files.
    pub fn as_str(self) -> &'static str {
        match self {
            Action::Ack => "ack",
            Action::Reset => "reset",
            Action::Write => "write",
            Action::Shelve => "shelve",
            Action::Unshelve => "unshelve",
            Action::OutOfService => "out-of-service",
            Action::InService => "in-service",
            Action::Force => "force",
            Action::Stop => "stop",
            Action::Configure => "configure",
        }
    }

    /// The action named `name`.
    pub fn parse(name: &str) -> Option<Action> {
        Action::ALL.into_iter().find(|a| a.as_str() == name)
    }
}

impl std::fmt::Display for Action {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A signed operator command, as sent to `<prefix>/command`. An unknown
/// action does not parse: it is refused, never taken for another.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Command {
    /// What to do.
    pub action: Action,
    /// The alarm id (`ack`, `reset`); empty for `write`.
    #[serde(default)]
    pub alarm: String,
    /// The tag written, by address (`write` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tag: Option<String>,
    /// The value written (`write`), how long to shelve (`shelve`: a
    /// duration such as `30m`, or `once` for one-shot), the transition
    /// forced (`force`: `CHART.TRANSITION`) or the chart stopped (`stop`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<String>,
    /// Why (`shelve`, `out-of-service`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Who sends it.
    pub operator: String,
    /// A value never used before (random hex).
    pub nonce: String,
    /// When it was issued, ms since the epoch.
    pub issued_at: u64,
    /// Hex Ed25519 signature of [`Command::canonical`] with the operator's
    /// private key.
    #[serde(default)]
    pub signature: String,
}

impl Command {
    /// The bytes that are signed ([`CANONICAL_VERSION`]): the version line,
    /// then each field as `<byte length>:<bytes>\n` in a fixed order (cell,
    /// action, alarm, operator, nonce, issued_at, tag, value, reason), a
    /// field the command does not carry (`tag`, `value`, `reason` absent) as
    /// `-\n`. No two commands have the same text, whatever their fields
    /// hold.
    pub fn canonical(&self, cell: &str) -> Vec<u8> {
        let mut text = format!("{CANONICAL_VERSION}\n").into_bytes();
        let mut field = |f: Option<&str>| match f {
            Some(f) => {
                text.extend_from_slice(format!("{}:", f.len()).as_bytes());
                text.extend_from_slice(f.as_bytes());
                text.push(b'\n');
            }
            None => text.extend_from_slice(b"-\n"),
        };
        field(Some(cell));
        field(Some(self.action.as_str()));
        field(Some(&self.alarm));
        field(Some(&self.operator));
        field(Some(&self.nonce));
        field(Some(&self.issued_at.to_string()));
        field(self.tag.as_deref());
        field(self.value.as_deref());
        field(self.reason.as_deref());
        text
    }

    /// SHA-256 of the command as signed: its canonical text (without its
    /// cell, the agent's own) and its signature. The same signed command
    /// has the same digest however its JSON was spaced or ordered, and
    /// from one version of the agent to the next; the journal keeps it
    /// with the command's rows, so that a command sent again after a
    /// restart is told apart from another with the same nonce.
    pub fn digest(&self) -> [u8; 32] {
        use sha2::Digest;
        let mut hash = sha2::Sha256::new();
        hash.update(self.canonical(""));
        hash.update(format!("{}:{}\n", self.signature.len(), self.signature).as_bytes());
        hash.finalize().into()
    }

    /// Signs the command for `cell` with the operator's private key.
    pub fn sign(&mut self, cell: &str, key: &OperatorKey) {
        self.signature = hex::encode(key.key.sign(&self.canonical(cell)).to_bytes());
    }

    /// The fields an operator writes, by name (what the gate and the CLI
    /// check for control characters).
    pub fn texts(&self) -> [(&'static str, &str); 5] {
        [
            ("operator", &self.operator),
            ("alarm", &self.alarm),
            ("tag", self.tag.as_deref().unwrap_or("")),
            ("value", self.value.as_deref().unwrap_or("")),
            ("reason", self.reason.as_deref().unwrap_or("")),
        ]
    }

    /// Checks what the operator wrote before it is signed or carried out:
    /// no field holds a control character (a newline would write a line
    /// of its own into the journal's and the CLI's output), and the nonce
    /// has its format ([`valid_nonce`]).
    ///
    /// # Errors
    /// The first field that does not pass, as a [`Refusal`].
    pub fn check_text(&self) -> Result<(), Refusal> {
        if let Some((field, _)) = self.texts().into_iter().find(|(_, t)| !printable_only(t)) {
            return Err(Refusal::ControlCharacter(field));
        }
        if !valid_nonce(&self.nonce) {
            return Err(Refusal::BadNonce);
        }
        Ok(())
    }
}

/// The first line of the signed text of a command ([`Command::canonical`]).
pub const CANONICAL_VERSION: &str = "cellwatch-command-v5";

/// The shortest and longest nonce, in hex digits.
pub const NONCE_DIGITS: std::ops::RangeInclusive<usize> = 16..=64;

/// Whether `nonce` is 16 to 64 lowercase hex digits: short enough to be
/// journaled whole (so that it is known again after a restart), long
/// enough not to repeat.
pub fn valid_nonce(nonce: &str) -> bool {
    NONCE_DIGITS.contains(&nonce.len())
        && nonce
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Whether `c` may change what a printed line looks like: a control
/// character (newline, carriage return, escape, …), a line or paragraph
/// separator, or a bidirectional override.
pub fn is_unprintable(c: char) -> bool {
    c.is_control()
        || matches!(
            c,
            '\u{2028}' | '\u{2029}' | '\u{200e}' | '\u{200f}' | '\u{061c}'
        )
        || ('\u{202a}'..='\u{202e}').contains(&c)
        || ('\u{2066}'..='\u{2069}').contains(&c)
}

/// Whether `text` holds no [unprintable](is_unprintable) character.
pub fn printable_only(text: &str) -> bool {
    !text.chars().any(is_unprintable)
}

/// `text` ready to print on one line: each [unprintable](is_unprintable)
/// character escaped as Rust writes it (`\n`, `\u{1b}`), a backslash
/// doubled, everything else (letters of any script) kept. What every
/// printer of operator or journal text uses.
pub fn escaped(text: &str) -> std::borrow::Cow<'_, str> {
    if printable_only(text) && !text.contains('\\') {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        if c == '\\' || is_unprintable(c) {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

/// An operator's private key, as `cellwatch keygen` writes it. Kept by the
/// operator, never on an agent.
pub struct OperatorKey {
    /// Whose key.
    pub operator: String,
    key: SigningKey,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyFile {
    operator: String,
    private_key: String,
}

impl OperatorKey {
    /// A new random key for `operator`.
    pub fn generate(operator: &str) -> OperatorKey {
        OperatorKey {
            operator: operator.into(),
            key: SigningKey::from_bytes(&rand::random::<[u8; 32]>()),
        }
    }

    /// The key from its 32-byte hex seed.
    ///
    /// # Errors
    /// Not 64 hex digits.
    pub fn from_hex(operator: &str, hex_key: &str) -> Result<OperatorKey, KeyError> {
        let bytes: [u8; 32] = hex::decode(hex_key.trim())
            .ok()
            .and_then(|b| b.try_into().ok())
            .ok_or(KeyError::NotHex)?;
        Ok(OperatorKey {
            operator: operator.into(),
            key: SigningKey::from_bytes(&bytes),
        })
    }

    /// Reads a key file (`operator = "…"`, `private_key = "<hex>"`).
    ///
    /// # Errors
    /// The file is not a key file; the message names it.
    pub fn parse(origin: &str, text: &str) -> Result<OperatorKey, KeyError> {
        let f: KeyFile = toml::from_str(text).map_err(|e| KeyError::Syntax {
            origin: origin.into(),
            message: e.message().into(),
        })?;
        Self::from_hex(&f.operator, &f.private_key).map_err(|e| KeyError::PrivateKey {
            origin: origin.into(),
            source: Box::new(e),
        })
    }

    /// The key file's text.
    pub fn to_file(&self) -> String {
        format!(
            "# cellwatch operator key of '{}'. PRIVATE: keep it on the operator's machine\n\
             # (chmod 600), never on an agent. Agents hold only the public key.\n\
             operator = \"{}\"\nprivate_key = \"{}\"\n",
            self.operator,
            self.operator,
            hex::encode(self.key.to_bytes())
        )
    }

    /// The public key.
    pub fn public(&self) -> VerifyingKey {
        self.key.verifying_key()
    }

    /// The public key, hex.
    pub fn public_hex(&self) -> String {
        hex::encode(self.key.verifying_key().to_bytes())
    }

    /// The entry an agent's operators file needs for this operator.
    pub fn operators_entry(&self, allow: &[Action]) -> String {
        let allow: Vec<String> = allow.iter().map(|a| format!("\"{a}\"")).collect();
        format!(
            "[operators.{}]\npublic_key = \"{}\"\nallow = [{}]\n",
            self.operator,
            self.public_hex(),
            allow.join(", ")
        )
    }
}

/// What an operator's name may hold, said in errors.
pub const OPERATOR_NAME: &str = "letters, digits, '-' or '_' (a bare key in the operators file)";

/// Whether `name` can name an operator: ASCII letters, digits, `-` and `_`,
/// what TOML writes as a bare key (`[operators.NAME]`).
pub fn valid_operator_name(name: &str) -> bool {
    !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

/// Why the operators file cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum KeysError {
    /// The file cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid TOML of the expected shape.
    #[error("{origin}: {message}")]
    Syntax {
        /// The file.
        origin: String,
        /// TOML's message.
        message: String,
    },
    /// An entry is wrong; the message says how.
    #[error("{origin}: operators.{operator}: {message}")]
    Entry {
        /// The file.
        origin: String,
        /// Whose entry.
        operator: String,
        /// What is wrong.
        message: String,
    },
}

/// Why a command is refused at the gate.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// No signature.
    #[error("unsigned command")]
    Unsigned,
    /// No key for this operator.
    #[error("unknown operator '{0}'")]
    UnknownOperator(String),
    /// The signature is not hex.
    #[error("signature is not hex")]
    SignatureNotHex,
    /// The signature does not match.
    #[error("bad signature")]
    BadSignature,
    /// The operator may not take this action.
    #[error("operator '{operator}' may not {action}")]
    NotAllowed {
        /// Who.
        operator: String,
        /// What.
        action: Action,
    },
    /// Issued too far from the agent's clock.
    #[error("issued {0} ms away from the agent's clock (more than {MAX_SKEW})")]
    Skew(u64),
    /// The nonce was used before.
    #[error("replayed command (nonce already used)")]
    Replay,
    /// A field holds a control character (a newline, a tab, an escape…).
    #[error("{0} holds a control character (a newline, tab or escape): write it on one line")]
    ControlCharacter(&'static str),
    /// The nonce is not 16 to 64 lowercase hex digits.
    #[error("nonce is not 16 to 64 lowercase hex digits")]
    BadNonce,
}

impl Refusal {
    /// Why the command was refused before anyone was known to have sent
    /// it (`cellwatch_requests_refused_total`'s reason), or `None` when the
    /// signature of a known operator was verified.
    pub fn unauthenticated(&self) -> Option<&'static str> {
        match self {
            Refusal::Unsigned => Some("unsigned"),
            Refusal::UnknownOperator(_) => Some("unknown_operator"),
            Refusal::SignatureNotHex | Refusal::BadSignature => Some("bad_signature"),
            Refusal::ControlCharacter(_) | Refusal::BadNonce => Some("malformed"),
            Refusal::NotAllowed { .. } | Refusal::Skew(_) | Refusal::Replay => None,
        }
    }
}

/// One operator as an agent knows them: a public key and what they may do.
#[derive(Debug, Clone)]
struct Operator {
    key: VerifyingKey,
    allow: BTreeSet<Action>,
}

/// The operators an agent accepts commands from (public keys only).
#[derive(Default, Debug)]
pub struct OperatorKeys {
    operators: HashMap<String, Operator>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OperatorsFile {
    operators: HashMap<String, toml::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OperatorEntry {
    public_key: String,
    allow: Vec<String>,
}

impl OperatorKeys {
    /// Parses an operators file's text.
    ///
    /// # Errors
    /// Malformed TOML, a key that is not an Ed25519 public key, an unknown
    /// action, or a shared secret of the old format.
    pub fn parse(origin: &str, text: &str) -> Result<OperatorKeys, KeysError> {
        let f: OperatorsFile = toml::from_str(text).map_err(|e| KeysError::Syntax {
            origin: origin.into(),
            message: e.message().into(),
        })?;
        let entry_error = |operator: &str, message: String| KeysError::Entry {
            origin: origin.into(),
            operator: operator.into(),
            message,
        };
        let mut operators = HashMap::new();
        for (name, value) in f.operators {
            if !valid_operator_name(&name) {
                return Err(entry_error(
                    &format!("{name:?}"),
                    format!("an operator's name is {OPERATOR_NAME}"),
                ));
            }
            if value.is_str() {
                return Err(entry_error(
                    &name,
                    format!("a shared secret is no longer accepted: operators sign with their own key; run `cellwatch keygen --operator {name}` and put the public_key and allow it prints here"),
                ));
            }
            let e: OperatorEntry = value
                .try_into()
                .map_err(|e: toml::de::Error| entry_error(&name, e.message().to_string()))?;
            let key = hex::decode(e.public_key.trim())
                .ok()
                .and_then(|b| <[u8; 32]>::try_from(b).ok())
                .and_then(|b| VerifyingKey::from_bytes(&b).ok())
                .ok_or_else(|| {
                    entry_error(
                        &name,
                        "public_key: not an Ed25519 public key (64 hex digits)".into(),
                    )
                })?;
            let mut allow = BTreeSet::new();
            for a in &e.allow {
                let action = Action::parse(a).ok_or_else(|| {
                    let known: Vec<&str> = Action::ALL.iter().map(|a| a.as_str()).collect();
                    entry_error(
                        &name,
                        format!("allow: unknown action '{a}': use {}", known.join(", ")),
                    )
                })?;
                allow.insert(action);
            }
            operators.insert(name, Operator { key, allow });
        }
        Ok(OperatorKeys { operators })
    }

    /// Loads the operators file.
    ///
    /// # Errors
    /// The file cannot be read or parsed.
    pub fn load(path: &Path) -> Result<OperatorKeys, KeysError> {
        let text = std::fs::read_to_string(path).map_err(|source| KeysError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&path.display().to_string(), &text)
    }

    /// How many operators are known.
    pub fn len(&self) -> usize {
        self.operators.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.operators.is_empty()
    }

    /// Every operator, by name: the public key (hex) and the actions
    /// allowed.
    pub fn entries(&self) -> Vec<(String, String, Vec<Action>)> {
        let mut entries: Vec<_> = self
            .operators
            .iter()
            .map(|(name, o)| {
                (
                    name.clone(),
                    hex::encode(o.key.to_bytes()),
                    o.allow.iter().copied().collect(),
                )
            })
            .collect();
        entries.sort();
        entries
    }
}

/// Checks signatures and permissions, and remembers nonces.
pub struct Gate {
    cell: String,
    keys: OperatorKeys,
    /// The plant operators list `keys` come from, if they do.
    plant_version: Option<u64>,
    /// Nonces seen within the skew window, oldest first.
    seen: VecDeque<(u64, String)>,
}

impl Gate {
    /// The operators read again (a reload): the nonces seen stay seen.
    pub fn set_keys(&mut self, keys: OperatorKeys) {
        self.keys = keys;
    }

    /// The operators of a configuration read again, from plant operators
    /// list `version` (`None`: the operators file): kept out when the
    /// gate already judges by a newer list.
    pub fn reloaded(&mut self, keys: OperatorKeys, version: Option<u64>) {
        if self.plant_version <= version {
            self.keys = keys;
            self.plant_version = version;
        }
    }

    /// The operators of plant operators list `version`.
    pub fn from_plant(&mut self, keys: OperatorKeys, version: u64) {
        self.keys = keys;
        self.plant_version = Some(version);
    }

    /// The operators it judges by.
    pub fn keys(&self) -> &OperatorKeys {
        &self.keys
    }

    /// A gate for `cell` with `keys`.
    pub fn new(cell: &str, keys: OperatorKeys) -> Gate {
        Gate {
            cell: cell.into(),
            keys,
            plant_version: None,
            seen: VecDeque::new(),
        }
    }

    /// Marks `nonce`, used at `at`, as seen (nonces of verified commands
    /// read back from the journal at start, so a replay is refused across
    /// a restart).
    pub fn remember(&mut self, at: u64, nonce: String) {
        self.seen.push_back((at, nonce));
    }

    /// How far back nonces must be remembered, ms: a command older than
    /// this is refused for its skew anyway.
    pub const NONCE_WINDOW_MS: u64 = 2 * MAX_SKEW_MS;

    /// Whether `operator` may `action`, for a command whose sender was
    /// authenticated otherwise than by a signature (the alarm server's
    /// OPC UA session): no signature, time or nonce to check.
    ///
    /// # Errors
    /// The operator is not known, or may not `action`.
    pub fn permits(&self, operator: &str, action: Action) -> Result<(), Refusal> {
        let Some(known) = self.keys.operators.get(operator) else {
            return Err(Refusal::UnknownOperator(operator.into()));
        };
        if !known.allow.contains(&action) {
            return Err(Refusal::NotAllowed {
                operator: operator.into(),
                action,
            });
        }
        Ok(())
    }

    /// Lets `cmd` through at `now`, or says why not.
    ///
    /// # Errors
    /// Why the command is refused.
    pub fn check(&mut self, cmd: &Command, now: u64) -> Result<(), Refusal> {
        while self
            .seen
            .front()
            .is_some_and(|(t, _)| t + Self::NONCE_WINDOW_MS < now)
        {
            self.seen.pop_front();
        }
        cmd.check_text()?;
        if cmd.signature.is_empty() {
            return Err(Refusal::Unsigned);
        }
        let Some(operator) = self.keys.operators.get(&cmd.operator) else {
            return Err(Refusal::UnknownOperator(cmd.operator.clone()));
        };
        let Some(sig) = hex::decode(&cmd.signature)
            .ok()
            .and_then(|b| <[u8; 64]>::try_from(b).ok())
        else {
            return Err(Refusal::SignatureNotHex);
        };
        if operator
            .key
            .verify_strict(&cmd.canonical(&self.cell), &Signature::from_bytes(&sig))
            .is_err()
        {
            return Err(Refusal::BadSignature);
        }
        if !operator.allow.contains(&cmd.action) {
            return Err(Refusal::NotAllowed {
                operator: cmd.operator.clone(),
                action: cmd.action,
            });
        }
        if cmd.issued_at.abs_diff(now) > MAX_SKEW_MS {
            return Err(Refusal::Skew(cmd.issued_at.abs_diff(now)));
        }
        if self.seen.iter().any(|(_, n)| *n == cmd.nonce) {
            return Err(Refusal::Replay);
        }
        self.seen.push_back((now, cmd.nonce.clone()));
        Ok(())
    }
}

/// A request that is not a command, described without repeating it: its
/// size, a hash and a short, escaped prefix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotACommand {
    /// Why, in a bounded text that never contains the request.
    pub reason: String,
    /// `too_large` or `invalid` (`cellwatch_requests_refused_total`'s
    /// reason).
    pub kind: &'static str,
}

/// How many bytes of a refused payload are journaled.
pub const PREFIX_BYTES: usize = 32;

impl NotACommand {
    /// A payload refused for `reason`, identified by its size, hash and
    /// first [`PREFIX_BYTES`] bytes. The payload may come in pieces.
    pub fn payload<'a>(
        kind: &'static str,
        reason: &str,
        pieces: impl IntoIterator<Item = &'a [u8]>,
    ) -> NotACommand {
        use sha2::Digest;
        let mut hash = Sha256::new();
        let mut size = 0;
        let mut head = Vec::with_capacity(PREFIX_BYTES);
        for piece in pieces {
            hash.update(piece);
            size += piece.len();
            let room = PREFIX_BYTES - head.len();
            head.extend_from_slice(&piece[..piece.len().min(room)]);
        }
        let prefix = String::from_utf8_lossy(&head).escape_debug().to_string();
        NotACommand {
            reason: format!(
                "{reason} ({size} bytes, sha256 {}, starts \"{prefix}\")",
                hex::encode(hash.finalize()),
            ),
            kind,
        }
    }

    /// JSON that does not parse as a command: where and what kind of error,
    /// never the offending text.
    pub fn json(error: &serde_json::Error, bytes: &[u8]) -> NotACommand {
        let kind = match error.classify() {
            serde_json::error::Category::Io => "an I/O error",
            serde_json::error::Category::Syntax => "invalid JSON",
            serde_json::error::Category::Data => "not a command's fields",
            serde_json::error::Category::Eof => "truncated JSON",
        };
        Self::payload(
            "invalid",
            &format!("{kind} at line {} column {}", error.line(), error.column()),
            [bytes],
        )
    }
}

/// `text` cut to at most `max` bytes (on a character boundary), with `…`
/// when cut: what is journaled of fields a sender chooses.
pub fn clip(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_string();
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &text[..end])
}

/// A fresh random nonce.
pub fn nonce() -> String {
    hex::encode(rand::random::<[u8; 16]>())
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod text;

#[cfg(test)]
mod actions;
