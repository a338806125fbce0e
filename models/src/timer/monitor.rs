//! The runtime monitor of transition timers.
//!
//! Fed signal changes with their times and [`TimerMonitor::advance`] as
//! time passes. A transition is *armed* when its start condition becomes
//! true (its state is entered) and measures θ from then:
//! - its event at θ ≤ Δt − τ: [`Outcome::Early`] (the paper's Case 1);
//! - no event by θ = Δt + τ: [`Outcome::Late`], raised at exactly that time
//!   (Case 2);
//! - its event with Δt − τ < θ < Δt + τ: [`Outcome::Normal`] (Case 3).
//!
//! Any other change of a signal in the condition disarms it (the state was
//! left another way). A signal whose value is unknown (bad quality, lost
//! connection) disarms every transition that reads it and keeps it
//! disarmed until the value is known again: no false alarm.
//!
//! Times are the PLC's (source timestamps), and they may come out of order
//! (two publishes crossing, a PLC clock set back). A change earlier than
//! the latest known value's time is a change whose place in time is not
//! known: it disarms every transition that reads its signal and arms none,
//! so no duration is measured through it ([`TimerMonitor::set_untimed`]).
//! A time at the end of the range never overflows: a deadline beyond it
//! is the end of the range.

use std::collections::{BTreeSet, HashMap};

use serde::Serialize;

use super::learn::{SignalEdge, TimerModel};

/// What the monitor found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "outcome", rename_all = "lowercase")]
pub enum Outcome {
    /// The event came at or before Δt − τ.
    Early {
        /// Transition id.
        transition: u32,
        /// When, ms.
        at_ms: u64,
        /// θ, ms.
        observed_ms: u64,
    },
    /// The event had not come at Δt + τ.
    Late {
        /// Transition id.
        transition: u32,
        /// When (exactly Δt + τ after arming), ms.
        at_ms: u64,
    },
    /// The event came inside the window.
    Normal {
        /// Transition id.
        transition: u32,
        /// When, ms.
        at_ms: u64,
        /// θ, ms.
        observed_ms: u64,
    },
}

struct Compiled {
    id: u32,
    condition: Vec<(usize, bool)>,
    /// The start condition as bit masks over the words of the signal
    /// bitset it touches (the paper's COM + literals): per word `(index,
    /// mask, want, need)`, `bits & mask == want` and the `need` signals (the
    /// condition's and the event's) known. Only those words: checking costs
    /// the condition's size, not the cell's.
    words: Vec<(usize, u64, u64, u64)>,
    event: (usize, bool),
    /// `common` method: the event that starts the timer.
    trigger: Option<(usize, bool)>,
    lo: u64,
    hi: u64,
}

/// Why a model cannot be monitored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ModelError {
    /// Another file version.
    #[error("timer model version {0} is not supported (expected 1)")]
    Version(u32),
    /// A literal names a signal not in the model's list.
    #[error("transition {id}: unknown signal '{tag}'")]
    UnknownSignal {
        /// Transition.
        id: u32,
        /// Signal.
        tag: String,
    },
}

/// The monitor of one model.
pub struct TimerMonitor {
    signals: Vec<String>,
    index: HashMap<String, usize>,
    values: Vec<Option<bool>>,
    /// One bit per signal: its value, and whether it is known.
    bits: Vec<u64>,
    known: Vec<u64>,
    transitions: Vec<Compiled>,
    /// Per signal: transitions whose condition or event reads it.
    readers: Vec<Vec<usize>>,
    /// Per transition: when it was armed.
    armed: Vec<Option<u64>>,
    /// The armed transitions by deadline (armed + Δt + τ): time passing
    /// costs only the transitions that fall due.
    due: BTreeSet<(u64, usize)>,
    /// The time of the latest known value: a change before it is out of
    /// order.
    latest: Option<u64>,
}

