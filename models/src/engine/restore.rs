//! Taking back what was: after a restart, the alarms and the machine state
//! the journal kept (`restore`); over a reload, what the engine replaced
//! carries (`carry_over`, `take_over`: its alarms, state, connection and
//! the tags' values, judged by the new checks); and which alarms an engine
//! can raise, so that no other is taken back. Reading the journal is the
//! agent's.

use super::{
    BadQuality, Carried, CellEngine, EngineEvent, EngineStep, MachineState, Reading, TagReading,
    Value,
};
use crate::alarm::{Alarm, AlarmKind, Transition};
use crate::value::Num;

impl CellEngine {
    /// Whether this engine can raise alarm `id`: one its checks declared,
    /// `communication` or `tag-quality`, or a PLC condition of a prefix it
    /// takes ([`CellEngine::taking_conditions`]). (System alarms are the
    /// agent's: [`CellEngine::on_system`] takes any id.)
    pub fn can_raise(&self, id: &str) -> bool {
        self.can_raise_own(id) || self.is_condition(id)
    }

    /// [`CellEngine::can_raise`] but for the PLC's conditions.
    pub(super) fn can_raise_own(&self, id: &str) -> bool {
        matches!(id, "communication" | "tag-quality") || self.alarms.is_declared(id)
    }

    /// Puts back the alarms that were not back to normal when the agent
    /// stopped, and the machine state, before any input. Each alarm comes
    /// back with its `raised_at`, acknowledgement and culprits, and is
    /// reported once as [`Transition::Restored`] (not a new raise). Fresh
    /// values then decide: a non-latched alarm clears or stays as its check
    /// says; a latched one waits for a reset as before.
    pub fn restore(
        &mut self,
        alarms: Vec<Alarm>,
        state: Option<MachineState>,
        now: u64,
    ) -> EngineStep {
        let mut step = EngineStep::default();
        for alarm in alarms {
            let id = alarm.id.clone();
            if alarm.active {
                for set in &mut self.sets {
                    set.restored(&alarm);
                }
            }
            self.alarms.restore(alarm);
            if let Some(alarm) = self.alarms.get(&id) {
                step.events.push(EngineEvent::Alarm {
                    alarm: alarm.clone(),
                    transition: Transition::Restored,
                    at: now,
                });
            }
        }
        if let Some(state) = state {
            self.state = state;
        }
        step
    }

    /// What a reload carries from this engine into the one built from the
    /// new configuration ([`CellEngine::take_over`]).
    pub fn carry_over(&self) -> Carried {
        let readings = (0..self.configured)
            .filter_map(|t| {
                let reading = match self.bad.get(&t) {
                    Some(BadQuality::WrongType(expected, received)) => Reading::WrongType {
                        expected: *expected,
                        received: *received,
                    },
                    Some(BadQuality::NotFinite(name)) => Reading::Number(Num::Float(match *name {
                        "+inf" => f64::INFINITY,
                        "-inf" => f64::NEG_INFINITY,
                        _ => f64::NAN,
                    })),
                    Some(BadQuality::Status) => Reading::Bad,
                    None => match self.value(t)? {
                        Value::Bool(b) => Reading::Good(b),
                        Value::Num(n) => Reading::Number(n),
                        Value::Text(text) => Reading::Text(text),
                    },
                };
                let at = self.timestamps[t].or(self.latest).unwrap_or(0);
                Some((self.tags[t].address.clone(), reading, at))
            })
            .collect();
        Carried {
            alarms: self
                .alarms
                .iter()
                .filter(|a| {
                    a.active || !a.acknowledged || a.shelved.is_some() || a.out_of_service.is_some()
                })
                .cloned()
                .collect(),
            state: self.state.clone(),
            connected: self.connected,
            readings,
        }
    }

