//! The first values after a connection: a fault is judged on whole data.
//!
//! A new subscription's first values come over one or more publishes; a
//! fault present when the agent starts (or reconnects) may be certain from
//! the first of them alone (`X0.06 = 0` makes ESE's fault whatever the
//! other contacts are), and judged then, its message would name every
//! contact still to come as unknown. So from the connection (or the first
//! value, when a source delivers one before it says so) until every
//! configured tag has been heard (a value or a bad status), or
//! [`FIRST_VALUES_MS`] at the latest, a fault found by a check that reads
//! a tag not heard yet is held: values are taken and the checks follow
//! them as always, and a fault that clears meanwhile is never raised. When
//! the wait ends, each fault still held is said again by its check with
//! the values then and raised at the time it was first seen; what is
//! still unknown after the wait is named as before. A fault whose check
//! has heard all it reads (a limit on its number, a discrete alarm on its
//! contact) is raised at once.

use super::{uncertain_trigger, CellEngine, EngineStep, Finding, Held, Settling};

/// How long after a connection the first values are waited for before a
/// fault found meanwhile is raised with what is still unknown named, ms.
pub(super) const FIRST_VALUES_MS: u64 = 5_000;

impl CellEngine {
    /// The first sign of a new link (the connection up, or a value, which
    /// a source may deliver before it says the connection is up): with
    /// tags not heard, the wait begins. Once per link: the engine is
    /// built, or the connection lost, awaiting it.
    pub(super) fn begin_settling(&mut self, now: u64) {
        if !std::mem::take(&mut self.awaiting_first) {
            return;
        }
        self.settling = (self.unheard > 0).then(|| {
            Box::new(Settling {
                until: now.saturating_add(FIRST_VALUES_MS),
                held: Vec::new(),
            })
        });
    }

    /// Tag `tag` heard (a value or a bad status) since the connection.
    pub(super) fn heard(&mut self, tag: usize) {
        if self.timestamps[tag].is_none() {
            self.unheard = self.unheard.saturating_sub(1);
        }
    }

    /// When the wait for the first values ends, if a fault waits on it.
    pub(super) fn settling_deadline(&self) -> Option<u64> {
        self.settling
            .as_ref()
            .filter(|s| !s.held.is_empty())
            .map(|s| s.until)
    }

    /// Whether alarm `id`'s check reads a tag not heard since the
    /// connection.
    fn reads_unheard(&self, id: &str) -> bool {
        let mut reads = Vec::new();
        for set in &self.sets {
            set.reads(id, &mut reads);
        }
        reads.iter().any(|s| {
            self.tag_index(s)
                .is_some_and(|t| t < self.configured && self.timestamps[t].is_none())
        })
    }

    /// A check's finding at source time `at`: held while the first values
    /// come (a fault not yet raised, or the clear of one held), applied
    /// otherwise.
    pub(super) fn judge_at(&mut self, f: Finding, at: u64, now: u64, step: &mut EngineStep) {
        let Some(settling) = self.settling.as_ref() else {
            return self.apply_at(f, at, now, step);
        };
        let held = settling.held.iter().position(|h| h.finding.id == f.id);
        let hold =
            held.is_none() && f.active && !self.is_active(&f.id) && self.reads_unheard(&f.id);
        // Judged across lost changes: said so when raised, though each tag
        // will have been heard by then.
        let uncertain = match hold && (self.lost.is_some() || self.lost_now.is_some()) {
            true => self.uncertain(&f),
            false => None,
        };
        let Some(settling) = self.settling.as_mut() else {
            return;
        };
        match (held, f.active) {
            // Still a fault: first seen when it was.
            (Some(_), true) => {}
            // Cleared before it was said: never raised.
            (Some(i), false) => {
                settling.held.remove(i);
            }
            (None, true) if hold => settling.held.push(Held {
                finding: f,
                at,
                seen: now,
                uncertain,
            }),
            (None, _) => self.apply_at(f, at, now, step),
        }
    }

