//! The `common` learner ([`common`]): each event a transition of its own,
//! timed from its trigger (the preceding event whose delay to it varies
//! least), with a start condition of the literals that hold from trigger
//! to event in every occurrence and not by chance. For stations that run
//! in parallel, where the paper's full-state method breaks. The model's
//! types and the timing rules both methods share are `mod.rs`'s.

use std::collections::BTreeMap;

use super::{
    literals, timing, DropReason, Dropped, Event, LearnOptions, Learned, LearnedTransition,
    SignalEdge, TimerModel, Timing, MODEL_VERSION,
};
use crate::timer::log::RunLog;

/// Every run's changes on one numbering of signals.
struct Aligned {
    names: Vec<String>,
    /// Per run: initial values, by global signal.
    initial: Vec<Vec<bool>>,
    /// Per run: (time, signal, value).
    changes: Vec<Vec<(u64, usize, bool)>>,
    /// Signals that change in some run.
    changing: Vec<bool>,
}

fn align(runs: &[RunLog]) -> Aligned {
    let mut names: Vec<String> = Vec::new();
    let mut mapped = Vec::new();
    for r in runs {
        mapped.push(
            r.signals
                .iter()
                .map(|s| match names.iter().position(|x| x == s) {
                    Some(i) => i,
                    None => {
                        names.push(s.clone());
                        names.len() - 1
                    }
                })
                .collect::<Vec<usize>>(),
        );
    }
    let mut changing = vec![false; names.len()];
    let mut initial = Vec::new();
    let mut changes = Vec::new();
    for (r, run) in runs.iter().enumerate() {
        let mut init = vec![false; names.len()];
        for (l, &g) in mapped[r].iter().enumerate() {
            init[g] = run.initial[l];
        }
        initial.push(init);
        changes.push(
            run.changes
                .iter()
                .map(|c| (c.at, mapped[r][c.signal], c.value))
                .collect::<Vec<_>>(),
        );
        for c in &run.changes {
            changing[mapped[r][c.signal]] = true;
        }
    }
    Aligned {
        names,
        initial,
        changes,
        changing,
    }
}

/// A candidate trigger of an event and its delays: (run, trigger time,
/// event time) per occurrence.
struct Candidate {
    trigger: (usize, bool),
    delays: Vec<(usize, u64, u64)>,
    spread: u64,
    mean: u64,
}

/// How far back a trigger may be, ms.
const HORIZON_MS: u64 = 120_000;

