//! Compiled evaluation of many switching functions over one signal bitset.
//!
//! A [`CompiledCell`] flattens each switching function into a list of step
//! blocks whose operands are packed `u32`s (signal bit, earlier step or
//! constant, each possibly negated). Every step block keeps how many of its
//! operands are true, and every signal and step knows the places it is an
//! operand of. [`CompiledCell::set`] changes one signal and updates only
//! those counts, walking up to a parent step only when a step's value
//! flips: the cost of a change is the number of places the signal is read,
//! not the size of the checks reading it. [`CompiledCell::evaluate_all`] is
//! the full re-evaluation it is measured and tested against.

use std::collections::HashMap;

use crate::logic::Term;
use crate::programs::Op;
use crate::signal::Signal;
use crate::switching::SwitchingFunction;

/// Index of a signal in a [`CompiledCell`].
pub type SignalIndex = u32;

const NEGATED: u32 = 1 << 31;
const KIND_SHIFT: u32 = 29;
const KIND_SIGNAL: u32 = 0;
const KIND_STEP: u32 = 1;
const KIND_CONST: u32 = 2;
const INDEX_MASK: u32 = (1 << KIND_SHIFT) - 1;
/// A place that is a check's root (its output), not a step block.
const ROOT: u32 = 1 << 30;
const PLACE_MASK: u32 = ROOT - 1;

/// One switching function, flattened.
#[derive(Debug, Clone)]
struct CompiledCheck {
    /// Per step: its operator and the range of its operands.
    steps: Vec<(Op, u32, u32)>,
    operands: Vec<u32>,
    root: u32,
}

/// Many switching functions compiled over one set of signals.
#[derive(Debug, Clone)]
pub struct CompiledCell {
    signals: Vec<Signal>,
    index: HashMap<Signal, SignalIndex>,
    /// One bit per signal.
    bits: Vec<u64>,
    checks: Vec<CompiledCheck>,
    /// `readers[reader_start[s]..reader_start[s + 1]]` are the checks that
    /// read signal `s`.
    reader_start: Vec<u32>,
    readers: Vec<u32>,
    outputs: Vec<bool>,
    /// Step values of the check being evaluated, reused.
    scratch: Vec<bool>,
    /// Every check's first step in the global step numbering.
    step_base: Vec<u32>,
    /// Per global step: an AND (else an OR), its operand count, how many
    /// of its operands are true now, and its value.
    step_and: Vec<bool>,
    step_len: Vec<u32>,
    step_true: Vec<u32>,
    step_value: Vec<bool>,
    /// `places[place_start[s]..place_start[s + 1]]`: where signal `s` is an
    /// operand: a global step, or `ROOT | check`; `NEGATED` if negated.
    place_start: Vec<u32>,
    places: Vec<u32>,
    /// The same for each global step: where its value is an operand.
    up_start: Vec<u32>,
    up: Vec<u32>,
    /// Work list of (place, operand value) while a change propagates.
    work: Vec<(u32, bool)>,
    /// Checks whose output flipped during one change, with the output
    /// they had before it, and a mark per check.
    touched: Vec<(u32, bool)>,
    touched_mark: Vec<bool>,
}

/// Counts for a CSR index: `starts[i]..starts[i + 1]` for each of `n` keys.
fn csr(n: usize, pairs: &[(u32, u32)]) -> (Vec<u32>, Vec<u32>) {
    let mut starts = vec![0u32; n + 1];
    for &(k, _) in pairs {
        starts[k as usize + 1] += 1;
    }
    for i in 0..n {
        starts[i + 1] += starts[i];
    }
    let mut fill = starts.clone();
    let mut values = vec![0u32; pairs.len()];
    for &(k, v) in pairs {
        values[fill[k as usize] as usize] = v;
        fill[k as usize] += 1;
    }
    (starts, values)
}

