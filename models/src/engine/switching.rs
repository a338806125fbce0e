//! Switching-function checks: fault coils compiled over one bitset and
//! evaluated incrementally, explained with paper 000's step blocks.

use std::collections::HashMap;

use super::checks::{read_with_compared, CheckSet, Declared, Finding};
use crate::alarm::{AlarmKind, Severity};
use crate::comments::CommentDb;
use crate::compiled::CompiledCell;
use crate::consequence::{short_of_faults, AlarmFacts};
use crate::explain::{explain_partial, read_comparisons, Polarity};
use crate::signal::Signal;
use crate::switching::SwitchingFunction;
use crate::value::{CmpOperand, Comparison, Num};

/// One switching-function check: a fault coil and its fault value.
#[derive(Debug, Clone)]
pub struct SwitchingCheck {
    /// Alarm id.
    pub id: String,
    /// The coil's switching function.
    pub sf: SwitchingFunction,
    /// Which coil value is the fault.
    pub polarity: Polarity,
    /// How urgent.
    pub severity: Severity,
    /// Fault type for history (`ESE`).
    pub fault_type: String,
    /// What the alarm's message says before its culprit; `None`: the
    /// fault type (a discrete alarm's text is its own).
    pub text: Option<String>,
    /// Comments for the culprits.
    pub comments: CommentDb,
    /// The check is armed only while this holds (CSD: cycle start pressed);
    /// `None`: always armed.
    pub armed_when: Option<SwitchingFunction>,
    /// The outputs the program derives from the fault coil (its forced
    /// outputs, [`crate::consequence::forced_outputs`]), each with its
    /// switching function: a check reading one may follow from this one's
    /// fault, judged with the output re-derived from the coil normal (down
    /// a permissive chain, from the outputs above it re-derived). The set
    /// drops another of its checks' fault coils and what is forced only
    /// through one ([`crate::consequence::short_of_faults`]).
    pub forces: Vec<SwitchingFunction>,
}

/// Switching-function checks compiled over one bitset.
///
/// Entry `c` of the compiled cell is check `c`'s switching function; entry
/// `n + k` is the arming condition of the `k`-th check that has one.
pub struct SwitchingChecks {
    checks: Vec<SwitchingCheck>,
    cell: CompiledCell,
    /// Per check: the compiled entry of its arming condition.
    arm_entry: Vec<Option<usize>>,
    known: Vec<bool>,
    /// Per signal: the checks that read it (function or arming condition).
    readers: Vec<Vec<usize>>,
    /// Per check: how many of its inputs are unknown.
    unknown_inputs: Vec<u32>,
    /// Per check: the verdict last reported (`None`: none yet, so the
    /// first verdict is always reported, which lets an alarm restored from
    /// the journal clear).
    reported: Vec<Option<bool>>,
    changed: Vec<usize>,
    /// The variables the comparison contacts compare, for culprits shown
    /// with their numbers.
    compared: Vec<Signal>,
    /// Their numbers now.
    numbers: HashMap<Signal, Num>,
    /// Per alarm id: its check.
    by_id: HashMap<String, usize>,
}

