//! Whether a forced transition may be carried out (paper 004, eq. (3)/(4)).
//!
//! The force switch stands in for a stuck step being done, never for the
//! transition's condition: `Auto = (S1 · t2) + (ForceSW · t2)`. Before an
//! agent writes the force switch it checks, in this order, and stops at
//! the first that fails:
//!
//! 1. `transition`: the chart and transition exist;
//! 2. `forcible`: the cell's configuration declares it forcible (the PLC
//!    program has the extra term, `cellwatch sfc patch`);
//! 3. `stuck`: a step it leaves is the one a stuck-step alarm names, and
//!    that alarm is active;
//! 4. `condition`: its condition holds now, every operand known — if not,
//!    the operands that keep it false, with values, expected values and
//!    comments.
//!
//! The operator's signature and permission are the gate's, before these.

use super::{Sfc, StepRef};
use crate::comments::CommentDb;
use crate::explain::{explain_partial, Polarity};
use crate::signal::Signal;
use crate::switching::SwitchingFunction;

/// One check of a force request and how it came out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ForceCheck {
    /// Which check (`transition`, `forcible`, `stuck`, `condition`).
    pub name: &'static str,
    /// Whether it holds.
    pub passed: bool,
    /// What was found, for the operator and the journal.
    pub detail: String,
}

/// The outcome of the checks: every check made, in order (the last one
/// failed unless all passed), and the steps the forced transition leads
/// to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ForceVerdict {
    /// The checks made.
    pub checks: Vec<ForceCheck>,
    /// Where the transition leads (empty if it does not exist).
    pub targets: Vec<StepRef>,
}

impl ForceVerdict {
    /// Whether every check passed.
    pub fn allowed(&self) -> bool {
        self.checks.iter().all(|c| c.passed)
    }

    /// The failed check, if any.
    pub fn refusal(&self) -> Option<&ForceCheck> {
        self.checks.iter().find(|c| !c.passed)
    }
}