impl CompiledCell {
    /// Compiles `sfs`; check `i` is `sfs[i]`. All signals start at 0 and
    /// every check is evaluated once.
    ///
    /// # Panics
    /// If there are more than 2^29 signals or steps in one check.
    pub fn new(sfs: &[SwitchingFunction]) -> CompiledCell {
        let mut index: HashMap<Signal, SignalIndex> = HashMap::new();
        let mut signals = Vec::new();
        let mut intern = |s: &Signal| -> u32 {
            *index.entry(s.clone()).or_insert_with(|| {
                signals.push(s.clone());
                u32::try_from(signals.len() - 1).expect("fewer than 2^32 signals")
            })
        };
        let mut checks = Vec::with_capacity(sfs.len());
        let mut reads: Vec<Vec<u32>> = Vec::with_capacity(sfs.len());
        for sf in sfs {
            let mut read = Vec::new();
            let mut pack = |t: &Term| -> u32 {
                let (kind, i, negated) = match t {
                    Term::Const(v) => (KIND_CONST, 0, *v),
                    Term::Signal { signal, negated } => {
                        let i = intern(signal);
                        read.push(i);
                        (KIND_SIGNAL, i, *negated)
                    }
                    Term::Block { id, negated } => (KIND_STEP, *id as u32, *negated),
                };
                assert!(i <= INDEX_MASK, "too many signals or steps to compile");
                (kind << KIND_SHIFT) | i | if negated { NEGATED } else { 0 }
            };
            let mut steps = Vec::with_capacity(sf.steps.len());
            let mut operands = Vec::new();
            for block in &sf.steps {
                let start = operands.len() as u32;
                operands.extend(block.terms.iter().map(&mut pack));
                steps.push((block.op, start, operands.len() as u32));
            }
            let root = pack(&sf.root);
            read.sort_unstable();
            read.dedup();
            reads.push(read);
            checks.push(CompiledCheck {
                steps,
                operands,
                root,
            });
        }
        let n = signals.len();
        let mut counts = vec![0u32; n + 1];
        for read in &reads {
            for &s in read {
                counts[s as usize + 1] += 1;
            }
        }
        for i in 0..n {
            counts[i + 1] += counts[i];
        }
        let reader_start = counts.clone();
        let mut readers = vec![0u32; counts[n] as usize];
        let mut fill = counts;
        for (c, read) in reads.iter().enumerate() {
            for &s in read {
                readers[fill[s as usize] as usize] = c as u32;
                fill[s as usize] += 1;
            }
        }
        // Where each signal and each step is an operand.
        let mut step_base = Vec::with_capacity(checks.len());
        let (mut step_and, mut step_len) = (Vec::new(), Vec::new());
        let mut signal_places: Vec<(u32, u32)> = Vec::new();
        let mut step_places: Vec<(u32, u32)> = Vec::new();
        for (c, check) in checks.iter().enumerate() {
            let base = u32::try_from(step_and.len()).expect("fewer than 2^30 steps");
            assert!(
                base + (check.steps.len() as u32) < ROOT,
                "too many steps to compile"
            );
            step_base.push(base);
            let mut place = |o: u32, at: u32| {
                let at = at | (o & NEGATED);
                let i = o & INDEX_MASK;
                match (o >> KIND_SHIFT) & 0b11 {
                    KIND_SIGNAL => signal_places.push((i, at)),
                    KIND_STEP => step_places.push((base + i, at)),
                    _ => {}
                }
            };
            for (k, &(op, start, end)) in check.steps.iter().enumerate() {
                step_and.push(op == Op::And);
                step_len.push(end - start);
                for &o in &check.operands[start as usize..end as usize] {
                    place(o, base + k as u32);
                }
            }
            place(check.root, ROOT | c as u32);
        }
        let steps = step_and.len();
        let (place_start, places) = csr(n, &signal_places);
        let (up_start, up) = csr(steps, &step_places);
        let mut cell = CompiledCell {
            signals,
            index,
            bits: vec![0; n.div_ceil(64)],
            outputs: vec![false; checks.len()],
            touched_mark: vec![false; checks.len()],
            checks,
            reader_start,
            readers,
            scratch: Vec::new(),
            step_base,
            step_and,
            step_len,
            step_true: vec![0; steps],
            step_value: vec![false; steps],
            place_start,
            places,
            up_start,
            up,
            work: Vec::new(),
            touched: Vec::new(),
        };
        cell.evaluate_all(&mut Vec::new());
        cell
    }

    /// The index of `signal`, if any check reads it.
    pub fn signal_index(&self, signal: &Signal) -> Option<SignalIndex> {
        self.index.get(signal).copied()
    }