impl SwitchingChecks {
    /// Compiles the checks. Every signal starts unknown, so every check
    /// starts suspended.
    ///
    /// A check with unknown inputs is evaluated in three-valued (Kleene)
    /// logic: a fault that is certain whatever the unknown contacts hold is
    /// reported (naming them); anything else holds the last verdict, so a
    /// clear is only ever called on known values.
    pub fn new(checks: Vec<SwitchingCheck>) -> Self {
        // A check's forced outputs stop at another check's fault coil.
        let coils: Vec<Signal> = checks
            .iter()
            .filter(|c| c.text.is_none())
            .map(|c| c.sf.coil.clone())
            .collect();
        let checks: Vec<SwitchingCheck> = checks
            .into_iter()
            .map(|mut c| {
                let own = c.sf.coil.clone();
                let forced = std::mem::take(&mut c.forces);
                c.forces = short_of_faults(forced, &own, |s| *s != own && coils.contains(s));
                c
            })
            .collect();
        let mut sfs: Vec<SwitchingFunction> = checks.iter().map(|c| c.sf.clone()).collect();
        let mut arm_entry = Vec::with_capacity(checks.len());
        for c in &checks {
            arm_entry.push(c.armed_when.as_ref().map(|a| {
                sfs.push(a.clone());
                sfs.len() - 1
            }));
        }
        let owner: Vec<usize> = (0..checks.len())
            .chain(
                arm_entry
                    .iter()
                    .enumerate()
                    .filter_map(|(c, e)| e.map(|_| c)),
            )
            .collect();
        let cell = CompiledCell::new(&sfs);
        let n = cell.signals().len();
        let mut readers = vec![Vec::new(); n];
        let mut unknown_inputs = vec![0u32; checks.len()];
        for (s, r) in readers.iter_mut().enumerate() {
            let mut owners: Vec<usize> = cell
                .readers(s as u32)
                .iter()
                .map(|&e| owner[e as usize])
                .collect();
            owners.sort_unstable();
            owners.dedup();
            for &c in &owners {
                unknown_inputs[c] += 1;
            }
            *r = owners;
        }
        let mut compared: Vec<Signal> = cell
            .signals()
            .iter()
            .filter_map(Comparison::of_signal)
            .flat_map(|c| match c.rhs {
                CmpOperand::Tag(t) => vec![c.lhs, t],
                CmpOperand::Const(_) => vec![c.lhs],
            })
            .collect();
        compared.sort();
        compared.dedup();
        SwitchingChecks {
            by_id: checks
                .iter()
                .enumerate()
                .map(|(i, c)| (c.id.clone(), i))
                .collect(),
            compared,
            numbers: HashMap::new(),
            reported: vec![None; checks.len()],
            checks,
            cell,
            arm_entry,
            known: vec![false; n],
            readers,
            unknown_inputs,
            changed: Vec::new(),
        }
    }

    /// How many checks.
    pub fn len(&self) -> usize {
        self.checks.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.checks.is_empty()
    }
}

impl CheckSet for SwitchingChecks {
    fn inputs(&self) -> Vec<Signal> {
        self.cell.signals().to_vec()
    }

    fn number_inputs(&self) -> Vec<Signal> {
        self.compared.clone()
    }

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

    /// A check reads its function's and its arming condition's signals;
    /// its fault holds its coil and the outputs the program derives from
    /// it (a discrete alarm: its contact).
    fn facts(&self, out: &mut Vec<AlarmFacts>) {
        for c in &self.checks {
            let mut reads = c.sf.leaves();
            if let Some(a) = &c.armed_when {
                reads.extend(a.leaves());
            }
            let mut effects = if c.text.is_some() {
                // A discrete alarm's function is its one contact.
                c.sf.leaves()
            } else {
                vec![c.sf.coil.clone()]
            };
            effects.extend(c.forces.iter().map(|f| f.coil.clone()));
            out.push(AlarmFacts {
                id: c.id.clone(),
                effects,
                reads,
            });
        }
    }

    /// The check's leaves and its arming condition's, each comparison
    /// followed by the variables it compares.
    fn reads(&self, id: &str, out: &mut Vec<Signal>) {
        let Some(check) = self.by_id.get(id).map(|&i| &self.checks[i]) else {
            return;
        };
        let arming = check.armed_when.iter().flat_map(SwitchingFunction::leaves);
        for s in check.sf.leaves().into_iter().chain(arming) {
            read_with_compared(s, out);
        }
    }

    fn without(
        &self,
        id: &str,
        now: &dyn Fn(&Signal) -> Option<bool>,
    ) -> Option<Vec<(Signal, bool)>> {
        self.held_normal(id, now)
    }

    /// A discrete alarm's text and contact; a check's coil at its fault
    /// value, its function in words and its arming condition.
    fn describe(&self, id: &str) -> Option<String> {
        let check = self.by_id.get(id).map(|&i| &self.checks[i])?;
        let mut text = match &check.text {
            Some(words) => format!("{words} ({})", check.sf.readable()),
            None => format!(
                "fault while {} is {}; {} = {}",
                check.sf.coil,
                check.polarity,
                check.sf.coil,
                check.sf.readable()
            ),
        };
        if let Some(armed) = &check.armed_when {
            text += &format!("; only while {}", armed.readable());
        }
        Some(text)
    }

    fn would_hold(&self, id: &str, instead: &[(Signal, bool)]) -> Option<bool> {
        self.holds_with(id, instead)
    }

