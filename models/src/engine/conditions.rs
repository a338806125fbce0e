//! The PLC's own alarms: conditions a server reports as OPC UA Alarms &
//! Conditions events, taken as alarms of the cell beside its checks'.
//!
//! The source reads each event into a [`PlcCondition`] (its id made of the
//! configured prefix, the event's source and condition names); the engine
//! raises, updates and clears the alarm as the condition's active state
//! says, stamped with the event's time (within the trust given to the
//! source's clock), and takes an acknowledgement made at the PLC (an HMI's)
//! as the alarm's, by whom the server says. An operator acknowledging it
//! in cellwatch is the agent's business: it asks the PLC first.

use super::{CellEngine, EngineEvent, EngineStep, Finding};
use crate::alarm::{AlarmKind, Severity, Transition};

/// One event of a PLC condition, as the source read it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlcCondition {
    /// The alarm's id: `<prefix>-<source name>-<condition name>`.
    pub id: String,
    /// The event's severity (1–1000) mapped to the alarm's.
    pub severity: Severity,
    /// The PLC's own text.
    pub message: String,
    /// The condition holds (`ActiveState/Id`).
    pub active: bool,
    /// Acknowledged at the PLC (`AckedState/Id`), and by whom if the server
    /// says (`ClientUserId`).
    pub acked: Option<String>,
    /// When the PLC says it happened (the event's `Time`), ms.
    pub time: u64,
}

/// Who an acknowledgement made at the PLC is journaled as.
pub const ACKED_AT_PLC: &str = "plc";

impl PlcCondition {
    /// The alarm's severity for an OPC UA severity (1–1000): up to 200
    /// low, 500 medium, 800 high, above critical.
    pub fn severity_of(opcua: u16) -> Severity {
        match opcua {
            0..=200 => Severity::Low,
            201..=500 => Severity::Medium,
            501..=800 => Severity::High,
            _ => Severity::Critical,
        }
    }
}

impl CellEngine {
    /// Takes the PLC's conditions as alarms whose ids start with one of
    /// `prefixes` followed by `-` (`opcua.events[].prefix`): they can be
    /// restored from the journal and carried over a reload like the
    /// checks' alarms.
    #[must_use]
    pub fn taking_conditions(mut self, prefixes: impl IntoIterator<Item = String>) -> Self {
        self.conditions = prefixes.into_iter().map(|p| format!("{p}-")).collect();
        self
    }

    /// Whether `id` is the id of a PLC condition this engine takes.
    pub fn is_condition(&self, id: &str) -> bool {
        self.conditions.iter().any(|p| id.starts_with(p.as_str())) && !self.can_raise_own(id)
    }

    /// An event of a PLC condition: its alarm raised, updated or cleared
    /// as its active state says, and acknowledged if the PLC says it is
    /// and cellwatch did not know.
    pub fn on_condition(&mut self, c: PlcCondition, now: u64) -> EngineStep {
        let mut step = EngineStep::default();
        if !self.is_condition(&c.id) {
            return step;
        }
        let known = self.alarms.get(&c.id);
        let changed = match known {
            None => c.active,
            Some(a) => a.active != c.active || (c.active && a.message != c.message),
        };
        if changed {
            let finding = Finding {
                at: Some(c.time),
                id: c.id.clone(),
                kind: AlarmKind::Plc,
                severity: c.severity,
                fault_type: "PLC".into(),
                latched: false,
                active: c.active,
                fault_step: None,
                culprits: Vec::new(),
                message: c.message,
            };
            let stamp = self.stamp(c.time, now);
            self.announce(finding, stamp, &mut step);
            self.update_state(now, &mut step);
        }
        if let Some(by) = c.acked {
            self.acked_at_plc(&c.id, &by, now, &mut step);
        }
        self.alarms.forget_if_normal(&c.id);
        step
    }

