//! The cell's master alarm database in the engine: each alarm's
//! rationalised priority (its severity from then on) and its guidance,
//! carried by every occurrence so that wherever the alarm is shown its
//! corrective action and response time are too. Reading the file is
//! [`crate::madb`]'s; which rows the cell has is the agent's to check.

use std::sync::Arc;

use super::{CellEngine, Finding};
use crate::alarm::Severity;
use crate::madb::{Guidance, Rationalisation, Rationalised};

impl CellEngine {
    /// Takes `rows` (alarm id, or a pattern with `*`, and its
    /// rationalisation) as the cell's master alarm database: each alarm is
    /// raised with its rationalised priority and carries its guidance.
    #[must_use]
    pub fn rationalising(mut self, rows: impl IntoIterator<Item = (String, Rationalised)>) -> Self {
        self.rationale = Rationalisation::new(rows);
        self
    }

    /// Finding `f` with its alarm's rationalised priority.
    pub(super) fn prioritised(&self, mut f: Finding) -> Finding {
        if let Some(p) = self.rationale.of(&f.id).and_then(|r| r.priority) {
            f.severity = p;
        }
        f
    }

    /// Alarm `id`'s guidance, if the database has it.
    pub(super) fn guidance_of(&self, id: &str) -> Option<Arc<Guidance>> {
        self.rationale.of(id).map(|r| r.guidance.clone())
    }

    /// Alarm `id`'s rationalised priority, if the database gives one.
    pub(super) fn priority_of(&self, id: &str) -> Option<Severity> {
        self.rationale.of(id).and_then(|r| r.priority)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fixture::{engine, load_normal};
    use crate::engine::Reading;
    use crate::signal::Signal;

    #[test]
    fn an_alarm_is_raised_with_its_rationalised_priority_and_guidance() {
        let guidance = Arc::new(Guidance {
            class: "safety".into(),
            consequence_of_inaction: "the axis stays stopped".into(),
            corrective_action: "Drive the Y axis off its limit switch in JOG".into(),
            response_time_ms: Some(300_000),
        });
        let rows = [(
            "ese".to_string(),
            Rationalised {
                priority: Some(Severity::High),
                guidance: guidance.clone(),
            },
        )];
        let mut e = engine().rationalising(rows);
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        let ese = e.alarms().find(|a| a.id == "ese").unwrap();
        assert_eq!(ese.severity, Severity::High);
        assert_eq!(ese.guidance, Some(guidance));
        let entry = e.catalogue().into_iter().find(|c| c.id == "ese").unwrap();
        assert_eq!(entry.severity, Severity::High);
    }
}
