//! The current shift's OEE as the cell runs: the facts since the shift
//! began (and the last of each before it) kept, and the figures computed
//! from them by the same [`super::shift`] the reports use, so what the
//! metrics say is what the report will say. Facts older than the current
//! shift are dropped when it changes.

use super::{shift, Facts, Figures, ModeChange, OeeRules, ShiftWindow};
use crate::report::{OrderChange, StateChange, StopCauses};

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
        }
    }

    /// The machine state changed.
    pub fn on_state(&mut self, at: u64, state: &str, fault_type: Option<&str>) {
        self.changes.push(StateChange {
            at,
            state: state.to_string(),
            fault_type: fault_type.map(str::to_string),
        });
    }

    /// A machine mode was entered or left.
    pub fn on_mode(&mut self, at: u64, mode: &str, entered: bool) {
        self.modes.push(ModeChange {
            at,
            mode: mode.to_string(),
            entered,
        });
    }

    /// `n` parts made.
    pub fn on_parts(&mut self, at: u64, n: u64) {
        self.parts.push((at, n));
    }

    /// `n` parts rejected.
    pub fn on_rejects(&mut self, at: u64, n: u64) {
        self.rejects.push((at, n));
    }

    /// The item in work changed.
    pub fn on_order(&mut self, at: u64, item: Option<&str>) {
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
        }
        let facts = Facts {
            changes: &self.changes,
            modes: &self.modes,
            parts: &self.parts,
            rejects: &self.rejects,
            orders: &self.orders,
        };
        let f = shift(&self.rules, &self.causes, &facts, &window, now);
        Some((window, f))
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
}
