//! Validating the configuration: where the operators come from when the
//! plant signs them (`commands.plant_key`, `commands.plant_list`).

use std::path::Path;

use toml::Spanned;

use super::Validator;
use crate::config::PlantOperatorsConfig;

impl Validator<'_> {
    /// The plant operators list's key and file (default: beside the
    /// journal, `plant-operators.json`); `None` without a key.
    pub(super) fn plant_operators(
        &mut self,
        key: Option<Spanned<String>>,
        list: Option<Spanned<String>>,
        journal: &Path,
    ) -> Option<PlantOperatorsConfig> {
        let Some(key) = key else {
            if let Some(list) = list {
                self.problem(
                    list.span(),
                    "commands.plant_list",
                    "without commands.plant_key no plant operators list is taken: give the plant administrator's public key",
                );
            }
            return None;
        };
        let hex_key = key.get_ref().trim().to_ascii_lowercase();
        let is_key = hex::decode(&hex_key)
            .ok()
            .and_then(|b| <[u8; 32]>::try_from(b).ok())
            .is_some_and(|b| ed25519_dalek::VerifyingKey::from_bytes(&b).is_ok());
        if !is_key {
            self.problem(
                key.span(),
                "commands.plant_key",
                "the plant administrator's Ed25519 public key, 64 hex digits (plant.toml's folder: admin/plant-admin.pub)",
            );
            return None;
        }
        let list = match list {
            Some(l) => self.path(l.get_ref()),
            None => journal.with_file_name("plant-operators.json"),
        };
        Some(PlantOperatorsConfig { key: hex_key, list })
    }
}
