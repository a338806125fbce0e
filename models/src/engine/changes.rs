//! A tag's value changing, whatever brought it (a reading, the connection
//! lost, a subscription resumed): the count of unknown tags, parts counted
//! (a rising edge, or a counter's increments), the exported gauges, the
//! work order, the comparison contacts computed from numbers, the flight
//! recorder, and the check sets that read the tag, each fed the change.
//! Whether a delivered value is taken at all (a duplicate, bad quality) is
//! `reading.rs`'s.

use super::{CellEngine, Derived, EngineStep, Finding, PartCounting, Rhs, Value};
use crate::value::Num;

impl CellEngine {
    /// Counts tag `tag` known or unknown.
    fn known_changed(&mut self, tag: usize, was: bool, is: bool, step: &mut EngineStep) {
        if tag >= self.configured || was == is {
            return;
        }
        if is {
            self.unknown -= 1;
            step.unknown_delta -= 1;
        } else {
            self.unknown += 1;
            step.unknown_delta += 1;
        }
    }

    /// Makes tag `tag` unknown, whatever its type; true if the machine
    /// state may have changed.
    pub(super) fn set_unknown(
        &mut self,
        tag: usize,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut EngineStep,
    ) -> bool {
        if self.others[tag].is_some() {
            self.set_other(tag, None, now, findings, step)
        } else {
            self.set_value(tag, None, now, findings, step)
        }
    }

    /// Sets boolean tag `tag`'s value; true if the machine state may have
    /// changed.
    pub(super) fn set_value(
        &mut self,
        tag: usize,
        value: Option<bool>,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut EngineStep,
    ) -> bool {
        if value.is_some() && self.others[tag].is_some() {
            // A number or string tag now sends booleans: forget the
            // other value first.
            self.set_other(tag, None, now, findings, step);
        }
        let before = self.values[tag];
        if before == value {
            return false;
        }
        self.known_changed(tag, before.is_some(), value.is_some(), step);
        if self.parts == PartCounting::Edge(tag) && before == Some(false) && value == Some(true) {
            step.parts.push((now, 1));
        }
        if self.rejects == PartCounting::Edge(tag) && before == Some(false) && value == Some(true) {
            step.rejects.push((now, 1));
        }
        self.remember(tag);
        self.values[tag] = value;
        let ring_at = self.ring_time(now);
        if let Some(recorder) = &mut self.recorder {
            recorder.change_bool(tag, ring_at, before, value);
        }
        step.evaluations += 1;
        if self.exported.get(tag) == Some(&true) {
            step.exported
                .push((tag, value.map(|b| f64::from(u8::from(b)))));
        }
        let address = &self.tags[tag].address;
        for &k in self.readers.of(tag) {
            let set = &mut self.sets[k as usize];
            if self.untimed {
                set.on_change_out_of_order(address, value, before, now, findings);
            } else {
                set.on_change(address, value, before, now, findings);
            }
        }
        self.running_reads[tag]
    }

    /// Sets number or string tag `tag`'s value; true if the machine state
    /// may have changed.
    pub(super) fn set_other(
        &mut self,
        tag: usize,
        value: Option<Value>,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut EngineStep,
    ) -> bool {
        if self.values[tag].is_some() {
            // A boolean tag now sends numbers (or the reverse): forget
            // the boolean first.
            self.set_value(tag, None, now, findings, step);
        }
        if self.others[tag] == value {
            return false;
        }
        self.remember(tag);
        let before = std::mem::replace(&mut self.others[tag], value);
        let ring_at = self.ring_time(now);
        if let Some(recorder) = &mut self.recorder {
            recorder.change(tag, ring_at, &before, &self.others[tag]);
        }
        self.known_changed(tag, before.is_some(), self.others[tag].is_some(), step);
        step.evaluations += 1;
        let number = |v: &Option<Value>| match v {
            Some(Value::Num(n)) => Some(*n),
            _ => None,
        };
        let (was, is) = (number(&before), number(&self.others[tag]));
        if self.exported.get(tag) == Some(&true) {
            step.exported.push((tag, is.map(Num::as_f64)));
        }
        for (counting, counted) in [
            (&mut self.parts, &mut step.parts),
            (&mut self.rejects, &mut step.rejects),
        ] {
            if let PartCounting::Counters(counters) = counting {
                for (_, counter) in counters.iter_mut().filter(|(t, _)| *t == tag) {
                    if let Some(n) = is.and_then(Num::as_count) {
                        let made = counter.next(n);
                        if made > 0 {
                            counted.push((now, made));
                        }
                    }
                }
            }
        }
        if Some(tag) == self.order_tags.0 || Some(tag) == self.order_tags.1 {
            self.order_changed(step);
        }
        if was != is {
            let address = &self.tags[tag].address;
            for &k in self.number_readers.of(tag) {
                self.sets[k as usize].on_number(address, is, now, findings);
            }
        }
        let mut state = self.running_reads[tag];
        for i in 0..self.compared_in.of(tag).len() {
            let d = &self.derived[self.compared_in.of(tag)[i] as usize];
            let value = self.compare(d);
            let t = d.tag;
            state |= self.set_value(t, value, now, findings, step);
        }
        state
    }

