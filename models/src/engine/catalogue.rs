//! The alarms a cell can raise, each described for its master alarm
//! database (ISA-18.2's MADB): kind, priority, the condition in words, the
//! contacts that can be its culprits with their comments, which alarms it
//! may follow from and cause, the modes that suppress it by design, its
//! delays. The agent adds its own system alarms and writes the file
//! (`cellwatch mad export`); this is what the engine knows.

use std::collections::BTreeMap;

use super::{CellEngine, Declared};
use crate::alarm::{AlarmKind, Severity};
use crate::signal::Signal;

/// One alarm the cell can raise, described.
#[derive(Debug, Clone, PartialEq)]
pub struct CatalogueEntry {
    /// The alarm id.
    pub id: String,
    /// What raises it.
    pub kind: AlarmKind,
    /// Its priority as configured.
    pub severity: Severity,
    /// The fault type in the machine-state history.
    pub fault_type: String,
    /// Whether it stays active until reset.
    pub latched: bool,
    /// Its condition in words, where its check can say.
    pub condition: Option<String>,
    /// The signals its check reads, each with its comment: its possible
    /// culprits.
    pub culprits: Vec<(Signal, Option<String>)>,
    /// The alarms it may follow from.
    pub causes: Vec<String>,
    /// The alarms that may follow from it.
    pub effects: Vec<String>,
    /// The machine modes that suppress it by design.
    pub suppressed_in: Vec<String>,
    /// How long its condition must hold to raise, and be gone to clear, ms.
    pub delays_ms: (u64, u64),
}

impl CellEngine {
    /// Every alarm this engine can raise, by id: its checks' and its own
    /// (`communication`, `tag-quality`). The PLC's conditions and the
    /// agent's system alarms are not known here.
    pub fn catalogue(&self) -> Vec<CatalogueEntry> {
        let mut declared: BTreeMap<String, Declared> = BTreeMap::new();
        for set in &self.sets {
            for d in set.alarms() {
                declared.insert(d.id.clone(), d);
            }
        }
        for (id, kind, severity, fault_type) in [
            (
                "communication",
                AlarmKind::Communication,
                Severity::High,
                "COMM",
            ),
            (
                "tag-quality",
                AlarmKind::TagQuality,
                Severity::Medium,
                "QUALITY",
            ),
        ] {
            declared.insert(
                id.into(),
                Declared {
                    id: id.into(),
                    kind,
                    severity,
                    fault_type: fault_type.into(),
                    latched: false,
                },
            );
        }
        let mut effects: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for edge in self.relation.edges() {
            effects.entry(edge.cause).or_default().push(edge.effect);
        }
        declared
            .into_values()
            .map(|d| self.describe(d, &mut effects))
            .collect()
    }

    fn describe(&self, d: Declared, effects: &mut BTreeMap<String, Vec<String>>) -> CatalogueEntry {
        let condition = match d.kind {
            AlarmKind::Communication => Some("the connection to the PLC is lost".into()),
            AlarmKind::TagQuality => Some(
                "a tag's value has bad or uncertain quality (the checks reading it suspended)"
                    .into(),
            ),
            _ => self.sets.iter().find_map(|s| s.describe(&d.id)),
        };
        let mut reads = Vec::new();
        for set in &self.sets {
            set.reads(&d.id, &mut reads);
        }
        reads.dedup();
        let culprits = reads
            .into_iter()
            .map(|s| {
                let comment = self.comments.get(&s).map(str::to_string);
                (s, comment)
            })
            .collect();
        let mut causes: Vec<String> = self
            .relation
            .causes_of(&d.id)
            .iter()
            .map(|(c, _)| c.clone())
            .collect();
        causes.sort();
        let mut effects = effects.remove(&d.id).unwrap_or_default();
        effects.sort();
        let suppressed_in = self
            .rules
            .modes
            .iter()
            .filter(|m| m.suppress.iter().any(|p| p.matches(&d.id)))
            .map(|m| m.id.clone())
            .collect();
        CatalogueEntry {
            severity: self.priority_of(&d.id).unwrap_or(d.severity),
            delays_ms: self.delays.get(&d.id).copied().unwrap_or((0, 0)),
            id: d.id,
            kind: d.kind,
            fault_type: d.fault_type,
            latched: d.latched,
            condition,
            culprits,
            causes,
            effects,
            suppressed_in,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fixture::engine;

    #[test]
    fn the_catalogue_lists_the_checks_alarms_and_the_engines_own_described() {
        let e = engine();
        let c = e.catalogue();
        let ids: Vec<&str> = c.iter().map(|a| a.id.as_str()).collect();
        assert_eq!(ids, ["communication", "ese", "tag-quality"]);
        let ese = &c[1];
        assert_eq!(
            (ese.kind, ese.severity),
            (AlarmKind::Switching, Severity::Critical)
        );
        let condition = ese.condition.as_deref().unwrap();
        assert!(
            condition.starts_with("fault while G8.02 is on; G8.02 = "),
            "{condition}"
        );
        assert!(condition.contains("X0.06"), "{condition}");
        let read: Vec<&str> = ese.culprits.iter().map(|(s, _)| s.name()).collect();
        assert!(read.contains(&"X0.06"), "{read:?}");
        assert_eq!(ese.delays_ms, (0, 0));
        assert_eq!(
            c[0].condition.as_deref(),
            Some("the connection to the PLC is lost")
        );
    }
}
