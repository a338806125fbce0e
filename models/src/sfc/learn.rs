//! Step supervision times learned from normal runs, as the transition
//! timers are: each step's activations (its flag rising, then falling) in
//! the run logs give its durations, and its supervision time is the
//! longest of them plus a margin:
//!
//! `supervision = longest + max(longest / 2, 2 × (longest − shortest), 1 s)`,
//! rounded up to 100 ms.
//!
//! A stuck step stays active until someone repairs it, far beyond any
//! normal duration, so a generous margin costs little detection time and
//! keeps normal runs quiet: half the longest covers the runs the training
//! did not see, twice the spread covers a step whose time varies, and the
//! second covers scan and publishing jitter on short steps.
//!
//! A step is not learned (and says why) when it is never active and left
//! in a run, when it is seen in fewer runs than required, or when its
//! durations spread wider than their mean — such a step waits for an
//! operator or for the next machine, and its time is no invariant.
//! Activations under way when a run starts or ends are not counted.

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use super::{Sfc, StepRef};
use crate::timer::log::RunLog;

/// The version of the step-supervision file format.
pub const STEPS_VERSION: u32 = 1;

/// One step's learned supervision.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearnedStep {
    /// `F1.S2`.
    pub step: String,
    /// Stuck when active longer than this, ms.
    pub supervision_ms: u64,
    /// Shortest training duration, ms.
    pub min_ms: u64,
    /// Longest training duration, ms.
    pub max_ms: u64,
    /// Mean training duration, ms.
    pub mean_ms: u64,
    /// Activations counted.
    pub count: usize,
    /// Runs it was seen in.
    pub support: usize,
}

/// The step-supervision file `cellwatch learn --sfc` writes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepModel {
    /// [`STEPS_VERSION`].
    pub version: u32,
    /// Runs learned from.
    pub runs: usize,
    /// The steps learned, in chart order.
    pub steps: Vec<LearnedStep>,
}

/// A step not learned, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotLearned {
    /// `F1.S3`.
    pub step: String,
    /// Why, for people.
    pub reason: String,
}

/// What the learner found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepsLearned {
    /// The model to save.
    pub model: StepModel,
    /// The steps left without a learned time.
    pub not_learned: Vec<NotLearned>,
}

/// The supervision rule of this module, over training durations (ms).
pub fn supervision_of(durations: &[u64]) -> u64 {
    let longest = durations.iter().copied().max().unwrap_or(0);
    let shortest = durations.iter().copied().min().unwrap_or(0);
    let margin = (longest / 2).max(2 * (longest - shortest)).max(1_000);
    (longest + margin).div_ceil(100) * 100
}

/// Learns every step of `sfc` whose flag the runs record; a step must be
/// seen in `min_support` runs (`None`: every run).
pub fn learn(sfc: &Sfc, runs: &[RunLog], min_support: Option<usize>) -> StepsLearned {
    let required = min_support.unwrap_or(runs.len()).max(1);
    let mut steps = Vec::new();
    let mut not_learned = Vec::new();
    for (r, step) in sfc.steps() {
        let name = sfc.step_name(r);
        let flag = step.flag.name();
        let mut durations = Vec::new();
        let mut support = 0;
        let mut recorded = false;
        for run in runs {
            let Some(s) = run.signals.iter().position(|n| n == flag) else {
                continue;
            };
            recorded = true;
            let before = durations.len();
            // Active at the start: that activation's beginning is unknown.
            let mut rose: Option<u64> = None;
            for c in run.changes.iter().filter(|c| c.signal == s) {
                match (c.value, rose) {
                    (true, _) => rose = Some(c.at),
                    (false, Some(at)) => {
                        durations.push(c.at.saturating_sub(at));
                        rose = None;
                    }
                    (false, None) => {}
                }
            }
            if durations.len() > before {
                support += 1;
            }
        }
        let why = if !recorded {
            Some(format!("its flag {flag} is in none of the runs"))
        } else if durations.is_empty() {
            Some("never active and left in the runs".to_string())
        } else if support < required {
            Some(format!(
                "active and left in {support} of the {required} runs required"
            ))
        } else {
            let longest = durations.iter().copied().max().unwrap_or(0);
            let shortest = durations.iter().copied().min().unwrap_or(0);
            let mean = durations.iter().sum::<u64>() / durations.len() as u64;
            if longest - shortest > mean {
                Some(format!(
                    "durations {shortest}..{longest} ms spread wider than their mean {mean} ms: \
                     it waits for something else (an operator, the next machine); declare its supervision"
                ))
            } else {
                steps.push(LearnedStep {
                    step: name.clone(),
                    supervision_ms: supervision_of(&durations),
                    min_ms: shortest,
                    max_ms: longest,
                    mean_ms: mean,
                    count: durations.len(),
                    support,
                });
                None
            }
        };
        if let Some(reason) = why {
            not_learned.push(NotLearned { step: name, reason });
        }
    }
    StepsLearned {
        model: StepModel {
            version: STEPS_VERSION,
            runs: runs.len(),
            steps,
        },
        not_learned,
    }
}

