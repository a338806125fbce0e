//! The transition-timer learner and its model file.
//!
//! The *full-state* method is the paper's: the state is the vector of every
//! signal that changes in some run (constant ones dropped), and each event
//! `E` that takes state `A` to `B` after `Δt` in `A` is a transition
//! `δ(A, E | Δt) = B`. Transitions are grouped across runs and kept when
//! - every occurrence has `Δt ≥ Δmin` (shorter ones are the program
//!   flipping its own signals, not a physical motion),
//! - they are seen in at least `min_support` runs (default: every run),
//! - every training `Δt` fits inside the window `[Δt − τ, Δt + τ]` (one that
//!   does not is no timing invariant, an operator's loading time, say).
//!
//! τ is fixed, or learned per transition ([`Tau::Auto`]):
//! `τ = max(2 × the largest deviation of a training Δt from their mean,
//! 5 % of the mean, 100 ms)`: twice the spread seen, never tighter than the
//! jitter of a physical motion or of the PLC scan.

mod common;

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use super::log::RunLog;

pub use common::common;

/// The version of the model file format.
pub const MODEL_VERSION: u32 = 1;

/// How τ is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tau {
    /// The same τ for every transition, ms.
    Fixed(u64),
    /// Learned per transition from the training spread.
    Auto,
}

/// Learner settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LearnOptions {
    /// Δmin, ms.
    pub delta_min: u64,
    /// τ.
    pub tau: Tau,
    /// Runs a transition must be seen in; `None`: every run.
    pub min_support: Option<usize>,
}

/// An event: a signal's edge.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Event {
    /// The signal.
    pub tag: String,
    /// `rise` or `fall`.
    pub edge: SignalEdge,
}

/// Rising or falling edge.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SignalEdge {
    /// 0 → 1.
    Rise,
    /// 1 → 0.
    Fall,
}

/// One learned transition, as stored in the model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearnedTransition {
    /// Function number (`nnn` in `ERROR_ALARM_nnn`), from 1.
    pub id: u32,
    /// Start condition: literals `tag` / `-tag`.
    pub from: Vec<String>,
    /// The event.
    pub event: Event,
    /// The state after it.
    pub to: Vec<String>,
    /// Mean Δt over the training runs, ms.
    pub delta_ms: u64,
    /// Shortest training Δt.
    pub min_ms: u64,
    /// Longest training Δt.
    pub max_ms: u64,
    /// Runs it was seen in.
    pub support: usize,
    /// `[Δt − τ, Δt + τ]`, ms.
    pub window_ms: [u64; 2],
    /// The paper's numbering of the states, `2:-3`, when signals are numbered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_numbered: Option<String>,
    /// The event that starts the timer (`common` method); `None`: the
    /// timer starts when the `from` state is entered (`full-state`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trigger: Option<Event>,
}

/// The model file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimerModel {
    /// [`MODEL_VERSION`].
    pub version: u32,
    /// `full-state` or `common`.
    pub method: String,
    /// Every signal of the training runs, numbered from 1 in this order.
    pub signals: Vec<String>,
    /// The transitions kept.
    pub transitions: Vec<LearnedTransition>,
}

/// Why a candidate transition was not kept.
#[derive(Debug, Clone, PartialEq)]
pub enum DropReason {
    /// Some Δt below Δmin.
    TooShort {
        /// The shortest Δt.
        min_ms: u64,
    },
    /// Seen in too few runs.
    Support {
        /// Runs seen in.
        seen: usize,
        /// Runs required.
        required: usize,
    },
    /// No preceding event is always followed by it at a consistent delay
    /// (`common` method).
    NoTrigger,
    /// Training Δt spread wider than the window.
    NotInvariant {
        /// Shortest.
        min_ms: u64,
        /// Longest.
        max_ms: u64,
        /// The window.
        window: [u64; 2],
    },
}

impl fmt::Display for DropReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DropReason::TooShort { min_ms } => write!(f, "Δt {min_ms} ms < Δmin"),
            DropReason::Support { seen, required } => write!(f, "seen in {seen} of the {required} runs required"),
            DropReason::NoTrigger => write!(f, "no preceding event is always followed by it"),
            DropReason::NotInvariant { min_ms, max_ms, window } => write!(
                f,
                "not a timing invariant: training Δt {min_ms}..{max_ms} ms do not fit the window [{}, {}] ms",
                window[0], window[1]
            ),
        }
    }
}

/// A candidate that was dropped, for the summary.
#[derive(Debug, Clone, PartialEq)]
pub struct Dropped {
    /// `δ(A, E | Δt) = B` as text.
    pub transition: String,
    /// Why.
    pub reason: DropReason,
}

/// The learner's result.
#[derive(Debug, Clone, PartialEq)]
pub struct Learned {
    /// The model to save.
    pub model: TimerModel,
    /// What was dropped and why.
    pub dropped: Vec<Dropped>,
}

/// Writes a state as the paper does, `2:-3`, with 1-based signal numbers.
pub fn numbered(state: &[(usize, bool)]) -> String {
    state
        .iter()
        .map(|&(s, v)| {
            if v {
                format!("{}", s + 1)
            } else {
                format!("-{}", s + 1)
            }
        })
        .collect::<Vec<_>>()
        .join(":")
}

