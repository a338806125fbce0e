//! The current shift's OEE as the cell runs: the facts since the shift
//! began (and the last of each before it) kept, and the figures computed
//! from them by the same [`super::shift`] the reports use, so what the
//! metrics say is what the report will say. Facts older than the current
//! shift are dropped when it changes.
//!
//! What is kept is bounded: once more than [`FOLD_AT`] state changes or
//! counts are kept (an alarm flood toggling the machine in and out of
//! `fault`), the figures up to the newest change are computed once and
//! kept as a sum, and the facts before it dropped. A fold cuts where one
//! state ends and another begins, so no stretch is split, and keeps what
//! the rest is judged by (the state, the order and the modes holding at
//! the cut, the last return to `running` before it): the figures are
//! the same as from the whole history. A fact dated before a fold (a
//! counter's value republished late) counts at the fold's cut.

use super::{shift, Facts, Figures, ModeChange, OeeRules, ShiftWindow};
use crate::report::{OrderChange, StateChange, StopCauses};

/// The most state changes, parts or rejects entries kept before a fold.
const FOLD_AT: usize = 4096;

/// The facts of the current shift and how to judge them.
#[derive(Debug, Clone)]
pub struct LiveOee {
    rules: OeeRules,
    causes: StopCauses,
    changes: Vec<StateChange>,
    modes: Vec<ModeChange>,
    parts: Vec<(u64, u64)>,
    rejects: Vec<(u64, u64)>,
    orders: Vec<OrderChange>,
    /// The start of the shift the facts are kept for.
    kept_from: u64,
    /// The figures of the shift up to `folded.0`, whose facts are no
    /// longer kept.
    folded: Option<(u64, Figures)>,
    /// The last return to `running` before the fold.
    earlier_start: Option<u64>,
    fold_at: usize,
}

impl LiveOee {
    /// Judges by `rules`, breakdowns named by `causes`.
    pub fn new(rules: OeeRules, causes: StopCauses) -> LiveOee {
        LiveOee {
            rules,
            causes,
            changes: Vec::new(),
            modes: Vec::new(),
            parts: Vec::new(),
            rejects: Vec::new(),
            orders: Vec::new(),
            kept_from: 0,
            folded: None,
            earlier_start: None,
            fold_at: FOLD_AT,
        }
    }

    /// Folds once more than `n` facts of a kind are kept (tests).
    #[cfg(test)]
    fn folding_at(mut self, n: usize) -> LiveOee {
        self.fold_at = n;
        self
    }

    /// `at`, or the fold's cut for a fact dated before it (late: a
    /// counter's value republished after a gap): it counts there.
    fn after_fold(&self, at: u64) -> u64 {
        self.folded.as_ref().map_or(at, |(cut, _)| at.max(*cut))
    }

    /// The machine state changed.
    pub fn on_state(&mut self, at: u64, state: &str, fault_type: Option<&str>) {
        let at = self.after_fold(at);
        self.changes.push(StateChange {
            at,
            state: state.to_string(),
            fault_type: fault_type.map(str::to_string),
        });
    }

    /// A machine mode was entered or left.
    pub fn on_mode(&mut self, at: u64, mode: &str, entered: bool) {
        let at = self.after_fold(at);
        self.modes.push(ModeChange {
            at,
            mode: mode.to_string(),
            entered,
        });
    }

    /// `n` parts made.
    pub fn on_parts(&mut self, at: u64, n: u64) {
        let at = self.after_fold(at);
        self.parts.push((at, n));
    }

    /// `n` parts rejected.
    pub fn on_rejects(&mut self, at: u64, n: u64) {
        let at = self.after_fold(at);
        self.rejects.push((at, n));
    }

    /// The item in work changed.
    pub fn on_order(&mut self, at: u64, item: Option<&str>) {
        let at = self.after_fold(at);
        self.orders.push(OrderChange {
            at,
            item: item.map(str::to_string),
            target: None,
        });
    }

