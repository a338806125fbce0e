//! Taking readings: the values the source delivers, one or a publish at a
//! time. Each is checked for a duplicate, placed in time (one earlier than
//! the latest seen is taken at the latest, out of order), judged for its
//! quality (bad, of the wrong type, not a number), the delays that ran out
//! before it was sampled are over first, then its value is set
//! (`changes.rs`) and the findings it brought applied, causes first.

use super::{
    BadQuality, CellEngine, EngineEvent, EngineStep, Finding, Reading, TagReading, Value,
    QUALITY_UPDATE_MS,
};
use crate::value::Num;

impl CellEngine {
    /// A value (or bad quality) for tag `tag`, with its source timestamp.
    pub fn on_reading(
        &mut self,
        tag: usize,
        reading: Reading,
        source_time: u64,
        now: u64,
    ) -> EngineStep {
        self.on_readings(
            &[TagReading {
                tag,
                reading,
                source_time,
            }],
            now,
        )
    }

    /// Values delivered together (one publish), in source-time order: one
    /// step for all.
    pub fn on_readings(&mut self, readings: &[TagReading], now: u64) -> EngineStep {
        self.readings(readings, now, false).0
    }

    /// Values delivered together, in source-time order, up to and
    /// including the first that changes an alarm: one step for those, and
    /// how many readings it took (at least one, unless `readings` is
    /// empty). The caller publishes the alarm at once and hands the rest
    /// in again, so an alarm never waits for the changes behind it.
    pub fn on_readings_to_alarm(
        &mut self,
        readings: &[TagReading],
        now: u64,
    ) -> (EngineStep, usize) {
        self.readings(readings, now, true)
    }

    fn readings(
        &mut self,
        readings: &[TagReading],
        now: u64,
        to_alarm: bool,
    ) -> (EngineStep, usize) {
        self.clock = now;
        self.begin_settling(now);
        let mut step = EngineStep::default();
        let mut findings = Vec::new();
        let mut used = 0;
        for r in readings {
            used += 1;
            if r.tag >= self.configured {
                continue;
            }
            step.readings += 1;
            let events = step.events.len();
            let changed = self.reading(r, now, &mut findings, &mut step);
            if self.settling.is_some() {
                self.settle(now, &mut step);
            }
            // The state follows each reading, so that a fault raised and
            // cleared within one publish still leaves its history rows.
            if changed || step.events.len() > events {
                // At the time the change was sampled, as the alarms judged
                // on it are (when the source's clock is trusted).
                let at = self.latest.map_or(now, |t| self.stamp(t, now));
                self.update_state(at, &mut step);
                if to_alarm && step.alarms().next().is_some() {
                    break;
                }
            }
        }
        self.collect_observations(&mut step);
        (step, used)
    }

