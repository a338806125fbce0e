//! Charts run as a PLC runs them, one scan at a time: the simulated cell's
//! side of paper 004, and the reference the equations are tested on.
//!
//! A transition fires when every step it leaves is active and *done* and
//! its condition holds (eq. (1)/(2): `Auto = S1 · t2`). A step in error is
//! active but not done: the chart stays there (stuck), whatever the
//! transitions leaving it see. A forcible transition also fires with the
//! force switch on while its condition holds and the chart is at its source
//! steps (eq. (3)/(4): `Auto = (S1 · t2) + (ForceSW · t2)`): the force
//! switch stands in for the step being done, never for the condition.
//!
//! In one scan every transition is judged on the state before the scan and
//! those that fire fire together; of several leaving one step (a selection
//! divergence) the first written wins, as IEC 61131-3 has it by default.

use std::collections::{BTreeSet, HashSet};

use super::{Sfc, StepRef};
use crate::signal::Signal;

/// The state of running charts.
#[derive(Debug, Clone, Default)]
pub struct Runner {
    active: BTreeSet<StepRef>,
    faulty: HashSet<StepRef>,
}

/// A transition that fired, and whether by force.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fired {
    /// Its chart.
    pub chart: usize,
    /// Its id.
    pub id: String,
    /// Fired by the force switch (its source step not done).
    pub forced: bool,
}

impl Runner {
    /// Every chart at its initial step.
    pub fn new(sfc: &Sfc) -> Runner {
        Runner {
            active: sfc
                .charts
                .iter()
                .enumerate()
                .filter_map(|(chart, c)| c.initial.map(|step| StepRef { chart, step }))
                .collect(),
            faulty: HashSet::new(),
        }
    }