    /// The conditions a server holds now (its answer to a refresh, for
    /// the events of one prefix): every alarm of that prefix it no longer
    /// holds ended at the PLC and was acknowledged there (a server keeps a
    /// condition while it is active or unacknowledged).
    pub fn on_conditions_held(&mut self, prefix: &str, held: &[String], now: u64) -> EngineStep {
        let mut step = EngineStep::default();
        let prefix = format!("{prefix}-");
        let gone: Vec<(String, bool, bool)> = self
            .alarms
            .iter()
            .filter(|a| a.kind == AlarmKind::Plc && a.id.starts_with(&prefix))
            .filter(|a| !held.contains(&a.id))
            .map(|a| (a.id.clone(), a.active, a.acknowledged))
            .collect();
        for (id, active, acknowledged) in gone {
            if active {
                let Some(a) = self.alarms.get(&id) else {
                    continue;
                };
                let finding = Finding {
                    at: None,
                    id: id.clone(),
                    kind: AlarmKind::Plc,
                    severity: a.severity,
                    fault_type: "PLC".into(),
                    latched: false,
                    active: false,
                    fault_step: None,
                    culprits: Vec::new(),
                    message: format!("{} (no longer held by the PLC)", a.message),
                };
                self.announce(finding, now, &mut step);
            }
            if !acknowledged {
                self.acked_at_plc(&id, ACKED_AT_PLC, now, &mut step);
            }
            self.alarms.forget_if_normal(&id);
        }
        self.update_state(now, &mut step);
        step
    }