    /// One reading; true if the machine state may have changed.
    fn reading(
        &mut self,
        r: &TagReading,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut EngineStep,
    ) -> bool {
        let tag = r.tag;
        if tag >= self.configured {
            return false;
        }
        if self.lost.is_some() {
            self.lost_now = self.take_lost(tag);
        }
        if let Some(last) = self.timestamps[tag] {
            let same = match &r.reading {
                Reading::Good(v) => self.values[tag] == Some(*v),
                Reading::Number(n) => {
                    matches!(&self.others[tag], Some(Value::Num(m)) if m == n)
                }
                Reading::Text(t) => {
                    matches!(&self.others[tag], Some(Value::Text(u)) if u == t)
                }
                Reading::Bad | Reading::WrongType { .. } | Reading::Unreachable => false,
            };
            if same && r.source_time <= last {
                step.duplicates += 1;
                self.lost_now = None;
                return false;
            }
        }
        self.heard(tag);
        self.timestamps[tag] = Some(r.source_time);
        // A number that is not one (NaN, ±inf) is bad quality, as a bad
        // status is: no limit is judged on it.
        let non_finite = not_finite(&r.reading);
        let why = match (&r.reading, non_finite) {
            (_, Some(name)) => Some(BadQuality::NotFinite(name)),
            (Reading::Bad, None) => Some(BadQuality::Status),
            (Reading::WrongType { expected, received }, None) => {
                Some(BadQuality::WrongType(*expected, *received))
            }
            _ => None,
        };
        let quality_changed = match why {
            Some(why) => {
                let was = self.bad.insert(tag, why);
                if was.is_none() {
                    step.went_bad += 1;
                    // One occurrence while tags keep going bad (the
                    // alarm's off-delay): counted in its text.
                    let occurring = self.bad.len() > 1 || self.is_active("tag-quality");
                    self.went_bad = if occurring { self.went_bad + 1 } else { 1 };
                }
                was != Some(why)
            }
            None => self.bad.remove(&tag).is_some(),
        };
        findings.clear();
        // Checks time events by when the PLC saw them, not when they
        // arrived: delivery jitter is not motion time. One earlier than
        // the latest seen is taken at the latest, and said to be out of
        // order.
        let at = match self.latest {
            Some(latest) if r.source_time < latest => {
                step.out_of_order += 1;
                self.untimed = true;
                latest
            }
            _ => {
                self.latest = Some(r.source_time);
                r.source_time
            }
        };
        let ring_at = self.ring_time(at);
        if let Some(recorder) = &mut self.recorder {
            recorder.pass(ring_at);
        }
        // Delays that ran out before this value was sampled (values sampled
        // over a while and delivered together, late or republished) are
        // over first, at their own time: a condition that lasted its delay
        // is announced before the value that ends it.
        if !self.pending.is_empty() {
            // One ending just as this value comes is judged on it.
            let before = step.events.len();
            self.run_out(at.saturating_sub(1), true, now, step);
            // The state follows them, at their time.
            let ran_out = step.events[before..].iter().rev().find_map(|e| match e {
                EngineEvent::Alarm { at, .. } => Some(*at),
                EngineEvent::State { .. } | EngineEvent::Mode { .. } => None,
            });
            if let Some(t) = ran_out {
                self.update_state(t, step);
            }
        }
        let changed = match &r.reading {
            _ if non_finite.is_some() => self.set_unknown(tag, at, findings, step),
            Reading::Good(v) => self.set_value(tag, Some(*v), at, findings, step),
            Reading::Number(n) => self.set_other(tag, Some(Value::Num(*n)), at, findings, step),
            Reading::Text(t) => {
                self.set_other(tag, Some(Value::Text(t.clone())), at, findings, step)
            }
            Reading::Bad | Reading::WrongType { .. } | Reading::Unreachable => {
                self.set_unknown(tag, at, findings, step)
            }
        };
        self.untimed = false;
        if quality_changed {
            // Raised, cleared (or its clear called off) at once; a text
            // that only names other tags at most every QUALITY_UPDATE_MS.
            let (active, bad) = (self.is_active("tag-quality"), !self.bad.is_empty());
            if active && bad && self.pending.remove("tag-quality").is_some() {
                // Bad again before its clear was announced: the same
                // occurrence goes on.
                self.quality_unsaid = true;
            } else if bad != active || now >= self.quality_said.saturating_add(QUALITY_UPDATE_MS) {
                findings.push(self.quality_finding());
                if bad {
                    self.quality_said = now;
                }
                self.quality_unsaid = false;
            } else {
                self.quality_unsaid = true;
            }
        }
        if findings.len() > 1 && !self.relation.is_empty() {
            // Causes first: within one change, an alarm that may follow
            // from another found with it is judged after it.
            let ids: Vec<String> = findings.iter().map(|f| f.id.clone()).collect();
            findings.sort_by_key(|f| {
                self.relation
                    .causes_of(&f.id)
                    .iter()
                    .filter(|(c, _)| ids.contains(c))
                    .count()
            });
        }
        for f in findings.drain(..) {
            self.judge_at(f, at, now, step);
        }
        self.lost_now = None;
        changed
    }
}

