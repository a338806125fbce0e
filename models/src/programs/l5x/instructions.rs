//! What each Logix ladder instruction does to its rung's flow: contacts,
//! coils, comparisons, timers, word instructions, calls and what is not
//! read. The routines and rungs around them are `l5x/mod.rs`'s.

use std::collections::HashSet;

use super::names::{number, NotSignal};
use super::scope::Access;
use super::{Frame, Ins, Reader, RungCtx, MAX_CALL_DEPTH};
use crate::programs::plcopen::{emit, Flow};
use crate::programs::{Instruction, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError};
use crate::value::{CmpOp, Comparison};

/// Timers, counters and other instructions whose bits (`.DN`, `.EN`) the
/// rung feeds: the rung condition is their input, and passes on.
const BLOCKS: &[&str] = &[
    "TON", "TOF", "RTO", "TONR", "TOFR", "RTOR", "CTU", "CTD", "CTUD", "RES", "MSG", "PID",
];

/// Word instructions: they leave the rung condition as it is.
const WORDS: &[&str] = &[
    "MOV", "MVM", "COP", "CPS", "CLR", "ADD", "SUB", "MUL", "DIV", "MOD", "CPT", "SQR", "NEG",
    "ABS", "BTD", "SWPB", "GSV", "SSV", "TOD", "FRD", "AND", "OR", "XOR", "NOT", "FLL",
];

/// A comparison operand: a number (decimal text), or a tag.
enum Value {
    Number(f64, String),
    Tag(Signal),
}

