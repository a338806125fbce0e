//! Overall equipment effectiveness from the machine-state history, the
//! parts and rejects counted and a shift calendar: availability,
//! performance and quality per shift and per day, with the six big losses.
//! Pure: the history, the counts and `now` are passed in; the journal, the
//! metrics and the report's printing are the agent's.
//!
//! For a shift's window (its breaks and the time a planned-stop mode holds
//! taken out):
//! - **planned production time** = the window's time the machine was
//!   observed (not `offline`), minus breaks and planned stops;
//! - **run time** = planned time `running` outside a setup mode, plus
//!   small stops (an `idle` stop shorter than `small_stop`: counted in
//!   the run, lost as speed);
//! - availability = run ÷ planned; performance = Σ(ideal cycle of the item
//!   in force × parts) ÷ run; quality = (parts − rejects) ÷ parts; OEE =
//!   A × P × Q.
//!
//! The six big losses, from the history:
//! - *breakdowns*: planned time in `fault` (by stop cause, its fault
//!   type) and in `idle` stops of `small_stop` or longer (the idle cause),
//!   outside a setup mode;
//! - *setup and adjustment*: planned time while a setup mode holds;
//! - *small stops*: `idle` stops shorter than `small_stop`;
//! - *reduced speed*: run − small stops − Σ ideal time of all parts;
//! - *start-up rejects*: rejects within `startup` after the machine went
//!   back to `running` from any other state; *production rejects*: the
//!   others; each priced at its item's ideal cycle.

mod calendar;
mod live;

use std::collections::{BTreeMap, BTreeSet};

use serde::Serialize;

pub use calendar::{Calendar, Shift, ShiftWindow, DAY_MS};
pub use live::LiveOee;

use crate::report::{OrderChange, StateChange, StopCauses};

/// A machine mode entered or left (`[[state.modes]]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModeChange {
    /// When, ms since the epoch.
    pub at: u64,
    /// The mode's id.
    pub mode: String,
    /// Entered (`true`) or left.
    pub entered: bool,
}

/// How OEE is judged: the calendar, which modes are planned stops or
/// setups, the ideal cycle times, the stop lengths that matter.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OeeRules {
    /// The shift calendar.
    pub calendar: Calendar,
    /// Machine modes whose time is a planned stop (not planned
    /// production time).
    pub planned_stops: Vec<String>,
    /// Machine modes whose time is setup and adjustment.
    pub setup: Vec<String>,
    /// An `idle` stop shorter than this is a small stop, ms.
    pub small_stop_ms: u64,
    /// Rejects within this time of a start are start-up rejects, ms.
    pub startup_ms: u64,
    /// The ideal cycle time of an item not listed, ms per part.
    pub ideal_cycle_ms: u64,
    /// The ideal cycle time per item code, ms per part.
    pub items: BTreeMap<String, u64>,
}

impl OeeRules {
    /// The ideal cycle time of `item`, ms.
    pub fn ideal_cycle(&self, item: Option<&str>) -> u64 {
        item.and_then(|i| self.items.get(i))
            .copied()
            .unwrap_or(self.ideal_cycle_ms)
    }
}

/// What the figures are computed from, each sorted by time and holding
/// the last change before the period.
#[derive(Debug, Clone, Copy, Default)]
pub struct Facts<'a> {
    /// Machine-state history.
    pub changes: &'a [StateChange],
    /// Machine modes entered and left.
    pub modes: &'a [ModeChange],
    /// Parts made, `(time, count)`, rejects included.
    pub parts: &'a [(u64, u64)],
    /// Parts rejected, `(time, count)`.
    pub rejects: &'a [(u64, u64)],
    /// Work-order changes (the item in force).
    pub orders: &'a [OrderChange],
    /// The last time the machine went back to `running` before the first
    /// of `changes`, when the history was cut there (the live figures
    /// fold what they no longer keep): rejects soon after it are start-up
    /// rejects.
    pub earlier_start: Option<u64>,
}

/// Breakdown time of one stop cause.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Breakdown {
    /// The cause's code (paper 002's Table 4, `--` unmatched).
    pub code: String,
    /// Its name.
    pub name: String,
    /// Stops begun in the period.
    pub stops: u32,
    /// Their planned time within the period, ms.
    pub ms: u64,
}

/// The six big losses.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Losses {
    /// Fault time and long idle stops, ms.
    pub breakdowns_ms: u64,
    /// Time a setup mode held, ms.
    pub setup_ms: u64,
    /// Idle stops shorter than `small_stop`, ms.
    pub small_stops_ms: u64,
    /// Run time neither small stops nor the ideal time of the parts, ms.
    pub reduced_speed_ms: u64,
    /// Rejects soon after a start.
    pub startup_rejects: u64,
    /// Their ideal time, ms.
    pub startup_rejects_ms: u64,
    /// The other rejects.
    pub production_rejects: u64,
    /// Their ideal time, ms.
    pub production_rejects_ms: u64,
}