    /// The current shift (or the last one ended) and its figures at `now`.
    pub fn figures(&mut self, now: u64) -> Option<(ShiftWindow, Figures)> {
        let window = self.rules.calendar.current(now)?;
        if window.start > self.kept_from {
            self.forget_before(window.start);
            self.folded = None;
            self.earlier_start = None;
        }
        let over = |n: usize| n > self.fold_at;
        if over(self.changes.len()) || over(self.parts.len()) || over(self.rejects.len()) {
            self.fold(&window, now);
        }
        let rest = ShiftWindow {
            start: self.folded.as_ref().map_or(window.start, |(cut, _)| *cut),
            ..window.clone()
        };
        let f = shift(&self.rules, &self.causes, &self.facts(), &rest, now);
        let f = match &self.folded {
            Some((_, before)) => {
                let mut total = before.clone();
                total.add(&f);
                // Reduced speed is what the whole run time leaves.
                total.losses.reduced_speed_ms = total
                    .run_ms
                    .saturating_sub(total.losses.small_stops_ms)
                    .saturating_sub(total.ideal_ms);
                total
            }
            None => f,
        };
        Some((window, f))
    }

    fn facts(&self) -> Facts<'_> {
        Facts {
            changes: &self.changes,
            modes: &self.modes,
            parts: &self.parts,
            rejects: &self.rejects,
            orders: &self.orders,
            earlier_start: self.earlier_start,
        }
    }

    /// Folds the shift's figures up to a cut into `folded` and drops the
    /// facts before it. The cut is `now` (at most the shift's end), or,
    /// while the machine is `idle` (a stop judged by its whole length), the
    /// start of that stop; every other stretch adds up across a cut.
    fn fold(&mut self, window: &ShiftWindow, now: u64) {
        let from = self.folded.as_ref().map_or(window.start, |(cut, _)| *cut);
        let mut cut = now.min(window.end);
        if let Some(idle) = super::runs(&self.changes, cut)
            .last()
            .filter(|r| r.state == "idle")
        {
            // The start of the idle stretch in progress.
            cut = cut.min(idle.from);
        }
        if cut <= from {
            return;
        }
        let before = ShiftWindow {
            start: from,
            ..window.clone()
        };
        let part = shift(&self.rules, &self.causes, &self.facts(), &before, cut);
        self.earlier_start = self.last_start_before(cut);
        self.forget_before(cut);
        let total = match self.folded.take() {
            Some((_, mut total)) => {
                total.add(&part);
                total
            }
            None => part,
        };
        self.folded = Some((cut, total));
    }

    /// The last time the machine went back to `running` before `t`, as
    /// [`shift`] finds starts (between stretches of the history up to `t`).
    fn last_start_before(&self, t: u64) -> Option<u64> {
        super::runs(&self.changes, t)
            .windows(2)
            .filter(|p| p[1].state == "running" && p[0].state != "running")
            .map(|p| p[1].from)
            .next_back()
            .or(self.earlier_start)
    }

    /// Drops what came before `start`, keeping the last state and order
    /// before it and the modes holding at it.
    fn forget_before(&mut self, start: u64) {
        self.kept_from = start;
        keep_last_before(&mut self.changes, start, |c| c.at);
        keep_last_before(&mut self.orders, start, |o| o.at);
        let mut holding: Vec<ModeChange> = Vec::new();
        for m in self.modes.iter().filter(|m| m.at < start) {
            holding.retain(|h| h.mode != m.mode);
            if m.entered {
                holding.push(m.clone());
            }
        }
        self.modes.retain(|m| m.at >= start);
        holding.append(&mut self.modes);
        self.modes = holding;
        self.parts.retain(|&(at, _)| at >= start);
        self.rejects.retain(|&(at, _)| at >= start);
    }
}