fn literals(state: &[(usize, bool)], names: &[String]) -> Vec<String> {
    state
        .iter()
        .map(|&(s, v)| {
            if v {
                names[s].clone()
            } else {
                format!("-{}", names[s])
            }
        })
        .collect()
}

/// The Δt statistics of a candidate and its window, or why it is dropped:
/// some Δt below Δmin, too few runs, or training Δt outside the window.
struct Timing {
    mean: u64,
    min: u64,
    max: u64,
    window: [u64; 2],
}

fn timing(
    dts: &[u64],
    seen: usize,
    required: usize,
    options: &LearnOptions,
) -> Result<Timing, DropReason> {
    let min = *dts.iter().min().unwrap_or(&0);
    let max = *dts.iter().max().unwrap_or(&0);
    let mean = dts.iter().sum::<u64>() / dts.len().max(1) as u64;
    let tau = match options.tau {
        Tau::Fixed(t) => t,
        Tau::Auto => auto_tau(dts, mean),
    };
    let window = [mean.saturating_sub(tau), mean + tau];
    if min < options.delta_min {
        Err(DropReason::TooShort { min_ms: min })
    } else if seen < required {
        Err(DropReason::Support { seen, required })
    } else if min < window[0] || max > window[1] {
        Err(DropReason::NotInvariant {
            min_ms: min,
            max_ms: max,
            window,
        })
    } else {
        Ok(Timing {
            mean,
            min,
            max,
            window,
        })
    }
}

/// Learns transition timers from `runs` with the paper's full-state method.
pub fn full_state(runs: &[RunLog], options: &LearnOptions) -> Learned {
    // One numbering of signals across runs, in order of first appearance.
    let mut names: Vec<String> = Vec::new();
    let index = |names: &mut Vec<String>, n: &str| match names.iter().position(|x| x == n) {
        Some(i) => i,
        None => {
            names.push(n.to_string());
            names.len() - 1
        }
    };
    let mapped: Vec<Vec<usize>> = runs
        .iter()
        .map(|r| r.signals.iter().map(|s| index(&mut names, s)).collect())
        .collect();
    // Signals that change in some run, or start differently in two runs.
    let mut changing = vec![false; names.len()];
    let mut first_initial: Vec<Option<bool>> = vec![None; names.len()];
    for (r, run) in runs.iter().enumerate() {
        for c in &run.changes {
            changing[mapped[r][c.signal]] = true;
        }
        for (local, &g) in mapped[r].iter().enumerate() {
            match first_initial[g] {
                None => first_initial[g] = Some(run.initial[local]),
                Some(v) if v != run.initial[local] => changing[g] = true,
                _ => {}
            }
        }
    }
    let state_signals: Vec<usize> = (0..names.len()).filter(|&s| changing[s]).collect();
    type Key = (Vec<(usize, bool)>, usize, bool, Vec<(usize, bool)>);
    let mut groups: BTreeMap<Key, Vec<(usize, u64)>> = BTreeMap::new();
    let mut order: Vec<Key> = Vec::new();
    for (r, run) in runs.iter().enumerate() {
        let mut value = vec![false; names.len()];
        for (local, &g) in mapped[r].iter().enumerate() {
            value[g] = run.initial[local];
        }
        let state = |value: &[bool]| -> Vec<(usize, bool)> {
            state_signals.iter().map(|&s| (s, value[s])).collect()
        };
        let mut entered = 0u64;
        for c in &run.changes {
            let g = mapped[r][c.signal];
            let from = state(&value);
            value[g] = c.value;
            let to = state(&value);
            let key = (from, g, c.value, to);
            let dt = c.at.saturating_sub(entered);
            entered = c.at;
            if !groups.contains_key(&key) {
                order.push(key.clone());
            }
            groups.entry(key).or_default().push((r, dt));
        }
    }
    let required = options.min_support.unwrap_or(runs.len()).max(1);
    let mut transitions = Vec::new();
    let mut dropped = Vec::new();
    for key in order {
        let occ = &groups[&key];
        let (from, signal, rise, to) = &key;
        let dts: Vec<u64> = occ.iter().map(|o| o.1).collect();
        let mut seen: Vec<usize> = occ.iter().map(|o| o.0).collect();
        seen.sort_unstable();
        seen.dedup();
        let edge = if *rise { "+" } else { "-" };
        let mean = dts.iter().sum::<u64>() / dts.len().max(1) as u64;
        let text = format!(
            "δ({}, {edge}{} | {mean}) = {}",
            numbered(from),
            signal + 1,
            numbered(to)
        );
        let Timing {
            mean,
            min,
            max,
            window,
        } = match timing(&dts, seen.len(), required, options) {
            Ok(t) => t,
            Err(reason) => {
                dropped.push(Dropped {
                    transition: text,
                    reason,
                });
                continue;
            }
        };
        transitions.push(LearnedTransition {
            id: transitions.len() as u32 + 1,
            from: literals(from, &names),
            event: Event {
                tag: names[*signal].clone(),
                edge: if *rise {
                    SignalEdge::Rise
                } else {
                    SignalEdge::Fall
                },
            },
            to: literals(to, &names),
            delta_ms: mean,
            min_ms: min,
            max_ms: max,
            support: seen.len(),
            window_ms: window,
            from_numbered: Some(numbered(from)),
            trigger: None,
        });
    }
    Learned {
        model: TimerModel {
            version: MODEL_VERSION,
            method: "full-state".into(),
            signals: names,
            transitions,
        },
        dropped,
    }
}

