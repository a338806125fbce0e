//! The source's link to the PLC: the connection up and down (one
//! `communication` alarm, every tag unknown while it is down, the values at
//! the cut kept), changes lost for good in a gap (an alarm judged on them
//! names no trigger and says why), and a subscription resumed with nothing
//! lost (the values at the cut back before the changes made meanwhile).
//! The values the source delivers are `reading.rs`'s.

use super::{uncertain_trigger, AtCut, CellEngine, EngineStep, Finding, Lost, Rhs};
use crate::alarm::{AlarmKind, Severity};
use crate::signal::Signal;

impl CellEngine {
    /// The source lost changes for good (`why`): of `tags`, or of any tag
    /// (`None`: a sequence gap says nothing of what was in it); `values`
    /// of them when it knows how many. Until each such tag's next value,
    /// an alarm raised or cleared on it carries "trigger uncertain" and
    /// names no trigger: the change that tripped it may be among the lost.
    pub fn on_gap(&mut self, tags: Option<&[usize]>, values: u64, why: &str) -> EngineStep {
        let n = self.tags.len();
        let lost = self.lost.get_or_insert_with(|| Lost {
            tags: vec![false; n],
            why: String::new(),
        });
        lost.why = why.to_string();
        match tags {
            None => {
                lost.tags.iter_mut().for_each(|t| *t = true);
                // Not resumed: what was before the cut is no longer known.
                self.at_cut = None;
            }
            Some(tags) => {
                for &t in tags {
                    if let Some(t) = lost.tags.get_mut(t) {
                        *t = true;
                    }
                }
            }
        }
        // Verdicts waiting out a delay across the gap say so when they come.
        let signals: Option<Vec<Signal>> = tags.map(|ts| {
            ts.iter()
                .filter_map(|&t| self.tags.get(t))
                .map(|t| t.address.clone())
                .collect()
        });
        for set in &mut self.sets {
            set.on_gap(signals.as_deref(), why);
        }
        let waiting: Vec<String> = self.pending.keys().cloned().collect();
        let gone: Option<std::collections::HashSet<&Signal>> =
            signals.as_ref().map(|s| s.iter().collect());
        for id in waiting {
            let touched = gone.as_ref().is_none_or(|gone| {
                let mut reads = Vec::new();
                for set in &self.sets {
                    set.reads(&id, &mut reads);
                }
                reads.iter().any(|r| gone.contains(r))
            });
            if let Some((_, _, f)) = self.pending.get_mut(&id).filter(|_| touched) {
                if !f.message.contains("(trigger uncertain") {
                    uncertain_trigger(f, why);
                }
            }
        }
        EngineStep {
            gaps: 1,
            lost_values: values,
            ..EngineStep::default()
        }
    }

    /// The source took up where the lost connection left off, losing
    /// nothing (the server kept the subscription and sends every change
    /// made meanwhile, in order): each tag not heard since the cut is again
    /// what it was then, so that the changes that follow are judged
    /// against it — a contact that opened during the cut is a trigger,
    /// not a value out of nowhere. Call it before those changes.
    pub fn on_resumed(&mut self, now: u64) -> EngineStep {
        self.clock = now;
        let mut step = EngineStep::default();
        let Some(cut) = self.at_cut.take() else {
            return step;
        };
        let mut findings = Vec::new();
        // Back to what was, at the last time seen: no timer measures
        // through it.
        let at = self.latest.unwrap_or(now);
        self.untimed = true;
        for t in 0..cut.values.len().min(self.configured) {
            if self.timestamps[t].is_some() {
                // Heard since: its own value stands.
                continue;
            }
            match (cut.values[t], &cut.others[t]) {
                (Some(v), _) => {
                    self.set_value(t, Some(v), at, &mut findings, &mut step);
                }
                (None, Some(v)) => {
                    self.set_other(t, Some(v.clone()), at, &mut findings, &mut step);
                }
                (None, None) => continue,
            }
            if cut.timestamps[t].is_some() {
                self.heard(t);
            }
            self.timestamps[t] = cut.timestamps[t];
        }
        self.untimed = false;
        for f in findings {
            self.judge_at(f, now, now, &mut step);
        }
        self.settle(now, &mut step);
        self.update_state(now, &mut step);
        self.collect_observations(&mut step);
        step
    }

    /// Why `tag`'s changes may have been lost, if they may; the mark is
    /// taken off: its value is here.
    pub(super) fn take_lost(&mut self, tag: usize) -> Option<String> {
        let lost = self.lost.as_mut()?;
        if !std::mem::take(lost.tags.get_mut(tag)?) {
            return None;
        }
        let why = lost.why.clone();
        if !lost.tags.iter().any(|&t| t) {
            self.lost = None;
        }
        Some(why)
    }

    /// Why the trigger of `f` is uncertain, if it is: the reading that
    /// judged it, or a contact it names, may have lost changes.
    pub(super) fn uncertain(&self, f: &Finding) -> Option<String> {
        if let Some(why) = &self.lost_now {
            return Some(why.clone());
        }
        let lost = self.lost.as_ref()?;
        let marked = |t: usize| lost.tags.get(t).copied().unwrap_or(false);
        f.culprits.iter().find_map(|c| {
            let t = self.tag_index(&c.address)?;
            let hit = marked(t)
                || self.derived.iter().any(|d| {
                    d.tag == t && (marked(d.lhs) || matches!(d.rhs, Rhs::Tag(r) if marked(r)))
                });
            hit.then(|| lost.why.clone())
        })
    }