/// The figures of a period: the times and counts, and the ratios from
/// them (0-1; `None` when their denominator is zero).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Figures {
    /// Planned production time, ms.
    pub planned_ms: u64,
    /// Run time, ms.
    pub run_ms: u64,
    /// Time in breaks and planned stops, ms.
    pub not_planned_ms: u64,
    /// Time within the shifts the machine was not observed (`offline`),
    /// ms: in neither planned nor run time.
    pub unobserved_ms: u64,
    /// Σ ideal cycle × parts, ms.
    pub ideal_ms: u64,
    /// Parts made, rejects included.
    pub parts: u64,
    /// Parts rejected.
    pub rejects: u64,
    /// The six big losses.
    pub losses: Losses,
    /// Breakdowns by stop cause.
    pub breakdowns: Vec<Breakdown>,
    /// run ÷ planned.
    pub availability: Option<f64>,
    /// ideal ÷ run.
    pub performance: Option<f64>,
    /// good ÷ parts.
    pub quality: Option<f64>,
    /// availability × performance × quality.
    pub oee: Option<f64>,
}

impl Figures {
    /// Adds `other`'s times and counts and computes the ratios again.
    pub fn add(&mut self, other: &Figures) {
        self.planned_ms += other.planned_ms;
        self.run_ms += other.run_ms;
        self.not_planned_ms += other.not_planned_ms;
        self.unobserved_ms += other.unobserved_ms;
        self.ideal_ms += other.ideal_ms;
        self.parts += other.parts;
        self.rejects += other.rejects;
        let (l, o) = (&mut self.losses, &other.losses);
        l.breakdowns_ms += o.breakdowns_ms;
        l.setup_ms += o.setup_ms;
        l.small_stops_ms += o.small_stops_ms;
        l.reduced_speed_ms += o.reduced_speed_ms;
        l.startup_rejects += o.startup_rejects;
        l.startup_rejects_ms += o.startup_rejects_ms;
        l.production_rejects += o.production_rejects;
        l.production_rejects_ms += o.production_rejects_ms;
        for b in &other.breakdowns {
            match self.breakdowns.iter_mut().find(|x| x.code == b.code) {
                Some(x) => {
                    x.stops += b.stops;
                    x.ms += b.ms;
                }
                None => self.breakdowns.push(b.clone()),
            }
        }
        self.breakdowns.sort_by(|a, b| a.code.cmp(&b.code));
        self.ratios();
    }

    fn ratios(&mut self) {
        let share = |a: u64, b: u64| (b > 0).then(|| a as f64 / b as f64);
        self.availability = share(self.run_ms, self.planned_ms);
        self.performance = share(self.ideal_ms, self.run_ms);
        self.quality = share(self.parts.saturating_sub(self.rejects), self.parts);
        self.oee = match (self.availability, self.performance, self.quality) {
            (Some(a), Some(p), Some(q)) => Some(a * p * q),
            _ => None,
        };
    }
}

/// One shift's figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShiftFigures {
    /// The shift worked.
    pub shift: ShiftWindow,
    /// Its figures.
    pub figures: Figures,
}

/// One day's shifts (those starting in it) and their sum.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DayFigures {
    /// Start of the day, ms since the epoch.
    pub day_start: u64,
    /// Each shift.
    pub shifts: Vec<ShiftFigures>,
    /// The day.
    pub total: Figures,
}

/// A maximal stretch of one state (a restart repeating it is one).
#[derive(Debug, Clone, Copy)]
struct Run<'a> {
    from: u64,
    to: u64,
    state: &'a str,
    fault_type: Option<&'a str>,
}

impl Run<'_> {
    fn is_small_stop(&self, rules: &OeeRules) -> bool {
        self.state == "idle" && self.to - self.from < rules.small_stop_ms
    }
}

/// The state runs from the first change to `horizon`; `offline` after it.
fn runs(changes: &[StateChange], horizon: u64) -> Vec<Run<'_>> {
    let mut out: Vec<Run<'_>> = Vec::new();
    for (i, c) in changes.iter().enumerate() {
        let to = changes.get(i + 1).map_or(horizon, |n| n.at).min(horizon);
        if c.at >= to {
            continue;
        }
        match out.last_mut() {
            Some(r) if r.state == c.state && r.fault_type == c.fault_type.as_deref() => r.to = to,
            _ => out.push(Run {
                from: c.at,
                to,
                state: &c.state,
                fault_type: c.fault_type.as_deref(),
            }),
        }
    }
    out
}

