//! Transition timers as engine checks.
//!
//! [`TimerChecks`] runs a [`TimerMonitor`] inside the engine: every early
//! or late event raises a latched alarm `<id>-<nnn>` (`nnn` the
//! transition's number, the paper's `ERROR_ALARM_nnn`) naming the
//! transition and blaming its event's signal; it stays active until an
//! operator resets it (`ERROR_RESET_nnn`). A signal the model reads but the
//! cell maps to no tag is refused when the check is built.

use std::collections::HashMap;

use super::learn::{Edge, TimerModel};
use super::monitor::{ModelError, Outcome, TimerMonitor};
use crate::alarm::{AlarmKind, Severity};
use crate::comments::CommentDb;
use crate::engine::{CheckSet, Declared, Finding, Observation};
use crate::explain::Culprit;
use crate::signal::Signal;

/// Why a timer model cannot run on a cell.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TimerCheckError {
    /// The model itself is invalid.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The model reads a signal the cell has no tag for.
    #[error("the timer model reads '{0}', which is no tag of this cell")]
    UnknownSignal(String),
}

/// A timer model bound to a cell's signals.
pub struct TimerChecks {
    id: String,
    severity: Severity,
    monitor: TimerMonitor,
    /// Model signal index → cell signal, and back.
    signals: Vec<Signal>,
    by_signal: HashMap<Signal, usize>,
    /// Per transition id: description, event signal and expected value.
    transitions: HashMap<u32, (String, usize, bool, [u64; 2])>,
    /// Durations observed since the last `take_observations`.
    observed: Vec<Observation>,
    /// The signals' comments (I/O list), for culprits and messages.
    comments: CommentDb,
}

impl TimerChecks {
    /// Binds `model` to the cell: `signal_of` maps a model signal name to
    /// the cell's signal (a tag's address).
    ///
    /// # Errors
    /// The model is invalid or names a signal the cell does not have.
    pub fn new(
        id: &str,
        model: &TimerModel,
        severity: Severity,
        signal_of: impl Fn(&str) -> Option<Signal>,
    ) -> Result<TimerChecks, TimerCheckError> {
        let monitor = TimerMonitor::new(model)?;
        let mut signals = Vec::new();
        for name in &model.signals {
            signals
                .push(signal_of(name).ok_or_else(|| TimerCheckError::UnknownSignal(name.clone()))?);
        }
        let by_signal = signals
            .iter()
            .enumerate()
            .map(|(i, s)| (s.clone(), i))
            .collect();
        let transitions = model
            .transitions
            .iter()
            .map(|t| {
                let what = label(t);
                let s = model
                    .signals
                    .iter()
                    .position(|n| *n == t.event.tag)
                    .unwrap_or(0);
                (t.id, (what, s, t.event.edge == Edge::Rise, t.window_ms))
            })
            .collect();
        Ok(TimerChecks {
            id: id.into(),
            severity,
            monitor,
            signals,
            by_signal,
            transitions,
            observed: Vec::new(),
            comments: CommentDb::default(),
        })
    }

    /// The signals' comments (the tags' I/O-list comments): each alarm's
    /// culprit carries its signal's, and its message ends with it.
    #[must_use]
    pub fn commented(mut self, comments: CommentDb) -> Self {
        self.comments = comments;
        self
    }

    fn findings(&mut self, outcomes: Vec<Outcome>, out: &mut Vec<Finding>) {
        for o in outcomes {
            let (id, late, observed) = match o {
                Outcome::Early {
                    transition,
                    observed_ms,
                    ..
                } => (transition, false, Some(observed_ms)),
                Outcome::Late { transition, .. } => (transition, true, None),
                Outcome::Normal {
                    transition,
                    observed_ms,
                    ..
                } => {
                    self.observed.push(Observation {
                        check: format!("{}-{transition:03}", self.id),
                        ms: observed_ms,
                    });
                    continue;
                }
            };
            if let Some(ms) = observed {
                self.observed.push(Observation {
                    check: format!("{}-{id:03}", self.id),
                    ms,
                });
            }
            let Some((what, s, expected, window)) = self.transitions.get(&id) else {
                continue;
            };
            let message = match observed {
                Some(ms) => format!(
                    "transition #{id:03} ({what}) too early: after {ms} ms, window [{}, {}] ms",
                    window[0], window[1]
                ),
                None => format!(
                    "transition #{id:03} ({what}) too late: nothing by {} ms",
                    window[1]
                ),
            };
            let comment = self.comments.get(&self.signals[*s]).map(str::to_string);
            let message = match &comment {
                Some(c) => format!("{message}: {c}"),
                None => message,
            };
            let culprit = Culprit {
                address: self.signals[*s].clone(),
                value: if late { !*expected } else { *expected },
                expected: if late { *expected } else { !*expected },
                comment,
                trigger: !late,
                compared: None,
            };
            let alarm = format!("{}-{id:03}", self.id);
            let base = Finding {
                at: None,
                id: alarm,
                kind: AlarmKind::Timer,
                severity: self.severity,
                fault_type: "TIMER".into(),
                latched: true,
                active: true,
                fault_step: None,
                culprits: vec![culprit],
                message,
            };
            // The event is momentary: the alarm latches, and its condition
            // is over at once, so that an operator may reset it.
            let mut over = base.clone();
            over.active = false;
            out.push(base);
            out.push(over);
        }
    }
}