    fn restate(&self, f: &mut Finding) {
        let Some(&c) = self.by_id.get(&f.id) else {
            return;
        };
        if !f.active || self.reported[c] != Some(true) {
            return;
        }
        // The contact whose first value made it certain, as first said (a
        // first value has no value before it: none, usually).
        let check = &self.checks[c];
        let changed = f
            .culprits
            .iter()
            .find(|c| c.trigger)
            .map_or_else(|| check.sf.coil.clone(), |c| c.address.clone());
        let again = finding(
            check,
            true,
            &|x| self.known_value(x),
            &|x| self.numbers.get(x).copied(),
            &changed,
            None,
        );
        *f = Finding { at: f.at, ..again };
    }

    fn alarms(&self) -> Vec<Declared> {
        self.checks
            .iter()
            .map(|c| Declared {
                id: c.id.clone(),
                kind: AlarmKind::Switching,
                severity: c.severity,
                fault_type: c.fault_type.clone(),
                latched: false,
            })
            .collect()
    }

    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        before: Option<bool>,
        _now: u64,
        out: &mut Vec<Finding>,
    ) {
        let Some(s) = self.cell.signal_index(signal) else {
            return;
        };
        let si = s as usize;
        let Some(v) = value else {
            if self.known[si] {
                self.known[si] = false;
                for &c in &self.readers[si] {
                    self.unknown_inputs[c] += 1;
                }
            }
            return;
        };
        if !self.known[si] {
            self.known[si] = true;
            for &c in &self.readers[si] {
                self.unknown_inputs[c] -= 1;
            }
        }
        let mut changed = std::mem::take(&mut self.changed);
        changed.clear();
        self.cell.set(s, v, &mut changed);
        self.changed = changed;
        for k in 0..self.readers[si].len() {
            let c = self.readers[si][k];
            let check = &self.checks[c];
            let verdict = if self.unknown_inputs[c] == 0 {
                let armed = self.arm_entry[c].is_none_or(|e| self.cell.output(e));
                Some(armed && self.cell.output(c) == check.polarity.fault_value())
            } else {
                self.certain_fault(c).then_some(true)
            };
            let Some(fault) = verdict else {
                continue;
            };
            if Some(fault) == self.reported[c] {
                continue;
            }
            self.reported[c] = Some(fault);
            out.push(finding(
                check,
                fault,
                &|x| self.known_value(x),
                &|x| self.numbers.get(x).copied(),
                signal,
                before,
            ));
        }
    }
}

impl SwitchingChecks {
    /// What alarm `id`'s fault holds, taken back: see
    /// [`CheckSet::without`].
    fn held_normal(
        &self,
        id: &str,
        now: &dyn Fn(&Signal) -> Option<bool>,
    ) -> Option<Vec<(Signal, bool)>> {
        let check = &self.checks[*self.by_id.get(id)?];
        let normal = !check.polarity.fault_value();
        // A discrete alarm's function is its contact: the contact is what
        // its fault holds; a coil's check holds the coil.
        let held = if check.text.is_some() {
            check.sf.leaves().into_iter().next()?
        } else {
            check.sf.coil.clone()
        };
        let mut out = vec![(held, normal)];
        // Each forced output after those it reads (`forced_outputs`): one
        // down a permissive chain reads the one above as re-derived, and
        // is unknown when that one could not be.
        for (k, f) in check.forces.iter().enumerate() {
            let value = f.certain(|x| {
                if let Some(&(_, v)) = out.iter().find(|(s, _)| s == x) {
                    Some(v)
                } else if check.forces[..k].iter().any(|g| g.coil == *x) {
                    None
                } else {
                    // An output's other contacts need not be this set's
                    // (a valve driven by a chart's step flag).
                    self.known_value(x).or_else(|| now(x))
                }
            });
            if let Some(v) = value {
                out.push((f.coil.clone(), v));
            }
        }
        Some(out)
    }

    /// Whether alarm `id`'s fault would hold with `instead`: see
    /// [`CheckSet::would_hold`].
    fn holds_with(&self, id: &str, instead: &[(Signal, bool)]) -> Option<bool> {
        let check = &self.checks[*self.by_id.get(id)?];
        let value = |x: &Signal| {
            instead
                .iter()
                .find(|(s, _)| s == x)
                .map(|&(_, v)| v)
                .or_else(|| self.known_value(x))
        };
        let armed = match &check.armed_when {
            None => true,
            Some(a) => a.certain(value)?,
        };
        Some(armed && check.sf.certain(value)? == check.polarity.fault_value())
    }

