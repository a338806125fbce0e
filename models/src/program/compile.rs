//! Compiling a program ([`Program::compile`]): its instructions run as a
//! PLC would, on terms instead of values, by a stack machine whose result
//! register holds a term and whose writes define the coils and their step
//! blocks. It owns the machine and what each operation does to it (IEC
//! and PMC instructions here, STL's first check and `O` groups in
//! `stl.rs`); the program it gives is `mod.rs`'s.

mod stl;

use std::collections::HashMap;

use super::{Coil, NotDerivable, Program, Warning};
use crate::comments::CommentDb;
use crate::logic::{Block, BlockId, Term};
use crate::programs::{self, Dialect, Instruction, Op, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError, SourceErrors};

/// How deep `AND(` ... `)` may nest.
const MAX_NESTING: usize = 256;

impl Program {
    /// Parses and compiles a program. `origin` names it in messages.
    ///
    /// # Errors
    /// Every unreadable line (see [`programs::parse`]), then the first structural
    /// error: an operation with no result to work on, an unbalanced stack or
    /// parenthesis.
    pub fn compile(
        origin: &str,
        source: &str,
        dialect: Option<Dialect>,
    ) -> Result<Program, SourceErrors> {
        Program::compile_in(origin, source, dialect, None)
    }

    /// [`Program::compile`], a TIA Portal export's comments taken in
    /// `language` (`de-DE`) where they have it (see [`programs::parse_in`]).
    ///
    /// # Errors
    /// As [`Program::compile`].
    pub fn compile_in(
        origin: &str,
        source: &str,
        dialect: Option<Dialect>,
        language: Option<&str>,
    ) -> Result<Program, SourceErrors> {
        let parsed = programs::parse_in(origin, source, dialect, language)?;
        let (dialect, instructions) = (parsed.dialect, parsed.instructions);
        let mut machine = Machine::new(origin, parsed.first_checks);
        for ins in &instructions {
            machine.step(ins)?;
        }
        let mut program = machine.finish(dialect, instructions.last().map(|i| i.at))?;
        let documentation = parsed
            .documentation
            .iter()
            .filter_map(|(name, comment)| Some((program.resolve(name).ok()?, comment.clone())))
            .collect();
        program.documentation = documentation;
        Ok(program)
    }
}