impl<'d> Reader<'_, 'd> {
    /// Runs one instruction on the flow reaching it; returns what flows on.
    pub(super) fn instruction(
        &mut self,
        i: &Ins,
        flow: Flow,
        rung: &mut RungCtx<'_, 'd>,
        reached: &mut HashSet<String>,
    ) -> Flow {
        let upper = i.name.to_ascii_uppercase();
        let place = self.place(rung.text, i.at);
        let and = |f: Flow| Flow::and(vec![flow.clone(), f]);
        match upper.as_str() {
            "XIC" | "XIO" => match self.tag(i, 0, rung) {
                Ok(s) => {
                    self.ids += 1;
                    and(Flow::Lit(s, upper == "XIO", self.ids))
                }
                Err(constant @ (Flow::True | Flow::False)) if upper == "XIO" => and(constant.not()),
                Err(other) => and(other),
            },
            "OTE" | "OTL" | "OTU" => {
                let value = Flow::and(vec![rung.prefix(self.cut.as_ref()), flow.clone()]);
                self.write(i, 0, &upper, value, rung);
                flow
            }
            "ONS" => and(Flow::Opaque(
                format!(
                    "'{}': a one-shot, a pulse that is not a function of the signals",
                    i.text
                ),
                place,
            )),
            "OSR" | "OSF" => {
                let pulse = Flow::Opaque(
                    format!(
                        "'{}': a one-shot, a pulse that is not a function of the signals",
                        i.text
                    ),
                    place,
                );
                self.write(i, 1, "OTE", pulse, rung);
                flow
            }
            "EQU" | "NEQ" | "GRT" | "GEQ" | "LES" | "LEQ" => {
                let op = match upper.as_str() {
                    "EQU" => CmpOp::Eq,
                    "NEQ" => CmpOp::Ne,
                    "GRT" => CmpOp::Gt,
                    "GEQ" => CmpOp::Ge,
                    "LES" => CmpOp::Lt,
                    _ => CmpOp::Le,
                };
                and(self.comparison(i, op, rung))
            }
            "LIM" => and(self.limit(i, rung)),
            "AFI" => and(Flow::False),
            "MCR" => {
                rung.zone = flow.clone();
                flow
            }
            "TND" => {
                let why = format!(
                    "routine {}, rung {}: after '{}' the rest of the scan may not run",
                    rung.frame.routine, rung.number, i.text
                );
                self.cut = Some(Flow::Opaque(why, place));
                flow
            }
            "JSR" => {
                self.call(i, &flow, rung, reached);
                flow
            }
            "NOP" | "SBR" | "RET" | "LBL" | "JMP" | "UID" | "UIE" => flow,
            _ if BLOCKS.contains(&upper.as_str()) => {
                self.outside(i, place, Outside::BlockInput);
                flow
            }
            _ if WORDS.contains(&upper.as_str()) => {
                let dest = match upper.as_str() {
                    "CPT" | "CLR" => i.args.first(),
                    "MOV" | "COP" | "CPS" => i.args.get(1),
                    _ => i.args.last(),
                };
                let dest = dest.and_then(|(_, d)| self.signal(rung.frame, d, Access::Write).ok());
                let index = self.out.len();
                self.outside(i, place, Outside::Word);
                if let Some(d) = dest {
                    // An Add-On Instruction's members are its parameters
                    // and local tags, none a BIT of another.
                    let member = rung
                        .frame
                        .aoi
                        .as_ref()
                        .is_some_and(|scope| scope.holds_member(&d));
                    self.words.push((index, d, member));
                }
                flow
            }
            _ if self.aois.contains_key(&upper) => {
                let definition = self.aois[&upper];
                self.add_on(i, definition, flow, rung, reached)
            }
            _ => and(self.unread(i, rung, format!("instruction '{}' is not read", i.name))),
        }
    }

    /// A located warning naming the routine and rung, and the flow after
    /// the instruction: not derivable.
    pub(super) fn unread(&mut self, i: &Ins, rung: &RungCtx<'_, 'd>, why: String) -> Flow {
        let place = self.place(rung.text, i.at);
        self.note_at(
            place,
            format!(
                "routine {}, rung {}: {why}",
                rung.frame.routine, rung.number
            ),
        );
        Flow::Opaque(i.text.clone(), place)
    }

    fn error(&mut self, at: Location, rung: &RungCtx<'_, 'd>, message: String) {
        self.errors.push(SourceError::new(
            self.origin,
            at,
            format!(
                "routine {}, rung {}: {message}",
                rung.frame.routine, rung.number
            ),
        ));
    }

    pub(super) fn outside(&mut self, i: &Ins, at: Location, kind: Outside) {
        self.out.push(Instruction {
            at,
            text: i.text.clone(),
            mnemonic: i.name.clone(),
            operation: Operation::Outside(kind),
            operand: None,
            operand_at: at,
        });
    }

    /// Operand `k` of `i` as a signal; else the flow it gives (a number
    /// an Add-On Instruction's input was given, or not derivable), an
    /// error recorded where it is malformed.
    fn tag(&mut self, i: &Ins, k: usize, rung: &RungCtx<'_, 'd>) -> Result<Signal, Flow> {
        let place = self.place(rung.text, i.at);
        let Some((offset, text)) = i.args.get(k) else {
            self.error(place, rung, format!("'{}' lacks operand {}", i.text, k + 1));
            return Err(Flow::Opaque(i.text.clone(), place));
        };
        match self.signal(rung.frame, text, Access::Read) {
            Ok(s) => Ok(Signal::new(&s)),
            Err(NotSignal::Number(n)) => Err(match number(&n) {
                Some(v) if v != 0.0 => Flow::True,
                Some(_) => Flow::False,
                None => Flow::Opaque(format!("'{}' reads the number {n}", i.text), place),
            }),
            Err(NotSignal::Indirect(why)) => {
                Err(Flow::Opaque(format!("indirect address {why}"), place))
            }
            Err(NotSignal::Malformed(why)) => {
                let at = self.place(rung.text, *offset);
                self.error(at, rung, why);
                Err(Flow::Opaque(i.text.clone(), place))
            }
        }
    }

    /// Writes operand `k` of `i` (`OTE`, `OTL`, `OTU`) with `value`.
    fn write(&mut self, i: &Ins, k: usize, kind: &str, value: Flow, rung: &RungCtx<'_, 'd>) {
        let place = self.place(rung.text, i.at);
        let Some((offset, text)) = i.args.get(k) else {
            self.error(place, rung, format!("'{}' lacks operand {}", i.text, k + 1));
            return;
        };
        let signal = match self.signal(rung.frame, text, Access::Write) {
            Ok(s) => Signal::new(&s),
            Err(NotSignal::Indirect(_) | NotSignal::Number(_)) => {
                return self.outside(i, place, Outside::Indirect)
            }
            Err(NotSignal::Malformed(why)) => {
                let at = self.place(rung.text, *offset);
                return self.error(at, rung, why);
            }
        };
        emit(&value, place, &mut self.out);
        let operation = match kind {
            "OTL" => Operation::Set,
            "OTU" => Operation::Reset,
            _ => Operation::Write { negated: false },
        };
        self.out.push(Instruction {
            at: place,
            text: format!("{}({signal})", i.name),
            mnemonic: i.name.clone(),
            operation,
            operand: Some(Operand::Signal(signal)),
            operand_at: place,
        });
    }

    /// A comparison operand: a Logix number or a tag; else why not.
    fn value(&mut self, text: &str, rung: &RungCtx<'_, 'd>) -> Option<Value> {
        if let Some(n) = number(text) {
            return Some(Value::Number(n, format_number(n)));
        }
        let s = match self.signal(rung.frame, text, Access::Read) {
            Ok(s) => s,
            Err(NotSignal::Number(n)) => {
                let n = number(&n)?;
                return Some(Value::Number(n, format_number(n)));
            }
            Err(_) => return None,
        };
        self.compared.insert(s.clone());
        Some(Value::Tag(Signal::new(&s)))
    }

    /// `EQU(a,b)` and the like: the comparison contact `a == b`.
    fn comparison(&mut self, i: &Ins, op: CmpOp, rung: &RungCtx<'_, 'd>) -> Flow {
        let (a, b) = match (i.args.first(), i.args.get(1), i.args.len()) {
            (Some((_, a)), Some((_, b)), 2) => (a.clone(), b.clone()),
            _ => {
                let place = self.place(rung.text, i.at);
                self.error(place, rung, format!("'{}' takes two operands", i.text));
                return Flow::Opaque(i.text.clone(), place);
            }
        };
        match (self.value(&a, rung), self.value(&b, rung)) {
            (Some(Value::Tag(l)), Some(r)) => self.contact(l, op, r),
            (Some(l @ Value::Number(..)), Some(Value::Tag(r))) => self.contact(r, mirror(op), l),
            (Some(Value::Number(l, _)), Some(Value::Number(r, _))) => {
                let holds = match op {
                    CmpOp::Eq => l == r,
                    CmpOp::Ne => l != r,
                    CmpOp::Gt => l > r,
                    CmpOp::Ge => l >= r,
                    CmpOp::Lt => l < r,
                    CmpOp::Le => l <= r,
                };
                if holds {
                    Flow::True
                } else {
                    Flow::False
                }
            }
            _ => self.unread(
                i,
                rung,
                format!(
                    "'{}' compares something that is not a tag or a number: not a contact, what follows it is not derivable",
                    i.text
                ),
            ),
        }
    }

    /// `LIM(low,test,high)` with number limits: `test` between them, or
    /// outside them when `low > high`, as Logix reads it.
    fn limit(&mut self, i: &Ins, rung: &RungCtx<'_, 'd>) -> Flow {
        let args: Vec<String> = i.args.iter().map(|(_, a)| a.clone()).collect();
        let [low, test, high] = args.as_slice() else {
            let place = self.place(rung.text, i.at);
            self.error(place, rung, format!("'{}' takes three operands", i.text));
            return Flow::Opaque(i.text.clone(), place);
        };
        match (number(low), self.value(test, rung), number(high)) {
            (Some(lo), Some(Value::Tag(t)), Some(hi)) => {
                let above = self.contact(t.clone(), CmpOp::Ge, Value::Number(lo, format_number(lo)));
                let below = self.contact(t, CmpOp::Le, Value::Number(hi, format_number(hi)));
                if lo <= hi {
                    Flow::and(vec![above, below])
                } else {
                    Flow::or(vec![above, below])
                }
            }
            _ => self.unread(
                i,
                rung,
                format!(
                    "'{}': a limit test is read with a tag between two numbers only: what follows it is not derivable",
                    i.text
                ),
            ),
        }
    }

    /// What a call on this rung (a `JSR`, an Add-On Instruction) writes
    /// under: nothing when the rung is always true at the call, else an
    /// opaque condition saying that `what` runs only when the rung is
    /// true, so that what it writes is not derivable.
    pub(super) fn call_guard(
        &self,
        i: &Ins,
        flow: &Flow,
        rung: &RungCtx<'_, 'd>,
        place: Location,
        what: &str,
    ) -> Flow {
        let condition = Flow::and(vec![rung.prefix(self.cut.as_ref()), flow.clone()]);
        if condition == Flow::True {
            return Flow::True;
        }
        Flow::Opaque(
            format!(
                "routine {}, rung {}: '{}' runs {what} only when the rung is true, so what it writes may not be written every scan",
                rung.frame.routine, rung.number, i.text
            ),
            place,
        )
    }

    /// `JSR(Routine,...)`: the routine runs here, on this rung's condition.
    fn call(
        &mut self,
        i: &Ins,
        flow: &Flow,
        rung: &RungCtx<'_, 'd>,
        reached: &mut HashSet<String>,
    ) {
        let place = self.place(rung.text, i.at);
        let Some((_, target)) = i.args.first() else {
            return self.error(place, rung, format!("'{}' names no routine", i.text));
        };
        let upper = target.to_ascii_uppercase();
        let Some(&node) = rung.frame.routines.get(&upper) else {
            self.unread(
                i,
                rung,
                format!("'{}': routine '{target}' is not in this export", i.text),
            );
            return;
        };
        if rung.frame.calls.contains(&upper) || rung.frame.calls.len() >= MAX_CALL_DEPTH {
            self.unread(
                i,
                rung,
                format!(
                    "'{}': routine '{target}' is already running (a JSR cycle, or calls deeper than {MAX_CALL_DEPTH}): not run again",
                    i.text
                ),
            );
            return;
        }
        let guard = self.call_guard(i, flow, rung, place, &format!("routine {target}"));
        let mut calls = rung.frame.calls.clone();
        calls.push(upper);
        let frame = Frame {
            program: rung.frame.program,
            routines: rung.frame.routines.clone(),
            routine: node.attribute("Name").unwrap_or(target).to_string(),
            calls,
            guard,
            aoi: rung.frame.aoi.clone(),
        };
        self.routine(node, &frame, reached);
    }

    /// The contact `lhs op rhs`.
    fn contact(&mut self, lhs: Signal, op: CmpOp, rhs: Value) -> Flow {
        let rhs = match rhs {
            Value::Number(_, text) => crate::value::operand(&text),
            Value::Tag(s) => crate::value::operand(s.name()),
        };
        let signal = Comparison { lhs, op, rhs }.signal();
        self.ids += 1;
        Flow::Lit(signal, false, self.ids)
    }

    /// Word instructions that write a tag a comparison reads say so; one
    /// that writes a word whose bits are coils (`D.3`), or a member of a
    /// structure whose BOOL members are coils (`MOV(-1, Fail.Failures)`
    /// with `Fail.Overload` a BIT of that SINT), makes those coils not
    /// derivable from there on: the PLC writes them as a number. Which
    /// member a BIT aliases is the data type's business, so every coil of
    /// the structure counts — never a coil read as derivable that a word
    /// instruction writes.
    pub(super) fn mark_word_writes(&mut self) {
        let coils: Vec<String> = self
            .out
            .iter()
            .filter(|i| {
                matches!(
                    i.operation,
                    Operation::Write { .. } | Operation::Set | Operation::Reset
                )
            })
            .filter_map(|i| match &i.operand {
                Some(Operand::Signal(s)) => Some(s.name().to_string()),
                _ => None,
            })
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let words = std::mem::take(&mut self.words);
        for (index, dest, member) in words.into_iter().rev() {
            let Some(ins) = self.out.get_mut(index) else {
                continue;
            };
            if self.compared.contains(&dest) {
                ins.text = format!(
                    "{} (writes '{dest}', which a comparison contact reads as the PLC holds it)",
                    ins.text
                );
            }
            let (at, mnemonic, text) = (ins.at, ins.mnemonic.clone(), ins.text.clone());
            let written: Vec<Instruction> = coils
                .iter()
                .filter(|c| {
                    if member {
                        c.strip_prefix(dest.as_str())
                            .is_some_and(|r| r.starts_with('.'))
                    } else {
                        holds(&dest, c)
                    }
                })
                .flat_map(|c| {
                    [
                        Instruction {
                            at,
                            text: format!("{text} → {c}"),
                            mnemonic: mnemonic.clone(),
                            operation: Operation::Outside(Outside::Bits),
                            operand: None,
                            operand_at: at,
                        },
                        Instruction {
                            at,
                            text: format!("OTE({c})"),
                            mnemonic: "OTE".into(),
                            operation: Operation::Write { negated: false },
                            operand: Some(Operand::Signal(Signal::new(c))),
                            operand_at: at,
                        },
                    ]
                })
                .collect();
            self.out.splice(index + 1..index + 1, written);
        }
    }
}