    /// Takes over from the engine a reload replaces (`carried`), before
    /// any other input: its alarms as they were (acknowledgements, shelves
    /// and removals kept; the alarms of checks no longer configured
    /// dropped, the agent's own kept), each reported once as
    /// [`Transition::Restored`]; its machine state; its connection; then
    /// the tags' values as they were, at their source times, which the new
    /// checks judge: an alarm whose condition no longer holds clears, a
    /// new check's condition that holds raises. What was under way is
    /// started again from here: a condition waiting out its delay, a
    /// transition being timed, a step's supervision time.
    pub fn take_over(&mut self, carried: Carried, now: u64) -> Vec<EngineStep> {
        let Carried {
            alarms,
            state,
            connected,
            readings,
        } = carried;
        let alarms = alarms
            .into_iter()
            .filter(|a| a.kind == AlarmKind::System || self.can_raise(&a.id))
            .collect();
        let mut steps = vec![self.restore(alarms, Some(state), now)];
        if let Some(up) = connected {
            steps.push(self.on_connection(up, now));
        }
        let mut values: Vec<TagReading> = readings
            .into_iter()
            .filter_map(|(address, reading, source_time)| {
                let tag = self.tag_index(&address).filter(|&t| t < self.configured)?;
                Some(TagReading {
                    tag,
                    reading,
                    source_time,
                })
            })
            .collect();
        values.sort_by_key(|r| r.source_time);
        if !values.is_empty() {
            steps.push(self.on_readings(&values, now));
        }
        steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::{AlarmState, Severity};
    use crate::engine::fixture::*;
    use crate::signal::Signal;

    fn restored(id: &str, latched: bool) -> Alarm {
        Alarm {
            id: id.into(),
            kind: if latched {
                AlarmKind::Timer
            } else {
                AlarmKind::Switching
            },
            severity: Severity::Critical,
            fault_type: "ESE".into(),
            active: true,
            acknowledged: !latched,
            latched,
            raised_at: 1_000,
            cleared_at: None,
            acked_by: (!latched).then(|| "kim".to_string()),
            ack_comment: None,
            fault_step: Some(6),
            culprits: Vec::new(),
            message: "ESE".into(),
            shelved: None,
            out_of_service: None,
            consequence: None,
            designed: None,
            guidance: None,
        }
    }

    #[test]
    fn an_engine_can_raise_its_checks_alarms_and_its_own_only() {
        let e = engine();
        for id in ["ese", "communication", "tag-quality"] {
            assert!(e.can_raise(id), "{id}");
        }
        for id in ["ese2", "tmr-001", "journal", ""] {
            assert!(!e.can_raise(id), "{id}");
        }
    }

    #[test]
    fn restored_alarms_come_back_as_they_were_and_follow_fresh_values() {
        let mut e = engine();
        let fault = MachineState::Fault {
            fault_type: "ESE".into(),
            element: Some("X0.06".into()),
        };
        let step = e.restore(
            vec![restored("ese", false), restored("tmr-001", true)],
            Some(fault.clone()),
            5_000,
        );
        assert_eq!(
            alarm_transitions(&step.events),
            [
                ("ese".to_string(), Transition::Restored),
                ("tmr-001".to_string(), Transition::Restored)
            ]
        );
        assert_eq!(e.state(), &fault);
        let ese = e.alarms().find(|a| a.id == "ese").unwrap();
        assert_eq!(
            (ese.state(), ese.raised_at, ese.acked_by.as_deref()),
            (AlarmState::ActiveAcknowledged, 1_000, Some("kim"))
        );
        e.on_connection(true, 5_001);
        // ESE still there: its check confirms it, no new raise.
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e
            .on_reading(x006, Reading::Good(false), 5_002, 5_002)
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Updated)]
        );
        // The normal image: ESE clears by the values, already acknowledged.
        let ev = load_normal(&mut e, 5_004);
        assert!(alarm_transitions(&ev).contains(&("ese".to_string(), Transition::Cleared)));
        let ese = e.alarms().find(|a| a.id == "ese").unwrap();
        assert_eq!(ese.state(), AlarmState::Normal);
        // The latched timer alarm waits for its reset, which works.
        let tmr = e.alarms().find(|a| a.id == "tmr-001").unwrap();
        assert!(tmr.active);
        let ev = e.reset("tmr-001", "kim", 5_006).unwrap().events;
        assert_eq!(
            alarm_transitions(&ev),
            [("tmr-001".to_string(), Transition::Cleared)]
        );
    }
}