/// A variable name or a direct word address (`TEMP`, `%MW10`, `T1.ET`):
/// what a comparison contact may compare.
fn is_variable(text: &str) -> bool {
    let ident = |p: &str| {
        p.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
            && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    (text.starts_with('%') && text.len() > 2 && !text.contains(' ')) || text.split('.').all(ident)
}

/// `GT 80` (or `EQ LIMIT`) right after loading the number `lhs`: the
/// comparison contact `lhs > 80`, as the numeric tags define them.
fn comparison(lhs: Option<&str>, ins: &Instruction) -> Option<Signal> {
    use crate::value::{CmpOp, Comparison};
    let lhs = lhs?;
    if !matches!(ins.operation, Operation::Outside(Outside::Arithmetic)) {
        return None;
    }
    let op = match ins.mnemonic.to_ascii_uppercase().as_str() {
        "GT" => CmpOp::Gt,
        "GE" => CmpOp::Ge,
        "LT" => CmpOp::Lt,
        "LE" => CmpOp::Le,
        "EQ" => CmpOp::Eq,
        "NE" => CmpOp::Ne,
        _ => return None,
    };
    let Some(Operand::Other(rhs)) = &ins.operand else {
        return None;
    };
    let constant = rhs.parse::<f64>().is_ok();
    if !constant && !is_variable(rhs) {
        return None;
    }
    Some(
        Comparison {
            lhs: Signal::new(lhs),
            op,
            rhs: crate::value::operand(rhs),
        }
        .signal(),
    )
}

/// The result register.
#[derive(Debug, Clone)]
enum Acc {
    /// Nothing loaded yet.
    Empty,
    Value(Term),
    /// The result of something that is not boolean logic.
    Poisoned(NotDerivable),
}

#[derive(Debug)]
enum Frame {
    /// Saved by `RD.STK`.
    Pushed {
        acc: Acc,
        at: Location,
        text: String,
    },
    /// STL `O` alone: the AND groups so far, ORed with the result when the
    /// expression ends.
    OrGroups { acc: Acc },
    /// Opened by `AND(` and the like; `op` None is XOR, `opaque` an
    /// arithmetic parenthesis.
    Paren {
        op: Option<Op>,
        negated: bool,
        opaque: Option<NotDerivable>,
        acc: Acc,
        at: Location,
        text: String,
    },
}

/// A jump or conditional region, in the block it stands in.
struct Jump {
    at: Location,
    text: String,
    target: Option<String>,
    block: usize,
}

struct Machine<'a> {
    origin: &'a str,
    blocks: Vec<Block>,
    acc: Acc,
    /// The block the next same-operator instruction may extend.
    open: Option<BlockId>,
    stack: Vec<Frame>,
    coils: Vec<Coil>,
    index: HashMap<Signal, usize>,
    warnings: Vec<Warning>,
    /// Jumps and conditional regions: their location and target label.
    jumps: Vec<Jump>,
    /// Labels by block (the count of blocks ended before) and name.
    labels: HashMap<(usize, String), Location>,
    /// Where each block ended (`END_FUNCTION_BLOCK`...), in order.
    block_ends: Vec<Location>,
    /// STL: the next check starts a new result ("first check"), as after
    /// an assignment or at the start of a network.
    first_check: bool,
    /// The dialect has first checks (STL) rather than loads.
    checks_first: bool,
    /// The variable the last instruction loaded, when it was a number: a
    /// comparison right after it is a comparison contact.
    numeric: Option<String>,
}

impl<'a> Machine<'a> {
    fn new(origin: &'a str, first_checks: bool) -> Self {
        Machine {
            first_check: first_checks,
            checks_first: first_checks,
            numeric: None,
            origin,
            blocks: Vec::new(),
            acc: Acc::Empty,
            open: None,
            stack: Vec::new(),
            coils: Vec::new(),
            index: HashMap::new(),
            warnings: Vec::new(),
            jumps: Vec::new(),
            labels: HashMap::new(),
            block_ends: Vec::new(),
        }
    }

    fn error(&self, at: Location, message: String) -> SourceErrors {
        SourceError::new(self.origin, at, message).into()
    }

    fn block(&mut self, op: Op, terms: Vec<Term>) -> Term {
        self.blocks.push(Block { op, terms });
        let id = self.blocks.len() - 1;
        self.open = Some(id);
        Term::Block { id, negated: false }
    }

    /// `a op b`, extending the open block when it has the same operator.
    fn extend(&mut self, op: Op, a: Term, b: Term) -> Term {
        if let Term::Block { id, negated: false } = a {
            if self.open == Some(id) && self.blocks[id].op == op {
                self.blocks[id].terms.push(b);
                return a;
            }
        }
        self.block(op, vec![a, b])
    }

    fn xor(&mut self, a: Term, b: Term) -> Term {
        let left = self.block(Op::And, vec![a.clone(), b.clone().negate()]);
        let right = self.block(Op::And, vec![a.negate(), b]);
        let t = self.block(Op::Or, vec![left, right]);
        self.open = None;
        t
    }

    /// Combines two results with a binary operator (None: XOR), keeping
    /// poison.
    fn combine(&mut self, op: Option<Op>, a: Acc, b: Acc, fresh: bool) -> Acc {
        match (a, b) {
            (Acc::Poisoned(p), _) | (_, Acc::Poisoned(p)) => Acc::Poisoned(p),
            (Acc::Value(a), Acc::Value(b)) => Acc::Value(match op {
                Some(op) if fresh => self.block(op, vec![a, b]),
                Some(op) => self.extend(op, a, b),
                None => self.xor(a, b),
            }),
            (Acc::Empty, _) | (_, Acc::Empty) => Acc::Empty,
        }
    }

