//! The plant operators list: every operator's public key and what they
//! may do on each cell, signed by the plant administrator's key
//! (`cellwatch plant`), whose public half each agent holds
//! (`commands.plant_key`). It reaches every agent over the bus and is
//! kept by each; a newer version replaces the operators an agent judges
//! commands by, live. An older or equal version is never taken, so a list
//! replayed from the past cannot bring back a revoked key.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use ed25519_dalek::{Signature, Signer, SigningKey, Verifier, VerifyingKey};
use serde::{Deserialize, Serialize};

use super::{valid_operator_name, Action, Operator, OperatorKeys};

/// The list's schema.
pub(crate) const LIST_SCHEMA: &str = "cellwatch.plant-operators.v1";
/// What the administrator's signature covers: this, then the list's text.
const SIGNED_PREFIX: &str = "cellwatch-plant-operators-v1\n";
/// The largest signed list an agent reads (a plant of thousands of
/// operators and cells stays far below).
pub(crate) const MAX_LIST_BYTES: usize = 512 * 1024;

/// The list as signed: its text and the signature over it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SignedList {
    /// The list's JSON text ([`PlantList`]).
    pub list: String,
    /// Ed25519 signature (hex) of [`SIGNED_PREFIX`] and `list`.
    pub signature: String,
}

/// The list itself.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PlantList {
    /// [`LIST_SCHEMA`].
    pub schema: String,
    /// The plant's name.
    pub plant: String,
    /// Grows by one with each change; an agent takes only a newer one.
    pub version: u64,
    /// When it was signed (RFC 3339).
    pub issued_at: String,
    /// Every operator: their public key and, per cell, what they may do.
    pub operators: BTreeMap<String, ListedOperator>,
}

/// One operator in the list.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ListedOperator {
    /// Their Ed25519 public key, hex.
    pub public_key: String,
    /// What they may do, by cell.
    pub cells: BTreeMap<String, BTreeSet<Action>>,
}

/// Why a signed list is not taken.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum ListError {
    /// Not a signed list.
    #[error("not a signed plant operators list: {0}")]
    Malformed(String),
    /// Larger than [`MAX_LIST_BYTES`].
    #[error("a plant operators list of {0} bytes: more than {MAX_LIST_BYTES}")]
    TooLarge(usize),
    /// The administrator's key does not verify it.
    #[error("the plant administrator's key does not verify this operators list")]
    BadSignature,
    /// An entry is wrong.
    #[error("operators.{0}: {1}")]
    Entry(String, String),
}

fn signed_bytes(list: &str) -> Vec<u8> {
    [SIGNED_PREFIX.as_bytes(), list.as_bytes()].concat()
}

impl PlantList {
    /// The list signed with the plant administrator's key `admin`.
    pub(crate) fn signed_by(&self, admin: &super::OperatorKey) -> SignedList {
        self.sign(&admin.key)
    }

    /// The list signed with the administrator's `key`.
    pub(crate) fn sign(&self, key: &SigningKey) -> SignedList {
        let list = serde_json::to_string(self).unwrap_or_default();
        let signature = hex::encode(key.sign(&signed_bytes(&list)).to_bytes());
        SignedList { list, signature }
    }

    /// The operators of `cell`: each listed with anything allowed there.
    ///
    /// # Errors
    /// A public key that is not one, or an operator's name out of format.
    pub(crate) fn keys_for(&self, cell: &str) -> Result<OperatorKeys, ListError> {
        let mut operators = HashMap::new();
        for (name, op) in &self.operators {
            if !valid_operator_name(name) {
                return Err(ListError::Entry(
                    name.clone(),
                    "not an operator's name".into(),
                ));
            }
            let Some(allow) = op.cells.get(cell).filter(|a| !a.is_empty()) else {
                continue;
            };
            let key = hex::decode(&op.public_key)
                .ok()
                .and_then(|b| <[u8; 32]>::try_from(b).ok())
                .and_then(|b| VerifyingKey::from_bytes(&b).ok())
                .ok_or_else(|| {
                    ListError::Entry(name.clone(), "public_key: not an Ed25519 public key".into())
                })?;
            operators.insert(
                name.clone(),
                Operator {
                    key,
                    allow: allow.clone(),
                },
            );
        }
        Ok(OperatorKeys { operators })
    }
}

impl SignedList {
    /// Reads a signed list's JSON.
    ///
    /// # Errors
    /// Too large, or not a signed list.
    pub(crate) fn parse(bytes: &[u8]) -> Result<SignedList, ListError> {
        if bytes.len() > MAX_LIST_BYTES {
            return Err(ListError::TooLarge(bytes.len()));
        }
        serde_json::from_slice(bytes).map_err(|e| ListError::Malformed(e.to_string()))
    }