/// The documented τ rule of [`Tau::Auto`].
pub fn auto_tau(dts: &[u64], mean: u64) -> u64 {
    let spread = dts.iter().map(|&d| d.abs_diff(mean)).max().unwrap_or(0);
    (2 * spread).max(mean / 20).max(100)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timer::log::{parse_csv, parse_numeric};

    const MAP: &str = "1,S1\n2,S2\n3,S3\n";
    const TABLE1: &str = "t,e\n10,+2\n140,+3\n150,-3\n";

    fn table1() -> RunLog {
        parse_numeric("map.csv", MAP, "table1.csv", TABLE1).unwrap()
    }

    fn text(t: &LearnedTransition) -> String {
        let e = if t.event.edge == SignalEdge::Rise {
            "+"
        } else {
            "-"
        };
        let n = |tag: &str| 1 + ["S1", "S2", "S3"].iter().position(|s| *s == tag).unwrap();
        let state = |lits: &[String]| {
            lits.iter()
                .map(|l| match l.strip_prefix('-') {
                    Some(s) => format!("-{}", n(s)),
                    None => format!("{}", n(l)),
                })
                .collect::<Vec<_>>()
                .join(":")
        };
        format!(
            "δ({}, {e}{} | {}) = {}",
            state(&t.from),
            n(&t.event.tag),
            t.delta_ms,
            state(&t.to)
        )
    }

    #[test]
    fn paper_table1_with_delta_min_100_keeps_one_transition() {
        let l = full_state(
            &[table1()],
            &LearnOptions {
                delta_min: 100,
                tau: Tau::Fixed(10),
                min_support: None,
            },
        );
        let kept: Vec<String> = l.model.transitions.iter().map(text).collect();
        assert_eq!(kept, ["δ(2:-3, +3 | 130) = 2:3"]);
        assert_eq!(l.dropped.len(), 2);
        assert_eq!(l.dropped[0].transition, "δ(-2:-3, +2 | 10) = 2:-3");
        assert_eq!(l.dropped[0].reason.to_string(), "Δt 10 ms < Δmin");
    }

    #[test]
    fn paper_table1_with_delta_min_0_keeps_eqs_1_to_3() {
        let l = full_state(
            &[table1()],
            &LearnOptions {
                delta_min: 0,
                tau: Tau::Fixed(10),
                min_support: None,
            },
        );
        let kept: Vec<String> = l.model.transitions.iter().map(text).collect();
        assert_eq!(
            kept,
            [
                "δ(-2:-3, +2 | 10) = 2:-3",
                "δ(2:-3, +3 | 130) = 2:3",
                "δ(2:3, -3 | 10) = 2:-3"
            ]
        );
        let states: Vec<&str> = l
            .model
            .transitions
            .iter()
            .map(|t| t.from_numbered.as_deref().unwrap())
            .collect();
        assert_eq!(states, ["-2:-3", "2:-3", "2:3"]);
        assert_eq!(numbered(&[(1, true), (2, false)]), "2:-3");
        assert_eq!(l.model.transitions[1].window_ms, [120, 140]);
    }

    #[test]
    fn a_transition_seen_in_one_run_of_ten_is_dropped() {
        let normal = "time_ms,tag,value\n0,start,0\n0,done,0\n1000,start,1\n3000,done,1\n";
        let odd = "time_ms,tag,value\n0,start,0\n0,done,0\n0,extra,0\n1000,start,1\n3000,done,1\n6000,extra,1\n";
        let mut runs: Vec<RunLog> = (0..9)
            .map(|_| parse_csv("n.csv", normal).unwrap())
            .collect();
        runs.push(parse_csv("odd.csv", odd).unwrap());
        let l = full_state(
            &runs,
            &LearnOptions {
                delta_min: 500,
                tau: Tau::Fixed(100),
                min_support: None,
            },
        );
        assert!(
            l.dropped.iter().any(|d| d.reason
                == DropReason::Support {
                    seen: 1,
                    required: 10
                }),
            "{:?}",
            l.dropped
        );
        assert!(l.model.transitions.iter().all(|t| t.event.tag != "extra"));
    }

    #[test]
    fn auto_tau_rule() {
        // Spread 34 ms: the 5 % and 100 ms floors hold.
        assert_eq!(auto_tau(&[2000, 2040, 1980], 2006), 100);
        // 5 % of 9050 ms.
        assert_eq!(auto_tau(&[9000, 9100], 9050), 452);
        // Twice the 200 ms spread.
        assert_eq!(auto_tau(&[4000, 4400], 4200), 400);
    }
}
