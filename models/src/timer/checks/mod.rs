//! Transition timers as engine checks.
//!
//! [`TimerChecks`] runs a [`TimerMonitor`] inside the engine: every early
//! or late event raises a latched alarm `<id>-<nnn>` (`nnn` the
//! transition's number, the paper's `ERROR_ALARM_nnn`) naming the
//! transition and blaming its event's signal; it stays active until an
//! operator resets it (`ERROR_RESET_nnn`). A signal the model reads but the
//! cell maps to no tag is refused when the check is built.
//!
//! With drift tracking on ([`TimerChecks::drifting`]), each transition's
//! durations inside its window also feed a [`DriftTracker`]: a low-priority
//! warning `<id>-<nnn>-drift`, not latched, says when they drift towards a
//! limit or scatter, and clears by itself when they are back; their place
//! in the window is [`CheckSet::window_positions`].
//!
//! A transition's alarm raised while a cause is active is that cause's
//! consequence when its event would have come without the cause's fault
//! ([`super::awaits`]: the event's signal, or the request that starts its
//! timer, held by the fault).

use std::collections::{BTreeMap, HashMap};

use super::awaits::Awaited;
use super::drift::{DriftRules, DriftTracker};
use super::learn::{SignalEdge, TimerModel};
use super::monitor::{ModelError, Outcome, TimerMonitor};
use crate::alarm::{Alarm, AlarmKind, Severity};
use crate::comments::CommentDb;
use crate::engine::{CheckSet, Declared, Finding, Observation, WindowPosition};
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
    /// Per transition id: the signals it reads (its start condition's,
    /// its trigger's and its event's), for the flight recorder.
    reads: HashMap<u32, Vec<usize>>,
    /// Durations observed since the last `take_observations`.
    observed: Vec<Observation>,
    /// The signals' comments (I/O list), for culprits and messages.
    comments: CommentDb,
    /// When drift is warned; `None`: not tracked.
    drift: Option<DriftRules>,
    /// Per transition id: its recent durations.
    trackers: BTreeMap<u32, DriftTracker>,
    /// Per transition id: what its alarm waits for.
    awaits: HashMap<u32, Awaited>,
    /// Per transition id: whether its last alarm was late (else early).
    late: HashMap<u32, bool>,
}