impl StepModel {
    /// Gives every step of `sfc` without a declared supervision time its
    /// learned one (a declared time wins). The steps named by the model that
    /// `sfc` does not have, as errors.
    pub fn apply(&self, sfc: &mut Sfc) -> Result<(), Vec<String>> {
        if self.version != STEPS_VERSION {
            return Err(vec![format!(
                "step-supervision file version {} (this cellwatch reads {STEPS_VERSION})",
                self.version
            )]);
        }
        let refs: HashMap<String, StepRef> =
            sfc.steps().map(|(r, _)| (sfc.step_name(r), r)).collect();
        let mut errors = Vec::new();
        for learned in &self.steps {
            match refs.get(&learned.step) {
                Some(r) => {
                    let step = &mut sfc.charts[r.chart].steps[r.step];
                    if step.supervision_ms.is_none() {
                        step.supervision_ms = Some(learned.supervision_ms);
                    }
                }
                None => errors.push(format!("step {}: no such step in the charts", learned.step)),
            }
        }
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::Severity;
    use crate::engine::{CheckSet, Finding};
    use crate::sfc::plant::{record, Stuck};
    use crate::sfc::SfcChecks;
    use crate::signal::Signal;

    /// The robot's steps take 1.0 to 1.4 s each; the PLC scans every 20 ms.
    const DWELL: [u64; 2] = [1_000, 1_400];
    const SCAN: u64 = 20;
    const LENGTH: u64 = 60_000;

    /// Replays `run` through the supervision of `sfc` in virtual time: each
    /// alarm raised, with when (ms), in order.
    fn replay(sfc: &Sfc, run: &RunLog, length: u64) -> Vec<(u64, Finding)> {
        let mut checks = SfcChecks::new("sfc", sfc.clone(), Severity::High, Default::default());
        let mut current = run.initial.clone();
        let mut found = Vec::new();
        let mut raised: Vec<(u64, Finding)> = Vec::new();
        let mut note = |at: u64, found: &mut Vec<Finding>| {
            for f in found.drain(..) {
                if f.active && !raised.iter().any(|(_, r)| r.id == f.id) {
                    raised.push((at, f));
                }
            }
        };
        for (i, name) in run.signals.iter().enumerate() {
            checks.on_change(&Signal::new(name), Some(current[i]), None, 0, &mut found);
        }
        note(0, &mut found);
        // Changes as they come, the clock advanced every scan between them.
        let mut changes = run.changes.iter().peekable();
        for now in (0..=length).step_by(SCAN as usize) {
            while let Some(c) = changes.next_if(|c| c.at <= now) {
                checks.advance(c.at, &mut found);
                note(c.at, &mut found);
                let before = current[c.signal];
                current[c.signal] = c.value;
                checks.on_change(
                    &Signal::new(&run.signals[c.signal]),
                    Some(c.value),
                    Some(before),
                    c.at,
                    &mut found,
                );
                note(c.at, &mut found);
            }
            checks.advance(now, &mut found);
            note(now, &mut found);
        }
        raised
    }

    /// The robot charts with no declared supervision.
    fn bare() -> Sfc {
        let mut sfc = crate::sfc::robot();
        for c in &mut sfc.charts {
            for s in &mut c.steps {
                s.supervision_ms = None;
            }
        }
        sfc
    }

    #[test]
    fn the_rule_gives_half_the_longest_twice_the_spread_or_a_second() {
        assert_eq!(supervision_of(&[1_000, 1_400]), 2_400);
        assert_eq!(supervision_of(&[1_000, 4_000]), 10_000);
        assert_eq!(supervision_of(&[200, 210]), 1_300);
        assert_eq!(supervision_of(&[10_001]), 15_100);
    }

    #[test]
    fn learned_from_four_normal_runs_quiet_on_twenty_and_every_stuck_step_found() {
        let sfc = bare();
        let training: Vec<RunLog> = (1..=4)
            .map(|seed| record(&sfc, DWELL, seed, SCAN, LENGTH, None).0)
            .collect();
        let learned = learn(&sfc, &training, None);
        // The manual branch (S3) never runs in automatic runs.
        assert_eq!(
            learned.not_learned,
            [NotLearned {
                step: "F1.S3".into(),
                reason: "never active and left in the runs".into()
            }]
        );
        let names: Vec<&str> = learned
            .model
            .steps
            .iter()
            .map(|s| s.step.as_str())
            .collect();
        assert_eq!(
            names,
            [
                "F1.S0", "F1.S1", "F1.S2", "F2.S5", "F2.S8", "F2.S11", "F2.S6", "F2.S9", "F2.S12",
                "F2.S13", "F2.S14", "F2.S15"
            ]
        );
        for s in &learned.model.steps {
            // A step lasts about its dwell (a resync's branches leave
            // together, when the condition the plant sets for the first
            // branch done holds).
            assert!(s.max_ms <= DWELL[1] + 2 * SCAN, "{s:?}");
            assert_eq!(s.support, 4);
            assert_eq!(s.supervision_ms, supervision_of(&[s.min_ms, s.max_ms]));
        }
        let mut supervised = sfc.clone();
        learned.model.apply(&mut supervised).unwrap();

        // Twenty normal runs, other seeds: not one stuck alarm.
        for seed in 100..120 {
            let (run, _) = record(&sfc, DWELL, seed, SCAN, LENGTH, None);
            let raised = replay(&supervised, &run, LENGTH);
            assert!(raised.is_empty(), "seed {seed}: {:?}", raised[0].1.message);
        }

        // Every learned step stuck in turn: its alarm, and only its alarm
        // first, within its supervision time (and one scan).
        for (i, s) in learned.model.steps.iter().enumerate() {
            let (chart, step) = s.step.split_once('.').unwrap();
            let c = sfc.chart(chart).unwrap();
            let r = StepRef {
                chart: c,
                step: sfc.charts[c]
                    .steps
                    .iter()
                    .position(|x| x.name == step)
                    .unwrap(),
            };
            let stuck = Stuck {
                step: r,
                after_ms: 10_000,
            };
            let seed = 200 + i as u64;
            let (run, at) = record(&sfc, DWELL, seed, SCAN, LENGTH, Some(stuck));
            let at = at.unwrap_or_else(|| panic!("{} never active", s.step));
            let raised = replay(&supervised, &run, LENGTH);
            let id = format!("sfc-{chart}-{step}");
            let (when, _) = raised
                .iter()
                .find(|(_, f)| f.id == id)
                .unwrap_or_else(|| panic!("{} stuck at {at} ms not detected", s.step));
            assert!(
                *when <= at + s.supervision_ms + SCAN,
                "{}: stuck at {at} ms, alarm at {when} ms",
                s.step
            );
            // Nothing before the fault (after it, the other branches of a
            // parallel sequence wait at their convergence and may follow).
            for (w, f) in &raised {
                assert!(*w > at, "{} raised at {w} ms before the fault", f.id);
            }
        }
    }

    #[test]
    fn a_waiting_step_and_a_missing_flag_are_not_learned() {
        let sfc = bare();
        let mut run = record(&sfc, DWELL, 1, SCAN, 30_000, None).0;
        // F1.S0's flag renamed away: not recorded.
        let s0 = run.signals.iter().position(|s| s == "S0.X").unwrap();
        run.signals[s0] = "OTHER".into();
        let learned = learn(&sfc, &[run.clone()], None);
        assert!(learned.not_learned.contains(&NotLearned {
            step: "F1.S0".into(),
            reason: "its flag S0.X is in none of the runs".into()
        }));
        // A step whose time varies widely waits for something else.
        let (a, _) = record(&sfc, [1_000, 1_000], 1, SCAN, 30_000, None);
        let (b, _) = record(&sfc, [5_000, 5_000], 2, SCAN, 60_000, None);
        let learned = learn(&sfc, &[a.clone(), b], None);
        let s2 = learned
            .not_learned
            .iter()
            .find(|n| n.step == "F1.S2")
            .unwrap();
        assert!(
            s2.reason.contains("spread wider than their mean"),
            "{}",
            s2.reason
        );
        // Seen in one run of two: support.
        let (short, _) = record(&sfc, [1_000, 1_000], 3, SCAN, 1_500, None);
        let learned = learn(&sfc, &[a, short], None);
        let s2 = learned
            .not_learned
            .iter()
            .find(|n| n.step == "F1.S2")
            .unwrap();
        assert_eq!(s2.reason, "active and left in 1 of the 2 runs required");
        // A model naming a step the charts lack.
        let model = StepModel {
            version: STEPS_VERSION,
            runs: 1,
            steps: vec![LearnedStep {
                step: "F1.S9".into(),
                supervision_ms: 1_000,
                min_ms: 1,
                max_ms: 1,
                mean_ms: 1,
                count: 1,
                support: 1,
            }],
        };
        assert_eq!(
            model.apply(&mut bare()).unwrap_err(),
            ["step F1.S9: no such step in the charts"]
        );
    }
}