    /// The connection to the PLC came up or went down.
    pub fn on_connection(&mut self, up: bool, now: u64) -> EngineStep {
        self.clock = now;
        let mut step = EngineStep::default();
        if Some(up) == self.connected {
            return step;
        }
        self.connected = Some(up);
        // Up: what the source resumes with, or a new subscription's
        // values, is here.
        self.at_cut = None;
        // One occurrence while the connection keeps going (the alarm's
        // off-delay): its losses are counted in its text.
        let occurring = self.is_active("communication");
        if !up {
            // A condition waiting out its delay is no longer seen to hold.
            self.pending.clear();
            self.losses = if occurring { self.losses + 1 } else { 1 };
        }
        let losses = match self.losses {
            0 | 1 => String::new(),
            n => format!(" ({n} losses since it was raised)"),
        };
        let finding = Finding {
            at: None,
            id: "communication".into(),
            kind: AlarmKind::Communication,
            severity: Severity::High,
            fault_type: "COMM".into(),
            latched: false,
            active: !up,
            fault_step: None,
            culprits: Vec::new(),
            message: if up {
                format!("communication restored{losses}")
            } else {
                format!("communication lost: every tag is unknown{losses}")
            },
        };
        if !up {
            self.at_cut = Some(Box::new(AtCut {
                values: self.values[..self.configured].to_vec(),
                others: self.others[..self.configured].to_vec(),
                timestamps: self.timestamps[..self.configured].to_vec(),
            }));
            // Every value is now unknown; checks hold their verdicts.
            let mut ignored = Vec::new();
            for t in 0..self.configured {
                self.set_unknown(t, now, &mut ignored, &mut step);
            }
            self.timestamps.iter_mut().for_each(|t| *t = None);
            self.unheard = self.configured;
            self.settling = None;
            self.awaiting_first = true;
        } else {
            self.begin_settling(now);
        }
        self.apply(finding, now, &mut step);
        if up && self.bad.is_empty() {
            // A `tag-quality` alarm restored from the journal clears once
            // the PLC is back and no tag is bad.
            let quality = self.quality_finding();
            self.apply(quality, now, &mut step);
        }
        self.update_state(now, &mut step);
        self.collect_observations(&mut step);
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::Transition;
    use crate::engine::fixture::*;
    use crate::engine::{EngineEvent, MachineState, Reading};

    #[test]
    fn an_alarm_judged_across_a_gap_names_no_trigger_until_each_tag_is_heard_again() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // Changes of any tag lost (a sequence gap): counted, and the next
        // alarm on a tag not heard since names no trigger.
        let gap = e.on_gap(None, 0, "publishes 7 to 9 lost");
        assert_eq!((gap.gaps, gap.lost_values), (1, 0));
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert!(alarm.culprits.iter().all(|c| !c.trigger), "{alarm:?}");
        assert!(
            alarm
                .message
                .ends_with("(trigger uncertain: publishes 7 to 9 lost)"),
            "{}",
            alarm.message
        );
        // Heard again: the clear names its trigger as usual.
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert!(!alarm.message.contains("uncertain"), "{}", alarm.message);
        // A gap of other tags leaves this one's alarms alone; every mark
        // goes once each of them is heard.
        let others: Vec<usize> = (0..e.tags().len()).filter(|&t| t != x006).collect();
        let gap = e.on_gap(Some(&others), 3, "3 values lost in a full queue");
        assert_eq!((gap.gaps, gap.lost_values), (1, 3));
        let ev = e.on_reading(x006, Reading::Good(false), 30, 30).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        // X0.06 is the only culprit: certain.
        assert!(alarm.culprits[0].trigger, "{alarm:?}");
        assert!(!alarm.message.contains("uncertain"), "{}", alarm.message);
        for &t in &others {
            let v = e.values()[t];
            e.on_reading(t, Reading::Good(v.unwrap_or(false)), 40, 40);
        }
        assert!(e.lost.is_none());
    }

    #[test]
    fn a_fault_made_during_a_cut_the_source_resumed_from_has_its_trigger() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_connection(false, 5);
        assert!(e.values().iter().all(Option::is_none), "{:?}", e.values());
        // Resumed: the values are back, with no alarm of their own.
        let back = e.on_resumed(8);
        assert!(alarm_transitions(&back.events).is_empty(), "{back:?}");
        assert!(e.values().iter().all(Option::is_some));
        // The change made during the cut, delivered after it.
        let ev = e.on_reading(x006, Reading::Good(false), 6, 9).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert!(alarm.culprits[0].trigger, "{alarm:?}");
        assert!(!alarm.message.contains("unknown"), "{}", alarm.message);
        // Not resumed (a new subscription): nothing comes back.
        e.on_connection(true, 10);
        e.on_connection(false, 10);
        e.on_gap(None, 0, "subscription replaced");
        e.on_resumed(11);
        assert!(e.values().iter().all(Option::is_none));
    }

    #[test]
    fn lost_connection_is_one_alarm_and_no_process_alarm() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let ev = e.on_connection(false, 5).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Raised)]
        );
        assert_eq!(e.state(), &MachineState::Offline);
        assert!(e.values().iter().all(Option::is_none));
        // Reconnected: values come back one by one; while the unknown ones
        // could still decide, the check holds, so a half-loaded normal
        // image raises nothing.
        let ev = e.on_connection(true, 6).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Cleared)]
        );
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        assert!(
            alarm_transitions(&e.on_reading(x006, Reading::Good(true), 7, 7).events).is_empty()
        );
        let ev = load_normal(&mut e, 8);
        assert!(alarm_transitions(&ev).is_empty(), "{ev:?}");
    }

    #[test]
    fn unreachable_from_the_start_is_one_alarm() {
        let mut e = engine();
        let ev = e.on_connection(false, 1).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Raised)]
        );
        assert!(e.on_connection(false, 2).events.is_empty());
    }
}