/// The id of transition `nnn`'s drift warning in timer check `check`:
/// `line-020-drift`.
pub fn drift_alarm(check: &str, transition: u32) -> String {
    format!("{check}-{transition:03}-drift")
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
                (
                    t.id,
                    (what, s, t.event.edge == SignalEdge::Rise, t.window_ms),
                )
            })
            .collect();
        let index = |name: &str| model.signals.iter().position(|n| n == name);
        let reads = model
            .transitions
            .iter()
            .map(|t| {
                let from = t.from.iter().map(|l| l.strip_prefix('-').unwrap_or(l));
                let trigger = t.trigger.iter().map(|e| e.tag.as_str());
                let mut read: Vec<usize> = Vec::new();
                for s in from
                    .chain(trigger)
                    .chain(std::iter::once(t.event.tag.as_str()))
                    .filter_map(index)
                {
                    if !read.contains(&s) {
                        read.push(s);
                    }
                }
                (t.id, read)
            })
            .collect();
        let signal = |name: &str| index(name).map(|s| signals[s].clone());
        let awaits = model
            .transitions
            .iter()
            .filter_map(|t| Some((t.id, Awaited::of(t, signal)?)))
            .collect();
        Ok(TimerChecks {
            awaits,
            late: HashMap::new(),
            id: id.into(),
            severity,
            monitor,
            signals,
            by_signal,
            transitions,
            reads,
            observed: Vec::new(),
            comments: CommentDb::default(),
            drift: None,
            trackers: model
                .transitions
                .iter()
                .map(|t| (t.id, DriftTracker::new(t)))
                .collect(),
        })
    }

    /// Tracks each transition's durations and warns of drift by `rules`
    /// (`None`: off, the default). Rules out of range
    /// ([`DriftRules::problems`]) are the caller's to refuse.
    #[must_use]
    pub fn drifting(mut self, rules: Option<DriftRules>) -> Self {
        self.drift = rules;
        self
    }

    /// A duration of transition `id` inside its window, `ms` long, ended at
    /// `at`: its drift warning raised, updated or cleared, if it changes.
    fn track(&mut self, id: u32, ms: u64, at: u64, out: &mut Vec<Finding>) {
        let (Some(rules), Some(tracker)) = (&self.drift, self.trackers.get_mut(&id)) else {
            return;
        };
        if tracker.measure(ms, at, rules).is_none() {
            return;
        }
        let Some((what, s, _, _)) = self.transitions.get(&id) else {
            return;
        };
        let message = format!("transition #{id:03} ({what}) {}", tracker.evidence());
        let message = match self.comments.get(&self.signals[*s]) {
            Some(c) => format!("{message}: {c}"),
            None => message,
        };
        out.push(Finding {
            at: None,
            id: drift_alarm(&self.id, id),
            kind: AlarmKind::Drift,
            severity: Severity::Low,
            fault_type: "DRIFT".into(),
            latched: false,
            active: tracker.active(),
            fault_step: None,
            culprits: Vec::new(),
            message,
        });
    }

    /// The transition whose alarm (`<id>-<nnn>`, `false`) or drift warning
    /// (`<id>-<nnn>-drift`, `true`) `id` is.
    fn transition_of(&self, id: &str) -> Option<(u32, bool)> {
        let rest = id.strip_prefix(self.id.as_str())?.strip_prefix('-')?;
        let (number, drift) = rest
            .strip_suffix("-drift")
            .map_or((rest, false), |n| (n, true));
        let t = number
            .parse::<u32>()
            .ok()
            .filter(|t| format!("{t:03}") == number)?;
        self.transitions.contains_key(&t).then_some((t, drift))
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
                    at_ms,
                } => {
                    self.observed.push(Observation {
                        check: format!("{}-{transition:03}", self.id),
                        ms: observed_ms,
                    });
                    self.track(transition, observed_ms, at_ms, out);
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
            self.late.insert(id, late);
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
pub fn label(t: &super::learn::LearnedTransition) -> String {
    let edge = |e: SignalEdge| if e == SignalEdge::Rise { "+" } else { "-" };
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

    /// A transition's alarm reads the event it waits for and the request
    /// that starts its timer; a late event holds nothing.
    fn facts(&self, out: &mut Vec<crate::consequence::AlarmFacts>) {
        for (t, (_, s, _, _)) in &self.transitions {
            let mut reads = vec![self.signals[*s].clone()];
            let request = self.awaits.get(t).and_then(|a| a.request.as_ref());
            reads.extend(request.map(|(r, _)| r.clone()));
            out.push(crate::consequence::AlarmFacts {
                id: format!("{}-{t:03}", self.id),
                effects: Vec::new(),
                reads,
            });
        }
    }

    /// Whether transition `nnn`'s event would still not have come (or
    /// still have come early): [`Awaited::would_hold`].
    fn would_hold(&self, id: &str, instead: &[(Signal, bool)]) -> Option<bool> {
        let t = self.transition_of(id).filter(|(_, drift)| !drift)?.0;
        let now = |s: &Signal| self.by_signal.get(s).and_then(|&i| self.monitor.value(i));
        self.awaits
            .get(&t)?
            .would_hold(*self.late.get(&t)?, instead, now)
    }

    /// Transition `nnn`'s start condition, trigger and event signals, for
    /// its alarm `<id>-<nnn>` and its drift warning `<id>-<nnn>-drift`.
    fn reads(&self, id: &str, out: &mut Vec<Signal>) {
        let Some((t, _)) = self.transition_of(id) else {
            return;
        };
        for &s in self.reads.get(&t).into_iter().flatten() {
            out.push(self.signals[s].clone());
        }
    }

    /// The transition, its event and its learned window; a drift
    /// warning's threshold.
    fn describe(&self, id: &str) -> Option<String> {
        let rest = id.strip_prefix(&self.id)?.strip_prefix('-')?;
        let (number, drift) = match rest.strip_suffix("-drift") {
            Some(n) => (n, true),
            None => (rest, false),
        };
        let t: u32 = number.parse().ok()?;
        let (what, event, value, [lo, hi]) = self.transitions.get(&t)?;
        let seconds = |ms: &u64| format!("{} s", *ms as f64 / 1000.0);
        let window = format!(
            "transition {t} ({what}): {} = {} expected between {} and {} after it starts",
            self.signals[*event],
            u8::from(*value),
            seconds(lo),
            seconds(hi)
        );
        Some(match (drift, &self.drift) {
            (true, Some(d)) => format!(
                "{window}; warns when its recent durations drift towards a limit ({} of the way)",
                d.fraction
            ),
            (true, None) => return None,
            (false, _) => format!("{window}; too early or too late is a fault"),
        })
    }

    fn alarms(&self) -> Vec<Declared> {
        let mut ids: Vec<u32> = self.transitions.keys().copied().collect();
        ids.sort_unstable();
        let mut out: Vec<Declared> = ids
            .iter()
            .map(|t| Declared {
                id: format!("{}-{t:03}", self.id),
                kind: AlarmKind::Timer,
                severity: self.severity,
                fault_type: "TIMER".into(),
                latched: true,
            })
            .collect();
        if self.drift.is_some() {
            out.extend(ids.iter().map(|&t| Declared {
                id: drift_alarm(&self.id, t),
                kind: AlarmKind::Drift,
                severity: Severity::Low,
                fault_type: "DRIFT".into(),
                latched: false,
            }));
        }
        out
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

    fn restored(&mut self, alarm: &Alarm) {
        if self.drift.is_none() {
            return;
        }
        for (&id, tracker) in &mut self.trackers {
            if alarm.id == drift_alarm(&self.id, id) {
                tracker.restored();
            }
        }
    }

    fn window_positions(&self, out: &mut Vec<WindowPosition>) {
        if self.drift.is_none() {
            return;
        }
        for (&id, t) in &self.trackers {
            let (Some(position), Some(mean_ms), Some(spread_ms)) =
                (t.position(), t.mean_ms(), t.spread_ms())
            else {
                continue;
            };
            out.push(WindowPosition {
                check: format!("{}-{id:03}", self.id),
                position,
                mean_ms,
                spread_ms,
                samples: t.samples(),
            });
        }
    }
}

#[cfg(test)]
mod tests;