    /// Every signal read, by index.
    pub fn signals(&self) -> &[Signal] {
        &self.signals
    }

    /// The current value of a signal.
    pub fn value(&self, s: SignalIndex) -> bool {
        self.bits[s as usize / 64] >> (s % 64) & 1 == 1
    }

    /// The current output of check `check`.
    pub fn output(&self, check: usize) -> bool {
        self.outputs[check]
    }

    /// The checks that read signal `s`.
    pub fn readers(&self, s: SignalIndex) -> &[u32] {
        let s = s as usize;
        &self.readers[self.reader_start[s] as usize..self.reader_start[s + 1] as usize]
    }

    /// Sets a signal and updates the checks that read it, appending to
    /// `changed` (in check order) every check whose output changed. Setting
    /// a signal to the value it has does nothing.
    pub fn set(&mut self, s: SignalIndex, value: bool, changed: &mut Vec<usize>) {
        if !self.write_bit(s, value) {
            return;
        }
        let (start, end) = (
            self.place_start[s as usize] as usize,
            self.place_start[s as usize + 1] as usize,
        );
        for k in start..end {
            let at = self.places[k];
            self.work
                .push((at & !NEGATED, value != (at & NEGATED != 0)));
        }
        while let Some((place, operand)) = self.work.pop() {
            if place & ROOT != 0 {
                let c = (place & PLACE_MASK) as usize;
                if self.outputs[c] != operand {
                    if !self.touched_mark[c] {
                        self.touched_mark[c] = true;
                        self.touched.push((c as u32, self.outputs[c]));
                    }
                    self.outputs[c] = operand;
                }
                continue;
            }
            // One operand of step `g` flipped to `operand`.
            let g = place as usize;
            if operand {
                self.step_true[g] += 1;
            } else {
                self.step_true[g] -= 1;
            }
            let value = if self.step_and[g] {
                self.step_true[g] == self.step_len[g]
            } else {
                self.step_true[g] > 0
            };
            if value != self.step_value[g] {
                self.step_value[g] = value;
                for k in self.up_start[g] as usize..self.up_start[g + 1] as usize {
                    let at = self.up[k];
                    self.work
                        .push((at & !NEGATED, value != (at & NEGATED != 0)));
                }
            }
        }
        // An output that flipped and flipped back did not change.
        let from = changed.len();
        for (c, before) in self.touched.drain(..) {
            self.touched_mark[c as usize] = false;
            if self.outputs[c as usize] != before {
                changed.push(c as usize);
            }
        }
        changed[from..].sort_unstable();
    }

    /// Sets a signal without evaluating anything; returns whether it changed.
    pub fn write_bit(&mut self, s: SignalIndex, value: bool) -> bool {
        let (word, bit) = (s as usize / 64, s % 64);
        let old = self.bits[word] >> bit & 1 == 1;
        if old != value {
            self.bits[word] ^= 1 << bit;
        }
        old != value
    }

    /// Re-evaluates every check from the signal bits, appending those whose
    /// output changed, and recounts every step (the baseline
    /// [`CompiledCell::set`] is measured against, and how the counts start).
    pub fn evaluate_all(&mut self, changed: &mut Vec<usize>) {
        for c in 0..self.checks.len() {
            let check = &self.checks[c];
            let base = self.step_base[c] as usize;
            let bits = &self.bits;
            let steps = &mut self.step_value[base..base + check.steps.len()];
            for (k, &(_, start, end)) in check.steps.iter().enumerate() {
                let ops = &check.operands[start as usize..end as usize];
                let count = ops.iter().filter(|&&o| operand(o, bits, steps)).count() as u32;
                self.step_true[base + k] = count;
                steps[k] = if self.step_and[base + k] {
                    count == end - start
                } else {
                    count > 0
                };
            }
            let v = operand(check.root, bits, steps);
            if v != self.outputs[c] {
                self.outputs[c] = v;
                changed.push(c);
            }
        }
    }