/// Learns transition timers with the `common` method.
///
/// The paper's full-state method breaks when stations run in parallel:
/// another station's events change the state, so one physical motion shows
/// up under many states with meaningless Δt. Here each event `E` (a signal
/// edge) is one transition, timed from its *trigger*: among the events that
/// precede every occurrence of `E` (after its previous occurrence, within
/// two minutes) and are always followed by `E` before they happen again,
/// the one whose delay to `E` varies least (ties: the nearest). The start
/// condition keeps only the literals that are stable from the trigger to
/// `E` in every occurrence and have the same value in all of them, and
/// that are not there by chance: a literal whose value holds a share `p`
/// of the training time is kept only if `p^n < 0.001` over the `n`
/// occurrences (another station's idle sensor is 0 nearly always, so it
/// is 0 at every occurrence by chance). Signals that never change are left
/// out. Δmin, support and the window-fit rule
/// then apply as in [`full_state`](super::full_state).
pub fn common(runs: &[RunLog], options: &LearnOptions) -> Learned {
    let a = align(runs);
    let occ = occurrences(&a, runs.len());
    let share = time_shares(&a);
    let required = options.min_support.unwrap_or(runs.len()).max(1);
    let mut transitions = Vec::new();
    let mut dropped = Vec::new();
    let describe = |s: usize, v: bool| format!("{}{}", if v { "+" } else { "-" }, a.names[s]);
    for (&(es, ev), e_runs) in &occ {
        let seen = e_runs.iter().filter(|o| !o.is_empty()).count();
        let Some(Candidate {
            trigger: (ts, tv),
            delays,
            mean,
            ..
        }) = best_trigger(&occ, (es, ev), e_runs)
        else {
            if seen >= required {
                dropped.push(Dropped {
                    transition: describe(es, ev),
                    reason: DropReason::NoTrigger,
                });
            }
            continue;
        };
        let ds: Vec<u64> = delays.iter().map(|d| d.2 - d.1).collect();
        let text = format!("δ({} → {} | {mean})", describe(ts, tv), describe(es, ev));
        let Timing {
            mean,
            min,
            max,
            window,
        } = match timing(&ds, seen, required, options) {
            Ok(t) => t,
            Err(reason) => {
                dropped.push(Dropped {
                    transition: text,
                    reason,
                });
                continue;
            }
        };
        let from = start_condition(&a, &share, &delays, (es, ev), (ts, tv));
        let to: Vec<(usize, bool)> = from
            .iter()
            .map(|&(s, v)| if s == es { (s, ev) } else { (s, v) })
            .collect();
        transitions.push(LearnedTransition {
            id: transitions.len() as u32 + 1,
            from: literals(&from, &a.names),
            event: Event {
                tag: a.names[es].clone(),
                edge: if ev {
                    SignalEdge::Rise
                } else {
                    SignalEdge::Fall
                },
            },
            to: literals(&to, &a.names),
            delta_ms: mean,
            min_ms: min,
            max_ms: max,
            support: seen,
            window_ms: window,
            from_numbered: None,
            trigger: Some(Event {
                tag: a.names[ts].clone(),
                edge: if tv {
                    SignalEdge::Rise
                } else {
                    SignalEdge::Fall
                },
            }),
        });
    }
    Learned {
        model: TimerModel {
            version: MODEL_VERSION,
            method: "common".into(),
            signals: a.names,
            transitions,
        },
        dropped,
    }
}

/// Occurrence times of each event type (signal, value), per run, in time
/// order.
type Occurrences = BTreeMap<(usize, bool), Vec<Vec<u64>>>;

/// Stage 1: when each event type happens in each run.
fn occurrences(a: &Aligned, runs: usize) -> Occurrences {
    let mut occ: Occurrences = BTreeMap::new();
    for (r, ch) in a.changes.iter().enumerate() {
        for &(t, s, v) in ch {
            occ.entry((s, v)).or_insert_with(|| vec![Vec::new(); runs])[r].push(t);
        }
    }
    occ
}

/// Stage 2: the share of the training time each signal is 1.
fn time_shares(a: &Aligned) -> Vec<f64> {
    let n = a.names.len();
    let mut high = vec![0u64; n];
    let mut total = 0u64;
    for (r, ch) in a.changes.iter().enumerate() {
        let mut value = a.initial[r].clone();
        let mut t = 0;
        for &(at, s, v) in ch {
            for (sig, h) in high.iter_mut().enumerate() {
                if value[sig] {
                    *h += at.saturating_sub(t);
                }
            }
            total += at.saturating_sub(t);
            t = at;
            value[s] = v;
        }
    }
    high.iter()
        .map(|&h| {
            if total == 0 {
                0.5
            } else {
                h as f64 / total as f64
            }
        })
        .collect()
}

/// Stage 3: the trigger of event `e` whose delay to it varies least (ties:
/// the nearest), among the events that precede every occurrence of `e` and
/// are always followed by it.
fn best_trigger(occ: &Occurrences, e: (usize, bool), e_runs: &[Vec<u64>]) -> Option<Candidate> {
    let mut best: Option<Candidate> = None;
    for (&trigger, t_runs) in occ {
        if trigger == e {
            continue;
        }
        let Some(delays) = trigger_delays(e_runs, t_runs) else {
            continue;
        };
        let ds: Vec<u64> = delays.iter().map(|d| d.2 - d.1).collect();
        let spread = ds.iter().max().unwrap_or(&0) - ds.iter().min().unwrap_or(&0);
        let mean = ds.iter().sum::<u64>() / ds.len() as u64;
        let better = match &best {
            None => true,
            Some(b) => spread < b.spread || (spread == b.spread && mean < b.mean),
        };
        if better {
            best = Some(Candidate {
                trigger,
                delays,
                spread,
                mean,
            });
        }
    }
    best
}