    fn operand(&self, ins: &Instruction) -> Acc {
        match &ins.operand {
            Some(Operand::Signal(s)) => Acc::Value(Term::signal(s.clone(), false)),
            Some(Operand::Const(v)) => Acc::Value(Term::Const(*v)),
            Some(Operand::Other(text)) => Acc::Poisoned(NotDerivable {
                at: ins.at,
                instruction: ins.text.clone(),
                reason: format!("'{text}' is not a boolean"),
            }),
            None => Acc::Empty,
        }
    }

    fn no_result(&self, ins: &Instruction, what: &str) -> SourceErrors {
        self.error(
            ins.at,
            format!(
                "'{}' with no result {what}: no load (RD/LD) before it",
                ins.text
            ),
        )
    }

    fn step(&mut self, ins: &Instruction) -> Result<(), SourceErrors> {
        if self.checks_first {
            return self.stl_step(ins);
        }
        self.iec_step(ins)
    }

    fn iec_step(&mut self, ins: &Instruction) -> Result<(), SourceErrors> {
        let numeric = self.numeric.take();
        if let Some(contact) = comparison(numeric.as_deref(), ins) {
            self.acc = Acc::Value(Term::signal(contact, false));
            self.open = None;
            return Ok(());
        }
        if let (Operation::Load { negated: false, .. }, Some(Operand::Other(text))) =
            (&ins.operation, &ins.operand)
        {
            if is_variable(text) {
                self.numeric = Some(text.clone());
            }
        }
        match &ins.operation {
            Operation::Load { negated, push } => {
                if *push {
                    if matches!(self.acc, Acc::Empty) {
                        return Err(self.no_result(ins, "to push"));
                    }
                    let acc = std::mem::replace(&mut self.acc, Acc::Empty);
                    self.stack.push(Frame::Pushed {
                        acc,
                        at: ins.at,
                        text: ins.text.clone(),
                    });
                }
                self.acc = negate_acc(self.operand(ins), *negated);
                self.open = None;
            }
            Operation::Logic { op, negated } => {
                if matches!(self.acc, Acc::Empty) {
                    return Err(self.no_result(ins, "to combine"));
                }
                let a = std::mem::replace(&mut self.acc, Acc::Empty);
                let b = negate_acc(self.operand(ins), *negated);
                self.acc = self.combine(Some(*op), a, b, false);
            }
            Operation::Xor { negated } => {
                if matches!(self.acc, Acc::Empty) {
                    return Err(self.no_result(ins, "to combine"));
                }
                let a = std::mem::replace(&mut self.acc, Acc::Empty);
                let b = negate_acc(self.operand(ins), *negated);
                self.acc = self.combine(None, a, b, true);
            }
            Operation::Combine(op) => {
                let saved = match self.stack.pop() {
                    Some(Frame::Pushed { acc, .. }) => acc,
                    Some(Frame::OrGroups { .. }) => {
                        return Err(self.error(
                            ins.at,
                            format!("'{}' inside an OR of AND groups ('O' alone)", ins.text),
                        ))
                    }
                    Some(Frame::Paren { at, text, .. }) => {
                        return Err(self.error(
                            ins.at,
                            format!(
                                "'{}' inside '{text}' opened at line {}: close it with ')' first",
                                ins.text, at.line
                            ),
                        ))
                    }
                    None => {
                        return Err(self.error(
                            ins.at,
                            format!(
                                "'{}' with nothing on the stack: no RD.STK before it",
                                ins.text
                            ),
                        ))
                    }
                };
                let current = std::mem::replace(&mut self.acc, Acc::Empty);
                self.acc = self.combine(Some(*op), saved, current, true);
            }
            Operation::Open { op, negated } => {
                if matches!(self.acc, Acc::Empty) {
                    return Err(self.no_result(ins, "to combine"));
                }
                self.open_paren(ins, *op, *negated, None)?;
            }
            Operation::Close => self.close_paren(ins)?,
            Operation::Not => match std::mem::replace(&mut self.acc, Acc::Empty) {
                Acc::Empty => return Err(self.no_result(ins, "to negate")),
                acc => {
                    self.acc = negate_acc(acc, true);
                    self.open = None;
                }
            },
            Operation::Write { negated } => {
                let value = self.result_for_write(ins)?;
                let value = negate_acc(value, *negated);
                self.define(ins, |_, _| value);
            }
            Operation::Set | Operation::Reset => {
                let value = self.result_for_write(ins)?;
                let set = matches!(ins.operation, Operation::Set);
                self.define(ins, |m, previous| {
                    if set {
                        m.combine(Some(Op::Or), value, previous, true)
                    } else {
                        m.combine(Some(Op::And), negate_acc(value, true), previous, true)
                    }
                });
            }
            Operation::Label(name) => {
                self.labels
                    .entry((self.block_ends.len(), name.clone()))
                    .or_insert(ins.at);
            }
            Operation::EndBlock => {
                self.drop_or_groups();
                self.check_balanced(Some(ins.at))?;
                self.block_ends.push(ins.at);
                self.acc = Acc::Empty;
                self.open = None;
                self.numeric = None;
                self.first_check = self.checks_first;
            }
            Operation::Outside(kind) => self.outside(ins, *kind)?,
            Operation::Constant(v) => {
                self.acc = Acc::Value(Term::Const(*v));
                self.open = None;
            }
            Operation::OrGroups => return Err(self.no_result(ins, "to OR")),
            Operation::Nothing => {}
        }
        Ok(())
    }

