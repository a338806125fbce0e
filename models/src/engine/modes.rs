//! Machine modes and designed suppression (ISA-18.2 / IEC 62682
//! state-based alarming): a cell declares the modes its PLC's tags say (a
//! mode word, a selector, a PackML state number) and, per mode, the alarms
//! that mean nothing in it (a press in setup, a line stopped for a
//! changeover). While a mode holds, the alarms it names are still
//! evaluated and journaled but carry [`DesignedSuppression`] and are not
//! announced; entering and leaving a mode is an [`EngineEvent::Mode`]; an
//! alarm active when its suppression ends is announced then
//! ([`Transition::Unsuppressed`]).
//!
//! A mode changes only on known values: while a tag it reads is unknown
//! (bad quality, the link down) it keeps what it last was, so that a lost
//! link neither ends a setup's suppression nor begins one.
//!
//! Not here: shelving (an operator's, timed) and out of service
//! (maintenance) are the alarm book's.

use super::{CellEngine, EngineEvent, EngineStep};
use crate::alarm::AlarmPattern;
use crate::alarm::{AlarmState, DesignedSuppression, Transition};
use crate::expr::Expr;
use crate::signal::Signal;

/// A machine mode and the alarms suppressed by design while it holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mode {
    /// Its id, as journaled and published (`setup`).
    pub id: String,
    /// It holds while this holds (over tag addresses; comparisons of
    /// numbers are contacts: `D104 == 2`).
    pub when: Expr,
    /// The alarms it suppresses.
    pub suppress: Vec<AlarmPattern>,
}

impl CellEngine {
    /// Every pattern of a mode that can match no alarm of this engine, as
    /// (mode index, pattern index): neither an alarm its checks declared,
    /// `communication`, `tag-quality`, nor a PLC condition of a prefix it
    /// takes (`<prefix>-…`). Call it after
    /// [`CellEngine::taking_conditions`].
    pub fn unmatched_patterns(&self) -> Vec<(usize, usize)> {
        let own = ["communication", "tag-quality"];
        let mut out = Vec::new();
        for (k, mode) in self.rules.modes.iter().enumerate() {
            for (j, p) in mode.suppress.iter().enumerate() {
                let matched = own.iter().copied().any(|id| p.matches(id))
                    || self.alarms.declared_ids().any(|id| p.matches(id))
                    || self.conditions.iter().any(|prefix| {
                        let wanted = format!("{prefix}-");
                        p.as_str().starts_with(&wanted) || p.matches(&format!("{wanted}x"))
                    });
                if !matched {
                    out.push((k, j));
                }
            }
        }
        out
    }

    /// The modes that hold now, by id.
    pub fn modes_on(&self) -> impl Iterator<Item = &str> {
        self.rules
            .modes
            .iter()
            .zip(&self.modes_on)
            .filter(|(_, on)| **on)
            .map(|(m, _)| m.id.as_str())
    }

    /// The mode that suppresses alarm `id` by design now, if one does:
    /// the first declared of those that hold.
    pub(super) fn designed_for(&self, id: &str) -> Option<&str> {
        self.rules
            .modes
            .iter()
            .zip(&self.modes_on)
            .find(|(m, on)| **on && m.suppress.iter().any(|p| p.matches(id)))
            .map(|(m, _)| m.id.as_str())
    }

    /// Re-judges every mode on the values now; each one entered or left is
    /// an event, and every alarm not back to normal whose designed
    /// suppression changes with it is one too.
    pub(super) fn update_modes(&mut self, now: u64, step: &mut EngineStep) {
        let mut changed = false;
        for k in 0..self.rules.modes.len() {
            let Some(holds) = self.mode_holds(k) else {
                continue;
            };
            if holds != self.modes_on[k] {
                self.modes_on[k] = holds;
                changed = true;
                step.events.push(EngineEvent::Mode {
                    mode: self.rules.modes[k].id.clone(),
                    entered: holds,
                    at: now,
                });
            }
        }
        if !changed {
            return;
        }
        let ids: Vec<String> = self.alarms.iter().map(|a| a.id.clone()).collect();
        for id in ids {
            let mode = self.designed_for(&id).map(str::to_string);
            let Some(alarm) = self.alarms.get(&id) else {
                continue;
            };
            let was = alarm.designed.as_ref().map(|d| d.mode.clone());
            if was == mode {
                continue;
            }
            let shown = alarm.state() != AlarmState::Normal;
            let transition = match (&was, &mode) {
                (None, Some(_)) => Transition::Suppressed,
                (Some(_), None) => Transition::Unsuppressed,
                // From one mode's suppression to another's: still
                // suppressed, by the other.
                _ => Transition::Updated,
            };
            let designed = mode.map(|mode| Box::new(DesignedSuppression { mode, since: now }));
            let Some(alarm) = self.alarms.set_designed(&id, designed) else {
                continue;
            };
            if shown {
                step.events.push(EngineEvent::Alarm {
                    alarm: alarm.clone(),
                    transition,
                    at: now,
                });
            }
        }
    }