    /// Ends the wait when every tag is heard or its time is up: each fault
    /// still held is said again with the values now and raised, at the
    /// time it was first seen. The caller brings the machine state up to
    /// date.
    pub(super) fn settle(&mut self, now: u64, step: &mut EngineStep) {
        let done = self
            .settling
            .as_ref()
            .is_some_and(|s| self.unheard == 0 || now >= s.until);
        if !done {
            return;
        }
        let Some(settling) = self.settling.take() else {
            return;
        };
        let mut held = settling.held;
        if held.len() > 1 && !self.relation.is_empty() {
            // Causes first, as within one change.
            let ids: Vec<String> = held.iter().map(|h| h.finding.id.clone()).collect();
            held.sort_by_key(|h| {
                self.relation
                    .causes_of(&h.finding.id)
                    .iter()
                    .filter(|(c, _)| ids.contains(c))
                    .count()
            });
        }
        for h in held {
            let mut f = h.finding;
            for set in &self.sets {
                set.restate(&mut f);
            }
            if let Some(why) = &h.uncertain {
                uncertain_trigger(&mut f, why);
            }
            self.apply_at(f, h.at, h.seen, step);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::Transition;
    use crate::engine::fixture::*;
    use crate::engine::{EngineEvent, Reading};
    use crate::signal::Signal;

    const NORMAL: &str = include_str!("../../../config/cnc/ese-normal.values");

    /// Paper 000's engraving machine in its normal state but for `open`,
    /// as (tag, value) in the order of the values file.
    fn values_with(e: &CellEngine, open: &str) -> Vec<(usize, bool)> {
        NORMAL
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
            .map(|line| {
                let (a, v) = line.split_once(',').unwrap();
                let t = e.tag_index(&Signal::new(a)).unwrap();
                (t, v == "1" && a != open)
            })
            .collect()
    }

    fn raises(events: &[EngineEvent]) -> Vec<(String, u64)> {
        events
            .iter()
            .filter_map(|e| match e {
                EngineEvent::Alarm {
                    alarm,
                    transition: Transition::Raised,
                    at,
                } => Some((alarm.message.clone(), *at)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_fault_present_at_start_is_raised_once_every_tag_is_heard_naming_none_unknown() {
        let mut e = engine();
        e.on_connection(true, 1_000);
        let values = values_with(&e, "X0.06");
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // The over-travel switch comes first: its fault is certain now,
        // but nothing is said while other tags are still to come.
        let first = e.on_reading(x006, Reading::Good(false), 900, 1_010);
        assert!(raises(&first.events).is_empty(), "{:?}", first.events);
        let mut events = Vec::new();
        let rest: Vec<_> = values.iter().filter(|(t, _)| *t != x006).collect();
        let (last, before) = rest.split_last().unwrap();
        for &&(t, v) in before {
            events.extend(e.on_reading(t, Reading::Good(v), 950, 1_020).events);
        }
        assert!(raises(&events).is_empty(), "{events:?}");
        // The last tag heard: raised, at the time it was first seen (by
        // the agent's clock: the PLC's is not trusted here), with its step
        // and culprit and no contact unknown.
        let s = e.on_reading(last.0, Reading::Good(last.1), 960, 1_030);
        let r = raises(&s.events);
        assert_eq!(r.len(), 1, "{:?}", s.events);
        assert_eq!(r[0].1, 1_010);
        assert!(r[0].0.starts_with("ESE at step 6: X0.06 = 0"), "{}", r[0].0);
        assert!(!r[0].0.contains("unknown"), "{}", r[0].0);
        assert_eq!(e.next_deadline(), None);
    }

    #[test]
    fn values_delivered_before_the_connection_is_said_are_waited_for_the_same() {
        // A source may hand over a new subscription's first values before
        // it says the connection is up.
        let mut e = engine();
        let values = values_with(&e, "X0.06");
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let s = e.on_reading(x006, Reading::Good(false), 900, 1_000);
        assert!(raises(&s.events).is_empty(), "{:?}", s.events);
        e.on_connection(true, 1_001);
        let mut events = Vec::new();
        for &(t, v) in values.iter().filter(|(t, _)| *t != x006) {
            events.extend(e.on_reading(t, Reading::Good(v), 950, 1_010).events);
        }
        let r = raises(&events);
        assert_eq!(r.len(), 1, "{events:?}");
        assert!(!r[0].0.contains("unknown"), "{}", r[0].0);
        // Raised at the time it was first seen, before the connection was
        // said.
        assert_eq!(r[0].1, 1_000);
    }

    #[test]
    fn a_fault_held_across_lost_changes_says_its_trigger_is_uncertain_when_raised() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        e.on_connection(false, 10);
        e.on_connection(true, 20);
        // The server dropped the subscription while the link was down.
        e.on_gap(None, 0, "subscription 1 dropped");
        let values = values_with(&e, "X0.06");
        let mut events = Vec::new();
        for &(t, v) in &values {
            events.extend(e.on_reading(t, Reading::Good(v), 30, 30).events);
        }
        let r = raises(&events);
        assert_eq!(r.len(), 1, "{events:?}");
        assert!(
            r[0].0
                .ends_with("(trigger uncertain: subscription 1 dropped)"),
            "{}",
            r[0].0
        );
        assert_eq!(r[0].0.matches("trigger uncertain").count(), 1, "{}", r[0].0);
    }

    #[test]
    fn a_tag_never_heard_is_named_unknown_when_the_wait_is_up() {
        let mut e = engine();
        e.on_connection(true, 1_000);
        let values = values_with(&e, "X0.06");
        let missing = e.tag_index(&Signal::new("G0.00")).unwrap();
        for &(t, v) in values.iter().filter(|(t, _)| *t != missing) {
            let s = e.on_reading(t, Reading::Good(v), 950, 1_010);
            assert!(raises(&s.events).is_empty(), "{:?}", s.events);
        }
        assert_eq!(e.next_deadline(), Some(1_000 + FIRST_VALUES_MS));
        assert!(raises(&e.advance(1_000 + FIRST_VALUES_MS - 1).events).is_empty());
        let s = e.advance(1_000 + FIRST_VALUES_MS);
        let r = raises(&s.events);
        assert_eq!(r.len(), 1, "{:?}", s.events);
        assert!(r[0].0.ends_with("(unknown: G0.00)"), "{}", r[0].0);
        assert_eq!(r[0].1, 1_010);
    }

    #[test]
    fn a_fault_gone_before_every_tag_is_heard_is_never_raised() {
        let mut e = engine();
        e.on_connection(true, 1_000);
        let values = values_with(&e, "");
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 900, 1_010);
        e.on_reading(x006, Reading::Good(true), 910, 1_011);
        let mut events = Vec::new();
        for &(t, v) in &values {
            events.extend(e.on_reading(t, Reading::Good(v), 950, 1_020).events);
        }
        assert!(alarm_transitions(&events).is_empty(), "{events:?}");
        // Settled: the next fault is raised at once.
        let s = e.on_reading(x006, Reading::Good(false), 970, 1_040);
        assert_eq!(raises(&s.events).len(), 1, "{:?}", s.events);
    }

    #[test]
    fn after_a_connection_lost_and_back_the_first_values_are_waited_for_again() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        e.on_connection(false, 10);
        e.on_connection(true, 20);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let s = e.on_reading(x006, Reading::Good(false), 30, 30);
        assert!(raises(&s.events).is_empty(), "{:?}", s.events);
        let s = e.advance(20 + FIRST_VALUES_MS);
        assert_eq!(raises(&s.events).len(), 1, "{:?}", s.events);
    }
}