    fn open_paren(
        &mut self,
        ins: &Instruction,
        op: Option<Op>,
        negated: bool,
        opaque: Option<NotDerivable>,
    ) -> Result<(), SourceErrors> {
        if self.stack.len() >= MAX_NESTING {
            return Err(self.error(
                ins.at,
                format!("'{}' nests deeper than {MAX_NESTING} parentheses", ins.text),
            ));
        }
        let acc = std::mem::replace(&mut self.acc, Acc::Empty);
        self.stack.push(Frame::Paren {
            op,
            negated,
            opaque,
            acc,
            at: ins.at,
            text: ins.text.clone(),
        });
        self.acc = self.operand(ins);
        self.open = None;
        Ok(())
    }

    fn close_paren(&mut self, ins: &Instruction) -> Result<(), SourceErrors> {
        match self.stack.pop() {
            Some(Frame::Paren { op, negated, opaque, acc, .. }) => {
                let inner = std::mem::replace(&mut self.acc, Acc::Empty);
                if matches!(inner, Acc::Empty) {
                    return Err(self.error(ins.at, "')' closes a parenthesis with no result inside: no LD after the '('".into()));
                }
                self.acc = match (opaque, acc) {
                    (Some(p), _) => Acc::Poisoned(p),
                    // STL: a parenthesis as the first check.
                    (None, Acc::Empty) => negate_acc(inner, negated),
                    (None, acc) => self.combine(op, acc, negate_acc(inner, negated), true),
                };
                Ok(())
            }
            Some(Frame::OrGroups { .. }) => Err(self.error(
                ins.at,
                "')' inside an OR of AND groups ('O' alone) opened after its '('".into(),
            )),
            Some(Frame::Pushed { at, text, .. }) => Err(self.error(
                ins.at,
                format!("')' while '{text}' from line {} is still on the stack: combine it first (AND.STK/OR.STK)", at.line),
            )),
            None => Err(self.error(ins.at, "')' closes no '('".into())),
        }
    }