impl TimerMonitor {
    /// Compiles `model`. Every signal starts unknown.
    ///
    /// # Errors
    /// An unsupported version or an unknown signal.
    pub fn new(model: &TimerModel) -> Result<TimerMonitor, ModelError> {
        if model.version != super::learn::MODEL_VERSION {
            return Err(ModelError::Version(model.version));
        }
        let index: HashMap<String, usize> = model
            .signals
            .iter()
            .enumerate()
            .map(|(i, s)| (s.clone(), i))
            .collect();
        let lookup = |id: u32, tag: &str| {
            index
                .get(tag)
                .copied()
                .ok_or_else(|| ModelError::UnknownSignal {
                    id,
                    tag: tag.into(),
                })
        };
        let mut transitions = Vec::new();
        let mut readers = vec![Vec::new(); model.signals.len()];
        for t in &model.transitions {
            let mut condition = Vec::new();
            for lit in &t.from {
                let (tag, v) = match lit.strip_prefix('-') {
                    Some(tag) => (tag, false),
                    None => (lit.as_str(), true),
                };
                condition.push((lookup(t.id, tag)?, v));
            }
            let event = (
                lookup(t.id, &t.event.tag)?,
                t.event.edge == SignalEdge::Rise,
            );
            let trigger = match &t.trigger {
                Some(e) => Some((lookup(t.id, &e.tag)?, e.edge == SignalEdge::Rise)),
                None => None,
            };
            let k = transitions.len();
            for &(s, _) in condition
                .iter()
                .chain(std::iter::once(&event))
                .chain(trigger.iter())
            {
                if !readers[s].contains(&k) {
                    readers[s].push(k);
                }
            }
            let mut words: Vec<(usize, u64, u64, u64)> = Vec::new();
            let mut word = |s: usize| -> usize {
                match words.iter().position(|w| w.0 == s / 64) {
                    Some(i) => i,
                    None => {
                        words.push((s / 64, 0, 0, 0));
                        words.len() - 1
                    }
                }
            };
            let mut bits = Vec::new();
            for &(s, v) in &condition {
                bits.push((word(s), s, Some(v)));
            }
            bits.push((word(event.0), event.0, None));
            for (i, s, v) in bits {
                let b = 1u64 << (s % 64);
                let w = &mut words[i];
                w.3 |= b;
                if let Some(v) = v {
                    w.1 |= b;
                    if v {
                        w.2 |= b;
                    }
                }
            }
            words.sort_unstable();
            transitions.push(Compiled {
                id: t.id,
                words,
                condition,
                event,
                trigger,
                lo: t.window_ms[0],
                hi: t.window_ms[1],
            });
        }
        let n = transitions.len();
        Ok(TimerMonitor {
            bits: vec![0; model.signals.len().div_ceil(64)],
            known: vec![0; model.signals.len().div_ceil(64)],
            values: vec![None; model.signals.len()],
            signals: model.signals.clone(),
            index,
            transitions,
            readers,
            armed: vec![None; n],
            due: BTreeSet::new(),
            latest: None,
        })
    }

    /// Arms transition `k` at `at` (re-arms it if it was).
    fn arm(&mut self, k: usize, at: u64) {
        self.disarm(k);
        self.armed[k] = Some(at);
        self.due.insert((self.deadline(k, at), k));
    }

    fn disarm(&mut self, k: usize) {
        if let Some(since) = self.armed[k].take() {
            self.due.remove(&(self.deadline(k, since), k));
        }
    }

    /// When transition `k`, armed at `since`, is late (Δt + τ later, at
    /// most the end of time).
    fn deadline(&self, k: usize, since: u64) -> u64 {
        since.saturating_add(self.transitions[k].hi)
    }

    /// How many transitions are armed now (waiting for their event).
    pub fn armed(&self) -> usize {
        self.due.len()
    }

    /// The earliest time an armed transition becomes late, if one is armed.
    pub fn next_deadline(&self) -> Option<u64> {
        self.due.first().map(|&(d, _)| d)
    }