    /// Signal `x`'s value, `None` while unknown.
    fn known_value(&self, x: &Signal) -> Option<bool> {
        self.cell
            .signal_index(x)
            .filter(|&i| self.known[i as usize])
            .map(|i| self.cell.value(i))
    }

    /// Whether check `c`, some of whose inputs are unknown, is at fault
    /// whatever they hold.
    fn certain_fault(&self, c: usize) -> bool {
        let known = |x: &Signal| self.known_value(x);
        let check = &self.checks[c];
        let armed = check
            .armed_when
            .as_ref()
            .is_none_or(|a| a.certain(known) == Some(true));
        armed && check.sf.certain(known) == Some(check.polarity.fault_value())
    }
}

/// The finding of `check` going to `fault`, explained from the `known`
/// values (and `before` for the signal that just changed). Contacts whose
/// value is unknown are named in the message; comparisons are shown with
/// the `numbers` they compare.
fn finding(
    check: &SwitchingCheck,
    fault: bool,
    known: &dyn Fn(&Signal) -> Option<bool>,
    numbers: &dyn Fn(&Signal) -> Option<Num>,
    changed: &Signal,
    before: Option<bool>,
) -> Finding {
    let mut finding = Finding {
        at: None,
        id: check.id.clone(),
        kind: AlarmKind::Switching,
        severity: check.severity,
        fault_type: check.fault_type.clone(),
        latched: false,
        active: fault,
        fault_step: None,
        culprits: Vec::new(),
        message: format!(
            "{} cleared",
            check.text.as_ref().unwrap_or(&check.fault_type)
        ),
    };
    if !fault {
        return finding;
    }
    let before_values = |x: &Signal| if x == changed { before } else { known(x) };
    let e = explain_partial(
        &check.sf,
        known,
        Some(&before_values),
        check.polarity,
        &check.comments,
    );
    finding.fault_step = e.fault_step;
    finding.culprits = e.culprits;
    read_comparisons(&mut finding.culprits, numbers, &check.comments);
    let text = check.text.as_ref().unwrap_or(&check.fault_type);
    let mut message = match (finding.fault_step, finding.culprits.first()) {
        (Some(step), Some(c)) => format!("{text} at step {step}: {c}"),
        (None, Some(c)) => format!("{text}: {c}"),
        _ => text.clone(),
    };
    if !e.unknown.is_empty() {
        let names: Vec<&str> = e.unknown.iter().map(Signal::name).collect();
        message.push_str(&format!(" (unknown: {})", names.join(", ")));
    }
    finding.message = message;
    finding
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::Expr;
    use crate::program::Program;
    use crate::signal::Observability;

    #[test]
    fn a_check_reads_its_leaves_its_arming_and_the_compared_variables() {
        let p =
            Program::compile("ese.il", include_str!("../../../config/cnc/ese.il"), None).unwrap();
        let sf = SwitchingFunction::expand(
            &p,
            &Signal::new("G8.02"),
            &Observability::default_for(p.dialect()),
        )
        .unwrap();
        let leaves = sf.leaves();
        let check = |id: &str, armed_when: Option<&str>| SwitchingCheck {
            forces: Vec::new(),
            text: None,
            id: id.into(),
            sf: sf.clone(),
            polarity: Polarity::On,
            severity: Severity::Critical,
            fault_type: "ESE".into(),
            comments: CommentDb::default(),
            armed_when: armed_when.map(|e| {
                SwitchingFunction::from_expr(Signal::new("armed"), &Expr::parse(e).unwrap())
            }),
        };
        let set = SwitchingChecks::new(vec![
            check("ese", None),
            check("ese-armed", Some("X0.06 * D0 > 5")),
        ]);
        let reads = |id: &str| {
            let mut out = Vec::new();
            set.reads(id, &mut out);
            out
        };
        assert_eq!(reads("ese"), leaves);
        let mut armed = leaves.clone();
        armed.extend([Signal::new("D0 > 5"), Signal::new("D0")]);
        assert_eq!(reads("ese-armed"), armed);
        assert!(reads("nope").is_empty());
        let (inputs, numbers) = (set.inputs(), set.number_inputs());
        assert!(armed
            .iter()
            .all(|s| inputs.contains(s) || numbers.contains(s)));
    }
}