    /// The result a write stores, after checking the stack is balanced.
    fn result_for_write(&self, ins: &Instruction) -> Result<Acc, SourceErrors> {
        // STL writes inside a nesting expression: Step 7 exports set and
        // reset boxes so (`U( U( ... ) S #m U( ... ) R #m U #m )`); the
        // next check after the write starts a new result.
        let open_paren_ok =
            self.checks_first && matches!(self.stack.last(), Some(Frame::Paren { .. }));
        if let Some(frame) = self.stack.last().filter(|_| !open_paren_ok) {
            let msg = match frame {
                Frame::Pushed { at, text, .. } => format!(
                    "unbalanced stack at '{}': '{text}' at line {} pushed a result that is never combined (AND.STK/OR.STK)",
                    ins.text, at.line
                ),
                Frame::Paren { at, text, .. } => format!(
                    "unbalanced parentheses at '{}': '{text}' at line {} is never closed with ')'",
                    ins.text, at.line
                ),
                Frame::OrGroups { .. } => format!(
                    "'{}' inside an OR of AND groups ('O' alone) that is not ended",
                    ins.text
                ),
            };
            return Err(self.error(ins.at, msg));
        }
        match &self.acc {
            Acc::Empty => Err(self.no_result(ins, "to write")),
            acc => Ok(acc.clone()),
        }
    }

    /// Writes the coil named by `ins`, its new logic computed from the
    /// logic it had so far in the scan.
    fn define(&mut self, ins: &Instruction, value: impl FnOnce(&mut Self, Acc) -> Acc) {
        let Some(Operand::Signal(signal)) = &ins.operand else {
            return;
        };
        let previous = match self.index.get(signal) {
            Some(&i) => match &self.coils[i].definition {
                Ok(t) => Acc::Value(t.clone()),
                Err(p) => Acc::Poisoned(p.clone()),
            },
            None => Acc::Value(Term::signal(signal.clone(), false)),
        };
        let definition = match value(self, previous) {
            Acc::Value(t) => Ok(t),
            Acc::Poisoned(p) => Err(p),
            Acc::Empty => unreachable_empty(ins),
        };
        self.open = None;
        match self.index.get(signal) {
            Some(&i) => {
                self.coils[i].definition = definition;
                self.coils[i].writes.push(ins.at);
            }
            None => {
                self.index.insert(signal.clone(), self.coils.len());
                self.coils.push(Coil {
                    signal: signal.clone(),
                    definition,
                    writes: vec![ins.at],
                });
            }
        }
    }

    fn outside(&mut self, ins: &Instruction, kind: Outside) -> Result<(), SourceErrors> {
        if kind == Outside::Unread {
            self.warnings.push(Warning {
                at: ins.at,
                message: ins.text.clone(),
            });
            return Ok(());
        }
        let (reason, warning) = match kind {
            Outside::Unread => ("", ""),
            Outside::Jump => (
                "written after a jump or conditional region, so the write may not run every scan",
                "jump or conditional region: coils written after it are not derivable",
            ),
            Outside::Arithmetic => (
                "computed by an instruction outside boolean logic (arithmetic, comparison, timer or counter)",
                "instruction outside boolean logic: the coils it feeds are not derivable",
            ),
            Outside::Call => (
                "computed after a call, timer, counter, edge or function, whose result is not boolean logic",
                "a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
            ),
            Outside::BlockInput => (
                "",
                "an input of a function block instance, not a coil: the boolean result is left as it is",
            ),
            Outside::Word => (
                "",
                "word instruction, not boolean logic: the boolean result is left as it is",
            ),
            Outside::Indirect => (
                "",
                "indirect address: the bit it writes is known only at run time, so no coil is derived for it",
            ),
            Outside::Bits => (
                "written as a bit of a number by a word instruction",
                "a word instruction writes this coil as a bit of a number: it is not derivable",
            ),
        };
        self.warnings.push(Warning {
            at: ins.at,
            message: format!("'{}': {warning}", ins.text),
        });
        let poison = NotDerivable {
            at: ins.at,
            instruction: ins.text.clone(),
            reason: reason.to_string(),
        };
        match kind {
            Outside::Jump => {
                let target = match &ins.operand {
                    Some(Operand::Other(t)) => Some(t.to_ascii_uppercase()),
                    _ => None,
                };
                self.jumps.push(Jump {
                    at: ins.at,
                    text: ins.text.clone(),
                    target,
                    block: self.block_ends.len(),
                });
            }
            Outside::Arithmetic if ins.mnemonic.ends_with('(') => {
                // Inside an arithmetic parenthesis the result is a number
                // already: `ADD( b` ... `MUL( c` ... `)` ... `)`.
                let nested = matches!(
                    self.stack.last(),
                    Some(Frame::Paren {
                        opaque: Some(_),
                        ..
                    })
                );
                if matches!(self.acc, Acc::Empty) && !nested {
                    return Err(self.no_result(ins, "to combine"));
                }
                self.open_paren(ins, None, false, Some(poison.clone()))?;
                self.acc = Acc::Poisoned(poison);
            }
            Outside::Arithmetic | Outside::Call | Outside::Bits => {
                self.acc = Acc::Poisoned(poison);
                self.open = None;
            }
            Outside::Word | Outside::Unread | Outside::Indirect | Outside::BlockInput => {}
        }
        Ok(())
    }