    /// The list, if the administrator's `key` signed it.
    ///
    /// # Errors
    /// A bad signature, or a list that does not read.
    pub(crate) fn open(&self, key: &VerifyingKey) -> Result<PlantList, ListError> {
        let signature = hex::decode(&self.signature)
            .ok()
            .and_then(|b| <[u8; 64]>::try_from(b).ok())
            .map(|b| Signature::from_bytes(&b))
            .ok_or(ListError::BadSignature)?;
        key.verify(&signed_bytes(&self.list), &signature)
            .map_err(|_| ListError::BadSignature)?;
        let list: PlantList =
            serde_json::from_str(&self.list).map_err(|e| ListError::Malformed(e.to_string()))?;
        if list.schema != LIST_SCHEMA {
            return Err(ListError::Malformed(format!("schema '{}'", list.schema)));
        }
        Ok(list)
    }
}

/// What changed for `cell` from `old` to `new`, in words: operators
/// added, removed, their actions or keys changed (empty: nothing).
pub(crate) fn changes(old: &OperatorKeys, new: &OperatorKeys) -> String {
    let mut said = Vec::new();
    for (name, o) in &new.operators {
        match old.operators.get(name) {
            None => said.push(format!("+{name} ({})", list(&o.allow))),
            Some(before) if before.key != o.key => said.push(format!("{name}: new key")),
            Some(before) if before.allow != o.allow => {
                said.push(format!(
                    "{name}: {} (was {})",
                    list(&o.allow),
                    list(&before.allow)
                ));
            }
            Some(_) => {}
        }
    }
    for name in old.operators.keys() {
        if !new.operators.contains_key(name) {
            said.push(format!("-{name}"));
        }
    }
    said.sort();
    said.join(", ")
}

fn list(actions: &BTreeSet<Action>) -> String {
    let names: Vec<&str> = actions.iter().map(|a| a.as_str()).collect();
    names.join(",")
}

/// The administrator's public key from its 64 hex digits.
///
/// # Errors
/// Not an Ed25519 public key.
pub(crate) fn admin_key(hex_key: &str) -> Result<VerifyingKey, super::KeyError> {
    hex::decode(hex_key.trim())
        .ok()
        .and_then(|b| <[u8; 32]>::try_from(b).ok())
        .and_then(|b| VerifyingKey::from_bytes(&b).ok())
        .ok_or(super::KeyError::NotAPublicKey)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn list(version: u64, kim_on_m01: &[Action]) -> PlantList {
        let kim = SigningKey::from_bytes(&[7; 32]);
        let mut cells = BTreeMap::new();
        cells.insert("m01".to_string(), kim_on_m01.iter().copied().collect());
        cells.insert("m02".to_string(), [Action::Ack].into_iter().collect());
        PlantList {
            schema: LIST_SCHEMA.into(),
            plant: "A".into(),
            version,
            issued_at: "2026-11-28T00:00:00Z".into(),
            operators: [(
                "kim".to_string(),
                ListedOperator {
                    public_key: hex::encode(kim.verifying_key().to_bytes()),
                    cells,
                },
            )]
            .into_iter()
            .collect(),
        }
    }

    #[test]
    fn only_the_administrators_key_opens_a_list_and_only_as_signed() {
        let admin = SigningKey::from_bytes(&[1; 32]);
        let other = SigningKey::from_bytes(&[2; 32]);
        let signed = list(3, &[Action::Ack, Action::Force]).sign(&admin);
        let opened = signed.open(&admin.verifying_key()).unwrap();
        assert_eq!(opened.version, 3);
        assert_eq!(
            signed.open(&other.verifying_key()),
            Err(ListError::BadSignature)
        );
        let mut changed = signed.clone();
        changed.list = changed.list.replace("\"version\":3", "\"version\":4");
        assert_eq!(
            changed.open(&admin.verifying_key()),
            Err(ListError::BadSignature)
        );
        let text = serde_json::to_vec(&signed).unwrap();
        assert_eq!(SignedList::parse(&text).unwrap(), signed);
        assert!(matches!(
            SignedList::parse(&vec![b' '; MAX_LIST_BYTES + 1]),
            Err(ListError::TooLarge(_))
        ));
    }

    #[test]
    fn a_cell_takes_the_operators_allowed_anything_on_it_and_says_what_changed() {
        let before = list(1, &[Action::Ack, Action::Force])
            .keys_for("m01")
            .unwrap();
        let after = list(2, &[Action::Ack]).keys_for("m01").unwrap();
        assert_eq!(after.entries()[0].2, vec![Action::Ack]);
        assert_eq!(changes(&before, &after), "kim: ack (was ack,force)");
        assert_eq!(changes(&after, &OperatorKeys::default()), "-kim");
        assert!(list(1, &[]).keys_for("m01").unwrap().is_empty());
        assert!(list(1, &[]).keys_for("m09").unwrap().is_empty());
    }
}
