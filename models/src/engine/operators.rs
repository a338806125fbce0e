//! Operators' actions on alarms: acknowledge, shelve and unshelve, take out
//! of service and return to it (ISA-18.2), reset a latched alarm. Each
//! answers with its step, or why it is refused. An acknowledgement made at
//! the PLC is `conditions.rs`'s.

use super::{CellEngine, EngineEvent, EngineStep};
use crate::alarm::{CommandRefused, Transition};

impl CellEngine {
    /// An operator acknowledges an alarm, saying `comment` if anything
    /// (kept with the occurrence, gone when it is raised again).
    ///
    /// # Errors
    /// No such alarm, or nothing to acknowledge.
    pub fn acknowledge(
        &mut self,
        id: &str,
        operator: &str,
        comment: Option<&str>,
        now: u64,
    ) -> Result<EngineStep, CommandRefused> {
        let alarm = self.alarms.acknowledge(id, operator, comment)?.clone();
        if self.is_condition(id) {
            self.alarms.forget_if_normal(id);
        }
        Ok(EngineStep {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Acknowledged,
                at: now,
            }],
            ..EngineStep::default()
        })
    }

    /// An operator shelves alarm `id`: until `until` (ms), or with `None`
    /// one-shot, until the alarm clears. It is still evaluated and
    /// journaled; its payloads say it is shelved.
    ///
    /// # Errors
    /// No such alarm, or a one-shot shelf on an alarm not active.
    pub fn shelve(
        &mut self,
        id: &str,
        operator: &str,
        reason: &str,
        until: Option<u64>,
        now: u64,
    ) -> Result<EngineStep, CommandRefused> {
        let shelf = crate::alarm::Shelf {
            by: operator.to_string(),
            reason: reason.to_string(),
            at: now,
            until,
        };
        let alarm = self.alarms.shelve(id, shelf)?.clone();
        Ok(EngineStep {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Shelved,
                at: now,
            }],
            ..EngineStep::default()
        })
    }

    /// An operator ends the shelf on alarm `id`.
    ///
    /// # Errors
    /// No such alarm, or it is not shelved.
    pub fn unshelve(&mut self, id: &str, now: u64) -> Result<EngineStep, CommandRefused> {
        let alarm = self.alarms.unshelve(id)?.clone();
        Ok(EngineStep {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Unshelved,
                at: now,
            }],
            ..EngineStep::default()
        })
    }

    /// An operator takes alarm `id` out of service (ISA-18.2): whatever its
    /// condition it is not raised until it is back in service; an active
    /// occurrence ends now. Any alarm the checks can raise may be taken out,
    /// raised before or not.
    ///
    /// # Errors
    /// No such alarm, or it is out of service already.
    pub fn take_out_of_service(
        &mut self,
        id: &str,
        operator: &str,
        reason: &str,
        now: u64,
    ) -> Result<EngineStep, CommandRefused> {
        let removal = crate::alarm::Removal {
            by: operator.to_string(),
            reason: reason.to_string(),
            at: now,
        };
        let alarm = self.alarms.take_out_of_service(id, removal, now)?.clone();
        self.pending.remove(id);
        for set in &mut self.sets {
            set.reset(id);
        }
        let mut step = EngineStep {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::OutOfService,
                at: now,
            }],
            ..EngineStep::default()
        };
        self.update_state(now, &mut step);
        Ok(step)
    }

    /// An operator puts alarm `id` back in service: raised at once if its
    /// condition holds (after its on-delay, if it has one).
    ///
    /// # Errors
    /// No such alarm, or it is not out of service.
    pub fn return_to_service(&mut self, id: &str, now: u64) -> Result<EngineStep, CommandRefused> {
        let (alarm, held) = self.alarms.return_to_service(id)?;
        let mut step = EngineStep {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::InService,
                at: now,
            }],
            ..EngineStep::default()
        };
        if let Some(f) = held {
            self.apply(f, now, &mut step);
        }
        self.update_state(now, &mut step);
        Ok(step)
    }

    /// An operator resets a latched alarm whose condition is gone.
    ///
    /// # Errors
    /// No such alarm, not latched, not active, or its condition still holds.
    pub fn reset(
        &mut self,
        id: &str,
        operator: &str,
        now: u64,
    ) -> Result<EngineStep, CommandRefused> {
        let alarm = self.alarms.reset(id, operator, now)?.clone();
        for set in &mut self.sets {
            set.reset(id);
        }
        let mut step = EngineStep {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Cleared,
                at: now,
            }],
            ..EngineStep::default()
        };
        self.update_state(now, &mut step);
        Ok(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::{Alarm, AlarmState};
    use crate::engine::fixture::*;
    use crate::engine::{MachineState, Reading};
    use crate::signal::Signal;

    fn shelf_of(e: &CellEngine, id: &str) -> Option<crate::alarm::Shelf> {
        e.alarms()
            .find(|a| a.id == id)
            .and_then(|a| a.shelved.as_deref().cloned())
    }

    #[test]
    fn a_shelf_lasts_its_time_in_virtual_time_and_survives_a_restart() {
        const MIN: u64 = 60_000;
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        // Shelved for 30 minutes: its updates say so.
        let ev = e
            .shelve("ese", "kim", "sensor cable", Some(10 + 30 * MIN), 10)
            .unwrap()
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Shelved)]
        );
        assert_eq!(shelf_of(&e, "ese").unwrap().until, Some(10 + 30 * MIN));
        assert!(alarm_transitions(&e.advance(10 + 30 * MIN - 1).events).is_empty());
        // A restart in the meantime keeps the shelf and its expiry.
        let saved: Vec<Alarm> = e.alarms().cloned().collect();
        let mut e = engine();
        e.restore(saved, None, 20 * MIN);
        assert_eq!(shelf_of(&e, "ese").unwrap().reason, "sensor cable");
        assert!(alarm_transitions(&e.advance(10 + 30 * MIN - 1).events).is_empty());
        // At expiry, announced again as it is: still active.
        let ev = e.advance(10 + 30 * MIN).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Unshelved)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert!(alarm.active && alarm.shelved.is_none());
        assert!(alarm_transitions(&e.advance(40 * MIN).events).is_empty());
        // Unshelving what is not shelved is refused.
        assert!(e.unshelve("ese", 40 * MIN).is_err());
    }

    #[test]
    fn a_one_shot_shelf_ends_when_the_alarm_clears() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // Not for an alarm that is not active, nor an unknown one.
        assert!(e.shelve("ese", "kim", "noise", None, 3).is_err());
        e.on_reading(x006, Reading::Good(false), 10, 10);
        e.shelve("ese", "kim", "known trouble", None, 11).unwrap();
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Cleared)]
        );
        assert_eq!(shelf_of(&e, "ese"), None);
        // The next occurrence is announced.
        let ev = e.on_reading(x006, Reading::Good(false), 30, 30).events;
        let EngineEvent::Alarm {
            alarm, transition, ..
        } = &ev[0]
        else {
            panic!()
        };
        assert_eq!(
            (*transition, alarm.shelved.is_none()),
            (Transition::Raised, true)
        );
        // A timed shelf does outlive an occurrence.
        e.shelve("ese", "kim", "known trouble", Some(1_000), 31)
            .unwrap();
        e.on_reading(x006, Reading::Good(true), 40, 40);
        let ev = e.on_reading(x006, Reading::Good(false), 50, 50).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.shelved.as_ref().and_then(|s| s.until), Some(1_000));
        assert!(e.shelve("nope", "kim", "x", None, 60).is_err());
    }

    #[test]
    fn out_of_service_raises_nothing_and_back_in_service_raises_what_holds() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // Never raised yet, but the check declares it: it can be taken out.
        let ev = e
            .take_out_of_service("ese", "kim", "switch replaced", 5)
            .unwrap()
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::OutOfService)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.state(), AlarmState::Normal);
        assert_eq!(alarm.out_of_service.as_ref().unwrap().by, "kim");
        assert!(e.take_out_of_service("ese", "kim", "again", 6).is_err());
        assert!(e.take_out_of_service("nope", "kim", "x", 6).is_err());
        // The condition becomes true: nothing raised, the machine not at
        // fault.
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10).events;
        assert_eq!(alarm_transitions(&ev), []);
        assert_eq!(e.state(), &MachineState::Running);
        // A restart keeps it out of service.
        let saved: Vec<Alarm> = e.alarms().cloned().collect();
        let mut e = engine();
        e.on_connection(true, 11);
        e.restore(saved, None, 11);
        load_normal(&mut e, 12);
        let ev = e.on_reading(x006, Reading::Good(false), 13, 13).events;
        assert_eq!(alarm_transitions(&ev), []);
        // Back in service while the condition holds: raised, with its
        // culprit.
        let ev = e.return_to_service("ese", 20).unwrap().events;
        assert_eq!(
            alarm_transitions(&ev),
            [
                ("ese".to_string(), Transition::InService),
                ("ese".to_string(), Transition::Raised)
            ]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[1] else {
            panic!()
        };
        assert_eq!(alarm.culprits[0].address.name(), "X0.06");
        assert_eq!(alarm.raised_at, 20);
        assert!(matches!(e.state(), MachineState::Fault { .. }));
        assert!(e.return_to_service("ese", 21).is_err());
        // Taken out while active: the occurrence ends, the fault with it;
        // back in service after the condition went, nothing is raised.
        let ev = e.take_out_of_service("ese", "kim", "again", 30).unwrap();
        let EngineEvent::Alarm { alarm, .. } = &ev.events[0] else {
            panic!()
        };
        assert_eq!(
            (alarm.state(), alarm.cleared_at),
            (AlarmState::Normal, Some(30))
        );
        assert_eq!(e.state(), &MachineState::Running);
        e.on_reading(x006, Reading::Good(true), 40, 40);
        let ev = e.return_to_service("ese", 50).unwrap().events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::InService)]
        );
    }
}
