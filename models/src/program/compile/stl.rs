//! Siemens STL on the compiling machine, as an S7 CPU computes it: a
//! check after an assignment starts a new result (the first check), and
//! `O` alone ORs the AND groups before it. It owns these steps only; the
//! machine and every other operation are `compile.rs`'s.

use super::{negate_acc, Acc, Frame, Machine};
use crate::logic::Term;
use crate::programs::{Instruction, Op, Operation, Outside};
use crate::source::SourceErrors;

impl Machine<'_> {
    /// STL: a check after an assignment starts a new result; `O` alone
    /// ORs AND groups; `U(` as a first check opens on nothing.
    pub(super) fn stl_step(&mut self, ins: &Instruction) -> Result<(), SourceErrors> {
        let first = std::mem::replace(&mut self.first_check, false);
        match &ins.operation {
            // After `O` alone, the groups so far stay: this check starts
            // the next group.
            Operation::Logic { negated, .. } | Operation::Xor { negated } if first => {
                self.acc = negate_acc(self.operand(ins), *negated);
                self.open = None;
            }
            Operation::Logic {
                op: Op::Or,
                negated,
            } => {
                // `O x` ends the AND groups: (groups + result) OR x.
                self.fold_or_groups();
                let a = std::mem::replace(&mut self.acc, Acc::Empty);
                let b = negate_acc(self.operand(ins), *negated);
                self.acc = self.combine(Some(Op::Or), a, b, false);
            }
            Operation::Open { op, negated } => {
                if first {
                    self.acc = Acc::Empty;
                } else if matches!(op, Some(Op::Or)) {
                    self.fold_or_groups();
                }
                self.open_paren(ins, *op, *negated, None)?;
                self.first_check = true;
            }
            Operation::Close => {
                self.fold_or_groups();
                self.close_paren(ins)?;
            }
            Operation::OrGroups => {
                if matches!(self.acc, Acc::Empty) {
                    return Err(self.no_result(ins, "to OR"));
                }
                self.fold_or_groups();
                let acc = std::mem::replace(&mut self.acc, Acc::Empty);
                self.stack.push(Frame::OrGroups { acc });
                self.first_check = true;
            }
            Operation::Constant(v) => {
                self.drop_or_groups();
                self.acc = Acc::Value(Term::Const(*v));
                self.open = None;
                self.first_check = true;
            }
            Operation::Not => {
                self.fold_or_groups();
                self.iec_step(ins)?;
            }
            Operation::Write { .. }
            | Operation::Set
            | Operation::Reset
            | Operation::Outside(Outside::Indirect) => {
                self.fold_or_groups();
                self.iec_step(ins)?;
                self.first_check = true;
            }
            Operation::Outside(Outside::Word | Outside::BlockInput) => {
                self.first_check = first;
                self.iec_step(ins)?;
            }
            Operation::Outside(Outside::Call | Outside::Jump | Outside::Bits) => {
                self.drop_or_groups();
                self.iec_step(ins)?;
                self.first_check = true;
            }
            _ => self.iec_step(ins)?,
        }
        Ok(())
    }

    /// Ends the AND groups of an STL expression: the result becomes their
    /// OR with it.
    fn fold_or_groups(&mut self) {
        while let Some(Frame::OrGroups { .. }) = self.stack.last() {
            let Some(Frame::OrGroups { acc }) = self.stack.pop() else {
                break;
            };
            let current = std::mem::replace(&mut self.acc, Acc::Empty);
            self.acc = match current {
                Acc::Empty => acc,
                current => self.combine(Some(Op::Or), acc, current, true),
            };
        }
    }

    /// A new expression starts: AND groups left open are dropped (the
    /// PLC forgets them too).
    pub(super) fn drop_or_groups(&mut self) {
        while let Some(Frame::OrGroups { .. }) = self.stack.last() {
            self.stack.pop();
        }
    }
}
