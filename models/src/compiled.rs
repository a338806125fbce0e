//! Compiled evaluation of many switching functions over one signal bitset.
//!
//! A [`CompiledCell`] flattens each switching function into a list of step
//! blocks whose operands are packed `u32`s (signal bit, earlier step or
//! constant, each possibly negated), and keeps an index from every signal
//! to the checks that read it. [`CompiledCell::set`] changes one signal and
//! re-evaluates only those checks; [`CompiledCell::evaluate_all`] is the
//! full re-evaluation it is measured and tested against.

use std::collections::HashMap;

use crate::il::Op;
use crate::logic::Term;
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
        let mut cell = CompiledCell {
            signals,
            index,
            bits: vec![0; n.div_ceil(64)],
            outputs: vec![false; checks.len()],
            checks,
            reader_start,
            readers,
            scratch: Vec::new(),
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

    /// Sets a signal and re-evaluates the checks that read it, appending to
    /// `changed` every check whose output changed. Setting a signal to the
    /// value it has does nothing.
    pub fn set(&mut self, s: SignalIndex, value: bool, changed: &mut Vec<usize>) {
        if !self.write_bit(s, value) {
            return;
        }
        let (start, end) = (
            self.reader_start[s as usize] as usize,
            self.reader_start[s as usize + 1] as usize,
        );
        for r in start..end {
            let c = self.readers[r] as usize;
            self.update(c, changed);
        }
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

    /// Re-evaluates every check, appending those whose output changed.
    pub fn evaluate_all(&mut self, changed: &mut Vec<usize>) {
        for c in 0..self.checks.len() {
            self.update(c, changed);
        }
    }

    fn update(&mut self, c: usize, changed: &mut Vec<usize>) {
        let v = self.evaluate(c);
        if v != self.outputs[c] {
            self.outputs[c] = v;
            changed.push(c);
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
}