/// The figures of `window` as far as `now`.
pub fn shift(
    rules: &OeeRules,
    causes: &StopCauses,
    facts: &Facts<'_>,
    window: &ShiftWindow,
    now: u64,
) -> Figures {
    let (start, horizon) = (window.start, window.end.min(now.max(window.start)));
    let runs = runs(facts.changes, horizon);
    let mut f = Figures::default();
    // Every instant where what counts may change.
    let mut cuts: BTreeSet<u64> = [start, horizon].into();
    let inside = |t: u64| t > start && t < horizon;
    cuts.extend(
        runs.iter()
            .flat_map(|r| [r.from, r.to])
            .filter(|&t| inside(t)),
    );
    cuts.extend(facts.modes.iter().map(|m| m.at).filter(|&t| inside(t)));
    cuts.extend(
        window
            .breaks
            .iter()
            .flat_map(|&(a, b)| [a, b])
            .filter(|&t| inside(t)),
    );
    let cuts: Vec<u64> = cuts.into_iter().collect();
    let mut active: BTreeSet<&str> = BTreeSet::new();
    let (mut next_mode, mut next_run) = (0, 0);
    let mut breakdowns: BTreeMap<String, Breakdown> = BTreeMap::new();
    for piece in cuts.windows(2) {
        let (a, b) = (piece[0], piece[1]);
        while let Some(m) = facts.modes.get(next_mode).filter(|m| m.at <= a) {
            if m.entered {
                active.insert(&m.mode);
            } else {
                active.remove(m.mode.as_str());
            }
            next_mode += 1;
        }
        while runs.get(next_run).is_some_and(|r| r.to <= a) {
            next_run += 1;
        }
        let run = runs.get(next_run).filter(|r| r.from <= a);
        let len = b - a;
        let holds = |modes: &[String]| modes.iter().any(|m| active.contains(m.as_str()));
        if window.in_break(a) || holds(&rules.planned_stops) {
            f.not_planned_ms += len;
            continue;
        }
        let Some(run) = run.filter(|r| r.state != "offline") else {
            f.unobserved_ms += len;
            continue;
        };
        f.planned_ms += len;
        if holds(&rules.setup) {
            f.losses.setup_ms += len;
        } else if run.state == "running" {
            f.run_ms += len;
        } else if run.is_small_stop(rules) {
            f.run_ms += len;
            f.losses.small_stops_ms += len;
        } else {
            f.losses.breakdowns_ms += len;
            let (code, name) = causes.classify(run.state, run.fault_type);
            let e = breakdowns.entry(code.clone()).or_insert(Breakdown {
                code,
                name,
                stops: 0,
                ms: 0,
            });
            e.ms += len;
            if run.from == a && run.from >= start {
                e.stops += 1;
            }
        }
    }
    f.breakdowns = breakdowns.into_values().collect();
    let within = |&&(at, _): &&(u64, u64)| at >= start && at < horizon;
    let item_at = |at: u64| {
        facts
            .orders
            .iter()
            .rev()
            .find(|o| o.at <= at)
            .and_then(|o| o.item.as_deref())
    };
    for &(at, n) in facts.parts.iter().filter(within) {
        f.parts += n;
        f.ideal_ms += n * rules.ideal_cycle(item_at(at));
    }
    // Starts: a run of `running` after any other state.
    let starts: Vec<u64> = facts
        .earlier_start
        .into_iter()
        .chain(
            runs.windows(2)
                .filter(|p| p[1].state == "running" && p[0].state != "running")
                .map(|p| p[1].from),
        )
        .collect();
    for &(at, n) in facts.rejects.iter().filter(within) {
        f.rejects += n;
        let priced = n * rules.ideal_cycle(item_at(at));
        let started = starts.iter().rev().find(|&&s| s <= at);
        if started.is_some_and(|&s| at - s < rules.startup_ms) {
            f.losses.startup_rejects += n;
            f.losses.startup_rejects_ms += priced;
        } else {
            f.losses.production_rejects += n;
            f.losses.production_rejects_ms += priced;
        }
    }
    f.losses.reduced_speed_ms = f
        .run_ms
        .saturating_sub(f.losses.small_stops_ms)
        .saturating_sub(f.ideal_ms);
    f.ratios();
    f
}

/// The figures of the shifts starting in `[day_start, day_start + 24 h)`
/// and of the day.
pub fn day(
    rules: &OeeRules,
    causes: &StopCauses,
    facts: &Facts<'_>,
    day_start: u64,
    now: u64,
) -> DayFigures {
    let shifts: Vec<ShiftFigures> = rules
        .calendar
        .windows(day_start, day_start + DAY_MS)
        .into_iter()
        .map(|w| ShiftFigures {
            figures: shift(rules, causes, facts, &w, now),
            shift: w,
        })
        .collect();
    let mut total = Figures::default();
    for s in &shifts {
        total.add(&s.figures);
    }
    DayFigures {
        day_start,
        shifts,
        total,
    }
}

#[cfg(test)]
mod tests;
