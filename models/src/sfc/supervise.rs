//! Step supervision: a step active longer than its supervision time is
//! stuck; its alarm names the chart and step, how long, and for every
//! transition leaving it the criteria analysis of what it waits for.
//!
//! The criteria analysis is the switching-function explanation applied to
//! what the transition needs (its source steps active and its condition,
//! eq. (1)/(2) of paper 004) with "off" as the fault: the operands that
//! keep it false, with their values, the values that would let it fire and
//! their comments. It is made when the step becomes stuck and again
//! whenever one of those operands changes while it is.

use std::collections::{BTreeSet, HashMap, HashSet};

use super::{Sfc, StepRef};
use crate::alarm::{Alarm, AlarmKind, Severity};
use crate::comments::CommentDb;
use crate::engine::{CheckSet, Declared, Finding};
use crate::explain::{explain_partial, Culprit, Polarity};
use crate::signal::Signal;
use crate::switching::SwitchingFunction;

/// The supervision of a cell's charts.
pub struct SfcChecks {
    id: String,
    sfc: Sfc,
    severity: Severity,
    comments: CommentDb,
    inputs: Vec<Signal>,
    /// Known values of the inputs.
    values: HashMap<Signal, bool>,
    /// Per step flag: its steps.
    by_flag: HashMap<Signal, Vec<StepRef>>,
    /// Per operand of a transition: the steps that transition leaves.
    readers: HashMap<Signal, Vec<StepRef>>,
    /// What each transition needs, compiled once, by (chart, index).
    needs: HashMap<(usize, usize), SwitchingFunction>,
    /// Active steps, since when (source time, ms).
    since: HashMap<StepRef, u64>,
    /// Supervised active steps by (deadline, step).
    deadlines: BTreeSet<(u64, StepRef)>,
    /// Steps whose stuck alarm is raised.
    stuck: HashSet<StepRef>,
}

impl SfcChecks {
    /// Supervises `sfc`; alarms are `<id>-<chart>-<step>`, culprits get
    /// their comments from `comments`.
    pub fn new(id: &str, sfc: Sfc, severity: Severity, comments: CommentDb) -> SfcChecks {
        let mut inputs = BTreeSet::new();
        let mut by_flag: HashMap<Signal, Vec<StepRef>> = HashMap::new();
        for (r, step) in sfc.steps() {
            by_flag.entry(step.flag.clone()).or_default().push(r);
            inputs.insert(step.flag.clone());
        }
        let mut readers: HashMap<Signal, Vec<StepRef>> = HashMap::new();
        let mut needs = HashMap::new();
        for (c, chart) in sfc.charts.iter().enumerate() {
            for (i, t) in chart.transitions.iter().enumerate() {
                let sf = needs_of(&sfc, c, i);
                for s in sf.leaves() {
                    inputs.insert(s.clone());
                    let r = readers.entry(s).or_default();
                    for &from in &t.from {
                        if !r.contains(&from) {
                            r.push(from);
                        }
                    }
                }
                needs.insert((c, i), sf);
            }
        }
        SfcChecks {
            id: id.to_string(),
            sfc,
            severity,
            comments,
            inputs: inputs.into_iter().collect(),
            values: HashMap::new(),
            by_flag,
            readers,
            needs,
            since: HashMap::new(),
            deadlines: BTreeSet::new(),
            stuck: HashSet::new(),
        }
    }

    /// The charts.
    pub fn sfc(&self) -> &Sfc {
        &self.sfc
    }

    /// The alarm id of step `r`.
    pub fn alarm_id(&self, r: StepRef) -> String {
        alarm_id(&self.id, &self.sfc, r)
    }

    /// The criteria analysis of transition `i` of chart `c` at the values
    /// known now: the operands keeping it from firing (empty when it may
    /// fire or an operand is unknown).
    pub fn criteria(&self, c: usize, i: usize) -> Vec<Culprit> {
        let Some(sf) = self.needs.get(&(c, i)) else {
            return Vec::new();
        };
        explain_partial(
            sf,
            |s| self.values.get(s).copied(),
            None,
            Polarity::Off,
            &self.comments,
        )
        .culprits
    }