    /// An error if a parenthesis, stack entry or OR of groups is left
    /// open (at the end of a block or of the program).
    fn check_balanced(&self, last: Option<Location>) -> Result<(), SourceErrors> {
        let Some(frame) = self.stack.last() else {
            return Ok(());
        };
        let (at, msg) = match frame {
            Frame::OrGroups { .. } => (last.unwrap_or(Location::line_start(1)), "an OR of AND groups ('O' alone) is never ended".to_string()),
            Frame::Pushed { at, text, .. } => (*at, format!("unbalanced stack: '{text}' pushes a result that is never combined (AND.STK/OR.STK)")),
            Frame::Paren { at, text, .. } => (*at, format!("unbalanced parentheses: '{text}' is never closed with ')'")),
        };
        Err(self.error(at, msg))
    }

    fn finish(mut self, dialect: Dialect, last: Option<Location>) -> Result<Program, SourceErrors> {
        // STL: AND groups nothing was assigned from end with the block.
        self.drop_or_groups();
        self.check_balanced(last)?;
        // From a jump (or its target, if that comes earlier) to the end of
        // its block, no write is known to run every scan. The earliest
        // such region a coil is written in explains it.
        let mut regions: Vec<(Location, Location, &Jump)> = self
            .jumps
            .iter()
            .map(|j| {
                let label = j
                    .target
                    .as_ref()
                    .and_then(|t| self.labels.get(&(j.block, t.clone())))
                    .copied();
                let start = label.map_or(j.at, |l| l.min(j.at));
                let end = self.block_ends.get(j.block).copied().unwrap_or(Location {
                    line: usize::MAX,
                    col: usize::MAX,
                });
                (start, end, j)
            })
            .collect();
        regions.sort_by_key(|(start, _, _)| *start);
        for coil in &mut self.coils {
            let hit = regions
                .iter()
                .find(|(start, end, _)| coil.writes.iter().any(|w| w >= start && w < end));
            if let Some((_, _, j)) = hit {
                coil.definition = Err(NotDerivable {
                    at: j.at,
                    instruction: j.text.clone(),
                    reason: "written after a jump or conditional region, so the write may not run every scan".into(),
                });
            }
        }
        Ok(Program {
            origin: self.origin.to_string(),
            dialect,
            blocks: self.blocks,
            coils: self.coils,
            index: self.index,
            warnings: self.warnings,
            documentation: CommentDb::default(),
        })
    }
}

fn negate_acc(acc: Acc, negate: bool) -> Acc {
    match acc {
        Acc::Value(t) => Acc::Value(t.negate_if(negate)),
        other => other,
    }
}

/// Writes are checked for a result before their value is computed, and
/// combining two results never empties them.
fn unreachable_empty(ins: &Instruction) -> ! {
    panic!(
        "internal error: write '{}' computed no result after the check",
        ins.text
    )
}
