//! A simple plant around running charts, for the simulated cell and for
//! run logs of it: a step that has been active for its dwell time makes
//! the condition of its first outgoing transition true (the shuttle
//! arrives, the arm finishes); every other input is off unless pinned.
//! Each activation of a step draws its dwell anew between the plant's
//! shortest and longest, so that runs vary as real ones do.
//!
//! Time is passed in (ms); nothing here reads a clock.

use std::collections::{BTreeSet, HashMap};

use super::run::{Fired, Runner};
use super::{Sfc, StepRef};
use crate::expr::Expr;
use crate::signal::Signal;
use crate::timer::line::Rng;
use crate::timer::log::{Change, RunLog};

/// The plant and the charts' runner.
#[derive(Debug, Clone)]
pub struct Plant {
    runner: Runner,
    /// Each active step: since when, and its dwell for this activation.
    active: HashMap<StepRef, (u64, u64)>,
    pinned: HashMap<Signal, bool>,
    dwell: [u64; 2],
    rng: Rng,
}

/// The inputs a scan read and the transitions that fired.
#[derive(Debug, Clone, Default)]
pub struct Scanned {
    /// Every input the plant drives now (pinned ones included).
    pub inputs: HashMap<Signal, bool>,
    /// What fired.
    pub fired: Vec<Fired>,
}

impl Plant {
    /// Every chart at its initial step; each step done after a dwell drawn
    /// in `[dwell[0], dwell[1]]` ms by a generator seeded with `seed`.
    pub fn new(sfc: &Sfc, dwell: [u64; 2], seed: u64) -> Plant {
        Plant {
            runner: Runner::new(sfc),
            active: HashMap::new(),
            pinned: HashMap::new(),
            dwell: [dwell[0], dwell[1].max(dwell[0])],
            rng: Rng::new(seed),
        }
    }

    /// The charts' runner (to put a step in error, or read active steps).
    pub fn runner(&self) -> &Runner {
        &self.runner
    }

    /// The charts' runner, to put a step in error.
    pub fn runner_mut(&mut self) -> &mut Runner {
        &mut self.runner
    }

    /// Holds input `s` at `value` (`None`: the plant drives it again).
    pub fn pin(&mut self, s: Signal, value: Option<bool>) {
        match value {
            Some(v) => self.pinned.insert(s, v),
            None => self.pinned.remove(&s),
        };
    }

    /// One PLC scan at `now` ms: the plant sets the inputs, then the charts
    /// run unless `stopped`, the force switch at `force`, `forcible` the
    /// transitions the program lets it move.
    pub fn scan(
        &mut self,
        sfc: &Sfc,
        now: u64,
        force: bool,
        stopped: bool,
        forcible: &dyn Fn(usize, &str) -> bool,
    ) -> Scanned {
        let mut inputs: HashMap<Signal, bool> = HashMap::new();
        for r in self.runner.active().collect::<Vec<_>>() {
            let (since, dwell) = match self.active.get(&r) {
                Some(&entry) => entry,
                None => {
                    let entry = (now, self.rng.between(self.dwell[0], self.dwell[1]));
                    self.active.insert(r, entry);
                    entry
                }
            };
            if now.saturating_sub(since) < dwell {
                continue;
            }
            if let Some(t) = sfc.leaving(r).next() {
                satisfy(&t.condition, false, &mut inputs);
            }
        }
        for (s, v) in &self.pinned {
            inputs.insert(s.clone(), *v);
        }
        let fired = if stopped {
            Vec::new()
        } else {
            let value = |s: &Signal| inputs.get(s).copied().unwrap_or(false);
            self.runner.scan(sfc, &value, force, forcible)
        };
        let runner = &self.runner;
        self.active.retain(|r, _| runner.is_active(*r));
        Scanned { inputs, fired }
    }
}

/// Every step flag and input the charts read, sorted.
pub fn signals(sfc: &Sfc) -> Vec<Signal> {
    let mut out = BTreeSet::new();
    for (_, step) in sfc.steps() {
        out.insert(step.flag.clone());
    }
    for chart in &sfc.charts {
        for t in &chart.transitions {
            out.extend(t.condition.signals());
        }
    }
    out.into_iter().collect()
}

/// The values the PLC shows after a scan: every input and step flag.
pub fn shown(sfc: &Sfc, plant: &Plant, scanned: &Scanned) -> Vec<(Signal, bool)> {
    let flags: HashMap<&Signal, bool> = sfc
        .steps()
        .map(|(r, s)| (&s.flag, plant.runner.is_active(r)))
        .collect();
    signals(sfc)
        .into_iter()
        .map(|s| {
            let v = match flags.get(&s) {
                Some(&v) => v,
                None => scanned.inputs.get(&s).copied().unwrap_or(false),
            };
            (s, v)
        })
        .collect()
}

/// A step put in error during a recorded run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stuck {
    /// The step.
    pub step: StepRef,
    /// It is put in error at its first activation at or after this, ms.
    pub after_ms: u64,
}

/// A run of the plant recorded as a run log (every step flag and input,
/// one scan every `scan_ms`, for `length_ms`), as `cellwatch learn` reads
/// them; with `stuck`, that step is put in error at its first activation
/// after the given time, and the time it became active is returned too.
pub fn record(
    sfc: &Sfc,
    dwell: [u64; 2],
    seed: u64,
    scan_ms: u64,
    length_ms: u64,
    stuck: Option<Stuck>,
) -> (RunLog, Option<u64>) {
    let mut plant = Plant::new(sfc, dwell, seed);
    let never = |_: usize, _: &str| false;
    let names = signals(sfc);
    let index: HashMap<&Signal, usize> = names.iter().enumerate().map(|(i, s)| (s, i)).collect();
    let mut log = RunLog {
        signals: names.iter().map(|s| s.name().to_string()).collect(),
        initial: vec![false; names.len()],
        changes: Vec::new(),
    };
    let mut current = Vec::new();
    let mut stuck_at = None;
    let mut now = 0;
    while now <= length_ms {
        let scanned = plant.scan(sfc, now, false, false, &never);
        if let Some(s) = stuck {
            if stuck_at.is_none() && now >= s.after_ms && plant.runner.is_active(s.step) {
                plant.runner.set_faulty(s.step, true);
                stuck_at = Some(plant.active.get(&s.step).map_or(now, |&(since, _)| since));
            }
        }
        let values = shown(sfc, &plant, &scanned);
        if now == 0 {
            for (s, v) in &values {
                log.initial[index[s]] = *v;
            }
            current = values;
        } else {
            for (i, (s, v)) in values.into_iter().enumerate() {
                if current[i].1 != v {
                    current[i].1 = v;
                    log.changes.push(Change {
                        at: now,
                        signal: index[&s],
                        value: v,
                    });
                }
            }
        }
        now += scan_ms;
    }
    (log, stuck_at)
}

/// Sets `inputs` so that `e` (negated when `negate`) holds: every literal of
/// a conjunction, the first branch of a disjunction.
fn satisfy(e: &Expr, negate: bool, inputs: &mut HashMap<Signal, bool>) {
    match (e, negate) {
        (Expr::Const(_), _) => {}
        (Expr::Lit(s, n), _) => {
            inputs.insert(s.clone(), !(*n ^ negate));
        }
        (Expr::Not(inner), _) => satisfy(inner, !negate, inputs),
        (Expr::And(es), false) | (Expr::Or(es), true) => {
            for e in es {
                satisfy(e, negate, inputs);
            }
        }
        (Expr::And(es), true) | (Expr::Or(es), false) => {
            if let Some(e) = es.first() {
                satisfy(e, negate, inputs);
            }
        }
    }
}