/// The delays `(run, t_trigger, t_event)` from a candidate trigger to every
/// occurrence of the event, or `None` if it is no trigger: some occurrence
/// has no trigger before it (within the horizon, after the previous
/// occurrence), or some trigger is not followed by the event before the
/// next trigger.
fn trigger_delays(e_runs: &[Vec<u64>], t_runs: &[Vec<u64>]) -> Option<Vec<(usize, u64, u64)>> {
    let mut delays = Vec::new();
    for (r, e_times) in e_runs.iter().enumerate() {
        let t_times = &t_runs[r];
        let mut prev_e = 0;
        for &te in e_times {
            let lo = prev_e.max(te.saturating_sub(HORIZON_MS));
            let last = t_times
                .iter()
                .rev()
                .find(|&&tt| tt < te && tt >= lo && tt > prev_e);
            match last {
                Some(&tt) if tt > prev_e || prev_e == 0 => delays.push((r, tt, te)),
                _ => return None,
            }
            prev_e = te;
        }
        for (i, &tt) in t_times.iter().enumerate() {
            let next_t = t_times.get(i + 1).copied().unwrap_or(u64::MAX);
            let next_e = e_times.iter().find(|&&te| te > tt).copied();
            match next_e {
                Some(te) if te < next_t && te - tt <= HORIZON_MS => {}
                // A trigger at the very end of a run may have no E yet.
                None if i + 1 == t_times.len() => {}
                _ => return None,
            }
        }
    }
    (!delays.is_empty()).then_some(delays)
}

/// Stage 4: the start condition: literals stable from the trigger to the
/// event in every occurrence, with the same value in all, and not there by
/// chance (`p^n < 0.001`, `p` the share of training time the literal holds).
fn start_condition(
    a: &Aligned,
    share: &[f64],
    delays: &[(usize, u64, u64)],
    (es, _ev): (usize, bool),
    (ts, tv): (usize, bool),
) -> Vec<(usize, bool)> {
    let n = a.names.len();
    let mut stable: Vec<Option<bool>> = vec![None; n];
    let mut excluded = vec![false; n];
    for &(r, tt, te) in delays {
        let mut value = a.initial[r].clone();
        let mut changed = vec![false; n];
        for &(t, s, v) in &a.changes[r] {
            if t > te || (t == te && s == es) {
                break;
            }
            if t < tt || (t == tt && s == ts && v == tv) {
                value[s] = v;
            } else if t < te || (t == tt) {
                changed[s] = true;
            }
        }
        for s in 0..n {
            if changed[s] || !a.changing[s] {
                excluded[s] = true;
            } else {
                match stable[s] {
                    None => stable[s] = Some(value[s]),
                    Some(v) if v != value[s] => excluded[s] = true,
                    _ => {}
                }
            }
        }
    }
    // A literal that holds most of the time would hold in every occurrence
    // by chance (another station's idle sensor): keep only those whose
    // chance of that, p^n, is below 0.1 %.
    let occurrences = i32::try_from(delays.len()).unwrap_or(i32::MAX);
    (0..n)
        .filter(|&s| !excluded[s])
        .filter_map(|s| stable[s].map(|v| (s, v)))
        .filter(|&(s, v)| {
            let p = if v { share[s] } else { 1.0 - share[s] };
            p.powi(occurrences) < 1e-3
        })
        .collect()
}