    /// Whether mode `k` holds on the values now; `None` while a tag it
    /// reads is unknown.
    fn mode_holds(&self, k: usize) -> Option<bool> {
        let expr = &self.rules.modes[k].when;
        let value = |s: &Signal| self.tag_index(s).and_then(|t| self.values[t]);
        if !expr.signals().iter().all(|s| value(s).is_some()) {
            return None;
        }
        Some(expr.eval(&|s: &Signal| value(s).unwrap_or(false)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::Alarm;
    use crate::engine::fixture::{alarm_transitions, engine_ruled, load_normal};
    use crate::engine::{Reading, StateRules, Tag};
    use crate::value::Num;

    /// The ESE cell with a mode word `D104`: mode `setup` (2) suppresses
    /// `ese`, connected, at its normal values.
    fn cell_with_setup(suppress: &[&str]) -> (CellEngine, usize, usize) {
        let word = Tag {
            name: "mode".into(),
            address: Signal::new("D104"),
        };
        let rules = StateRules {
            modes: vec![Mode {
                id: "setup".into(),
                when: Expr::parse("D104 == 2").unwrap(),
                suppress: suppress.iter().map(|p| AlarmPattern::new(p)).collect(),
            }],
            ..StateRules::default()
        };
        let mut e = engine_ruled(&[word], rules);
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let d104 = e.tag_index(&Signal::new("D104")).unwrap();
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        (e, d104, x006)
    }

    fn modes(step: &EngineStep) -> Vec<(&str, bool)> {
        step.modes().map(|(m, entered, _)| (m, entered)).collect()
    }

    fn ese(e: &CellEngine) -> Alarm {
        e.alarms().find(|a| a.id == "ese").unwrap().clone()
    }

    #[test]
    fn an_alarm_raised_in_a_mode_that_suppresses_it_is_evaluated_and_announced_when_it_ends() {
        let (mut e, d104, x006) = cell_with_setup(&["es*"]);
        let step = e.on_reading(d104, Reading::Number(Num::UInt(2)), 10, 10);
        assert_eq!(modes(&step), [("setup", true)]);
        assert_eq!(e.modes_on().collect::<Vec<_>>(), ["setup"]);
        // Raised, journaled, but suppressed by design: not announced.
        let step = e.on_reading(x006, Reading::Good(false), 20, 20);
        assert_eq!(
            alarm_transitions(&step.events),
            [("ese".into(), Transition::Raised)]
        );
        let alarm = ese(&e);
        assert_eq!(
            alarm.designed.as_deref(),
            Some(&DesignedSuppression {
                mode: "setup".into(),
                since: 20
            })
        );
        assert!(alarm.active && !alarm.is_announced());
        // The mode ends with the alarm active: announced now.
        let step = e.on_reading(d104, Reading::Number(Num::UInt(1)), 30, 30);
        assert_eq!(modes(&step), [("setup", false)]);
        assert_eq!(
            alarm_transitions(&step.events),
            [("ese".into(), Transition::Unsuppressed)]
        );
        let alarm = ese(&e);
        assert!(alarm.active && alarm.is_announced() && alarm.designed.is_none());
        assert_eq!(e.modes_on().count(), 0);
    }

    #[test]
    fn an_active_alarm_is_suppressed_when_its_mode_begins_and_others_are_not() {
        let (mut e, d104, x006) = cell_with_setup(&["tag-quality"]);
        e.on_reading(x006, Reading::Good(false), 20, 20);
        assert!(ese(&e).is_announced());
        // A mode that names other alarms leaves this one announced.
        let step = e.on_reading(d104, Reading::Number(Num::UInt(2)), 30, 30);
        assert_eq!(modes(&step), [("setup", true)]);
        assert!(alarm_transitions(&step.events).is_empty());
        let (mut e, d104, x006) = cell_with_setup(&["ese"]);
        e.on_reading(x006, Reading::Good(false), 20, 20);
        let step = e.on_reading(d104, Reading::Number(Num::UInt(2)), 30, 30);
        assert_eq!(
            alarm_transitions(&step.events),
            [("ese".into(), Transition::Suppressed)]
        );
        assert_eq!(ese(&e).designed.map(|d| d.since), Some(30));
        // Cleared and acknowledged while suppressed: back to normal.
        let step = e.on_reading(x006, Reading::Good(true), 40, 40);
        assert_eq!(
            alarm_transitions(&step.events),
            [("ese".into(), Transition::Cleared)]
        );
        assert!(ese(&e).designed.is_some());
    }

    #[test]
    fn a_mode_keeps_what_it_was_while_its_tag_is_unknown() {
        let (mut e, d104, x006) = cell_with_setup(&["ese"]);
        e.on_reading(d104, Reading::Number(Num::UInt(2)), 10, 10);
        e.on_reading(x006, Reading::Good(false), 20, 20);
        // The mode word goes bad, then the link drops: still in setup,
        // the alarm still suppressed.
        let step = e.on_reading(d104, Reading::Bad, 30, 30);
        assert_eq!(modes(&step), []);
        let step = e.on_connection(false, 40);
        assert_eq!(modes(&step), []);
        assert!(ese(&e).designed.is_some());
        assert_eq!(e.modes_on().collect::<Vec<_>>(), ["setup"]);
    }

    #[test]
    fn a_pattern_that_names_no_alarm_of_the_cell_is_found() {
        let (e, _, _) = cell_with_setup(&["ese", "door-*", "*", "communication"]);
        assert_eq!(e.unmatched_patterns(), [(0, 1)]);
        let e = e.taking_conditions(["door".to_string()]);
        assert_eq!(e.unmatched_patterns(), []);
    }
}