    fn acked_at_plc(&mut self, id: &str, by: &str, now: u64, step: &mut EngineStep) {
        if self.alarms.get(id).is_none_or(|a| a.acknowledged) {
            return;
        }
        if let Ok(alarm) = self.alarms.acknowledge(id, by, None) {
            step.events.push(EngineEvent::Alarm {
                alarm: alarm.clone(),
                transition: Transition::Acknowledged,
                at: now,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::{CellEngine, StateRules};

    fn engine() -> CellEngine {
        CellEngine::new("c1", Vec::new(), Vec::new(), StateRules::default())
            .unwrap()
            .taking_conditions(["plc".to_string()])
            .trusting_source_time(60_000)
    }

    fn event(active: bool, acked: Option<&str>, time: u64) -> PlcCondition {
        PlcCondition {
            id: "plc-Press-Overpressure".into(),
            severity: PlcCondition::severity_of(700),
            message: "Hydraulic pressure above 210 bar".into(),
            active,
            acked: acked.map(Into::into),
            time,
        }
    }

    fn transitions(step: &EngineStep) -> Vec<Transition> {
        step.alarms().map(|(_, t, _)| t).collect()
    }

    #[test]
    fn a_plc_alarm_follows_from_another_by_the_configurations_edge() {
        let mut relation = crate::consequence::Relation::default();
        relation.add("plc-Press-Overpressure", "plc-Press-Pump");
        let mut e = engine().relating(relation, true);
        e.on_condition(event(true, None, 1_000), 1_000);
        let pump = PlcCondition {
            id: "plc-Press-Pump".into(),
            message: "Pump motor overload".into(),
            ..event(true, None, 1_200)
        };
        e.on_condition(pump, 1_200);
        let a = e.alarms().find(|a| a.id == "plc-Press-Pump").unwrap();
        let c = a.consequence.as_ref().expect("a consequence");
        assert_eq!(
            (c.cause.as_str(), c.first_out.as_str(), c.suppressed),
            ("plc-Press-Overpressure", "plc-Press-Overpressure", true)
        );
    }

    #[test]
    fn a_condition_is_raised_at_the_plcs_time_and_cleared_when_it_returns_to_normal() {
        let mut e = engine();
        let s = e.on_condition(event(true, None, 1_000), 5_000);
        let (a, t, at) = s.alarms().next().unwrap();
        assert_eq!(
            (t, at, a.kind, a.severity),
            (Transition::Raised, 1_000, AlarmKind::Plc, Severity::High)
        );
        assert_eq!(a.message, "Hydraulic pressure above 210 bar");
        // The same event again (a republish, a refresh): nothing new.
        assert!(e.on_condition(event(true, None, 1_000), 5_100).is_empty());
        let s = e.on_condition(event(false, None, 2_000), 5_200);
        assert_eq!(transitions(&s), [Transition::Cleared]);
        let a = e.alarms().next().unwrap();
        assert!(!a.active && !a.acknowledged);
    }

    #[test]
    fn an_acknowledgement_at_the_plc_is_the_alarms_by_whom_the_server_says() {
        let mut e = engine();
        e.on_condition(event(true, None, 1_000), 1_000);
        let s = e.on_condition(event(true, Some("hmi-2: anna"), 1_500), 1_500);
        assert_eq!(transitions(&s), [Transition::Acknowledged]);
        assert_eq!(
            e.alarms().next().unwrap().acked_by.as_deref(),
            Some("hmi-2: anna")
        );
        // Acknowledged in cellwatch first: the PLC's confirmation is no
        // second acknowledgement.
        let mut e = engine();
        e.on_condition(event(true, None, 1_000), 1_000);
        e.acknowledge("plc-Press-Overpressure", "op1", None, 1_200)
            .unwrap();
        assert!(e
            .on_condition(event(true, Some("op1"), 1_300), 1_300)
            .is_empty());
    }

    #[test]
    fn a_condition_the_plc_no_longer_holds_ends_and_is_acknowledged() {
        let mut e = engine();
        e.on_condition(event(true, None, 1_000), 1_000);
        let s = e.on_conditions_held("plc", &[], 9_000);
        assert_eq!(
            transitions(&s),
            [Transition::Cleared, Transition::Acknowledged]
        );
        let (a, _, _) = s.alarms().last().unwrap();
        assert_eq!(a.acked_by.as_deref(), Some(ACKED_AT_PLC));
        assert!(
            a.message.ends_with("(no longer held by the PLC)"),
            "{}",
            a.message
        );
        assert_eq!(e.alarms().count(), 0, "back to normal: forgotten");
        // Held: untouched.
        let mut e = engine();
        e.on_condition(event(true, None, 1_000), 1_000);
        let held = ["plc-Press-Overpressure".to_string()];
        assert!(e.on_conditions_held("plc", &held, 9_000).is_empty());
    }

    #[test]
    fn a_reload_carries_the_plcs_alarms_over_and_one_without_the_prefix_drops_them() {
        let mut e = engine();
        e.on_condition(event(true, None, 1_000), 1_000);
        let mut next = engine();
        let steps = next.take_over(e.carry_over(), 2_000);
        let restored: Vec<_> = steps
            .iter()
            .flat_map(|s| s.alarms())
            .map(|(a, t, _)| (a.id.clone(), t))
            .collect();
        assert_eq!(
            restored,
            [("plc-Press-Overpressure".to_string(), Transition::Restored)]
        );
        assert!(next.alarms().next().unwrap().active);
        let mut without =
            CellEngine::new("c1", Vec::new(), Vec::new(), StateRules::default()).unwrap();
        without.take_over(e.carry_over(), 2_000);
        assert_eq!(without.alarms().count(), 0);
    }

    #[test]
    fn a_condition_back_to_normal_is_forgotten_and_raised_anew_when_it_comes_back() {
        let mut e = engine();
        e.on_condition(event(true, None, 1_000), 1_000);
        e.on_condition(event(false, None, 2_000), 2_000);
        assert_eq!(
            e.alarms().count(),
            1,
            "cleared, not acknowledged: still shown"
        );
        e.acknowledge("plc-Press-Overpressure", "op1", None, 3_000)
            .unwrap();
        assert_eq!(e.alarms().count(), 0, "normal: nothing left to show");
        // A server naming a new condition for every occurrence leaves
        // nothing behind once each is over.
        for k in 0..100 {
            let mut c = event(true, None, 4_000 + k);
            c.id = format!("plc-Press-Run{k}");
            e.on_condition(c.clone(), 4_000 + k);
            c.active = false;
            c.acked = Some("hmi".into());
            e.on_condition(c, 4_000 + k);
        }
        assert_eq!(e.alarms().count(), 0);
        let s = e.on_condition(event(true, None, 9_000), 9_000);
        assert_eq!(transitions(&s), [Transition::Raised]);
    }

    #[test]
    fn only_ids_of_a_configured_prefix_are_conditions() {
        let mut e = engine();
        let mut other = event(true, None, 1_000);
        other.id = "ese".into();
        assert!(e.on_condition(other, 1_000).is_empty());
        assert!(e.is_condition("plc-Press-Overpressure"));
        assert!(!e.is_condition("communication"));
    }

    #[test]
    fn severities_fall_in_four_bands() {
        let bands: Vec<Severity> = [1, 200, 201, 500, 501, 800, 801, 1000]
            .into_iter()
            .map(PlcCondition::severity_of)
            .collect();
        use Severity::*;
        assert_eq!(
            bands,
            [Low, Low, Medium, Medium, High, High, Critical, Critical]
        );
    }
}