    /// Evaluates one check from the current bits.
    pub fn evaluate(&mut self, c: usize) -> bool {
        let check = &self.checks[c];
        let scratch = &mut self.scratch;
        scratch.clear();
        let bits = &self.bits;
        for &(op, start, end) in &check.steps {
            let ops = &check.operands[start as usize..end as usize];
            let v = match op {
                Op::And => ops.iter().all(|&o| operand(o, bits, scratch)),
                Op::Or => ops.iter().any(|&o| operand(o, bits, scratch)),
            };
            scratch.push(v);
        }
        operand(check.root, bits, scratch)
    }
}

#[inline]
fn operand(o: u32, bits: &[u64], steps: &[bool]) -> bool {
    let i = o & INDEX_MASK;
    let v = match (o >> KIND_SHIFT) & 0b11 {
        KIND_SIGNAL => bits[i as usize / 64] >> (i % 64) & 1 == 1,
        KIND_STEP => steps[i as usize],
        _ => false,
    };
    v != (o & NEGATED != 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::Program;
    use crate::signal::Observability;

    #[test]
    fn only_readers_are_reevaluated_and_changes_reported() {
        let p = Program::compile(
            "t.il",
            "LD X1\nAND X2\nST Y1\nLDN X3\nOR TRUE\nST Y2\nLD X3\nST Y3",
            None,
        )
        .unwrap();
        let o = Observability::parse(p.dialect(), "X1,X2,X3").unwrap();
        let sfs: Vec<_> = ["Y1", "Y2", "Y3"]
            .iter()
            .map(|c| SwitchingFunction::expand(&p, &Signal::new(c), &o).unwrap())
            .collect();
        let mut cell = CompiledCell::new(&sfs);
        assert_eq!(
            (cell.output(0), cell.output(1), cell.output(2)),
            (false, true, false)
        );
        let x1 = cell.signal_index(&Signal::new("X1")).unwrap();
        let x2 = cell.signal_index(&Signal::new("X2")).unwrap();
        let x3 = cell.signal_index(&Signal::new("X3")).unwrap();
        assert_eq!(cell.readers(x3), &[1, 2]);
        let mut changed = Vec::new();
        cell.set(x1, true, &mut changed);
        assert!(changed.is_empty());
        cell.set(x2, true, &mut changed);
        assert_eq!(changed, [0]);
        changed.clear();
        cell.set(x3, true, &mut changed);
        assert_eq!(changed, [2]);
        cell.set(x3, true, &mut changed);
        assert_eq!(changed, [2]);
    }

    #[test]
    fn counts_follow_every_change_as_a_full_evaluation_would() {
        // X1 read in several steps and both ways (a flip that flips back
        // must not be reported), relays, constants, a bare contact root.
        let p = Program::compile(
            "t.il",
            "LD X1\nAND X2\nOR( X3\nANDN X1\n)\nAND( X4\nOR X1\n)\nST R1\n\
             LD R1\nORN X2\nST Y1\nLD X1\nANDN X1\nOR X5\nST Y2\nLD X3\nST Y3\n\
             LDN X4\nOR( X1\nAND( X2\nOR X3\n)\n)\nAND TRUE\nST Y4\nLD X1\nST Y5",
            None,
        )
        .unwrap();
        let o = Observability::parse(p.dialect(), "X1,X2,X3,X4,X5").unwrap();
        let sfs: Vec<_> = ["Y1", "Y2", "Y3", "Y4", "Y5"]
            .iter()
            .map(|c| SwitchingFunction::expand(&p, &Signal::new(c), &o).unwrap())
            .collect();
        let mut cell = CompiledCell::new(&sfs);
        let n = cell.signals().len() as u32;
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        let mut changed = Vec::new();
        for _ in 0..5000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let s = (seed % u64::from(n)) as u32;
            let v = seed >> 40 & 1 == 1;
            let before: Vec<bool> = (0..sfs.len()).map(|c| cell.output(c)).collect();
            changed.clear();
            cell.set(s, v, &mut changed);
            let truth: Vec<bool> = (0..sfs.len()).map(|c| cell.evaluate(c)).collect();
            let outputs: Vec<bool> = (0..sfs.len()).map(|c| cell.output(c)).collect();
            assert_eq!(outputs, truth);
            let expected: Vec<usize> = (0..sfs.len()).filter(|&c| before[c] != truth[c]).collect();
            assert_eq!(changed, expected);
        }
    }
}