/// What a transition measures, for people: `+DONE after +START` (timed
/// from a trigger), or `-F17.01 in -F17.00:F17.01` (timed from entering its
/// state).
pub fn label(t: &super::learn::Transition) -> String {
    let edge = |e: Edge| if e == Edge::Rise { "+" } else { "-" };
    match &t.trigger {
        Some(tr) => format!(
            "{}{} after {}{}",
            edge(t.event.edge),
            t.event.tag,
            edge(tr.edge),
            tr.tag
        ),
        None => format!(
            "{}{} in {}",
            edge(t.event.edge),
            t.event.tag,
            t.from.join(":")
        ),
    }
}

impl CheckSet for TimerChecks {
    fn inputs(&self) -> Vec<Signal> {
        self.signals.clone()
    }

    fn alarms(&self) -> Vec<Declared> {
        let mut ids: Vec<u32> = self.transitions.keys().copied().collect();
        ids.sort_unstable();
        ids.into_iter()
            .map(|t| Declared {
                id: format!("{}-{t:03}", self.id),
                kind: AlarmKind::Timer,
                severity: self.severity,
                fault_type: "TIMER".into(),
                latched: true,
            })
            .collect()
    }

    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        _before: Option<bool>,
        now: u64,
        out: &mut Vec<Finding>,
    ) {
        let Some(&s) = self.by_signal.get(signal) else {
            return;
        };
        let outcomes = self.monitor.set(s, value, now);
        self.findings(outcomes, out);
    }

    fn on_change_out_of_order(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        _before: Option<bool>,
        now: u64,
        out: &mut Vec<Finding>,
    ) {
        let Some(&s) = self.by_signal.get(signal) else {
            return;
        };
        let outcomes = self.monitor.set_untimed(s, value, now);
        self.findings(outcomes, out);
    }

    fn advance(&mut self, now: u64, out: &mut Vec<Finding>) {
        let outcomes = self.monitor.advance(now);
        self.findings(outcomes, out);
    }

    fn next_deadline(&self) -> Option<u64> {
        self.monitor.next_deadline()
    }

    fn take_observations(&mut self, out: &mut Vec<Observation>) {
        out.append(&mut self.observed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::Transition as AlarmTransition;
    use crate::engine::{CellEngine, EngineEvent, Reading, StateRules, Tag};
    use crate::timer::learn::{Event, Transition, MODEL_VERSION};

    fn model() -> TimerModel {
        TimerModel {
            version: MODEL_VERSION,
            method: "common".into(),
            signals: vec!["move".into(), "arrived".into()],
            transitions: vec![Transition {
                id: 7,
                from: vec![],
                event: Event {
                    tag: "arrived".into(),
                    edge: Edge::Rise,
                },
                to: vec![],
                delta_ms: 6000,
                min_ms: 5950,
                max_ms: 6050,
                support: 4,
                window_ms: [5700, 6300],
                from_numbered: None,
                trigger: Some(Event {
                    tag: "move".into(),
                    edge: Edge::Rise,
                }),
            }],
        }
    }

    #[test]
    fn late_event_latches_until_reset() {
        let tags = vec![
            Tag {
                name: "move".into(),
                address: Signal::new("Y1.00"),
            },
            Tag {
                name: "arrived".into(),
                address: Signal::new("X1.00"),
            },
        ];
        let checks = TimerChecks::new("line", &model(), Severity::High, |n| {
            tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
        })
        .unwrap();
        let mut e = CellEngine::new(
            "c",
            tags.clone(),
            vec![Box::new(checks)],
            StateRules::default(),
        )
        .unwrap();
        e.on_connection(true, 0);
        e.on_reading(0, Reading::Good(false), 0, 0);
        e.on_reading(1, Reading::Good(false), 0, 0);
        assert_eq!(e.next_deadline(), None);
        e.on_reading(0, Reading::Good(true), 1000, 1000);
        // The agent wakes exactly when the window closes.
        assert_eq!(e.next_deadline(), Some(7300));
        assert!(e
            .advance(7299)
            .events
            .iter()
            .all(|ev| !matches!(ev, EngineEvent::Alarm { .. })));
        let ev = e.advance(7300).events;
        let EngineEvent::Alarm {
            alarm,
            transition: AlarmTransition::Raised,
            ..
        } = &ev[0]
        else {
            panic!("{ev:?}")
        };
        assert_eq!(alarm.id, "line-007");
        assert_eq!(
            alarm.message,
            "transition #007 (+arrived after +move) too late: nothing by 6300 ms"
        );
        assert_eq!(alarm.culprits[0].to_string(), "X1.00 = 0 (expected 1)");
        assert!(alarm.active && alarm.latched);
        assert_eq!(e.next_deadline(), None);
        // A normal cycle is measured.
        e.on_reading(0, Reading::Good(false), 7400, 7400);
        e.on_reading(0, Reading::Good(true), 7500, 7500);
        // The sensor arrives late: still latched.
        let observed = e.on_reading(1, Reading::Good(true), 8000, 8000);
        assert!(e.alarms().any(|a| a.id == "line-007" && a.active));
        // Re-armed at 7500, the sensor at 8000 is early (500 ms): measured too.
        assert_eq!(
            observed.observations,
            [crate::engine::Observation {
                check: "line-007".into(),
                ms: 500
            }]
        );
        let ev = e.reset("line-007", "kim", 9000).unwrap().events;
        assert!(matches!(
            &ev[0],
            EngineEvent::Alarm {
                transition: AlarmTransition::Cleared,
                ..
            }
        ));
    }

    #[test]
    fn an_event_out_of_time_order_is_counted_and_raises_nothing() {
        let tags = vec![
            Tag {
                name: "move".into(),
                address: Signal::new("Y1.00"),
            },
            Tag {
                name: "arrived".into(),
                address: Signal::new("X1.00"),
            },
        ];
        let checks = TimerChecks::new("line", &model(), Severity::High, |n| {
            tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
        })
        .unwrap();
        let mut e =
            CellEngine::new("c", tags, vec![Box::new(checks)], StateRules::default()).unwrap();
        e.on_connection(true, 0);
        e.on_reading(0, Reading::Good(false), 0, 0);
        e.on_reading(1, Reading::Good(false), 0, 0);
        e.on_reading(0, Reading::Good(true), 10_000, 10_000);
        // The sensor stamped 2 s before the motion started: no "early", no
        // panic, counted.
        let step = e.on_reading(1, Reading::Good(true), 8_000, 10_010);
        assert_eq!(step.out_of_order, 1);
        assert!(step.events.is_empty(), "{:?}", step.events);
        assert!(step.observations.is_empty());
        // Nothing armed is left to fall late.
        assert_eq!(e.next_deadline(), None);
        assert!(e.advance(20_000).events.is_empty());
        // The next cycle in order is measured again.
        e.on_reading(0, Reading::Good(false), 20_000, 20_000);
        e.on_reading(1, Reading::Good(false), 20_000, 20_000);
        e.on_reading(0, Reading::Good(true), 21_000, 21_000);
        let step = e.on_reading(1, Reading::Good(true), 27_000, 27_000);
        assert_eq!(step.out_of_order, 0);
        assert_eq!(
            step.observations,
            [crate::engine::Observation {
                check: "line-007".into(),
                ms: 6000
            }]
        );
    }

    #[test]
    fn unknown_model_signal_is_refused() {
        let err = TimerChecks::new("line", &model(), Severity::High, |_| None)
            .err()
            .unwrap();
        assert_eq!(
            err.to_string(),
            "the timer model reads 'move', which is no tag of this cell"
        );
    }
}