    /// The active steps.
    pub fn active(&self) -> impl Iterator<Item = StepRef> + '_ {
        self.active.iter().copied()
    }

    /// Whether step `r` is active (its flag).
    pub fn is_active(&self, r: StepRef) -> bool {
        self.active.contains(&r)
    }

    /// Puts step `r` in error (`true`: it never gets done) or out of it.
    pub fn set_faulty(&mut self, r: StepRef, faulty: bool) {
        if faulty {
            self.faulty.insert(r);
        } else {
            self.faulty.remove(&r);
        }
    }

    /// One scan at the inputs `value`, with the force switch `force`;
    /// `forcible` says which transitions (chart, id) the program lets the
    /// force switch move. The transitions that fired.
    pub fn scan(
        &mut self,
        sfc: &Sfc,
        value: &dyn Fn(&Signal) -> bool,
        force: bool,
        forcible: &dyn Fn(usize, &str) -> bool,
    ) -> Vec<Fired> {
        let mut fired = Vec::new();
        let mut taken: HashSet<StepRef> = HashSet::new();
        for (c, chart) in sfc.charts.iter().enumerate() {
            for t in &chart.transitions {
                let at_source =
                    !t.from.is_empty() && t.from.iter().all(|r| self.active.contains(r));
                // A step already left by an earlier transition of this scan
                // (selection: the first written wins).
                if !at_source || t.from.iter().any(|r| taken.contains(r)) {
                    continue;
                }
                let condition = t.condition.eval(&|s| value(s));
                if !condition {
                    continue;
                }
                let done = t.from.iter().all(|r| !self.faulty.contains(r));
                let forced = !done && force && forcible(c, &t.id);
                if done || forced {
                    taken.extend(t.from.iter().copied());
                    fired.push((c, t, forced));
                }
            }
        }
        for (_, t, _) in &fired {
            for r in &t.from {
                self.active.remove(r);
                self.faulty.remove(r);
            }
        }
        for (_, t, _) in &fired {
            self.active.extend(t.to.iter().copied());
        }
        fired
            .into_iter()
            .map(|(chart, t, forced)| Fired {
                chart,
                id: t.id.clone(),
                forced,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Paper 004, Fig. 1: from S1, t2 to the automatic branch (S2), t3 to
    /// the manual one (S3); both lead on to S4.
    const FIG1: &str = r#"
[[chart]]
name = "F1"
initial = "S1"
[[chart.step]]
name = "S1"
flag = "S1.X"
[[chart.step]]
name = "S2"
flag = "S2.X"
comment = "Auto"
[[chart.step]]
name = "S3"
flag = "S3.X"
comment = "Manual"
[[chart.step]]
name = "S4"
flag = "S4.X"
[[chart.transition]]
id = "t2"
from = "S1"
to = "S2"
condition = "T2"
[[chart.transition]]
id = "t3"
from = "S1"
to = "S3"
condition = "T3"
[[chart.transition]]
id = "t4"
from = "S2"
to = "S4"
condition = "T4"
[[chart.transition]]
id = "t5"
from = "S3"
to = "S4"
condition = "T5"
"#;

    fn fig1() -> Sfc {
        super::super::text::parse("fig1.sfc.toml", FIG1, &|_| true).unwrap()
    }

    fn inputs(on: &'static [&'static str]) -> impl Fn(&Signal) -> bool {
        move |s: &Signal| on.contains(&s.name())
    }

    fn names(sfc: &Sfc, r: &Runner) -> Vec<String> {
        r.active().map(|s| sfc.step_name(s)).collect()
    }

    #[test]
    fn equations_1_to_4_of_paper_004() {
        let sfc = fig1();
        let all = |_: usize, _: &str| true;
        let s1 = StepRef { chart: 0, step: 0 };
        // Eq. (1): S1 done and t2: the automatic branch.
        let mut r = Runner::new(&sfc);
        let fired = r.scan(&sfc, &inputs(&["T2"]), false, &all);
        assert_eq!(fired[0].id, "t2");
        assert_eq!(names(&sfc, &r), ["F1.S2"]);
        // Eq. (2): t3, the manual one.
        let mut r = Runner::new(&sfc);
        r.scan(&sfc, &inputs(&["T3"]), false, &all);
        assert_eq!(names(&sfc, &r), ["F1.S3"]);
        // S1 stuck: t2 alone never moves it.
        let mut r = Runner::new(&sfc);
        r.set_faulty(s1, true);
        for _ in 0..5 {
            assert!(r.scan(&sfc, &inputs(&["T2"]), false, &all).is_empty());
        }
        assert_eq!(names(&sfc, &r), ["F1.S1"]);
        // The force switch without t2 moves nothing ...
        assert!(r.scan(&sfc, &inputs(&[]), true, &all).is_empty());
        assert_eq!(names(&sfc, &r), ["F1.S1"]);
        // ... nor for a transition the program does not let it force ...
        let only_t3 = |_: usize, id: &str| id == "t3";
        assert!(r.scan(&sfc, &inputs(&["T2"]), true, &only_t3).is_empty());
        // ... eq. (3): with t2 it moves the chart to the automatic branch.
        let fired = r.scan(&sfc, &inputs(&["T2"]), true, &all);
        assert_eq!(
            fired,
            [Fired {
                chart: 0,
                id: "t2".into(),
                forced: true
            }]
        );
        assert_eq!(names(&sfc, &r), ["F1.S2"]);
        // Eq. (4) likewise for the manual branch.
        let mut r = Runner::new(&sfc);
        r.set_faulty(s1, true);
        r.scan(&sfc, &inputs(&["T3"]), true, &all);
        assert_eq!(names(&sfc, &r), ["F1.S3"]);
        // Both conditions: the first written wins.
        let mut r = Runner::new(&sfc);
        r.scan(&sfc, &inputs(&["T2", "T3"]), false, &all);
        assert_eq!(names(&sfc, &r), ["F1.S2"]);
    }

    #[test]
    fn the_robot_syncs_resyncs_and_jumps() {
        let sfc = super::super::robot();
        let none = |_: usize, _: &str| false;
        let mut r = Runner::new(&sfc);
        assert_eq!(names(&sfc, &r), ["F1.S0"]);
        for (on, expect) in [
            (&["%IX0.0.1"][..], &["F1.S1"][..]),
            (&["%IX0.0.2"], &["F1.S2"]),
            (&["%IX0.0.3"], &["F2.S5", "F2.S8", "F2.S11"]),
            (&["%IX0.1.0", "%IX0.1.1"], &["F2.S11", "F2.S6", "F2.S9"]),
            // Resync waits for all three.
            (&["%IX0.1.3"], &["F2.S11", "F2.S6", "F2.S9"]),
            (&["%IX0.1.2"], &["F2.S6", "F2.S9", "F2.S12"]),
            (&["%IX0.1.3"], &["F2.S13"]),
            (&["%IX0.1.4"], &["F2.S14"]),
            (&["%IX0.2.1"], &["F2.S15"]),
            (&["%IX0.2.2"], &["F1.S0"]),
        ] {
            let on: Vec<&str> = on.to_vec();
            r.scan(&sfc, &|s: &Signal| on.contains(&s.name()), false, &none);
            let mut got = names(&sfc, &r);
            let mut want: Vec<String> = expect.iter().map(|s| s.to_string()).collect();
            got.sort();
            want.sort();
            assert_eq!(got, want, "after {on:?}");
        }
    }
}