    /// The index of a signal.
    pub fn signal(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// Signal `s`'s value now, `None` while unknown.
    pub fn value(&self, s: usize) -> Option<bool> {
        self.values.get(s).copied().flatten()
    }

    /// The signals, by index.
    pub fn signals(&self) -> &[String] {
        &self.signals
    }

    /// The start condition holds: its signals as wanted, and they and the
    /// event's signal known.
    fn holds(&self, t: &Compiled) -> bool {
        t.words.iter().all(|&(w, mask, want, need)| {
            self.known[w] & need == need && self.bits[w] & mask == want
        })
    }

    /// Signal `s` became `value` (`None`: unknown) at `at`; late outcomes
    /// due before `at` are reported first. A change earlier than the latest
    /// known value is taken as [`TimerMonitor::set_untimed`].
    pub fn set(&mut self, s: usize, value: Option<bool>, at: u64) -> Vec<Outcome> {
        if self.latest.is_some_and(|latest| at < latest) {
            return self.set_untimed(s, value, at);
        }
        if value.is_some() {
            self.latest = Some(at);
        }
        let mut out = self.advance(at);
        let old = self.values[s];
        if old == value {
            return out;
        }
        // Taken, not copied, while the transitions are updated.
        let readers = std::mem::take(&mut self.readers[s]);
        // The event first: a transition armed before this change sees it.
        for &k in &readers {
            let Some(since) = self.armed[k] else { continue };
            let t = &self.transitions[k];
            let is_event = t.event.0 == s && value == Some(t.event.1) && old == Some(!t.event.1);
            if is_event {
                // Armed by a change no later than this one (`latest`).
                let theta = at.saturating_sub(since);
                out.push(if theta <= t.lo {
                    Outcome::Early {
                        transition: t.id,
                        at_ms: at,
                        observed_ms: theta,
                    }
                } else if theta >= t.hi {
                    Outcome::Late {
                        transition: t.id,
                        at_ms: since.saturating_add(t.hi),
                    }
                } else {
                    Outcome::Normal {
                        transition: t.id,
                        at_ms: at,
                        observed_ms: theta,
                    }
                });
                self.disarm(k);
            } else if value.is_none() || t.trigger.is_none() {
                // Unknown value, or (full-state) the state left another way.
                self.disarm(k);
            }
        }
        self.store(s, value);
        for &k in &readers {
            let t = &self.transitions[k];
            let start = match t.trigger {
                // `common`: the trigger starts (or restarts) the timer when
                // the start condition holds.
                Some((ts, tv)) => ts == s && value == Some(tv) && old == Some(!tv) && self.holds(t),
                // `full-state`: entering the state starts it.
                None => {
                    self.armed[k].is_none()
                        && self.holds(t)
                        && t.condition.iter().any(|&(c, _)| c == s)
                }
            };
            if start {
                self.arm(k, at);
            }
        }
        self.readers[s] = readers;
        out
    }

    /// Signal `s` became `value` at a time not known to be in order with
    /// the others (its source time `at` is earlier than one already seen):
    /// its value is taken, and every transition reading it is disarmed
    /// without a verdict and none is armed by it. Late outcomes due by
    /// `at` are reported first.
    pub fn set_untimed(&mut self, s: usize, value: Option<bool>, at: u64) -> Vec<Outcome> {
        let out = self.advance(at);
        if self.values[s] == value {
            return out;
        }
        for i in 0..self.readers[s].len() {
            let k = self.readers[s][i];
            self.disarm(k);
        }
        self.store(s, value);
        out
    }

    /// Keeps signal `s`'s value and its bits.
    fn store(&mut self, s: usize, value: Option<bool>) {
        self.values[s] = value;
        let (w, b) = (s / 64, 1u64 << (s % 64));
        match value {
            Some(v) => {
                self.known[w] |= b;
                if v {
                    self.bits[w] |= b;
                } else {
                    self.bits[w] &= !b;
                }
            }
            None => self.known[w] &= !b,
        }
    }

    /// Time is now `now`: every armed transition past Δt + τ is late.
    pub fn advance(&mut self, now: u64) -> Vec<Outcome> {
        let mut out = Vec::new();
        // In deadline order, which is the order of the outcomes' times.
        while let Some(&(deadline, k)) = self.due.first() {
            if deadline > now {
                break;
            }
            self.due.pop_first();
            self.armed[k] = None;
            out.push(Outcome::Late {
                transition: self.transitions[k].id,
                at_ms: deadline,
            });
        }
        out
    }
}

/// Runs `model`'s monitor over one run log in virtual time: initial values
/// at 0, every change, then time advanced to the last change (the end of
/// the log ends the observation).
///
/// # Errors
/// The model cannot be monitored.
pub fn replay(model: &TimerModel, run: &super::log::RunLog) -> Result<Vec<Outcome>, ModelError> {
    let mut m = TimerMonitor::new(model)?;
    let index: Vec<Option<usize>> = run.signals.iter().map(|s| m.signal(s)).collect();
    let mut out = Vec::new();
    for (i, &v) in run.initial.iter().enumerate() {
        if let Some(s) = index[i] {
            out.extend(m.set(s, Some(v), 0));
        }
    }
    let mut end = 0;
    for c in &run.changes {
        if let Some(s) = index[c.signal] {
            out.extend(m.set(s, Some(c.value), c.at));
        }
        end = c.at;
    }
    out.extend(m.advance(end));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timer::learn::{Event, LearnedTransition};

    /// δ(2:-3, +3 | 130) = 2:3 with τ = 10.
    fn monitor() -> TimerMonitor {
        let model = TimerModel {
            version: 1,
            method: "full-state".into(),
            signals: vec!["S1".into(), "S2".into(), "S3".into()],
            transitions: vec![LearnedTransition {
                id: 1,
                from: vec!["S2".into(), "-S3".into()],
                event: Event {
                    tag: "S3".into(),
                    edge: SignalEdge::Rise,
                },
                to: vec!["S2".into(), "S3".into()],
                delta_ms: 130,
                min_ms: 130,
                max_ms: 130,
                support: 1,
                window_ms: [120, 140],
                from_numbered: None,
                trigger: None,
            }],
        };
        let mut m = TimerMonitor::new(&model).unwrap();
        m.set(0, Some(false), 0);
        m.set(2, Some(false), 0);
        m.set(1, Some(false), 0);
        // Entering 2:-3 at t = 1000 arms the timer.
        assert!(m.set(1, Some(true), 1000).is_empty());
        m
    }

    #[test]
    fn early_normal_late_in_virtual_time() {
        let mut m = monitor();
        assert_eq!(
            m.set(2, Some(true), 1115),
            [Outcome::Early {
                transition: 1,
                at_ms: 1115,
                observed_ms: 115
            }]
        );
        let mut m = monitor();
        assert_eq!(
            m.set(2, Some(true), 1125),
            [Outcome::Normal {
                transition: 1,
                at_ms: 1125,
                observed_ms: 125
            }]
        );
        let mut m = monitor();
        assert_eq!(
            m.set(2, Some(true), 1135),
            [Outcome::Normal {
                transition: 1,
                at_ms: 1135,
                observed_ms: 135
            }]
        );
        let mut m = monitor();
        assert!(m.advance(1139).is_empty());
        assert_eq!(
            m.advance(1140),
            [Outcome::Late {
                transition: 1,
                at_ms: 1140
            }]
        );
        assert!(m.advance(5000).is_empty(), "reported once");
        // Late is reported at exactly Δt + τ even when time jumps past it.
        let mut m = monitor();
        assert_eq!(
            m.advance(9000),
            [Outcome::Late {
                transition: 1,
                at_ms: 1140
            }]
        );
    }

    #[test]
    fn unknown_signal_suspends_the_timer() {
        let mut m = monitor();
        m.set(2, None, 1050);
        assert!(
            m.advance(2000).is_empty(),
            "no late alarm on an unknown signal"
        );
        // Known again and the state is re-entered: armed afresh.
        m.set(2, Some(false), 3000);
        assert_eq!(
            m.advance(3140),
            [Outcome::Late {
                transition: 1,
                at_ms: 3140
            }]
        );
    }

    #[test]
    fn a_change_out_of_time_order_gives_no_verdict() {
        // Armed at 1000; the event stamped 900, before the arming: whether
        // it came before or after is not known, so no outcome, and the
        // transition is disarmed.
        let mut m = monitor();
        assert!(m.set(2, Some(true), 900).is_empty());
        assert_eq!(m.armed(), 0);
        assert!(m.advance(5000).is_empty());
        // The state entered again by a change stamped before the latest
        // one: not armed.
        m.set(2, Some(false), 5000);
        m.set(1, Some(false), 5001);
        assert!(m.set(1, Some(true), 4000).is_empty());
        assert_eq!(m.armed(), 0);
        assert!(m.advance(10_000).is_empty());
        // In order again: armed and judged as before.
        m.set(1, Some(false), 10_001);
        m.set(1, Some(true), 10_002);
        assert_eq!(
            m.advance(10_142),
            [Outcome::Late {
                transition: 1,
                at_ms: 10_142
            }]
        );
        // Duplicate times are in order.
        m.set(1, Some(false), 10_200);
        m.set(1, Some(true), 10_200);
        assert_eq!(
            m.set(2, Some(true), 10_200),
            [Outcome::Early {
                transition: 1,
                at_ms: 10_200,
                observed_ms: 0
            }]
        );
    }

    #[test]
    fn times_at_the_end_of_the_range_do_not_overflow() {
        let mut m = monitor();
        m.set(1, Some(false), u64::MAX - 5);
        m.set(1, Some(true), u64::MAX - 5);
        assert_eq!(m.next_deadline(), Some(u64::MAX));
        assert_eq!(
            m.advance(u64::MAX),
            [Outcome::Late {
                transition: 1,
                at_ms: u64::MAX
            }]
        );
        // Armed at the end of time: its deadline is there too, and falls
        // due before the event at the same time is looked at.
        m.set(1, Some(false), u64::MAX);
        m.set(1, Some(true), u64::MAX);
        assert_eq!(
            m.set(2, Some(true), u64::MAX),
            [Outcome::Late {
                transition: 1,
                at_ms: u64::MAX
            }]
        );
    }

    #[test]
    fn leaving_the_state_another_way_disarms() {
        let mut m = monitor();
        m.set(1, Some(false), 1050);
        assert!(m.advance(2000).is_empty());
    }
}