/// Whether a word instruction writing `dest` may write coil `coil`: a bit
/// of it (`dest.3`, `dest.Member`), or a member of the structure `dest` is
/// a member of. A program tag's `Program:<name>.` prefix is its scope, not
/// a structure.
fn holds(dest: &str, coil: &str) -> bool {
    if coil.strip_prefix(dest).is_some_and(|r| r.starts_with('.')) {
        return true;
    }
    let scope = |name: &str| -> usize {
        match name.strip_prefix("Program:") {
            Some(rest) => rest
                .find('.')
                .map_or(name.len(), |dot| "Program:".len() + dot + 1),
            None => 0,
        }
    };
    let tag = &dest[scope(dest)..];
    match tag.rfind('.') {
        Some(dot) => {
            let structure = &dest[..scope(dest) + dot + 1];
            coil.starts_with(structure)
        }
        None => false,
    }
}

/// `a op b` as `b op' a`.
fn mirror(op: CmpOp) -> CmpOp {
    match op {
        CmpOp::Gt => CmpOp::Lt,
        CmpOp::Ge => CmpOp::Le,
        CmpOp::Lt => CmpOp::Gt,
        CmpOp::Le => CmpOp::Ge,
        other => other,
    }
}

/// A number as the comparison contact writes it: integers without a point.
fn format_number(n: f64) -> String {
    if n.fract() == 0.0 && n.abs() < 1e15 {
        format!("{}", n as i64)
    } else {
        format!("{n}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_word_write_holds_its_bits_and_its_structure_s_members() {
        use super::holds;
        assert!(holds("D", "D.3"));
        assert!(holds("Fail.Failures", "Fail.Overload"));
        assert!(holds(
            "Program:Main.Fail.Failures",
            "Program:Main.Fail.Overload"
        ));
        assert!(!holds("Program:Main.Count", "Program:Main.Seal"));
        assert!(!holds("Count", "Counter.0"));
        assert!(!holds("Fail.Failures", "Failures.Overload"));
    }
}
