//! Operator commands (acknowledge, reset) and their authorisation.
//!
//! A command names its operator and carries an HMAC-SHA256, keyed with that
//! operator's secret, over a canonical text of the request (cell, action,
//! alarm, operator, nonce, time). The agent refuses a command that is
//! unsigned, signed with the wrong key, from an unknown operator, issued
//! more than [`MAX_SKEW`] away from its clock, or whose nonce it has seen
//! (a replay). Keys live in a secrets file (`[operators] name = "<hex>"`),
//! never in the cell configuration. Every command, accepted or refused, is
//! journaled by the caller.

use std::collections::{HashMap, VecDeque};
use std::path::Path;

use hmac::{Hmac, Mac};
use serde::{Deserialize, Serialize};
use sha2::Sha256;

/// How far a command's time may be from the agent's clock.
pub const MAX_SKEW_MS: u64 = 60_000;
/// Same, as a name for documentation.
pub const MAX_SKEW: &str = "60 s";

/// What an operator asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Action {
    /// Acknowledge an alarm.
    Ack,
    /// Reset a latched alarm whose condition has ended.
    Reset,
}

impl Action {
    /// Every action.
    pub const ALL: [Action; 2] = [Action::Ack, Action::Reset];

    /// The name on the wire and in the journal.
    pub fn as_str(self) -> &'static str {
        match self {
            Action::Ack => "ack",
            Action::Reset => "reset",
        }
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
    /// The alarm id.
    pub alarm: String,
    /// Who sends it.
    pub operator: String,
    /// A value never used before (random hex).
    pub nonce: String,
    /// When it was issued, ms since the epoch.
    pub issued_at: u64,
    /// Hex HMAC-SHA256 of [`Command::canonical`] with the operator's key.
    #[serde(default)]
    pub signature: String,
}

impl Command {
    /// The text that is signed.
    pub fn canonical(&self, cell: &str) -> String {
        format!(
            "cellwatch-command-v1\n{cell}\n{}\n{}\n{}\n{}\n{}",
            self.action, self.alarm, self.operator, self.nonce, self.issued_at
        )
    }

    /// Signs the command for `cell` with `key`.
    pub fn sign(&mut self, cell: &str, key: &[u8]) {
        self.signature = hex::encode(mac(key, &self.canonical(cell)).finalize().into_bytes());
    }
}

fn mac(key: &[u8], text: &str) -> Hmac<Sha256> {
    let mut m = <Hmac<Sha256> as Mac>::new_from_slice(key).expect("HMAC takes keys of any length");
    m.update(text.as_bytes());
    m
}

/// Why the operator keys cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum KeysError {
    /// The secrets file cannot be read.
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
    /// A key is not hex.
    #[error("{origin}: operators.{operator}: the key is not hex")]
    NotHex {
        /// The file.
        origin: String,
        /// Whose key.
        operator: String,
    },
    /// A key is too short to be safe.
    #[error("{origin}: operators.{operator}: the key must be at least 16 bytes (32 hex digits)")]
    TooShort {
        /// The file.
        origin: String,
        /// Whose key.
        operator: String,
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
    /// Issued too far from the agent's clock.
    #[error("issued {0} ms away from the agent's clock (more than {MAX_SKEW})")]
    Skew(u64),
    /// The nonce was used before.
    #[error("replayed command (nonce already used)")]
    Replay,
}

/// Operators' keys, from the secrets file.
#[derive(Default)]
pub struct OperatorKeys {
    keys: HashMap<String, Vec<u8>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SecretsFile {
    operators: HashMap<String, String>,
}

impl OperatorKeys {
    /// Parses a secrets file's text.
    ///
    /// # Errors
    /// Malformed TOML or a key that is not hex of at least 16 bytes.
    pub fn parse(origin: &str, text: &str) -> Result<OperatorKeys, KeysError> {
        let f: SecretsFile = toml::from_str(text).map_err(|e| KeysError::Syntax {
            origin: origin.into(),
            message: e.message().into(),
        })?;
        let mut keys = HashMap::new();
        for (name, hex_key) in f.operators {
            let Ok(key) = hex::decode(hex_key.trim()) else {
                return Err(KeysError::NotHex {
                    origin: origin.into(),
                    operator: name,
                });
            };
            if key.len() < 16 {
                return Err(KeysError::TooShort {
                    origin: origin.into(),
                    operator: name,
                });
            }
            keys.insert(name, key);
        }
        Ok(OperatorKeys { keys })
    }