/// Checks a request to force `transition` of `chart`.
///
/// `forcible` says whether the configuration lets (chart, transition) be
/// forced; `stuck_alarm` gives the id of a step's stuck alarm and whether
/// it is active now; `value` the current value of a contact (`None`:
/// unknown, bad or never read).
pub fn check(
    sfc: &Sfc,
    chart: &str,
    transition: &str,
    forcible: impl Fn(&str, &str) -> bool,
    stuck_alarm: impl Fn(StepRef) -> (String, bool),
    value: impl Fn(&Signal) -> Option<bool>,
    comments: &CommentDb,
) -> ForceVerdict {
    let mut checks = Vec::new();
    let mut verdict = |name, passed, detail: String| {
        checks.push(ForceCheck {
            name,
            passed,
            detail,
        });
        passed
    };
    let Some((_, t)) = sfc.transition(chart, transition) else {
        let why = if sfc.chart(chart).is_none() {
            format!("no chart '{chart}'")
        } else {
            format!("chart {chart} has no transition '{transition}'")
        };
        verdict("transition", false, why);
        return ForceVerdict {
            checks,
            targets: Vec::new(),
        };
    };
    let name = format!("{chart}.{}", t.id);
    let targets = t.to.clone();
    let done = |checks| ForceVerdict {
        checks,
        targets: targets.clone(),
    };
    let to =
        t.to.iter()
            .map(|&r| sfc.step_name(r))
            .collect::<Vec<_>>()
            .join(" + ");
    let from = t
        .from
        .iter()
        .map(|&r| sfc.step_name(r))
        .collect::<Vec<_>>()
        .join(" + ");
    let condition = SwitchingFunction::from_expr(Signal::new(&name), &t.condition);
    verdict(
        "transition",
        true,
        format!("{name}: {from} -> {to} when {}", condition.notation()),
    );
    if !verdict(
        "forcible",
        forcible(chart, &t.id),
        if forcible(chart, &t.id) {
            format!("{name} is declared forcible")
        } else {
            format!("{name} is not declared forcible on this cell (checks.sfc forcible)")
        },
    ) {
        return done(checks);
    }
    let alarms: Vec<(StepRef, String, bool)> = t
        .from
        .iter()
        .map(|&r| {
            let (id, active) = stuck_alarm(r);
            (r, id, active)
        })
        .collect();
    let stuck = match alarms.iter().find(|(_, _, active)| *active) {
        Some((r, id, _)) => verdict(
            "stuck",
            true,
            format!("{} is stuck (alarm {id} active)", sfc.step_name(*r)),
        ),
        None => verdict(
            "stuck",
            false,
            format!(
                "no stuck-step alarm is active for {from} ({}): only a stuck step is forced on",
                alarms
                    .iter()
                    .map(|(_, id, _)| id.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ),
    };
    if !stuck {
        return done(checks);
    }
    let about = super::about(t.comment.as_deref());
    match condition.certain(&value) {
        Some(true) => verdict(
            "condition",
            true,
            format!("{}{about} holds: {}", t.id, condition.notation()),
        ),
        Some(false) => {
            let culprits =
                explain_partial(&condition, &value, None, Polarity::Off, comments).culprits;
            verdict(
                "condition",
                false,
                format!(
                    "{}{about} does not hold: {}",
                    t.id,
                    super::culprit_list(&culprits)
                ),
            )
        }
        None => {
            let unknown: Vec<String> = condition
                .leaves()
                .into_iter()
                .filter(|s| value(s).is_none())
                .map(|s| s.to_string())
                .collect();
            verdict(
                "condition",
                false,
                format!(
                    "{}{about} cannot be judged: {} unknown",
                    t.id,
                    unknown.join(", ")
                ),
            )
        }
    };
    done(checks)
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;

    use super::super::robot;

    fn run(
        sfc: &Sfc,
        chart: &str,
        t: &str,
        stuck: &[&str],
        on: &[&str],
        known: &[&str],
    ) -> ForceVerdict {
        let values: HashMap<Signal, bool> = known
            .iter()
            .map(|s| (Signal::new(s), on.contains(s)))
            .collect();
        let comments: CommentDb = [(
            Signal::new("%IX0.0.3"),
            "Shuttle waiting-position sensor".to_string(),
        )]
        .into_iter()
        .collect();
        check(
            sfc,
            chart,
            t,
            |c, t| [("F1", "t3"), ("F2", "t18")].contains(&(c, t)),
            |r| {
                let name = sfc.step_name(r);
                (
                    format!("sfc-{}", name.replace('.', "-")),
                    stuck.contains(&name.as_str()),
                )
            },
            |s| values.get(s).copied(),
            &comments,
        )
    }

    fn names(v: &ForceVerdict) -> Vec<(&str, bool)> {
        v.checks.iter().map(|c| (c.name, c.passed)).collect()
    }

    #[test]
    fn every_check_in_order_and_the_first_failure_ends_them() {
        let sfc = robot();
        let io = ["%IX0.0.3", "%IX0.2.2"];
        // Everything holds: t3 from a stuck S2 while the shuttle is there.
        let v = run(&sfc, "F1", "t3", &["F1.S2"], &["%IX0.0.3"], &io);
        assert!(v.allowed());
        assert_eq!(
            names(&v),
            [
                ("transition", true),
                ("forcible", true),
                ("stuck", true),
                ("condition", true)
            ]
        );
        let to: Vec<String> = v.targets.iter().map(|&r| sfc.step_name(r)).collect();
        assert_eq!(to, ["F2.S5", "F2.S8", "F2.S11"]);
        assert_eq!(
            v.checks[2].detail,
            "F1.S2 is stuck (alarm sfc-F1-S2 active)"
        );
        // The condition false: refused, naming the operand and its comment.
        let v = run(&sfc, "F1", "t3", &["F1.S2"], &[], &io);
        let r = v.refusal().unwrap();
        assert_eq!(r.name, "condition");
        assert_eq!(
            r.detail,
            "t3 (Shuttle at waiting position) does not hold: %IX0.0.3 = 0 (expected 1): Shuttle waiting-position sensor"
        );
        // Unknown operand: refused, never guessed.
        let v = run(&sfc, "F1", "t3", &["F1.S2"], &[], &[]);
        assert_eq!(v.refusal().unwrap().name, "condition");
        assert!(v.refusal().unwrap().detail.ends_with("%IX0.0.3 unknown"));
        // No stuck alarm for its source step.
        let v = run(&sfc, "F1", "t3", &["F2.S15"], &["%IX0.0.3"], &io);
        assert_eq!(
            names(&v),
            [("transition", true), ("forcible", true), ("stuck", false)]
        );
        assert!(v.checks[2].detail.contains("sfc-F1-S2"), "{v:?}");
        // Not declared forcible.
        let v = run(&sfc, "F1", "t2", &["F1.S1"], &["%IX0.0.2"], &io);
        assert_eq!(names(&v), [("transition", true), ("forcible", false)]);
        // Unknown transition and chart.
        let v = run(&sfc, "F1", "t99", &[], &[], &io);
        assert_eq!(
            v.refusal().unwrap().detail,
            "chart F1 has no transition 't99'"
        );
        let v = run(&sfc, "F9", "t3", &[], &[], &io);
        assert_eq!(v.refusal().unwrap().detail, "no chart 'F9'");
        // t18 back to F1's S0 from a stuck S15.
        let v = run(&sfc, "F2", "t18", &["F2.S15"], &["%IX0.2.2"], &io);
        assert!(v.allowed());
        assert_eq!(sfc.step_name(v.targets[0]), "F1.S0");
    }
}