/// The name of a non-finite number, or `None` for a finite one.
fn not_finite(reading: &Reading) -> Option<&'static str> {
    match reading {
        Reading::Number(Num::Float(x)) if x.is_nan() => Some("NaN"),
        Reading::Number(Num::Float(x)) if x.is_infinite() && *x > 0.0 => Some("+inf"),
        Reading::Number(Num::Float(x)) if x.is_infinite() => Some("-inf"),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::{AlarmState, CommandRefused, Transition};
    use crate::engine::fixture::*;
    use crate::engine::{HistoryKind, MachineState};
    use crate::signal::Signal;

    #[test]
    fn fault_raises_with_culprit_and_clears() {
        let mut e = engine();
        let ev = e.on_connection(true, 1).events;
        assert_eq!(alarm_transitions(&ev), []);
        let ev = load_normal(&mut e, 2);
        assert!(alarm_transitions(&ev).is_empty());
        assert_eq!(e.state(), &MachineState::Running);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Raised)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.fault_step, Some(6));
        assert_eq!(alarm.culprits[0].address.name(), "X0.06");
        assert!(alarm.culprits[0].trigger);
        assert_eq!(
            e.state(),
            &MachineState::Fault {
                fault_type: "ESE".into(),
                element: Some("X0.06".into())
            }
        );
        assert!(matches!(
            ev.last(),
            Some(EngineEvent::State {
                kind: HistoryKind::Fault,
                ..
            })
        ));
        // Delivered again after a subscription is recreated: ignored.
        let dup = e.on_reading(x006, Reading::Good(false), 10, 11);
        assert!(dup.events.is_empty());
        assert_eq!(dup.duplicates, 1);
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Cleared)]
        );
        assert!(matches!(
            ev.last(),
            Some(EngineEvent::State {
                kind: HistoryKind::Recovery,
                state: MachineState::Running,
                ..
            })
        ));
        let a = e.alarms().next().unwrap();
        assert_eq!(a.state(), AlarmState::ClearedUnacknowledged);
        let ev = e
            .acknowledge("ese", "kim", Some("limit switch re-seated"), 30)
            .unwrap()
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Acknowledged)]
        );
        let a = e.alarms().next().unwrap();
        assert_eq!(a.state(), AlarmState::Normal);
        assert_eq!(
            (a.acked_by.as_deref(), a.ack_comment.as_deref()),
            (Some("kim"), Some("limit switch re-seated"))
        );
        assert_eq!(
            e.acknowledge("ese", "kim", None, 31),
            Err(CommandRefused::NothingToAcknowledge("ese".into()))
        );
        assert!(e.reset("ese", "kim", 32).is_err());
        // Raised again: the last occurrence's comment is not this one's.
        e.on_reading(x006, Reading::Good(false), 40, 40);
        let a = e.alarms().next().unwrap();
        assert_eq!(a.state(), AlarmState::ActiveUnacknowledged);
        assert_eq!(
            (a.acked_by.as_deref(), a.ack_comment.as_deref()),
            (None, None)
        );
    }

    #[test]
    fn a_publish_is_cut_after_each_alarm_and_comes_to_the_same() {
        let mut whole = engine();
        let mut cut = engine();
        for e in [&mut whole, &mut cut] {
            e.on_connection(true, 1);
            load_normal(e, 2);
        }
        let x006 = whole.tag_index(&Signal::new("X0.06")).unwrap();
        let other = (0..whole.tags().len()).find(|&t| t != x006).unwrap();
        let r = |tag, v, at| TagReading {
            tag,
            reading: Reading::Good(v),
            source_time: at,
        };
        let publish = [
            r(other, false, 10),
            r(x006, false, 11),
            r(other, true, 12),
            r(x006, true, 13),
            r(other, false, 14),
        ];
        let all = whole.on_readings(&publish, 20);
        assert_eq!(alarm_transitions(&all.events).len(), 2);
        let mut rest = &publish[..];
        let mut parts = Vec::new();
        while !rest.is_empty() {
            let (step, used) = cut.on_readings_to_alarm(rest, 20);
            rest = &rest[used..];
            parts.push((used, step));
        }
        let used: Vec<usize> = parts.iter().map(|(n, _)| *n).collect();
        assert_eq!(used, [2, 2, 1], "cut after the raise and after the clear");
        let alarms = |p: &(usize, EngineStep)| alarm_transitions(&p.1.events);
        assert_eq!(alarms(&parts[0]), [("ese".to_string(), Transition::Raised)]);
        assert_eq!(
            alarms(&parts[1]),
            [("ese".to_string(), Transition::Cleared)]
        );
        assert!(alarms(&parts[2]).is_empty());
        let events: Vec<EngineEvent> = parts.iter().flat_map(|(_, s)| s.events.clone()).collect();
        assert_eq!(events, all.events);
        let readings: u64 = parts.iter().map(|(_, s)| s.readings).sum();
        assert_eq!(readings, all.readings);
        assert_eq!(cut.all_values(), whole.all_values());
        assert_eq!(cut.on_readings_to_alarm(&[], 21).1, 0);
    }

    #[test]
    fn bad_quality_suspends_and_is_reported() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e.on_reading(x006, Reading::Bad, 3, 3).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("tag-quality".to_string(), Transition::Raised)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(
            alarm.message,
            "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06)"
        );
        // Another contact of the same OR opens while X0.06 is unknown: the
        // fault is certain whatever X0.06 holds, so ESE is raised, naming
        // the unknown contact and blaming only known ones.
        let x004 = e.tag_index(&Signal::new("X0.04")).unwrap();
        let ev = e.on_reading(x004, Reading::Good(false), 4, 4).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Raised)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.culprits.len(), 1, "{:?}", alarm.culprits);
        assert_eq!(alarm.culprits[0].address.name(), "X0.04");
        assert!(
            alarm.message.ends_with("(unknown: X0.06)"),
            "{}",
            alarm.message
        );
        // X0.04 closes again: X0.06 could still hold the fault, so nothing
        // is cleared on an unknown value.
        let ev = e.on_reading(x004, Reading::Good(true), 5, 5).events;
        assert_eq!(alarm_transitions(&ev), []);
        // X0.06 good again and closed: the check clears on known values.
        let ev = e.on_reading(x006, Reading::Good(true), 6, 6).events;
        let t = alarm_transitions(&ev);
        assert!(
            t.contains(&("ese".to_string(), Transition::Cleared)),
            "{t:?}"
        );
        assert!(
            t.contains(&("tag-quality".to_string(), Transition::Cleared)),
            "{t:?}"
        );
    }

    #[test]
    fn an_unknown_contact_that_could_decide_suspends() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        // Step 5's OR: X0.07 unknown, every other term normal: the fault
        // depends on X0.07, nothing is raised.
        let x007 = e.tag_index(&Signal::new("X0.07")).unwrap();
        let ev = e.on_reading(x007, Reading::Bad, 3, 3).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("tag-quality".to_string(), Transition::Raised)]
        );
        // And it is raised once X0.07 is known open.
        let ev = e.on_reading(x007, Reading::Good(false), 4, 4).events;
        let t = alarm_transitions(&ev);
        assert!(
            t.contains(&("ese".to_string(), Transition::Raised)),
            "{t:?}"
        );
    }
}