    fn finding(&self, r: StepRef, active: bool, now: u64) -> Finding {
        let name = self.sfc.step_name(r);
        let step = self.sfc.step(r);
        let what = super::about(step.comment.as_deref());
        let lasted = self
            .since
            .get(&r)
            .map_or(0, |&since| now.saturating_sub(since));
        let mut finding = Finding {
            at: None,
            id: self.alarm_id(r),
            kind: AlarmKind::Step,
            severity: self.severity,
            fault_type: format!("STUCK {name}"),
            latched: false,
            active,
            fault_step: None,
            culprits: Vec::new(),
            message: format!("{name}{what} left"),
        };
        if !active {
            return finding;
        }
        let mut waits = Vec::new();
        let chart = &self.sfc.charts[r.chart];
        for (i, t) in chart.transitions.iter().enumerate() {
            if !t.from.contains(&r) {
                continue;
            }
            let culprits = self.criteria(r.chart, i);
            let about = super::about(t.comment.as_deref());
            let value = |s: &Signal| self.values.get(s).copied();
            waits.push(if !culprits.is_empty() {
                format!(
                    "{}{about} waits for {}",
                    t.id,
                    super::culprit_list(&culprits)
                )
            } else if self.needs[&(r.chart, i)].certain(value) == Some(true) {
                format!("{}{about} can fire", t.id)
            } else {
                format!("{}{about}: operands unknown", t.id)
            });
            for c in culprits {
                if !finding.culprits.iter().any(|k| k.address == c.address) {
                    finding.culprits.push(c);
                }
            }
        }
        let supervision = step.supervision_ms.unwrap_or(0);
        finding.message = format!(
            "{name}{what} stuck for {:.1} s (supervision {:.1} s): {}",
            lasted as f64 / 1000.0,
            supervision as f64 / 1000.0,
            if waits.is_empty() {
                "no transition leaves it".to_string()
            } else {
                waits.join("; ")
            }
        );
        finding
    }
}

/// The stuck alarm of step `r` in the supervision `id` of `sfc`:
/// `<id>-<chart>-<step>`.
pub fn alarm_id(id: &str, sfc: &Sfc, r: StepRef) -> String {
    format!("{id}-{}-{}", sfc.charts[r.chart].name, sfc.step(r).name)
}

/// What transition `i` of chart `c` needs to fire, compiled.
fn needs_of(sfc: &Sfc, c: usize, i: usize) -> SwitchingFunction {
    let t = &sfc.charts[c].transitions[i];
    SwitchingFunction::from_expr(
        Signal::new(&format!("{}.{}", sfc.charts[c].name, t.id)),
        &sfc.needs(t),
    )
}

impl CheckSet for SfcChecks {
    fn inputs(&self) -> Vec<Signal> {
        self.inputs.clone()
    }

    fn alarms(&self) -> Vec<Declared> {
        self.sfc
            .steps()
            .filter(|(_, s)| s.supervision_ms.is_some())
            .map(|(r, _)| Declared {
                id: self.alarm_id(r),
                kind: AlarmKind::Step,
                severity: self.severity,
                fault_type: format!("STUCK {}", self.sfc.step_name(r)),
                latched: false,
            })
            .collect()
    }

    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        before: Option<bool>,
        now: u64,
        out: &mut Vec<Finding>,
    ) {
        match value {
            Some(v) => self.values.insert(signal.clone(), v),
            None => self.values.remove(signal),
        };
        if let Some(steps) = self.by_flag.get(signal).cloned() {
            for r in steps {
                match value {
                    Some(true) if before != Some(true) => {
                        self.since.insert(r, now);
                        if let Some(sup) = self.sfc.step(r).supervision_ms {
                            self.deadlines.insert((now.saturating_add(sup), r));
                        }
                    }
                    Some(false) => {
                        if self.stuck.remove(&r) {
                            out.push(self.finding(r, false, now));
                        }
                        if let Some(since) = self.since.remove(&r) {
                            if let Some(sup) = self.sfc.step(r).supervision_ms {
                                self.deadlines.remove(&(since.saturating_add(sup), r));
                            }
                        }
                    }
                    // Unknown: the step's verdict holds until it is known.
                    _ => {}
                }
            }
        }
        // A stuck step's analysis follows its transitions' operands.
        if let Some(steps) = self.readers.get(signal) {
            for &r in steps {
                if self.stuck.contains(&r) {
                    out.push(self.finding(r, true, now));
                }
            }
        }
    }

    fn advance(&mut self, now: u64, out: &mut Vec<Finding>) {
        while let Some(&(deadline, r)) = self.deadlines.first() {
            if deadline > now {
                break;
            }
            self.deadlines.pop_first();
            let active = self.values.get(&self.sfc.step(r).flag) == Some(&true);
            if active && self.stuck.insert(r) {
                out.push(self.finding(r, true, now));
            }
        }
    }

    fn next_deadline(&self) -> Option<u64> {
        self.deadlines.first().map(|&(at, _)| at)
    }

    /// The step is taken as still stuck: its flag seen off clears the
    /// alarm.
    fn restored(&mut self, alarm: &Alarm) {
        let found = self
            .sfc
            .steps()
            .map(|(r, _)| r)
            .find(|&r| self.alarm_id(r) == alarm.id);
        if let Some(r) = found {
            self.stuck.insert(r);
        }
    }
}