/// Keeps the items at or after `start` and the last one before it.
fn keep_last_before<T>(items: &mut Vec<T>, start: u64, at: impl Fn(&T) -> u64) {
    let first_kept = items.iter().position(|i| at(i) >= start);
    let cut = first_kept.unwrap_or(items.len()).saturating_sub(1);
    items.drain(..cut);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oee::{Calendar, Shift};

    const MIN: u64 = 60_000;

    #[test]
    fn the_live_figures_are_the_shifts_and_old_facts_are_dropped_at_its_change() {
        let rules = OeeRules {
            calendar: Calendar {
                shifts: vec![Shift {
                    name: "a".into(),
                    days: [true; 7],
                    start: 0,
                    end: 12 * 60,
                    breaks: vec![],
                }],
                utc_offset_ms: 0,
            },
            ideal_cycle_ms: MIN,
            ..OeeRules::default()
        };
        let mut live = LiveOee::new(rules.clone(), StopCauses::default());
        live.on_state(0, "running", None);
        live.on_parts(30 * MIN, 20);
        live.on_state(60 * MIN, "fault", Some("ESE"));
        let (w, f) = live.figures(120 * MIN).unwrap();
        assert_eq!((w.start, f.planned_ms, f.run_ms), (0, 120 * MIN, 60 * MIN));
        assert_eq!(f.performance, Some(20.0 / 60.0));
        // The next day's shift: yesterday's parts forgotten, the fault
        // still holding.
        let day = 24 * 60 * MIN;
        let (w, f) = live.figures(day + 10 * MIN).unwrap();
        assert_eq!(
            (w.start, f.parts, f.losses.breakdowns_ms),
            (day, 0, 10 * MIN)
        );
        assert_eq!(live.parts.len(), 0);
        assert_eq!(live.changes.len(), 1);
    }

    /// One fact of a random history: a state, a mode, parts, rejects or
    /// an order, at a minute of a 24-hour day.
    #[derive(Debug, Clone)]
    enum Fact {
        State(u8),
        Mode(bool, bool),
        Parts(u8),
        Rejects(u8),
        Order(u8),
        Look,
    }

    fn fact() -> impl proptest::strategy::Strategy<Value = (u64, Fact)> {
        use proptest::prelude::*;
        let f = prop_oneof![
            4 => (0u8..4).prop_map(Fact::State),
            1 => (any::<bool>(), any::<bool>()).prop_map(|(m, e)| Fact::Mode(m, e)),
            2 => (1u8..5).prop_map(Fact::Parts),
            1 => (1u8..3).prop_map(Fact::Rejects),
            1 => (0u8..3).prop_map(Fact::Order),
            2 => Just(Fact::Look),
        ];
        (5 * 60..15 * 60u64, f)
    }

    proptest::proptest! {
        /// Folded as often as can be (every second fact), the live
        /// figures are those of the whole history.
        #[test]
        fn folding_changes_no_figure(mut facts in proptest::collection::vec(fact(), 1..120)) {
            facts.sort_by_key(|(m, _)| *m);
            let rules = OeeRules {
                calendar: Calendar {
                    shifts: vec![
                        Shift { name: "a".into(), days: [true; 7], start: 6 * 60, end: 14 * 60, breaks: vec![(10 * 60, 10 * 60 + 15)] },
                        Shift { name: "b".into(), days: [true; 7], start: 14 * 60, end: 22 * 60, breaks: vec![] },
                    ],
                    utc_offset_ms: 0,
                },
                ideal_cycle_ms: MIN,
                items: [("x".to_string(), 2 * MIN)].into(),
                planned_stops: vec!["p".into()],
                setup: vec!["s".into()],
                small_stop_ms: 5 * MIN,
                startup_ms: 10 * MIN,
            };
            let whole = LiveOee::new(rules.clone(), StopCauses::default());
            let folding = LiveOee::new(rules, StopCauses::default()).folding_at(1);
            let mut both = [whole, folding];
            for (minute, f) in &facts {
                let at = minute * MIN;
                for live in &mut both {
                    match f {
                        Fact::State(k) => {
                            let (state, fault) = [("running", None), ("idle", None), ("fault", Some("JAM")), ("offline", None)][*k as usize];
                            live.on_state(at, state, fault);
                        }
                        Fact::Mode(m, e) => live.on_mode(at, if *m { "p" } else { "s" }, *e),
                        Fact::Parts(n) => live.on_parts(at, u64::from(*n)),
                        Fact::Rejects(n) => live.on_rejects(at, u64::from(*n)),
                        Fact::Order(k) => live.on_order(at, [None, Some("x"), Some("y")][*k as usize]),
                        Fact::Look => {}
                    }
                }
                if matches!(f, Fact::Look) {
                    let [w, f] = &mut both;
                    proptest::prop_assert_eq!(w.figures(at), f.figures(at));
                }
            }
            let end = 24 * 60 * MIN;
            let [w, f] = &mut both;
            proptest::prop_assert_eq!(w.figures(end), f.figures(end));
        }
    }
}
