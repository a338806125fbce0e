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
//!
//! An operand is named as the explanation names culprits: a contact as
//! `bDoorOpen = 1 (expected 0): Door open`, a comparison by the variable it
//! compares, its number and what it needs,
//! `rSpindleSpeed = 1650.0 (needs >= 1800): Spindle speed`, an instance's
//! output (`T1.Q`, `fbClamp.Done`) by itself with the instance's comment
//! when it has none of its own. The numbers are those known when the
//! analysis is made: a number that moves without changing what the
//! comparison says makes no new analysis.
//!
//! A stuck step raised while a cause is active is that cause's consequence
//! when, with the signals the cause's fault holds taken back to their
//! values without it, what the step waits for would be there: a
//! transition leaving it could fire, or an output the program drives from
//! the step's flag ([`SfcChecks::driving`]: the valve that makes the motion
//! the step waits for) would be at another value (the cause took the
//! step's command back). The step's own contacts at fault with its outputs
//! as commanded keep it a first-out.

use std::collections::{BTreeSet, HashMap, HashSet};

use super::{Sfc, StepRef};
use crate::alarm::{Alarm, AlarmKind, Severity};
use crate::comments::CommentDb;
use crate::engine::checks::read_with_compared;
use crate::engine::{CheckSet, Declared, Finding};
use crate::explain::{comment_of, explain_partial, read_comparisons, Culprit, Polarity};
use crate::program::Program;
use crate::signal::{Observability, Signal};
use crate::switching::SwitchingFunction;
use crate::value::{CmpOperand, Comparison, Num};

/// The supervision of a cell's charts.
pub struct SfcChecks {
    id: String,
    sfc: Sfc,
    severity: Severity,
    comments: CommentDb,
    inputs: Vec<Signal>,
    /// Known values of the inputs.
    values: HashMap<Signal, bool>,
    /// The variables the comparison operands compare.
    compared: Vec<Signal>,
    /// Their numbers now.
    numbers: HashMap<Signal, Num>,
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
    /// Per step: the outputs the program drives from its flag.
    drives: HashMap<StepRef, Vec<Signal>>,
}

impl SfcChecks {
    /// Supervises `sfc`; alarms are `<id>-<chart>-<step>`, culprits get
    /// their comments from `comments`, else from the chart file's
    /// variables.
    pub fn new(id: &str, sfc: Sfc, severity: Severity, comments: CommentDb) -> SfcChecks {
        let comments = sfc.variables.clone().overridden_by(comments);
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
        let mut compared: Vec<Signal> = inputs
            .iter()
            .filter_map(Comparison::of_signal)
            .flat_map(|c| match c.rhs {
                CmpOperand::Tag(t) => vec![c.lhs, t],
                CmpOperand::Const(_) => vec![c.lhs],
            })
            .collect();
        compared.sort();
        compared.dedup();
        SfcChecks {
            compared,
            numbers: HashMap::new(),
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
            drives: HashMap::new(),
        }
    }

    /// Reads, with each supervised step, the outputs `program` derives
    /// from its flag (its actions: the valve of the motion it waits for)
    /// over `observable`, those `is_tag` accepts: a cause that holds one
    /// explains the step stuck.
    #[must_use]
    pub fn driving(
        mut self,
        program: &Program,
        observable: &Observability,
        is_tag: impl Fn(&Signal) -> bool,
    ) -> SfcChecks {
        for (r, step) in self.sfc.steps() {
            if step.supervision_ms.is_none() {
                continue;
            }
            let outputs: Vec<Signal> =
                crate::consequence::forced_outputs(program, &step.flag, observable, &is_tag)
                    .into_iter()
                    .map(|sf| sf.coil)
                    .collect();
            for o in &outputs {
                if !self.inputs.contains(o) {
                    self.inputs.push(o.clone());
                }
            }
            self.drives.insert(r, outputs);
        }
        self.inputs.sort();
        self
    }