    /// Loads the secrets file, warning when others may read it.
    ///
    /// # Errors
    /// The file cannot be read or parsed.
    pub fn load(path: &Path) -> Result<OperatorKeys, KeysError> {
        let text = std::fs::read_to_string(path).map_err(|source| KeysError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            if let Ok(meta) = std::fs::metadata(path) {
                if meta.permissions().mode() & 0o077 != 0 {
                    tracing::warn!(path = %path.display(), "the operator secrets file is readable by others; chmod 600 it");
                }
            }
        }
        Self::parse(&path.display().to_string(), &text)
    }

    /// The key of `operator`.
    pub fn key(&self, operator: &str) -> Option<Vec<u8>> {
        self.keys.get(operator).cloned()
    }

    /// How many operators have keys.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }
}

/// Checks signatures and remembers nonces.
pub struct Gate {
    cell: String,
    keys: OperatorKeys,
    /// Nonces seen within the skew window, oldest first.
    seen: VecDeque<(u64, String)>,
}

impl Gate {
    /// A gate for `cell` with `keys`.
    pub fn new(cell: &str, keys: OperatorKeys) -> Gate {
        Gate {
            cell: cell.into(),
            keys,
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
        if cmd.signature.is_empty() {
            return Err(Refusal::Unsigned);
        }
        let Some(key) = self.keys.keys.get(&cmd.operator) else {
            return Err(Refusal::UnknownOperator(cmd.operator.clone()));
        };
        let Ok(sig) = hex::decode(&cmd.signature) else {
            return Err(Refusal::SignatureNotHex);
        };
        if mac(key, &cmd.canonical(&self.cell))
            .verify_slice(&sig)
            .is_err()
        {
            return Err(Refusal::BadSignature);
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
}

/// How many bytes of a refused payload are journaled.
pub const PREFIX_BYTES: usize = 32;

impl NotACommand {
    /// A payload refused for `reason`, identified by its size, hash and
    /// first [`PREFIX_BYTES`] bytes. The payload may come in pieces.
    pub fn payload<'a>(reason: &str, pieces: impl IntoIterator<Item = &'a [u8]>) -> NotACommand {
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
mod tests {
    use super::*;

    const KEYS: &str = "[operators]\nkim = \"00112233445566778899aabbccddeeff\"\n";

    fn cmd(now: u64) -> Command {
        Command {
            action: Action::Ack,
            alarm: "ese".into(),
            operator: "kim".into(),
            nonce: nonce(),
            issued_at: now,
            signature: String::new(),
        }
    }

    #[test]
    fn signed_once_accepted_then_replay_refused() {
        let mut gate = Gate::new("m01", OperatorKeys::parse("k", KEYS).unwrap());
        let mut c = cmd(1_000_000);
        assert_eq!(gate.check(&c, 1_000_000), Err(Refusal::Unsigned));
        c.sign(
            "m01",
            &hex::decode("00112233445566778899aabbccddeeff").unwrap(),
        );
        assert_eq!(gate.check(&c, 1_000_500), Ok(()));
        assert_eq!(gate.check(&c, 1_000_600), Err(Refusal::Replay));
        let mut wrong = cmd(1_000_000);
        wrong.sign("m01", b"not the key of kim at all");
        assert_eq!(gate.check(&wrong, 1_000_000), Err(Refusal::BadSignature));
        let mut other_cell = cmd(1_000_000);
        other_cell.sign(
            "m02",
            &hex::decode("00112233445566778899aabbccddeeff").unwrap(),
        );
        assert_eq!(
            gate.check(&other_cell, 1_000_000),
            Err(Refusal::BadSignature)
        );
        let mut old = cmd(1_000_000);
        old.sign(
            "m01",
            &hex::decode("00112233445566778899aabbccddeeff").unwrap(),
        );
        assert!(gate
            .check(&old, 1_100_000)
            .unwrap_err()
            .to_string()
            .starts_with("issued 100000 ms away"));
    }

    #[test]
    fn bad_secrets_files() {
        assert_eq!(
            OperatorKeys::parse("k", "[operators]\nkim = \"zz\"")
                .err()
                .unwrap()
                .to_string(),
            "k: operators.kim: the key is not hex"
        );
        assert!(OperatorKeys::parse("k", "[operators]\nkim = \"00\"")
            .err()
            .unwrap()
            .to_string()
            .contains("at least 16 bytes"));
    }
}

#[cfg(test)]
mod actions {
    use super::*;

    #[test]
    fn an_unknown_action_does_not_parse() {
        let text = r#"{"action":"force","alarm":"ese","operator":"kim","nonce":"n","issued_at":1,"signature":"00"}"#;
        let err = serde_json::from_str::<Command>(text)
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("unknown variant `force`, expected `ack` or `reset`"),
            "{err}"
        );
        let ok = text.replace("force", "reset");
        assert_eq!(
            serde_json::from_str::<Command>(&ok).unwrap().action,
            Action::Reset
        );
    }
}