    /// Recomputes the work order from its tags; a change goes to `step`.
    /// An unknown value (unit out of reach) keeps the last known one.
    fn order_changed(&mut self, step: &mut EngineStep) {
        let (item, target) = self.order_tags;
        let mut order = self.order.clone();
        match item.and_then(|t| self.others[t].as_ref()) {
            Some(Value::Text(s)) => order.item = Some(s.trim().to_string()),
            Some(v) => order.item = Some(v.to_string()),
            None => {}
        }
        if let Some(Value::Num(n)) = target.and_then(|t| self.others[t].as_ref()) {
            order.target = n.as_count();
        }
        if order != self.order {
            self.order = order.clone();
            step.order = Some(order);
        }
    }

    /// Tag `t`'s value as a number (a contact as 0 or 1); `None` while
    /// unknown or text.
    pub(super) fn number(&self, t: usize) -> Option<Num> {
        match (&self.others[t], self.values[t]) {
            (Some(Value::Num(n)), _) => Some(*n),
            (_, Some(b)) => Some(Num::UInt(u64::from(b))),
            _ => None,
        }
    }

    /// A comparison's value now: unknown while an operand is.
    fn compare(&self, d: &Derived) -> Option<bool> {
        let lhs = self.number(d.lhs)?;
        let rhs = match d.rhs {
            Rhs::Const(n) => n,
            Rhs::Tag(t) => self.number(t)?,
        };
        Some(d.op.holds(lhs, rhs))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::{Severity, Transition};
    use crate::comments::CommentDb;
    use crate::engine::{
        EngineEvent, Reading, StateRules, SwitchingCheck, SwitchingChecks, Tag, TagReading,
    };
    use crate::explain::Polarity;
    use crate::expr::Expr;
    use crate::program::Program;
    use crate::signal::{Observability, Signal};
    use crate::switching::SwitchingFunction;

    fn engine(n: usize) -> CellEngine {
        let tags = (0..n)
            .map(|i| Tag {
                name: format!("t{i}"),
                address: Signal::new(&format!("X{i}.00")),
            })
            .collect();
        CellEngine::new("c", tags, Vec::new(), StateRules::default())
            .unwrap()
            .counting_parts(Some(1))
    }

    #[test]
    fn unknown_count_is_kept_incrementally_and_matches_a_scan() {
        let mut e = engine(5);
        let mut unknown = 5i64;
        assert_eq!(e.unknown_tags(), 5);
        unknown += e.on_connection(true, 0).unknown_delta;
        let script = [
            (0, Reading::Good(true)),
            (1, Reading::Good(false)),
            (0, Reading::Bad),
            (2, Reading::Good(true)),
            (0, Reading::Good(false)),
            (4, Reading::Bad),
            (2, Reading::Bad),
        ];
        for (k, (tag, r)) in script.into_iter().enumerate() {
            unknown += e
                .on_reading(tag, r, k as u64 + 1, k as u64 + 1)
                .unknown_delta;
            let scanned = e.values().iter().filter(|v| v.is_none()).count();
            assert_eq!(e.unknown_tags(), scanned);
            assert_eq!(unknown, scanned as i64);
        }
        unknown += e.on_connection(false, 100).unknown_delta;
        assert_eq!(unknown, 5);
        assert_eq!(e.unknown_tags(), 5);
    }

    #[test]
    fn rising_edges_of_the_part_done_tag_are_parts() {
        let mut e = engine(2);
        e.on_connection(true, 0);
        // The first value is no edge: the part may have been counted before.
        assert!(e.on_reading(1, Reading::Good(true), 1, 1).parts.is_empty());
        assert!(e.on_reading(1, Reading::Good(false), 2, 2).parts.is_empty());
        assert_eq!(e.on_reading(1, Reading::Good(true), 3, 3).parts, [(3, 1)]);
        // Unknown, then true again: not a counted edge.
        e.on_reading(1, Reading::Bad, 4, 4);
        assert!(e.on_reading(1, Reading::Good(true), 5, 5).parts.is_empty());
        let batch = [
            TagReading {
                tag: 1,
                reading: Reading::Good(false),
                source_time: 6,
            },
            TagReading {
                tag: 1,
                reading: Reading::Good(true),
                source_time: 7,
            },
            TagReading {
                tag: 0,
                reading: Reading::Good(true),
                source_time: 7,
            },
            TagReading {
                tag: 1,
                reading: Reading::Good(true),
                source_time: 7,
            },
        ];
        let step = e.on_readings(&batch, 8);
        assert_eq!(step.parts, [(7, 1)]);
        assert_eq!(step.readings, 4);
        assert_eq!(step.duplicates, 1);
    }

    #[test]
    fn a_reject_signal_or_counter_counts_rejects_apart_from_parts() {
        let mut e = engine(3).counting_rejects(PartCounting::Edge(2));
        e.on_connection(true, 0);
        e.on_reading(2, Reading::Good(false), 1, 1);
        let step = e.on_reading(2, Reading::Good(true), 2, 2);
        assert_eq!(
            (step.rejects.as_slice(), step.parts.is_empty()),
            (&[(2, 1)][..], true)
        );
        let counter = crate::value::Counter::new(u64::from(u16::MAX));
        let mut e = engine(3).counting_rejects(PartCounting::Counters(vec![(2, counter)]));
        e.on_connection(true, 0);
        e.on_reading(2, Reading::Number(Num::Int(10)), 1, 1);
        let step = e.on_reading(2, Reading::Number(Num::Int(13)), 2, 2);
        assert_eq!(step.rejects, [(2, 3)]);
        assert!(step.parts.is_empty());
    }

    #[test]
    fn csd_faults_only_while_cycle_start_is_pressed() {
        let p =
            Program::compile("csd.il", include_str!("../../../config/cnc/csd.il"), None).unwrap();
        let sf = SwitchingFunction::expand(
            &p,
            &Signal::new("G9.00"),
            &Observability::default_for(p.dialect()),
        )
        .unwrap();
        let tags: Vec<Tag> = sf
            .leaves()
            .into_iter()
            .map(|s| Tag {
                name: s.name().into(),
                address: s,
            })
            .collect();
        let check = SwitchingCheck {
            forces: Vec::new(),
            text: None,
            id: "csd".into(),
            sf,
            polarity: Polarity::On,
            severity: Severity::High,
            fault_type: "CSD".into(),
            comments: CommentDb::default(),
            armed_when: Some(SwitchingFunction::from_expr(
                Signal::new("armed"),
                &Expr::parse("X200.01").unwrap(),
            )),
        };
        let mut e = CellEngine::new(
            "m",
            tags,
            vec![Box::new(SwitchingChecks::new(vec![check]))],
            StateRules::default(),
        )
        .unwrap();
        e.on_connection(true, 0);
        let mut raised = Vec::new();
        for line in include_str!("../../../config/cnc/csd-normal.values")
            .lines()
            .filter(|l| l.contains(',') && !l.starts_with("address") && !l.starts_with('#'))
        {
            let (a, v) = line.split_once(',').unwrap();
            let t = e.tag_index(&Signal::new(a)).unwrap();
            raised.extend(e.on_reading(t, Reading::Good(v == "1"), 1, 1).events);
        }
        // Cycle start released: the paper's SF is true (-X200.01) but nothing is wrong.
        assert!(
            !raised
                .iter()
                .any(|ev| matches!(ev, EngineEvent::Alarm { .. })),
            "{raised:?}"
        );
        let set = |e: &mut CellEngine, a: &str, v: bool, t: u64| {
            let i = e.tag_index(&Signal::new(a)).unwrap();
            e.on_reading(i, Reading::Good(v), t, t).events
        };
        set(&mut e, "X201.02", false, 2);
        set(&mut e, "X201.06", true, 3);
        let ev = set(&mut e, "X200.01", true, 4);
        let EngineEvent::Alarm {
            alarm,
            transition: Transition::Raised,
            ..
        } = &ev[0]
        else {
            panic!("{ev:?}")
        };
        assert_eq!(alarm.fault_step, Some(3));
        assert_eq!(alarm.culprits[0].address.name(), "X200.01");
        let ev = set(&mut e, "X200.01", false, 5);
        assert!(
            matches!(
                &ev[0],
                EngineEvent::Alarm {
                    transition: Transition::Cleared,
                    ..
                }
            ),
            "{ev:?}"
        );
    }
}