    /// Whether step `r` would still be stuck with the signals of
    /// `instead` at their values and every other at its own: see the
    /// module's documentation. `None` where an operand is unknown.
    fn stuck_with(&self, r: StepRef, instead: &[(Signal, bool)]) -> Option<bool> {
        let held = |x: &Signal| instead.iter().find(|(s, _)| s == x).map(|&(_, v)| v);
        let value = |x: &Signal| held(x).or_else(|| self.values.get(x).copied());
        if !value(&self.sfc.step(r).flag)? {
            return Some(false);
        }
        let taken =
            self.drives.get(&r).into_iter().flatten().any(
                |o| matches!((held(o), self.values.get(o)), (Some(v), Some(&now)) if v != now),
            );
        let mut unknown = false;
        let chart = &self.sfc.charts[r.chart];
        for (i, t) in chart.transitions.iter().enumerate() {
            if !t.from.contains(&r) {
                continue;
            }
            let Some(needs) = self.needs.get(&(r.chart, i)) else {
                continue;
            };
            // One that can fire now, the step stuck all the same, is not
            // what the cause keeps from firing.
            let now = needs.certain(|x| self.values.get(x).copied());
            match needs.certain(value) {
                Some(true) if now == Some(false) => return Some(false),
                Some(_) => {}
                None => unknown = true,
            }
        }
        if taken {
            Some(false)
        } else {
            (!unknown).then_some(true)
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
    /// known now: the operands keeping it from firing, each with its value
    /// and comment (a comparison with the number it compares), empty when
    /// it may fire or an operand is unknown.
    pub fn criteria(&self, c: usize, i: usize) -> Vec<Culprit> {
        let Some(sf) = self.needs.get(&(c, i)) else {
            return Vec::new();
        };
        let mut culprits = explain_partial(
            sf,
            |s| self.values.get(s).copied(),
            None,
            Polarity::Off,
            &self.comments,
        )
        .culprits;
        for k in &mut culprits {
            if k.comment.is_none() {
                k.comment = comment_of(&self.comments, &k.address);
            }
        }
        read_comparisons(
            &mut culprits,
            |s| self.numbers.get(s).copied(),
            &self.comments,
        );
        culprits
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

    fn number_inputs(&self) -> Vec<Signal> {
        self.compared.clone()
    }

    /// The step's flag and the operands of the transitions leaving it
    /// (their source steps' flags and their conditions' contacts, each
    /// comparison followed by the variables it compares).
    fn reads(&self, id: &str, out: &mut Vec<Signal>) {
        let Some((r, step)) = self.sfc.steps().find(|(r, _)| self.alarm_id(*r) == id) else {
            return;
        };
        read_with_compared(step.flag.clone(), out);
        for o in self.drives.get(&r).into_iter().flatten() {
            read_with_compared(o.clone(), out);
        }
        let chart = &self.sfc.charts[r.chart];
        for (i, t) in chart.transitions.iter().enumerate() {
            if !t.from.contains(&r) {
                continue;
            }
            for s in self
                .needs
                .get(&(r.chart, i))
                .into_iter()
                .flat_map(|sf| sf.leaves())
            {
                read_with_compared(s, out);
            }
        }
    }

    /// The number is kept for the next analysis; what the comparison says
    /// comes as a change of its contact.
    fn on_number(
        &mut self,
        signal: &Signal,
        value: Option<Num>,
        _now: u64,
        _out: &mut Vec<Finding>,
    ) {
        match value {
            Some(n) => self.numbers.insert(signal.clone(), n),
            None => self.numbers.remove(signal),
        };
    }

    /// A stuck step reads and holds what the transitions leaving it wait
    /// for: a timer waiting for the same operand follows from it. It reads
    /// the outputs driven from its flag too.
    fn facts(&self, out: &mut Vec<crate::consequence::AlarmFacts>) {
        for (r, s) in self.sfc.steps() {
            if s.supervision_ms.is_none() {
                continue;
            }
            let mut waits: Vec<Signal> = Vec::new();
            for (c, chart) in self.sfc.charts.iter().enumerate() {
                for (i, t) in chart.transitions.iter().enumerate() {
                    if !t.from.contains(&r) {
                        continue;
                    }
                    for leaf in self
                        .needs
                        .get(&(c, i))
                        .map(|sf| sf.leaves())
                        .unwrap_or_default()
                    {
                        if leaf != s.flag && !waits.contains(&leaf) {
                            waits.push(leaf);
                        }
                    }
                }
            }
            let mut reads = waits.clone();
            reads.extend(self.drives.get(&r).into_iter().flatten().cloned());
            out.push(crate::consequence::AlarmFacts {
                id: self.alarm_id(r),
                effects: waits,
                reads,
            });
        }
    }

    fn would_hold(&self, id: &str, instead: &[(Signal, bool)]) -> Option<bool> {
        let r = self
            .sfc
            .steps()
            .map(|(r, _)| r)
            .find(|&r| self.alarm_id(r) == id)?;
        self.stuck_with(r, instead)
    }

    /// The step, its chart and its supervision time.
    fn describe(&self, id: &str) -> Option<String> {
        let (r, step) = self
            .sfc
            .steps()
            .find(|(r, s)| s.supervision_ms.is_some() && self.alarm_id(*r) == id)?;
        let supervision = step.supervision_ms? as f64 / 1000.0;
        let mut text = format!(
            "step {} active longer than {supervision} s (its flag {})",
            self.sfc.step_name(r),
            step.flag
        );
        if let Some(c) = &step.comment {
            text += &format!(": {c}");
        }
        Some(text)
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
